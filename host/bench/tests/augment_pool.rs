//! Pooled η that cannot merge materials, end to end: simulated captures of the four-material
//! scene's object re-dressed with materials of one colour whose η differ, fitted with the
//! default pipeline (steps A, B with pooling, C). A pool may only lend a material its own η.

use ellipso_model::optics::pbrdf::PbrdfParams;
use ellipso_sim::scene::{Scene, shipped_scene};

use ellipso_bench::accuracy::{CaptureCase, SimulatedCapture, sensor_model, simulate_with_truth};
use ellipso_bench::truth::TruthObject;
use ellipso_fit::data::{FitFlag, VertexFit};
use ellipso_fit::pipeline::{FitConfig, fit_sample_set};
use ellipso_fit::solve::SolverConfig;

/// The glaze of the shipped scenes (blue, a σs = 0.08 lobe) with refractive index `eta`.
fn glaze(eta: f64) -> PbrdfParams<f64> {
    PbrdfParams {
        eta,
        sigma_s: 0.08,
        sigma_ss: 0.2,
        rho_s: 1.0,
        rho_ss: [0.10, 0.15, 0.25],
        rho_d: [0.05, 0.20, 0.45],
    }
}

/// The multi-material scene's object with every vertex's material set by `dress(position)`
/// (material index, parameters), captured with 80 photos.
fn capture(
    names: &[&str],
    dress: impl Fn([f64; 3]) -> (usize, PbrdfParams<f64>),
) -> (Scene, SimulatedCapture) {
    let scene = Scene::load(&shipped_scene("multi_material.toml")).unwrap();
    let mut truth = TruthObject::from_scene(&scene, Some(2)).unwrap();
    for (v, p) in truth.mesh.positions().iter().enumerate() {
        let (m, params) = dress(p.coords.into());
        truth.material[v] = m;
        truth.params[v] = params;
    }
    truth.material_names = names.iter().map(|n| n.to_string()).collect();
    let case = CaptureCase {
        photos: 80,
        subdivisions: Some(2),
        ..CaptureCase::default()
    };
    let c = simulate_with_truth(&scene, &case, truth).unwrap();
    (scene, c)
}

fn fit(scene: &Scene, c: &SimulatedCapture) -> Vec<VertexFit> {
    let config = FitConfig {
        solver: SolverConfig {
            sensor: sensor_model(scene),
            ..SolverConfig::default()
        },
        ..FitConfig::default()
    };
    fit_sample_set(&c.set, None, &config, &mut |_| {}).fits
}

fn median(mut v: Vec<f64>) -> f64 {
    assert!(!v.is_empty());
    ellipso_model::stats::median(&mut v)
}

/// η of the vertices that report it (not withheld by the identifiability rule), with their
/// true η.
fn reported(c: &SimulatedCapture, fits: &[VertexFit]) -> Vec<(f64, f64)> {
    fits.iter()
        .enumerate()
        .filter(|(_, f)| f.eta_identified())
        .map(|(v, f)| (f.params.eta, c.truth.params[v].eta))
        .collect()
}

#[test]
fn two_materials_of_one_colour_keep_their_own_eta() {
    // The object is centred on x = 0: one half each.
    let (scene, c) = capture(&["low", "high"], |p| {
        if p[0] < 0.0 {
            (0, glaze(1.45))
        } else {
            (1, glaze(1.65))
        }
    });
    let fits = fit(&scene, &c);
    assert!(
        fits.iter().any(|f| f.flags.contains(&FitFlag::EtaPooled)),
        "the pool took part"
    );
    let pts = reported(&c, &fits);
    let low = median(pts.iter().filter(|p| p.1 < 1.5).map(|p| p.0).collect());
    let high = median(pts.iter().filter(|p| p.1 > 1.6).map(|p| p.0).collect());
    eprintln!("two materials of one colour: η {low:.4} (true 1.45), {high:.4} (true 1.65)");
    assert!((low - 1.45).abs() < 0.015, "{low}");
    assert!((high - 1.65).abs() < 0.015, "{high}");
    // And per vertex: a pooled vertex's η stays with its own material.
    for (f, (eta, truth)) in fits.iter().filter(|f| f.eta_identified()).zip(&pts) {
        if f.flags.contains(&FitFlag::EtaPooled) {
            assert!(
                (eta - truth).abs() < 0.1,
                "vertex {}: {eta} for {truth}",
                f.vertex
            );
        }
    }
}

#[test]
fn an_eta_gradient_is_not_pooled_flat() {
    // One colour, η rising linearly with height from 1.40 to 1.75.
    let (lo, hi) = (0.0, 0.08);
    let (scene, c) = capture(&["gradient"], |p| {
        let t = ((p[2] - lo) / (hi - lo)).clamp(0.0, 1.0);
        (0, glaze(1.40 + 0.35 * t))
    });
    let fits = fit(&scene, &c);
    let mut pts = reported(&c, &fits);
    assert!(pts.len() > 30, "{} vertices report η", pts.len());
    pts.sort_by(|a, b| a.1.total_cmp(&b.1));
    // Thirds by true η: each third's fitted median follows its true median.
    let thirds: Vec<(f64, f64)> = pts
        .chunks(pts.len().div_ceil(3))
        .map(|t| {
            (
                median(t.iter().map(|p| p.0).collect()),
                median(t.iter().map(|p| p.1).collect()),
            )
        })
        .collect();
    eprintln!("η gradient, thirds (fitted, true): {thirds:?}");
    for (fitted, truth) in &thirds {
        assert!((fitted - truth).abs() < 0.03, "{thirds:?}");
    }
    let span = thirds.last().unwrap().0 - thirds[0].0;
    let true_span = thirds.last().unwrap().1 - thirds[0].1;
    assert!(span > 0.7 * true_span, "{thirds:?}");
}

#[test]
fn a_material_the_data_cannot_identify_is_withheld_not_returned_at_the_start_value() {
    // A nearly black, rough material (albedos 0.002): its few photons fix no η.
    let black = PbrdfParams {
        eta: 1.62,
        sigma_s: 0.6,
        sigma_ss: 0.8,
        rho_s: 0.002,
        rho_ss: [0.002; 3],
        rho_d: [0.002, 0.002, 0.002],
    };
    let (scene, c) = capture(&["black"], |_| (0, black));
    let fits = fit(&scene, &c);
    let fitted: Vec<&VertexFit> = fits
        .iter()
        .filter(|f| !f.flags.contains(&FitFlag::TooFewViews))
        .collect();
    assert!(fitted.len() > 30, "{} vertices fitted", fitted.len());
    let reported = fitted.iter().filter(|f| f.eta_identified()).count();
    let at_start = fitted
        .iter()
        .filter(|f| f.eta_identified() && (f.params.eta - 1.5).abs() < 1e-3)
        .count();
    eprintln!(
        "black material: {} fitted, {reported} report η, {at_start} of them at 1.5",
        fitted.len()
    );
    // None of its vertices presents η as a measurement — least of all the start value — and
    // no pool lent one.
    assert_eq!(reported, 0);
    assert_eq!(at_start, 0);
    assert!(
        fits.iter().all(|f| !f.flags.contains(&FitFlag::EtaPooled)),
        "a pool of unidentified η lent its value"
    );
    // What is reported is the data's, not the prior's: within a few standard errors of 1.62.
    for f in fitted.iter().filter(|f| f.eta_identified()) {
        assert!(
            (f.params.eta - 1.62).abs() < 4.0 * f.std_error[0] + 0.01,
            "vertex {}: {} ± {}",
            f.vertex,
            f.params.eta,
            f.std_error[0]
        );
    }
}
