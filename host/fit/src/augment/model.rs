//! What the augmentation's steps share: its result types ([`Augmentation`], [`ClusterModel`],
//! [`PartitionSummary`]), the colour reach within which clusters are one material's
//! ([`POOL_COLOUR_DISTANCE`]) and whether a vertex's own η counts (`eta_trusted`). Kept apart
//! from `augment` itself so its steps (clustering, pooling) depend on these and not on the
//! module that runs them.

use super::cluster::FeatureScaling;
use super::pool;
use crate::data::{VertexFit, VertexGuide};

/// The model of one cluster.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClusterModel {
    /// Centroid in feature space ([`super::cluster::FEATURE_DIM`] values).
    pub centroid: Vec<f64>,
    /// Member vertices.
    pub members: usize,
    /// η_cluster ∈ [1, 3].
    pub eta: f64,
    /// σ_s ∈ [`super::AugmentConfig::sigma_min`], 1].
    pub sigma_s: f64,
    /// σ_ss ∈ [σ_s, 1].
    pub sigma_ss: f64,
    /// ρ_s ≥ 0.
    pub rho_s: f64,
    /// ρ_ss ≥ 0 per channel.
    pub rho_ss: [f64; 3],
    /// RMS I^s residual of the two-lobe fit, model units.
    pub fit_rms: f64,
    /// DoP samples η was fitted to (0: too few, η is the members' median η).
    pub eta_samples: usize,
    /// Samples of the two-lobe fit.
    pub lobe_samples: usize,
    /// The members' pooled η (random-effects mean, [`pool`]).
    pub eta_pooled: pool::Pooled,
}

/// How the vertices were partitioned.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PartitionSummary {
    /// Vertices clustered (fitted and not excluded by a flag).
    pub members: usize,
    /// Number of k-means clusters.
    pub k: usize,
    /// Members per k-means cluster.
    pub sizes: Vec<usize>,
    /// k-means inertia (sum of squared feature distances).
    pub inertia: f64,
    /// Mean silhouette of the partition (None for k ≤ 1).
    pub silhouette: Option<f64>,
    /// Automatic choice: (k, silhouette or None when a cluster was too small).
    pub tried: Vec<(usize, Option<f64>)>,
    /// Minimum members for a cluster model.
    pub min_cluster_vertices: usize,
    /// The silhouette's k when clusters of it that were not separated were joined into one
    /// material (`cluster::join_unseparated`); absent when the partition stands as chosen.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joined_from: Option<usize>,
    /// Feature normalisation.
    pub scaling: FeatureScaling,
}

/// The result of [`super::augment()`] (module doc of `augment`). Serialises as a compact
/// summary: the per-vertex vectors are skipped, their counts kept.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Augmentation {
    /// Clusters with a model.
    pub clusters: Vec<ClusterModel>,
    /// Per vertex: index into `clusters` of its nearest model cluster.
    #[serde(skip)]
    pub assignment: Vec<Option<usize>>,
    /// Per vertex: virtual samples (weights sum to λ_g, or empty), σ_s floor (0: none), the
    /// cluster lobe as a start and the pooled η prior, for the final pass.
    #[serde(skip)]
    pub guides: Vec<VertexGuide>,
    /// Vertices with at least one virtual sample.
    pub vertices_with_virtual_samples: usize,
    /// Vertices with a pooled η prior.
    pub vertices_with_eta_prior: usize,
    /// The partition.
    pub partition: PartitionSummary,
}

/// Clusters whose colour centroids are closer than this pool η together: the virtual-sample
/// kernel's reach, 0.1·√(2 ln 100) ≈ 0.30 (`virtual_samples` module doc) — colours that share
/// virtual samples share a material.
pub const POOL_COLOUR_DISTANCE: f64 = 0.3035;

/// Whether a vertex's step-A η is its data's (not flagged `EtaUnidentifiable`, `GrazingOnly`
/// or `AtBound`): only then does it place the vertex in η and decide whether the pooled η
/// applies to it.
pub(super) fn eta_trusted(f: &VertexFit) -> bool {
    use crate::data::FitFlag;
    !f.flags.iter().any(|flag| {
        matches!(
            flag,
            FitFlag::EtaUnidentifiable | FitFlag::GrazingOnly | FitFlag::AtBound
        )
    })
}
