//! "Never silently wrong", across processes: the `ellipso` binary on the inputs a hostile new
//! user tries (issue 16). Each test is the regression test of one defect:
//! - a capture at 20 fps pairs every frame with its own pulse (not the next one);
//! - `capture` refuses an `--out` that holds anything (an older recording above all);
//! - SIGINT / SIGTERM end a capture cleanly: frames in flight drained, end record written,
//!   the board stopped;
//! - `fit` refuses to report nothing, warns about and counts every skipped frame, and refuses a
//!   manifest whose sensor fields are impossible;
//! - pose appends start on a fresh line and frames without a pose are re-tracked;
//! - numeric flags are checked against the same limits as the files; a closed stdout ends the
//!   output, not the process.

use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use ellipso_session::events::SessionEvent;
use ellipso_session::reader;
use ellipso_tests::{ellipso_bin, shipped_scene as scene};

fn ellipso(args: &[&str]) -> Output {
    Command::new(ellipso_bin())
        .args(args)
        .output()
        .expect("run ellipso")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `ellipso capture --sim sphere.toml` of `photos` small frames every `interval_ms`.
fn capture_cmd(out: &Path, photos: u32, interval_ms: u32) -> Command {
    let mut c = Command::new(ellipso_bin());
    c.args(["capture", "--sim"])
        .arg(scene("sphere.toml"))
        .arg("--out")
        .arg(out)
        .args(["--photos", &photos.to_string()])
        .args(["--resolution", "96x80", "--supersampling", "1"])
        .args(["--interval-ms", &interval_ms.to_string(), "--no-track"]);
    c
}

/// A pairing event: frame id, pulse seq, basis.
type Pair = (u64, u64, Option<String>);

/// Every pairing, and the frame ids and pulse seqs of the session.
fn pairs_of(dir: &Path) -> (Vec<Pair>, Vec<u64>, Vec<u64>) {
    let s = reader::open(dir).expect("session opens");
    let mut pairs = Vec::new();
    let mut pulses = Vec::new();
    for e in &s.events {
        match e {
            SessionEvent::Pairing {
                frame_id,
                seq,
                basis,
                ..
            } => pairs.push((*frame_id, *seq, basis.clone())),
            SessionEvent::Pulse { seq, .. } => pulses.push(*seq),
            _ => {}
        }
    }
    let frames = s.frames.iter().map(|f| f.frame_id).collect();
    (pairs, frames, pulses)
}

#[test]
fn a_20_fps_capture_pairs_every_frame_with_its_own_pulse() {
    // The capture at 50 ms (and 75 ms): the simulated camera delivers ~65 ms after the
    // trigger, so each frame arrives after the next pulse fired. The scene has no frame drops or
    // missed triggers, so the k-th frame is the k-th pulse's.
    let tmp = tempfile::tempdir().unwrap();
    for interval_ms in [50, 75] {
        let out = tmp.path().join(format!("s{interval_ms}"));
        let o = capture_cmd(&out, 10, interval_ms).output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        // the layout as docs/session-format.md names it (it was written `monopolar`)
        let text = std::fs::read_to_string(out.join("manifest.json")).unwrap();
        assert!(text.contains("\"layout\": \"mono_polar\""), "{text}");
        let (pairs, mut frames, mut pulses) = pairs_of(&out);
        frames.sort_unstable();
        pulses.sort_unstable();
        assert_eq!((frames.len(), pulses.len()), (10, 10));
        assert_eq!(pairs.len(), 10, "every frame paired at {interval_ms} ms");
        for (frame_id, seq, basis) in &pairs {
            let k = frames.iter().position(|f| f == frame_id).unwrap();
            assert_eq!(
                pulses[k], *seq,
                "frame {frame_id} (the {k}th) paired with pulse {seq}, not {} at {interval_ms} ms",
                pulses[k]
            );
            assert_eq!(basis.as_deref(), Some("camera_time"));
        }
    }
}

/// Waits until `dir/frames` holds at least `n` PNGs.
fn wait_for_frames(dir: &Path, n: usize, what: &str) {
    let frames = dir.join("frames");
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let count = std::fs::read_dir(&frames)
            .map(|d| {
                d.filter_map(Result::ok)
                    .filter(|e| e.path().extension().is_some_and(|x| x == "png"))
                    .count()
            })
            .unwrap_or(0);
        if count >= n {
            return;
        }
        assert!(Instant::now() < deadline, "{what}: no frames in time");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Every file under `dir` with its bytes (to prove nothing recorded changed).
fn snapshot(dir: &Path) -> Vec<(std::path::PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().filter_map(Result::ok) {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((p.clone(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn capture_refuses_an_out_that_holds_an_older_recording() {
    let tmp = tempfile::tempdir().unwrap();
    let old = tmp.path().join("old");
    let o = capture_cmd(&old, 3, 100).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    // the manifest lost (a crash before it was written, a user's `rm`), frames and log there
    std::fs::remove_file(old.join("manifest.json")).unwrap();
    let before = snapshot(&old);
    let o = capture_cmd(&old, 3, 100).output().unwrap();
    assert!(!o.status.success(), "captured over an older recording");
    let err = stderr(&o);
    assert!(
        err.contains("not empty") && err.contains(&old.display().to_string()),
        "{err}"
    );
    assert_eq!(snapshot(&old), before, "the older recording changed");
    // a file, and any other non-empty directory, are refused too
    let file = tmp.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    let o = capture_cmd(&file, 3, 100).output().unwrap();
    assert!(!o.status.success() && stderr(&o).contains("not a directory"));
    let other = tmp.path().join("other");
    std::fs::create_dir(&other).unwrap();
    std::fs::write(other.join("notes.txt"), b"mine").unwrap();
    let o = capture_cmd(&other, 3, 100).output().unwrap();
    assert!(!o.status.success() && stderr(&o).contains("not empty"));
    assert_eq!(std::fs::read(other.join("notes.txt")).unwrap(), b"mine");
    // an empty directory is fine
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let o = capture_cmd(&empty, 2, 100).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn sigint_and_sigterm_end_a_capture_cleanly() {
    let tmp = tempfile::tempdir().unwrap();
    // SIGHUP: the terminal closed (issue 46; main died without its end record)
    for (signal, name) in [
        (libc::SIGINT, "SIGINT"),
        (libc::SIGTERM, "SIGTERM"),
        (libc::SIGHUP, "SIGHUP"),
    ] {
        let out = tmp.path().join(name);
        let mut child = capture_cmd(&out, 200, 100)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        wait_for_frames(&out, 3, name);
        let pid = i32::try_from(child.id()).unwrap();
        // SAFETY: `pid` is our own child, alive (its stderr is still open); kill only signals it.
        assert_eq!(unsafe { libc::kill(pid, signal) }, 0);
        let deadline = Instant::now() + Duration::from_secs(60);
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            assert!(Instant::now() < deadline, "{name}: capture did not end");
            std::thread::sleep(Duration::from_millis(20));
        };
        let o = child.wait_with_output().unwrap();
        assert_eq!(status.code(), Some(128 + signal), "{name}: {}", stderr(&o));
        assert!(stderr(&o).contains("stopped by signal"), "{}", stderr(&o));
        let s = reader::open(&out).expect("session opens");
        assert!(s.report.ended_cleanly, "{name}: no end record");
        assert_eq!(s.report.summary(), "intact", "{name}");
        let end = s.manifest.end.as_ref().unwrap();
        assert_eq!(end.reason, "stopped by user", "{name}");
        assert!(
            s.events.iter().any(
                |e| matches!(e, SessionEvent::End { reason, .. } if reason == "stopped by user")
            )
        );
        let pulses = s
            .events
            .iter()
            .filter(|e| matches!(e, SessionEvent::Pulse { .. }))
            .count();
        assert!(pulses < 200, "{name}: the board was not stopped");
        // frames in flight were drained: every pulse's frame is on disk, logged and paired
        let paired = s.frames.iter().filter(|f| f.pulse_seq.is_some()).count();
        assert_eq!(
            (s.frames.len(), paired),
            (pulses, pulses),
            "{name}: frames in flight lost"
        );
        for f in &s.frames {
            s.load_frame(f).expect("every frame loads");
        }
    }
}

#[test]
fn a_killed_capture_leaves_no_end_key_at_all() {
    // docs/session-format.md: `end` is absent after a crash (it was written as `null`)
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("killed");
    let mut child = capture_cmd(&out, 200, 100)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    wait_for_frames(&out, 2, "kill");
    child.kill().unwrap();
    let _ = child.wait();
    let text = std::fs::read_to_string(out.join("manifest.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(v.get("end").is_none(), "{text}");
}

#[test]
fn numeric_flags_are_checked_against_the_files_limits() {
    let tmp = tempfile::tempdir().unwrap();
    let sphere = scene("sphere.toml");
    let sphere = sphere.to_str().unwrap();
    let out = tmp.path().join("o");
    let out = out.to_str().unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "sim", "render", sphere, "--out", out, "--width", "100000", "--height", "100000",
            ],
            "2..=16384",
        ),
        (
            vec!["sim", "render", sphere, "--out", out, "--frames", "0"],
            "1..=",
        ),
        (
            vec![
                "sim", "render", sphere, "--out", out, "--width", "321", "--height", "256",
            ],
            "odd",
        ),
        (
            vec![
                "sim",
                "render",
                sphere,
                "--out",
                out,
                "--supersampling",
                "9",
            ],
            "1..=8",
        ),
        (
            vec![
                "capture",
                "--sim",
                sphere,
                "--out",
                out,
                "--resolution",
                "100000x100000",
            ],
            "2..=16384",
        ),
        (
            vec!["capture", "--sim", sphere, "--out", out, "--photos", "0"],
            "1..=",
        ),
        (
            vec![
                "capture",
                "--sim",
                sphere,
                "--out",
                out,
                "--interval-ms",
                "0",
            ],
            "longer than 0",
        ),
        (
            vec![
                "capture",
                "--sim",
                sphere,
                "--out",
                out,
                "--interval-ms",
                "nan",
            ],
            "outside",
        ),
        (
            vec!["capture", "--sim", sphere, "--out", out, "--interval-ms=-5"],
            "outside",
        ),
        // shorter than the scene's 8 ms exposure: the board's own rule, before anything is recorded
        (
            vec![
                "capture",
                "--sim",
                sphere,
                "--out",
                out,
                "--interval-ms",
                "1",
            ],
            "would refuse",
        ),
        (
            vec!["fit", out, "--mesh", sphere, "--outer", "4294967295"],
            "1..=20",
        ),
        (vec!["fit", out, "--mesh", sphere, "--outer", "0"], "1..=20"),
        (vec!["bench", "pose", sphere, "--frames", "0"], "1..="),
        (
            vec!["model", "dop", "--eta", "1e78", "--theta-deg", "30"],
            "[1, 5]",
        ),
        (
            vec!["model", "fresnel", "--eta", "1e155", "--theta-deg", "30"],
            "[1, 5]",
        ),
        (
            vec!["polar", "x.png", "--out", out, "--dark-intensity", "nan"],
            "outside",
        ),
        (
            vec!["sim", "serve", sphere, "--pty", "--ber", "2"],
            "outside",
        ),
    ];
    for (args, needle) in cases {
        let started = Instant::now();
        let o = ellipso(&args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?} exited 0");
        assert!(
            o.status.code().is_some()
                && !err.contains("panicked")
                && !err.contains("memory allocation"),
            "{args:?} died: {err}"
        );
        assert!(err.contains(needle), "{args:?}: `{needle}` not in {err}");
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "{args:?} took long"
        );
    }
    assert!(
        !Path::new(out).exists(),
        "a refused command left output behind"
    );
}

#[test]
fn mesh_debug_pictures_never_go_into_the_session() {
    let tmp = tempfile::tempdir().unwrap();
    let session = tmp.path().join("session");
    std::fs::create_dir_all(&session).unwrap();
    let before = snapshot(&session);
    let inside = session.join("pictures");
    let o = ellipso(&[
        "mesh",
        session.to_str().unwrap(),
        "--out",
        tmp.path().join("mesh.ply").to_str().unwrap(),
        "--debug",
        inside.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("inside the session") && stderr(&o).contains("--debug"),
        "{}",
        stderr(&o)
    );
    assert!(!inside.exists(), "the refused folder was created");
    assert_eq!(snapshot(&session), before);
}

#[test]
fn model_on_absurd_input_says_the_range_and_never_prints_nan() {
    let base = [
        "model",
        "mueller",
        "--sigma-s",
        "0.2",
        "--sigma-ss",
        "0.5",
        "--rho-ss",
        "0.1,0.1,0.1",
        "--rho-d",
        "0.5,0.4,0.3",
        "--to-light",
        "0.1,0,1",
        "--to-camera",
        "-0.1,0,1",
        "--json",
    ];
    let run = |extra: &[&str]| {
        let mut args = base.to_vec();
        args.extend_from_slice(extra);
        ellipso(&args)
    };
    let o = run(&["--eta", "1e200", "--rho-s", "1", "--normal", "0,0,1"]);
    assert!(!o.status.success() && stderr(&o).contains("--eta must be in [1, 5]"));
    let o = run(&["--eta", "1.5", "--rho-s", "1e308", "--normal", "0,0,1"]);
    assert!(!o.status.success() && stderr(&o).contains("--rho-s must be in [0, 1000]"));
    // a valid direction of any length is a direction
    let o = run(&["--eta", "1.5", "--rho-s", "1", "--normal", "0,0,1e300"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(!text.contains("null") && !text.contains("NaN"), "{text}");
}

#[test]
fn boards_of_every_family_the_scenes_accept_are_tracked() {
    // tag16h5 and tag25h9 boards validated and rendered, but tracking only knew tag36h11: every
    // frame was rejected with "no tag of a known board detected"
    let tmp = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(scene("../boards/base_a4.toml")).unwrap();
    let sphere = std::fs::read_to_string(scene("sphere.toml")).unwrap();
    for family in ["tag25h9", "tag16h5"] {
        let board = tmp.path().join(format!("{family}.toml"));
        std::fs::write(
            &board,
            base.replace("\"tag36h11\"", &format!("\"{family}\"")),
        )
        .unwrap();
        let scene_file = tmp.path().join(format!("{family}-scene.toml"));
        std::fs::write(
            &scene_file,
            sphere.replace(
                "file = \"../boards/base_a4.toml\"",
                &format!("file = \"{}\"", board.display()),
            ),
        )
        .unwrap();
        let out = tmp.path().join(family);
        let o = Command::new(ellipso_bin())
            .args(["capture", "--sim"])
            .arg(&scene_file)
            .arg("--out")
            .arg(&out)
            .args([
                "--photos",
                "6",
                "--resolution",
                "612x512",
                "--supersampling",
                "1",
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{family}: {}", stderr(&o));
        let s = reader::open(&out).unwrap();
        let posed = s
            .events
            .iter()
            .filter(|e| matches!(e, SessionEvent::Pose { .. }))
            .count();
        assert!(posed >= 4, "{family}: only {posed} of 6 frames posed");
        assert_eq!(s.manifest.boards[0].family, family);
    }
}

/// Lines of the docs and README that show an `ellipso` command (continuation lines joined).
fn documented_commands() -> Vec<(String, String)> {
    let root = scene("..").join("..");
    let mut files: Vec<_> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    files.push(root.join("README.md"));
    let mut out = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let mut joined = String::new();
        for line in text.lines() {
            joined.push_str(line.trim_end_matches('\\'));
            if line.ends_with('\\') {
                joined.push(' ');
                continue;
            }
            let name = f.file_name().unwrap().to_string_lossy().into_owned();
            out.push((name, std::mem::take(&mut joined)));
        }
    }
    out
}

#[test]
fn every_flag_the_docs_show_exists() {
    // docs/fit.md showed `--no-augment`, which the CLI rejects
    const SUBCOMMANDS: [&str; 14] = [
        "board",
        "rig",
        "demo",
        "capture",
        "model",
        "polar",
        "calibrate",
        "fit",
        "bench",
        "devices",
        "replay",
        "sim",
        "mesh",
        "export",
    ];
    let mut help: std::collections::BTreeMap<String, String> = Default::default();
    let mut checked = 0;
    let mut missing = Vec::new();
    for (file, line) in documented_commands() {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        for (i, t) in tokens.iter().enumerate() {
            let t = t.trim_start_matches('`');
            let after_cargo = t == "--" && i > 0 && tokens[i - 1] == "--release";
            if t != "ellipso" && !after_cargo {
                continue;
            }
            let Some(sub) = tokens.get(i + 1).map(|s| s.trim_end_matches('`')) else {
                continue;
            };
            if !SUBCOMMANDS.contains(&sub) {
                continue;
            }
            let mut path = vec![sub];
            // `pose\|calibration` (a table's alternatives): the first one
            if let Some(next) = tokens
                .get(i + 2)
                .and_then(|s| s.trim_end_matches('`').split("\\|").next())
                && ["model", "sim", "bench", "export", "board", "rig"].contains(&sub)
                && next.chars().all(|c| c.is_ascii_lowercase())
            {
                path.push(next);
            }
            let key = path.join(" ");
            let text = help.entry(key.clone()).or_insert_with(|| {
                let mut args = path.clone();
                args.push("--help");
                let o = ellipso(&args);
                assert!(o.status.success(), "ellipso {key} --help failed ({file})");
                String::from_utf8_lossy(&o.stdout).into_owned()
            });
            // every --flag up to the next command on the line, comments included
            let end = tokens[i + 1..]
                .iter()
                .position(|t| t.trim_matches('`') == "ellipso")
                .map_or(tokens.len(), |k| i + 1 + k);
            for flag in tokens[i + 1..end].iter().filter_map(|t| {
                let t = t.trim_start_matches(['[', '(', '`']);
                let t = t.split(['=', ']', ')', ',', '`', '|']).next().unwrap_or("");
                (t.starts_with("--") && t.len() > 2).then_some(t)
            }) {
                checked += 1;
                if !text.contains(&format!("{flag} ")) && !text.contains(&format!("{flag}\n")) {
                    missing.push(format!("{file}: ellipso {key} {flag}"));
                }
            }
        }
    }
    assert!(checked > 20, "only {checked} documented flags found");
    assert!(
        missing.is_empty(),
        "documented flags the CLI rejects: {missing:#?}"
    );
}

/// Issue 46 item 1: frames 8 px tall or less crashed pose tracking (a segfault in the AprilTag
/// library) in `capture` and `replay`. Now each such frame is a pose rejection naming its size
/// (or, at the size limit, a search that finds nothing), and the session ends with its record.
#[test]
fn tiny_frames_are_rejected_by_the_tracker_not_crashed_on() {
    let tmp = tempfile::tempdir().unwrap();
    // Tags are searched on the full raw image (issue 42), so 64×8 is exactly at the size limit
    // (searched, nothing found) and 64×6 under it (refused by size); neither may crash.
    for (res, too_small) in [("2x2", true), ("64x6", true), ("64x8", false)] {
        let out = tmp.path().join(res);
        let o = Command::new(ellipso_bin())
            .args(["capture", "--sim"])
            .arg(scene("sphere.toml"))
            .arg("--out")
            .arg(&out)
            .args(["--photos", "2", "--resolution", res, "--supersampling", "1"])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{res}: {}", stderr(&o));
        let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), stderr(&o));
        let named = if too_small {
            "too small to hold a tag"
        } else {
            "no tag of a known board detected"
        };
        assert!(text.contains(named), "{res}: {text}");
        let s = reader::open(&out).expect("session opens");
        assert!(s.report.ended_cleanly, "{res}: no end record");
        let o = ellipso(&["replay", out.to_str().unwrap()]);
        assert_ne!(o.status.code(), None, "{res}: replay died by a signal");
    }
}
