//! The polarimetric renderer: one scene frame → the raw mosaic the camera delivers, plus truth.
//!
//! # What it does
//! Ray casting from the camera through every raw pixel (each raw pixel is its own ray through
//! its own centre, N×N stratified sub-samples when supersampling, which models the mosaic's
//! instantaneous field of view), shadow rays to the flash, the pBRDF of [`ellipso_model::optics`] for
//! the flash's polarised light, the analyser and colour filter of that pixel's mosaic position
//! ([`ellipso_model::mosaic::SensorLayout`]), radiometry ([`radiometry`]), then the sensor chain (shot and
//! read noise, saturation, quantisation). Only the stages of the scene's
//! [`EffectPlan`] run; each execution is counted per frame.
//!
//! # Contract
//! - [`Renderer::render_frame`]`(k)` renders pose `k` of `scene.camera_poses`. The result's
//!   [`RenderedFrame::dn`] holds DN as f32 (whole numbers when quantisation is planned) and
//!   [`RenderedFrame::raw`] the u16 frame exactly as the camera delivers it: unshifted, 12-bit
//!   data in 0..=4095 (8-bit in 0..=255, 16-bit in 0..=65535), row-major, mosaic phase of
//!   `mosaic.rs` (no flips).
//! - **Threads and seeds**: rows are rendered in parallel on the caller's rayon pool
//!   (`pool.install(|| renderer.render_frame(k))` to choose the thread count). Every noise draw
//!   of row `y` comes from the ChaCha8 stream `y` of the frame seed `mix(seed, k)`; rows draw in
//!   pixel order, so frames are bit-identical for the same scene, options and seed on any number
//!   of threads. Without noise stages the output does not depend on the seed at all.
//! - **Resolution override** ([`RenderOptions::resolution_px`]) scales the intrinsics
//!   (fx·s, (cx + ½)·s − ½) so the same field of view is seen at a coarser sampling.
//! - **Flash energy** ([`Renderer::render_frame_lit`]): the scene's flash is one full-energy
//!   pulse; a frame lit by a fraction `e` of it (a bracketed, shorter pulse) collects `e` times
//!   the electrons before noise, saturation and quantisation. The scene has no other light, so
//!   this scales the whole signal; shot noise follows the smaller signal, read noise does not
//!   shrink, so short pulses are noisier relative to their signal, as on the rig.
//! - Motion blur: the pose moves linearly (speed along the capture path's direction at that
//!   pose) and turns (about the axis of the path's rotation there) symmetrically about the listed
//!   pose during the exposure; `samples` instants are averaged. The truth pose is mid-exposure.

mod fixed_pattern;
mod footprint;
pub mod radiometry;
mod sensor;
mod shade;
pub mod truth;
mod uniform;

#[cfg(test)]
mod tests;

pub use fixed_pattern::{FixedPattern, PixelPattern};
pub use footprint::{Footprint, IdealPixel, PointFrame};
pub use truth::{BOARD_MATERIAL_BASE, FrameTruth, NO_HIT_MATERIAL, PixelTruth};
pub use uniform::UniformTarget;

use crate::effects::{EffectPlan, LightTransport, Stage, StageCounts, StageParams, StageSet};
use crate::scene::{Scene, SensorKind};
use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::Ray;
use ellipso_model::mosaic::{Analyser, MosaicError, SensorLayout};
use ellipso_model::optics::OpticsError;
use ellipso_model::optics::pbrdf::PbrdfParams;
use ellipso_model::rig::FlashSpec;
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use radiometry::Radiometry;
use rayon::prelude::*;
use shade::{PixelSensor, Shader};

/// Largest supported supersampling factor per axis (64 rays per raw pixel, times motion samples).
pub const MAX_SUPERSAMPLING: u32 = 8;

/// Render settings that are not part of the scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RenderOptions {
    /// N: N×N stratified rays per raw pixel (1 = the pixel centre only). Default 2, which keeps
    /// AprilTag corners accurate (edges are area-averaged as on a real sensor).
    pub supersampling: u32,
    /// Noise seed (`None`: the scene's `seed`).
    pub seed: Option<u64>,
    /// `[width, height]` override (intrinsics scaled); whole mosaic tiles.
    pub resolution_px: Option<[u32; 2]>,
    /// Whether to produce per-pixel truth (normal, depth, material).
    pub pixel_truth: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            supersampling: 2,
            seed: None,
            resolution_px: None,
            pixel_truth: false,
        }
    }
}

/// Why a render cannot run.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A frame index past the capture's poses.
    #[error("frame {index} does not exist: the capture has {count} poses (0..{count})")]
    FrameOutOfRange {
        /// Requested index.
        index: usize,
        /// Number of poses.
        count: usize,
    },
    /// The requested resolution does not fit the mosaic.
    #[error("resolution {width}×{height}: {source}")]
    Resolution {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
        /// What the mosaic needs.
        source: MosaicError,
    },
    /// A caller's buffer does not hold one frame.
    #[error("buffer of {len} pixels cannot hold a {width}×{height} frame")]
    BufferSize {
        /// Buffer length, pixels.
        len: usize,
        /// Frame width.
        width: u32,
        /// Frame height.
        height: u32,
    },
    /// A side above the scene files' limit.
    #[error(
        "resolution {width}×{height}: sides above {max} px are refused, as in scene files",
        max = crate::scene::rig::MAX_SIDE_PX
    )]
    TooLarge {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
    },
    /// Supersampling outside 1..=MAX_SUPERSAMPLING.
    #[error("supersampling {0} must be in 1..={MAX_SUPERSAMPLING}")]
    Supersampling(u32),
    /// A flash energy that is negative or not finite.
    #[error("flash energy {0} must be finite and ≥ 0 (1 = the scene's full pulse)")]
    FlashEnergy(f64),
    /// A material outside the pBRDF's domain.
    #[error("material '{name}': {source}")]
    Material {
        /// Material name.
        name: String,
        /// What is wrong.
        source: OpticsError,
    },
}

/// One rendered frame.
#[derive(Clone, Debug)]
pub struct RenderedFrame {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// DN per raw pixel, row-major (whole numbers when quantisation is planned).
    pub dn: Vec<f32>,
    /// Pose, flash and trigger truth.
    pub truth: FrameTruth,
    /// Per-pixel truth, when requested.
    pub pixels: Option<PixelTruth>,
    /// How often each stage ran for this frame.
    pub counts: StageCounts,
}

impl RenderedFrame {
    /// The raw frame in its u16 container: DN rounded to the nearest integer (a no-op when
    /// quantisation is planned) and clamped to 0..=65535.
    pub fn raw(&self) -> Vec<u16> {
        self.dn
            .iter()
            .map(|&v| v.round().clamp(0.0, 65535.0) as u16)
            .collect()
    }
}

/// The mosaic layout of a scene sensor.
pub fn sensor_layout(kind: SensorKind) -> SensorLayout {
    match kind {
        SensorKind::MonoPolar => SensorLayout::MonoPolar,
        SensorKind::ColourPolar => SensorLayout::ColourPolar,
    }
}

/// SplitMix64 finaliser: a bijective 64-bit mix (Steele et al. 2014).
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The noise seed of frame `index` under render seed `seed`.
pub fn frame_seed(seed: u64, index: usize) -> u64 {
    mix(seed ^ mix(index as u64 ^ 0x9e37_79b9_7f4a_7c15))
}

/// Renders frames of one scene (see the module doc for the contract).
pub struct Renderer<'s> {
    scene: &'s Scene,
    plan: EffectPlan,
    set: StageSet,
    camera: CameraModel,
    layout: SensorLayout,
    radiometry: Radiometry,
    materials: Vec<PbrdfParams<f64>>,
    options: RenderOptions,
    seed: u64,
    pattern: FixedPattern,
    flash: FlashSpec,
    /// The pixel of each nominal analyser ([`Analyser::index`] order) with no angle error: its
    /// trigonometry taken once per render, not twice per pixel.
    nominal_pixels: [PixelSensor; 4],
}

/// The flash a render lights the scene with: the scene's (what a session records), turned by
/// `flash_polariser_error` and with the profile of `flash_profile_error` when those are planned.
pub fn true_flash(recorded: &FlashSpec, plan: &EffectPlan) -> FlashSpec {
    let mut flash = recorded.clone();
    if let Some(StageParams::FlashPolariserError(e)) = plan.params(Stage::FlashPolariserError) {
        flash.polariser_deg += e.angle_deg;
    }
    if let Some(StageParams::FlashProfileError(e)) = plan.params(Stage::FlashProfileError) {
        flash.profile = ellipso_model::rig::FlashProfileSpec {
            kind: ellipso_model::rig::FlashProfileKind::CosPower,
            exponent: Some(e.exponent),
            angle_deg: None,
            relative: None,
        };
    }
    flash
}

impl<'s> Renderer<'s> {
    /// A renderer for `scene` with the plan derived from it.
    pub fn new(scene: &'s Scene, options: RenderOptions) -> Result<Self, RenderError> {
        Self::with_plan(scene, EffectPlan::from_scene(scene), options)
    }

    /// A renderer with an explicit plan (a plan of another scene, or one with stages removed).
    pub fn with_plan(
        scene: &'s Scene,
        plan: EffectPlan,
        options: RenderOptions,
    ) -> Result<Self, RenderError> {
        if !(1..=MAX_SUPERSAMPLING).contains(&options.supersampling) {
            return Err(RenderError::Supersampling(options.supersampling));
        }
        let layout = sensor_layout(scene.rig.camera.sensor);
        let mut camera = scene.rig.camera.camera_model();
        if let Some([w, h]) = options.resolution_px {
            if w > crate::scene::rig::MAX_SIDE_PX || h > crate::scene::rig::MAX_SIDE_PX {
                return Err(RenderError::TooLarge {
                    width: w,
                    height: h,
                });
            }
            let sx = f64::from(w) / f64::from(camera.width);
            let sy = f64::from(h) / f64::from(camera.height);
            let i = &mut camera.intrinsics;
            i.fx *= sx;
            i.fy *= sy;
            i.cx = (i.cx + 0.5) * sx - 0.5;
            i.cy = (i.cy + 0.5) * sy - 0.5;
            camera.width = w;
            camera.height = h;
        }
        layout
            .check_frame_size(camera.width, camera.height)
            .map_err(|source| RenderError::Resolution {
                width: camera.width,
                height: camera.height,
                source,
            })?;
        let materials = scene
            .materials
            .iter()
            .map(|m| {
                let p = m.params.to_pbrdf();
                p.validate()
                    .map(|()| p)
                    .map_err(|source| RenderError::Material {
                        name: m.name.clone(),
                        source,
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let vignetting = match plan.params(Stage::Vignetting) {
            Some(StageParams::Vignetting(v)) => Some(v.exponent),
            _ => None,
        };
        let flash = true_flash(&scene.rig.flash, &plan);
        let radiometry = Radiometry::new(&scene.rig.camera, &flash, vignetting);
        let pattern = FixedPattern::new(&plan, layout, scene.effects.sensor_seed);
        Ok(Self {
            nominal_pixels: Analyser::ALL.map(|a| PixelSensor::new(a.angle_rad(), [0.0; 3])),
            flash,
            pattern,
            scene,
            set: plan.stage_set(),
            plan,
            camera,
            layout,
            radiometry,
            materials,
            seed: options.seed.unwrap_or(scene.seed),
            options,
        })
    }

    /// The plan this renderer executes.
    pub fn plan(&self) -> &EffectPlan {
        &self.plan
    }

    /// The camera model frames are rendered with (after any resolution override).
    pub fn camera(&self) -> &CameraModel {
        &self.camera
    }

    /// The radiometric chain (what the fit's normaliser must match).
    pub fn radiometry(&self) -> &Radiometry {
        &self.radiometry
    }

    /// The sensor mosaic.
    pub fn layout(&self) -> SensorLayout {
        self.layout
    }

    /// Number of frames (camera poses) in the capture.
    pub fn frame_count(&self) -> usize {
        self.scene.camera_poses.len()
    }

    /// The shading state of this render.
    fn shader(&self) -> Shader<'_> {
        let extinction = match self.plan.params(Stage::PolariserExtinction) {
            Some(StageParams::PolariserExtinction(x)) if x.ratio >= 1.0 => 1.0 / x.ratio,
            _ => 0.0,
        };
        Shader {
            scene: self.scene,
            set: self.set,
            transport: self.plan.transport,
            radiometry: &self.radiometry,
            materials: self.materials.clone(),
            extinction,
        }
    }

    /// The instants of the exposure of pose `index` (one unless motion blur is planned).
    fn sub_poses(&self, index: usize) -> Vec<Isometry3<f64>> {
        let poses = &self.scene.camera_poses;
        let pose = poses[index].world_from_camera;
        let Some(StageParams::MotionBlur(m)) = self.plan.params(Stage::MotionBlur) else {
            return vec![pose];
        };
        let (a, b) = match (
            index.checked_sub(1).and_then(|i| poses.get(i)),
            poses.get(index + 1),
        ) {
            (_, Some(next)) => (pose, next.world_from_camera),
            (Some(prev), None) => (prev.world_from_camera, pose),
            (None, None) => (pose, pose),
        };
        let step = b.translation.vector - a.translation.vector;
        let direction_world = if step.norm() > 1e-12 {
            step / step.norm()
        } else {
            pose.rotation * Vector3::x()
        };
        let turn = (a.rotation.inverse() * b.rotation).scaled_axis();
        let axis_camera = if turn.norm() > 1e-12 {
            Unit::new_normalize(turn)
        } else {
            Vector3::y_axis()
        };
        let exposure_s = self.scene.rig.camera.exposure_us * 1e-6;
        let k = m.samples.max(1);
        (0..k)
            .map(|j| {
                let tau_s = ((f64::from(j) + 0.5) / f64::from(k) - 0.5) * exposure_s;
                let shift = Translation3::from(direction_world * (m.linear_speed_m_per_s * tau_s));
                let angle = m.angular_speed_deg_per_s.to_radians() * tau_s;
                let turn = UnitQuaternion::from_axis_angle(&axis_camera, angle);
                Isometry3::from_parts(shift, nalgebra::UnitQuaternion::identity())
                    * pose
                    * Isometry3::from_parts(Translation3::identity(), turn)
            })
            .collect()
    }

    /// Camera-frame unit direction through pixel `(u, v)`.
    fn ray_camera(&self, u: f64, v: f64, counts: &mut StageCounts) -> Vector3<f64> {
        if self.set.has(Stage::LensDistortion) {
            counts.add(Stage::LensDistortion, 1);
            if let Ok(d) = self.camera.unproject_to_ray([u, v]) {
                return d.into_inner();
            }
        }
        let i = self.camera.intrinsics;
        Vector3::new((u - i.cx) / i.fx, (v - i.cy) / i.fy, 1.0).normalize()
    }

    /// The sensor's fixed pattern (truth for calibration benches).
    pub fn fixed_pattern(&self) -> &FixedPattern {
        &self.pattern
    }

    /// The fixed-pattern values of raw pixel `(x, y)`, counting each planned stage once.
    fn pixel_pattern(&self, x: u32, y: u32, counts: &mut StageCounts) -> PixelPattern {
        if !self.pattern.is_active() {
            return PixelPattern::IDEAL;
        }
        for stage in [
            Stage::AnalyserErrors,
            Stage::Prnu,
            Stage::BlackLevel,
            Stage::HotPixels,
        ] {
            if self.set.has(stage) {
                counts.add(stage, 1);
            }
        }
        self.pattern.pixel(x, y)
    }

    /// What raw pixel `(x, y)` with fixed pattern `pattern` measures.
    fn pixel_sensor(&self, x: u32, y: u32, pattern: &PixelPattern) -> PixelSensor {
        let weights = match self.layout.colour_at(x, y) {
            Some(c) => {
                let mut w = [0.0; 3];
                w[c.index()] = 1.0;
                w
            }
            None => [1.0 / 3.0; 3],
        };
        let analyser = self.layout.analyser_at(x, y);
        let sensor = if pattern.angle_error_rad == 0.0 {
            // θ + 0 is θ: the same values as computing them here.
            self.nominal_pixels[analyser.index()]
        } else {
            PixelSensor::new(analyser.angle_rad() + pattern.angle_error_rad, weights)
        };
        PixelSensor {
            weights,
            extinction: pattern.inverse_extinction,
            ..sensor
        }
    }

    /// Renders frame `index` on the current rayon pool, lit by the scene's full flash pulse.
    pub fn render_frame(&self, index: usize) -> Result<RenderedFrame, RenderError> {
        self.render_frame_lit(index, 1.0)
    }

    /// Renders frame `index` lit by `flash_energy_rel` of the scene's flash pulse (a bracketed
    /// pulse's on-time over the full pulse's; 1 is [`Renderer::render_frame`] exactly).
    pub fn render_frame_lit(
        &self,
        index: usize,
        flash_energy_rel: f64,
    ) -> Result<RenderedFrame, RenderError> {
        let frame = self.frame_setup(index, flash_energy_rel)?;
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let mut dn = vec![0f32; w * h];
        let row_counts: Vec<StageCounts> = dn
            .par_chunks_mut(w)
            .enumerate()
            .map(|(y, row)| self.render_row(y as u32, row, &frame))
            .collect();
        let mut counts = StageCounts::default();
        for c in &row_counts {
            counts.merge(c);
        }
        let pose = &self.scene.camera_poses[index];
        let pixels = self
            .options
            .pixel_truth
            .then(|| self.pixel_truth(&pose.world_from_camera));
        Ok(RenderedFrame {
            width: self.camera.width,
            height: self.camera.height,
            dn,
            truth: FrameTruth::new(self.scene, pose, &self.camera, frame.seed),
            pixels,
            counts,
        })
    }

    /// Renders frame `index` straight into a caller's u16 buffer (`width × height`, row-major,
    /// as [`RenderedFrame::raw`]), e.g. a camera backend's frame pool; returns the frame's truth
    /// and stage counts. A buffer of the wrong size is an error, and then nothing is rendered.
    pub fn render_raw_into(
        &self,
        index: usize,
        out: &mut [u16],
    ) -> Result<(FrameTruth, StageCounts), RenderError> {
        let expected = self.camera.width as usize * self.camera.height as usize;
        if out.len() != expected {
            return Err(RenderError::BufferSize {
                len: out.len(),
                width: self.camera.width,
                height: self.camera.height,
            });
        }
        let f = self.render_frame(index)?;
        for (o, v) in out.iter_mut().zip(&f.dn) {
            *o = v.round().clamp(0.0, 65535.0) as u16;
        }
        Ok((f.truth, f.counts))
    }

    /// Per-pixel truth from the centre rays at the mid-exposure pose.
    fn pixel_truth(&self, world_from_camera: &Isometry3<f64>) -> PixelTruth {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let rows: Vec<Vec<([f32; 3], f32, u16)>> = (0..h)
            .into_par_iter()
            .map(|y| {
                let mut scratch = StageCounts::default();
                (0..w)
                    .map(|x| {
                        let d = self.ray_camera(x as f64, y as f64, &mut scratch);
                        let ray = Ray::new(
                            world_from_camera.translation.vector.into(),
                            world_from_camera.rotation * d,
                        );
                        match self.scene.intersect(&ray, 0.0, f64::INFINITY) {
                            Some(hit) => {
                                let n = hit.hit.normal_shading;
                                (
                                    [n.x as f32, n.y as f32, n.z as f32],
                                    (hit.hit.t * d.z) as f32,
                                    truth::material_code(&hit.kind),
                                )
                            }
                            None => ([0.0; 3], f32::NAN, NO_HIT_MATERIAL),
                        }
                    })
                    .collect()
            })
            .collect();
        let flat: Vec<_> = rows.into_iter().flatten().collect();
        PixelTruth {
            width: self.camera.width,
            height: self.camera.height,
            normal_world: flat.iter().map(|p| p.0).collect(),
            depth_m: flat.iter().map(|p| p.1).collect(),
            material: flat.iter().map(|p| p.2).collect(),
        }
    }

    /// Whether the plan's transport is the full Stokes path.
    pub fn observes_polarisation(&self) -> bool {
        self.plan.transport == LightTransport::Stokes
    }
}
