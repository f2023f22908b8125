//! The rig file's loader: good files load, bad values are refused by key.

use super::*;

fn write(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("rig.toml");
    std::fs::write(&p, text).unwrap();
    p
}

fn good() -> String {
    let board = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../sim/boards/base_a4.toml");
    format!(
        r#"
[trigger]
port = "/dev/ttyACM0"

[sensor]
backend = "aravis"
address = "192.168.10.2"
layout = "monopolar"
bit_depth = 12
exposure_us = 8000

[camera]
width = 2448
height = 2048
fx = 3500.0
fy = 3500.0
cx = 1223.5
cy = 1023.5
k1 = 0.0
k2 = 0.0
k3 = 0.0
p1 = 0.0
p2 = 0.0

[capture]
photos = 150
interval_ms = 500.0
flash_duration_us = 2000

[[boards]]
file = "{}"
"#,
        board.display()
    )
}

#[test]
fn a_good_rig_file_loads_with_its_board() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = RigFile::load(&write(tmp.path(), &good())).unwrap();
    assert_eq!(rig.board_config().frame_period_us, 500_000);
    assert_eq!(rig.board_config().pulses, PulseCount::Count(150));
    let boards = rig.boards().unwrap();
    assert_eq!(boards.len(), 1);
    assert!(!boards[0].corners_board_m.is_empty());
}

#[test]
fn the_flash_section_calibrate_writes_loads_back() {
    let estimate = ellipso_vision::calibrate::flash::FlashEstimate {
        flash_camera_m: nalgebra::Point3::new(0.000_1, -0.030_2, 0.001_7),
        covariance_m2: nalgebra::Matrix3::identity() * 1e-8,
        std_m: [1e-4; 3],
        ray_angle_residuals_rad: vec![1e-3; 12],
        rms_angle_rad: 1e-3,
    };
    let tmp = tempfile::tempdir().unwrap();
    let text = format!("{}\n{}", good(), estimate.to_toml_flash_section());
    let rig = RigFile::load(&write(tmp.path(), &text)).unwrap();
    assert_eq!(
        rig.flash.map(|f| f.offset_m),
        Some([0.000_1, -0.030_2, 0.001_7])
    );
    assert!(
        RigFile::load(&write(tmp.path(), &good()))
            .unwrap()
            .flash
            .is_none()
    );
}

#[test]
fn errors_name_the_file_and_the_key() {
    let tmp = tempfile::tempdir().unwrap();
    let cases = [
        (
            good().replace("bit_depth = 12", "bit_depth = 11"),
            "sensor.bit_depth",
        ),
        (
            good().replace("192.168.10.2", "camera.local"),
            "sensor.address",
        ),
        (
            good().replace("flash_duration_us = 2000", "flash_duration_us = 9000"),
            "flash outside the exposure",
        ),
        (
            good().replace("photos = 150", "photos = 0"),
            "capture.photos",
        ),
        (good().replace("port = ", "prot = "), "unknown field `prot`"),
        (
            format!("{}\n[flash]\noffset_m = [0.0, nan, 0.0]\n", good()),
            "flash.offset_m",
        ),
        (good().replace("[capture]", "[capture\n"), "rig.toml"),
    ];
    for (text, expected) in cases {
        let p = write(tmp.path(), &text);
        let e = RigFile::load(&p).unwrap_err().to_string();
        assert!(
            e.contains(expected) && e.contains("rig.toml"),
            "{expected}: {e}"
        );
    }
}

/// Issue 46 item 10: every impossible value of a rig file is refused by its key, before the
/// camera backend is looked for (`RigFile::load` is the first thing a hardware capture does).
#[test]
fn impossible_values_are_refused_by_their_key() {
    let tmp = tempfile::tempdir().unwrap();
    let sensor = |extra: &str| {
        good().replace(
            "exposure_us = 8000",
            &format!("exposure_us = 8000\n{extra}"),
        )
    };
    let cases = [
        (sensor("gain_db = nan"), "sensor.gain_db"),
        (sensor("gain_db = inf"), "sensor.gain_db"),
        (sensor("gain_db = -400.0"), "sensor.gain_db"),
        (good().replace("fx = 3500.0", "fx = 1e308"), "camera.fx"),
        (
            good().replace("width = 2448", "width = 2447"),
            "camera.width",
        ),
        (good().replace("cx = 1223.5", "cx = -5000.0"), "camera.cx"),
        (
            format!("{}translation_m = [nan, 0.0, 0.0]\n", good()),
            "boards[0].translation_m",
        ),
        (
            format!("{}rotation_deg = [inf, 0.0, 0.0]\n", good()),
            "boards[0].rotation_deg",
        ),
        (
            good().replace(
                "flash_duration_us = 2000",
                "flash_duration_us = 2\nflash_delay_us = 4294967295",
            ),
            "flash outside the exposure",
        ),
        (
            good().replace("interval_ms = 500.0", "interval_ms = 1e300"),
            "capture.interval_ms",
        ),
        (
            good().replace("192.168.10.2", "255.255.255.255"),
            "sensor.address",
        ),
        (good().replace("192.168.10.2", "0.0.0.0"), "sensor.address"),
        (
            good().replace("192.168.10.2", "239.0.0.1"),
            "sensor.address",
        ),
        (good().replace("/dev/ttyACM0", "/dev/zero"), "trigger.port"),
        (
            format!("{}\n[flash]\noffset_m = [1e6, 0.0, 0.0]\n", good()),
            "flash.offset_m",
        ),
    ];
    for (text, expected) in cases {
        let p = write(tmp.path(), &text);
        let e = RigFile::load(&p)
            .map(|_| ())
            .expect_err(expected)
            .to_string();
        assert!(
            e.contains(expected) && e.contains("rig.toml"),
            "{expected}: {e}"
        );
    }
    // a directory is no trigger port either
    let text = good().replace("/dev/ttyACM0", &tmp.path().display().to_string());
    let e = RigFile::load(&write(tmp.path(), &text))
        .unwrap_err()
        .to_string();
    assert!(e.contains("trigger.port"), "{e}");
}
