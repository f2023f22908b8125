//! `ellipso calibrate --sphere` keeps what it determined: on a session whose board views
//! calibrate the camera but whose frames do not measure the flash (here the calibration scene's
//! board photos, no sphere in them: no highlight is found, as on photos where the sphere is not
//! where `--sphere` says or an orbit whose highlights reflect one ray) the `[camera]` section is
//! still written, and the command fails naming why and the photos to take. `ellipso calibrate
//! flash` on the same session writes nothing: the rig file it was to put `[flash]` into is left
//! as it was, and a rig file that is not TOML is refused before any work.

use std::process::Command;

use ellipso_tests::{ellipso_bin, shipped_scene as scene};

#[test]
fn a_failed_flash_part_keeps_the_camera_and_names_the_photos() {
    let tmp = tempfile::tempdir().unwrap();
    let session = tmp.path().join("scan");
    let o = Command::new(ellipso_bin())
        .args(["capture", "--interval-ms", "50", "--sim"])
        .arg(scene("calibration.toml"))
        .args(["--resolution", "1224x1024"])
        .args(["--supersampling", "1", "--out"])
        .arg(&session)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "capture: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let out = tmp.path().join("camera.toml");
    // a sphere of 4 cm on the board's origin: not in these photos
    let o = Command::new(ellipso_bin())
        .arg("calibrate")
        .arg(&session)
        .args(["--sphere", "0.04,0,0,0.04", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(
        !o.status.success(),
        "a flash was measured without a sphere:\n{stdout}"
    );
    for named in [
        "flash (position and polariser angle) was not measured",
        "[camera] section is written",
        "near each corner",
        "two distances",
        "--sphere R,X,Y,Z",
    ] {
        assert!(stderr.contains(named), "`{named}` not said:\n{stderr}");
    }
    let text = std::fs::read_to_string(&out).expect("the camera section is kept");
    assert!(text.contains("[camera]") && text.contains("fx ="), "{text}");
    assert!(!text.contains("[flash]"), "{text}");
    assert!(stdout.contains("written to"), "{stdout}");

    // `calibrate flash` into a rig file: not measured → the file is untouched
    let rig = tmp.path().join("rig.toml");
    let mine = "# my rig\n[sensor]\nbit_depth = 12\n";
    std::fs::write(&rig, mine).unwrap();
    let o = Command::new(ellipso_bin())
        .args(["calibrate", "flash"])
        .arg(&session)
        .args(["--sphere", "0.04,0,0,0.04", "--out"])
        .arg(&rig)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "a flash was measured without a sphere");
    for named in [
        "was not measured",
        "nothing is written",
        "calibrate flash SESSION",
    ] {
        assert!(stderr.contains(named), "`{named}` not said:\n{stderr}");
    }
    assert_eq!(std::fs::read_to_string(&rig).unwrap(), mine);
    // a rig file that is not TOML: refused, untouched
    std::fs::write(&rig, "[sensor\n").unwrap();
    let o = Command::new(ellipso_bin())
        .args(["calibrate", "flash"])
        .arg(&session)
        .args(["--sphere", "0.04,0,0,0.04", "--out"])
        .arg(&rig)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && stderr.contains("not TOML"),
        "{stderr}"
    );
    assert_eq!(std::fs::read_to_string(&rig).unwrap(), "[sensor\n");
}
