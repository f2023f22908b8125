//! Uniform targets: what the sensor of a scene delivers when a uniformly bright, unpolarised or
//! linearly polarised target fills its view (a light panel; the same through a polariser
//! sheet), or when the lens is capped — the calibration captures of `docs/sensor-calibration.md`.
//!
//! Contract: [`Renderer::render_uniform`] runs no ray casting: each raw pixel's expected signal
//! is `electrons × vignetting(field angle of its centre ray) × PRNU gain × analysed intensity`,
//! the analysed intensity `½[(1+e)s0 + (1−e)(s1 cos2θ + s2 sin2θ)]` with the pixel's own angle
//! θ (nominal plus its error) and 1/ER `e` (its own, else the global extinction, else 0); then
//! the sensor chain with the pixel's fixed offset, exactly as in a scene frame. The wire grid's
//! off-axis tilt (`PixelSensor::for_ray`) is not applied here: a sheet calibration sees the
//! analysers as the sensor holds them. Noise comes from ChaCha8 stream `y` of `seed` per row, so
//! a frame is a pure function of (scene, target, seed) on any thread count.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::Renderer;
use crate::effects::{Stage, StageCounts, StageParams};

/// A target filling the view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UniformTarget {
    /// Expected photo-electrons at the image centre of a pixel without PRNU behind an analyser
    /// parallel to fully polarised light of this target (0: the lens capped).
    pub electrons: f64,
    /// Normalised linear Stokes vector of the light (`[1, 0, 0]` unpolarised;
    /// `[1, cos2φ, sin2φ]` behind an ideal sheet at φ).
    pub stokes: [f64; 3],
}

impl Renderer<'_> {
    /// One raw frame of `target` (module doc), DN per pixel, row-major.
    pub fn render_uniform(&self, target: &UniformTarget, seed: u64) -> Vec<f32> {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let global_e = match self.plan.params(Stage::PolariserExtinction) {
            Some(StageParams::PolariserExtinction(x)) if x.ratio >= 1.0 => 1.0 / x.ratio,
            _ => 0.0,
        };
        let chain = super::sensor::SensorChain::new(
            self.set,
            match self.plan.params(Stage::ReadNoise) {
                Some(StageParams::ReadNoise(r)) => r.sigma_e,
                _ => 0.0,
            },
            &self.radiometry,
        );
        let analysers = self.observes_polarisation();
        let vignette = self.set.has(Stage::Vignetting);
        let mut dn = vec![0f32; w * h];
        dn.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(y as u64);
            let mut counts = StageCounts::default();
            for (x, out) in row.iter_mut().enumerate() {
                let (x, y) = (x as u32, y as u32);
                let pattern = self.pixel_pattern(x, y, &mut counts);
                let pixel = self.pixel_sensor(x, y, &pattern);
                let [s0, s1, s2] = target.stokes;
                let analysed = if analysers {
                    let e = pixel.extinction.unwrap_or(global_e);
                    0.5 * ((1.0 + e) * s0 + (1.0 - e) * (s1 * pixel.cos2 + s2 * pixel.sin2))
                } else {
                    s0
                };
                let vig = if vignette {
                    let d = self.ray_camera(f64::from(x), f64::from(y), &mut counts);
                    self.radiometry.vignetting(d.z.clamp(-1.0, 1.0).acos())
                } else {
                    1.0
                };
                let electrons = target.electrons * vig * pattern.gain * analysed;
                *out = chain.digitise(electrons, pattern.offset_dn, &mut rng, &mut counts);
            }
        });
        dn
    }
}
