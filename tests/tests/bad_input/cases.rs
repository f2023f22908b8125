//! The cases of the bad-input table on recorded inputs: scene files and sessions. Frames and
//! meshes are in `frames_meshes.rs`, CLI flags in `flags.rs`.

use std::path::Path;

use ellipso_tests::shipped_scene;

use super::support::{Case, Expect, case, damaged, edit_file, ellipso, fit, mesh, s, sphere_text};

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
