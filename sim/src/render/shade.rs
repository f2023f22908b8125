//! Shading one ray sample: what one primary ray, through one raw pixel with its analyser and
//! colour filter, contributes in flash-irradiance × model-intensity units (W/m², see
//! [`super::radiometry`]).
//!
//! Contract:
//! - Only the stages in the plan's [`StageSet`] run, each counted in [`StageCounts`] once per
//!   execution; lobes whose albedo is zero at the hit are skipped and not counted.
//! - Objects use the pBRDF of [`ellipso_model::optics::pbrdf`] lobe by lobe, on the cheapest exact path
//!   of the plan's [`LightTransport`]:
//!   - `Stokes`: [`pbrdf::diffuse_unit`] and [`pbrdf::reflection_unit`] (Mueller matrices) applied
//!     to the flash Stokes vector, then the pixel's analyser;
//!   - `IntensityOfPolarised`: row 0 of each lobe applied to the polarised flash light (as
//!     [`pbrdf::evaluate_s0`]), no outgoing rotation;
//!   - `Scalar`: M00 of each lobe (as [`pbrdf::scalar_brdf`]), no rotation at all.
//!
//!   The three paths agree with `pbrdf::apply` / `evaluate_s0` / `scalar_brdf` (tested).
//! - Flash light: s_light = [1, 1, 0, 0] in the light frame whose x is the flash polariser's
//!   transmission axis ([`crate::scene::FlashSpec::polariser_axis_world`]); z = −ω_i, so the frame's
//!   up is y = z × x (docs/model.md §1 "Frames", §6 "Observation channels"). Unpolarised flash:
//!   [1, 0, 0, 0].
//! - Boards are matte paper: a Lambertian depolariser with the print albedo (no specular), so
//!   they never need Mueller work.
//! - Analyser at θ (nominal, plus the pixel's angle error when `analyser_errors` is planned) with
//!   extinction ratio ER (the pixel's own under `analyser_errors`, else the global one when
//!   `polariser_extinction` is planned; e = 1/ER, else 0):
//!   I = ½[(1 + e) s0 + (1 − e)(s1 cos2ψ + s2 sin2ψ)], ψ the wire grid's effective axis for the
//!   ray in the ray's camera frame (`PixelSensor::for_ray`; ψ = θ on the optical axis); a
//!   camera without analysers measures s0.

use crate::effects::{LightTransport, Stage, StageCounts, StageSet};
use crate::scene::{MaterialSample, Scene, SceneHit, SurfaceKind};
use ellipso_model::geometry::Ray;
use ellipso_model::optics::fresnel::FresnelTerms;
use ellipso_model::optics::pbrdf::{self, Geometry, PbrdfParams};
use ellipso_model::optics::{Rotator, Stokes, Vec3};
use nalgebra::{Isometry3, Point3, Unit, Vector3};

use super::radiometry::Radiometry;

/// Offset of shadow-ray origins along the geometric normal, metres (scenes are metre-scale;
/// 1 µm is far above f64 rounding at that scale and far below any modelled feature).
const SHADOW_OFFSET_M: f64 = 1e-6;

/// The camera and flash at one instant of the exposure.
#[derive(Clone, Debug)]
pub(crate) struct PoseContext {
    /// Camera to world at this instant.
    pub world_from_camera: Isometry3<f64>,
    /// Camera "up" (image up) in the world: −(camera y).
    pub camera_up_world: Vector3<f64>,
    /// Flash position, world.
    pub flash_world: Point3<f64>,
    /// Flash axis, world.
    pub flash_axis_world: Unit<Vector3<f64>>,
    /// Flash polariser transmission axis, world (`None`: unpolarised flash).
    pub polariser_axis_world: Option<Unit<Vector3<f64>>>,
}

impl PoseContext {
    /// The context of `world_from_camera` for a scene's flash as recorded.
    #[cfg(test)]
    pub fn new(scene: &Scene, world_from_camera: Isometry3<f64>) -> Self {
        Self::with_flash(&scene.rig.flash, world_from_camera)
    }

    /// The context of `world_from_camera` for `flash` (the true flash of a render).
    pub fn with_flash(
        flash: &ellipso_model::rig::FlashSpec,
        world_from_camera: Isometry3<f64>,
    ) -> Self {
        Self {
            camera_up_world: -(world_from_camera.rotation * Vector3::y()),
            flash_world: flash.position_world(&world_from_camera),
            flash_axis_world: flash.axis_world(&world_from_camera),
            polariser_axis_world: flash.polariser_axis_world(&world_from_camera),
            world_from_camera,
        }
    }
}

/// What one raw pixel measures: its analyser and colour response.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PixelSensor {
    /// Nominal analyser angle (from image right toward image up), radians.
    pub angle_rad: f64,
    /// `angle_rad.sin_cos()`, taken once per pixel for all of its rays.
    pub angle_sin_cos: (f64, f64),
    /// cos 2ψ of the analyser's effective axis for the ray being shaded (the nominal angle
    /// until [`PixelSensor::for_ray`]).
    pub cos2: f64,
    /// sin 2ψ of the same.
    pub sin2: f64,
    /// Colour weights over (R, G, B): one-hot under a colour filter, ⅓ each on a mono sensor.
    pub weights: [f64; 3],
    /// This pixel's own 1/ER when the sensor's fixed pattern gives it one (`analyser_errors`);
    /// `None`: the render's global extinction.
    pub extinction: Option<f64>,
}

impl PixelSensor {
    /// A pixel with an analyser at `angle_rad` and colour `weights`.
    pub fn new(angle_rad: f64, weights: [f64; 3]) -> Self {
        let (sin2, cos2) = (2.0 * angle_rad).sin_cos();
        Self {
            angle_rad,
            angle_sin_cos: angle_rad.sin_cos(),
            cos2,
            sin2,
            weights,
            extinction: None,
        }
    }

    /// The pixel for a primary ray along `dir_camera` (OpenCV camera frame, unit): its wire-grid
    /// analyser's effective axis in the ray's camera frame
    /// ([`ellipso_model::optics::measure::effective_cos_sin_2`], docs/model.md "Analysers off the
    /// optical axis") — the same model the fit inverts.
    pub fn for_ray(&self, dir_camera: &Vector3<f64>) -> Self {
        let to_camera = [-dir_camera.x, -dir_camera.y, -dir_camera.z];
        let (cos2, sin2) = ellipso_model::optics::measure::effective_cos_sin_2_of(
            self.angle_rad,
            self.angle_sin_cos,
            [1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            to_camera,
        );
        Self {
            cos2,
            sin2,
            ..*self
        }
    }
}

/// Everything shading needs that is fixed for a render.
pub(crate) struct Shader<'a> {
    pub scene: &'a Scene,
    pub set: StageSet,
    pub transport: LightTransport,
    pub radiometry: &'a Radiometry,
    /// pBRDF parameters per scene material.
    pub materials: Vec<PbrdfParams<f64>>,
    /// 1/ER when polariser extinction is planned, else 0.
    pub extinction: f64,
}

fn v3(v: &Vector3<f64>) -> Vec3<f64> {
    Vec3::new(v.x, v.y, v.z)
}

fn weighted(w: &[f64; 3], rgb: &[f64; 3]) -> f64 {
    w[0] * rgb[0] + w[1] * rgb[1] + w[2] * rgb[2]
}

impl Shader<'_> {
    /// The analysed intensity of a Stokes vector at `pixel`.
    fn analyse(&self, s: Stokes<f64>, pixel: &PixelSensor, counts: &mut StageCounts) -> f64 {
        if self.set.has(Stage::PolariserExtinction) {
            counts.add(Stage::PolariserExtinction, 1);
        }
        let e = pixel.extinction.unwrap_or(self.extinction);
        0.5 * ((1.0 + e) * s.s0 + (1.0 - e) * (s.s1 * pixel.cos2 + s.s2 * pixel.sin2))
    }

    /// Whether shading `hit` reads the analyser's axis (`PixelSensor::cos2`, `sin2`): only an
    /// object's polarised light does; a board is a depolariser, whose analysed response
    /// ([`Shader::analyse_unpolarised`]) does not depend on it. A ray that hits a board needs
    /// no [`PixelSensor::for_ray`] (its wire-grid geometry is a tenth of a frame's time).
    pub fn reads_analyser_axis(hit: &SceneHit) -> bool {
        matches!(hit.kind, SurfaceKind::Object { .. })
    }

    /// Analysed response to unpolarised light of intensity `s0` (a depolarising surface).
    fn analyse_unpolarised(&self, s0: f64, pixel: &PixelSensor, counts: &mut StageCounts) -> f64 {
        if self.transport != LightTransport::Stokes {
            return s0;
        }
        if self.set.has(Stage::PolariserExtinction) {
            counts.add(Stage::PolariserExtinction, 1);
        }
        0.5 * (1.0 + pixel.extinction.unwrap_or(self.extinction)) * s0
    }

    /// Flash irradiance (W/m²) × analysed model intensity for a primary `ray` (unit direction)
    /// that hit `hit`, as seen by `pixel`. Zero when the point is unlit or faces away.
    pub fn sample(
        &self,
        ctx: &PoseContext,
        ray: &Ray,
        hit: &SceneHit,
        pixel: &PixelSensor,
        counts: &mut StageCounts,
    ) -> f64 {
        let p = hit.hit.point;
        let normal = hit.hit.normal_shading.into_inner();
        let to_camera = -ray.dir;
        let to_flash = ctx.flash_world - p;
        let distance_m = to_flash.norm();
        if !distance_m.is_finite() || distance_m <= 0.0 {
            return 0.0;
        }
        let to_light = to_flash / distance_m;
        if normal.dot(&to_light) <= 0.0 || normal.dot(&to_camera) <= 0.0 {
            return 0.0;
        }
        if self.set.has(Stage::Shadows) {
            counts.add(Stage::Shadows, 1);
            let n_g = hit.hit.normal_geometric.into_inner();
            let side = if n_g.dot(&to_light) >= 0.0 { 1.0 } else { -1.0 };
            let origin = p + n_g * (side * SHADOW_OFFSET_M);
            let shadow = Ray::new(origin, ctx.flash_world - origin);
            if self.scene.occluded(&shadow, 1e-9, 1.0 - 1e-9) {
                return 0.0;
            }
        }
        let irradiance = if self.set.has(Stage::FlashFalloff) {
            counts.add(Stage::FlashFalloff, 1);
            let cos_axis = (-to_light).dot(&ctx.flash_axis_world);
            self.radiometry
                .flash_irradiance_from_cos(distance_m, cos_axis)
        } else {
            self.radiometry.flash_irradiance_w_per_m2(1.0, 0.0)
        };
        let m = match hit.kind {
            SurfaceKind::Board { albedo, .. } => {
                if !self.set.has(Stage::Diffuse) {
                    return 0.0;
                }
                counts.add(Stage::Diffuse, 1);
                let s0 = f64::from(albedo) * normal.dot(&to_light);
                self.analyse_unpolarised(s0, pixel, counts)
            }
            SurfaceKind::Object { material, .. } => {
                let params = match material {
                    MaterialSample::Uniform(id) => self.materials[id],
                    MaterialSample::Blend(_) => self.scene.material_params(&material).to_pbrdf(),
                };
                self.object(ctx, normal, to_light, to_camera, &params, pixel, counts)
            }
        };
        irradiance * m
    }

    /// Analysed model intensity of an object point (unit flash).
    #[expect(clippy::too_many_arguments, reason = "one shading sample's full state")]
    pub(super) fn object(
        &self,
        ctx: &PoseContext,
        normal: Vector3<f64>,
        to_light: Vector3<f64>,
        to_camera: Vector3<f64>,
        p: &PbrdfParams<f64>,
        pixel: &PixelSensor,
        counts: &mut StageCounts,
    ) -> f64 {
        let w = &pixel.weights;
        let rho_d = weighted(w, &p.rho_d);
        let rho_ss = weighted(w, &p.rho_ss);
        let do_diffuse = self.set.has(Stage::Diffuse) && rho_d > 0.0;
        let do_spec = self.set.has(Stage::Specular) && p.rho_s > 0.0;
        let do_ss = self.set.has(Stage::SingleScattering) && rho_ss > 0.0;
        if !(do_diffuse || do_spec || do_ss) {
            return 0.0;
        }
        // Light frame: x = polariser axis (y = z × x with z = −ω_i); unpolarised: any up.
        let light_up = match ctx.polariser_axis_world {
            Some(axis) => (-to_light).cross(&axis),
            None => ctx.camera_up_world,
        };
        let Ok(g) = Geometry::from_up_vectors(
            v3(&normal),
            v3(&to_light),
            v3(&to_camera),
            v3(&light_up),
            v3(&ctx.camera_up_world),
        ) else {
            return 0.0;
        };
        let polarised = ctx.polariser_axis_world.is_some();
        let s_light = Stokes::new(1.0, if polarised { 1.0 } else { 0.0 }, 0.0, 0.0);
        let reflection_weight = |counts: &mut StageCounts| {
            let mut k = 0.0;
            if do_spec {
                counts.add(Stage::Specular, 1);
                k += p.rho_s * pbrdf::lobe_weight(&g, p.sigma_s);
            }
            if do_ss {
                counts.add(Stage::SingleScattering, 1);
                k += rho_ss * pbrdf::lobe_weight(&g, p.sigma_ss);
            }
            k
        };
        match self.transport {
            LightTransport::Stokes => {
                counts.add(Stage::Polarisation, 1);
                let mut s = Stokes::new(0.0, 0.0, 0.0, 0.0);
                if do_diffuse {
                    counts.add(Stage::Diffuse, 1);
                    if self.set.has(Stage::DiffusePolarisation) {
                        counts.add(Stage::DiffusePolarisation, 1);
                    }
                    s = s + pbrdf::diffuse_unit(&g, p.eta).apply(s_light).scale(rho_d);
                }
                if do_spec || do_ss {
                    let k = reflection_weight(counts);
                    s = s + pbrdf::reflection_unit(&g, p.eta).apply(s_light).scale(k);
                }
                self.analyse(s, pixel, counts)
            }
            LightTransport::Scalar => {
                let mut m = 0.0;
                if do_diffuse {
                    counts.add(Stage::Diffuse, 1);
                    m += rho_d
                        * FresnelTerms::dielectric(g.cos_theta_i, p.eta).t_plus()
                        * FresnelTerms::dielectric(g.cos_theta_o, p.eta).t_plus()
                        * g.cos_theta_i;
                }
                if do_spec || do_ss {
                    let k = reflection_weight(counts);
                    m += k * FresnelTerms::dielectric(g.cos_theta_d, p.eta).r_plus();
                }
                m
            }
            LightTransport::IntensityOfPolarised => {
                let s = s_light.to_array();
                let dot = |v: [f64; 4]| v[0] * s[0] + v[1] * s[1] + v[2] * s[2] + v[3] * s[3];
                let mut m = 0.0;
                if do_diffuse {
                    counts.add(Stage::Diffuse, 1);
                    let fi = FresnelTerms::dielectric(g.cos_theta_i, p.eta);
                    let rot = g
                        .light_frame
                        .rotator_to_axis(g.to_light.cross(g.normal))
                        .unwrap_or_else(Rotator::identity);
                    m += rho_d
                        * dot(rot.apply_row([fi.t_plus(), fi.t_minus(), 0.0, 0.0]))
                        * FresnelTerms::dielectric(g.cos_theta_o, p.eta).t_plus()
                        * g.cos_theta_i;
                }
                if do_spec || do_ss {
                    let k = reflection_weight(counts);
                    let fd = FresnelTerms::dielectric(g.cos_theta_d, p.eta);
                    let rot = g
                        .light_frame
                        .rotator_to_axis(pbrdf::reflection_axis(&g))
                        .unwrap_or_else(Rotator::identity);
                    m += k * dot(rot.apply_row([fd.r_plus(), fd.r_minus(), 0.0, 0.0]));
                }
                m
            }
        }
    }
}
