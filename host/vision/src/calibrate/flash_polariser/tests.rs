//! The polariser-angle estimator on synthetic Stokes sums and mosaics, and end to end on rendered
//! frames of the shipped glossy sphere with a known flash offset and polariser angle.

use super::*;
use crate::calibrate::flash::{
    HighlightObservation, SpherePoint, estimate_flash_position, sphere_point,
};
use crate::calibrate::highlight::{HighlightConfig, Sphere, find_highlight};
use ellipso_model::mosaic::SensorLayout;
use ellipso_polar::synthetic::mosaic_from_stokes;
use ellipso_polar::{PolarConfig, RawFrame, process};
use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::scene::Scene;
use nalgebra::Point3;

/// A view's Stokes sum for light polarised along `polariser_deg` (rig convention) with DoLP
/// `dolp` and polarised intensity `w`.
fn view(polariser_deg: f64, dolp: f64, w: f64) -> HighlightStokes {
    let a = (-2.0 * polariser_deg).to_radians();
    HighlightStokes {
        s0: w / dolp,
        s1: w * a.cos(),
        s2: w * a.sin(),
        pixels: 10,
    }
}

fn config() -> PolarConfig {
    stokes_config()
}

#[test]
fn weighted_circular_mean_and_its_scatter() {
    // views at 1.5 ± 0.2° (equal weights): the mean 1.5°, σ = sd/√n·√(n/(n−1))·… = 0.2/√2·√2
    let views = [view(1.3, 0.9, 1.0), view(1.7, 0.9, 1.0)];
    let e = estimate_polariser_angle(&views).unwrap();
    assert!((e.polariser_deg - 1.5).abs() < 1e-9, "{e:?}");
    // two views, Δ = ±0.2: σ² = 2 · (0.04 + 0.04) / 4 = 0.04
    assert!((e.std_deg - 0.2).abs() < 1e-9, "{e:?}");
    assert!((e.min_dolp - 0.9).abs() < 1e-9);
    // a heavier view pulls the mean: weights 3 and 1 at 1.0° and 2.0° → 1.25° (small angles:
    // the circular mean of close angles is their weighted mean to O(Δ³))
    let e = estimate_polariser_angle(&[view(1.0, 1.0, 3.0), view(2.0, 1.0, 1.0)]).unwrap();
    assert!((e.polariser_deg - 1.25).abs() < 1e-4, "{e:?}");
    // across the ±90° seam: 89° and −89° are one axis 2° wide, the mean is 90°
    let e = estimate_polariser_angle(&[view(89.0, 1.0, 1.0), view(-89.0, 1.0, 1.0)]).unwrap();
    assert!((e.polariser_deg.abs() - 90.0).abs() < 1e-9, "{e:?}");
    assert!((e.std_deg - 1.0).abs() < 1e-9, "{e:?}");
    assert_eq!(
        estimate_polariser_angle(&views[..1]),
        Err(PolariserError::TooFewViews(1))
    );
}

/// The model's reading is the polariser angle, within 0.1°, for a highlight on the optical
/// axis (the analysers' nominal angles, Fresnel s ≈ p), turns off axis by a small amount that changes
/// little with the angle, and is the negated AoLP (a 30° polariser does not read −30°).
#[test]
fn model_reading_on_and_off_axis() {
    let flash = Point3::new(0.0, -0.03, 0.0);
    let on_axis = SpherePoint {
        point_camera_m: Point3::new(0.0, 0.0, 0.5),
        // the mirror normal: bisecting the directions to the camera and to the flash
        normal_camera: ((-nalgebra::Vector3::new(0.0, 0.0, 0.5)).normalize()
            + (flash.coords - nalgebra::Vector3::new(0.0, 0.0, 0.5)).normalize())
        .normalize(),
    };
    for p in [0.0, 7.0, 30.0, -60.0] {
        let r = model_reading_deg(&on_axis, &flash, p).unwrap();
        // the flash's own ray is 3.4° off the axis (its polarisation is across that ray) and
        // r_s ≠ r_p at 1.7°: up to 0.07° at 30°
        assert!((r - p).abs() < 0.1, "on axis: {p}° reads {r}°");
    }
    // 8° right of and 6° below the axis
    let at = nalgebra::Vector3::new(0.07, 0.052, 0.5);
    let normal = ((-at).normalize() + (flash.coords - at).normalize()).normalize();
    let off = SpherePoint {
        point_camera_m: Point3::from(at),
        normal_camera: normal,
    };
    let c0 = model_reading_deg(&off, &flash, 0.0).unwrap();
    let c7 = model_reading_deg(&off, &flash, 7.0).unwrap() - 7.0;
    assert!(c0.abs() > 0.05 && c0.abs() < 2.0, "off-axis turn {c0}°");
    assert!((c7 - c0).abs() < 0.05, "turn at 0° {c0}°, at 7° {c7}°");
}

/// A 12-bit mono mosaic: an unpolarised background of `bg` with a Gaussian spot (σ 3 superpixels)
/// at raw (`x`, `y`) polarised along AoLP `aolp_deg` (polar's convention), peak `peak` in DN.
fn spot(x: f64, y: f64, aolp_deg: f64, peak: f64, bg: f64) -> ellipso_polar::PolarImage {
    let a = (2.0 * aolp_deg).to_radians();
    let frame = mosaic_from_stokes(SensorLayout::MonoPolar, 128, 96, 12, |px, py, _| {
        let r2 = (px as f64 - x).powi(2) + (py as f64 - y).powi(2);
        let i = peak * (-r2 / (2.0 * 36.0)).exp();
        [bg + i, i * a.cos(), i * a.sin()]
    })
    .expect("mosaic");
    process(&frame, &config()).expect("process")
}

#[test]
fn highlight_stokes_reads_the_spot_and_skips_its_saturated_core() {
    // AoLP 20° (counter-clockwise, image up) is polariser_deg −20° (camera y is image down)
    let img = spot(64.5, 40.5, 20.0, 1500.0, 100.0);
    let s = highlight_stokes(&img, 128, [64.5, 40.5], 16.0).unwrap();
    assert!((s.aolp_deg() - 20.0).abs() < 0.05, "{s:?} {}", s.aolp_deg());
    assert!((s.polariser_deg() + 20.0).abs() < 0.05, "{s:?}");
    assert!(s.dolp() > MIN_DOLP, "{s:?}");
    // a core far above full scale: saturated pixels masked, the ring still gives the angle
    let img = spot(64.5, 40.5, 20.0, 40_000.0, 100.0);
    let s = highlight_stokes(&img, 128, [64.5, 40.5], 24.0).unwrap();
    assert!((s.polariser_deg() + 20.0).abs() < 0.1, "{s:?}");
    // an unpolarised spot is refused naming the DoLP
    let flat = mosaic_from_stokes(SensorLayout::MonoPolar, 128, 96, 12, |px, py, _| {
        let r2 = (px as f64 - 64.5).powi(2) + (py as f64 - 40.5).powi(2);
        [100.0 + 1500.0 * (-r2 / 72.0).exp(), 0.0, 0.0]
    })
    .unwrap();
    let flat = process(&flat, &config()).unwrap();
    assert!(matches!(
        highlight_stokes(&flat, 128, [64.5, 40.5], 16.0),
        Err(PolariserError::NotPolarised { .. })
    ));
    // saturated throughout the window
    let img = spot(64.5, 40.5, 20.0, 1e7, 100.0);
    assert!(matches!(
        highlight_stokes(&img, 128, [64.5, 40.5], 4.0),
        Err(PolariserError::NoValidPixels { .. })
    ));
}

/// The shipped sphere scene shot hand-held (a walk at 0.35–0.6 m, the aim off by up to ~10°, so
/// the sphere moves around the image and in depth) with the flash at `offset_m` behind a
/// polariser at `polariser_deg`.
pub(crate) fn sphere_capture(offset_m: [f64; 3], polariser_deg: f64) -> Scene {
    let path = ellipso_sim::scene::shipped_scene("sphere.toml");
    let text = std::fs::read_to_string(&path).expect("sphere scene");
    let start = text.find("[capture]").expect("capture table");
    let end = start + text[start..].find("\n[effects]").expect("effects table");
    let walk = "[capture]\npath = \"random_walk\"\nphoto_count = 150\nlook_at_m = [0.0, 0.0, 0.04]\n\
                elevation_deg = [30.0, 70.0]\ndistance_m = [0.35, 0.6]\naim_jitter_deg = 5.0\n";
    let text = format!("{}{walk}{}", &text[..start], &text[end..]).replace(
        "offset_m = [0.0, -0.03, 0.0]\npolariser_deg = 0.0",
        &format!("offset_m = {offset_m:?}\npolariser_deg = {polariser_deg:?}"),
    );
    assert!(text.contains(&format!("polariser_deg = {polariser_deg:?}")));
    Scene::from_toml_str(&text, &path).expect("hand-held sphere scene")
}

/// 12 hand-held frames of the sphere at 816×680 with the flash at (4, −31, 2) mm behind a
/// polariser at 7° (a sign error reads −7°, 14° off): the offset within the 1 mm and the
/// angle within its 0.5°, each within 4σ of its estimate.
#[test]
fn rendered_sphere_gives_the_flash_offset_and_polariser_angle() {
    let truth_offset = [0.004, -0.031, 0.002];
    let truth_deg = 7.0;
    let scene = sphere_capture(truth_offset, truth_deg);
    let options = RenderOptions {
        resolution_px: Some([816, 680]),
        ..RenderOptions::default()
    };
    let renderer = Renderer::new(&scene, options).expect("renderer");
    let camera = *renderer.camera();
    let sphere = Sphere {
        radius_m: 0.04,
        centre_m: Point3::new(0.0, 0.0, 0.04),
    };
    let n = scene.camera_poses.len();
    let mut observations = Vec::new();
    let mut stokes = Vec::new();
    for k in (0..12).map(|i| i * n / 12) {
        let f = renderer.render_frame(k).expect("render");
        let raw = RawFrame::new(
            f.width,
            f.height,
            scene.rig.camera.bit_depth,
            renderer.layout(),
            f.raw(),
        )
        .expect("raw frame");
        let camera_from_world = scene.camera_poses[k].world_from_camera.inverse();
        let h = find_highlight(
            &raw,
            &camera,
            &camera_from_world,
            &sphere,
            &HighlightConfig::default(),
        )
        .unwrap_or_else(|e| panic!("frame {k}: {e}"));
        let img = process(&raw, &config()).expect("process");
        let s = highlight_stokes(
            &img,
            f.width,
            h.pixel,
            window_radius_px(h.blob_px, renderer.layout().tile_px()),
        )
        .unwrap_or_else(|e| panic!("frame {k}: {e}"));
        eprintln!(
            "frame {k}: highlight {:.1?} px, {} px summed, DoLP {:.3}, polariser {:.3}°",
            h.pixel,
            s.pixels,
            s.dolp(),
            s.polariser_deg()
        );
        stokes.push(s);
        observations.push(HighlightObservation {
            camera_from_board: camera_from_world,
            sphere_centre_board_m: sphere.centre_m,
            sphere_radius_m: sphere.radius_m,
            highlight_px: h.pixel,
        });
    }
    let pos = estimate_flash_position(&camera, &observations).expect("flash position");
    let err_mm = (pos.flash_camera_m.coords - nalgebra::Vector3::from(truth_offset)) * 1e3;
    let raw_angle = estimate_polariser_angle(&stokes).expect("polariser angle");
    let points: Vec<_> = observations
        .iter()
        .enumerate()
        .map(|(i, o)| sphere_point(&camera, i, o).expect("sphere point"))
        .collect();
    let angle = estimate_polariser_angle_corrected(&stokes, &points, &pos.flash_camera_m)
        .expect("polariser angle");
    let err_deg = angle.polariser_deg - truth_deg;
    eprintln!(
        "uncorrected {:.3}° ± {:.3}°; corrected residuals {:.3?}°, largest correction {:.3}°",
        raw_angle.polariser_deg, raw_angle.std_deg, angle.residuals_deg, angle.max_correction_deg
    );
    eprintln!(
        "flash error {:.3?} mm (|e| {:.3}), σ {:.3?} mm; polariser {:.3}° ± {:.3}°, error {err_deg:+.3}°",
        err_mm.as_slice(),
        err_mm.norm(),
        pos.std_m.map(|s| s * 1e3),
        angle.polariser_deg,
        angle.std_deg
    );
    assert!(err_mm.norm() < 1.0, "flash error {:.3} mm", err_mm.norm());
    assert!(err_deg.abs() < 0.5, "polariser error {err_deg:.3}°");
    assert!(
        err_deg.abs() <= 4.0 * angle.std_deg + 0.02,
        "polariser error {err_deg:.3}° vs σ {:.3}°",
        angle.std_deg
    );
}
