//! The dual-number Jacobian against central differences, and the coaxial approximation
//! against the full model at the rig's flash offset.

use super::jacobian::{N_FIT_PARAMS, observe_with_jacobian, slot};
use super::*;
use crate::optics::coaxial::{self, CoaxialGeometry};
use crate::optics::measure::{
    FlashPolariser, ObservationChannels, dop_diffuse_with_d_eta, observe,
};
use crate::optics::pbrdf::evaluate;

fn flat(o: &[ObservationChannels<f64>; 3]) -> [f64; 9] {
    core::array::from_fn(|k| {
        let c = &o[k / 3];
        [c.diffuse, c.specular, c.alpha][k % 3]
    })
}

/// Reads input `slot` of (params, normal).
fn perturb(
    p: &PbrdfParams<f64>,
    n: [f64; 3],
    index: usize,
    delta: f64,
) -> (PbrdfParams<f64>, [f64; 3]) {
    let (mut p, mut n) = (*p, n);
    match index {
        slot::ETA => p.eta += delta,
        slot::SIGMA_S => p.sigma_s += delta,
        slot::SIGMA_SS => p.sigma_ss += delta,
        slot::RHO_S => p.rho_s += delta,
        4..=6 => p.rho_ss[index - 4] += delta,
        7..=9 => p.rho_d[index - 7] += delta,
        _ => n[index - 10] += delta,
    }
    (p, n)
}

#[test]
fn dual_jacobian_matches_central_differences_at_ten_thousand_points() {
    let mut r = rng(200);
    let mut checked = 0;
    let mut worst = 0.0f64;
    while checked < 10_000 {
        let n = unit(&mut r);
        let wi = at_cos(n, tangent(&mut r, n), r.random_range(0.1..0.95));
        let wo = at_cos(n, tangent(&mut r, n), r.random_range(0.1..0.95));
        // Away from the kinks: no near-coaxial pair, no clamp active (σ ≥ 0.05, η > 1).
        if dot(wi, wo) > 0.9995 {
            continue;
        }
        let p = params(&mut r, 0.05);
        let g = geometry::<f64>(n, wi, wo);
        let (lf, cf) = (g.light_frame, g.camera_frame);
        let (twi, two) = (
            crate::optics::Vec3::from_f64(wi),
            crate::optics::Vec3::from_f64(wo),
        );
        let jac =
            observe_with_jacobian(n, twi, two, &lf, &cf, &p, FlashPolariser::default()).unwrap();
        let value = |p: &PbrdfParams<f64>, n: [f64; 3]| {
            let g = crate::optics::pbrdf::Geometry::new(
                crate::optics::Vec3::from_f64(n),
                twi,
                two,
                lf,
                cf,
            )
            .unwrap();
            flat(&observe(&g, p, FlashPolariser::default()))
        };
        let v0 = value(&p, n);
        let scale = v0.iter().fold(0.0f64, |m, x| m.max(x.abs())) + 1e-3;
        for index in 0..N_FIT_PARAMS {
            let h = 1e-6;
            let (pp, np) = perturb(&p, n, index, h);
            let (pm, nm) = perturb(&p, n, index, -h);
            let (vp, vm) = (value(&pp, np), value(&pm, nm));
            for k in 0..9 {
                let c = &jac[k / 3];
                let ad = [c.diffuse, c.specular, c.alpha][k % 3];
                assert!((ad.re - v0[k]).abs() <= 1e-14 * scale);
                let fd = (vp[k] - vm[k]) / (2.0 * h);
                let err = (ad.du[index] - fd).abs() / (scale + ad.du[index].abs());
                worst = worst.max(err);
                assert!(
                    err < 1e-5,
                    "input {index}, output {k}: dual {} vs central {fd}",
                    ad.du[index]
                );
            }
        }
        checked += 1;
    }
    assert!(worst < 1e-5);
}

#[test]
fn coaxial_dual_derivatives_match_central_differences() {
    use super::jacobian::{seed_normal, seed_params};
    use crate::optics::{Frame, Vec3};
    let mut r = rng(202);
    let camera = Frame::camera(
        Vec3::from_f64([0.0, 0.0, 1.0]),
        Vec3::from_f64([0.0, 1.0, 0.0]),
    )
    .unwrap();
    let flat = |t: &[coaxial::CoaxialTerms<f64>; 3]| -> [f64; 12] {
        core::array::from_fn(|k| {
            let c = &t[k / 4];
            [c.ds, c.ss, c.dp_alpha, c.dp_beta][k % 4]
        })
    };
    for _ in 0..2000 {
        let n = at_cos(
            [0.0, 0.0, 1.0],
            tangent(&mut r, [0.0, 0.0, 1.0]),
            r.random_range(0.2..0.98),
        );
        let p = params(&mut r, 0.05);
        let dual = coaxial::terms(
            &CoaxialGeometry::from_world(seed_normal(n), &camera.cast()),
            &seed_params(&p),
        );
        let value = |p: &PbrdfParams<f64>, n: [f64; 3]| {
            let n = Vec3::from_f64(n).normalized_or_none(0.0).unwrap();
            flat(&coaxial::terms(&CoaxialGeometry::from_world(n, &camera), p))
        };
        let v0 = value(&p, n);
        let scale = v0.iter().fold(0.0f64, |m, x| m.max(x.abs())) + 1e-3;
        for index in 0..N_FIT_PARAMS {
            let h = 1e-6;
            let ((pp, np), (pm, nm)) = (perturb(&p, n, index, h), perturb(&p, n, index, -h));
            let (vp, vm) = (value(&pp, np), value(&pm, nm));
            for k in 0..12 {
                let c = &dual[k / 4];
                let ad = [c.ds, c.ss, c.dp_alpha, c.dp_beta][k % 4].du[index];
                let fd = (vp[k] - vm[k]) / (2.0 * h);
                assert!(
                    (ad - fd).abs() / (scale + ad.abs()) < 1e-5,
                    "input {index}, term {k}: {ad} vs {fd}"
                );
            }
        }
    }
}

#[test]
fn jacobian_has_no_component_along_the_normal_and_clamped_inputs_have_none() {
    let mut r = rng(203);
    for _ in 0..200 {
        let n = unit(&mut r);
        let wi = at_cos(n, tangent(&mut r, n), r.random_range(0.1..0.95));
        let wo = at_cos(n, tangent(&mut r, n), r.random_range(0.1..0.95));
        let p = params(&mut r, 0.05);
        let g = geometry::<f64>(n, wi, wo);
        let (twi, two) = (
            crate::optics::Vec3::from_f64(wi),
            crate::optics::Vec3::from_f64(wo),
        );
        let jac = observe_with_jacobian(
            n,
            twi,
            two,
            &g.light_frame,
            &g.camera_frame,
            &p,
            FlashPolariser::default(),
        )
        .unwrap();
        for c in &jac {
            for o in [c.diffuse, c.specular, c.alpha] {
                // Scaling the normal changes nothing: ∇_n · n = 0.
                let along: f64 = (0..3).map(|k| o.du[slot::NORMAL[k]] * n[k]).sum();
                assert!(along.abs() < 1e-10 * (1.0 + o.re.abs()));
            }
        }
        // Below ALPHA_MIN the roughness is clamped: no derivative flows through σ.
        let tiny = PbrdfParams {
            sigma_s: 1e-9,
            sigma_ss: 1e-8,
            ..p
        };
        let jac = observe_with_jacobian(
            n,
            twi,
            two,
            &g.light_frame,
            &g.camera_frame,
            &tiny,
            FlashPolariser::default(),
        )
        .unwrap();
        assert!(
            jac.iter().all(
                |c| c.specular.du[slot::SIGMA_S] == 0.0 && c.specular.du[slot::SIGMA_SS] == 0.0
            )
        );
    }
}

#[test]
fn dop_derivative_matches_central_differences() {
    let mut r = rng(201);
    for _ in 0..10_000 {
        let (c, eta) = (r.random_range(0.01..1.0), r.random_range(1.05..3.0));
        let (_, d) = dop_diffuse_with_d_eta(c, eta);
        let h = 1e-6;
        let fd = (dop_diffuse_with_d_eta(c, eta + h).0 - dop_diffuse_with_d_eta(c, eta - h).0)
            / (2.0 * h);
        assert!((d - fd).abs() < 1e-8, "c={c} η={eta}: {d} vs {fd}");
    }
}

/// Worst deviations of the coaxial 3×3 observations from the full model over random normals,
/// flash directions and albedos at a flash offset of `offset_deg`, for θ_o ≤ `max_theta_deg`
/// and σ_s = σ_ss = `sigma`. Returns [|ΔI^d|, |ΔI^s|, |ΔI^α|] / (DS + SS) and, for the diffuse
/// lobe alone, |ΔI^d| / DS: the worst case over the samples and the mean.
pub(crate) fn coaxial_deviation(
    offset_deg: f64,
    max_theta_deg: f64,
    sigma: f64,
    samples: usize,
    seed: u64,
) -> ([f64; 4], [f64; 4]) {
    let mut r = rng(seed);
    let mut worst = [0.0f64; 4];
    let mut sum = [0.0f64; 4];
    let mut count = 0usize;
    let flash = FlashPolariser::default().stokes(1.0);
    for _ in 0..samples {
        let n = unit(&mut r);
        let wo = at_cos(
            n,
            tangent(&mut r, n),
            r.random_range(max_theta_deg.to_radians().cos()..=1.0),
        );
        let axis = tangent(&mut r, wo);
        let wi = rotate(wo, axis, offset_deg.to_radians());
        if dot(n, wi) <= 0.0 {
            continue;
        }
        let p = PbrdfParams {
            sigma_s: sigma,
            sigma_ss: sigma,
            ..params(&mut r, 0.1)
        };
        // The flash is rigidly mounted: its up vector is the camera's (image up ⊥ ω_o).
        let up = tangent(&mut r, wo);
        let g = geometry_up::<f64>(n, wi, wo, up, up);
        let full = evaluate(&g, &p);
        let terms = coaxial::terms(&CoaxialGeometry::from_world(g.normal, &g.camera_frame), &p);
        for (c, t) in terms.iter().enumerate() {
            let s = full.apply(c, flash);
            let approx = t.observation();
            let scale = t.ds + t.ss;
            if scale > 1e-9 {
                let dev = [
                    (s.s0 - s.s1) - approx.diffuse,
                    s.s1 - approx.specular,
                    -s.s2 - approx.alpha,
                ];
                for k in 0..3 {
                    worst[k] = worst[k].max(dev[k].abs() / scale);
                    sum[k] += dev[k].abs() / scale;
                }
                count += 1;
            }
            let d = full.diffuse[c].apply(flash);
            if t.ds > 1e-9 {
                let dev = ((d.s0 - d.s1) - t.ds).abs() / t.ds;
                worst[3] = worst[3].max(dev);
                sum[3] += dev;
            }
        }
    }
    (worst, sum.map(|x| x / count.max(1) as f64))
}

/// Documented worst-case bounds (docs/model.md §5, "Coaxial approximation at the rig's offset"),
/// θ_o ≤ 60°, 3.5° offset: (σ, [I^d, I^s, I^α] / (DS + SS), diffuse-only I^d / DS).
const COAXIAL_BOUNDS_60: [(f64, [f64; 4]); 3] = [
    (0.1, [0.22, 0.80, 0.055, 0.22]),
    (0.3, [0.22, 0.21, 0.055, 0.22]),
    (1.0, [0.22, 0.09, 0.055, 0.22]),
];

#[test]
fn coaxial_approximation_is_bounded_at_the_rig_offset() {
    for (sigma, bound) in COAXIAL_BOUNDS_60 {
        let (worst, mean) = coaxial_deviation(3.5, 60.0, sigma, 10_000, 300);
        eprintln!("σ {sigma}: worst {worst:.4?} mean {mean:.4?}");
        for k in 0..4 {
            assert!(
                worst[k] <= bound[k],
                "σ {sigma}, quantity {k}: {} > {}",
                worst[k],
                bound[k]
            );
        }
    }
    // Exactly coaxial, only the dropped τ² terms remain: ≤ DoP_d(60°, 2.5)² ≈ 0.065 of DS.
    let (worst0, _) = coaxial_deviation(0.0, 60.0, 0.3, 5_000, 301);
    assert!(worst0[3] < 0.07 && worst0[2] < 0.035, "{worst0:?}");
    // The deviation grows with the offset: 0° < 3.5° (sanity of the harness itself).
    assert!(coaxial_deviation(3.5, 60.0, 0.3, 5_000, 301).0[3] > worst0[3]);
}
