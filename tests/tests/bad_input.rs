//! The "bad input tried" table of docs/reliability.md, measured: every case runs the `ellipso`
//! binary on one bad input (scenes, sessions, frames, meshes, CLI flags, signals; the full disk
//! is `full_disk.rs`) and is classified as
//! - **clear error**: non-zero exit whose message contains what is wrong (the case's needle);
//! - **handled**: a damaged but usable input (exit 0) whose output says what was wrong;
//! - **panic**: a panic, an abort or a death by signal the case did not send;
//! - **hang**: no exit within 180 s;
//! - **data changed**: a byte of a recorded session (frames, manifest, the log's existing lines)
//!   or of the input file differs afterwards.
//!
//! `cargo test -p ellipso-tests --test bad_input -- --nocapture` prints the table. The test fails
//! on any panic, hang, data change, or outcome other than the one the case expects.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use ellipso_sim::geometry::TriangleMesh;
use ellipso_sim::geometry::ply::{PlyFormat, write_ply};
use ellipso_sim::geometry::procedural::icosphere;
use ellipso_tests::{ellipso_bin, shipped_scene};
use nalgebra::Point3;

/// What a case must do.
#[derive(Clone, Copy, Debug)]
enum Expect {
    /// Exit non-zero, stderr containing this.
    Refuse(&'static str),
    /// Exit 0, stdout or stderr containing this.
    Warn(&'static str),
}

/// How a case went.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Verdict {
    ClearError,
    Handled,
    Panic,
    Hang,
    DataChanged,
    /// Not what the case expects (exit 0 where a refusal was due, or the message lacks the
    /// needle).
    Unexpected,
}

/// The bytes a run must not change: files compared whole, logs by prefix.
struct Protected {
    whole: Vec<(PathBuf, Option<Vec<u8>>)>,
    prefix: Vec<(PathBuf, Vec<u8>)>,
}

impl Protected {
    fn of(paths: &[PathBuf]) -> Self {
        let mut whole = Vec::new();
        let mut prefix = Vec::new();
        for p in paths {
            let mut stack = vec![p.clone()];
            while let Some(q) = stack.pop() {
                if q.is_dir() {
                    for e in std::fs::read_dir(&q).unwrap().filter_map(Result::ok) {
                        // outputs the commands write inside a session are not recorded data
                        if e.file_name() != "replay" {
                            stack.push(e.path());
                        }
                    }
                } else if q.file_name().is_some_and(|n| n == "events.jsonl") {
                    prefix.push((q.clone(), std::fs::read(&q).unwrap_or_default()));
                } else {
                    whole.push((q.clone(), std::fs::read(&q).ok()));
                }
            }
        }
        Self { whole, prefix }
    }

    fn unchanged(&self) -> bool {
        self.whole.iter().all(|(p, b)| std::fs::read(p).ok() == *b)
            && self.prefix.iter().all(|(p, b)| {
                std::fs::read(p)
                    .unwrap_or_default()
                    .starts_with(b.as_slice())
            })
    }
}

/// Runs `cmd`, at most 180 s; (exit code or None, stdout + stderr, timed out).
fn run_bounded(mut cmd: Command) -> (Option<i32>, String, String, bool) {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn ellipso");
    let out = child.stdout.take().unwrap();
    let err = child.stderr.take().unwrap();
    let read = |mut r: Box<dyn std::io::Read + Send>| {
        std::thread::spawn(move || {
            let mut s = String::new();
            let _ = r.read_to_string(&mut s);
            s
        })
    };
    let (out, err) = (read(Box::new(out)), read(Box::new(err)));
    let deadline = Instant::now() + Duration::from_secs(180);
    let (code, timed_out) = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break (s.code(), false);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break (None, true);
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    (code, out.join().unwrap(), err.join().unwrap(), timed_out)
}

fn classify(
    expect: Expect,
    code: Option<i32>,
    stdout: &str,
    stderr: &str,
    timed_out: bool,
    unchanged: bool,
) -> Verdict {
    if timed_out {
        return Verdict::Hang;
    }
    if stderr.contains("panicked") || stderr.contains("memory allocation") || code == Some(101) {
        return Verdict::Panic;
    }
    if !unchanged {
        return Verdict::DataChanged;
    }
    match expect {
        Expect::Refuse(needle) if code.is_some_and(|c| c != 0) && stderr.contains(needle) => {
            Verdict::ClearError
        }
        Expect::Warn(needle)
            if code == Some(0) && (stdout.contains(needle) || stderr.contains(needle)) =>
        {
            Verdict::Handled
        }
        _ if code.is_none() => Verdict::Panic,
        _ => Verdict::Unexpected,
    }
}

/// One tried input.
struct Case {
    category: &'static str,
    name: String,
    expect: Expect,
    /// Prepares the input in its own directory and returns the command and what it must not
    /// change.
    setup: Box<dyn Fn(&Path) -> (Command, Vec<PathBuf>) + Send + Sync>,
}

fn case(
    category: &'static str,
    name: impl Into<String>,
    expect: Expect,
    setup: impl Fn(&Path) -> (Command, Vec<PathBuf>) + Send + Sync + 'static,
) -> Case {
    Case {
        category,
        name: name.into(),
        expect,
        setup: Box::new(setup),
    }
}

fn ellipso(args: &[&str]) -> Command {
    let mut c = Command::new(ellipso_bin());
    c.args(args);
    c
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// The sphere scene with its board path absolute (so copies work from anywhere).
fn sphere_text() -> String {
    let board = shipped_scene("../boards/base_a4.toml")
        .canonicalize()
        .unwrap();
    std::fs::read_to_string(shipped_scene("sphere.toml"))
        .unwrap()
        .replace(
            "file = \"../boards/base_a4.toml\"",
            &format!("file = \"{}\"", board.display()),
        )
}

/// One captured session for every session, frame and mesh case (copied per case).
fn fixture() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let root = tempfile::tempdir().unwrap().keep();
        let out = root.join("session");
        let o = ellipso(&["capture", "--sim"])
            .arg(shipped_scene("sphere.toml").canonicalize().unwrap())
            .arg("--out")
            .arg(&out)
            .args([
                "--photos",
                "8",
                "--resolution",
                "612x512",
                "--supersampling",
                "1",
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        out
    })
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dst = to.join(e.file_name());
        if e.path().is_dir() {
            copy_dir(&e.path(), &dst);
        } else {
            std::fs::copy(e.path(), dst).unwrap();
        }
    }
}

/// A copy of the fixture session in `dir`, damaged by `damage`.
fn damaged(dir: &Path, damage: impl Fn(&Path)) -> PathBuf {
    let s = dir.join("session");
    copy_dir(fixture(), &s);
    damage(&s);
    s
}

/// The sphere object (r = 40 mm at z = 40 mm, moved by `offset`) as a mesh file.
fn mesh(dir: &Path, offset: f64) -> PathBuf {
    let (dirs, faces) = icosphere(1);
    let pos = dirs
        .iter()
        .map(|d| Point3::new(offset, 0.0, 0.04) + d.into_inner() * 0.04)
        .collect();
    let m = TriangleMesh::new(pos, None, None, faces).unwrap();
    let p = dir.join("mesh.ply");
    std::fs::write(&p, write_ply(&m, PlyFormat::BinaryLittleEndian, false)).unwrap();
    p
}

/// `ellipso fit SESSION --mesh MESH --outer 1 --out DIR/fit`.
fn fit(dir: &Path, session: &Path, mesh: &Path) -> Command {
    let mut c = ellipso(&["fit"]);
    c.arg(session)
        .arg("--mesh")
        .arg(mesh)
        .args(["--outer", "1", "--out"])
        .arg(dir.join("fit"));
    c
}

fn edit_file(p: &Path, from: &str, to: &str) {
    let t = std::fs::read_to_string(p).unwrap();
    // sessions of older builds name the layout `monopolar`
    let from = if from == "\"mono_polar\"" && !t.contains(from) {
        "\"monopolar\""
    } else {
        from
    };
    assert!(t.contains(from), "{from} not in {}", p.display());
    std::fs::write(p, t.replacen(from, to, 1)).unwrap();
}

fn scene_cases() -> Vec<Case> {
    let edits: Vec<(&str, &str, &str, &'static str)> = vec![
        ("eta NaN", "eta = 1.5", "eta = nan", "eta"),
        ("eta 1e78", "eta = 1.5", "eta = 1e78", "eta"),
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

fn session_cases() -> Vec<Case> {
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

fn frame_cases() -> Vec<Case> {
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

fn mesh_cases() -> Vec<Case> {
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
        ("nowhere near the views", |d| mesh(d, 100.0), "no vertex"),
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

fn flag_cases() -> Vec<Case> {
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

fn wait_for_frames(dir: &Path, n: usize) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while std::fs::read_dir(dir.join("frames"))
        .map(|d| {
            d.filter_map(Result::ok)
                .filter(|e| e.path().extension().is_some_and(|x| x == "png"))
                .count()
        })
        .unwrap_or(0)
        < n
    {
        assert!(Instant::now() < deadline, "no frames in time");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A signal sent mid-run; the verdict is computed here (the generic runner cannot send it).
fn signal_case(dir: &Path, what: &str, signal: i32) -> Verdict {
    let session;
    let mut child = if what == "capture" {
        session = dir.join("cap");
        let mut c = ellipso(&["capture", "--sim"]);
        c.arg(shipped_scene("sphere.toml"))
            .arg("--out")
            .arg(&session)
            .args([
                "--photos",
                "200",
                "--resolution",
                "96x80",
                "--supersampling",
                "1",
            ])
            .args(["--interval-ms", "100", "--no-track"]);
        c
    } else {
        // fit mid-way through re-tracking every frame of a session without poses
        session = damaged(dir, |s| {
            let p = s.join("events.jsonl");
            let t = std::fs::read_to_string(&p).unwrap();
            let kept: Vec<&str> = t
                .lines()
                .filter(|l| !l.contains("\"type\":\"pose"))
                .collect();
            std::fs::write(&p, kept.join("\n") + "\n").unwrap();
        });
        fit(dir, &session, &mesh(dir, 0.0))
    }
    .stdout(Stdio::null())
    .stderr(Stdio::piped())
    .spawn()
    .unwrap();
    let before = if what == "capture" {
        wait_for_frames(&session, 3);
        None
    } else {
        let p = Protected::of(std::slice::from_ref(&session));
        std::thread::sleep(Duration::from_millis(300));
        Some(p)
    };
    let pid = i32::try_from(child.id()).unwrap();
    // SAFETY: our own child, not yet waited for; kill only sends it a signal.
    unsafe { libc::kill(pid, signal) };
    let deadline = Instant::now() + Duration::from_secs(120);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let Some(status) = status else {
        return Verdict::Hang;
    };
    let mut err = String::new();
    use std::io::Read;
    let _ = child.stderr.take().unwrap().read_to_string(&mut err);
    if err.contains("panicked") {
        return Verdict::Panic;
    }
    if let Some(before) = before {
        // the fit may die on the signal; what was recorded must not change, and a second run
        // must finish the job
        if !before.unchanged() {
            return Verdict::DataChanged;
        }
        let o = fit(dir, &session, &mesh(dir, 0.0)).output().unwrap();
        return if o.status.success() {
            Verdict::Handled
        } else {
            Verdict::Unexpected
        };
    }
    let Ok(s) = ellipso_host::session::reader::open(&session) else {
        return Verdict::DataChanged;
    };
    let frames_load = s.frames.iter().all(|f| s.load_frame(f).is_ok());
    let clean = match signal {
        libc::SIGKILL => !s.report.ended_cleanly && s.report.bad_lines.is_empty(),
        sig => {
            status.code() == Some(128 + sig)
                && s.report.ended_cleanly
                && s.report.summary() == "intact"
        }
    };
    if frames_load && clean {
        Verdict::Handled
    } else {
        Verdict::Unexpected
    }
}

#[test]
fn bad_input_table() {
    let mut cases = scene_cases();
    cases.extend(session_cases());
    cases.extend(frame_cases());
    cases.extend(mesh_cases());
    cases.extend(flag_cases());
    let tmp = tempfile::tempdir().unwrap();
    fixture();
    let mut results: Vec<(&'static str, String, Verdict)> = Vec::new();
    for (i, c) in cases.iter().enumerate() {
        let dir = tmp.path().join(format!("case{i}"));
        std::fs::create_dir(&dir).unwrap();
        let (cmd, protect) = (c.setup)(&dir);
        let before = Protected::of(&protect);
        let (code, stdout, stderr, timed_out) = run_bounded(cmd);
        let v = classify(
            c.expect,
            code,
            &stdout,
            &stderr,
            timed_out,
            before.unchanged(),
        );
        if !matches!(v, Verdict::ClearError | Verdict::Handled) {
            println!(
                "{} / {}: {v:?} (exit {code:?})\n{stderr}",
                c.category, c.name
            );
        }
        results.push((c.category, c.name.clone(), v));
        let _ = std::fs::remove_dir_all(&dir);
    }
    let signals = [
        ("capture", libc::SIGINT),
        ("capture", libc::SIGTERM),
        ("capture", libc::SIGKILL),
        ("fit", libc::SIGINT),
    ];
    for (i, (what, sig)) in signals.into_iter().enumerate() {
        let dir = tmp.path().join(format!("signal{i}"));
        std::fs::create_dir(&dir).unwrap();
        let v = signal_case(&dir, what, sig);
        results.push(("signals", format!("{what} + signal {sig}"), v));
    }
    println!(
        "| input | tried | clear error | handled (went on, said what was wrong) | panic | hang | data changed | other |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut categories: Vec<&str> = results.iter().map(|r| r.0).collect();
    categories.dedup();
    for cat in categories {
        let of = |v: Verdict| results.iter().filter(|r| r.0 == cat && r.2 == v).count();
        let tried = results.iter().filter(|r| r.0 == cat).count();
        println!(
            "| {cat} | {tried} | {} | {} | {} | {} | {} | {} |",
            of(Verdict::ClearError),
            of(Verdict::Handled),
            of(Verdict::Panic),
            of(Verdict::Hang),
            of(Verdict::DataChanged),
            of(Verdict::Unexpected)
        );
    }
    let bad: Vec<_> = results
        .iter()
        .filter(|r| !matches!(r.2, Verdict::ClearError | Verdict::Handled))
        .collect();
    assert!(bad.is_empty(), "cases not handled as documented: {bad:#?}");
}
