//! `ellipso capture --sim` across processes: every frame paired with its own pulse at 20 fps, an
//! `--out` holding anything refused, SIGINT / SIGTERM / SIGHUP ending a capture cleanly, and a
//! killed capture leaving no `end` key.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use ellipso_session::events::SessionEvent;
use ellipso_session::reader;
use ellipso_tests::{ellipso_bin, shipped_scene as scene};

use super::{snapshot, stderr};

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
