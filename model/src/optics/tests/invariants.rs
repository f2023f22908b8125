//! Physics invariants of the full model and independent re-derivations of its frames.

use core::f64::consts::PI;

use super::*;
use crate::optics::coaxial::{self, CoaxialGeometry};
use crate::optics::fresnel::{FresnelTerms, brewster_angle_rad, normal_incidence_reflectance};
use crate::optics::measure::{Analyser, FlashPolariser, SensorIntensities, dop_diffuse};
use crate::optics::pbrdf::{
    diffuse_unit, evaluate, evaluate_s0, lobe_weight, reflection_axis, reflection_unit,
    reflection_unit_naive, scalar_brdf,
};
use crate::optics::{Mueller, Rotator, Stokes};

fn max_abs_diff(a: &Mueller<f64>, b: &Mueller<f64>) -> f64 {
    a.m.iter()
        .flatten()
        .zip(b.m.iter().flatten())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn max_abs(a: &Mueller<f64>) -> f64 {
    a.m.iter().flatten().map(|x| x.abs()).fold(0.0, f64::max)
}

#[test]
fn normal_incidence_reflection_is_r0_diag_1_1_m1_m1() {
    let mut r = rng(1);
    for _ in 0..200 {
        let n = unit(&mut r);
        let eta = r.random_range(1.0..3.0);
        let up = unit(&mut r);
        let g = geometry_up::<f64>(n, n, n, up, up);
        let r0 = normal_incidence_reflectance(eta);
        let want = Mueller::diagonal([r0, r0, -r0, -r0]);
        assert!(max_abs_diff(&reflection_unit(&g, eta), &want) < 1e-15);
    }
}

#[test]
fn brewster_reflection_is_fully_s_polarised() {
    let mut r = rng(2);
    for _ in 0..200 {
        let eta = r.random_range(1.05..3.0);
        let h = unit(&mut r);
        let t = tangent(&mut r, h);
        let theta_b = brewster_angle_rad(eta);
        let wi = at_cos(h, t, theta_b.cos());
        let wo = [0, 1, 2].map(|k| 2.0 * theta_b.cos() * h[k] - wi[k]);
        let g = geometry::<f64>(h, wi, wo);
        let out = reflection_unit(&g, eta).apply(Stokes::unpolarised(1.0));
        assert!((out.dolp() - 1.0).abs() < 1e-9, "DoLP {}", out.dolp());
        // M22 = M33 = R× = 0 at Brewster.
        let m = reflection_unit(&g, eta);
        assert!(m.m[3][3].abs() < 1e-12);
        // Polarisation is along s = ω_i × ω_o.
        let s = reflection_axis(&g);
        let ang = out.aolp_rad();
        let e = g.camera_frame.x.scale(ang.cos()) + g.camera_frame.y.scale(ang.sin());
        assert!(e.cross(s).norm_squared() / s.norm_squared() < 1e-16);
        // R× changes sign across Brewster: the (3,3) entry is R×.
        for (dt, sign) in [(-1e-3, -1.0), (1e-3, 1.0)] {
            let wi2 = at_cos(h, t, (theta_b + dt).cos());
            let wo2 = [0, 1, 2].map(|k| 2.0 * (theta_b + dt).cos() * h[k] - wi2[k]);
            let m2 = reflection_unit(&geometry::<f64>(h, wi2, wo2), eta);
            assert!(m2.m[3][3] * sign > 0.0);
        }
    }
}

#[test]
fn grazing_reflection_keeps_everything() {
    let mut r = rng(3);
    for _ in 0..100 {
        let h = unit(&mut r);
        let t = tangent(&mut r, h);
        let wi = at_cos(h, t, 1e-6);
        let wo = [0, 1, 2].map(|k| 2.0 * 1e-6 * h[k] - wi[k]);
        let g = geometry::<f64>(h, wi, wo);
        let s_in = Stokes::linear(1.0, r.random_range(0.0..PI));
        let out = reflection_unit(&g, 1.5).apply(s_in);
        // R+ = 1 − O(cosθ_d): 1e-6 here, up to the rounding of h for near-opposite ω.
        assert!(
            (out.s0 - 1.0).abs() < 1e-5 && (out.dolp() - 1.0).abs() < 1e-9,
            "{out:?}"
        );
    }
}

/// Mueller matrix of a real 2×2 Jones matrix [[a, b], [c, d]] (linear 3×3 block + M33).
fn jones_to_mueller(j: [[f64; 2]; 2]) -> Mueller<f64> {
    let [[a, b], [c, d]] = j;
    let (a2, b2, c2, d2) = (a * a, b * b, c * c, d * d);
    Mueller {
        m: [
            [
                (a2 + b2 + c2 + d2) / 2.0,
                (a2 - b2 + c2 - d2) / 2.0,
                a * b + c * d,
                0.0,
            ],
            [
                (a2 + b2 - c2 - d2) / 2.0,
                (a2 - b2 - c2 + d2) / 2.0,
                a * b - c * d,
                0.0,
            ],
            [a * c + b * d, a * c - b * d, a * d + b * c, 0.0],
            [0.0, 0.0, 0.0, a * d - b * c],
        ],
    }
}

#[test]
fn specular_block_matches_3d_jones_calculus() {
    // Independent model: reflect the 3-D E-field with r_s on ŝ and Verdet r_p on p̂ = k̂ × ŝ.
    let mut r = rng(4);
    for _ in 0..2000 {
        let n = unit(&mut r);
        let t = tangent(&mut r, n);
        let wi = at_cos(n, t, r.random_range(0.05..1.0));
        let wo = at_cos(n, tangent(&mut r, n), r.random_range(0.05..1.0));
        if dot(cross(wi, wo), cross(wi, wo)) < 1e-6 {
            continue;
        }
        let eta = r.random_range(1.2..2.0);
        let g = geometry_up::<f64>(n, wi, wo, unit(&mut r), unit(&mut r));
        let f = FresnelTerms::dielectric(g.cos_theta_d, eta);
        let s = normalize(cross(wi, wo));
        let k_in = wi.map(|x| -x);
        let p_in = cross(k_in, s);
        let p_out = cross(wo, s);
        let (li, lo) = (g.light_frame, g.camera_frame);
        let mut jm = [[0.0; 2]; 2];
        for (col, e_in) in [li.x.re(), li.y.re()].into_iter().enumerate() {
            let (es, ep) = (dot(e_in, s), dot(e_in, p_in));
            let e_out = [0, 1, 2].map(|k| f.r_s * es * s[k] + f.r_p * ep * p_out[k]);
            jm[0][col] = dot(e_out, lo.x.re());
            jm[1][col] = dot(e_out, lo.y.re());
        }
        let want = jones_to_mueller(jm);
        let got = reflection_unit(&g, eta);
        assert!(max_abs_diff(&got, &want) < 1e-14, "{got:?}\n{want:?}");
        assert!(max_abs_diff(&got, &reflection_unit_naive(&g, eta)) < 1e-15);
    }
}

#[test]
fn lobes_match_the_angle_based_formulas_of_the_reference() {
    // docs/model.md §1 "Local s/p frames": C_{i→d} = C(φ_i + 90°), C_{d→o} = C(−(φ_o + 90°)),
    // φ by atan2.
    let mut r = rng(5);
    for _ in 0..2000 {
        let n = unit(&mut r);
        let wi = at_cos(n, tangent(&mut r, n), r.random_range(0.05..1.0));
        let wo = at_cos(n, tangent(&mut r, n), r.random_range(0.05..1.0));
        let eta = r.random_range(1.0..3.0);
        let g = geometry_up::<f64>(n, wi, wo, unit(&mut r), unit(&mut r));
        let az =
            |f: &crate::optics::Frame<f64>, d: [f64; 3]| dot(f.y.re(), d).atan2(dot(f.x.re(), d));
        let c_in = |d: [f64; 3]| Rotator::from_angle(az(&g.light_frame, d) + PI / 2.0).mueller();
        let c_out =
            |d: [f64; 3]| Rotator::from_angle(-(az(&g.camera_frame, d) + PI / 2.0)).mueller();
        let fi = FresnelTerms::dielectric(g.cos_theta_i, eta).transmission_mueller();
        let fo = FresnelTerms::dielectric(g.cos_theta_o, eta).transmission_mueller();
        let want_d = c_out(n)
            .mul(&fo)
            .mul(&Mueller::depolariser())
            .mul(&fi)
            .mul(&c_in(n))
            .scale(g.cos_theta_i);
        let got_d = diffuse_unit(&g, eta);
        assert!(max_abs_diff(&got_d, &want_d) < 1e-12);
        let h = g.half.re();
        let fr = FresnelTerms::dielectric(g.cos_theta_d, eta).reflection_mueller();
        let want_r = c_out(h).mul(&fr).mul(&c_in(h));
        // Tolerance: the angle-based reference goes through atan2/sin/cos.
        assert!(max_abs_diff(&reflection_unit(&g, eta), &want_r) < 1e-12);
    }
}

#[test]
fn rotating_the_bases_and_rotating_the_scene() {
    let mut r = rng(6);
    for _ in 0..500 {
        let n = unit(&mut r);
        let wi = at_cos(n, tangent(&mut r, n), r.random_range(0.0..1.0));
        let wo = at_cos(n, tangent(&mut r, n), r.random_range(0.0..1.0));
        let p = params(&mut r, 0.05);
        let (lu, cu) = (unit(&mut r), unit(&mut r));
        let g = geometry_up::<f64>(n, wi, wo, lu, cu);
        let base = evaluate(&g, &p).total(1);
        // Rotating the bases: new frames about the same z; P' = C_{o→o'} P C_{i'→i}.
        let g2 = geometry_up::<f64>(n, wi, wo, unit(&mut r), unit(&mut r));
        let rot_in = g2.light_frame.rotator_to(&g.light_frame).mueller();
        let rot_out = g.camera_frame.rotator_to(&g2.camera_frame).mueller();
        let want = rot_out.mul(&base).mul(&rot_in);
        let got = evaluate(&g2, &p).total(1);
        assert!(max_abs_diff(&got, &want) < 1e-12 * (1.0 + max_abs(&base)));
        // Rotating the element: the whole scene (normal, directions, ups) by one rotation.
        let (axis, angle) = (unit(&mut r), r.random_range(-PI..PI));
        let rot = |v: [f64; 3]| rotate(v, axis, angle);
        let g3 = geometry_up::<f64>(rot(n), rot(wi), rot(wo), rot(lu), rot(cu));
        let got3 = evaluate(&g3, &p).total(1);
        assert!(max_abs_diff(&got3, &base) < 1e-12 * (1.0 + max_abs(&base)));
    }
}

#[test]
fn diffuse_dop_and_aolp_follow_the_closed_form_and_the_normal_azimuth() {
    let mut r = rng(7);
    for _ in 0..2000 {
        let n = unit(&mut r);
        let wi = at_cos(n, tangent(&mut r, n), r.random_range(0.01..1.0));
        let wo = at_cos(n, tangent(&mut r, n), r.random_range(0.01..0.999));
        let eta = r.random_range(1.0..3.0);
        let g = geometry_up::<f64>(n, wi, wo, unit(&mut r), unit(&mut r));
        let out = diffuse_unit(&g, eta).apply(Stokes::unpolarised(1.0));
        assert!((out.dolp() - dop_diffuse(g.cos_theta_o, eta)).abs() < 1e-13);
        if out.dolp() > 1e-6 {
            // Diffuse polarisation is parallel to the plane of emission (the projected normal).
            let nl = g.camera_frame.to_local(g.normal);
            let phi = nl.y.atan2(nl.x);
            let d = (out.aolp_rad() - phi).rem_euclid(PI);
            assert!(d.min(PI - d) < 1e-9, "AoLP {} vs φ {}", out.aolp_rad(), phi);
        }
    }
}

#[test]
fn scalar_brdf_is_reciprocal_and_fast_paths_agree() {
    let mut r = rng(8);
    for _ in 0..2000 {
        let n = unit(&mut r);
        let wi = at_cos(n, tangent(&mut r, n), r.random_range(0.01..1.0));
        let wo = at_cos(n, tangent(&mut r, n), r.random_range(0.01..1.0));
        let p = params(&mut r, 0.02);
        let g = geometry::<f64>(n, wi, wo);
        let swapped = geometry::<f64>(n, wo, wi);
        let (a, b) = (scalar_brdf(&g, &p), scalar_brdf(&swapped, &p));
        let lobes = evaluate(&g, &p);
        let s_light = Stokes::new(
            1.0,
            r.random_range(-0.5..0.5),
            r.random_range(-0.5..0.5),
            0.1,
        );
        let s0 = evaluate_s0(&g, &p, s_light);
        let applied = crate::optics::pbrdf::apply(&g, &p, s_light);
        for c in 0..3 {
            let want = lobes.apply(c, s_light).to_array();
            for (x, y) in applied[c].to_array().iter().zip(want) {
                assert!((x - y).abs() <= 1e-12 * want[0].abs().max(1.0));
            }
            // P carries cosθ_i, so the reciprocal quantity is M00 / cosθ_i.
            let (x, y) = (a[c] / g.cos_theta_i, b[c] / swapped.cos_theta_i);
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{x} vs {y}");
            assert!((lobes.total(c).m[0][0] - a[c]).abs() <= 1e-12 * a[c].abs().max(1.0));
            let want = lobes.apply(c, s_light).s0;
            assert!((s0[c] - want).abs() <= 1e-12 * want.abs().max(1.0));
        }
    }
}

#[test]
fn back_facing_gives_zero_and_sensor_model_obeys_malus() {
    let n = [0.0, 0.0, 1.0];
    let p = PbrdfParams {
        eta: 1.5,
        sigma_s: 0.3,
        sigma_ss: 0.5,
        rho_s: 1.0,
        rho_ss: [0.2; 3],
        rho_d: [0.5; 3],
    };
    let below = geometry::<f64>(n, [0.6, 0.0, -0.8], [0.0, 0.0, 1.0]);
    assert_eq!(evaluate(&below, &p).total(0), Mueller::zero());
    assert_eq!(scalar_brdf(&below, &p), [0.0; 3]);
    // Normal incidence, flash polariser at ψ: the specular reflection through an analyser at θ
    // follows Malus: I = κ R(0) cos²(θ − ψ') with ψ' the mirrored angle (x_i = −x_o).
    let g = geometry::<f64>(n, n, n);
    let kappa = lobe_weight(&g, 0.3) * normal_incidence_reflectance(1.5);
    for k in 0..18 {
        let psi = (k as f64 * 10.0).to_radians();
        let out = reflection_unit(&g, 1.5)
            .scale(lobe_weight(&g, 0.3))
            .apply(FlashPolariser { angle_rad: psi }.stokes(1.0));
        for deg in [0.0, 20.0, 45.0, 90.0, 135.0] {
            let a = Analyser::from_deg(deg);
            let want = kappa * (a.angle_rad - (PI - psi)).cos().powi(2);
            assert!((a.intensity(out) - want).abs() < 1e-13);
        }
    }
}

#[test]
fn exact_coaxial_full_model_equals_talk_matrix_plus_tau_squared_terms() {
    // docs/model.md §5: the talk matrix drops exactly τ²β² at (1,1), ±τ²αβ at (1,2)/(2,1),
    // −τ²α² at (2,2).
    let mut r = rng(9);
    for _ in 0..2000 {
        let n = unit(&mut r);
        let w = at_cos(n, tangent(&mut r, n), r.random_range(0.0..1.0));
        let up = unit(&mut r);
        let p = params(&mut r, 0.05);
        let g = geometry_up::<f64>(n, w, w, up, up);
        let cg = CoaxialGeometry::from_world(g.normal, &g.camera_frame);
        let terms = coaxial::terms(&cg, &p);
        let lobes = evaluate(&g, &p);
        for (c, term) in terms.iter().enumerate() {
            let full = lobes.total(c).linear3();
            let mut approx = term.linear3();
            let tau = -FresnelTerms::dielectric(cg.cos_theta, p.eta).t_minus();
            let k = p.rho_d[c] * cg.cos_theta * tau * tau;
            approx[1][1] += k * cg.beta * cg.beta;
            approx[1][2] -= k * cg.alpha * cg.beta;
            approx[2][1] += k * cg.alpha * cg.beta;
            approx[2][2] -= k * cg.alpha * cg.alpha;
            for i in 0..3 {
                for j in 0..3 {
                    assert!(
                        (full[i][j] - approx[i][j]).abs() < 1e-12 * (1.0 + full[0][0]),
                        "{full:?} {approx:?}"
                    );
                }
            }
            // Camera channel identity on model output.
            let s = lobes.apply(c, FlashPolariser::default().stokes(1.0));
            let i = SensorIntensities::from_stokes(s);
            assert!((i.i0 + i.i90 - i.i45 - i.i135).abs() < 1e-12);
        }
    }
}

#[test]
fn polarimetric_reciprocity_of_every_lobe() {
    // Reciprocity for Mueller matrices (Sekera 1966): with the reversed path's frames obtained by
    // turning the original ones 180° about x (x' = x, y' = −y, z' = −z),
    // P(ω_o → ω_i) = Q·P(ω_i → ω_o)ᵀ·Q, Q = diag(1, 1, −1, 1), up to the foreshortening cosine
    // folded into P (cosθ_i forward, cosθ_o reversed).
    use crate::optics::{Frame, Vec3};
    let mut r = rng(10);
    let q = Mueller::diagonal([1.0, 1.0, -1.0, 1.0]);
    for _ in 0..2000 {
        let n = unit(&mut r);
        let wi = at_cos(n, tangent(&mut r, n), r.random_range(0.02..1.0));
        let wo = at_cos(n, tangent(&mut r, n), r.random_range(0.02..1.0));
        let p = params(&mut r, 0.05);
        let g = geometry_up::<f64>(n, wi, wo, unit(&mut r), unit(&mut r));
        let turn = |f: &Frame<f64>| Frame {
            x: f.x,
            y: -f.y,
            z: -f.z,
        };
        let rev = crate::optics::pbrdf::Geometry::new(
            Vec3::from_f64(n),
            Vec3::from_f64(wo),
            Vec3::from_f64(wi),
            turn(&g.camera_frame),
            turn(&g.light_frame),
        )
        .unwrap();
        let (fwd, bwd) = (evaluate(&g, &p), evaluate(&rev, &p));
        for c in 0..3 {
            let a = fwd.total(c).scale(1.0 / g.cos_theta_i);
            let b = q
                .mul(&bwd.total(c).transpose())
                .mul(&q)
                .scale(1.0 / rev.cos_theta_i);
            assert!(
                max_abs_diff(&a, &b) < 1e-12 * (1.0 + max_abs(&a)),
                "{a:?}\n{b:?}"
            );
        }
    }
}
