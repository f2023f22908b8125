//! The material label of every vertex for the mixed-material gate ([`material_labels`]): the
//! group of clusters its own fit places it in, or none where its data leave that open
//! (docs/fit-augment.md "Gating mixed samples").

use super::cluster::{self, ClusterConfig, FEATURE_DIM, Feature};
use super::{Clustering, trusted_se};
use crate::data::VertexFit;

/// Step A's fits of `n` vertices grouped into materials as [`super::augment`] groups them (features,
/// k-means, choice of k): each vertex's material — a group ([`cluster::separated_groups`]) of
/// clusters — or `None` where its own fit cannot say which ([`confident_group`]) or it has no
/// finite fit. What the next outer iteration's extraction uses to gate samples that mix
/// materials (`ObserveConfig::vertex_labels`; `None` mixes with nothing), so clusters that one
/// material's spread split apart do not gate each other, and a vertex whose η its data leave
/// open does not paint its neighbour's material into a patch of another.
pub fn material_labels(n: usize, fits: &[VertexFit], config: &ClusterConfig) -> Vec<Option<usize>> {
    let c = Clustering::new(n, fits, config);
    let partition = &c.selection.partition;
    if partition.centroids.is_empty() {
        return vec![None; n];
    }
    let groups = cluster::separated_groups(&c.member_features, partition);
    c.by_vertex
        .iter()
        .map(|f| {
            let f = (*f)?;
            let own = c.scaling.feature(f.params.rho_d, f.params.eta);
            confident_group(&own, trusted_se(f), &partition.centroids, &groups)
        })
        .collect()
}

/// Two-sided 95 % normal quantile: the half-width, in standard errors, of the η interval a
/// vertex's own fit allows ([`confident_group`]).
const LABEL_Z: f64 = 1.96;

/// Points of a vertex's η interval at which [`confident_group`] checks the nearest cluster.
const LABEL_ETA_STEPS: usize = 33;

/// The group of the cluster nearest `feature` when that group is the nearest one's at every η
/// of the vertex's interval η ± [`LABEL_Z`]·`se` (its own η, unshrunk; clamped to the range
/// of the clusters' own η; checked at [`LABEL_ETA_STEPS`] evenly spaced points); `None` when
/// the interval leaves the choice open. A vertex whose η is unidentified (`se` infinite) is
/// placed by its colour where that decides at every η, and left unlabelled between two
/// materials of one colour: its data say nothing about which of them it is of.
pub(super) fn confident_group(
    feature: &Feature,
    se: f64,
    centroids: &[Feature],
    groups: &[usize],
) -> Option<usize> {
    let eta_axis = FEATURE_DIM - 1;
    // The feature's η coordinate is 2·min(η, 3) (`FeatureScaling::feature`), η ≥ 1.
    let half = if se.is_finite() {
        2.0 * LABEL_Z * se
    } else {
        f64::INFINITY
    };
    // η between the materials' own: an η beyond every material's is none of theirs, and
    // sweeping there would only hand the vertex to whichever extreme lies nearest in colour.
    let (lowest, highest) = centroids
        .iter()
        .map(|c| c[eta_axis])
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), e| {
            (a.min(e), b.max(e))
        });
    if lowest.is_nan() || highest.is_nan() || lowest > highest {
        return None;
    }
    let lo = (feature[eta_axis] - half).clamp(lowest, highest);
    let hi = (feature[eta_axis] + half).clamp(lowest, highest);
    let mut found: Option<usize> = None;
    for step in 0..LABEL_ETA_STEPS {
        let t = step as f64 / (LABEL_ETA_STEPS - 1) as f64;
        let mut at = *feature;
        at[eta_axis] = lo + t * (hi - lo);
        let group = groups[cluster::nearest(&at, centroids).0];
        match found {
            None => found = Some(group),
            Some(g) if g != group => return None,
            Some(_) => {}
        }
    }
    found
}
