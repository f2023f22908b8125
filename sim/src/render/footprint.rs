//! What one pixel collects: the rays of its footprint through the shader, then the sensor — for
//! the raw mosaic frame, and for an ideal analyser sensor sampled at any image point.
//!
//! Contract:
//! - A raw pixel integrates the `n × n` stratified rays of its one-pixel footprint (centres
//!   `x + (i + ½)/n − ½`) over every instant of the exposure, with the analyser and colour
//!   filter of its mosaic position; the mean signal × the radiometric scale × the flash energy
//!   are its expected electrons, which the planned sensor stages digitise
//!   ([`super::sensor::SensorChain`]). Frames use exactly this (`Renderer::render_row`).
//! - [`PointFrame::sample`] is the same measurement by an **ideal polarisation sensor**: at an
//!   arbitrary image point, every analyser (0°, 45°, 90°, 135°) of every colour band (R, G, B on
//!   a colour sensor; the mean of R, G, B on a mono one) measures the same footprint — a
//!   one-pixel square centred on the point with the render's supersampling
//!   ([`Footprint::Pixel`]) or the point's single ray ([`Footprint::Point`]) — through the same
//!   shader, radiometry and sensor stages. No mosaic, no demosaic, no interpolation: what the
//!   error budget puts in their place to measure what they cost. Its noise comes from a ChaCha8
//!   stream seeded by the frame's noise seed and the caller's `seed`, so a sample is a pure
//!   function of (scene, frame, point, footprint, seed).

use ellipso_model::geometry::Ray;
use ellipso_model::mosaic::{Analyser, Channel};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::sensor::SensorChain;
use super::shade::{PixelSensor, PoseContext, Shader};
use super::{RenderError, Renderer, frame_seed, mix};
use crate::effects::{Stage, StageCounts, StageParams};

/// What every pixel of one frame shares: the camera and flash at each instant of the exposure,
/// the shading state, the sensor chain, the frame's noise seed and its flash energy.
pub(super) struct FrameSetup<'s> {
    contexts: Vec<PoseContext>,
    shader: Shader<'s>,
    pub(super) chain: SensorChain,
    pub(super) seed: u64,
    flash_energy_rel: f64,
}

/// Which rays an ideal pixel averages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Footprint {
    /// The one-pixel square centred on the point, with the render's supersampling (what a raw
    /// pixel there would integrate).
    Pixel,
    /// The point's own ray alone.
    Point,
}

/// The four analysers' DN of every band at one image point, as an ideal sensor measures them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdealPixel {
    /// `[I0, I45, I90, I135]` per band (R, G, B; a mono sensor fills band 0 only), DN.
    pub dn: [[f32; 4]; 3],
    /// Bands measured: 3 on a colour sensor, 1 on a mono one.
    pub bands: usize,
}

/// One frame of a render, ready to be sampled at any image point by an ideal sensor (module
/// doc). Cheap to build; share it across threads.
pub struct PointFrame<'r, 's> {
    renderer: &'r Renderer<'s>,
    frame: FrameSetup<'r>,
}

impl<'s> Renderer<'s> {
    /// What every pixel of frame `index` lit by `flash_energy_rel` of the full pulse shares.
    pub(super) fn frame_setup(
        &self,
        index: usize,
        flash_energy_rel: f64,
    ) -> Result<FrameSetup<'_>, RenderError> {
        if !(flash_energy_rel.is_finite() && flash_energy_rel >= 0.0) {
            return Err(RenderError::FlashEnergy(flash_energy_rel));
        }
        let count = self.frame_count();
        if index >= count {
            return Err(RenderError::FrameOutOfRange { index, count });
        }
        let contexts: Vec<PoseContext> = self
            .sub_poses(index)
            .into_iter()
            .map(|w| PoseContext::with_flash(&self.flash, w))
            .collect();
        let read_noise_e = match self.plan.params(Stage::ReadNoise) {
            Some(StageParams::ReadNoise(r)) => r.sigma_e,
            _ => 0.0,
        };
        Ok(FrameSetup {
            contexts,
            shader: self.shader(),
            chain: SensorChain::new(self.set, read_noise_e, &self.radiometry),
            seed: frame_seed(self.seed, index),
            flash_energy_rel,
        })
    }

    /// One row of DN of `frame`; returns the row's stage counts.
    pub(super) fn render_row(
        &self,
        y: u32,
        row: &mut [f32],
        frame: &FrameSetup<'_>,
    ) -> StageCounts {
        let mut counts = StageCounts::default();
        let mut rng = ChaCha8Rng::seed_from_u64(frame.seed);
        rng.set_stream(u64::from(y));
        let n = self.options.supersampling;
        for (x, out) in row.iter_mut().enumerate() {
            let x = x as u32;
            let pattern = self.pixel_pattern(x, y, &mut counts);
            let pixel = self.pixel_sensor(x, y, &pattern);
            let centre = [f64::from(x), f64::from(y)];
            let electrons =
                pattern.gain * self.expected_electrons(centre, n, &pixel, frame, &mut counts);
            *out = frame
                .chain
                .digitise(electrons, pattern.offset_dn, &mut rng, &mut counts);
        }
        counts
    }

    /// The expected electrons of `pixel` over the `n × n` stratified rays of the one-pixel
    /// footprint centred at `centre` (raw pixel coordinates, OpenCV centres) and every instant
    /// of the exposure: flash irradiance × analysed model intensity × vignetting, averaged,
    /// times the radiometric scale and the flash energy.
    fn expected_electrons(
        &self,
        centre: [f64; 2],
        n: u32,
        pixel: &PixelSensor,
        frame: &FrameSetup<'_>,
        counts: &mut StageCounts,
    ) -> f64 {
        let step = 1.0 / f64::from(n);
        let blur = self.set.has(Stage::MotionBlur) && frame.contexts.len() > 1;
        let vignette = self.set.has(Stage::Vignetting);
        let samples = f64::from(n * n) * frame.contexts.len() as f64;
        let mut signal = 0.0;
        for sy in 0..n {
            let v = centre[1] + (f64::from(sy) + 0.5) * step - 0.5;
            for sx in 0..n {
                let u = centre[0] + (f64::from(sx) + 0.5) * step - 0.5;
                let dir_camera = self.ray_camera(u, v, counts);
                let vig = if vignette {
                    counts.add(Stage::Vignetting, 1);
                    // dir_camera is unit, so z is the cosine of the field angle.
                    self.radiometry
                        .vignetting(dir_camera.z.clamp(-1.0, 1.0).acos())
                } else {
                    1.0
                };
                // The analyser's effective axis along this ray, taken when a hit's shading
                // reads it (the same for every instant: it depends on the camera-frame ray).
                let mut ray_pixel: Option<PixelSensor> = None;
                for ctx in &frame.contexts {
                    if blur {
                        counts.add(Stage::MotionBlur, 1);
                    }
                    let w2c = &ctx.world_from_camera;
                    let ray = Ray::new(w2c.translation.vector.into(), w2c.rotation * dir_camera);
                    if let Some(hit) = self.scene.intersect(&ray, 0.0, f64::INFINITY) {
                        let seen_by = if Shader::reads_analyser_axis(&hit) {
                            &*ray_pixel.get_or_insert_with(|| pixel.for_ray(&dir_camera))
                        } else {
                            pixel
                        };
                        signal += vig * frame.shader.sample(ctx, &ray, &hit, seen_by, counts);
                    }
                }
            }
        }
        // Multiplying by exactly 1.0 leaves a full-energy frame bit-identical.
        signal / samples * self.radiometry.electrons_per_irradiance() * frame.flash_energy_rel
    }

    /// Frame `index` lit by `flash_energy_rel` of the full pulse, for ideal samples at any
    /// image point ([`PointFrame::sample`]).
    pub fn point_frame(
        &self,
        index: usize,
        flash_energy_rel: f64,
    ) -> Result<PointFrame<'_, 's>, RenderError> {
        Ok(PointFrame {
            renderer: self,
            frame: self.frame_setup(index, flash_energy_rel)?,
        })
    }
}

impl PointFrame<'_, '_> {
    /// What an ideal polarisation sensor measures at image point `point_px` (raw pixel
    /// coordinates, OpenCV centres) with `footprint`; `seed` selects the noise draw (module doc).
    pub fn sample(&self, point_px: [f64; 2], footprint: Footprint, seed: u64) -> IdealPixel {
        let r = self.renderer;
        let n = match footprint {
            Footprint::Pixel => r.options.supersampling,
            Footprint::Point => 1,
        };
        let bands: &[Option<Channel>] = if r.layout.colour_at(0, 0).is_some() {
            &[
                Some(Channel::Red),
                Some(Channel::Green),
                Some(Channel::Blue),
            ]
        } else {
            &[None]
        };
        let mut rng = ChaCha8Rng::seed_from_u64(mix(self.frame.seed ^ mix(seed)));
        let mut counts = StageCounts::default();
        let mut dn = [[0f32; 4]; 3];
        for (b, colour) in bands.iter().enumerate() {
            let weights = match colour {
                Some(c) => {
                    let mut w = [0.0; 3];
                    w[c.index()] = 1.0;
                    w
                }
                None => [1.0 / 3.0; 3],
            };
            for (k, analyser) in Analyser::ALL.iter().enumerate() {
                let pixel = PixelSensor::new(analyser.angle_rad(), weights);
                let e = r.expected_electrons(point_px, n, &pixel, &self.frame, &mut counts);
                dn[b][k] = self.frame.chain.digitise(e, 0.0, &mut rng, &mut counts);
            }
        }
        IdealPixel {
            dn,
            bands: bands.len(),
        }
    }
}
