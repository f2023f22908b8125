//! Effects on demand, proven: a scene runs only the stages its plan holds (execution counts of
//! a real render), and adding one effect changes only that stage's count.

use super::*;
use crate::render::{RenderOptions, Renderer};
use crate::scene::Scene;
use std::path::Path;

fn scene_edited(name: &str, edit: impl Fn(String) -> String) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap();
    Scene::from_toml_str(&edit(text), &path).unwrap()
}

/// The S0-only scene with a purely diffuse ball (ρ_s = 0 and ρ_ss = 0).
fn plain_s0(extra: &str) -> Scene {
    let extra = extra.to_string();
    scene_edited("s0_only.toml", move |t| {
        t.replace("rho_s = 0.2", "rho_s = 0.0") + &extra
    })
}

fn counts(scene: &Scene) -> StageCounts {
    let opts = RenderOptions {
        supersampling: 1,
        resolution_px: Some([48, 40]),
        ..RenderOptions::default()
    };
    Renderer::new(scene, opts)
        .unwrap()
        .render_frame(0)
        .unwrap()
        .counts
}

#[test]
fn s0_only_scene_runs_no_polarisation_specular_or_sensor_stages() {
    let scene = plain_s0("");
    let plan = EffectPlan::from_scene(&scene);
    assert_eq!(plan.transport, LightTransport::Scalar);
    let c = counts(&scene);
    for s in Stage::ALL {
        if plan.contains(s) {
            continue;
        }
        assert_eq!(c.get(s), 0, "{} ran but is not planned", s.name());
    }
    for s in [
        Stage::Polarisation,
        Stage::DiffusePolarisation,
        Stage::Specular,
        Stage::SingleScattering,
        Stage::PolariserExtinction,
        Stage::ShotNoise,
        Stage::ReadNoise,
    ] {
        assert!(!plan.contains(s), "{}", s.name());
    }
    assert!(c.get(Stage::Diffuse) > 0 && c.get(Stage::Shadows) > 0);
}

#[test]
fn adding_one_effect_changes_only_its_own_count() {
    let base = counts(&plain_s0(""));
    let noisy = counts(&plain_s0("\n[effects]\nread_noise = { sigma_e = 2.0 }\n"));
    assert_eq!(base.differing(&noisy), vec![Stage::ReadNoise]);
    assert_eq!(noisy.get(Stage::ReadNoise), 48 * 40);
    let scattering = counts(&scene_edited("s0_only.toml", |t| {
        t.replace("rho_s = 0.2", "rho_s = 0.0")
            .replace("rho_ss = [0.0, 0.0, 0.0]", "rho_ss = [0.1, 0.1, 0.1]")
    }));
    assert_eq!(base.differing(&scattering), vec![Stage::SingleScattering]);
    let specular = counts(&scene_edited("s0_only.toml", |t| t));
    assert_eq!(base.differing(&specular), vec![Stage::Specular]);
}

#[test]
fn analysers_bring_in_the_stokes_path_and_diffuse_polarisation() {
    let scene = scene_edited("s0_only.toml", |t| {
        t.replace("analysers = false", "analysers = true")
    });
    let plan = EffectPlan::from_scene(&scene);
    assert_eq!(plan.transport, LightTransport::Stokes);
    assert!(plan.contains(Stage::Polarisation) && plan.contains(Stage::DiffusePolarisation));
    let c = counts(&scene);
    assert!(c.get(Stage::Polarisation) > 0);
    assert_eq!(
        c.get(Stage::DiffusePolarisation),
        c.get(Stage::Polarisation)
    );
}

#[test]
fn full_scene_plans_every_listed_effect_and_hands_faults_to_the_rig() {
    let scene = scene_edited("multi_material.toml", |t| t);
    let plan = EffectPlan::from_scene(&scene);
    // Everything but lens distortion (the scene's lens has no distortion coefficients) and the
    // real sensor's and flash's effects (the scene describes the rig the fit assumes).
    let unlisted = [
        Stage::LensDistortion,
        Stage::AnalyserErrors,
        Stage::Prnu,
        Stage::BlackLevel,
        Stage::HotPixels,
        Stage::FlashPolariserError,
        Stage::FlashProfileError,
    ];
    for s in Stage::ALL {
        assert_eq!(plan.contains(s), !unlisted.contains(&s), "{}", s.name());
    }
    assert_eq!(plan.omitted.len(), unlisted.len());
    let f = plan.rig_faults();
    assert_eq!(f.trigger_jitter.unwrap().sigma_us, 20.0);
    assert_eq!(f.frame_drops.unwrap().probability, 0.01);
    assert_eq!(f.link_corruption.unwrap().bit_error_rate, 1e-6);
    assert_eq!(f.link_disconnect.unwrap().at_frame, 120);
    let rig: Vec<_> = plan
        .stages
        .iter()
        .filter(|s| s.executor == Executor::Rig)
        .map(|s| s.stage)
        .collect();
    assert_eq!(
        rig,
        [
            Stage::TriggerJitter,
            Stage::FrameDrops,
            Stage::LinkCorruption,
            Stage::LinkDisconnect
        ]
    );
    // The renderer never executes rig stages.
    let c = counts(&scene);
    for s in rig {
        assert_eq!(c.get(s), 0);
    }
    assert!(c.get(Stage::MotionBlur) > 0 && c.get(Stage::Vignetting) > 0);
    let table = plan.to_table();
    assert!(table.contains("link_disconnect") && table.contains("at_frame = 120"));
}

#[test]
fn a_static_rig_has_no_motion_blur_and_a_lone_sphere_no_shadows() {
    let scene = scene_edited("multi_material.toml", |t| {
        t.replace(
            "linear_speed_m_per_s = 0.05, angular_speed_deg_per_s = 10.0",
            "linear_speed_m_per_s = 0.0, angular_speed_deg_per_s = 0.0",
        )
    });
    let plan = EffectPlan::from_scene(&scene);
    assert!(!plan.contains(Stage::MotionBlur));
    assert!(
        plan.omitted
            .iter()
            .any(|o| o.stage == Stage::MotionBlur && o.reason.contains("static"))
    );
    let lone = scene_edited("s0_only.toml", |t| {
        let cut = t.find("[[boards]]").unwrap();
        let rest = &t[cut..];
        let next = rest.find("[rig.camera]").unwrap();
        format!("{}{}", &t[..cut], &rest[next..])
    });
    let plan = EffectPlan::from_scene(&lone);
    assert!(!plan.contains(Stage::Shadows));
    assert_eq!(counts(&lone).get(Stage::Shadows), 0);
}

#[test]
fn real_sensor_effects_cost_one_draw_per_raw_pixel_only_when_listed() {
    let base = scene_edited("sphere.toml", |t| t);
    let c0 = counts(&base);
    for s in [
        Stage::AnalyserErrors,
        Stage::Prnu,
        Stage::BlackLevel,
        Stage::HotPixels,
    ] {
        assert_eq!(c0.get(s), 0, "{}", s.name());
    }
    let scene = scene_edited("sphere.toml", |t| {
        t.replace(
            "[effects]",
            "[effects]\nblack_level = { dn = 64.0, dsnu_dn = 1.0 }\nprnu = { sigma_rel = 0.01 }\n\
             analyser_errors = { angle_sigma_deg = 1.0, extinction_ratio_rgb = [150.0, 250.0, 80.0] }\n\
             hot_pixels = { fraction = 0.0001, dn = 200.0 }\nflash_polariser_error = { angle_deg = 1.0 }\n\
             flash_profile_error = { exponent = 2.0 }",
        )
    });
    let plan = EffectPlan::from_scene(&scene);
    let c = counts(&scene);
    for s in [
        Stage::AnalyserErrors,
        Stage::Prnu,
        Stage::BlackLevel,
        Stage::HotPixels,
    ] {
        assert!(plan.contains(s));
        assert_eq!(c.get(s), 48 * 40, "{}: one draw per raw pixel", s.name());
    }
    assert!(plan.contains(Stage::FlashPolariserError) && plan.contains(Stage::FlashProfileError));
    // everything else runs exactly as often as without the new effects
    for s in Stage::ALL {
        if ![
            Stage::AnalyserErrors,
            Stage::Prnu,
            Stage::BlackLevel,
            Stage::HotPixels,
        ]
        .contains(&s)
        {
            assert_eq!(c.get(s), c0.get(s), "{}", s.name());
        }
    }
}
