//! GGX microfacet distribution and separable Smith shadowing, in their cosine forms.
//!
//! Contract (docs/model.md §3; Walter, Marschner, Li, Torrance, "Microfacet Models for Refraction
//! through Rough Surfaces", EGSR 2007, eqs. 33–34), with α = σ the GGX roughness:
//! ```text
//! D(θ_h)  = α² / (π (α² cos²θ_h + sin²θ_h)²)
//! G1(θ)   = 2 cosθ / (cosθ + √(α² + (1 − α²) cos²θ))
//! G       = G1(θ_i)·G1(θ_o)                       (separable, no height correlation)
//! ```
//! No tangent appears, so nothing overflows at grazing; sin²θ_h is formed as (1−c)(1+c).
//!
//! Clamps: α is clamped to ≥ [`ALPHA_MIN`] (below it GGX is a numerical delta and D(0) = 1/(πα²)
//! would overflow f32; derivatives w.r.t. α vanish there); α is not clamped above (callers
//! validate σ ∈ [0, 1]). Cosines are clamped to ≤ 1; a negative cosine (back-facing microfacet
//! or direction) gives 0, the Heaviside χ⁺ of the Smith model.

use core::f64::consts::PI;

use super::Real;

/// Smallest GGX roughness the model evaluates (σ below it behaves as σ = `ALPHA_MIN`).
pub const ALPHA_MIN: f64 = 1e-6;

/// The GGX normal distribution D(θ_h) for `cos_theta_h` = n·h and roughness `alpha`.
pub fn ggx_d<T: Real>(cos_theta_h: T, alpha: T) -> T {
    if cos_theta_h.re() < 0.0 {
        return T::zero();
    }
    let c = cos_theta_h.min_re(T::one());
    let a2 = alpha.max_re(T::from_f64(ALPHA_MIN)).sq();
    let sin2 = (T::one() - c) * (T::one() + c);
    let den = a2 * c.sq() + sin2;
    a2 / (T::from_f64(PI) * den.sq())
}

/// The Smith masking term G1(θ) for `cos_theta` = n·ω and roughness `alpha`.
pub fn smith_g1<T: Real>(cos_theta: T, alpha: T) -> T {
    if cos_theta.re() < 0.0 {
        return T::zero();
    }
    let c = cos_theta.min_re(T::one());
    c * smith_g1_over_cos(c, alpha)
}

/// G1(θ)/cosθ = 2/(cosθ + √(α² + (1 − α²) cos²θ)): finite at grazing (→ 2/α), which lets the
/// specular weight divide by cosθ_o without a singularity. Returns 0 for negative cosines.
pub fn smith_g1_over_cos<T: Real>(cos_theta: T, alpha: T) -> T {
    if cos_theta.re() < 0.0 {
        return T::zero();
    }
    let c = cos_theta.min_re(T::one());
    let a2 = alpha.max_re(T::from_f64(ALPHA_MIN)).sq();
    let root = (a2 + (T::one() - a2) * c.sq()).sqrt_clamped();
    T::from_f64(2.0) / (c + root)
}

/// The microfacet weight of a reflection lobe with the foreshortening cosine folded in
/// (docs/model.md §4): D(θ_h)·G1(θ_i)·G1(θ_o)/(4 cosθ_o) = κ·cosθ_i / ρ.
pub fn microfacet_weight<T: Real>(cos_theta_i: T, cos_theta_o: T, cos_theta_h: T, alpha: T) -> T {
    ggx_d(cos_theta_h, alpha)
        * smith_g1(cos_theta_i, alpha)
        * smith_g1_over_cos(cos_theta_o, alpha)
        * T::from_f64(0.25)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_values() {
        // docs/model.md §8 "Microfacet values".
        assert!((ggx_d(1.0, 0.3) - 3.53678).abs() < 1e-5);
        assert!((ggx_d(10f64.to_radians().cos(), 0.3) - 2.07712).abs() < 1e-5);
        assert!((smith_g1(60f64.to_radians().cos(), 0.3) - 0.94032).abs() < 1e-5);
        let c = 89.99f64.to_radians().cos();
        assert!((smith_g1(c, 0.3) - 0.0011629).abs() < 1e-7);
        // Cosine and tan forms agree.
        let t = 89.99f64.to_radians().tan();
        assert!((smith_g1(c, 0.3) - 2.0 / (1.0 + (1.0 + 0.09 * t * t).sqrt())).abs() < 1e-12);
        for a in [0.01, 0.3, 1.0] {
            assert!((ggx_d(1.0, a) - 1.0 / (PI * a * a)).abs() < 1e-9 / (a * a));
        }
    }

    #[test]
    fn d_is_normalised_projected_area() {
        // ∫ D cosθ dω = 1 over the hemisphere (midpoint rule in cosθ).
        for a in [0.1, 0.3, 0.7, 1.0] {
            let n = 200_000;
            let sum: f64 = (0..n)
                .map(|k| {
                    let c = (k as f64 + 0.5) / n as f64;
                    ggx_d(c, a) * c
                })
                .sum::<f64>()
                * 2.0
                * PI
                / n as f64;
            assert!((sum - 1.0).abs() < 1e-3, "α={a}: {sum}");
        }
    }

    #[test]
    fn degenerate_inputs_are_finite() {
        for a in [0.0f32, 1e-6, 1.0] {
            for c in [0.0f32, 1e-12, 1.0, -0.5] {
                assert!(ggx_d(c, a).is_finite() && smith_g1(c, a).is_finite());
                assert!(smith_g1_over_cos(c, a).is_finite());
                assert!(microfacet_weight(c, c, c, a).is_finite());
            }
        }
        assert_eq!(smith_g1(-0.1, 0.5), 0.0);
    }
}
