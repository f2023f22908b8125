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
    use ellipso_vision::calibrate::flash_session::{FlashMeasurement, replace_flash_section};
    let flash = FlashMeasurement {
        position: ellipso_vision::calibrate::flash::FlashEstimate {
            flash_camera_m: nalgebra::Point3::new(0.000_1, -0.030_2, 0.001_7),
            covariance_m2: nalgebra::Matrix3::identity() * 1e-8,
            std_m: [1e-4; 3],
            ray_angle_residuals_rad: vec![1e-3; 12],
            rms_angle_rad: 1e-3,
        },
        polariser: ellipso_vision::calibrate::flash_polariser::PolariserEstimate {
            polariser_deg: 1.234_567,
            std_deg: 0.01,
            residuals_deg: vec![0.01; 12],
            min_dolp: 0.9,
            max_correction_deg: 0.8,
        },
    };
    let tmp = tempfile::tempdir().unwrap();
    // `calibrate flash` puts the table into the rig file, whose other tables load as before
    let text = replace_flash_section(&good(), &flash.to_toml_flash_section()).unwrap();
    let rig = RigFile::load(&write(tmp.path(), &text)).unwrap();
    assert_eq!(
        rig.flash.map(|f| f.offset_m),
        Some([0.000_1, -0.030_2, 0.001_7])
    );
    assert_eq!(rig.flash.and_then(|f| f.polariser_deg), Some(1.234_567));
    assert_eq!(
        rig.camera,
        RigFile::load(&write(tmp.path(), &good())).unwrap().camera
    );
    assert_eq!(rig.boards.len(), 1);
    // a second run replaces the table
    let again = replace_flash_section(&text, &flash.to_toml_flash_section()).unwrap();
    assert_eq!(again, text);
    assert!(
        RigFile::load(&write(tmp.path(), &good()))
            .unwrap()
            .flash
            .is_none()
    );
    // an old file without polariser_deg loads (0° is the default the capture records)
    let old = format!("{}\n[flash]\noffset_m = [0.0, -0.03, 0.0]\n", good());
    let rig = RigFile::load(&write(tmp.path(), &old)).unwrap();
    assert_eq!(rig.flash.and_then(|f| f.polariser_deg), None);
    let bad = format!("{old}polariser_deg = 400.0\n");
    let e = RigFile::load(&write(tmp.path(), &bad))
        .unwrap_err()
        .to_string();
    assert!(e.contains("flash.polariser_deg"), "{e}");
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

/// A 16×8 calibration of ideal analysers for `layout`, written to `path`; its identity.
fn write_calibration(path: &Path, layout: SensorLayout) -> String {
    use ellipso_polar::sensor_calibration::{
        FORMAT, PixelRecord, SensorCalibration, SensorFigures, SensorHeader, VERSION, file,
    };
    let (w, h) = (16u32, 8u32);
    let pixels = (0..w * h)
        .map(|i| {
            let (s2, c2) = (2.0 * layout.analyser_at(i % w, i / w).angle_rad()).sin_cos();
            PixelRecord {
                dark_dn: 64.0,
                analysis: [0.5, (0.5 * c2) as f32, (0.5 * s2) as f32],
            }
        })
        .collect();
    let mut cal = SensorCalibration {
        header: SensorHeader {
            format: FORMAT.into(),
            version: VERSION,
            sensor: ellipso_session::manifest::SensorInfo {
                layout,
                width: w,
                height: h,
                bit_depth: 12,
            },
            gain_db: 0.0,
            figures: SensorFigures {
                gain_dn_per_e: 0.39,
                gain_e_per_dn: 1.0 / 0.39,
                read_noise_dn: 0.9,
                read_noise_e: 2.3,
                black_level_dn: 64.0,
                dsnu_dn: 0.0,
                prnu_rel: 0.0,
                saturation_dn: 4031.0,
                saturation_e: 10_500.0,
                vignetting_exponent: 0.0,
                extinction_ratio: vec![1e9],
                analyser_angle_mean_error_deg: [0.0; 4],
                analyser_angle_sd_deg: 0.0,
                hot_pixels: 0,
                photon_transfer: Vec::new(),
            },
            source: "test".into(),
        },
        pixels,
        checksum: 0,
    };
    file::write(&mut cal, path).unwrap()
}

/// `[sensor] calibration` names a file relative to the rig file: its identity and absolute path
/// come back for the session; another layout, a missing file and a corrupt one are refused by
/// the key (the camera's size is checked against `[camera]` where there is one).
#[test]
fn the_sensor_calibration_is_named_by_the_rig_file_and_checked() {
    let tmp = tempfile::tempdir().unwrap();
    let without_camera = |name: &str| {
        let text = good();
        let start = text.find("[camera]").unwrap();
        let end = text.find("[capture]").unwrap();
        format!("{}{}", &text[..start], &text[end..]).replace(
            "exposure_us = 8000\n",
            &format!("exposure_us = 8000\ncalibration = \"{name}\"\n"),
        )
    };
    let id = write_calibration(&tmp.path().join("cam.senscal"), SensorLayout::MonoPolar);
    let rig = RigFile::load(&write(tmp.path(), &without_camera("cam.senscal"))).unwrap();
    let named = rig.sensor_calibration().unwrap().unwrap();
    assert_eq!(named.id, id);
    assert!(named.file.is_absolute() && named.file.ends_with("cam.senscal"));
    // none named: none recorded
    let rig = RigFile::load(&write(tmp.path(), &good())).unwrap();
    assert!(rig.sensor_calibration().unwrap().is_none());
    // another layout, a missing file, a corrupt file, [camera] of another size
    write_calibration(
        &tmp.path().join("colour.senscal"),
        SensorLayout::ColourPolar,
    );
    std::fs::write(tmp.path().join("bad.senscal"), b"ELLIPSO-SENSCAL\ngarbage").unwrap();
    for (name, want) in [
        ("colour.senscal", "colour_polar sensor"),
        ("absent.senscal", "absent.senscal"),
        ("bad.senscal", "corrupt"),
    ] {
        let rig = RigFile::load(&write(tmp.path(), &without_camera(name))).unwrap();
        let e = rig.sensor_calibration().unwrap_err().to_string();
        assert!(
            e.contains("sensor.calibration") && e.contains(want),
            "{name}: {e}"
        );
    }
    let with_camera = good().replace(
        "exposure_us = 8000\n",
        "exposure_us = 8000\ncalibration = \"cam.senscal\"\n",
    );
    let rig = RigFile::load(&write(tmp.path(), &with_camera)).unwrap();
    let e = rig.sensor_calibration().unwrap_err().to_string();
    assert!(e.contains("16×8 sensor, [camera] is 2448×2048"), "{e}");
}
