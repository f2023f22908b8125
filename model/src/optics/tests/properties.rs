//! Whole-domain sweeps: over a million random and adversarial evaluations, every output is
//! finite and maps physically valid Stokes vectors to physically valid ones, in f32 and f64;
//! f32 agrees with f64 where the problem is well conditioned.

use proptest::prelude::*;
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::optics::measure::{FlashPolariser, observe};
use crate::optics::pbrdf::{evaluate, evaluate_s0, scalar_brdf};
use crate::optics::{Mueller, Stokes};

/// Relative tolerance of the Stokes validity check √(s1²+s2²+s3²) ≤ s0 in f64 / f32.
const VALID_TOL_F64: f64 = 1e-12;
const VALID_TOL_F32: f64 = 1e-5;
/// f32 vs f64: max entry difference relative to the largest f64 entry, where conditioned.
const F32_REL_TOL: f64 = 2e-4;

struct Case {
    n: [f64; 3],
    wi: [f64; 3],
    wo: [f64; 3],
    light_up: [f64; 3],
    camera_up: [f64; 3],
    p: PbrdfParams<f64>,
    /// True when the inputs are away from every degenerate value (f32 vs f64 comparable).
    conditioned: bool,
}

/// Half of the draws are adversarial specials, the rest uniform in [lo, hi].
fn pick(r: &mut ChaCha8Rng, special: &[f64], lo: f64, hi: f64) -> f64 {
    if r.random_bool(0.5) {
        special[r.random_range(0..special.len())]
    } else {
        r.random_range(lo..=hi)
    }
}

fn case(r: &mut ChaCha8Rng) -> Case {
    let axis_aligned = r.random_bool(0.2);
    let n = if axis_aligned {
        [0.0, 0.0, 1.0]
    } else {
        unit(r)
    };
    let cos_specials: [f64; 3] = [0.0, 1e-12, 1.0];
    let ci = pick(r, &cos_specials, 0.0, 1.0);
    let co = pick(r, &cos_specials, 0.0, 1.0);
    let eta: f64 = pick(r, &[1.0, 1.0 + 1e-9, 3.0], 1.0, 3.0);
    let mut wi = at_cos(n, tangent(r, n), ci);
    let mut wo = at_cos(n, tangent(r, n), co);
    match r.random_range(0..10) {
        // Exactly coaxial: azimuth undefined.
        0 => wo = wi,
        // Exactly at Brewster on the microfacet.
        1 => {
            let tb = eta.atan();
            let h = at_cos(n, tangent(r, n), r.random_range(0.5..=1.0));
            wi = at_cos(h, tangent(r, h), tb.cos());
            wo = [0, 1, 2].map(|k| 2.0 * tb.cos() * h[k] - wi[k]);
        }
        // Opposite directions (grazing both sides).
        2 if ci == 0.0 => wo = wi.map(|x| -x),
        // Below the horizon.
        3 => wi = at_cos(n, tangent(r, n), -r.random_range(0.0..1.0)),
        _ => {}
    }
    // Up vectors: random, parallel to the propagation axis, or zero (fallbacks).
    let up = |r: &mut ChaCha8Rng, z: [f64; 3]| match r.random_range(0..6) {
        0 => z,
        1 => [0.0; 3],
        _ => unit(r),
    };
    let light_up = up(r, wi);
    let camera_up = up(r, wo);
    let sigma_specials: [f64; 3] = [0.0, 1e-6, 1.0];
    let a: f64 = pick(r, &sigma_specials, 0.0, 1.0);
    let b: f64 = pick(r, &sigma_specials, 0.0, 1.0);
    let albedo = |r: &mut ChaCha8Rng| {
        if r.random_bool(0.2) {
            0.0
        } else {
            r.random_range(0.0..2.0)
        }
    };
    let p = PbrdfParams {
        eta,
        sigma_s: a.min(b),
        sigma_ss: a.max(b),
        rho_s: albedo(r),
        rho_ss: [(); 3].map(|_| albedo(r)),
        rho_d: [(); 3].map(|_| albedo(r)),
    };
    let cos_ok = |c: f64| (1e-3..=1.0).contains(&c);
    let conditioned = cos_ok(dot(n, wi)) && cos_ok(dot(n, wo)) && a.min(b) >= 0.05 && eta >= 1.01;
    Case {
        n,
        wi,
        wo,
        light_up,
        camera_up,
        p,
        conditioned,
    }
}

/// A random physically valid Stokes vector (a third fully polarised).
fn stokes(r: &mut impl Rng) -> Stokes<f64> {
    let d = unit(r);
    let dop = if r.random_bool(0.33) {
        1.0
    } else {
        r.random_range(0.0..=1.0)
    };
    let s0 = r.random_range(0.0..2.0);
    Stokes::new(s0, s0 * dop * d[0], s0 * dop * d[1], s0 * dop * d[2])
}

/// Every entry finite, and every valid input maps to a valid output: s0 ≥ −slack and
/// √(s1²+s2²+s3²) ≤ s0 + slack, with slack = tol·max|M|·s0_in (the rounding scale of the product:
/// outputs may be tiny after cancellation, so the slack is relative to the computation, not to
/// the output).
fn check_matrix<T: Real>(m: &Mueller<T>, inputs: &[Stokes<f64>], tol: f64) {
    assert!(m.is_finite(), "{m:?}");
    let max_entry = m.re().iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    for s in inputs {
        let out = m.apply(Stokes::from_array(s.to_array().map(T::from_f64)));
        let [s0, s1, s2, s3] = out.to_array().map(Real::re);
        let slack = tol * max_entry * s.s0 * 4.0;
        let pol = (s1 * s1 + s2 * s2 + s3 * s3).sqrt();
        assert!(
            s0 >= -slack && pol <= s0 + slack,
            "{out:?} from {s:?} through {m:?}"
        );
    }
}

#[test]
fn million_random_and_adversarial_evaluations_are_finite_and_physical() {
    let mut r = rng(100);
    let cases = 250_000;
    let mut evaluations = 0usize;
    let mut worst_f32 = 0.0f64;
    for _ in 0..cases {
        let c = case(&mut r);
        let inputs = [stokes(&mut r), stokes(&mut r)];
        let g64 = geometry_up::<f64>(c.n, c.wi, c.wo, c.light_up, c.camera_up);
        let g32 = geometry_up::<f32>(c.n, c.wi, c.wo, c.light_up, c.camera_up);
        let p32: PbrdfParams<f32> = c.p.cast();
        let l64 = evaluate(&g64, &c.p);
        let l32 = evaluate(&g32, &p32);
        let s_flash = FlashPolariser::default().stokes(1.0);
        let o64 = observe(&g64, &c.p, FlashPolariser::default());
        let s0 = evaluate_s0(&g64, &c.p, s_flash);
        let m00 = scalar_brdf(&g32, &p32);
        evaluations += 5;
        for ch in 0..3 {
            for (name, m) in [
                ("diffuse", l64.diffuse[ch]),
                ("ss", l64.single_scattering[ch]),
                ("total", l64.total(ch)),
            ] {
                let _ = name;
                check_matrix(&m, &inputs, VALID_TOL_F64);
            }
            check_matrix(&l32.total(ch), &inputs, VALID_TOL_F32);
            assert!(
                o64[ch].diffuse.is_finite()
                    && o64[ch].specular.is_finite()
                    && o64[ch].alpha.is_finite()
            );
            assert!(s0[ch].is_finite() && m00[ch].is_finite() && m00[ch] >= 0.0);
            if c.conditioned {
                let (a, b) = (l64.total(ch), l32.total(ch));
                let scale = a.m.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
                if scale > 0.0 {
                    let diff =
                        a.m.iter()
                            .flatten()
                            .zip(b.m.iter().flatten())
                            .fold(0.0f64, |m, (x, y)| m.max((x - *y as f64).abs()));
                    worst_f32 = worst_f32.max(diff / scale);
                }
            }
        }
        check_matrix(&l64.specular, &inputs, VALID_TOL_F64);
    }
    assert!(evaluations >= 1_000_000);
    assert!(
        worst_f32 < F32_REL_TOL,
        "f32 vs f64 relative difference {worst_f32}"
    );
}

proptest! {
    #[test]
    fn total_lobe_maps_valid_stokes_to_valid_stokes(
        ci in 0.0f64..=1.0, co in 0.0f64..=1.0, az_i in 0.0f64..6.3, az_o in 0.0f64..6.3,
        eta in 1.0f64..3.0, sa in 0.0f64..=1.0, sb in 0.0f64..=1.0,
        rho in prop::array::uniform3(0.0f64..2.0), dop in 0.0f64..=1.0, chi in 0.0f64..6.3,
    ) {
        let n = [0.0, 0.0, 1.0];
        let wi = at_cos(n, [az_i.cos(), az_i.sin(), 0.0], ci);
        let wo = at_cos(n, [az_o.cos(), az_o.sin(), 0.0], co);
        let p = PbrdfParams { eta, sigma_s: sa.min(sb), sigma_ss: sa.max(sb), rho_s: rho[0], rho_ss: rho, rho_d: rho };
        let g = geometry::<f64>(n, wi, wo);
        let s = Stokes::new(1.0, dop * chi.cos(), dop * chi.sin() * 0.8, dop * chi.sin() * 0.6);
        for ch in 0..3 {
            let out = evaluate(&g, &p).apply(ch, s);
            prop_assert!(out.is_physical(VALID_TOL_F64), "{:?}", out);
        }
    }
}
