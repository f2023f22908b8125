//! Synthetic samples with known truth, for the solver's tests and the accuracy benchmark.
//!
//! Contract:
//! - [`synthesize_vertex`] renders one vertex through the SAME optics as the simulator
//!   (`pbrdf::apply` with the view's flash Stokes vector, then the four analysers at their
//!   effective angles for the ray, `ViewGeometry::analyser_angles`), scales by the normaliser N (DN per model
//!   unit), adds sensor noise in electrons (shot noise as a Gaussian of variance = electrons,
//!   Gaussian read noise), quantises to integer DN and clips at full scale, then gates every
//!   sample with the shared [`GateConfig`] rules and counts the reasons, exactly as observation
//!   extraction does for real frames. Kept samples hold the observation channels divided by N.
//! - `noise = None` is an ideal sensor: no noise, no quantisation, no clipping, and therefore
//!   no dark or saturation gate (only non-finite and grazing apply).
//! - A monochrome sensor (`colour = false`) sees the mean of the three colour channels (the
//!   model is linear in the albedos, so that is the response of the mean albedos); the three
//!   channel entries of a sample are then equal.
//! - [`orbit_views`] places cameras on a spiral orbit around a point, with the flash rigidly
//!   offset in the camera frame and its polariser along the camera's x axis (image right), i.e.
//!   parallel to the 0° analyser as on the rig (docs/model.md §6 "Observation channels").

use ellipso_model::optics::Stokes;
use ellipso_model::optics::Vec3;
use ellipso_model::optics::measure::SensorIntensities;
use ellipso_model::optics::pbrdf::{PbrdfParams, apply};
use ellipso_model::radiometry::Radiometry;
use nalgebra::{Point3, Vector3};
use rand_distr::{Distribution, StandardNormal};

use super::data::{
    GateCounts, OBSERVATION_CHANNELS, Sample, SampleGeometry, VertexSamples, ViewGeometry,
};
use super::gate::GateConfig;

/// The sensor's noise and range, in the units the renderer uses.
#[derive(Clone, Debug, PartialEq)]
pub struct SensorNoise {
    /// The ADC's largest code, DN.
    pub full_scale_dn: f64,
    /// DN per electron (ADC scale × analogue gain).
    pub dn_per_electron: f64,
    /// Read noise, electrons RMS.
    pub read_noise_e: f64,
    /// Whether photon shot noise is applied.
    pub shot_noise: bool,
}

impl SensorNoise {
    /// The sensor of a radiometric chain, with `read_noise_e` electrons RMS read noise.
    pub fn from_radiometry(radiometry: &Radiometry, read_noise_e: f64, shot_noise: bool) -> Self {
        Self {
            full_scale_dn: radiometry.full_scale_dn(),
            dn_per_electron: radiometry.dn_per_electron(),
            read_noise_e,
            shot_noise,
        }
    }

    /// One noisy, quantised, clipped reading of an expected `dn`.
    fn read(&self, dn: f64, rng: &mut impl rand::Rng) -> f64 {
        // dn_per_electron > 0 for any real sensor; the floor keeps the division finite.
        let gain = self.dn_per_electron.max(1e-12);
        let electrons = (dn / gain).max(0.0);
        let mut noisy = electrons;
        if self.shot_noise {
            let z: f64 = StandardNormal.sample(rng);
            noisy += electrons.sqrt() * z;
        }
        if self.read_noise_e > 0.0 {
            let z: f64 = StandardNormal.sample(rng);
            noisy += self.read_noise_e * z;
        }
        (noisy * gain).round().clamp(0.0, self.full_scale_dn)
    }
}

/// Synthesises the gated samples of one vertex (see the module doc). `normaliser(view, geometry)`
/// gives N (DN per model unit) for each visible view.
#[expect(
    clippy::too_many_arguments,
    reason = "the generator's inputs are independent knobs of the synthetic capture"
)]
pub fn synthesize_vertex(
    views: &[ViewGeometry],
    vertex: u32,
    position_world: [f64; 3],
    normal_world: [f64; 3],
    truth: &PbrdfParams<f64>,
    normaliser: &dyn Fn(&ViewGeometry, &SampleGeometry) -> f64,
    noise: Option<&SensorNoise>,
    colour: bool,
    gate: &GateConfig,
    rng: &mut impl rand::Rng,
) -> VertexSamples {
    let mut gates = GateCounts::default();
    let mut samples = Vec::with_capacity(views.len());
    let position = Point3::from(position_world);
    let normal = Vector3::from(normal_world).normalize();
    let mono_truth = PbrdfParams {
        rho_ss: [truth.rho_ss.iter().sum::<f64>() / 3.0; 3],
        rho_d: [truth.rho_d.iter().sum::<f64>() / 3.0; 3],
        ..*truth
    };
    let params = if colour { truth } else { &mono_truth };
    let channels = if colour { 3 } else { 1 };
    // An ideal sensor has no range: only the non-finite and grazing gates apply.
    let ideal_gate = GateConfig {
        dark_fraction: 0.0,
        ..gate.clone()
    };
    for (index, view) in views.iter().enumerate() {
        let Some(g) = view.geometry_at(&position) else {
            gates.not_in_view += 1;
            continue;
        };
        let cos_o = normal.dot(&Vector3::from(g.to_camera));
        let cos_i = normal.dot(&Vector3::from(g.to_light));
        if cos_o <= 0.0 || cos_i <= 0.0 {
            gates.not_in_view += 1;
            continue;
        }
        let Ok(model) = g.model::<f64>(Vec3::from_f64(normal.into())) else {
            gates.not_in_view += 1;
            continue;
        };
        let s_light = if view.polarised() {
            view.flash_polariser().stokes(1.0)
        } else {
            Stokes::unpolarised(1.0)
        };
        let stokes = apply(&model, params, s_light);
        let n = normaliser(view, &g);
        let angles = view.analyser_angles(&g);
        let mut analysers_dn = [[0f32; 4]; 3];
        for (c, s) in stokes.iter().enumerate().take(channels) {
            let i = angles.intensities(*s);
            for (k, v) in [i.i0, i.i45, i.i90, i.i135].into_iter().enumerate() {
                let dn = n * v;
                let read = match noise {
                    Some(sensor) => sensor.read(dn, rng),
                    None => dn,
                };
                analysers_dn[c][k] = read as f32;
            }
        }
        let (check_gate, full_scale) = match noise {
            Some(sensor) => (gate, sensor.full_scale_dn),
            None => (&ideal_gate, f64::INFINITY),
        };
        if let Err(reason) = check_gate.check_sample(&analysers_dn, channels, full_scale, cos_o) {
            reason.count(&mut gates);
            continue;
        }
        let mut obs = [[0f32; OBSERVATION_CHANNELS]; 3];
        for (c, entry) in obs.iter_mut().enumerate() {
            let a = analysers_dn[c.min(channels - 1)].map(f64::from);
            let o = SensorIntensities {
                i0: a[0],
                i45: a[1],
                i90: a[2],
                i135: a[3],
            }
            .observation();
            *entry = [o.diffuse, o.specular, o.alpha, a[1] + a[3]].map(|v| (v / n) as f32);
        }
        gates.kept += 1;
        samples.push(Sample {
            view: index as u32,
            channels: obs,
            normaliser: n as f32,
        });
    }
    gate.reject_colour_outliers(&mut samples, colour, &mut gates);
    VertexSamples {
        vertex,
        position_world,
        normal_world: normal.into(),
        samples,
        gates,
    }
}

/// `count` views on a spiral orbit of `radius_m` around `look_at`: azimuth sweeps `turns` full
/// turns while the elevation goes linearly from `elevation_deg[0]` to `elevation_deg[1]`. Each
/// camera looks at `look_at` with image up as close to world +z as possible; the flash sits at
/// `flash_offset_camera_m` in the OpenCV camera frame (x right, y down, z forward) and its
/// polariser axis is the camera's x (image right).
pub fn orbit_views(
    count: usize,
    radius_m: f64,
    elevation_deg: [f64; 2],
    turns: f64,
    look_at: [f64; 3],
    flash_offset_camera_m: [f64; 3],
) -> Vec<ViewGeometry> {
    let target = Vector3::from(look_at);
    (0..count)
        .map(|k| {
            let t = if count > 1 {
                k as f64 / (count - 1) as f64
            } else {
                0.0
            };
            let azimuth = std::f64::consts::TAU * turns * t;
            let elevation =
                (elevation_deg[0] + (elevation_deg[1] - elevation_deg[0]) * t).to_radians();
            let dir = Vector3::new(
                elevation.cos() * azimuth.cos(),
                elevation.cos() * azimuth.sin(),
                elevation.sin(),
            );
            let camera = target + dir * radius_m;
            let forward = -dir;
            // Looking straight down: the azimuth direction stands in for world up.
            let right = forward
                .cross(&Vector3::z())
                .try_normalize(1e-9)
                .unwrap_or_else(|| Vector3::new(-azimuth.sin(), azimuth.cos(), 0.0));
            let up = right.cross(&forward);
            let o = flash_offset_camera_m;
            let flash = camera + right * o[0] - up * o[1] + forward * o[2];
            ViewGeometry {
                frame_id: k as u64,
                camera_position_world: camera.into(),
                camera_up_world: up.into(),
                flash_position_world: flash.into(),
                polariser_axis_world: Some(right.into()),
                camera_axis_world: Some(forward.into()),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn truth() -> PbrdfParams<f64> {
        PbrdfParams {
            eta: 1.49,
            sigma_s: 0.1,
            sigma_ss: 0.3,
            rho_s: 1.0,
            rho_ss: [0.1, 0.08, 0.06],
            rho_d: [0.6, 0.1, 0.08],
        }
    }

    #[test]
    fn orbit_cameras_look_at_the_target_with_polariser_along_image_right() {
        let views = orbit_views(
            20,
            0.5,
            [20.0, 70.0],
            1.5,
            [0.0, 0.0, 0.04],
            [0.0, 0.03, 0.0],
        );
        for v in &views {
            let c = Vector3::from(v.camera_position_world);
            let to_target = Vector3::new(0.0, 0.0, 0.04) - c;
            assert!((to_target.norm() - 0.5).abs() < 1e-12);
            let up = Vector3::from(v.camera_up_world);
            let axis = Vector3::from(v.polariser_axis_world.unwrap());
            assert!(up.dot(&to_target).abs() < 1e-12 && axis.dot(&to_target).abs() < 1e-12);
            assert!(up.z > 0.0, "image up points up");
            // The flash sits 3 cm below the lens (OpenCV +y is image down).
            let f = Vector3::from(v.flash_position_world) - c;
            assert!((f + up * 0.03).norm() < 1e-12);
        }
    }

    #[test]
    #[expect(clippy::needless_range_loop, reason = "parallel per-channel arrays")]
    fn noiseless_samples_equal_the_model_and_noise_is_gated() {
        let views = orbit_views(60, 0.5, [20.0, 70.0], 1.5, [0.0; 3], [0.0, 0.03, 0.0]);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = |_: &ViewGeometry, g: &SampleGeometry| 3000.0 * 0.25 / g.light_distance_m.powi(2);
        let gate = GateConfig::default();
        let normal = [0.0, 0.0, 1.0];
        let v = synthesize_vertex(
            &views,
            5,
            [0.0; 3],
            normal,
            &truth(),
            &n,
            None,
            true,
            &gate,
            &mut rng,
        );
        assert!(v.samples.len() > 40);
        assert_eq!(v.gates.kept as usize, v.samples.len());
        for s in &v.samples {
            let view = &views[s.view as usize];
            let g = view.geometry_at(&Point3::origin()).unwrap();
            let m = g.model::<f64>(Vec3::from_f64(normal)).unwrap();
            let o = ellipso_model::optics::measure::observe(&m, &truth(), view.flash_polariser());
            for c in 0..3 {
                // I^t = I45 + I135 = s0 = I^d + I^s for ideal analysers (on the axis).
                let want = [
                    o[c].diffuse,
                    o[c].specular,
                    o[c].alpha,
                    o[c].diffuse + o[c].specular,
                ];
                for k in 0..4 {
                    let got = f64::from(s.channels[c][k]);
                    assert!((got - want[k]).abs() < 1e-6 * (1.0 + want[k].abs()));
                }
            }
        }
        // A bright sensor saturates the highlight; a dim one goes dark.
        let hot = SensorNoise {
            full_scale_dn: 4095.0,
            dn_per_electron: 0.4,
            read_noise_e: 2.3,
            shot_noise: true,
        };
        let bright = |_: &ViewGeometry, _: &SampleGeometry| 40_000.0;
        let v = synthesize_vertex(
            &views,
            5,
            [0.0; 3],
            normal,
            &truth(),
            &bright,
            Some(&hot),
            true,
            &gate,
            &mut rng,
        );
        assert!(v.gates.saturated > 0, "{:?}", v.gates);
        let dim = |_: &ViewGeometry, _: &SampleGeometry| 2.0;
        let v = synthesize_vertex(
            &views,
            5,
            [0.0; 3],
            normal,
            &truth(),
            &dim,
            Some(&hot),
            true,
            &gate,
            &mut rng,
        );
        assert!(v.samples.is_empty() && v.gates.dark > 40, "{:?}", v.gates);
        // Back-facing views are not in view.
        let v = synthesize_vertex(
            &views,
            5,
            [0.0; 3],
            [0.0, 0.0, -1.0],
            &truth(),
            &n,
            None,
            true,
            &gate,
            &mut rng,
        );
        assert_eq!(v.gates.not_in_view, 60);
    }
}
