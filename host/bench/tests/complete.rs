//! A full parameter set for every vertex the views see (`ellipso_fit::complete`), on simulated
//! captures of the shipped scenes' object: vertices whose samples a gate removed take their
//! material's values, a small patch of another η keeps its own, and hard objects (one
//! material, eight, all black) end with honest coverage and no panic.

use ellipso_model::optics::pbrdf::PbrdfParams;
use ellipso_sim::scene::{Scene, shipped_scene};

use ellipso_bench::accuracy::{CaptureCase, SimulatedCapture, sensor_model, simulate_with_truth};
use ellipso_bench::truth::TruthObject;
use ellipso_fit::complete::{Completion, complete};
use ellipso_fit::data::{FitFlag, VertexFit};
use ellipso_fit::pipeline::{FitConfig, fit_sample_set};
use ellipso_fit::solve::SolverConfig;

fn material(eta: f64, rho_d: [f64; 3], sigma_s: f64) -> PbrdfParams<f64> {
    PbrdfParams {
        eta,
        sigma_s,
        sigma_ss: (2.5 * sigma_s).min(1.0),
        rho_s: 1.0,
        rho_ss: [0.1, 0.12, 0.15],
        rho_d,
    }
}

/// The multi-material scene's object (icosphere 3: 642 vertices) with every vertex's material
/// set by `dress(vertex, position)`, captured with 80 photos.
fn capture(
    names: &[&str],
    dress: impl Fn(usize, [f64; 3]) -> (usize, PbrdfParams<f64>),
) -> (Scene, SimulatedCapture) {
    let scene = Scene::load(&shipped_scene("multi_material.toml")).unwrap();
    let mut truth = TruthObject::from_scene(&scene, Some(3)).unwrap();
    for (v, p) in truth.mesh.positions().iter().enumerate() {
        let (m, params) = dress(v, p.coords.into());
        truth.material[v] = m;
        truth.params[v] = params;
    }
    truth.material_names = names.iter().map(|n| n.to_string()).collect();
    let case = CaptureCase {
        photos: 80,
        subdivisions: Some(3),
        ..CaptureCase::default()
    };
    let c = simulate_with_truth(&scene, &case, truth).unwrap();
    (scene, c)
}

/// Every `k`-th vertex the views see loses its samples as if a gate had removed each one
/// (counted as mixed), then the default pipeline and the completion run.
fn fit_and_complete(
    scene: &Scene,
    c: &mut SimulatedCapture,
    every: usize,
) -> (Vec<VertexFit>, Completion, Vec<usize>) {
    let mut dropped = Vec::new();
    for (v, vs) in c.set.vertices.iter_mut().enumerate() {
        if v % every == 0 && !vs.samples.is_empty() {
            vs.gates.mixed += vs.samples.len() as u64;
            vs.gates.kept = 0;
            vs.samples.clear();
            dropped.push(v);
        }
    }
    let config = FitConfig {
        solver: SolverConfig {
            sensor: sensor_model(scene),
            ..SolverConfig::default()
        },
        ..FitConfig::default()
    };
    let outcome = fit_sample_set(&c.set, None, &config, &mut |_| {});
    let mut fits = outcome.fits;
    let a = outcome.augmentation.expect("step B ran");
    let completion = complete(
        &c.set,
        &mut fits,
        &a,
        &c.truth.mesh,
        config.solver.normal_prior_deg,
        config.solver.albedo_cap,
        config.solver.max_eta_std_error,
    );
    (fits, completion, dropped)
}

/// The `n` vertices of the scene's object (icosphere 3) nearest its highest vertex: a patch
/// on the top, which the views see well.
fn nearest_the_top(scene: &Scene, n: usize) -> Vec<usize> {
    let truth = TruthObject::from_scene(scene, Some(3)).unwrap();
    let positions = truth.mesh.positions();
    let top = positions
        .iter()
        .copied()
        .max_by(|a, b| a.z.total_cmp(&b.z))
        .unwrap();
    let mut by_distance: Vec<(usize, f64)> = positions
        .iter()
        .enumerate()
        .map(|(v, p)| (v, (p - top).norm()))
        .collect();
    by_distance.sort_by(|a, b| a.1.total_cmp(&b.1));
    by_distance[..n].iter().map(|p| p.0).collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    assert!(!v.is_empty());
    ellipso_model::stats::median(&mut v)
}

#[test]
fn vertices_without_a_sample_take_the_material_they_lie_in() {
    // Two halves of two colours and two η.
    let red = material(1.49, [0.6, 0.1, 0.08], 0.05);
    let blue = material(1.75, [0.05, 0.2, 0.45], 0.1);
    let (scene, mut c) = capture(&["red", "blue"], |_, p| {
        if p[0] < 0.0 { (0, red) } else { (1, blue) }
    });
    let (fits, completion, dropped) = fit_and_complete(&scene, &mut c, 5);
    eprintln!("{}", completion.report_lines().join("\n"));
    assert!(dropped.len() > 50);
    let observed = fits
        .iter()
        .filter(|f| !f.flags.contains(&FitFlag::Unobserved))
        .count();
    let full = fits
        .iter()
        .filter(|f| !f.flags.contains(&FitFlag::Unobserved) && f.identifiable().eta)
        .count();
    assert_eq!(full, observed, "every vertex the views see has a full set");
    assert_eq!(completion.coverage, 1.0);
    // The dropped vertices: completed, finite σ, and (nearly all) the η of their own half.
    let mut right = 0;
    for &v in &dropped {
        let f = &fits[v];
        assert!(
            f.flags.contains(&FitFlag::FromMaterial),
            "vertex {v}: {:?}",
            f.flags
        );
        assert!(f.reported_std_error().iter().all(|s| s.is_finite()), "{v}");
        right += usize::from((f.params.eta - c.truth.params[v].eta).abs() < 0.02);
    }
    eprintln!(
        "{right} of {} completed vertices got their own half's η",
        dropped.len()
    );
    assert!(right as f64 >= 0.9 * dropped.len() as f64);
    // The unobserved underside stays withheld.
    assert!(
        fits.iter()
            .filter(|f| f.flags.contains(&FitFlag::Unobserved))
            .all(|f| !f.identifiable().vertex)
    );
}

#[test]
fn a_patch_smaller_than_a_cluster_keeps_its_own_eta() {
    // One colour; a 20-vertex patch on the top (the vertices nearest the pole) has η 1.80 in
    // a material of η 1.50.
    let scene = Scene::load(&shipped_scene("multi_material.toml")).unwrap();
    let patch = nearest_the_top(&scene, 20);
    let white = |eta| material(eta, [0.5, 0.5, 0.5], 0.1);
    let (scene, mut c) = capture(&["body", "patch"], |v, _| {
        if patch.contains(&v) {
            (1, white(1.80))
        } else {
            (0, white(1.50))
        }
    });
    // No vertex loses its samples here (a prime step past every index).
    let (fits, completion, _) = fit_and_complete(&scene, &mut c, 1_000_003);
    eprintln!("{}", completion.report_lines().join("\n"));
    let patch_eta: Vec<f64> = patch
        .iter()
        .filter(|&&v| fits[v].identifiable().eta)
        .map(|&v| fits[v].params.eta)
        .collect();
    assert!(
        patch_eta.len() >= 15,
        "{} patch vertices report η",
        patch_eta.len()
    );
    let m = median(patch_eta.clone());
    eprintln!(
        "patch: median η {m:.4} (true 1.80) over {} vertices",
        patch_eta.len()
    );
    assert!((m - 1.80).abs() < 0.03, "{patch_eta:?}");
    // Not one patch vertex reports the body's η.
    assert!(
        patch_eta.iter().all(|e| (e - 1.50).abs() > 0.1),
        "{patch_eta:?}"
    );
}

#[test]
fn one_eight_and_black_materials_end_with_honest_coverage() {
    // One material.
    let grey = material(1.55, [0.4, 0.4, 0.4], 0.15);
    let (scene, mut c) = capture(&["grey"], |_, _| (0, grey));
    let (fits, completion, _) = fit_and_complete(&scene, &mut c, 4);
    assert_eq!(completion.coverage, 1.0);
    let eta = median(
        fits.iter()
            .filter(|f| f.identifiable().eta)
            .map(|f| f.params.eta)
            .collect(),
    );
    assert!((eta - 1.55).abs() < 0.02, "{eta}");

    // Eight materials: octants of distinct colours and η.
    let colours = [
        [0.6, 0.1, 0.1],
        [0.1, 0.6, 0.1],
        [0.1, 0.1, 0.6],
        [0.6, 0.6, 0.1],
        [0.6, 0.1, 0.6],
        [0.1, 0.6, 0.6],
        [0.7, 0.7, 0.7],
        [0.3, 0.2, 0.1],
    ];
    let names = ["m0", "m1", "m2", "m3", "m4", "m5", "m6", "m7"];
    let centre_z = 0.04;
    let (scene, mut c) = capture(&names, |_, p| {
        let k = usize::from(p[0] > 0.0)
            + 2 * usize::from(p[1] > 0.0)
            + 4 * usize::from(p[2] > centre_z);
        (k, material(1.4 + 0.05 * k as f64, colours[k], 0.1))
    });
    let (fits, completion, _) = fit_and_complete(&scene, &mut c, 4);
    eprintln!("{}", completion.report_lines().join("\n"));
    assert!(fits.iter().all(|f| f.params.validate().is_ok()));
    let withheld_seen = fits
        .iter()
        .filter(|f| !f.flags.contains(&FitFlag::Unobserved) && !f.identifiable().eta)
        .count();
    // Every withheld vertex is counted as such: the coverage is what the outputs report.
    assert_eq!(completion.observed - completion.full_set, withheld_seen);

    // All black: nothing to identify; no panic, and what is reported says so.
    let black = PbrdfParams {
        eta: 1.6,
        sigma_s: 0.6,
        sigma_ss: 0.8,
        rho_s: 0.002,
        rho_ss: [0.002; 3],
        rho_d: [0.002; 3],
    };
    let (scene, mut c) = capture(&["black"], |_, _| (0, black));
    let (fits, completion, _) = fit_and_complete(&scene, &mut c, 4);
    eprintln!("{}", completion.report_lines().join("\n"));
    assert!(fits.iter().all(|f| f.params.validate().is_ok()));
    // No η is reported for a material whose data fix none.
    assert!(
        fits.iter().all(|f| !f.identifiable().eta),
        "black η reported"
    );
    assert!(completion.coverage < 0.5, "{}", completion.coverage);
}

#[test]
fn a_patch_with_too_few_samples_per_vertex_is_answered_from_its_own_samples() {
    // One colour; a 40-vertex patch on the top has η 1.80 in a material of η 1.50, and every
    // patch vertex keeps 6 of its samples — fewer than the per-vertex solve's 12, so each is
    // completed, and its colour cannot tell the two materials apart.
    let scene = Scene::load(&shipped_scene("multi_material.toml")).unwrap();
    let patch = nearest_the_top(&scene, 40);
    let white = |eta| material(eta, [0.5, 0.5, 0.5], 0.1);
    let (scene, mut c) = capture(&["body", "patch"], |v, _| {
        if patch.contains(&v) {
            (1, white(1.80))
        } else {
            (0, white(1.50))
        }
    });
    for &v in &patch {
        let s = &mut c.set.vertices[v];
        let stride = s.samples.len().div_ceil(6).max(1);
        s.samples = s.samples.iter().step_by(stride).copied().collect();
        assert!(
            (1..12).contains(&s.samples.len()),
            "{v}: {}",
            s.samples.len()
        );
    }
    let (fits, completion, _) = fit_and_complete(&scene, &mut c, 1_000_003);
    eprintln!("{}", completion.report_lines().join("\n"));
    assert!(
        completion.eta_local > 0,
        "no vertex took its surroundings' η: {:?}",
        completion.report_lines()
    );
    let answered: Vec<&VertexFit> = patch
        .iter()
        .map(|&v| &fits[v])
        .filter(|f| f.identifiable().eta)
        .collect();
    assert!(
        answered.len() >= 30,
        "{} patch vertices report η",
        answered.len()
    );
    let m = median(answered.iter().map(|f| f.params.eta).collect());
    eprintln!("patch: median η {m:.4} (true 1.80) over {}", answered.len());
    assert!((m - 1.80).abs() < 0.05, "median {m}");
    // Whatever each reports, its σ does not claim more than it knows: the error within 3σ.
    for f in &answered {
        let sigma = f.reported_std_error()[0];
        assert!(
            (f.params.eta - 1.80).abs() <= 3.0 * sigma,
            "η {} ± {sigma} for a true 1.80",
            f.params.eta
        );
    }
}
