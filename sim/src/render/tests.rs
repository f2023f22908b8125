//! Renderer tests: every shipped scene renders, determinism across seeds and thread counts,
//! saturation, shadows, the radiometry contract, and real AprilTag detection on a render.

use super::*;
use crate::scene::Scene;
use ellipso_model::mosaic::SensorLayout;
use std::path::{Path, PathBuf};

pub(super) fn scene_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name)
}

/// A shipped scene with its TOML text edited by `edit`.
pub(super) fn scene_edited(name: &str, edit: impl Fn(String) -> String) -> Scene {
    let path = scene_path(name);
    let text = std::fs::read_to_string(&path).unwrap();
    Scene::from_toml_str(&edit(text), &path).unwrap()
}

/// The text without its `[effects]` table (it is the last table in every shipped scene).
pub(super) fn without_effects(text: String) -> String {
    match text.find("\n[effects]") {
        Some(i) => text[..i].to_string(),
        None => text,
    }
}

pub(super) fn small(w: u32, h: u32) -> RenderOptions {
    RenderOptions {
        supersampling: 1,
        resolution_px: Some([w, h]),
        ..RenderOptions::default()
    }
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

#[test]
fn every_shipped_scene_renders_within_the_adc_range() {
    for name in [
        "sphere.toml",
        "s0_only.toml",
        "calibration.toml",
        "multi_material.toml",
        "multi_material_bracket.toml",
    ] {
        let scene = Scene::load(&scene_path(name)).unwrap();
        let r = Renderer::new(&scene, small(64, 48)).unwrap();
        let f = r.render_frame(0).unwrap();
        let max = r.radiometry().full_scale_dn() as f32;
        assert_eq!(f.dn.len(), 64 * 48, "{name}");
        assert!(f.dn.iter().all(|v| v.is_finite() && *v >= 0.0), "{name}");
        assert!(f.dn.iter().all(|v| *v <= max), "{name}: above {max}");
        let lit = f.dn.iter().filter(|v| **v > 5.0).count();
        assert!(lit > 64 * 48 / 4, "{name}: only {lit} lit pixels");
        assert_eq!(f.truth.index, 0);
    }
}

#[test]
fn same_seed_is_bit_identical_on_one_and_two_threads() {
    let scene = Scene::load(&scene_path("sphere.toml")).unwrap();
    let r = Renderer::new(&scene, small(64, 48)).unwrap();
    let a = in_pool(1, || r.render_frame(1).unwrap());
    let b = in_pool(2, || r.render_frame(1).unwrap());
    let c = in_pool(2, || r.render_frame(1).unwrap());
    assert_eq!(a.raw(), b.raw());
    assert_eq!(b.raw(), c.raw());
    assert_eq!(a.counts, b.counts);
}

/// A bracketed pulse: the signal scales with the flash energy before the sensor (exactly, without
/// sensor effects); energy 1 is the plain render bit for bit, noise included; the highlights a full
/// pulse clips are measured by a sixteenth of it; a bad energy is an error, not a black frame.
#[test]
fn flash_energy_scales_the_signal_before_the_sensor() {
    let clean = scene_edited("sphere.toml", without_effects);
    let r = Renderer::new(&clean, small(64, 48)).unwrap();
    let full = r.render_frame(2).unwrap();
    let quarter = r.render_frame_lit(2, 0.25).unwrap();
    for (f, q) in full.dn.iter().zip(&quarter.dn) {
        assert!((q - 0.25 * f).abs() <= 1e-5 * f.max(1.0), "{q} vs {f}/4");
    }
    assert!(full.dn.iter().any(|&v| v > 100.0));
    assert!(
        r.render_frame_lit(2, 0.0)
            .unwrap()
            .dn
            .iter()
            .all(|&v| v == 0.0)
    );

    // A 5× exposure clips the board at full energy; a sixteenth of the pulse measures it.
    let noisy = scene_edited("sphere.toml", |t| {
        t.replace("exposure_us = 8000.0", "exposure_us = 40000.0")
    });
    let r = Renderer::new(&noisy, small(64, 48)).unwrap();
    let full = r.render_frame(3).unwrap();
    assert_eq!(r.render_frame_lit(3, 1.0).unwrap().raw(), full.raw());
    let max = r.radiometry().full_scale_dn() as f32;
    let clipped = |f: &RenderedFrame| f.dn.iter().filter(|&&v| v >= max).count();
    let short = r.render_frame_lit(3, 0.0625).unwrap();
    assert!(
        clipped(&full) > 100 && clipped(&short) < clipped(&full) / 10,
        "{} clipped at 1/16 vs {} at full energy",
        clipped(&short),
        clipped(&full)
    );
    for bad in [-0.1, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            r.render_frame_lit(3, bad),
            Err(RenderError::FlashEnergy(_))
        ));
    }
}

#[test]
fn another_seed_changes_only_noisy_renders() {
    let noisy = Scene::load(&scene_path("sphere.toml")).unwrap();
    let quiet = scene_edited("sphere.toml", without_effects);
    let with_seed = |scene: &Scene, seed| {
        let opts = RenderOptions {
            seed: Some(seed),
            ..small(64, 48)
        };
        Renderer::new(scene, opts)
            .unwrap()
            .render_frame(0)
            .unwrap()
            .raw()
    };
    let (n1, n2) = (with_seed(&noisy, 1), with_seed(&noisy, 2));
    let differing = n1.iter().zip(&n2).filter(|(a, b)| a != b).count();
    assert!(
        differing > n1.len() / 4,
        "noise barely changed: {differing}"
    );
    assert_eq!(with_seed(&quiet, 1), with_seed(&quiet, 2));
}

#[test]
fn saturation_clips_at_the_adc_full_scale() {
    let scene = scene_edited("sphere.toml", |t| {
        t.replace("exposure_us = 8000.0", "exposure_us = 400000.0")
    });
    let r = Renderer::new(&scene, small(64, 48)).unwrap();
    let f = r.render_frame(0).unwrap();
    let raw = f.raw();
    assert_eq!(r.radiometry().full_scale_dn(), 4095.0);
    assert_eq!(*raw.iter().max().unwrap(), 4095);
    assert!(raw.iter().filter(|v| **v == 4095).count() > 100);
    // The same render without the saturation stage goes past the 12-bit range.
    let mut plan = r.plan().clone();
    plan.stages.retain(|s| s.stage != Stage::Saturation);
    let unclipped = Renderer::with_plan(&scene, plan, small(64, 48))
        .unwrap()
        .render_frame(0)
        .unwrap();
    assert!(unclipped.dn.iter().any(|v| *v > 4095.0));
    assert_eq!(unclipped.counts.get(Stage::Saturation), 0);
}

#[test]
fn points_in_the_flash_shadow_get_no_direct_light() {
    // Flash 15 cm to the side: the sphere casts a wide shadow on the board.
    let scene = scene_edited("sphere.toml", |t| {
        without_effects(t).replace(
            "offset_m = [0.0, -0.03, 0.0]",
            "offset_m = [0.15, 0.0, 0.0]",
        )
    });
    let opts = RenderOptions {
        pixel_truth: true,
        ..small(128, 96)
    };
    let r = Renderer::new(&scene, opts).unwrap();
    let f = r.render_frame(0).unwrap();
    let pose = scene.camera_poses[0].world_from_camera;
    let flash = scene.rig.flash.position_world(&pose);
    let (mut shadowed, mut lit) = (0, 0);
    for y in 0..96u32 {
        for x in 0..128u32 {
            let i = (y * 128 + x) as usize;
            if f.pixels.as_ref().unwrap().material[i] < BOARD_MATERIAL_BASE
                || f.pixels.as_ref().unwrap().material[i] == NO_HIT_MATERIAL
            {
                continue;
            }
            let d = r.ray_camera(f64::from(x), f64::from(y), &mut StageCounts::default());
            let ray = Ray::new(pose.translation.vector.into(), pose.rotation * d);
            let hit = scene.intersect(&ray, 0.0, f64::INFINITY).unwrap();
            let p = hit.hit.point + hit.hit.normal_geometric.into_inner() * 1e-6;
            if scene.occluded(&Ray::new(p, flash - p), 1e-9, 1.0 - 1e-9) {
                shadowed += 1;
                assert_eq!(f.dn[i], 0.0, "shadowed board pixel ({x}, {y}) is lit");
            } else {
                lit += 1;
            }
        }
    }
    assert!(shadowed > 20, "no shadow to test: {shadowed}");
    assert!(lit > 1000);
}

#[test]
fn board_pixels_follow_the_radiometric_normaliser() {
    let scene = scene_edited("sphere.toml", without_effects);
    let r = Renderer::new(&scene, small(128, 96)).unwrap();
    let f = r.render_frame(0).unwrap();
    let pose = scene.camera_poses[0].world_from_camera;
    let ctx = shade::PoseContext::new(&scene, pose);
    let mut checked = 0;
    for (x, y) in (0..96u32)
        .step_by(7)
        .flat_map(|y| (0..128u32).step_by(9).map(move |x| (x, y)))
    {
        let d = r.ray_camera(f64::from(x), f64::from(y), &mut StageCounts::default());
        let ray = Ray::new(pose.translation.vector.into(), pose.rotation * d);
        let Some(hit) = scene.intersect(&ray, 0.0, f64::INFINITY) else {
            continue;
        };
        let crate::scene::SurfaceKind::Board { albedo, .. } = hit.kind else {
            continue;
        };
        let to_flash = ctx.flash_world - hit.hit.point;
        let dist = to_flash.norm();
        let cos_i = hit.hit.normal_shading.dot(&(to_flash / dist));
        let theta = (-(to_flash / dist)).dot(&ctx.flash_axis_world).acos();
        let m = 0.5 * f64::from(albedo) * cos_i;
        let expected = r.radiometry().normaliser(dist, theta, d.z.acos()) * m;
        let got = f64::from(f.dn[(y * 128 + x) as usize]);
        assert!(
            (got - expected).abs() < 1e-3 * expected.max(1.0),
            "({x}, {y}): {got} vs {expected}"
        );
        checked += 1;
    }
    assert!(checked >= 20, "only {checked} board pixels");
}

#[test]
fn frame_index_past_the_capture_is_an_error() {
    let scene = Scene::load(&scene_path("calibration.toml")).unwrap();
    let r = Renderer::new(&scene, small(64, 48)).unwrap();
    let n = r.frame_count();
    assert!(matches!(
        r.render_frame(n),
        Err(RenderError::FrameOutOfRange { .. })
    ));
    let bad = RenderOptions {
        resolution_px: Some([63, 48]),
        ..RenderOptions::default()
    };
    assert!(matches!(
        Renderer::new(&scene, bad),
        Err(RenderError::Resolution { .. })
    ));
    let bad = RenderOptions {
        supersampling: 0,
        ..RenderOptions::default()
    };
    assert!(Renderer::new(&scene, bad).is_err());
}

#[test]
fn rendered_calibration_board_is_detected_with_accurate_corners() {
    let scene = Scene::load(&scene_path("calibration.toml")).unwrap();
    let (w, h) = (816u32, 680u32);
    let opts = RenderOptions {
        resolution_px: Some([w, h]),
        ..RenderOptions::default()
    };
    let r = Renderer::new(&scene, opts).unwrap();
    let f = r.render_frame(0).unwrap();
    // s0-like image: I90 + I0 per superpixel (one diagonal), scaled to 8 bits.
    let (sw, sh) = ((w / 2) as usize, (h / 2) as usize);
    let full = r.radiometry().full_scale_dn() as f32;
    let grey: Vec<u8> = (0..sw * sh)
        .map(|i| {
            let (sx, sy) = (i % sw, i / sw);
            let at = |dx: usize, dy: usize| f.dn[(2 * sy + dy) * w as usize + 2 * sx + dx];
            ((at(0, 0) + at(1, 1)) / (2.0 * full) * 255.0 * 2.0).clamp(0.0, 255.0) as u8
        })
        .collect();
    let found = crate::tag_checks::detect::detect_tag36h11(&grey, sw, sh);
    assert!(found.len() >= 20, "only {} tags detected", found.len());
    let pose = scene.camera_poses[0].world_from_camera;
    let board = &scene.boards[0];
    let mut errors = Vec::new();
    for (id, corners) in &found {
        let truth = board
            .tag_corners_world_m(*id)
            .expect("detected id is on the board");
        for (c, p) in corners.iter().zip(truth) {
            let px = r
                .camera()
                .project(&pose.inverse_transform_point(&p))
                .unwrap();
            // Superpixel (X, Y) covers raw pixels 2X..2X+1: its centre is raw 2X + 0.5.
            let expected = [(px[0] - 0.5) / 2.0, (px[1] - 0.5) / 2.0];
            errors.push(((c[0] - expected[0]).powi(2) + (c[1] - expected[1]).powi(2)).sqrt());
        }
    }
    errors.sort_by(f64::total_cmp);
    let median = errors[errors.len() / 2];
    assert!(median < 0.35, "median corner error {median} superpixels");
}

#[test]
fn raw_into_a_caller_buffer_matches_the_frame_and_checks_its_size() {
    let scene = Scene::load(&scene_path("sphere.toml")).unwrap();
    let r = Renderer::new(&scene, small(64, 48)).unwrap();
    let mut buf = vec![0u16; 64 * 48];
    let (truth, counts) = r.render_raw_into(2, &mut buf).unwrap();
    let f = r.render_frame(2).unwrap();
    assert_eq!(buf, f.raw());
    assert_eq!((truth, counts), (f.truth, f.counts));
    let mut short = vec![0u16; 10];
    assert!(matches!(
        r.render_raw_into(2, &mut short),
        Err(RenderError::BufferSize { len: 10, .. })
    ));
}

#[test]
fn motion_blur_smears_the_frame_but_keeps_its_energy() {
    let scene = scene_edited("multi_material.toml", |t| {
        without_effects(t)
            + "\n[effects]\nmotion_blur = { samples = 8, linear_speed_m_per_s = 2.0, angular_speed_deg_per_s = 200.0 }\n"
    });
    let r = Renderer::new(&scene, small(96, 80)).unwrap();
    let blurred = r.render_frame(3).unwrap();
    let mut plan = r.plan().clone();
    plan.stages.retain(|s| s.stage != Stage::MotionBlur);
    let sharp = Renderer::with_plan(&scene, plan, small(96, 80))
        .unwrap()
        .render_frame(3)
        .unwrap();
    assert_eq!(sharp.counts.get(Stage::MotionBlur), 0);
    assert_eq!(blurred.counts.get(Stage::MotionBlur), 96 * 80 * 8);
    let changed = blurred
        .dn
        .iter()
        .zip(&sharp.dn)
        .filter(|(a, b)| a != b)
        .count();
    assert!(changed > 96 * 80 / 10, "only {changed} pixels changed");
    let sum = |v: &[f32]| v.iter().map(|x| f64::from(*x)).sum::<f64>();
    let ratio = sum(&blurred.dn) / sum(&sharp.dn);
    assert!((ratio - 1.0).abs() < 0.1, "energy ratio {ratio}");
    // The truth pose is the mid-exposure (listed) pose either way.
    assert_eq!(blurred.truth, sharp.truth);
}

#[test]
fn vignetting_scales_each_pixel_by_cos_n_of_its_field_angle() {
    let plain = Scene::load(&scene_path("s0_only.toml")).unwrap();
    let vignetted = scene_edited("s0_only.toml", |t| {
        t + "\n[effects]\nvignetting = { exponent = 4.0 }\n"
    });
    let r = Renderer::new(&vignetted, small(64, 54)).unwrap();
    let a = Renderer::new(&plain, small(64, 54))
        .unwrap()
        .render_frame(0)
        .unwrap();
    let b = r.render_frame(0).unwrap();
    let mut checked = 0;
    for y in 0..54u32 {
        for x in 0..64u32 {
            let i = (y * 64 + x) as usize;
            if a.dn[i] < 1.0 {
                continue;
            }
            let d = r.ray_camera(f64::from(x), f64::from(y), &mut StageCounts::default());
            let ratio = f64::from(b.dn[i]) / f64::from(a.dn[i]);
            assert!(
                (ratio - d.z.powi(4)).abs() < 1e-5,
                "({x}, {y}): {ratio} vs {}",
                d.z.powi(4)
            );
            checked += 1;
        }
    }
    assert!(checked > 300, "only {checked} lit pixels");
    // Corners are measurably darker than the centre.
    let c = r
        .ray_camera(0.0, 0.0, &mut StageCounts::default())
        .z
        .powi(4);
    assert!(c < 0.99);
}

#[test]
fn colour_mosaic_pixels_see_their_filter_channel() {
    // glossy_plastic has rho_d = [0.60, 0.10, 0.08]: red pixels on it are far brighter than blue.
    let scene = scene_edited("multi_material.toml", without_effects);
    let plastic = scene.material_id("glossy_plastic").unwrap() as u16;
    let opts = RenderOptions {
        pixel_truth: true,
        ..small(128, 108)
    };
    let r = Renderer::new(&scene, opts).unwrap();
    assert_eq!(r.layout(), SensorLayout::ColourPolar);
    let (mut sum, mut n) = ([0.0f64; 3], [0usize; 3]);
    for k in 0..6 {
        let f = r.render_frame(k).unwrap();
        let truth = f.pixels.as_ref().unwrap();
        for y in 0..108u32 {
            for x in 0..128u32 {
                let i = (y * 128 + x) as usize;
                // I90 pixels only: the cross-polarised, mostly diffuse channel.
                if truth.material[i] != plastic || r.layout().analyser_deg_at(x, y) != 90.0 {
                    continue;
                }
                let c = r.layout().colour_at(x, y).unwrap().index();
                sum[c] += f64::from(f.dn[i]);
                n[c] += 1;
            }
        }
    }
    assert!(n[0] > 5 && n[2] > 5, "too few plastic pixels: {n:?}");
    let (red, blue) = (sum[0] / n[0] as f64, sum[2] / n[2] as f64);
    assert!(red > 3.0 * blue, "red {red}, blue {blue}");
}

mod invariants;
