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

use ellipso_host::session::events::SessionEvent;
use ellipso_host::session::reader;
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

/// (frame id, seq) of every pairing, and the frame ids and pulse seqs of the session.
fn pairs_of(dir: &Path) -> (Vec<(u64, u64, Option<String>)>, Vec<u64>, Vec<u64>) {
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
