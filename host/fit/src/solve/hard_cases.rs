//! The hard cases the user asked to stay numerically stable (README): each its own test. Every
//! result must be finite, inside its bounds, flagged with the right reason, and carry an
//! uncertainty — never a silent wrong number.

use ellipso_model::optics::pbrdf::PbrdfParams;

use super::super::data::{GateCounts, Sample, VertexGuide, VertexSamples, VirtualSample};
use super::super::synthetic::orbit_views;
use super::tests::{MATERIALS, angle_deg, assert_sane, material, sensor, synth, views};
use super::*;

const UP: [f64; 3] = [0.0, 0.0, 1.0];

#[test]
fn dark_vertex_is_flagged_and_finite() {
    let views = views();
    // 1/2000 of the normal exposure: every sample falls below the dark gate.
    let v = synth(&views, UP, &material("rubber"), Some(&sensor()), 5e-4, 1);
    assert!(v.gates.dark > v.gates.kept, "{:?}", v.gates);
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    assert!(fit.flags.contains(&FitFlag::Dark), "{:?}", fit.flags);
    assert!(fit.flags.contains(&FitFlag::TooFewViews), "{:?}", fit.flags);
    assert!(fit.std_error.iter().all(|e| e.is_infinite()));
    // Dim but above the gate on some views: fitted, flagged dark by its signal.
    let v = synth(&views, UP, &material("rubber"), Some(&sensor()), 0.02, 2);
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    assert!(
        fit.flags.contains(&FitFlag::Dark) || fit.flags.contains(&FitFlag::TooFewViews),
        "{fit:?}"
    );
}

#[test]
fn saturated_vertex_is_flagged_and_finite() {
    let views = views();
    let v = synth(
        &views,
        UP,
        &material("glossy_plastic"),
        Some(&sensor()),
        4.0,
        3,
    );
    assert!(v.gates.saturated > 5, "{:?}", v.gates);
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    assert!(fit.flags.contains(&FitFlag::Saturated), "{:?}", fit.flags);
}

#[test]
fn near_normal_incidence_views_leave_eta_unidentifiable() {
    // Cameras within ~10° of the normal: ∂DoP/∂η < 0.01.
    let views = orbit_views(60, 0.5, [80.0, 88.0], 2.0, [0.0; 3], [0.0, 0.03, 0.0]);
    let truth = material("ceramic");
    let v = synth(&views, UP, &truth, Some(&sensor()), 1.0, 4);
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    assert!(fit.flags.contains(&FitFlag::EtaUnidentifiable), "{fit:?}");
    let err = (fit.params.eta - truth.eta).abs();
    assert!(
        err <= 3.0 * fit.std_error[0] || fit.std_error[0] > 0.05,
        "{fit:?}"
    );
}

#[test]
fn fewer_views_than_unknowns_is_under_determined() {
    let views = orbit_views(7, 0.5, [30.0, 60.0], 1.0, [0.0; 3], [0.0, 0.03, 0.0]);
    let v = synth(&views, UP, &material("glaze"), Some(&sensor()), 1.0, 5);
    assert!(v.samples.len() < 12);
    let config = SolverConfig {
        min_views: 1,
        ..SolverConfig::default()
    };
    let fit = fit_vertex(&views, &v, true, None, &VertexGuide::default(), &config);
    assert_sane(&fit);
    assert!(fit.flags.contains(&FitFlag::UnderDetermined), "{fit:?}");
    // 7 samples × 9 residuals > 12 unknowns, but the lobes are not separable: some error is ∞
    // or large.
    assert!(
        fit.std_error.iter().any(|e| e.is_nan() || *e >= 0.1),
        "{fit:?}"
    );
    // With the default minimum the vertex is not fitted at all.
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    assert!(
        fit.flags.contains(&FitFlag::TooFewViews) && fit.flags.contains(&FitFlag::UnderDetermined)
    );
}

#[test]
fn grazing_only_views_are_flagged() {
    // Cameras 12–22° above the horizon of an upward normal: every view 68–78° off the normal.
    let views = orbit_views(80, 0.5, [12.0, 22.0], 1.0, [0.0; 3], [0.0, 0.03, 0.0]);
    let v = synth(&views, UP, &material("ceramic"), Some(&sensor()), 1.0, 6);
    assert!(v.samples.len() >= 12, "{:?}", v.gates);
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    assert!(fit.flags.contains(&FitFlag::GrazingOnly), "{fit:?}");
}

#[test]
fn eta_near_one_stays_in_bounds_and_honest() {
    let views = views();
    let truth = PbrdfParams {
        eta: 1.02,
        ..material("ceramic")
    };
    let v = synth(&views, UP, &truth, Some(&sensor()), 1.0, 7);
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    let err = (fit.params.eta - truth.eta).abs();
    eprintln!("η = 1.02: {fit:?}");
    assert!(
        err < 0.02 || fit.flags.contains(&FitFlag::EtaUnidentifiable),
        "{fit:?}"
    );
    // η = 1.02 lies below the default range [1.1, 3] (the paper's): the fit ends at the
    // bound and says so.
    let v = synth(&views, UP, &truth, None, 1.0, 7);
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    assert!((fit.params.eta - 1.1).abs() < 0.01, "{fit:?}");
    assert!(fit.flags.contains(&FitFlag::AtBound), "{fit:?}");
    // With the range opened to η → 1 (configurable), noiseless data is recovered, with
    // ∂DoP/∂η small but non-zero.
    let open = SolverConfig {
        eta_bounds: [1.001, 3.0],
        ..SolverConfig::default().without_priors()
    };
    let fit = fit_vertex(&views, &v, true, None, &VertexGuide::default(), &open);
    assert!((fit.params.eta - 1.02).abs() < 1e-4, "{fit:?}");
}

/// Every bound of the box (η above, ρ_s, ρ_d caps, the normal cone) is enforced, and a fit that
/// ends at one is flagged, never silently reported (η below and σ at its floor have their own
/// tests above and below).
#[test]
fn each_bound_is_enforced_and_flagged() {
    let views = views();
    let cases: [(&str, PbrdfParams<f64>); 3] = [
        (
            "η above its range",
            PbrdfParams {
                eta: 3.6,
                ..material("ceramic")
            },
        ),
        (
            "ρ_s above the cap",
            PbrdfParams {
                rho_s: 9.0,
                ..material("ceramic")
            },
        ),
        (
            "ρ_d above the cap",
            PbrdfParams {
                rho_d: [8.0, 6.0, 7.0],
                ..material("ceramic")
            },
        ),
    ];
    let config = SolverConfig::default();
    for (what, truth) in cases {
        let v = synth(&views, UP, &truth, None, 1.0, 21);
        let fit = fit_vertex(&views, &v, true, None, &VertexGuide::default(), &config);
        assert_sane(&fit);
        assert!(fit.flags.contains(&FitFlag::AtBound), "{what}: {fit:?}");
    }
    // A dark vertex handed a mesh normal 40° off: the prior cone keeps the fit near the mesh
    // normal unless the data insists, and a normal far outside the cone is flagged.
    let tilted = super::tests::unit([40f64.to_radians().sin(), 0.0, 40f64.to_radians().cos()]);
    let mut v = synth(&views, UP, &material("rubber"), Some(&sensor()), 0.05, 22);
    v.normal_world = tilted;
    let fit = fit_vertex(&views, &v, true, None, &VertexGuide::default(), &config);
    assert_sane(&fit);
    let off = angle_deg(fit.normal_world, tilted);
    assert!(
        off <= 2.5 * config.normal_prior_deg || fit.flags.contains(&FitFlag::AtBound),
        "{off}° {fit:?}"
    );
}

#[test]
fn sigma_towards_zero_hits_the_floor_and_says_so() {
    let views = views();
    let truth = PbrdfParams {
        sigma_s: 0.005,
        sigma_ss: 0.005,
        ..material("glossy_plastic")
    };
    let v = synth(&views, UP, &truth, Some(&sensor()), 1.0, 8);
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    eprintln!("σ → 0: {fit:?}");
    assert!(fit.params.sigma_s >= 0.01);
    assert!(
        fit.flags.contains(&FitFlag::AtBound) || fit.std_error[1] > 0.05,
        "{fit:?}"
    );
    assert!(angle_deg(fit.normal_world, UP) < 1.0);
}

#[test]
fn very_rough_lobes_at_one() {
    let views = views();
    let truth = PbrdfParams {
        sigma_s: 1.0,
        sigma_ss: 1.0,
        ..material("ceramic")
    };
    let v = synth(&views, UP, &truth, Some(&sensor()), 1.0, 9);
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    eprintln!("σ = 1: {fit:?}");
    // Recovered, at the bound, or honestly uncertain: in measurement mode a sharp σ_s lobe
    // can absorb the noise of a few near-coaxial samples (χ²/dof ≈ 0.9 there with the test
    // sensor), which leaves σ_ss within its standard error of 1 rather than above 0.9.
    assert!(
        fit.params.sigma_ss > 0.9
            || fit.flags.contains(&FitFlag::AtBound)
            || 1.0 - fit.params.sigma_ss <= 3.0 * fit.std_error[2],
        "{fit:?}"
    );
    assert!((fit.params.eta - truth.eta).abs() < 0.1);
}

#[test]
fn unobserved_means_no_view_saw_it_lit_not_every_sample_gated() {
    let views = views();
    let config = SolverConfig::default();
    let with_gates = |gates: GateCounts| VertexSamples {
        vertex: 0,
        position_world: [0.0; 3],
        normal_world: UP,
        samples: Vec::new(),
        gates,
    };
    let fit = |gates| {
        fit_vertex(
            &views,
            &with_gates(gates),
            true,
            None,
            &VertexGuide::default(),
            &config,
        )
    };
    // out of view, occluded, in the flash's shadow: no view saw it
    let unseen = fit(GateCounts {
        not_in_view: 40,
        occluded: 30,
        shadowed: 20,
        ..GateCounts::default()
    });
    assert!(
        unseen.flags.contains(&FitFlag::Unobserved) && unseen.flags.contains(&FitFlag::TooFewViews)
    );
    // seen, every sample gated for what its pixels showed
    for gates in [
        GateCounts {
            mixed: 12,
            occluded: 5,
            ..GateCounts::default()
        },
        GateCounts {
            grazing: 7,
            ..GateCounts::default()
        },
        GateCounts {
            dark: 3,
            saturated: 2,
            ..GateCounts::default()
        },
        GateCounts {
            colour_outlier: 1,
            non_finite: 1,
            ..GateCounts::default()
        },
    ] {
        let f = fit(gates.clone());
        assert!(f.flags.contains(&FitFlag::TooFewViews), "{gates:?}");
        assert!(
            !f.flags.contains(&FitFlag::Unobserved),
            "{gates:?}: {:?}",
            f.flags
        );
    }
}

#[test]
fn adversarial_inputs_never_produce_nan() {
    let views = views();
    let config = SolverConfig::default();
    let empty = VertexSamples {
        vertex: 0,
        position_world: [0.0; 3],
        normal_world: [0.0; 3],
        samples: Vec::new(),
        gates: GateCounts::default(),
    };
    let fit = fit_vertex(&views, &empty, true, None, &VertexGuide::default(), &config);
    assert_sane(&fit);
    assert!(fit.flags.contains(&FitFlag::TooFewViews));
    assert!(fit.flags.contains(&FitFlag::Unobserved), "{fit:?}");
    // All-zero channels on every view.
    let zeros = VertexSamples {
        samples: (0..100)
            .map(|k| Sample {
                view: k,
                channels: [[0.0; 4]; 3],
                normaliser: 1000.0,
            })
            .collect(),
        normal_world: UP,
        ..empty.clone()
    };
    for colour in [true, false] {
        let fit = fit_vertex(
            &views,
            &zeros,
            colour,
            None,
            &VertexGuide::default(),
            &config,
        );
        assert_sane(&fit);
        assert!(fit.flags.contains(&FitFlag::Dark), "{fit:?}");
    }
    // NaN channels, zero normalisers, views out of range, NaN position/normal, NaN virtuals.
    let mut bad = synth(
        &views,
        UP,
        &material(MATERIALS[1]),
        Some(&sensor()),
        1.0,
        10,
    );
    bad.samples[0].channels[1][1] = f32::NAN;
    bad.samples[1].normaliser = 0.0;
    bad.samples[2].view = 10_000;
    let virt = VertexGuide {
        virtual_samples: vec![VirtualSample {
            cos_theta_h: f64::NAN,
            specular: [f64::NAN; 3],
            weight: f64::NAN,
        }],
        sigma_s_floor: f64::NAN,
        eta_prior: Some([f64::NAN, f64::NAN]),
        lobe_start: Some([f64::NAN; 3]),
    };
    let fit = fit_vertex(&views, &bad, true, None, &virt, &config);
    assert_sane(&fit);
    assert_eq!(fit.samples_used as usize, bad.samples.len() - 3);
    bad.normal_world = [f64::NAN; 3];
    let fit = fit_vertex(&views, &bad, true, None, &VertexGuide::default(), &config);
    assert_sane(&fit);
    bad.position_world = [f64::NAN; 3];
    let fit = fit_vertex(&views, &bad, true, None, &VertexGuide::default(), &config);
    assert_sane(&fit);
    assert!(fit.flags.contains(&FitFlag::TooFewViews));
}

/// Issue 46 item 3: a material of η 1.0 (below the range) came back as η = 1.100 ± 0.0045,
/// flagged only `AtBound` and drawn as measured. A value pinned at a bound is withheld.
#[test]
fn eta_pinned_at_its_bound_is_withheld() {
    let views = views();
    let truth = PbrdfParams {
        eta: 1.0,
        ..material("ceramic")
    };
    let v = synth(&views, UP, &truth, Some(&sensor()), 1.0, 46);
    let fit = fit_vertex(
        &views,
        &v,
        true,
        None,
        &VertexGuide::default(),
        &SolverConfig::default(),
    );
    assert_sane(&fit);
    assert!((fit.params.eta - 1.1).abs() < 0.01, "{fit:?}");
    assert!(fit.flags.contains(&FitFlag::AtBound), "{fit:?}");
    assert!(fit.flags.contains(&FitFlag::EtaUnidentifiable), "{fit:?}");
    let shown = crate::data::Identifiable::of_mask(FitFlag::mask(&fit.flags));
    assert!(
        !shown.eta,
        "η at its bound is reported as a measurement: {fit:?}"
    );
}
