//! `ellipso fit` and the sensor calibration, across processes, on a session recorded by
//! `ellipso capture --sim` and rewritten to look like one from the physical rig (source
//! `hardware`, relative radiometry, no recorded noise or extinction):
//!
//! - fitted without a calibration it prints a warning naming what it assumes (ideal analysers,
//!   the black level, the noise model's constants), never silently;
//! - `--sensor-calibration FILE` reads the frames with the file and says which one, and so does
//!   a calibration the session recorded, without the flag;
//! - a corrupt, truncated, foreign or newer file, one of another sensor size or layout, and a
//!   file that is no longer the one the session recorded each fail with one error naming it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use ellipso_model::mosaic::SensorLayout;
use ellipso_polar::sensor_calibration::{SensorCalibration, file};
use ellipso_polar::test_support::ideal_calibration;
use ellipso_session::manifest::SensorInfo;
use ellipso_tests::fit_fixture::sphere_mesh;
use ellipso_tests::{ellipso_bin, shipped_scene as scene};

fn write_calibration(mut cal: SensorCalibration, path: &Path) -> String {
    file::write(&mut cal, path).unwrap()
}

/// Records a small sphere session and rewrites its manifest as a hardware session's.
fn hardware_session(dir: &Path) -> (PathBuf, SensorInfo) {
    let session = dir.join("session");
    let o = Command::new(ellipso_bin())
        .args(["capture", "--interval-ms", "50", "--sim"])
        .arg(scene("sphere.toml"))
        .args(["--photos", "12", "--resolution", "612x512"])
        .args(["--supersampling", "1", "--out"])
        .arg(&session)
        .output()
        .unwrap();
    assert!(o.status.success(), "capture: {}", stderr(&o));
    let path = session.join("manifest.json");
    let mut m: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    m["source"] = serde_json::json!({
        "kind": "hardware",
        "trigger_port": "unix:/nonexistent",
        "camera": "aravis:127.0.0.1",
    });
    let rig = m["rig"].as_object_mut().unwrap();
    rig.insert("radiometry".into(), serde_json::json!({"kind": "relative"}));
    rig.remove("noise");
    rig.remove("analyser_extinction_ratio");
    std::fs::write(&path, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
    let sensor: SensorInfo = serde_json::from_value(m["sensor"].clone()).unwrap();
    (session, sensor)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn fit(session: &Path, mesh: &Path, out: &Path, extra: &[&std::ffi::OsStr]) -> Output {
    Command::new(ellipso_bin())
        .arg("fit")
        .arg(session)
        .arg("--mesh")
        .arg(mesh)
        .args(["--outer", "1", "--holdout", "0", "--out"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn a_hardware_session_says_what_it_assumes_and_bad_calibrations_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let (session, sensor) = hardware_session(tmp.path());
    let mesh = sphere_mesh(tmp.path());
    let (w, h, layout) = (sensor.width, sensor.height, sensor.layout);

    // no calibration: the fit runs, with a warning naming each assumption
    let o = fit(&session, &mesh, &tmp.path().join("fit-plain"), &[]);
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    let warning = e
        .lines()
        .find(|l| l.starts_with("warning:") && l.contains("without a sensor calibration"))
        .unwrap_or_else(|| panic!("no warning naming the assumed sensor:\n{e}"));
    for assumed in [
        "ideal analysers",
        "black level of 0 DN",
        "0.39 DN/e⁻",
        "0.9 DN",
    ] {
        assert!(warning.contains(assumed), "{assumed} not named: {warning}");
    }

    // a calibration of this sensor: used, named, no warning
    let good = tmp.path().join("good.senscal");
    let id = write_calibration(ideal_calibration(layout, w, h, 0.0), &good);
    let o = fit(
        &session,
        &mesh,
        &tmp.path().join("fit-cal"),
        &["--sensor-calibration".as_ref(), good.as_os_str()],
    );
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(e.contains(&format!("sensor calibration {id}")), "{e}");
    assert!(!e.contains("without a sensor calibration"), "{e}");

    // bad files, each refused by name before any work
    let bytes = std::fs::read(&good).unwrap();
    let bad = |name: &str, content: Vec<u8>| {
        let p = tmp.path().join(name);
        std::fs::write(&p, content).unwrap();
        p
    };
    let mut flipped = bytes.clone();
    let last = flipped.len() - 20;
    flipped[last] ^= 0x40;
    let version = {
        let text = String::from_utf8_lossy(&bytes[..400]).to_string();
        let at = text.find("\"version\":1").expect("version in the header") + 10;
        let mut b = bytes.clone();
        b[at] = b'7';
        b
    };
    let other_size = tmp.path().join("size.senscal");
    write_calibration(ideal_calibration(layout, w / 2, h, 0.0), &other_size);
    let other_layout = tmp.path().join("layout.senscal");
    let flip = match layout {
        SensorLayout::MonoPolar => SensorLayout::ColourPolar,
        SensorLayout::ColourPolar => SensorLayout::MonoPolar,
    };
    write_calibration(ideal_calibration(flip, w, h, 0.0), &other_layout);
    let cases: Vec<(PathBuf, String)> = vec![
        (bad("flipped.senscal", flipped), "checksum".into()),
        (
            bad("short.senscal", bytes[..bytes.len() / 2].to_vec()),
            "corrupt".into(),
        ),
        (
            bad("text.senscal", b"not a calibration at all".to_vec()),
            "not an ellipso sensor calibration".into(),
        ),
        (bad("newer.senscal", version), "version 7".into()),
        (
            other_size,
            format!("{}×{h} sensor, the frame is {w}×{h}", w / 2),
        ),
        (other_layout, "sensor, the frame is".into()),
    ];
    for (i, (path, want)) in cases.iter().enumerate() {
        let o = fit(
            &session,
            &mesh,
            &tmp.path().join(format!("fit-bad-{i}")),
            &["--sensor-calibration".as_ref(), path.as_os_str()],
        );
        let e = stderr(&o);
        assert!(!o.status.success(), "{}: accepted", path.display());
        assert!(e.contains(want.as_str()), "{}: {e}", path.display());
        let name = path.file_name().unwrap().to_string_lossy();
        assert!(
            e.contains(name.as_ref()) || e.contains("sensor calibration"),
            "{name} not named: {e}"
        );
    }

    // the session records the good file's identity (as `capture` writes it from the rig file);
    // the file is then replaced by another calibration: stale, by name, with or without
    // --sensor-calibration
    let manifest = session.join("manifest.json");
    let mut m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    m["rig"]["sensor_calibration"] = serde_json::json!({"id": id, "file": good});
    std::fs::write(&manifest, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
    // recorded: used without the flag
    let o = fit(&session, &mesh, &tmp.path().join("fit-recorded"), &[]);
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(e.contains(&format!("sensor calibration {id}")), "{e}");
    assert!(!e.contains("without a sensor calibration"), "{e}");
    let replaced = tmp.path().join("replaced.senscal");
    write_calibration(ideal_calibration(layout, w, h, 1.0), &replaced);
    std::fs::copy(&replaced, &good).unwrap();
    for extra in [
        vec![],
        vec!["--sensor-calibration".as_ref(), replaced.as_os_str()],
    ] {
        let o = fit(&session, &mesh, &tmp.path().join("fit-stale"), &extra);
        let e = stderr(&o);
        assert!(!o.status.success(), "a replaced calibration was accepted");
        assert!(
            e.contains(&format!(
                "is not the one the rig file or session names ({id})"
            )),
            "{e}"
        );
    }
}
