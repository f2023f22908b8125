//! The cases of the bad-input table on the files a fit reads beside the session's log: damaged
//! frames (skipped by `fit`, refused by `polar`) and meshes that are missing, damaged or out of
//! view (refused by `fit`).

use std::path::{Path, PathBuf};

use super::support::{Case, Expect, case, damaged, ellipso, fit, fixture, mesh, s};

pub fn frame_cases() -> Vec<Case> {
    type Damage = fn(&Path);
    let damages: Vec<(&str, Damage)> = vec![
        ("truncated PNG", |p| {
            let b = std::fs::read(p).unwrap();
            std::fs::write(p, &b[..b.len() / 2]).unwrap();
        }),
        ("zero bytes", |p| std::fs::write(p, b"").unwrap()),
        ("random bytes", |p| {
            std::fs::write(
                p,
                (0..999u32)
                    .map(|i| i.wrapping_mul(7919) as u8)
                    .collect::<Vec<_>>(),
            )
            .unwrap()
        }),
        ("8-bit PNG", |p| {
            image::GrayImage::new(612, 512).save(p).unwrap()
        }),
        ("RGB PNG", |p| {
            image::RgbImage::new(612, 512).save(p).unwrap()
        }),
        ("wrong size", |p| {
            image::ImageBuffer::<image::Luma<u16>, _>::new(64, 48)
                .save(p)
                .unwrap()
        }),
        ("values beyond 12 bits", |p| {
            image::ImageBuffer::<image::Luma<u16>, _>::from_pixel(612, 512, image::Luma([65535]))
                .save(p)
                .unwrap()
        }),
        ("a directory", |p| {
            std::fs::remove_file(p).unwrap();
            std::fs::create_dir(p).unwrap();
        }),
    ];
    let mut cases = Vec::new();
    for (name, damage) in damages {
        // the fit skips the frame, says so and goes on with the rest
        cases.push(case(
            "frames",
            format!("{name} (fit)"),
            Expect::Warn("skipped"),
            move |dir| {
                let s = damaged(dir, |s| {
                    let mut frames: Vec<_> = std::fs::read_dir(s.join("frames"))
                        .unwrap()
                        .map(|e| e.unwrap().path())
                        .collect();
                    frames.sort();
                    damage(&frames[2]);
                });
                (fit(dir, &s, &mesh(dir, 0.0)), vec![s])
            },
        ));
        // `polar` on the file itself names it (any even size is a frame to `polar`: it has no
        // manifest to compare with)
        if name == "wrong size" {
            continue;
        }
        cases.push(case(
            "frames",
            format!("{name} (polar)"),
            Expect::Refuse("frame.png"),
            move |dir| {
                let p = dir.join("frame.png");
                std::fs::copy(
                    fixture()
                        .join("frames")
                        .read_dir()
                        .unwrap()
                        .next()
                        .unwrap()
                        .unwrap()
                        .path(),
                    &p,
                )
                .unwrap();
                damage(&p);
                let mut c = ellipso(&["polar", &s(&p), "--out"]);
                c.arg(dir.join("out")).args(["--bit-depth", "12"]);
                (c, vec![])
            },
        ));
    }
    cases
}

pub fn mesh_cases() -> Vec<Case> {
    type Make = fn(&Path) -> PathBuf;
    let meshes: Vec<(&str, Make, &'static str)> = vec![
        ("missing", |d| d.join("absent.ply"), "absent.ply"),
        (
            "a directory",
            |d| {
                let p = d.join("m.ply");
                std::fs::create_dir(&p).unwrap();
                p
            },
            "m.ply",
        ),
        (
            "empty",
            |d| {
                let p = d.join("m.ply");
                std::fs::write(&p, b"").unwrap();
                p
            },
            "m.ply",
        ),
        (
            "truncated",
            |d| {
                let p = mesh(d, 0.0);
                let b = std::fs::read(&p).unwrap();
                std::fs::write(&p, &b[..b.len() / 2]).unwrap();
                p
            },
            "mesh.ply",
        ),
        (
            "garbage",
            |d| {
                let p = d.join("m.ply");
                std::fs::write(&p, b"ply\nformat nonsense\n").unwrap();
                p
            },
            "m.ply",
        ),
        (
            "NaN vertex",
            |d| {
                let p = d.join("m.obj");
                std::fs::write(&p, b"v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n").unwrap();
                p
            },
            "m.obj",
        ),
        (
            "face index out of range",
            |d| {
                let p = d.join("m.obj");
                std::fs::write(&p, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
                p
            },
            "m.obj",
        ),
        (
            "no faces",
            |d| {
                let p = d.join("m.obj");
                std::fs::write(&p, b"v 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
                p
            },
            "m.obj",
        ),
        (
            "unknown format",
            |d| {
                let p = d.join("m.stl");
                std::fs::write(&p, b"solid x\nendsolid x\n").unwrap();
                p
            },
            "m.stl",
        ),
        (
            "nowhere near the views",
            |d| mesh(d, 100.0),
            "px in the median view",
        ),
    ];
    meshes
        .into_iter()
        .map(|(name, make, needle)| {
            case("meshes", name, Expect::Refuse(needle), move |dir| {
                let s = damaged(dir, |_| {});
                let m = make(dir);
                (fit(dir, &s, &m), vec![s])
            })
        })
        .collect()
}
