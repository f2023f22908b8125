//! Which clusters of a partition are distinct materials ([`separated_groups`]): the rule that
//! joins the splits k-means makes of one material's spread and keeps materials apart
//! (docs/fit-augment.md "Joining what is not separated").
//!
//! Contract:
//! - Two clusters are **separated** when, on the line through their centres, the distance
//!   between their members' medians exceeds [`UNIMODAL_SPLIT_RATIO`] times the wider of their
//!   robust spreads along that line (1.4826·MAD, `ellipso_model::stats::robust_sigma`),
//!   raised by the sampling margin (1 + [`SPLIT_RATIO_NOISE`]/√n_eff), n_eff twice the smaller
//!   cluster's size ([`split_ratio`] and [`split_threshold`]).
//! - Groups join transitively ([`super::join_pairs`]); a group is named by its smallest
//!   cluster index.
//! - Only the line through the centres counts: the noise of the feature dimensions across it
//!   (the other colour channels, or η where the colours differ) says nothing about whether
//!   the two are one material, and a rule on the full-dimensional distance counted it —
//!   two materials of one colour whose η differ by eleven times their members' η noise were
//!   joined (generated dev scene 14: lasf9 η 1.850 beside polystyrene 1.590, both orange:
//!   the lasf9 vertices without their own fit took polystyrene's η, −14 %).

use super::{Feature, Partition, distance_sq, join_pairs};

/// Separation at which a split stops being one unimodal spread: the ratio of the distance
/// between the two halves' medians to their robust spread (1.4826·MAD) when k-means cuts a
/// **uniform** density in two — 2.70 (2·10⁶ draws). The uniform is the flattest unimodal
/// density, and of the symmetric unimodal shapes its halves lie farthest apart in these units
/// (measured the same way: normal 2.28, the cosine-shaped arcsine-of-uniform 2.41, triangular
/// 2.24, Laplace 1.94, Student t₃ 2.12). Two materials of equal normal noise σ split at this
/// ratio when their means differ by 2.5σ (2.71 measured; 3σ gives 3.07, 4σ 4.01): closer
/// than that, no vertex's own fit can tell which of the two it is of anyway.
pub const UNIMODAL_SPLIT_RATIO: f64 = 2.70;

/// The sampling margin of [`UNIMODAL_SPLIT_RATIO`]: a uniform density of n points cut in two
/// exceeds 2.70·(1 + c/√n) in 1 % of draws with c ≤ 6.4 for n = 40 … 1000 (4000 draws each:
/// c = 6.4 at 40, 4.6 at 100, 4.0 at 300, 3.6 at 1000) — the partition is judged at the 99 %
/// level.
pub const SPLIT_RATIO_NOISE: f64 = 6.4;

/// `(ratio, threshold)` of clusters `i` and `j` of `partition` (module doc): the distance of
/// their members' medians along the line through the centres over the wider robust spread
/// along it, and the ratio above which they are separated. `(NaN, ∞)` when either cluster is
/// empty or the centres coincide; a ratio of ∞ when both spreads are 0 and the medians differ.
pub fn split_ratio(points: &[Feature], partition: &Partition, i: usize, j: usize) -> (f64, f64) {
    let (ci, cj) = (&partition.centroids[i], &partition.centroids[j]);
    let length = distance_sq(ci, cj).sqrt();
    if length.is_nan() || length <= 0.0 {
        return (f64::NAN, f64::INFINITY);
    }
    let axis: Feature = std::array::from_fn(|d| (cj[d] - ci[d]) / length);
    let along = |p: &Feature| (0..p.len()).map(|d| (p[d] - ci[d]) * axis[d]).sum::<f64>();
    let mut a = Vec::new();
    let mut b = Vec::new();
    for (p, &label) in points.iter().zip(&partition.labels) {
        if label == i {
            a.push(along(p));
        } else if label == j {
            b.push(along(p));
        }
    }
    if a.is_empty() || b.is_empty() {
        return (f64::NAN, f64::INFINITY);
    }
    let threshold = split_threshold(a.len().min(b.len()));
    let gap = (ellipso_model::stats::median(&mut b) - ellipso_model::stats::median(&mut a)).abs();
    let spread =
        ellipso_model::stats::robust_sigma(&mut a).max(ellipso_model::stats::robust_sigma(&mut b));
    let ratio = if spread > 0.0 {
        gap / spread
    } else if gap > 0.0 {
        f64::INFINITY
    } else {
        0.0
    };
    (ratio, threshold)
}

/// The ratio two clusters the smaller of which holds `smaller` members must exceed:
/// [`UNIMODAL_SPLIT_RATIO`]·(1 + [`SPLIT_RATIO_NOISE`]/√(2·smaller)) — the margin of an even
/// split of 2·`smaller` points (the smaller cluster's noise rules the ratio's).
pub fn split_threshold(smaller: usize) -> f64 {
    let n_eff = (2 * smaller).max(1) as f64;
    UNIMODAL_SPLIT_RATIO * (1.0 + SPLIT_RATIO_NOISE / n_eff.sqrt())
}

/// The groups of `partition`'s clusters (a group index per cluster, the smallest cluster index
/// of its group) that are distinct materials (module doc).
///
/// Why: k-means splits whatever it is given, and the silhouette accepts a split of one
/// unimodal spread. One material's noise, or a region whose fits share a bias (the underside's
/// unidentified albedo), then becomes two "materials", and a gate that drops every sample
/// whose footprint crosses their border drops real samples for nothing, while each half pools
/// the η its split selected. Materials that differ stay apart, including two of one colour
/// whose η differ by more than their members' η noise allows.
pub fn separated_groups(points: &[Feature], partition: &Partition) -> Vec<usize> {
    join_pairs(partition.centroids.len(), |i, j| {
        let (ratio, threshold) = split_ratio(points, partition, i, j);
        tracing::debug!(
            "clusters {i} and {j}: medians {ratio:.2} robust spreads apart along their centres' line (separated above {threshold:.2})"
        );
        // A NaN ratio (an empty cluster, coincident centres) is not separated.
        ratio.is_nan() || ratio <= threshold
    })
}
