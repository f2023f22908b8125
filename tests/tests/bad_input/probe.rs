//! The second probe's cases (issue 28), each the reproduction of what the probe found and the
//! behaviour a user expects: outputs that would have lost a user's files or written over an
//! input, calibration from an orbit, impossible inputs fitted into confident answers, unbounded
//! and special-file inputs, errors that blamed the wrong thing. The runs that need a signal or
//! two processes at once are in `runs.rs`.

use std::path::{Path, PathBuf};
use std::process::Command;

use ellipso_fit::shard::part::PartFile;
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyFormat, write_ply};
use ellipso_model::geometry::procedural::icosphere;
use ellipso_tests::ellipso_bin;
use ellipso_tests::fit_fixture::write_fit_dir;
use nalgebra::Point3;

use super::support::{
    Case, Expect, case, copy_dir, damaged, edit_log, edit_manifest, ellipso, fifo, fit, fixture,
    fixture40, mesh, s,
};

/// A shell running `script` with `$0` = the ellipso binary.
fn sh(script: String) -> Command {
    let mut c = Command::new("sh");
    c.arg("-c").arg(script).arg(ellipso_bin());
    c
}

/// A copy of the 40-frame orbit in `dir`.
fn orbit(dir: &Path) -> PathBuf {
    let s = dir.join("orbit");
    copy_dir(fixture40(), &s);
    s
}

/// Case 1 and 3: outputs never lose a user's files nor write over an input.
pub fn output_cases() -> Vec<Case> {
    let mut cases = vec![
        case(
            "outputs",
            "demo --out: a directory holding summary.json and the user's thesis.tex",
            Expect::Refuse("did not write"),
            |dir| {
                let d = dir.join("d");
                std::fs::create_dir(&d).unwrap();
                std::fs::write(d.join("summary.json"), b"{}").unwrap();
                std::fs::write(d.join("thesis.tex"), b"keep").unwrap();
                let mut c = ellipso(&["demo", "--quick", "--out"]);
                c.arg(&d);
                (c, vec![d])
            },
        ),
        case(
            "outputs",
            "demo --out: a directory holding session/manifest.json beside the user's files",
            Expect::Refuse("did not write"),
            |dir| {
                let d = dir.join("d");
                copy_dir(fixture(), &d.join("session"));
                std::fs::write(d.join("notes.txt"), b"keep").unwrap();
                let mut c = ellipso(&["demo", "--quick", "--out"]);
                c.arg(&d);
                (c, vec![d])
            },
        ),
        case(
            "outputs",
            "sim render --out: a directory with the user's file",
            Expect::Refuse("did not write"),
            |dir| {
                let d = dir.join("r");
                std::fs::create_dir(&d).unwrap();
                std::fs::write(d.join("frame_00000.png"), b"mine").unwrap();
                let mut c = ellipso(&["sim", "render"]);
                c.arg(ellipso_tests::shipped_scene("sphere.toml"))
                    .arg("--out")
                    .arg(&d)
                    .args(["--frames", "1", "--width", "64", "--height", "48"]);
                (c, vec![d])
            },
        ),
        case(
            "outputs",
            "replay --out: another command's output",
            Expect::Refuse("output of `ellipso fit`"),
            |dir| {
                let session = damaged(dir, |_| {});
                let d = dir.join("out");
                std::fs::create_dir(&d).unwrap();
                std::fs::write(
                    d.join(".ellipso-output.json"),
                    br#"{"command":"fit","software":"ellipso","files":["fit.ply"]}"#,
                )
                .unwrap();
                std::fs::write(d.join("fit.ply"), b"ply\n").unwrap();
                let mut c = ellipso(&["replay"]);
                c.arg(&session).arg("--out").arg(&d);
                (c, vec![session, d])
            },
        ),
        case(
            "outputs",
            "mesh --out x.ply over the user's text file",
            Expect::Refuse("not a PLY file"),
            |dir| {
                let session = damaged(dir, |_| {});
                let x = dir.join("x.ply");
                std::fs::write(&x, b"my notes").unwrap();
                let mut c = ellipso(&["mesh"]);
                c.arg(&session).arg("--out").arg(&x);
                (c, vec![session, x])
            },
        ),
        case(
            "outputs",
            "mesh --out x.obj writes OBJ, not PLY bytes",
            Expect::Warn("OBJ written"),
            |dir| {
                let session = orbit(dir);
                let x = dir.join("x.obj");
                let script = format!(
                    "\"$0\" mesh '{}' --out '{}' && head -c 14 '{}' | grep -q '# ellipso mesh' \
                     && echo OBJ written >&2",
                    session.display(),
                    x.display(),
                    x.display()
                );
                (sh(script), vec![session])
            },
        ),
    ];
    // an output equal to, inside or around an input, or inside a session
    type Args = fn(&Path, &Path) -> Vec<String>;
    let overlapping: Vec<(&str, Args, &'static str)> = vec![
        (
            "mesh --out SESSION/manifest.json",
            |_, s| {
                vec![
                    "mesh".into(),
                    str(s),
                    "--out".into(),
                    str(&s.join("manifest.json")),
                ]
            },
            "recorded session",
        ),
        (
            "model plot --out SESSION/frames/00000001.png",
            |_, s| {
                vec![
                    "model".into(),
                    "plot".into(),
                    "--out".into(),
                    str(&s.join("frames").join("00000001.png")),
                ]
            },
            "recorded session",
        ),
        (
            "fit --out SESSION",
            |d, s| fit_args(d, s, s),
            "this is the recorded session",
        ),
        (
            "fit --out SESSION/frames",
            |d, s| fit_args(d, s, &s.join("frames")),
            "recorded session",
        ),
        (
            "fit --out the directory holding the session",
            |d, s| fit_args(d, s, d),
            "contains",
        ),
        (
            "export colmap --out SESSION/colmap",
            |_, s| {
                vec![
                    "export".into(),
                    "colmap".into(),
                    str(s),
                    "--out".into(),
                    str(&s.join("colmap")),
                ]
            },
            "recorded session",
        ),
        (
            "calibrate --out SESSION/frames/camera.toml",
            |_, s| {
                vec![
                    "calibrate".into(),
                    str(s),
                    "--out".into(),
                    str(&s.join("frames").join("camera.toml")),
                ]
            },
            "recorded session",
        ),
        (
            "polar SESSION/frames/00000001.png --out SESSION/frames",
            |_, s| {
                vec![
                    "polar".into(),
                    str(&s.join("frames").join("00000001.png")),
                    "--out".into(),
                    str(&s.join("frames")),
                ]
            },
            "recorded session",
        ),
    ];
    for (name, args, needle) in overlapping {
        cases.push(case("outputs", name, Expect::Refuse(needle), move |dir| {
            let session = damaged(dir, |_| {});
            let mut c = Command::new(ellipso_bin());
            c.args(args(dir, &session));
            (c, vec![session])
        }));
    }
    cases.push(case(
        "outputs",
        "export mitsuba FIT --out FIT",
        Expect::Refuse("which this run reads"),
        |dir| {
            let f = write_fit_dir(&dir.join("fit"));
            let mut c = ellipso(&["export", "mitsuba"]);
            c.arg(&f).arg("--out").arg(&f);
            (c, vec![f])
        },
    ));
    cases
}

fn str(p: &Path) -> String {
    s(p)
}

/// `fit SESSION --mesh SPHERE --outer 1 --out OUT` as arguments.
fn fit_args(dir: &Path, session: &Path, out: &Path) -> Vec<String> {
    vec![
        "fit".into(),
        str(session),
        "--mesh".into(),
        str(&mesh(dir, 0.0)),
        "--outer".into(),
        "1".into(),
        "--out".into(),
        str(out),
    ]
}

/// Case 2 and 11: calibration from an orbit, and the orbit's poses with a tag cut by the sphere.
pub fn orbit_cases() -> Vec<Case> {
    vec![
        case(
            "calibration and tags",
            "calibrate on a 40-frame orbit of the sphere (the probe: fx 973 ± 4, fy 490 ± 15, cy −127 ± 10)",
            Expect::Refuse("take 15–30 calibration photos"),
            |dir| {
                let session = orbit(dir);
                let mut c = ellipso(&["calibrate"]);
                c.arg(&session).arg("--out").arg(dir.join("camera.toml"));
                (c, vec![session])
            },
        ),
        case(
            "calibration and tags",
            "re-tracking the orbit: a tag cut by the sphere costs the tag, not the frame",
            Expect::Warn("40 of 40 frames"),
            |dir| {
                let session = orbit(dir);
                let mut c = ellipso(&["replay"]);
                c.arg(&session).arg("--out").arg(dir.join("r"));
                (c, vec![session])
            },
        ),
    ]
}

/// A mesh file of the sphere's icosphere with positions mapped by `at` and faces by `face`.
fn sphere_like(
    dir: &Path,
    at: impl Fn(Point3<f64>) -> Point3<f64>,
    face: impl Fn([u32; 3]) -> [u32; 3],
) -> PathBuf {
    let (dirs, faces) = icosphere(1);
    let pos = dirs
        .iter()
        .map(|d| at(Point3::new(0.0, 0.0, 0.04) + d.into_inner() * 0.04))
        .collect();
    let faces = faces.into_iter().map(face).collect();
    let m = TriangleMesh::new(pos, None, None, faces).unwrap();
    let p = dir.join("m.ply");
    std::fs::write(&p, write_ply(&m, PlyFormat::BinaryLittleEndian, false)).unwrap();
    p
}

/// Case 7: impossible inputs are refused with their cause instead of fitted.
pub fn impossible_cases() -> Vec<Case> {
    type MakeMesh = fn(&Path) -> PathBuf;
    let meshes: Vec<(&str, MakeMesh, &'static str)> = vec![
        (
            "mesh collapsed to one point",
            |d| sphere_like(d, |_| Point3::new(0.0, 0.0, 0.04), |f| f),
            "0 m across",
        ),
        (
            "mesh of zero area (flattened onto a line)",
            |d| sphere_like(d, |p| Point3::new(p.x, 0.0, 0.04), |f| f),
            "have no area",
        ),
        (
            "mesh scaled by 1e-40",
            |d| sphere_like(d, |p| Point3::from(p.coords * 1e-40), |f| f),
            "px in the median view",
        ),
        (
            "mesh with its winding flipped",
            |d| sphere_like(d, |p| p, |f| [f[0], f[2], f[1]]),
            "wind clockwise",
        ),
    ];
    let mut cases: Vec<Case> = meshes
        .into_iter()
        .map(|(name, make, needle)| {
            case(
                "impossible inputs",
                name,
                Expect::Refuse(needle),
                move |dir| {
                    let session = damaged(dir, |_| {});
                    let m = make(dir);
                    (fit(dir, &session, &m), vec![session])
                },
            )
        })
        .collect();
    type Damage = fn(&Path);
    let sessions: Vec<(&str, Damage, &[&str], &'static str)> = vec![
        (
            "every pose identical",
            |s| {
                let first = std::cell::RefCell::new(None);
                edit_log(s, |mut v| {
                    if v["type"] == "pose" {
                        let mut f = first.borrow_mut();
                        let keep = f.get_or_insert_with(|| {
                            (
                                v["rotation_camera_from_world"].clone(),
                                v["translation_camera_from_world_m"].clone(),
                            )
                        });
                        v["rotation_camera_from_world"] = keep.0.clone();
                        v["translation_camera_from_world_m"] = keep.1.clone();
                    }
                    Some(v)
                })
            },
            &["fit"],
            "one and the same pose",
        ),
        (
            "a camera 1e308 m from the board",
            |s| {
                edit_log(s, |mut v| {
                    if v["type"] == "pose" && v["frame_id"] == 2 {
                        v["translation_camera_from_world_m"][0] = 1e308.into();
                    }
                    Some(v)
                })
            },
            &["fit", "mesh", "colmap"],
            "m from the board origin",
        ),
        (
            "fx = 1e308",
            |s| edit_manifest(s, |v| v["rig"]["camera"]["fx"] = 1e308.into()),
            &["fit", "mesh", "colmap"],
            "fx = 1e308",
        ),
        (
            "k1 = 1e308",
            |s| edit_manifest(s, |v| v["rig"]["camera"]["k1"] = 1e308.into()),
            &["fit", "colmap"],
            "k1 = 1e308",
        ),
        (
            "two pose events for one frame that disagree",
            |s| {
                let p = s.join("events.jsonl");
                let text = std::fs::read_to_string(&p).unwrap();
                let pose = text
                    .lines()
                    .find(|l| l.contains("\"type\":\"pose\""))
                    .unwrap();
                let mut v: serde_json::Value = serde_json::from_str(pose).unwrap();
                v["translation_camera_from_world_m"][0] = 0.3.into();
                std::fs::write(&p, format!("{text}{v}\n")).unwrap();
            },
            &["fit"],
            "pose events disagree",
        ),
        (
            "gain −400 dB",
            |s| {
                edit_log(s, |mut v| {
                    if v["type"] == "frame" {
                        v["gain_db"] = (-400.0).into();
                    }
                    Some(v)
                })
            },
            &["fit"],
            "gain_db",
        ),
        (
            "exposure 0 µs (was blamed on 23753 samples in shadow)",
            |s| {
                edit_log(s, |mut v| {
                    if v["type"] == "frame" {
                        v["exposure_us"] = 0.into();
                    }
                    Some(v)
                })
            },
            &["fit"],
            "exposure_us",
        ),
        (
            "flash energy 1e308 (was blamed as non-finite)",
            |s| {
                edit_log(s, |mut v| {
                    if v["type"] == "pairing" {
                        v["flash_energy_rel"] = 1e308.into();
                    }
                    Some(v)
                })
            },
            &["fit"],
            "flash_energy_rel",
        ),
    ];
    for (name, damage, commands, needle) in sessions {
        for &command in commands {
            cases.push(case(
                "impossible inputs",
                format!("{name} ({command})"),
                Expect::Refuse(needle),
                move |dir| {
                    let session = damaged(dir, damage);
                    let c = match command {
                        "fit" => fit(dir, &session, &mesh(dir, 0.0)),
                        "mesh" => {
                            let mut c = ellipso(&["mesh"]);
                            c.arg(&session).arg("--out").arg(dir.join("m.ply"));
                            c
                        }
                        _ => {
                            let mut c = ellipso(&["export", "colmap"]);
                            c.arg(&session).arg("--out").arg(dir.join("colmap"));
                            c
                        }
                    };
                    (c, vec![session])
                },
            ));
        }
    }
    cases.push(case(
        "impossible inputs",
        "two pose events for one frame that disagree (replay)",
        Expect::Warn("pose events that disagree"),
        |dir| {
            let session = damaged(dir, |s| {
                let p = s.join("events.jsonl");
                let text = std::fs::read_to_string(&p).unwrap();
                let pose = text
                    .lines()
                    .find(|l| l.contains("\"type\":\"pose\""))
                    .unwrap();
                let mut v: serde_json::Value = serde_json::from_str(pose).unwrap();
                v["translation_camera_from_world_m"][0] = 0.3.into();
                std::fs::write(&p, format!("{text}{v}\n")).unwrap();
            });
            let mut c = ellipso(&["replay"]);
            c.arg(&session).arg("--out").arg(dir.join("r"));
            (c, vec![session])
        },
    ));
    cases
}

/// Case 8: endless sources and special files are refused before they are read; numeric flags
/// are bounded.
pub fn bound_cases() -> Vec<Case> {
    let mut cases = vec![
        case(
            "unbounded inputs",
            "fit --mesh /dev/zero (grew to 15.7 GB)",
            Expect::Refuse("character device"),
            |dir| {
                let session = damaged(dir, |_| {});
                (fit(dir, &session, Path::new("/dev/zero")), vec![session])
            },
        ),
        case(
            "unbounded inputs",
            "fit-merge /dev/zero as a part file",
            Expect::Refuse("character device"),
            |dir| {
                let mut c = ellipso(&["fit-merge", "/dev/zero", "--out"]);
                c.arg(dir.join("out"));
                (c, vec![])
            },
        ),
        case(
            "unbounded inputs",
            "polar on a FIFO",
            Expect::Refuse("FIFO"),
            |dir| {
                let p = dir.join("frame.png");
                fifo(&p);
                let mut c = ellipso(&["polar", &s(&p), "--out"]);
                c.arg(dir.join("out"));
                (c, vec![])
            },
        ),
        case(
            "unbounded inputs",
            "a frame that is a FIFO (fit)",
            Expect::Warn("skipped"),
            |dir| {
                let session = damaged(dir, |s| fifo(&s.join("frames").join("00000003.png")));
                (fit(dir, &session, &mesh(dir, 0.0)), vec![])
            },
        ),
    ];
    type Damage = fn(&Path);
    let special: Vec<(&str, Damage, &'static str)> = vec![
        (
            "manifest a FIFO",
            |s| fifo(&s.join("manifest.json")),
            "FIFO",
        ),
        (
            "event log a FIFO",
            |s| fifo(&s.join("events.jsonl")),
            "FIFO",
        ),
        (
            "manifest a link to /dev/zero",
            |s| {
                std::fs::remove_file(s.join("manifest.json")).unwrap();
                std::os::unix::fs::symlink("/dev/zero", s.join("manifest.json")).unwrap();
            },
            "character device",
        ),
        (
            "event log a link to /dev/zero",
            |s| {
                std::fs::remove_file(s.join("events.jsonl")).unwrap();
                std::os::unix::fs::symlink("/dev/zero", s.join("events.jsonl")).unwrap();
            },
            "character device",
        ),
    ];
    for (name, damage, needle) in special {
        for command in ["fit", "replay"] {
            cases.push(case(
                "unbounded inputs",
                format!("{name} ({command})"),
                Expect::Refuse(needle),
                move |dir| {
                    let session = damaged(dir, damage);
                    let c = if command == "fit" {
                        fit(dir, &session, &mesh(dir, 0.0))
                    } else {
                        let mut c = ellipso(&["replay"]);
                        c.arg(&session).arg("--out").arg(dir.join("r"));
                        c
                    };
                    (c, vec![])
                },
            ));
        }
    }
    for (flag, value, needle) in [
        ("--threads", "100000", "1..=256"),
        ("--vertices", "10000000", "100..=2000000"),
        ("--vertices", "0", "100..=2000000"),
        ("--votes", "0", "1..=100"),
    ] {
        cases.push(case(
            "unbounded inputs",
            format!("mesh {flag} {value}"),
            Expect::Refuse(needle),
            move |dir| {
                let session = damaged(dir, |_| {});
                let mut c = ellipso(&["mesh"]);
                c.arg(&session)
                    .args([flag, value, "--out"])
                    .arg(dir.join("m.ply"));
                (c, vec![session])
            },
        ));
    }
    cases
}

/// A real part file of the 8-frame fixture (`fit --shard 0/1`), at `dir/p.part`.
fn part_file(dir: &Path) -> (PathBuf, PathBuf) {
    let session = damaged(dir, |_| {});
    let m = mesh(dir, 0.0);
    let p = dir.join("p.part");
    let o = ellipso(&["fit"])
        .arg(&session)
        .arg("--mesh")
        .arg(&m)
        .args(["--shard", "0/1", "--out"])
        .arg(&p)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    (p, session)
}

/// Case 5 and 9: no panic on any input; errors that name the right cause, once.
pub fn error_cases() -> Vec<Case> {
    vec![
        case(
            "errors",
            "fit-merge: a part whose shard index ≥ count, checksum valid (panicked)",
            Expect::Refuse("impossible"),
            |dir| {
                let (p, session) = part_file(dir);
                let mut part = PartFile::read(&p).unwrap();
                part.shard.index = 5;
                part.shard.count = 2;
                part.write(&p).unwrap();
                let mut c = ellipso(&["fit-merge"]);
                c.arg(&p).arg("--out").arg(dir.join("out"));
                (c, vec![session, p])
            },
        ),
        case(
            "errors",
            "fit-merge: parts whose text holds terminal escapes",
            Expect::Refuse("\\u{1b}"),
            |dir| {
                let (p, session) = part_file(dir);
                let mut part = PartFile::read(&p).unwrap();
                part.session_dir = dir.join("\u{1b}[2J\u{1b}[31mgone");
                part.write(&p).unwrap();
                let mut c = ellipso(&["fit-merge"]);
                c.arg(&p).arg("--out").arg(dir.join("out"));
                (c, vec![session, p])
            },
        ),
        case(
            "errors",
            "fit --shard 0/2 --out out/ (said 'Not a directory')",
            Expect::Refuse("names a directory"),
            |dir| {
                let session = damaged(dir, |_| {});
                let mut c = ellipso(&["fit"]);
                c.arg(&session)
                    .arg("--mesh")
                    .arg(mesh(dir, 0.0))
                    .args(["--shard", "0/2", "--out"])
                    .arg(format!("{}/out/", dir.display()));
                (c, vec![session])
            },
        ),
        case(
            "errors",
            "fit --mesh absent.ply: the OS message said once",
            Expect::RefuseOnce("No such file or directory"),
            |dir| {
                let session = damaged(dir, |_| {});
                (fit(dir, &session, &dir.join("absent.ply")), vec![session])
            },
        ),
        case(
            "errors",
            "fit --out into the session with --view 999999: refused at once, before any work",
            Expect::Refuse("recorded session"),
            |dir| {
                let session = damaged(dir, |_| {});
                let mut c = ellipso(&["fit"]);
                c.arg(&session)
                    .arg("--mesh")
                    .arg(mesh(dir, 0.0))
                    .args(["--view", "999999", "--out"])
                    .arg(session.join("fit"));
                (c, vec![session])
            },
        ),
        case(
            "errors",
            "fit 2>&1 | head -1 (panicked writing to the closed pipe)",
            Expect::Warn("results in"),
            |dir| {
                let session = damaged(dir, |_| {});
                let out = dir.join("fit");
                let script = format!(
                    "\"$0\" fit '{}' --mesh '{}' --outer 1 --out '{}' 2>&1 | head -1 >/dev/null; \
                     s=${{PIPESTATUS[0]}}; echo \"ellipso exited $s\" >&2; \
                     test \"$s\" = 0 && test -f '{}' && echo results in >&2",
                    session.display(),
                    mesh(dir, 0.0).display(),
                    out.display(),
                    out.join("fit.ply").display()
                );
                let mut c = Command::new("bash");
                c.arg("-c").arg(script).arg(ellipso_bin());
                (c, vec![session])
            },
        ),
    ]
}
