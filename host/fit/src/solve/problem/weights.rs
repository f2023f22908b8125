//! The measurement loss's noise weights: each analyser pixel's 1/σ from the sensor model
//! (shot noise at the predicted intensity + read noise + quantisation), first from the
//! observations, then re-derived from the model at every LM start (iteratively reweighted least
//! squares), with Huber downweighting of whole outlying samples when virtual samples anchor the
//! lobe.
//!
//! Contract: every 1/σ is finite and positive (the floor variance is positive and samples with a
//! non-positive normaliser never enter a problem); paper mode is untouched (no-op, change 0);
//! the weights change only in [`Problem::reweight`] (and the initial ones at construction), so
//! they stay fixed inside each LM run.

use crate::solve::LossMode;

use super::{Albedos, Problem, Scratch, median};

/// Huber threshold of [`Problem::downweight_outliers`], in robust standard deviations (3: a
/// Gaussian sample is downweighted with probability 0.3 %).
pub(in super::super) const HUBER_K: f64 = 3.0;

impl Problem<'_> {
    /// Measurement mode: weights from the observations themselves (floored at 0), used only
    /// until [`Problem::reweight`] replaces them with the model's prediction at the start of
    /// every LM run (observation-derived weights correlate with the noise and bias the fit).
    pub(super) fn with_initial_weights(mut self) -> Self {
        if self.loss == LossMode::Measurement {
            let predicted = self.pixel_obs.clone();
            let _ = self.set_weights(|k, c| predicted[k][c]);
        }
        self
    }

    /// The predicted noise of one sample's four analyser pixels from their predicted
    /// intensities `i` (model units): for a pixel of expected model intensity I,
    /// Var = (g·N·I + σ_floor²)/N² in model units², with g DN per electron (shot noise: g·DN)
    /// and σ_floor² = read noise² + 1/12 (quantisation), DN². Negative predictions are floored
    /// at 0. The prediction is capped at 4× the observation + 3σ_floor, so a model far off the
    /// data cannot buy itself small weights (a cap that only acts on gross misfits).
    fn inverse_sigma(&self, k: usize, c: usize, i: [f64; 4]) -> [f64; 4] {
        let n = self.normalisers[k];
        let g = self.dn_per_electron;
        let f = self.floor_variance_dn2;
        let o = &self.pixel_obs[k][c];
        // f > 0 and n > 0 (non-positive N are skipped in `new`): var > 0.
        core::array::from_fn(|j| {
            let pred = i[j].min(4.0 * o[j].max(0.0) + 3.0 * f.sqrt() / n).max(0.0);
            let var = (g * n * pred + f) / (n * n);
            1.0 / var.sqrt()
        })
    }

    /// Sets the weights from `predicted(sample, channel)`; returns the largest relative change
    /// of any 1/σ.
    fn set_weights(&mut self, predicted: impl Fn(usize, usize) -> [f64; 4]) -> f64 {
        let mut change: f64 = 0.0;
        for k in 0..self.len() {
            for c in 0..self.channels {
                let w = self.inverse_sigma(k, c, predicted(k, c));
                for (new, old) in w.iter().zip(&self.inv_sigma[k][c]) {
                    change = change.max(if *old > 0.0 {
                        (new / old - 1.0).abs()
                    } else {
                        1.0
                    });
                }
                self.inv_sigma[k][c] = w;
            }
        }
        change
    }

    /// Measurement mode: re-derives every residual's noise from the model's prediction at the
    /// point whose unit lobes are in `scratch` (an f64 evaluation just done) with `albedos`
    /// (ρ_s among them) — iteratively reweighted least squares, the weights held fixed inside each
    /// LM run (quasi-likelihood: consistent, unlike weights from the noisy data). No-op in
    /// paper mode. Returns the largest relative change of any 1/σ (0 in paper mode).
    pub fn reweight(&mut self, scratch: &Scratch<f64>, albedos: &Albedos<f64>) -> f64 {
        if self.loss != LossMode::Measurement || scratch.pixels.len() != self.len() {
            return 0.0;
        }
        let predicted: Vec<[[f64; 4]; 3]> = scratch
            .pixels
            .iter()
            .map(|[a, b, s]| {
                core::array::from_fn(|c| {
                    core::array::from_fn(|j| {
                        albedos.rho_d[c] * a[j] + albedos.rho_ss[c] * b[j] + albedos.rho_s * s[j]
                    })
                })
            })
            .collect();
        let change = self.set_weights(|k, c| predicted[k][c]);
        if self.robust {
            self.downweight_outliers(&predicted);
        }
        change
    }

    /// Huber downweighting of whole samples (Huber, *Robust Statistics*, 1981): a sample's
    /// standardised residual z_k = RMS over its pixel rows of the whitened residual at the
    /// current prediction is compared with the vertex's robust scale s = 1.4826·median(z)
    /// (floored at 1, the value at a perfect fit); beyond [`HUBER_K`]·s every 1/σ of the sample
    /// is scaled by √(k·s/z_k), the Huber weight k·s/z_k on its squared residual. A pixel that
    /// sees something the model of one surface point cannot explain — the board behind a
    /// silhouette, a neighbouring material across a boundary a misplaced vertex straddles —
    /// then costs linearly, not quadratically, and cannot drag the lobe and η to a bound.
    fn downweight_outliers(&mut self, predicted: &[[[f64; 4]; 3]]) {
        let n = self.len();
        if n == 0 {
            return;
        }
        let z: Vec<f64> = (0..n)
            .map(|k| {
                let mut sum = 0.0;
                let rows = predicted[k]
                    .iter()
                    .zip(&self.pixel_obs[k])
                    .zip(&self.inv_sigma[k])
                    .take(self.channels);
                for ((pred, obs), w) in rows {
                    for ((p, o), w) in pred.iter().zip(obs).zip(w) {
                        let r = w * (p - o);
                        sum += r * r;
                    }
                }
                (sum / (4 * self.channels) as f64).sqrt()
            })
            .collect();
        let scale = (1.4826 * median(z.clone())).max(1.0);
        let limit = HUBER_K * scale;
        for (k, zk) in z.iter().enumerate() {
            if *zk > limit && zk.is_finite() {
                let factor = (limit / zk).sqrt();
                for c in 0..self.channels {
                    self.inv_sigma[k][c].iter_mut().for_each(|w| *w *= factor);
                }
            }
        }
    }
}
