//! The cases of the bad-input table, by input kind.

use std::path::{Path, PathBuf};
use std::process::Command;

use ellipso_tests::{ellipso_bin, shipped_scene};

use super::support::{
    Case, Expect, case, damaged, edit_file, ellipso, fit, fixture, mesh, s, sphere_text,
};

pub fn scene_cases() -> Vec<Case> {
    let edits: Vec<(&str, &str, &str, &'static str)> = vec![
        ("eta NaN", "eta = 1.517", "eta = nan", "eta"),
        ("eta 1e78", "eta = 1.517", "eta = 1e78", "eta"),
        ("rho_s 1e308", "rho_s = 1.0", "rho_s = 1e308", "rho_s"),
        (
            "negative radius",
            "radius_m = 0.04",
            "radius_m = -0.04",
            "radius_m",
        ),
        (
            "unknown key",
            "seed = 1",
            "seed = 1\ncolour = 3",
            "unknown field",
        ),
        (
            "resolution 100000²",
            "resolution_px = [2448, 2048]",
            "resolution_px = [100000, 100000]",
            "resolution_px",
        ),
        (
            "bit depth 9",
            "bit_depth = 12",
            "bit_depth = 9",
            "bit_depth",
        ),
        (
            "exposure 0",
            "exposure_us = 8000.0",
            "exposure_us = 0.0",
            "exposure_us",
        ),
        (
            "photo count 0",
            "photo_count = 150",
            "photo_count = 0",
            "photo_count",
        ),
        ("seed negative", "seed = 1", "seed = -1", "seed"),
        (
            "mesh path a directory",
            "shape = \"sphere\"\nradius_m = 0.04",
            "shape = \"mesh\"\nmesh = \".\"",
            "is a directory",
        ),
        (
            "mesh path missing",
            "shape = \"sphere\"\nradius_m = 0.04",
            "shape = \"mesh\"\nmesh = \"absent.ply\"",
            "does not exist",
        ),
        (
            "string for a number",
            "radius_m = 0.04",
            "radius_m = \"big\"",
            "invalid type",
        ),
        (
            "duplicate key",
            "seed = 1",
            "seed = 1\nseed = 2",
            "duplicate key",
        ),
    ];
    let mut cases: Vec<Case> = edits
        .into_iter()
        .map(|(name, from, to, needle)| {
            case("scenes", name, Expect::Refuse(needle), move |dir| {
                let p = dir.join("scene.toml");
                std::fs::write(&p, sphere_text().replacen(from, to, 1)).unwrap();
                (ellipso(&["sim", "plan", &s(&p)]), vec![p])
            })
        })
        .collect();
    let raw: Vec<(&str, Vec<u8>)> = vec![
        ("empty file", Vec::new()),
        (
            "binary garbage",
            (0..4096u32)
                .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
                .collect(),
        ),
        ("truncated", sphere_text().as_bytes()[..600].to_vec()),
    ];
    for (name, bytes) in raw {
        cases.push(case(
            "scenes",
            name,
            Expect::Refuse("scene.toml"),
            move |dir| {
                let p = dir.join("scene.toml");
                std::fs::write(&p, &bytes).unwrap();
                (ellipso(&["sim", "plan", &s(&p)]), vec![p])
            },
        ));
    }
    cases.push(case(
        "scenes",
        "missing file",
        Expect::Refuse("absent.toml"),
        |dir| {
            (
                ellipso(&["sim", "plan", &s(&dir.join("absent.toml"))]),
                vec![],
            )
        },
    ));
    cases.push(case(
        "scenes",
        "a directory",
        Expect::Refuse("scene.d"),
        |dir| {
            let d = dir.join("scene.d");
            std::fs::create_dir(&d).unwrap();
            (ellipso(&["sim", "plan", &s(&d)]), vec![])
        },
    ));
    cases.push(case(
        "scenes",
        "board file a directory",
        Expect::Refuse("is a directory"),
        |dir| {
            let p = dir.join("scene.toml");
            let board = shipped_scene("../boards/base_a4.toml")
                .canonicalize()
                .unwrap();
            std::fs::write(
                &p,
                sphere_text().replace(&board.display().to_string(), &s(dir)),
            )
            .unwrap();
            (ellipso(&["sim", "plan", &s(&p)]), vec![p])
        },
    ));
    cases
}

pub fn session_cases() -> Vec<Case> {
    let mut cases = Vec::new();
    // refused when opened (replay opens, reads and reports)
    let manifest_edits: Vec<(&str, &str, &str, &'static str)> = vec![
        (
            "schema version 2",
            "\"schema_version\": 1",
            "\"schema_version\": 2",
            "schema v2",
        ),
        (
            "bit depth 0",
            "\"bit_depth\": 12",
            "\"bit_depth\": 0",
            "sensor.bit_depth",
        ),
        (
            "bit depth 20",
            "\"bit_depth\": 12",
            "\"bit_depth\": 20",
            "sensor.bit_depth",
        ),
        (
            "odd width",
            "\"width\": 612",
            "\"width\": 611",
            "sensor.width",
        ),
        (
            "unknown layout",
            "\"mono_polar\"",
            "\"bayer\"",
            "sensor.layout",
        ),
        (
            "width a string",
            "\"width\": 612",
            "\"width\": \"wide\"",
            "manifest.json:",
        ),
    ];
    for (name, from, to, needle) in manifest_edits {
        cases.push(case("sessions", name, Expect::Refuse(needle), move |dir| {
            let s = damaged(dir, |s| edit_file(&s.join("manifest.json"), from, to));
            let mut c = ellipso(&["replay"]);
            c.arg(&s).arg("--out").arg(dir.join("r"));
            (c, vec![s])
        }));
    }
    cases.push(case(
        "sessions",
        "manifest missing",
        Expect::Refuse("manifest.json"),
        |dir| {
            let s = damaged(dir, |s| {
                std::fs::remove_file(s.join("manifest.json")).unwrap()
            });
            let mut c = ellipso(&["replay"]);
            c.arg(&s).arg("--out").arg(dir.join("r"));
            (c, vec![s])
        },
    ));
    cases.push(case(
        "sessions",
        "manifest garbage",
        Expect::Refuse("manifest.json:1:"),
        |dir| {
            let s = damaged(dir, |s| {
                std::fs::write(s.join("manifest.json"), b"{\x01}").unwrap()
            });
            let mut c = ellipso(&["replay"]);
            c.arg(&s).arg("--out").arg(dir.join("r"));
            (c, vec![s])
        },
    ));
    cases.push(case(
        "sessions",
        "session path a file",
        Expect::Refuse("manifest.json"),
        |dir| {
            let f = dir.join("file");
            std::fs::write(&f, b"x").unwrap();
            (ellipso(&["replay", &s(&f)]), vec![f])
        },
    ));
    // damaged but usable: replay goes on and says what it found
    type Damage = fn(&Path);
    let usable: Vec<(&str, Damage, &'static str)> = vec![
        (
            "log deleted",
            |s| std::fs::remove_file(s.join("events.jsonl")).unwrap(),
            "frames without metadata",
        ),
        (
            "last log line cut",
            |s| {
                let p = s.join("events.jsonl");
                let b = std::fs::read(&p).unwrap();
                std::fs::write(&p, &b[..b.len() - 9]).unwrap();
            },
            "last log line truncated",
        ),
        (
            "corrupt middle line",
            |s| {
                let p = s.join("events.jsonl");
                let t = std::fs::read_to_string(&p).unwrap();
                let mut lines: Vec<&str> = t.lines().collect();
                lines[3] = "{\"type\":\"pulse\",\"seq\":\"x\"}";
                std::fs::write(&p, lines.join("\n") + "\n").unwrap();
            },
            "corrupt log lines skipped (line 4)",
        ),
        (
            "duplicate frame event",
            |s| {
                let p = s.join("events.jsonl");
                let t = std::fs::read_to_string(&p).unwrap();
                let frame = t
                    .lines()
                    .find(|l| l.contains("\"type\":\"frame\""))
                    .unwrap()
                    .to_string();
                std::fs::write(&p, t + &frame + "\n").unwrap();
            },
            "frame ids logged twice",
        ),
        (
            "duplicate pulse event",
            |s| {
                let p = s.join("events.jsonl");
                let t = std::fs::read_to_string(&p).unwrap();
                let pulse = t
                    .lines()
                    .find(|l| l.contains("\"type\":\"pulse\""))
                    .unwrap()
                    .to_string();
                std::fs::write(&p, t + &pulse + "\n").unwrap();
            },
            "pulses logged twice",
        ),
        (
            "no end record (killed)",
            |s| {
                let p = s.join("manifest.json");
                let mut v: serde_json::Value =
                    serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
                v.as_object_mut().unwrap().remove("end");
                std::fs::write(&p, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
            },
            "did not end cleanly",
        ),
    ];
    for (name, damage, needle) in usable {
        cases.push(case("sessions", name, Expect::Warn(needle), move |dir| {
            let s = damaged(dir, damage);
            let mut c = ellipso(&["replay"]);
            c.arg(&s).arg("--out").arg(dir.join("r"));
            (c, vec![s])
        }));
    }
    // the fit refuses to report nothing
    let fit_refusals: Vec<(&str, Damage, &'static str)> = vec![
        (
            "frames/ missing (fit)",
            |s| std::fs::remove_dir_all(s.join("frames")).unwrap(),
            "no vertex",
        ),
        (
            "bit depth 8 over 12-bit data (fit)",
            |s| {
                edit_file(
                    &s.join("manifest.json"),
                    "\"bit_depth\": 12",
                    "\"bit_depth\": 8",
                )
            },
            "8-bit maximum",
        ),
        (
            "flash not recorded (fit)",
            |s| {
                let p = s.join("manifest.json");
                let mut v: serde_json::Value =
                    serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
                v["rig"]["flash"] = serde_json::Value::Null;
                std::fs::write(&p, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
            },
            "rig.flash",
        ),
        (
            "camera model not recorded (fit)",
            |s| {
                let p = s.join("manifest.json");
                let mut v: serde_json::Value =
                    serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
                v["rig"]["camera"] = serde_json::Value::Null;
                std::fs::write(&p, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
            },
            "rig",
        ),
        (
            "every frame flagged (calibrate)",
            |s| {
                let p = s.join("events.jsonl");
                let t = std::fs::read_to_string(&p).unwrap();
                std::fs::write(
                    &p,
                    t.replace(
                        "\"status\":\"complete\"",
                        "\"status\":\"flagged\",\"reason\":\"x\"",
                    ),
                )
                .unwrap();
            },
            "no complete frame",
        ),
    ];
    for (name, damage, needle) in fit_refusals {
        cases.push(case("sessions", name, Expect::Refuse(needle), move |dir| {
            let s = damaged(dir, damage);
            let c = if name.contains("calibrate") {
                let mut c = ellipso(&["calibrate"]);
                c.arg(&s).arg("--out").arg(dir.join("cam.toml"));
                c
            } else {
                fit(dir, &s, &mesh(dir, 0.0))
            };
            (c, vec![s])
        }));
    }
    cases
}

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

pub fn flag_cases() -> Vec<Case> {
    let flags: Vec<(&str, Vec<&'static str>, &'static str)> = vec![
        (
            "render --width 100000",
            vec![
                "sim", "render", "SCENE", "--out", "OUT", "--width", "100000", "--height", "100000",
            ],
            "2..=16384",
        ),
        (
            "render --width 321 (odd)",
            vec![
                "sim", "render", "SCENE", "--out", "OUT", "--width", "321", "--height", "256",
            ],
            "odd",
        ),
        (
            "render --frames 0",
            vec!["sim", "render", "SCENE", "--out", "OUT", "--frames", "0"],
            "1..=",
        ),
        (
            "render --frame 10000",
            vec!["sim", "render", "SCENE", "--out", "OUT", "--frame", "10000"],
            "--frame 10000",
        ),
        (
            "render --supersampling 0",
            vec![
                "sim",
                "render",
                "SCENE",
                "--out",
                "OUT",
                "--supersampling",
                "0",
            ],
            "1..=8",
        ),
        (
            "capture --resolution 100000x100000",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--resolution",
                "100000x100000",
            ],
            "2..=16384",
        ),
        (
            "capture --resolution 0x0",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--resolution",
                "0x0",
            ],
            "2..=16384",
        ),
        (
            "capture --photos 0",
            vec!["capture", "--sim", "SCENE", "--out", "OUT", "--photos", "0"],
            "1..=",
        ),
        (
            "capture --interval-ms 0",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--interval-ms",
                "0",
            ],
            "longer than 0",
        ),
        (
            "capture --interval-ms nan",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--interval-ms",
                "nan",
            ],
            "outside",
        ),
        (
            "capture --interval-ms 1e300",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--interval-ms",
                "1e300",
            ],
            "outside",
        ),
        (
            "capture --interval-ms 1 (< exposure)",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--interval-ms",
                "1",
            ],
            "would refuse",
        ),
        (
            "capture --supersampling 9",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--supersampling",
                "9",
            ],
            "1..=8",
        ),
        (
            "fit --outer 4294967295",
            vec!["fit", "OUT", "--mesh", "SCENE", "--outer", "4294967295"],
            "1..=20",
        ),
        (
            "fit --outer 0",
            vec!["fit", "OUT", "--mesh", "SCENE", "--outer", "0"],
            "1..=20",
        ),
        (
            "fit --view 999999 (no such frame)",
            vec![
                "fit", "SESSION", "--mesh", "MESH", "--outer", "1", "--out", "OUT", "--view",
                "999999",
            ],
            "frame 999999",
        ),
        (
            "bench pose --frames 0",
            vec!["bench", "pose", "SCENE", "--frames", "0"],
            "1..=",
        ),
        (
            "bench pose --resolution 3x3",
            vec!["bench", "pose", "SCENE", "--resolution", "3x3"],
            "odd",
        ),
        (
            "bench calibration --frames 0",
            vec!["bench", "calibration", "SCENE", "--frames", "0"],
            "1..=",
        ),
        (
            "polar --dark-intensity nan",
            vec!["polar", "SCENE", "--out", "OUT", "--dark-intensity", "nan"],
            "outside",
        ),
        (
            "polar --dark-level 1e9",
            vec!["polar", "SCENE", "--out", "OUT", "--dark-level", "1e9"],
            "outside",
        ),
        (
            "polar --bit-depth 14",
            vec!["polar", "SCENE", "--out", "OUT", "--bit-depth", "14"],
            "8, 10, 12, 16",
        ),
        (
            "sim serve --ber 2",
            vec!["sim", "serve", "SCENE", "--pty", "--ber", "2"],
            "outside",
        ),
        (
            "sim serve --drift-ppm inf",
            vec!["sim", "serve", "SCENE", "--pty", "--drift-ppm", "inf"],
            "outside",
        ),
        (
            "model dop --eta 1e78",
            vec!["model", "dop", "--eta", "1e78", "--theta-deg", "30"],
            "[1, 5]",
        ),
        (
            "model fresnel --eta 1e155",
            vec!["model", "fresnel", "--eta", "1e155", "--theta-deg", "30"],
            "[1, 5]",
        ),
        (
            "model fresnel --theta-deg 91",
            vec!["model", "fresnel", "--eta", "1.5", "--theta-deg", "91"],
            "--theta-deg",
        ),
        (
            "model mueller --eta 1e200",
            vec![
                "model",
                "mueller",
                "--eta",
                "1e200",
                "--sigma-s",
                "0.2",
                "--sigma-ss",
                "0.5",
                "--rho-s",
                "1",
                "--rho-ss",
                "0,0,0",
                "--rho-d",
                "0,0,0",
                "--normal",
                "0,0,1",
                "--to-light",
                "0,0,1",
                "--to-camera",
                "0,0,1",
            ],
            "[1, 5]",
        ),
        (
            "model mueller --rho-s 1e308",
            vec![
                "model",
                "mueller",
                "--eta",
                "1.5",
                "--sigma-s",
                "0.2",
                "--sigma-ss",
                "0.5",
                "--rho-s",
                "1e308",
                "--rho-ss",
                "0,0,0",
                "--rho-d",
                "0,0,0",
                "--normal",
                "0,0,1",
                "--to-light",
                "0,0,1",
                "--to-camera",
                "0,0,1",
            ],
            "[0, 1000]",
        ),
        (
            "model mueller --normal 0,0,0",
            vec![
                "model",
                "mueller",
                "--eta",
                "1.5",
                "--sigma-s",
                "0.2",
                "--sigma-ss",
                "0.5",
                "--rho-s",
                "1",
                "--rho-ss",
                "0,0,0",
                "--rho-d",
                "0,0,0",
                "--normal",
                "0,0,0",
                "--to-light",
                "0,0,1",
                "--to-camera",
                "0,0,1",
            ],
            "non-zero",
        ),
    ];
    let mut cases: Vec<Case> = flags
        .into_iter()
        .map(|(name, args, needle)| {
            case("CLI flags", name, Expect::Refuse(needle), move |dir| {
                let session = if args.contains(&"SESSION") {
                    Some(damaged(dir, |_| {}))
                } else {
                    None
                };
                let scene = shipped_scene("sphere.toml");
                let m = dir.join("mesh.ply");
                let args: Vec<String> = args
                    .iter()
                    .map(|a| match *a {
                        "SCENE" => s(&scene),
                        "OUT" => s(&dir.join("out")),
                        "SESSION" => s(session.as_ref().unwrap()),
                        "MESH" => s(&mesh(dir, 0.0)),
                        other => other.to_string(),
                    })
                    .collect();
                let _ = m;
                let mut c = Command::new(ellipso_bin());
                c.args(&args);
                (c, session.into_iter().collect())
            })
        })
        .collect();
    // a reader that goes away is no reason to die, nor to skip the results
    cases.push(case("CLI flags", "stdout closed (fit | head -0)", Expect::Warn("results in"), |dir| {
        let s = damaged(dir, |_| {});
        let m = mesh(dir, 0.0);
        let script = format!(
            "\"$0\" fit '{}' --mesh '{}' --outer 1 --out '{}' | head -c 0; test -f '{}' && echo results in >&2",
            s.display(),
            m.display(),
            dir.join("fit").display(),
            dir.join("fit").join("fit.ply").display()
        );
        let mut c = Command::new("sh");
        c.arg("-c").arg(script).arg(ellipso_bin());
        (c, vec![s])
    }));
    cases
}
