//! The sensor stages of one raw pixel: shot noise, read noise, saturation, quantisation.
//!
//! Contract: [`SensorChain::digitise`] turns the expected signal of one pixel (electrons) into
//! its digital number (DN, f32), running only the planned stages in this order:
//! 1. shot noise: electrons ~ Poisson(expected) (rand_distr's exact sampler);
//! 2. read noise: + N(0, σ_e²);
//! 3. saturation: clip to [0, full_well_e];
//! 4. DN = electrons × DN/e⁻ + the pixel's fixed offset (black level, DSNU, hot-pixel signal;
//!    0 unless those stages are planned), never negative: a real ADC's black level keeps codes
//!    ≥ 0, and we clip at 0 in every case so the u16 container is well defined;
//! 5. saturation: clip to the ADC's full scale 2^bits − 1;
//! 6. quantisation: round half away from zero to a whole DN.
//!
//! Randomness comes only from the `rng` passed in, so the caller decides the seed contract.

use crate::effects::{Stage, StageCounts, StageSet};
use rand::Rng;
use rand_distr::{Distribution, Normal, Poisson, StandardNormal};

use super::radiometry::Radiometry;

/// The planned sensor stages and their constants.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SensorChain {
    pub set: StageSet,
    pub read_noise_e: f64,
    pub full_well_e: f64,
    pub dn_per_electron: f64,
    pub full_scale_dn: f64,
}

impl SensorChain {
    /// The chain of a plan.
    pub fn new(set: StageSet, read_noise_e: f64, radiometry: &Radiometry) -> Self {
        Self {
            set,
            read_noise_e,
            full_well_e: radiometry.full_well_e(),
            dn_per_electron: radiometry.dn_per_electron(),
            full_scale_dn: radiometry.full_scale_dn(),
        }
    }

    /// The DN of one pixel whose expected signal is `electrons` and whose fixed offset is
    /// `offset_dn`.
    pub fn digitise<R: Rng>(
        &self,
        electrons: f64,
        offset_dn: f64,
        rng: &mut R,
        counts: &mut StageCounts,
    ) -> f32 {
        let mut e = electrons.max(0.0);
        if self.set.has(Stage::ShotNoise) {
            counts.add(Stage::ShotNoise, 1);
            // Poisson::new rejects λ ≤ 0 and non-finite λ: such pixels have no photons.
            if let Ok(p) = Poisson::new(e) {
                e = p.sample(rng);
            } else {
                e = 0.0;
            }
        }
        if self.set.has(Stage::ReadNoise) {
            counts.add(Stage::ReadNoise, 1);
            e += match Normal::new(0.0, self.read_noise_e) {
                Ok(n) => n.sample(rng),
                Err(_) => self.read_noise_e * rng.sample::<f64, _>(StandardNormal),
            };
        }
        let saturate = self.set.has(Stage::Saturation);
        if saturate {
            counts.add(Stage::Saturation, 1);
            e = e.min(self.full_well_e);
        }
        let mut dn = (e * self.dn_per_electron + offset_dn).max(0.0);
        if saturate {
            dn = dn.min(self.full_scale_dn);
        }
        if self.set.has(Stage::Quantisation) {
            counts.add(Stage::Quantisation, 1);
            dn = dn.round();
        }
        dn as f32
    }
}
