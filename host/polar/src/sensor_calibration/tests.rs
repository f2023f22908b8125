//! The calibration file's checks and the per-pixel estimator on a synthetic sensor.

use std::path::Path;

use ellipso_model::mosaic::SensorLayout;
use ellipso_session::manifest::SensorInfo;

use super::file::{self, SensorCalibrationError};
use super::*;
use crate::{PolarConfig, RawFrame, process};

/// An 8×8 mono sensor with per-pixel angle errors, extinction, gains and dark levels.
fn synthetic(layout: SensorLayout, w: u32, h: u32) -> SensorCalibration {
    let mut pixels = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let k = layout.analyser_at(x, y);
            let err = 0.02 * ((x * 7 + y * 3) % 5) as f64 - 0.04;
            let angle = k.angle_rad() + err;
            let e = 1.0 / (80.0 + f64::from((x + y) % 3) * 40.0);
            let g = 1.0 + 0.01 * f64::from((x * 5 + y) % 4) - 0.015;
            let (s2, c2) = (2.0 * angle).sin_cos();
            pixels.push(PixelRecord {
                dark_dn: 64.0 + ((x + 2 * y) % 3) as f32,
                analysis: [
                    (0.5 * g * (1.0 + e)) as f32,
                    (0.5 * g * (1.0 - e) * c2) as f32,
                    (0.5 * g * (1.0 - e) * s2) as f32,
                ],
            });
        }
    }
    SensorCalibration {
        header: SensorHeader {
            format: FORMAT.into(),
            version: VERSION,
            sensor: SensorInfo {
                layout,
                width: w,
                height: h,
                bit_depth: 16,
            },
            gain_db: 0.0,
            figures: SensorFigures {
                gain_dn_per_e: 0.4,
                gain_e_per_dn: 2.5,
                read_noise_dn: 1.0,
                read_noise_e: 2.5,
                black_level_dn: 65.0,
                dsnu_dn: 1.0,
                prnu_rel: 0.01,
                saturation_dn: 65000.0,
                saturation_e: 162500.0,
                vignetting_exponent: 0.0,
                extinction_ratio: vec![120.0],
                analyser_angle_mean_error_deg: [0.0; 4],
                analyser_angle_sd_deg: 1.0,
                hot_pixels: 0,
                photon_transfer: Vec::new(),
            },
            source: "synthetic".into(),
        },
        pixels,
        checksum: 0,
    }
}

#[test]
fn per_pixel_estimator_recovers_the_stokes_vector_the_sensor_saw() {
    for layout in [SensorLayout::MonoPolar, SensorLayout::ColourPolar] {
        let cal = synthetic(layout, 16, 8);
        let s_true = [0.6, 0.15, -0.2];
        let data: Vec<u16> = (0..16u32 * 8)
            .map(|i| {
                let (x, y) = (i % 16, i / 16);
                let p = cal.pixel(x, y);
                let a = p.analysis.map(f64::from);
                let signal = a[0] * s_true[0] + a[1] * s_true[1] + a[2] * s_true[2];
                (f64::from(p.dark_dn) + signal * (65535.0 - 65.0)).round() as u16
            })
            .collect();
        let frame = RawFrame::new(16, 8, 16, layout, data).unwrap();
        let img = process_with_sensor(&frame, &PolarConfig::default(), &cal).unwrap();
        let ideal = process(&frame, &PolarConfig::default()).unwrap();
        let (mut worst, mut worst_ideal) = (0.0f64, 0.0f64);
        for (band, ideal_band) in img.bands.iter().zip(&ideal.bands) {
            for i in 0..band.s0.data().len() {
                for (plane, ideal_plane, want) in [
                    (&band.s0, &ideal_band.s0, s_true[0]),
                    (&band.s1, &ideal_band.s1, s_true[1]),
                    (&band.s2, &ideal_band.s2, s_true[2]),
                ] {
                    worst = worst.max((f64::from(plane.data()[i]) - want).abs());
                    worst_ideal = worst_ideal.max((f64::from(ideal_plane.data()[i]) - want).abs());
                }
            }
        }
        assert!(worst < 1e-4, "{layout:?}: calibrated error {worst}");
        assert!(
            worst_ideal > 3e-3,
            "{layout:?}: ideal formulas' error {worst_ideal}"
        );
    }
}

#[test]
fn file_round_trips_and_every_bad_file_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sensor.cal");
    let mut cal = synthetic(SensorLayout::MonoPolar, 8, 8);
    let id = file::write(&mut cal, &path).unwrap();
    let back = file::read(&path, Some(&id)).unwrap();
    assert_eq!(back, cal);
    assert!(file::is_sensor_calibration(&path));

    let bytes = std::fs::read(&path).unwrap();
    let at = |p: &Path, b: &[u8]| {
        std::fs::write(p, b).unwrap();
        file::read(p, None).unwrap_err()
    };
    let p = dir.path().join("bad.cal");
    // one flipped payload bit: the checksum
    let mut flipped = bytes.clone();
    let n = flipped.len();
    flipped[n - 20] ^= 1;
    let e = at(&p, &flipped);
    assert!(
        matches!(e, SensorCalibrationError::Corrupt { .. }) && e.to_string().contains("checksum"),
        "{e}"
    );
    // truncated
    let e = at(&p, &bytes[..n - 100]);
    assert!(
        e.to_string().contains("bytes, a 8×8 calibration has"),
        "{e}"
    );
    // not a calibration
    let e = at(&p, b"{\"angle_deg\": [0, 45, 90, 135]}");
    assert!(
        matches!(e, SensorCalibrationError::NotACalibration { .. }),
        "{e}"
    );
    // another version
    let mut newer = cal.clone();
    newer.header.version = 2;
    let (b, _) = file::to_bytes(&newer);
    let e = at(&p, &b);
    assert!(
        matches!(e, SensorCalibrationError::Version { found: 2, .. }),
        "{e}"
    );
    // stale: not the identity the rig file names
    let e = file::read(&path, Some("0123456789abcdef")).unwrap_err();
    assert!(
        matches!(e, SensorCalibrationError::Stale { .. }) && e.to_string().contains(&id),
        "{e}"
    );
    // a frame of another size or layout
    let frame = RawFrame::new(16, 8, 16, SensorLayout::MonoPolar, vec![0; 128]).unwrap();
    let e = cal.check_frame(&frame).unwrap_err().to_string();
    assert!(e.contains("8×8 sensor") && e.contains("16×8"), "{e}");
    let frame = RawFrame::new(8, 8, 16, SensorLayout::ColourPolar, vec![0; 64]);
    if let Ok(frame) = frame {
        let e = cal.check_frame(&frame).unwrap_err().to_string();
        assert!(
            e.contains("mono_polar") && e.contains("colour_polar"),
            "{e}"
        );
    }
}

/// The calibrated demosaic writes back what the fit's analysers (extinction e) would record for
/// the Stokes vector the sensor saw: within 2e-4 (the frame's 16-bit rounding through A⁺)
/// where the plain demosaic is off by the synthetic sensor's errors (> 2e-3); and for a
/// calibration of ideal analysers with no dark offsets it returns the plain demosaic's values.
#[test]
fn calibrated_demosaic_writes_back_the_modelled_analysers() {
    use std::sync::Arc;
    for layout in [SensorLayout::MonoPolar, SensorLayout::ColourPolar] {
        let cal = synthetic(layout, 16, 8);
        let s_true = [0.6, 0.15, -0.2];
        let frame_of = |cal: &SensorCalibration| {
            let data: Vec<u16> = (0..16u32 * 8)
                .map(|i| {
                    let (x, y) = (i % 16, i / 16);
                    let p = cal.pixel(x, y);
                    let a = p.analysis.map(f64::from);
                    let signal = a[0] * s_true[0] + a[1] * s_true[1] + a[2] * s_true[2];
                    (f64::from(p.dark_dn) + signal * (65535.0 - 65.0)).round() as u16
                })
                .collect();
            RawFrame::new(16, 8, 16, layout, data).unwrap()
        };
        let frame = frame_of(&cal);
        for er in [None, Some(200.0)] {
            let e = er.map_or(0.0, |r: f64| 1.0 / r);
            let want = [0.0f64, 45.0, 90.0, 135.0].map(|deg| {
                let (s2, c2) = (2.0 * deg.to_radians()).sin_cos();
                0.5 * ((1.0 + e) * s_true[0] + (1.0 - e) * (c2 * s_true[1] + s2 * s_true[2]))
            });
            let demosaic = CalibratedDemosaic::new(Arc::new(cal.clone()), er);
            let config = demosaic.config(&PolarConfig::default()).unwrap();
            let levels = config.levels(&frame).unwrap();
            let image = demosaic.demosaic(&frame, &levels).unwrap();
            let plain = crate::demosaic::demosaic(
                &frame,
                &levels,
                crate::demosaic::DemosaicMethod::Superpixel,
            );
            let (mut worst, mut worst_plain) = (0.0f64, 0.0f64);
            for (band, plain_band) in image.bands.iter().zip(&plain.bands) {
                for ((got, plain), want) in
                    band.intensity.iter().zip(&plain_band.intensity).zip(want)
                {
                    for (v, p) in got.data().iter().zip(plain.data()) {
                        worst = worst.max((f64::from(*v) - want).abs());
                        worst_plain = worst_plain.max((f64::from(*p) - want).abs());
                    }
                }
            }
            assert!(
                worst < 2e-4,
                "{layout:?} ER {er:?}: calibrated off by {worst}"
            );
            assert!(
                worst_plain > 2e-3,
                "{layout:?}: plain off by only {worst_plain}"
            );
        }
        // ideal analysers, dark level = black level: the plain demosaic's values
        let mut ideal = cal.clone();
        for y in 0..8 {
            for x in 0..16 {
                let angle = layout.analyser_at(x, y).angle_rad();
                let (s2, c2) = (2.0 * angle).sin_cos();
                ideal.pixels[(y * 16 + x) as usize] = PixelRecord {
                    dark_dn: 65.0,
                    analysis: [0.5, (0.5 * c2) as f32, (0.5 * s2) as f32],
                };
            }
        }
        let frame = frame_of(&ideal);
        let demosaic = CalibratedDemosaic::new(Arc::new(ideal), None);
        let config = demosaic.config(&PolarConfig::default()).unwrap();
        let levels = config.levels(&frame).unwrap();
        let image = demosaic.demosaic(&frame, &levels).unwrap();
        let plain =
            crate::demosaic::demosaic(&frame, &levels, crate::demosaic::DemosaicMethod::Superpixel);
        for (band, plain_band) in image.bands.iter().zip(&plain.bands) {
            for (got, plain) in band.intensity.iter().zip(&plain_band.intensity) {
                for (v, p) in got.data().iter().zip(plain.data()) {
                    assert!((v - p).abs() < 1e-6, "{layout:?}: {v} vs plain {p}");
                }
            }
        }
    }
}

/// A session names its calibration by identity; another file, another sensor size or layout is
/// refused by name.
#[test]
fn a_session_gets_its_own_calibration_or_a_named_error() {
    use ellipso_session::rig::{RigRecord, SensorCalibrationRef};
    let dir = tempfile::tempdir().unwrap();
    let mut cal = synthetic(SensorLayout::MonoPolar, 16, 8);
    let path = dir.path().join("cam.senscal");
    let id = file::write(&mut cal, &path).unwrap();
    let mut manifest = ellipso_session::manifest::Manifest::new(
        ellipso_session::manifest::SessionSource::Hardware {
            trigger_port: "unix:x".into(),
            camera: "aravis:127.0.0.1".into(),
        },
        SensorInfo {
            layout: SensorLayout::MonoPolar,
            width: 16,
            height: 8,
            bit_depth: 16,
        },
        0,
    );
    assert!(session::for_session(&manifest, None).unwrap().is_none());
    assert_eq!(
        session::for_session(&manifest, Some(&path))
            .unwrap()
            .unwrap()
            .id(),
        id
    );
    let mut rig = RigRecord::relative(
        ellipso_model::camera::CameraModel {
            width: 16,
            height: 8,
            intrinsics: ellipso_model::camera::Intrinsics {
                fx: 16.0,
                fy: 16.0,
                cx: 7.5,
                cy: 3.5,
            },
            distortion: Default::default(),
        },
        None,
    );
    rig.sensor_calibration = Some(SensorCalibrationRef {
        id: id.clone(),
        file: path.clone(),
    });
    manifest.rig = Some(rig.clone());
    assert_eq!(
        session::for_session(&manifest, None).unwrap().unwrap().id(),
        id
    );
    // another file than the one recorded
    let mut other = synthetic(SensorLayout::MonoPolar, 16, 8);
    other.pixels[0].dark_dn += 1.0;
    let other_path = dir.path().join("other.senscal");
    file::write(&mut other, &other_path).unwrap();
    let e = session::for_session(&manifest, Some(&other_path)).unwrap_err();
    assert!(matches!(e, SensorCalibrationError::Stale { .. }), "{e}");
    // another sensor size, another layout
    manifest.rig = None;
    manifest.sensor.width = 32;
    let e = session::for_session(&manifest, Some(&path)).unwrap_err();
    assert!(
        matches!(e, SensorCalibrationError::SensorSize { .. }),
        "{e}"
    );
    manifest.sensor.width = 16;
    manifest.sensor.layout = SensorLayout::ColourPolar;
    let e = session::for_session(&manifest, Some(&path)).unwrap_err();
    assert!(matches!(e, SensorCalibrationError::Layout { .. }), "{e}");
}
