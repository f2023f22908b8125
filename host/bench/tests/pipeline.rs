//! The fit's steps A (joint solve), B (augmentation) and C on simulated captures with known
//! truth (moved from `ellipso-fit`, which does not depend on the simulator).

use ellipso_bench::accuracy::{CaptureCase, evaluate, simulate};
use ellipso_fit::pipeline::{FitConfig, fit_sample_set};
use ellipso_fit::solve::SolverConfig;
use ellipso_sim::scene::Scene;

fn capture() -> ellipso_bench::accuracy::SimulatedCapture {
    let scene = Scene::load(&ellipso_sim::scene::shipped_scene("sphere.toml")).unwrap();
    let case = CaptureCase {
        photos: 40,
        subdivisions: Some(1),
        ..CaptureCase::default()
    };
    simulate(&scene, &case).unwrap()
}

#[test]
fn every_vertex_gets_a_valid_result_with_and_without_augmentation() {
    let c = capture();
    for config in [FitConfig::joint_only(), FitConfig::default()] {
        let out = fit_sample_set(&c.set, None, &config, &mut |_| {});
        assert_eq!(out.fits.len(), c.set.vertices.len());
        assert_eq!(out.augmentation.is_some(), config.augment.is_some());
        for (k, f) in out.fits.iter().enumerate() {
            assert_eq!(f.vertex as usize, k);
            assert!(f.params.validate().is_ok(), "vertex {k}: {:?}", f.params);
            assert!(f.normal_world.iter().all(|v| v.is_finite()));
        }
        let scores = evaluate(&c, &out.fits);
        // Front vertices of the glass sphere: normals come back from a 5° tilt.
        assert!(scores.scored > 10, "{scores:?}");
        assert!(
            scores.normal_median_deg < scores.normal_input_median_deg,
            "{scores:?}"
        );
        assert!(out.times.fit_s() >= 0.0);
    }
}

/// The shared steps must earn their place: on a small four-material capture, A + B + C is
/// never worse than A alone on η (per vertex and per material), the normals and the
/// roughnesses, and better on per-vertex η (issue: the augmentation used to make things
/// worse, per-vertex η 1.7 → 5.2 %).
#[test]
fn shared_steps_are_never_worse_than_step_a_alone() {
    let scene = Scene::load(&ellipso_sim::scene::shipped_scene("multi_material.toml")).unwrap();
    let case = CaptureCase {
        photos: 60,
        subdivisions: Some(2),
        ..CaptureCase::default()
    };
    let c = simulate(&scene, &case).unwrap();
    let run = |config: FitConfig| {
        let config = FitConfig {
            solver: SolverConfig {
                sensor: ellipso_bench::accuracy::sensor_model(&scene),
                ..config.solver.clone()
            },
            ..config
        };
        evaluate(&c, &fit_sample_set(&c.set, None, &config, &mut |_| {}).fits)
    };
    let a = run(FitConfig::joint_only());
    let abc = run(FitConfig::default());
    eprintln!("A: {a:?}\nA+B+C: {abc:?}");
    // "Never worse" up to the noise of these figures on ~600 vertices.
    assert!(
        abc.eta_median_pct < 0.5 * a.eta_median_pct,
        "{abc:?} vs {a:?}"
    );
    assert!(abc.eta_mean_pct <= a.eta_mean_pct, "{abc:?} vs {a:?}");
    assert!(
        abc.eta_material_pct <= a.eta_material_pct + 0.1,
        "{abc:?} vs {a:?}"
    );
    assert!(abc.normal_median_deg <= a.normal_median_deg * 1.05 + 0.01);
    assert!(abc.sigma_s_abs <= a.sigma_s_abs, "{abc:?} vs {a:?}");
    assert!(
        abc.sigma_ss_abs <= a.sigma_ss_abs * 1.05,
        "{abc:?} vs {a:?}"
    );
    assert!(abc.rho_d_median_pct <= a.rho_d_median_pct * 1.05 + 0.1);
}

#[test]
fn the_pipeline_is_deterministic_across_thread_counts() {
    let c = capture();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                fit_sample_set(&c.set, None, &FitConfig::with_augmentation(1), &mut |_| {}).fits
            })
    };
    assert_eq!(run(1), run(2));
}
