//! Specular augmentation (the paper's Step B: docs/model.md §11 "Steps A, B, C and the outer
//! loop", docs/fit-augment.md): cluster the vertices of the joint solve by material, fit one
//! two-lobe specular model per cluster, and give every vertex "virtual" coaxial specular samples
//! from its nearest cluster, which regularise the sharp lobes that sparse views constrain poorly
//! in the final per-vertex passes.
//!
//! API:
//! - [`augment`]`(set: &SampleSet, fits: &[VertexFit], config: &AugmentConfig) -> Augmentation`.
//!   `fits` are the joint solve's results (any order, matched to `set.vertices` by
//!   [`VertexFit::vertex`]; out-of-range, duplicate (the first wins) and non-finite fits are
//!   ignored).
//! - [`Augmentation`]: `clusters` (only clusters that got a model), per vertex `assignment`
//!   (index into `clusters` of the nearest model cluster in feature space; `None` without a
//!   usable fit or when no cluster has a model) and `guides` (for `fit::solve::fit_vertex`):
//!   the virtual samples (empty when the vertex is outside the kernel), the σ_s floor
//!   (σ_s,cluster/2 for the final pass, the paper's; 0 — no floor — for a vertex without virtual
//!   samples: a cluster it is not close to says nothing about its lobe), the cluster's lobe as
//!   a start, and the pooled η prior ([`pool`]).
//!
//! Steps:
//! 1. [`cluster`]: features (ρ_d RGB clipped and PCA-scaled, 2·min(η, 3) with η shrunk towards
//!    the members' median by its own reliability, so a vertex whose η its data cannot fix is
//!    placed by its colour) of the members — vertices with a fit and none of `exclude_flags`
//!    (by default only the prior-valued `TooFewViews` and `UnderDetermined`: a dark or
//!    η-unidentifiable vertex still belongs to a material) — then k-means (fixed or automatic k).
//! 2. For each cluster with ≥ the minimum size, on real samples drawn by [`draw_pairs`] and
//!    evaluated by [`sample_geometry`] (the vertex's fitted normal; unpolarised-flash views
//!    skipped): [`eta_fit`] η_cluster from the diffuse DoP of ≤ `max_eta_samples` samples, then
//!    [`lobe_fit`] (σ_s, σ_ss, ρ_s, ρ_ss) from I^s of ≤ `max_lobe_samples` samples at their
//!    real geometry, in model units.
//! 3. [`virtual_samples`]: every vertex with a fit gets its nearest model cluster's coaxial
//!    profile (unclipped: virtual samples are model values, not pixels), kernel-weighted and
//!    renormalised to λ_g.
//! 4. [`pool_eta`]: per cluster the vertices' step-A η and standard errors give the material's
//!    η (a robust centre) and the between-vertex spread ([`pool`], DerSimonian & Laird 1986); a
//!    vertex inside the kernel whose own η agrees with it gets it as a prior for the final
//!    passes.
//!
//! Determinism: every random choice comes from `ChaCha8Rng` seeded by [`stream_seed`] (the
//! config seed, a purpose, an index); parallel loops (rayon) only map independent items and
//! every reduction is serial in index order, so the result is bit-identical for any number of
//! threads.
//!
//! Memory: the guides hold up to `profile_samples` × 40 bytes of virtual samples per vertex
//! (1.3 kB at 32), i.e. ~130 MB for 100 000 vertices; the values are shared per cluster and the
//! kept samples are a prefix of its profile, so a compact form is possible if that matters.

pub mod cluster;
pub mod eta_fit;
mod labels;
pub mod lobe_fit;
mod model;
pub mod pool;
mod pooling;
mod seed;
pub mod virtual_samples;

pub use labels::material_labels;

#[cfg(test)]
mod tests;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use self::cluster::{ClusterConfig, Feature, FeatureScaling};
use ellipso_model::optics::Vec3;
use ellipso_model::optics::measure::FlashPolariser;
use ellipso_model::optics::pbrdf::Geometry;
use nalgebra::Point3;

use self::eta_fit::DopSample;
use self::lobe_fit::LobeSample;
use self::model::eta_trusted;
pub use self::model::{Augmentation, ClusterModel, POOL_COLOUR_DISTANCE, PartitionSummary};
pub use self::pooling::{LOCAL_RINGS, pool_eta};
pub use self::seed::stream_seed;
use crate::data::{Sample, SampleSet, VertexFit, VertexGuide};

/// Everything the augmentation can be told.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AugmentConfig {
    /// Features and k-means.
    pub cluster: ClusterConfig,
    /// Total weight of a vertex's virtual samples, λ_g (paper: 0.1).
    pub lambda_g: f64,
    /// Points of the coaxial profile (default 32 on a squared grid carrying the paper's 180
    /// uniform samples' weight, `virtual_samples`).
    pub profile_samples: usize,
    /// σ of the feature-distance kernel (paper: 0.1).
    pub kernel_sigma: f64,
    /// Virtual samples with a raw weight at or below this are dropped (paper: 0.01).
    pub min_raw_weight: f64,
    /// Samples per cluster for η_cluster (paper: 4096).
    pub max_eta_samples: usize,
    /// Samples per cluster for the two-lobe fit (paper: 65 536).
    pub max_lobe_samples: usize,
    /// Smallest σ_s of a cluster model (docs/model.md §12, σ → 0: 0.01–0.05).
    pub sigma_min: f64,
    /// Upper bound of the cluster lobes' albedos (the solver's cap, default 5).
    pub albedo_cap: f64,
    /// Seed of the sample draws.
    pub seed: u64,
}

impl Default for AugmentConfig {
    fn default() -> Self {
        Self {
            cluster: ClusterConfig::default(),
            lambda_g: 0.1,
            profile_samples: 32,
            kernel_sigma: 0.1,
            min_raw_weight: 0.01,
            max_eta_samples: 4096,
            max_lobe_samples: 65_536,
            sigma_min: 0.02,
            albedo_cap: crate::solve::SolverConfig::default().albedo_cap,
            seed: 0xa06_0e47,
        }
    }
}

/// Draws up to `max` (vertex, sample index) pairs uniformly without replacement from the
/// samples of `members` (ascending), in ascending order.
pub fn draw_pairs(
    set: &SampleSet,
    members: &[usize],
    max: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<(usize, usize)> {
    let mut starts = Vec::with_capacity(members.len() + 1);
    let mut total = 0usize;
    for &v in members {
        starts.push(total);
        total += set.vertices[v].samples.len();
    }
    starts.push(total);
    let picks: Vec<usize> = if total <= max {
        (0..total).collect()
    } else {
        let mut v = rand::seq::index::sample(rng, total, max).into_vec();
        v.sort_unstable();
        v
    };
    picks
        .into_iter()
        .map(|i| {
            let m = starts.partition_point(|&s| s <= i) - 1;
            (members[m], i - starts[m])
        })
        .collect()
}

/// The model geometry of one real sample with the vertex's fitted normal and the view's flash,
/// or `None` (unpolarised flash, undefined geometry, or back-facing).
pub fn sample_geometry(
    set: &SampleSet,
    vertex: usize,
    sample: &Sample,
    fit: &VertexFit,
) -> Option<(Geometry<f64>, FlashPolariser)> {
    let view = set.views.get(sample.view as usize)?;
    if !view.polarised() {
        return None;
    }
    let sg = view.geometry_at(&Point3::from(set.vertices[vertex].position_world))?;
    let g = sg.model(Vec3::from_f64(fit.normal_world)).ok()?;
    g.front_facing.then_some((g, view.flash_polariser()))
}

/// The median η of the `count` entries of `informative` (scaled colour, η) nearest `colour`:
/// where an uncertain η is shrunk to (`pool::EtaShrink::apply_towards`). `count` is the
/// smallest cluster a material may form, so a material of a colour of its own has that many
/// members and they are its own; towards one median over every material, an uncertain vertex
/// of a minority material was placed among the majority's η, a mode of its own that the
/// separation rule then kept as a second "material" (dev scene 16: lithium niobate split in
/// two clusters whose pools were both withheld). `None` without informative members.
fn colour_median_eta(
    informative: &[([f64; 3], f64)],
    colour: [f64; 3],
    count: usize,
) -> Option<f64> {
    if informative.is_empty() {
        return None;
    }
    let mut by_distance: Vec<(f64, f64)> = informative
        .iter()
        .map(|(c, eta)| {
            (
                (0..3).map(|i| (c[i] - colour[i]).powi(2)).sum::<f64>(),
                *eta,
            )
        })
        .collect();
    let count = count.clamp(1, by_distance.len());
    by_distance.select_nth_unstable_by(count - 1, |a, b| a.0.total_cmp(&b.0));
    let mut etas: Vec<f64> = by_distance[..count].iter().map(|p| p.1).collect();
    Some(ellipso_model::stats::median(&mut etas))
}

/// A vertex's step-A standard error of η where [`eta_trusted`], infinite where its flags
/// disown its η.
fn trusted_se(f: &VertexFit) -> f64 {
    if eta_trusted(f) {
        f.std_error[0]
    } else {
        f64::INFINITY
    }
}

fn fit_is_finite(f: &VertexFit) -> bool {
    let p = &f.params;
    [p.eta, p.sigma_s, p.sigma_ss, p.rho_s]
        .iter()
        .chain(&p.rho_ss)
        .chain(&p.rho_d)
        .chain(&f.normal_world)
        .all(|v| v.is_finite())
}

/// Fits η_cluster and the two-lobe model of one cluster; `None` when the lobe fit has too few
/// usable samples.
fn fit_cluster(
    set: &SampleSet,
    by_vertex: &[Option<&VertexFit>],
    members: &[usize],
    centroid: &Feature,
    index: usize,
    config: &AugmentConfig,
) -> Option<ClusterModel> {
    let fit_of = |v: usize| by_vertex[v].expect("members have fits");
    let mut rng = ChaCha8Rng::seed_from_u64(stream_seed(config.seed, 10, index as u64));
    let pairs = draw_pairs(set, members, config.max_eta_samples, &mut rng);
    let dop: Vec<DopSample> = pairs
        .par_iter()
        .filter_map(|&(v, s)| {
            let sample = &set.vertices[v].samples[s];
            let (g, flash) = sample_geometry(set, v, sample, fit_of(v))?;
            eta_fit::dop_sample(&g, flash, sample, fit_of(v))
        })
        .collect();
    let (eta, eta_samples) = match eta_fit::fit_eta(&dop) {
        Some(eta) => (eta, dop.len()),
        None => {
            let mut etas: Vec<f64> = members.iter().map(|&v| fit_of(v).params.eta).collect();
            let (lo, hi) = eta_fit::ETA_RANGE;
            (ellipso_model::stats::median(&mut etas).clamp(lo, hi), 0)
        }
    };
    let mut rng = ChaCha8Rng::seed_from_u64(stream_seed(config.seed, 11, index as u64));
    let pairs = draw_pairs(set, members, config.max_lobe_samples, &mut rng);
    // Shot-noise weights, normalised to mean 1 over the drawn samples (`lobe_fit` module doc).
    let weights: Vec<f64> = pairs
        .iter()
        .map(|&(v, s)| lobe_fit::noise_weight(&set.vertices[v].samples[s]))
        .collect();
    let mean_weight = weights.iter().sum::<f64>() / weights.len().max(1) as f64;
    let lobe: Vec<LobeSample> = pairs
        .par_iter()
        .zip(weights.par_iter())
        .filter_map(|(&(v, s), &w)| {
            let sample = &set.vertices[v].samples[s];
            let (g, flash) = sample_geometry(set, v, sample, fit_of(v))?;
            LobeSample::new(&g, flash, sample, fit_of(v), eta, w / mean_weight)
        })
        .collect();
    let fit = lobe_fit::fit_lobes(&lobe, config.sigma_min, config.albedo_cap)?;
    Some(ClusterModel {
        eta_pooled: pool::Pooled::default(),
        centroid: centroid.to_vec(),
        members: members.len(),
        eta,
        sigma_s: fit.sigma_s,
        sigma_ss: fit.sigma_ss,
        rho_s: fit.rho_s,
        rho_ss: fit.rho_ss,
        fit_rms: fit.rms,
        eta_samples,
        lobe_samples: lobe.len(),
    })
}

/// Step A's fits grouped into materials: the members (finite fits without an excluded flag),
/// every finite fit's feature, and the chosen partition of the members.
struct Clustering<'f> {
    by_vertex: Vec<Option<&'f VertexFit>>,
    members: Vec<usize>,
    /// The members' features, in the order of `members` (what k-means clustered).
    member_features: Vec<Feature>,
    features: Vec<Option<Feature>>,
    selection: cluster::Selection,
    scaling: FeatureScaling,
}

impl<'f> Clustering<'f> {
    fn new(n: usize, fits: &'f [VertexFit], config: &ClusterConfig) -> Self {
        let mut by_vertex: Vec<Option<&VertexFit>> = vec![None; n];
        for f in fits {
            if let Some(slot) = by_vertex.get_mut(f.vertex as usize)
                && slot.is_none()
                && fit_is_finite(f)
            {
                *slot = Some(f);
            }
        }
        let excluded = |f: &VertexFit| {
            f.flags
                .iter()
                .any(|flag| config.exclude_flags.contains(flag))
        };
        let members: Vec<usize> = (0..n)
            .filter(|&v| by_vertex[v].is_some_and(|f| !excluded(f)))
            .collect();
        let member_rho_d: Vec<[f64; 3]> = members
            .iter()
            .map(|&v| by_vertex[v].expect("member").params.rho_d)
            .collect();
        let scaling = FeatureScaling::from_members(&member_rho_d);
        let shrink = pool::EtaShrink::from_members(
            &members
                .iter()
                .map(|&v| {
                    let f = by_vertex[v].expect("member");
                    (f.params.eta, f.std_error[0])
                })
                .collect::<Vec<_>>(),
        );
        // The shrinkage target: the median η of the informative members nearest in colour.
        let informative: Vec<([f64; 3], f64)> = members
            .iter()
            .filter_map(|&v| {
                let f = by_vertex[v]?;
                let trusted = eta_trusted(f) && f.std_error[0] <= pool::INFORMATIVE_SE;
                trusted.then(|| (scaling.colour(f.params.rho_d), f.params.eta))
            })
            .collect();
        let neighbours =
            cluster::effective_min_cluster_vertices(config.min_cluster_vertices, members.len());
        let features: Vec<Option<Feature>> = by_vertex
            .iter()
            .map(|f| {
                f.map(|f| {
                    // A vertex whose own η its flags disown is placed by its colour alone.
                    let colour = scaling.colour(f.params.rho_d);
                    let target = colour_median_eta(&informative, colour, neighbours)
                        .unwrap_or(shrink.median_eta);
                    scaling.feature(
                        f.params.rho_d,
                        shrink.apply_towards(f.params.eta, trusted_se(f), target),
                    )
                })
            })
            .collect();
        let member_features: Vec<Feature> = members
            .iter()
            .map(|&v| features[v].expect("member"))
            .collect();
        let selection = cluster::select(&member_features, config);
        Self {
            by_vertex,
            members,
            member_features,
            features,
            selection,
            scaling,
        }
    }
}

/// Clusters the joint solve's vertices, fits the cluster models and builds every vertex's
/// virtual specular samples (module doc).
pub fn augment(set: &SampleSet, fits: &[VertexFit], config: &AugmentConfig) -> Augmentation {
    let n = set.vertices.len();
    let Clustering {
        by_vertex,
        members,
        member_features: _,
        features,
        selection,
        scaling,
    } = Clustering::new(n, fits, &config.cluster);
    let partition = &selection.partition;
    let mut lists = vec![Vec::new(); partition.centroids.len()];
    for (i, &label) in partition.labels.iter().enumerate() {
        lists[label].push(members[i]);
    }
    let clusters: Vec<ClusterModel> = lists
        .par_iter()
        .enumerate()
        .map(|(j, list)| {
            (list.len() >= selection.min_cluster_vertices)
                .then(|| fit_cluster(set, &by_vertex, list, &partition.centroids[j], j, config))
                .flatten()
        })
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect();
    let centroids: Vec<Feature> = clusters
        .iter()
        .map(|c| core::array::from_fn(|i| c.centroid[i]))
        .collect();
    let profiles: Vec<Vec<virtual_samples::ProfilePoint>> = clusters
        .iter()
        .map(|c| {
            virtual_samples::coaxial_profile(
                c.eta,
                c.sigma_s,
                c.sigma_ss,
                c.rho_s,
                c.rho_ss,
                config.profile_samples,
            )
        })
        .collect();
    let per_vertex: Vec<(Option<usize>, VertexGuide)> = features
        .par_iter()
        .map(|f| {
            let Some(f) = f.filter(|_| !centroids.is_empty()) else {
                return (None, VertexGuide::default());
            };
            let (j, d2) = cluster::nearest(&f, &centroids);
            let samples = virtual_samples::weighted(
                &profiles[j],
                d2.sqrt(),
                config.kernel_sigma,
                config.min_raw_weight,
                config.lambda_g,
            );
            if samples.is_empty() {
                return (Some(j), VertexGuide::default());
            }
            let c = &clusters[j];
            let guide = VertexGuide {
                virtual_samples: samples,
                sigma_s_floor: c.sigma_s / 2.0,
                eta_prior: None,
                lobe_start: Some([c.sigma_s, c.sigma_ss, c.rho_s]),
            };
            (Some(j), guide)
        })
        .collect();
    let mut assignment = Vec::with_capacity(n);
    let mut guides = Vec::with_capacity(n);
    for (a, g) in per_vertex {
        assignment.push(a);
        guides.push(g);
    }
    Augmentation {
        vertices_with_virtual_samples: guides
            .iter()
            .filter(|g| !g.virtual_samples.is_empty())
            .count(),
        vertices_with_eta_prior: 0,
        partition: PartitionSummary {
            members: members.len(),
            k: partition.centroids.len(),
            sizes: partition.sizes.clone(),
            inertia: partition.inertia,
            silhouette: selection.silhouette,
            tried: selection.tried.clone(),
            min_cluster_vertices: selection.min_cluster_vertices,
            joined_from: selection.joined_from,
            scaling,
        },
        clusters,
        assignment,
        guides,
    }
}
