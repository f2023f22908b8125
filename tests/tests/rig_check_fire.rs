//! `ellipso rig check RIG.toml --fire N` end to end, across processes: `ellipso sim serve --pty
//! --wire` is the trigger board the rig file names, and `--sim-camera SCENE` puts the simulated
//! camera on its trigger wire in place of the rig file's camera. The check fires through the
//! capture `ellipso capture --rig` runs, into a temporary session it removes, and reports per
//! flash its frame, the flash timing, the black level and saturation, then what to fix.
//! Also: the bad inputs (`--fire 0`, an absurd N, a trigger port that does not exist).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

use ellipso_tests::{ellipso_bin, shipped_scene};

/// Kills the child on drop (tests must not leave servers behind).
struct Guard(Child);

impl Drop for Guard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `ellipso sim serve SCENE --pty --wire WIRE`; returns it with its pty path.
fn serve(scene: &Path, wire: &Path) -> (Guard, String) {
    let mut child = Command::new(ellipso_bin())
        .args(["sim", "serve"])
        .arg(scene)
        .args(["--pty", "--wire"])
        .arg(wire)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn ellipso sim serve");
    let stdout = child.stdout.take().expect("stdout");
    let mut lines = BufReader::new(stdout).lines();
    let first = lines.next().expect("a first line").expect("utf-8");
    let pty = first
        .strip_prefix("pty: ")
        .unwrap_or_else(|| panic!("first line names the pty: {first}"))
        .trim()
        .to_string();
    std::thread::spawn(move || for _ in lines {});
    (Guard(child), pty)
}

/// The sphere scene in `dir` with a 64 DN black level and the flash's radiant intensity
/// `flash_w_per_sr` (board paths made absolute so the copy loads from anywhere).
fn scene(dir: &Path, name: &str, flash_w_per_sr: f64) -> PathBuf {
    let boards = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/boards");
    let text = std::fs::read_to_string(shipped_scene("sphere.toml"))
        .unwrap()
        .replace("\"../boards/", &format!("\"{}/", boards.display()));
    assert!(
        text.trim_end()
            .ends_with("polariser_extinction = { ratio = 300.0 }"),
        "[effects] ends the scene"
    );
    let needle = "radiant_intensity_w_per_sr = 0.5";
    assert!(text.contains(needle), "the scene's flash intensity");
    let text = text.replace(
        needle,
        &format!("radiant_intensity_w_per_sr = {flash_w_per_sr:?}"),
    );
    let path = dir.join(name);
    std::fs::write(
        &path,
        format!("{text}black_level = {{ dn = 64.0, dsnu_dn = 1.0 }}\n"),
    )
    .unwrap();
    path
}

/// A rig file on trigger port `port`: 8 ms exposure, the flash 100 µs after its start for 2 ms,
/// one photo per 200 ms.
fn rig(dir: &Path, port: &str) -> PathBuf {
    rig_with_gain(dir, "rig.toml", port, 0.0)
}

/// [`rig`] with the sensor's analogue gain `gain_db`.
fn rig_with_gain(dir: &Path, name: &str, port: &str, gain_db: f64) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(
        &path,
        format!(
            "[trigger]\nport = \"{port}\"\n\n[sensor]\nbackend = \"aravis\"\naddress = \
             \"127.0.0.1\"\nlayout = \"monopolar\"\nbit_depth = 12\nexposure_us = 8000\n\
             gain_db = {gain_db:?}\n\n\
             [capture]\nphotos = 150\ninterval_ms = 200.0\nflash_delay_us = 100\n\
             flash_duration_us = 2000\n"
        ),
    )
    .unwrap();
    path
}

fn check(rig: &Path, extra: &[&str]) -> Output {
    Command::new(ellipso_bin())
        .args(["rig", "check"])
        .arg(rig)
        .args(extra)
        .output()
        .expect("run ellipso rig check")
}

/// The `flash …` lines of a report.
fn flash_lines(text: &str) -> Vec<&str> {
    text.lines()
        .map(str::trim)
        .filter(|l| l.starts_with("flash "))
        .collect()
}

/// Temporary sessions the check left behind (it must leave none).
fn leftovers() -> Vec<PathBuf> {
    std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("ellipso-rig-check-"))
        })
        .collect()
}

/// A well-set simulated rig: every flash pairs, lands inside the exposure (the simulated
/// camera starts exposing 6 µs after the trigger edge), reads the scene's 64 DN black level
/// (61: its 1st percentile under the read and shot noise) and clips nothing; the check passes.
/// Then the same rig with a flash 1000× brighter: the frames saturate, the check names the fix
/// and fails.
#[test]
fn rig_check_fires_through_the_capture_and_reports_pairing_timing_and_levels() {
    let tmp = tempfile::tempdir().unwrap();
    let before = leftovers();
    let good = scene(tmp.path(), "good.toml", 0.5);
    let wire = tmp.path().join("w.sock");
    let (_server, pty) = serve(&good, &wire);
    let rig = rig(tmp.path(), &pty);
    let sim = |scene: &Path| {
        vec![
            "--fire".to_string(),
            "3".into(),
            "--sim-camera".into(),
            scene.display().to_string(),
            "--wire".into(),
            wire.display().to_string(),
            "--resolution".into(),
            "64x64".into(),
        ]
    };
    let args = sim(&good);
    let o = check(&rig, &args.iter().map(String::as_str).collect::<Vec<_>>());
    let text = String::from_utf8_lossy(&o.stdout).to_string();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{text}\n{err}");
    assert!(
        text.contains("flashes: 3 of 3 paired with a frame"),
        "{text}"
    );
    let lines = flash_lines(&text);
    assert_eq!(lines.len(), 3, "{text}");
    for l in &lines {
        assert!(
            l.contains("flash on +100…+2100 µs after the trigger"),
            "{l}"
        );
        assert!(l.contains("flash inside the exposure"), "{l}");
        assert!(l.contains("for 8000 µs"), "{l}");
        // the exposure start is measured: 6 µs after the edge, within its stated uncertainty
        let start = l.split("exposure ").nth(1).expect("exposure start");
        let (d, rest) = start.split_once(" ± ").expect("± uncertainty");
        let u: f64 = rest.split_whitespace().next().unwrap().parse().unwrap();
        let d: f64 = d.parse().unwrap();
        assert!((d - 6.0).abs() <= u + 1.0, "{d} ± {u}: {l}");
        let black: u32 = l
            .split("black level ")
            .nth(1)
            .and_then(|s| s.split_whitespace().next())
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("black level: {l}"));
        assert!((50..=70).contains(&black), "the scene's 64 DN: {l}");
        assert!(l.contains("0.00 % of pixels at full scale"), "{l}");
    }
    assert!(!text.contains("fix before capturing"), "{text}");
    assert_eq!(leftovers(), before, "the temporary session is removed");

    // without --fire: nothing fired, and it says so
    let o = check(&rig, &[]);
    let text = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(o.status.success(), "{text}");
    assert!(text.contains("flashes: none fired"), "{text}");
    assert!(flash_lines(&text).is_empty(), "{text}");
    // --fire with the rig file's own camera, which is not there: a clear error, not a report
    let o = check(&rig, &["--fire", "2"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    let last = err.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("error: ") && last.contains("firing test flashes"),
        "{err}"
    );
    assert!(err.contains("aravis") || err.contains("camera"), "{err}");
    assert_eq!(
        leftovers(),
        before,
        "no session left by a camera that did not open"
    );

    let hot = scene(tmp.path(), "hot.toml", 500.0);
    let args = sim(&hot);
    let o = check(&rig, &args.iter().map(String::as_str).collect::<Vec<_>>());
    let text = String::from_utf8_lossy(&o.stdout).to_string();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success(),
        "saturated frames fail the check: {text}"
    );
    assert!(
        text.contains("flashes: 3 of 3 paired with a frame"),
        "{text}"
    );
    assert!(
        text.contains("3 of 3 frames saturated") && text.contains("lower sensor.gain_db"),
        "{text}"
    );
    assert!(
        err.lines()
            .last()
            .is_some_and(|l| l.starts_with("error: ") && l.contains("1 problem")),
        "{err}"
    );
    assert_eq!(leftovers(), before, "removed after a failed check too");

    // the well-lit scene through a rig file that sets 40 dB of gain (100×): the stand-in camera
    // amplifies by the rig file's gain, as the real one would, so the frames clip; the scene's
    // own gain (0 dB) no longer decides (before, the check passed whatever the rig file said)
    let loud = rig_with_gain(tmp.path(), "loud.toml", &pty, 40.0);
    let args = sim(&good);
    let o = check(&loud, &args.iter().map(String::as_str).collect::<Vec<_>>());
    let text = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(!o.status.success(), "40 dB clips the frames: {text}");
    assert!(
        text.contains("3 of 3 frames saturated") && text.contains("lower sensor.gain_db"),
        "{text}"
    );
    // a gain the simulated camera does not have is refused by its key
    let absurd = rig_with_gain(tmp.path(), "absurd.toml", &pty, 55.0);
    let o = check(
        &absurd,
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("sensor.gain_db = 55 dB"), "{err}");
    assert_eq!(leftovers(), before, "removed after a refused camera too");
}

/// `--fire 0`, an absurd count and a port that does not exist are refused, each by name.
#[test]
fn rig_check_fire_refuses_bad_counts_and_a_missing_port() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig(tmp.path(), "/dev/ellipso-no-such-port");
    for n in ["0", "51", "1000000", "x"] {
        let o = check(&rig, &["--fire", n]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "--fire {n}");
        assert!(err.contains("--fire"), "names the flag: {err}");
        assert!(
            err.contains("1 to 50") || err.contains("whole number"),
            "says what is allowed: {err}"
        );
    }
    let o = check(&rig, &["--fire", "3"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("trigger.port") && err.contains("/dev/ellipso-no-such-port"),
        "names the port: {err}"
    );
    // --sim-camera only makes sense with --fire and its wire
    let o = check(&rig, &["--sim-camera", "x.toml"]);
    assert!(!o.status.success());
}
