//! The `ellipso` binary end to end, across processes:
//! - `ellipso sim serve --pty` (the virtual trigger board on a pseudo-terminal) driven by
//!   `ellipso capture --trigger PTY --wire SOCKET` (the host's real serial code), with link bit
//!   errors swept over BER 0, 1e-5, 1e-4, 1e-3;
//! - SIGKILL of a capture mid-recording, then `ellipso replay` on the partial session;
//! - `ellipso demo --quick` as a user's first impression.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use ellipso_session::events::SessionEvent;
use ellipso_session::reader;
use ellipso_tests::{ellipso_bin, shipped_scene as scene};

/// Kills the child on drop (tests must not leave servers behind).
struct Guard(Child);

impl Drop for Guard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `ellipso sim serve` and returns it with its pty path.
fn serve(scene: &Path, wire: &Path, ber: f64) -> (Guard, String) {
    let mut child = Command::new(ellipso_bin())
        .args(["sim", "serve"])
        .arg(scene)
        .arg("--pty")
        .arg("--wire")
        .arg(wire)
        .args(["--ber", &ber.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("spawn ellipso sim serve");
    let stdout = child.stdout.take().expect("stdout");
    let mut lines = BufReader::new(stdout).lines();
    let first = lines.next().expect("a first line").expect("utf-8");
    let pty = first
        .strip_prefix("pty: ")
        .unwrap_or_else(|| panic!("first line names the pty: {first}"));
    let pty = pty.trim().to_string();
    // keep draining stdout so the server never blocks on a full pipe
    std::thread::spawn(move || for _ in lines {});
    (Guard(child), pty)
}

fn capture_args(out: &Path, photos: u32) -> Vec<String> {
    vec![
        "capture".into(),
        "--sim".into(),
        scene("sphere.toml").display().to_string(),
        "--out".into(),
        out.display().to_string(),
        "--photos".into(),
        photos.to_string(),
        "--resolution".into(),
        "96x80".into(),
        "--supersampling".into(),
        "1".into(),
        "--interval-ms".into(),
        "100".into(),
        "--no-track".into(),
    ]
}

struct Counts {
    /// Pulse events that break the board's own timing (flash 100 µs after the trigger, on for
    /// the configured duration, sequence numbers rising): what a corrupted message that slipped
    /// through would look like.
    implausible_pulses: usize,
    frames: usize,
    pulses: usize,
    paired: usize,
    pairing_errors: usize,
    bad_frames: u64,
    ended: Option<String>,
}

fn counts(dir: &Path) -> Counts {
    let s = reader::open(dir).expect("session opens");
    let mut c = Counts {
        implausible_pulses: 0,
        frames: s.frames.len(),
        pulses: 0,
        paired: 0,
        pairing_errors: 0,
        bad_frames: 0,
        ended: None,
    };
    let mut last_seq: Option<u64> = None;
    for e in &s.events {
        match e {
            SessionEvent::Pulse {
                seq,
                t_trigger_device_us,
                t_flash_on_device_us,
                t_flash_off_device_us,
                ..
            } => {
                c.pulses += 1;
                let delay = t_flash_on_device_us.0.wrapping_sub(t_trigger_device_us.0);
                let on = t_flash_off_device_us.0.wrapping_sub(t_flash_on_device_us.0);
                let rising = last_seq.is_none_or(|l| *seq > l);
                if delay != 100 || on != 5_000 || !rising {
                    c.implausible_pulses += 1;
                }
                last_seq = Some(*seq);
            }
            SessionEvent::Pairing { .. } => c.paired += 1,
            SessionEvent::PairingError { .. } => c.pairing_errors += 1,
            SessionEvent::Link { counters, .. } => c.bad_frames = counters.bad_frames(),
            SessionEvent::End { reason, .. } => c.ended = Some(reason.clone()),
            _ => {}
        }
    }
    c
}

#[test]
fn capture_over_sim_serve_pty_with_bit_errors() {
    let tmp = tempfile::tempdir().unwrap();
    println!(
        "| BER | pulses | frames | paired | pairing errors | bad frames dropped | corrupt accepted |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (i, ber) in [0.0, 1e-5, 1e-4, 1e-3].into_iter().enumerate() {
        let wire = tmp.path().join(format!("w{i}.sock"));
        let (_server, pty) = serve(&scene("sphere.toml"), &wire, ber);
        let out = tmp.path().join(format!("s{i}"));
        let status = Command::new(ellipso_bin())
            .args(capture_args(&out, 12))
            .arg("--trigger")
            .arg(&pty)
            .arg("--wire")
            .arg(&wire)
            .status()
            .expect("spawn ellipso capture");
        assert!(status.success(), "capture at BER {ber} failed: {status}");
        let c = counts(&out);
        println!(
            "| {ber:e} | {} | {} | {} | {} | {} | {} |",
            c.pulses, c.frames, c.paired, c.pairing_errors, c.bad_frames, c.implausible_pulses
        );
        assert_eq!(
            c.implausible_pulses, 0,
            "a corrupted pulse event was accepted at BER {ber}"
        );
        assert_eq!(c.ended.as_deref(), Some("completed"), "BER {ber}");
        assert_eq!(
            c.frames, 12,
            "every exposure delivered a frame at BER {ber}"
        );
        assert!(
            c.paired + c.pairing_errors >= c.frames,
            "every frame accounted for at BER {ber}"
        );
        if ber == 0.0 {
            assert_eq!((c.pulses, c.paired, c.bad_frames), (12, 12, 0));
        }
    }
}

#[test]
fn sigkill_mid_recording_leaves_a_replayable_session() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("killed");
    let mut child = Command::new(ellipso_bin())
        .args(capture_args(&out, 200))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn ellipso capture");
    let frames = out.join("frames");
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let n = std::fs::read_dir(&frames)
            .map(|d| {
                d.filter_map(Result::ok)
                    .filter(|e| e.path().extension().is_some_and(|x| x == "png"))
                    .count()
            })
            .unwrap_or(0);
        if n >= 5 {
            break;
        }
        assert!(Instant::now() < deadline, "capture wrote no frames in time");
        std::thread::sleep(Duration::from_millis(20));
    }
    // SIGKILL: no chance to finish anything
    child.kill().expect("kill");
    let _ = child.wait();
    let s = reader::open(&out).expect("a killed session still opens");
    assert!(!s.report.ended_cleanly);
    assert!(s.frames.len() >= 5);
    for f in &s.frames {
        s.load_frame(f)
            .unwrap_or_else(|e| panic!("frame {} unreadable after SIGKILL: {e}", f.frame_id));
    }
    let replay = Command::new(ellipso_bin())
        .arg("replay")
        .arg(&out)
        .output()
        .expect("spawn ellipso replay");
    let text = String::from_utf8_lossy(&replay.stdout);
    assert!(
        replay.status.success(),
        "replay failed: {}",
        String::from_utf8_lossy(&replay.stderr)
    );
    assert!(text.contains("did not end cleanly"), "{text}");
    // replaying twice gives identical results
    let first = std::fs::read(out.join("replay").join("replay.json")).unwrap();
    let again = Command::new(ellipso_bin())
        .arg("replay")
        .arg(&out)
        .status()
        .unwrap();
    assert!(again.success());
    assert_eq!(
        first,
        std::fs::read(out.join("replay").join("replay.json")).unwrap()
    );
}

#[test]
fn demo_quick_runs_and_says_where_its_results_are() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("demo");
    let o = Command::new(ellipso_bin())
        .args(["demo", "--quick", "--out"])
        .arg(&out)
        .output()
        .expect("spawn demo");
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "demo failed: {}\n{text}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(text.contains("results in"), "{text}");
    assert!(out.join("pictures").join("camera-path.png").is_file());
    // the real workflow: the mesh is carved from the frames, and compared with the truth only
    // after the fit
    assert!(out.join("fit").join("mesh.ply").is_file());
    assert!(out.join("fit").join("mesh-report.json").is_file());
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let fit = &summary["fit"];
    assert!(
        fit["input_mesh"]
            .as_str()
            .is_some_and(|p| p.ends_with("mesh.ply")),
        "{fit}"
    );
    for key in ["mesh_before_fit", "mesh_after_fit"] {
        let chamfer = fit[key]["chamfer_m"].as_f64().unwrap_or(f64::NAN);
        // a carved mesh is never exact, and never far off the 40 mm sphere (quarter resolution,
        // 24 photos: a few millimetres)
        assert!(chamfer > 0.0 && chamfer < 0.02, "{key}: {fit}");
    }
}

/// The sphere scene with its link dropping for good at pulse `at_frame`, in a temp dir (board
/// file paths made absolute so the copy loads from anywhere).
fn disconnecting_scene(dir: &Path, at_frame: u32) -> PathBuf {
    let boards = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("sim")
        .join("boards");
    let text = std::fs::read_to_string(scene("sphere.toml"))
        .unwrap()
        .replace("\"../boards/", &format!("\"{}/", boards.display()));
    assert!(
        text.trim_end()
            .ends_with("polariser_extinction = { ratio = 300.0 }"),
        "[effects] ends the scene"
    );
    let path = dir.join("disconnecting.toml");
    std::fs::write(
        &path,
        format!("{text}link_disconnect = {{ at_frame = {at_frame} }}\n"),
    )
    .unwrap();
    path
}

#[test]
fn a_disconnect_mid_capture_ends_it_cleanly_and_keeps_what_was_recorded() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = disconnecting_scene(tmp.path(), 6);
    let wire = tmp.path().join("w.sock");
    let (_server, pty) = serve(&scene, &wire, 0.0);
    let out = tmp.path().join("s");
    let mut args = capture_args(&out, 12);
    args[2] = scene.display().to_string();
    let status = Command::new(ellipso_bin())
        .args(args)
        .arg("--trigger")
        .arg(&pty)
        .arg("--wire")
        .arg(&wire)
        .status()
        .expect("spawn ellipso capture");
    assert!(
        status.success(),
        "a disconnect is not a failure of the capture: {status}"
    );
    let c = counts(&out);
    let ended = c.ended.clone().unwrap_or_default();
    assert!(
        ended.contains("disconnected"),
        "the session says what happened: {ended}"
    );
    assert_eq!(c.implausible_pulses, 0);
    assert_eq!(c.pulses, 6, "pulses before the disconnect are all recorded");
    let s = reader::open(&out).unwrap();
    assert!(
        s.report.ended_cleanly,
        "the capture still ended cleanly: {}",
        s.report.summary()
    );
    for f in &s.frames {
        s.load_frame(f).unwrap();
    }
    assert!(
        c.paired >= 5,
        "frames before the disconnect stay paired ({} paired)",
        c.paired
    );
}

/// `capture --rig` with a camera that is not there: one clear error line naming the camera (or
/// the missing backend feature), and no session left behind.
#[test]
fn capture_from_a_rig_file_without_its_camera_fails_with_one_clear_line() {
    let tmp = tempfile::tempdir().unwrap();
    let board = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/boards/base_a4.toml");
    let rig = tmp.path().join("rig.toml");
    std::fs::write(
        &rig,
        format!(
            "[trigger]\nport = \"/dev/null-no-such-board\"\n\n[sensor]\nbackend = \"aravis\"\naddress = \"127.0.0.1\"\n\
             layout = \"monopolar\"\nbit_depth = 12\nexposure_us = 8000\n\n[camera]\nwidth = 2448\nheight = 2048\n\
             fx = 3500.0\nfy = 3500.0\ncx = 1223.5\ncy = 1023.5\nk1 = 0.0\nk2 = 0.0\nk3 = 0.0\np1 = 0.0\np2 = 0.0\n\n\
             [capture]\nphotos = 10\ninterval_ms = 500.0\nflash_duration_us = 2000\n\n[[boards]]\nfile = \"{}\"\n",
            board.display()
        ),
    )
    .unwrap();
    let out = tmp.path().join("s");
    let o = Command::new(ellipso_bin())
        .args(["capture", "--rig"])
        .arg(&rig)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("spawn ellipso capture");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    let line = err.lines().last().unwrap_or_default();
    assert!(line.starts_with("error: "), "{err}");
    assert!(
        line.contains("camera") || line.contains("aravis"),
        "names the camera: {line}"
    );
    assert!(
        !out.join("manifest.json").exists(),
        "no session is created when the rig cannot start"
    );
}

/// Mean raw DN of a recorded frame.
fn mean_dn(s: &reader::Session, f: &reader::FrameEntry) -> f64 {
    let (_, _, px) = s.load_frame(f).expect("frame loads");
    px.iter().map(|&v| f64::from(v)).sum::<f64>() / px.len() as f64
}

/// `ellipso sim serve` in one process, `ellipso capture --bracket` in another: the bracket goes to
/// the board over the pty, the flash's light comes back over the wire socket, and the capture
/// process renders each frame at the energy its exposure collected. Every frame's recorded step
/// and energy follow its pulse, and its brightness follows its energy.
#[test]
fn bracketed_capture_across_processes_renders_each_step_at_its_energy() {
    let tmp = tempfile::tempdir().unwrap();
    let wire = tmp.path().join("w.sock");
    let (_server, pty) = serve(&scene("sphere.toml"), &wire, 0.0);
    let out = tmp.path().join("s");
    let status = Command::new(ellipso_bin())
        .args(capture_args(&out, 9))
        .args(["--bracket", "1,0.25,0.0625", "--trigger", &pty, "--wire"])
        .arg(&wire)
        .status()
        .expect("spawn ellipso capture");
    assert!(status.success(), "capture failed: {status}");
    let s = reader::open(&out).expect("session opens");
    assert_eq!(s.frames.len(), 9);
    let mut means = [Vec::new(), Vec::new(), Vec::new()];
    for f in &s.frames {
        let seq = f.pulse_seq.expect("paired");
        let step = usize::from(f.bracket_step);
        assert_eq!(step as u64, seq % 3, "frame {}", f.frame_id);
        // 5 ms full pulse: 5000, 1250 and 313 µs.
        assert_eq!(f.flash_on_us, Some([5_000, 1_250, 313][step]));
        assert_eq!(f.flash_energy_rel, [1.0, 0.25, 0.0626][step]);
        means[step].push(mean_dn(&s, f));
    }
    // Neighbouring orbit poses see nearly the same scene: the brightness ratio is the energy's.
    for (step, (lo, hi)) in [(1, (0.2, 0.3)), (2, (0.045, 0.085))] {
        for (full, short) in means[0].iter().zip(&means[step]) {
            let ratio = short / full;
            assert!(
                (lo..hi).contains(&ratio),
                "step {step}: mean {short:.1} DN vs {full:.1} DN at full energy ({ratio:.3})"
            );
        }
    }
}

/// A shipped bracket scene brackets by itself (no `--bracket`), in process, and refuses a bad
/// `--bracket` with one line naming the step.
#[test]
fn the_bracket_scene_brackets_by_default_and_a_bad_bracket_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let mut args = capture_args(&out, 6);
    args[2] = scene("multi_material_bracket.toml").display().to_string();
    let status = Command::new(ellipso_bin())
        .args(&args)
        .status()
        .expect("spawn ellipso capture");
    assert!(status.success(), "capture failed: {status}");
    let s = reader::open(&out).expect("session opens");
    let steps: Vec<(u64, u8)> = s
        .frames
        .iter()
        .filter_map(|f| f.pulse_seq.map(|seq| (seq, f.bracket_step)))
        .collect();
    assert!(steps.len() >= 5, "{steps:?}");
    assert!(steps.iter().all(|&(seq, step)| u64::from(step) == seq % 3));

    let bad = Command::new(ellipso_bin())
        .args(capture_args(&tmp.path().join("bad"), 3))
        .args(["--bracket", "1,0.25,0"])
        .output()
        .expect("spawn ellipso capture");
    assert!(!bad.status.success());
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(
        stderr.contains("--bracket") && stderr.contains("step 2 is 0"),
        "{stderr}"
    );
    assert!(
        !tmp.path().join("bad").exists(),
        "nothing created for a refused argument"
    );
}
