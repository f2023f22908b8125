//! The calibration bench on a reduced-resolution render of the shipped calibration scene.

use super::*;

fn scene_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../sim/scenes/calibration.toml")
}

/// Half resolution (1224×1024), all 7 listed poses: the corners carry half the pixels of the
/// full-size render, so the bounds are looser than the 5 MP targets, but still tight
/// enough to catch a wrong corner convention (0.5 px shift → cx, cy off by ≈0.05 %), a wrong
/// distortion sign or a broken detection-image mapping (all ≥ 1 %).
#[test]
fn half_resolution_calibration_recovers_the_rendered_camera() {
    let args = CalibrationArgs {
        scene: scene_path(),
        frames: None,
        resolution: Some([1224, 1024]),
        seed: None,
        image: DetectImage::S0,
        free_k3: false,
        out: PathBuf::from("."),
    };
    let b = run_bench(&args).expect("bench runs");
    assert_eq!(b.frames, 7);
    assert!(b.views_used >= 6, "views kept: {}", b.views_used);
    assert!(b.rms_px < 0.3, "reprojection RMS {} px", b.rms_px);
    for r in &b.params {
        eprintln!(
            "{}: truth {} estimate {} rel {:.2e} σ {:.2e} ({:.1}σ)",
            r.name, r.truth, r.estimate, r.relative_error, r.std_error, r.error_sigmas
        );
        let bound = match r.name {
            "fx" | "fy" | "cx" | "cy" => 2e-3,
            "k1" => 5e-2,
            _ => continue,
        };
        assert!(
            r.relative_error < bound,
            "{}: relative error {:.2e} ≥ {bound:.0e}",
            r.name,
            r.relative_error
        );
    }
}

#[test]
fn spread_covers_the_path_without_repeats() {
    assert_eq!(super::super::spread(7, None), vec![0, 1, 2, 3, 4, 5, 6]);
    assert_eq!(super::super::spread(150, Some(4)), vec![0, 37, 75, 112]);
    assert_eq!(super::super::spread(3, Some(10)), vec![0, 1, 2]);
}

#[test]
fn targets_are_judged_on_intrinsics_and_k1_only() {
    let row = |name: &'static str, relative_error: f64| ParamRow {
        name,
        truth: 1.0,
        estimate: 1.0,
        relative_error,
        std_error: 0.0,
        error_sigmas: f64::NAN,
        estimated: true,
    };
    assert!(meets_targets(&[row("fx", 9e-4), row("k1", 1.9e-2), row("k2", 0.5)]));
    assert!(!meets_targets(&[row("cy", 1.1e-3)]));
    assert!(!meets_targets(&[row("k1", 2.1e-2)]));
    assert!(!meets_targets(&[row("fx", f64::NAN)]));
}
