//! Virtual specular samples (optics.md §7.7–§7.8): a cluster's two-lobe model evaluated on a
//! grid of exactly coaxial half-angles, weighted per vertex by a Gaussian kernel of the
//! vertex's feature distance to the cluster centroid.
//!
//! Contract:
//! - Profile: θ_h,m = m · 90°/M for m = 0…M−1 (M = 180: 0°…89.5° in 0.5° steps); the value
//!   is `coaxial::specular_term(cosθ_h, params)` = R(0)(ρ_s D_s G_s + ρ_ss,c D_ss G_ss)/(4cosθ_h)
//!   at θ_i = θ_o = θ_h with R(0) from η_cluster (optics.md §4), clipped to ≤ 1 (§7.7), in
//!   model units (the cluster model is fitted in model units, so no mean-N bridge is needed).
//! - Weights: raw_m = exp(−d²/(2σ_k²))·cosθ_h,m with d the Euclidean (not squared) feature
//!   distance to the centroid and σ_k = 0.1, as the paper's equation is written. The released
//!   code's k-means returns squared distances, which would make the kernel exp(−d⁴/0.02), a
//!   much wider gate (d < 0.55 instead of d < 0.30 for raw > 0.01 at θ_h = 0); we keep the
//!   written form, whose reach is set by the feature scaling (`cluster::FeatureScaling`).
//!   Samples with raw ≤ `min_raw_weight` (0.01) are dropped and the rest renormalised to sum
//!   to λ_g (0.1). Because cosθ_h decreases along the grid, the kept samples are a prefix of
//!   the profile; a vertex whose kernel value is ≤ 0.01 gets none (an empty vector).

use ellipso_sim::optics::coaxial::specular_term;
use ellipso_sim::optics::pbrdf::PbrdfParams;

use crate::fit::data::VirtualSample;

/// One cluster's coaxial profile: (cosθ_h, I^s RGB clipped to ≤ 1) on the half-angle grid.
pub fn coaxial_profile(
    eta: f64,
    sigma_s: f64,
    sigma_ss: f64,
    rho_s: f64,
    rho_ss: [f64; 3],
    samples: usize,
) -> Vec<(f64, [f64; 3])> {
    let params = PbrdfParams {
        eta,
        sigma_s,
        sigma_ss,
        rho_s,
        rho_ss,
        rho_d: [0.0; 3],
    };
    (0..samples)
        .map(|m| {
            let theta_h = (90.0 * m as f64 / samples as f64).to_radians();
            let c = theta_h.cos();
            (c, specular_term(c, &params).map(|v| v.min(1.0)))
        })
        .collect()
}

/// The Gaussian kernel exp(−d²/(2σ²)) of a feature distance `distance` (≥ 0, not squared).
pub fn kernel(distance: f64, sigma: f64) -> f64 {
    (-(distance * distance) / (2.0 * sigma * sigma)).exp()
}

/// A vertex's virtual samples from `profile` at feature distance `distance` (module doc).
/// Empty when no raw weight exceeds `min_raw_weight` or the inputs are not finite.
pub fn weighted(
    profile: &[(f64, [f64; 3])],
    distance: f64,
    kernel_sigma: f64,
    min_raw_weight: f64,
    lambda_g: f64,
) -> Vec<VirtualSample> {
    let k = kernel(distance, kernel_sigma);
    if !(k.is_finite() && lambda_g.is_finite() && lambda_g > 0.0) {
        return Vec::new();
    }
    let kept: Vec<(f64, [f64; 3], f64)> = profile
        .iter()
        .map(|&(c, v)| (c, v, k * c))
        .filter(|&(_, v, raw)| raw > min_raw_weight && v.iter().all(|x| x.is_finite()))
        .collect();
    let total: f64 = kept.iter().map(|s| s.2).sum();
    if total.is_nan() || total <= 0.0 {
        return Vec::new();
    }
    kept.into_iter()
        .map(|(cos_theta_h, specular, raw)| VirtualSample {
            cos_theta_h,
            specular,
            weight: lambda_g * raw / total,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_sim::optics::fresnel::normal_incidence_reflectance;
    use ellipso_sim::optics::microfacet::{ggx_d, smith_g1};

    #[test]
    fn profile_grid_and_values() {
        let p = coaxial_profile(1.5, 0.2, 0.5, 0.6, [0.3, 0.2, 0.1], 180);
        assert_eq!(p.len(), 180);
        assert_eq!(p[0].0, 1.0);
        assert!((p[179].0 - 89.5f64.to_radians().cos()).abs() < 1e-15);
        for (m, (c, _)) in p.iter().enumerate() {
            assert!((c.acos().to_degrees() - 0.5 * m as f64).abs() < 1e-9);
        }
        // Spot value against the coaxial formula of optics.md §4, built from D and G1.
        let (c, v) = p[40];
        let r0 = normal_incidence_reflectance(1.5);
        let lobe = |a: f64| ggx_d(c, a) * smith_g1(c, a).powi(2) / (4.0 * c);
        for (ch, rho_ss) in [0.3, 0.2, 0.1].iter().enumerate() {
            let want = r0 * (0.6 * lobe(0.2) + rho_ss * lobe(0.5));
            assert!(
                (v[ch] - want).abs() < 1e-12 * want.max(1.0),
                "{} vs {want}",
                v[ch]
            );
        }
        // A very sharp, bright lobe clips to 1 at normal incidence.
        let sharp = coaxial_profile(1.5, 0.01, 0.01, 10.0, [1.0; 3], 180);
        assert_eq!(sharp[0].1, [1.0; 3]);
        assert!(
            sharp
                .iter()
                .all(|(_, v)| v.iter().all(|x| *x <= 1.0 && *x >= 0.0))
        );
    }

    #[test]
    fn weights_sum_to_lambda_and_far_vertices_get_none() {
        let p = coaxial_profile(1.5, 0.2, 0.5, 0.6, [0.3, 0.2, 0.1], 180);
        let near = weighted(&p, 0.0, 0.1, 0.01, 0.1);
        // cosθ_h > 0.01 up to θ_h = 89.43°: all but the last (89.5°) are kept at d = 0.
        assert_eq!(near.len(), 179);
        let sum: f64 = near.iter().map(|s| s.weight).sum();
        assert!((sum - 0.1).abs() < 1e-15);
        // Weights fall with θ_h as cosθ_h does.
        assert!((near[0].weight / near[120].weight - 1.0 / 60f64.to_radians().cos()).abs() < 1e-12);
        // d = 0.25: kernel 0.0439, so cosθ_h must exceed 0.228 (θ_h < 76.8°).
        let mid = weighted(&p, 0.25, 0.1, 0.01, 0.1);
        assert_eq!(mid.len(), 154);
        assert!((mid.iter().map(|s| s.weight).sum::<f64>() - 0.1).abs() < 1e-15);
        // Beyond d = 0.1·√(2 ln 100) = 0.3035 nothing survives.
        assert!(weighted(&p, 0.31, 0.1, 0.01, 0.1).is_empty());
        assert!(weighted(&p, f64::INFINITY, 0.1, 0.01, 0.1).is_empty());
        assert!(weighted(&p, f64::NAN, 0.1, 0.01, 0.1).is_empty());
        assert!(weighted(&[], 0.0, 0.1, 0.01, 0.1).is_empty());
    }
}
