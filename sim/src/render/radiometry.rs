//! The renderer's radiometry: the chain itself ([`Radiometry`], with its units and camera
//! equation) lives in `ellipso_model::radiometry`, shared with the fit; this module re-exports it
//! and adds the per-scene convenience [`normaliser`], tested against the shipped scenes.

pub use ellipso_model::radiometry::{
    CameraRadiometry, PHOTON_ENERGY_J, Radiometry, SYSTEM_CALIBRATION, SensorNoiseSpec,
};
use ellipso_model::rig::{CameraSpec, FlashSpec};

use crate::effects::{EffectPlan, Stage, StageParams};
use crate::scene::Scene;

/// What a session records of a scene's camera, so that its fit needs no scene file: the
/// camera-equation parameters with the planned vignetting, the sensor noise and the analysers'
/// extinction ratio (see [`recorded_sensor`]).
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedSensor {
    /// Camera-equation parameters, vignetting exponent as the effect plan applies it.
    pub radiometry: CameraRadiometry,
    /// Read noise, shot noise, quantisation, conversion gain of the scene's camera.
    pub noise: SensorNoiseSpec,
    /// Extinction ratio of the on-chip analysers when the plan simulates it (`None`: ideal).
    pub analyser_extinction_ratio: Option<f64>,
}

/// The sensor of `scene` as its renderer simulates it ([`RecordedSensor`]).
pub fn recorded_sensor(scene: &Scene) -> RecordedSensor {
    let plan = EffectPlan::from_scene(scene);
    let vignetting_exponent = match plan.params(Stage::Vignetting) {
        Some(StageParams::Vignetting(v)) => Some(v.exponent),
        _ => None,
    };
    let analyser_extinction_ratio = match plan.params(Stage::PolariserExtinction) {
        Some(StageParams::PolariserExtinction(x)) => Some(x.ratio),
        _ => None,
    };
    let camera = &scene.rig.camera;
    RecordedSensor {
        radiometry: camera.radiometry(vignetting_exponent),
        noise: SensorNoiseSpec {
            read_noise_e: scene.effects.read_noise.as_ref().map_or(0.0, |n| n.sigma_e),
            shot_noise: scene.effects.shot_noise.is_some(),
            quantised: scene.effects.quantisation.is_some(),
            gain_db: camera.gain_db,
            full_well_e: camera.full_well_e,
            bit_depth: camera.bit_depth,
        },
        analyser_extinction_ratio,
    }
}

/// The normaliser N for a scene's rig (see [`Radiometry::normaliser`]); `vignetting_exponent`
/// as planned (`scene.effects.vignetting.map(|v| v.exponent)`).
pub fn normaliser(
    camera: &CameraSpec,
    flash: &FlashSpec,
    vignetting_exponent: Option<f64>,
    flash_to_point_distance_m: f64,
    angle_from_flash_axis_rad: f64,
    field_angle_rad: f64,
) -> f64 {
    Radiometry::new(camera, flash, vignetting_exponent).normaliser(
        flash_to_point_distance_m,
        angle_from_flash_axis_rad,
        field_angle_rad,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use ellipso_model::rig::FlashProfileKind;
    use std::path::Path;

    fn sphere_scene() -> Scene {
        Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sphere.toml")).unwrap()
    }

    #[test]
    fn white_board_on_axis_sits_mid_scale_in_the_sphere_scene() {
        let s = sphere_scene();
        let r = Radiometry::new(&s.rig.camera, &s.rig.flash, None);
        // White paper (0.85) seen head-on through an analyser: m = ½ · 0.85.
        let dn = r.normaliser(0.5, 0.0, 0.0) * 0.5 * 0.85;
        let fraction = dn / r.full_scale_dn();
        assert!((0.3..0.6).contains(&fraction), "white board at {fraction}");
    }

    #[test]
    fn normaliser_scales_as_inverse_square_exposure_and_gain() {
        let s = sphere_scene();
        let mut cam = s.rig.camera.clone();
        let f = s.rig.flash.clone();
        let n1 = normaliser(&cam, &f, None, 0.5, 0.0, 0.0);
        assert!((normaliser(&cam, &f, None, 1.0, 0.0, 0.0) * 4.0 / n1 - 1.0).abs() < 1e-12);
        cam.exposure_us *= 2.0;
        assert!((normaliser(&cam, &f, None, 0.5, 0.0, 0.0) / n1 - 2.0).abs() < 1e-12);
        cam.gain_db = 20.0;
        assert!((normaliser(&cam, &f, None, 0.5, 0.0, 0.0) / n1 - 20.0).abs() < 1e-9);
        // cos^4 at 30° off axis; cos^1 flash profile at 60°.
        let v = normaliser(&s.rig.camera, &f, Some(4.0), 0.5, 0.0, 30f64.to_radians());
        assert!((v / n1 - 30f64.to_radians().cos().powi(4)).abs() < 1e-12);
        let p = normaliser(&s.rig.camera, &f, None, 0.5, 60f64.to_radians(), 0.0);
        assert!((p / n1 - 0.5).abs() < 1e-12);
    }

    #[test]
    fn cosine_and_angle_forms_agree_for_both_profile_kinds() {
        let s = sphere_scene();
        let mut flash = s.rig.flash.clone();
        for exponent in [None, Some(1.0), Some(3.5)] {
            flash.profile.exponent = exponent;
            let r = Radiometry::new(&s.rig.camera, &flash, Some(4.0));
            for deg in [0.0f64, 10.0, 45.0, 89.0, 120.0] {
                let a = r.flash_irradiance_w_per_m2(0.4, deg.to_radians());
                let b = r.flash_irradiance_from_cos(0.4, deg.to_radians().cos());
                assert!(
                    (a - b).abs() <= 1e-12 * a.max(1.0),
                    "{exponent:?} {deg}: {a} {b}"
                );
                let v =
                    r.vignetting(deg.to_radians()) - r.vignetting_from_cos(deg.to_radians().cos());
                assert!(v.abs() < 1e-12);
            }
        }
        flash.profile.kind = FlashProfileKind::Table;
        flash.profile.angle_deg = Some(vec![0.0, 30.0, 60.0]);
        flash.profile.relative = Some(vec![1.0, 0.5, 0.1]);
        let r = Radiometry::new(&s.rig.camera, &flash, None);
        let a = r.flash_irradiance_w_per_m2(0.4, 45f64.to_radians());
        let b = r.flash_irradiance_from_cos(0.4, 45f64.to_radians().cos());
        assert!((a - b).abs() <= 1e-9 * a && (a / (0.5 / 0.16) - 0.3).abs() < 1e-9);
    }

    #[test]
    fn tiny_distances_stay_finite() {
        let s = sphere_scene();
        let n = normaliser(&s.rig.camera, &s.rig.flash, None, 0.0, 0.0, 0.0);
        assert!(n.is_finite() && n > 0.0);
    }
}
