//! The fit pipeline on a fixed set of observations (optics.md §7.5–§7.8):
//!
//! 1. **Step A** — joint per-vertex solve (normal + pBRDF) of every vertex
//!    ([`super::solve::fit_all`]), warm-started from a previous result when one is given;
//! 2. **Step B** (opt-in, see [`FitConfig`]) — k-means clusters on (ρd, η), a two-lobe specular
//!    model per cluster, and 180 virtual specular samples per vertex with total weight λg
//!    ([`super::augment`]);
//! 3. **Step C** (with B) — `final_passes` per-vertex passes with the virtual samples, each
//!    warm-started from the previous pass.
//!
//! Contract: deterministic for a given input on any thread count (every stage is); every
//! vertex of the input gets a [`VertexFit`] (flagged where it cannot be trusted); the wall time
//! of each stage is measured and returned. The outer loop with the shape update, which needs
//! fresh observations after every geometry change, lives with the session driver
//! ([`super::session`]).

use std::time::Instant;

use super::augment::{AugmentConfig, Augmentation, augment};
use super::data::{SampleSet, VertexFit};
use super::solve::{SolverConfig, fit_all};

/// Settings of the whole fit.
///
/// The default runs step A only: on the shipped scenes, measured by `ellipso bench accuracy`
/// (docs/accuracy-vs-time.md), steps B + C cost 3–10× the time of step A and made the
/// four-material blob worse (per-vertex η error 1.7 % → 5.2 %, normal p90 0.7° → 2.1°, a few
/// vertices' ρd blown up) while helping the single-material sphere's σ only marginally. They
/// stay one switch away ([`FitConfig::with_augmentation`], `ellipso fit --augment`).
#[derive(Clone, Debug)]
pub struct FitConfig {
    /// The per-vertex solver (iterations, loss weights, bounds).
    pub solver: SolverConfig,
    /// Specular augmentation (steps B and C); `None` stops after step A (the default).
    pub augment: Option<AugmentConfig>,
    /// Step C passes (paper: 3).
    pub final_passes: usize,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            solver: SolverConfig::default(),
            augment: None,
            final_passes: 3,
        }
    }
}

impl FitConfig {
    /// The paper's full recipe: step A, then clusters and virtual samples (B) and `passes`
    /// final passes (C).
    pub fn with_augmentation(passes: usize) -> Self {
        Self {
            augment: Some(AugmentConfig::default()),
            final_passes: passes,
            ..Self::default()
        }
    }
}

/// Wall time of each stage, seconds.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimes {
    /// Observation extraction (filled by drivers that extract).
    pub observe_s: f64,
    /// Step A.
    pub joint_s: f64,
    /// Step B.
    pub augment_s: f64,
    /// Step C.
    pub final_s: f64,
    /// Shape updates (filled by the session driver).
    pub shape_s: f64,
}

impl StageTimes {
    /// The fit proper: steps A + B + C.
    pub fn fit_s(&self) -> f64 {
        self.joint_s + self.augment_s + self.final_s
    }
}

/// What the pipeline produced.
#[derive(Clone, Debug)]
pub struct FitOutcome {
    /// One result per vertex of the sample set, in order.
    pub fits: Vec<VertexFit>,
    /// Clusters and virtual samples (when step B ran).
    pub augmentation: Option<Augmentation>,
    /// Stage timings.
    pub times: StageTimes,
}

/// Runs steps A, B, C on `set`; `init` warm-starts step A (one entry per vertex).
/// `progress` is told each stage as it starts.
pub fn fit_sample_set(
    set: &SampleSet,
    init: Option<&[VertexFit]>,
    config: &FitConfig,
    progress: &mut dyn FnMut(&str),
) -> FitOutcome {
    let mut times = StageTimes::default();
    progress("joint per-vertex solve (normal + pBRDF)");
    let started = Instant::now();
    let mut fits = fit_all(set, init, None, &config.solver);
    times.joint_s = started.elapsed().as_secs_f64();
    let mut augmentation = None;
    if let Some(augment_config) = &config.augment {
        progress("clusters and virtual specular samples");
        let started = Instant::now();
        let a = augment(set, &fits, augment_config);
        times.augment_s = started.elapsed().as_secs_f64();
        let started = Instant::now();
        for pass in 0..config.final_passes {
            progress(&format!(
                "final pass {}/{} with virtual samples",
                pass + 1,
                config.final_passes
            ));
            fits = fit_all(set, Some(&fits), Some(&a.virtual_samples), &config.solver);
        }
        times.final_s = started.elapsed().as_secs_f64();
        augmentation = Some(a);
    }
    FitOutcome {
        fits,
        augmentation,
        times,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::accuracy::{CaptureCase, evaluate, simulate};
    use ellipso_sim::scene::Scene;

    fn capture() -> crate::fit::accuracy::SimulatedCapture {
        let scene = Scene::load(&crate::cli::demo::shipped_scene("sphere.toml")).unwrap();
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
        for config in [FitConfig::default(), FitConfig::with_augmentation(1)] {
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
}
