//! η_cluster of the augmentation (docs/fit-augment.md "Cluster model"): the refractive index
//! that best explains the diffuse degree of polarisation of a cluster's samples.
//!
//! Contract:
//! - Each sample's diffuse-only Stokes vector is the observation minus the vertex's own
//!   fitted specular + single-scattering prediction (`measure::observe` with ρ_d = 0). Channels
//!   are combined with weights ρ_d/Σρ_d (docs/model.md §11 "Monochrome projection"), and
//!   DoP = (s1·u1 + s2·u2)/s0 with s0 = I^d + I^s, s1 = I^s, s2 = −I^α of that diffuse part and
//!   (u1, u2) the unit direction of the model's diffuse polarisation at the fitted normal: the
//!   polarised part projected on its predicted direction is linear in the data, so unlike
//!   √(s1² + s2²) it carries no Rice bias on dark samples (docs/model.md §12, dark pixels).
//!   Noiseless it is exactly |T−|/T+ of the rank-one diffuse lobe, i.e. `dop_diffuse(θ_o, η)`,
//!   with no τ² bias. Deliberate difference: the paper uses raw I^s as β and DP/I^d (biased by
//!   the specular and by the dropped τ² terms, up to ~6 % of DoP at DoP 0.25).
//! - Samples with s0 ≤ 0, |DoP| > 2 (gross outliers only: a one-sided cut would bias), a
//!   degenerate direction (normal incidence) or a specular prediction larger than the diffuse
//!   s0 are dropped.
//! - η ∈ [1, 3] minimises Σ(DoP − DoP_d(θ_o, η))²: a grid (step 0.01), then Gauss–Newton with
//!   the closed-form ∂DoP/∂η (`measure::dop_diffuse_with_d_eta`) and step halving.

use ellipso_model::optics::measure::{
    FlashPolariser, dop_diffuse, dop_diffuse_with_d_eta, observe,
};
use ellipso_model::optics::pbrdf::{Geometry, PbrdfParams};

use crate::data::{Sample, VertexFit};

/// Bounds of η_cluster.
pub const ETA_RANGE: (f64, f64) = (1.0, 3.0);
/// Fewer usable DoP samples than this: η_cluster falls back to the members' median η.
pub const MIN_ETA_SAMPLES: usize = 16;

/// One sample's diffuse DoP and view angle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DopSample {
    /// cosθ_o (fitted normal · direction to the camera).
    pub cos_theta_o: f64,
    /// Observed diffuse DoP (module doc).
    pub dop: f64,
}

/// The channel weights ρ_d/Σρ_d (equal when Σρ_d is not positive).
fn channel_weights(rho_d: [f64; 3]) -> [f64; 3] {
    let sum: f64 = rho_d.iter().map(|v| v.max(0.0)).sum();
    if sum > 0.0 && sum.is_finite() {
        rho_d.map(|v| v.max(0.0) / sum)
    } else {
        [1.0 / 3.0; 3]
    }
}

/// The diffuse DoP of one sample (module doc), or `None` when unusable.
pub fn dop_sample(
    g: &Geometry<f64>,
    flash: FlashPolariser,
    sample: &Sample,
    fit: &VertexFit,
) -> Option<DopSample> {
    let spec_params = PbrdfParams {
        rho_d: [0.0; 3],
        ..fit.params
    };
    let spec = observe(g, &spec_params, flash);
    let w = channel_weights(fit.params.rho_d);
    let (mut i_d, mut i_s, mut i_a, mut spec_s0) = (0.0, 0.0, 0.0, 0.0);
    for c in 0..3 {
        let [d, s, a, _] = sample.channels[c].map(f64::from);
        i_d += w[c] * (d - spec[c].diffuse);
        i_s += w[c] * (s - spec[c].specular);
        i_a += w[c] * (a - spec[c].alpha);
        spec_s0 += w[c] * (spec[c].diffuse + spec[c].specular);
    }
    let s0 = i_d + i_s;
    if s0.is_nan() || s0 <= 0.0 || spec_s0 > s0 {
        return None;
    }
    // The diffuse lobe's own polarisation direction in (I^s, I^α) at the fitted normal: the
    // observed DP is projected on it (linear in the data, so no Rice bias, docs/model.md §12);
    // √(I^s² + I^α²) is biased up by the noise on dark samples.
    let diffuse_params = PbrdfParams {
        rho_s: 0.0,
        rho_ss: [0.0; 3],
        rho_d: [1.0; 3],
        ..fit.params
    };
    let u = observe(g, &diffuse_params, flash)[0];
    let norm = u.specular.hypot(u.alpha);
    if norm.is_nan() || norm <= 1e-12 * u.diffuse.abs() {
        return None;
    }
    let dop = (i_s * u.specular + i_a * u.alpha) / (norm * s0);
    // A symmetric guard against gross outliers only (a one-sided DoP ≤ 1 cut would bias).
    (dop.is_finite() && dop.abs() <= 2.0).then_some(DopSample {
        cos_theta_o: g.cos_theta_o,
        dop,
    })
}

/// Σ(DoP − DoP_d(θ_o, η))².
fn eta_cost(samples: &[DopSample], eta: f64) -> f64 {
    samples
        .iter()
        .map(|s| (s.dop - dop_diffuse(s.cos_theta_o, eta)).powi(2))
        .sum()
}

/// η ∈ [1, 3] minimising the DoP residuals, or `None` with fewer than [`MIN_ETA_SAMPLES`].
pub fn fit_eta(samples: &[DopSample]) -> Option<f64> {
    if samples.len() < MIN_ETA_SAMPLES {
        return None;
    }
    let (lo, hi) = ETA_RANGE;
    let steps = ((hi - lo) / 0.01).round() as usize;
    let (mut eta, mut cost) = (0..=steps)
        .map(|k| lo + (hi - lo) * k as f64 / steps as f64)
        .map(|e| (e, eta_cost(samples, e)))
        .fold((lo, f64::INFINITY), |b, c| if c.1 < b.1 { c } else { b });
    for _ in 0..50 {
        let (mut num, mut den) = (0.0, 0.0);
        for s in samples {
            let (model, d) = dop_diffuse_with_d_eta(s.cos_theta_o, eta);
            num += (model - s.dop) * d;
            den += d * d;
        }
        if den.is_nan() || den <= 0.0 {
            break;
        }
        let mut step = -num / den;
        let mut accepted = false;
        for _ in 0..20 {
            let next = (eta + step).clamp(lo, hi);
            let c = eta_cost(samples, next);
            if c < cost {
                (eta, cost, accepted) = (next, c, true);
                break;
            }
            step *= 0.5;
        }
        if !accepted || step.abs() < 1e-13 {
            break;
        }
    }
    Some(eta)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eta_fit_recovers_eta_from_exact_dop() {
        for eta in [1.05, 1.33, 1.5, 2.3, 2.95] {
            let samples: Vec<DopSample> = (0..40)
                .map(|k| {
                    let c = (2.0 * k as f64).to_radians().cos();
                    DopSample {
                        cos_theta_o: c,
                        dop: dop_diffuse(c, eta),
                    }
                })
                .collect();
            let got = fit_eta(&samples).unwrap();
            assert!((got - eta).abs() < 1e-9, "η={eta}: {got}");
        }
        assert!(fit_eta(&[]).is_none());
    }
}
