//! Scores of the specular lobe against the simulator's truth — what a flash-energy bracket is
//! for (issue 18): the clusters' σs per material, and how many samples at the lobe peak of
//! glossy vertices survived the gates.
//!
//! Contract:
//! - **Near-mirror view** ([`is_near_mirror`]): the half vector of the view lies inside the true
//!   lobe's half maximum, GGX D(θ_h; σs) ≥ ½·D(0; σs) — for σs = 0.03 that is θ_h ≤ 1.1°, for
//!   0.08 θ_h ≤ 2.9°. The simulator records these views per vertex among the views that see it
//!   lit and unblocked, before any gate (`SimulatedCapture::near_mirror`).
//! - **Peak samples** ([`PeakSamples`]): for each glossy material (true σs ≤
//!   [`GLOSSY_SIGMA_S_MAX`]), the vertices with a near-mirror view among the fitted views, how
//!   many of them kept at least one sample from such a view, and the totals, also per flash
//!   energy of the view (what limits the count: a view lit at an energy whose peak clips keeps
//!   nothing). Target (issue 18): every such vertex keeps one.
//! - **Cluster σs** ([`ClusterLobe`]): per material, the median over its vertices of the σs of
//!   the cluster each is assigned to (`Augmentation::assignment`) — the σs the material's
//!   virtual samples and floor come from — and its error relative to the true σs. With one
//!   cluster per material this is that cluster's σs.

use std::collections::BTreeSet;

use ellipso_model::optics::microfacet::ggx_d;

use super::SimulatedCapture;
use ellipso_fit::augment::Augmentation;

/// Materials with a true σs at or below this are glossy (the glaze 0.08 and the glossy plastic
/// 0.03 of the four-material blob; the ceramic's 0.2 is not).
pub const GLOSSY_SIGMA_S_MAX: f64 = 0.1;

/// Whether a view with `cos_theta_h` = n·h (true normal) lies inside the half maximum of a GGX
/// lobe of roughness `sigma_s` (module doc).
pub fn is_near_mirror(cos_theta_h: f64, sigma_s: f64) -> bool {
    // ggx_d floors α itself; D(0) > 0 for any α, so the ratio is defined.
    ggx_d(cos_theta_h, sigma_s) >= 0.5 * ggx_d(1.0, sigma_s)
}

/// Samples at the lobe peak of one glossy material (module doc).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct PeakSamples {
    /// Material name.
    pub material: String,
    /// True σs.
    pub sigma_s_true: f64,
    /// Vertices with at least one near-mirror view among the fitted views.
    pub vertices_with_near_mirror_view: usize,
    /// Of those, vertices that kept at least one sample from a near-mirror view.
    pub vertices_with_peak_kept: usize,
    /// Near-mirror (vertex, view) pairs among the fitted views.
    pub near_mirror_views: usize,
    /// Of those, samples kept by the gates.
    pub peak_samples_kept: usize,
    /// Per relative flash energy of the view, descending: (energy, near-mirror views, kept).
    pub by_energy: Vec<(f64, usize, usize)>,
}

impl PeakSamples {
    /// Counts one near-mirror view lit at `energy` (exact: the energies are the bracket's own
    /// values), `kept` or not.
    fn count(&mut self, energy: f64, kept: bool) {
        if !self.by_energy.iter().any(|e| e.0 == energy) {
            self.by_energy.push((energy, 0, 0));
            self.by_energy.sort_by(|a, b| b.0.total_cmp(&a.0));
        }
        for e in self.by_energy.iter_mut().filter(|e| e.0 == energy) {
            e.1 += 1;
            e.2 += usize::from(kept);
        }
    }
}

/// The cluster σs of one material (module doc).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ClusterLobe {
    /// Material name.
    pub material: String,
    /// True σs.
    pub sigma_s_true: f64,
    /// Median over the material's assigned vertices of their cluster's σs (NaN: none assigned).
    pub sigma_s_cluster: f64,
    /// (σs_cluster − σs_true)/σs_true, %.
    pub sigma_s_error_pct: f64,
    /// Fraction of the material's vertices assigned to the cluster whose σs is the median.
    pub share: f64,
}

/// Both scores of one fit.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct LobeScores {
    /// Per material with at least one vertex (empty without step B).
    pub clusters: Vec<ClusterLobe>,
    /// Per glossy material.
    pub peaks: Vec<PeakSamples>,
}

impl LobeScores {
    /// The score of material `name`, if it has one.
    pub fn cluster(&self, name: &str) -> Option<&ClusterLobe> {
        self.clusters.iter().find(|c| c.material == name)
    }

    /// The peak counts of material `name`, if it is glossy.
    pub fn peak(&self, name: &str) -> Option<&PeakSamples> {
        self.peaks.iter().find(|p| p.material == name)
    }
}

/// Scores `capture` (its `set` = the views the fit saw) and the fit's clusters.
pub fn score(capture: &SimulatedCapture, augmentation: Option<&Augmentation>) -> LobeScores {
    let truth = &capture.truth;
    let set = &capture.set;
    let fitted: BTreeSet<u64> = set.views.iter().map(|v| v.frame_id).collect();
    let mut scores = LobeScores::default();
    for (m, name) in truth.material_names.iter().enumerate() {
        let members: Vec<usize> = (0..truth.material.len())
            .filter(|&v| truth.material[v] == m)
            .collect();
        let Some(&first) = members.first() else {
            continue;
        };
        let sigma_s_true = truth.params[first].sigma_s;
        if let Some(a) = augmentation {
            let mut assigned: Vec<(f64, usize)> = members
                .iter()
                .filter_map(|&v| a.assignment.get(v).copied().flatten())
                .filter_map(|c| a.clusters.get(c).map(|cl| (cl.sigma_s, c)))
                .collect();
            assigned.sort_by(|x, y| x.0.total_cmp(&y.0));
            let (sigma_s_cluster, share) = match assigned.get(assigned.len() / 2) {
                Some(&(sigma, c)) => {
                    let same = assigned.iter().filter(|x| x.1 == c).count();
                    (sigma, same as f64 / members.len() as f64)
                }
                None => (f64::NAN, 0.0),
            };
            scores.clusters.push(ClusterLobe {
                material: name.clone(),
                sigma_s_true,
                sigma_s_cluster,
                // True σs of a material is > 0 (the scene validates it).
                sigma_s_error_pct: 100.0 * (sigma_s_cluster - sigma_s_true)
                    / sigma_s_true.max(1e-12),
                share,
            });
        }
        if sigma_s_true > GLOSSY_SIGMA_S_MAX {
            continue;
        }
        let mut peak = PeakSamples {
            material: name.clone(),
            sigma_s_true,
            ..PeakSamples::default()
        };
        for &v in &members {
            let candidates: BTreeSet<u64> = capture
                .near_mirror
                .get(v)
                .into_iter()
                .flatten()
                .copied()
                .filter(|id| fitted.contains(id))
                .collect();
            if candidates.is_empty() {
                continue;
            }
            let kept_ids: BTreeSet<u64> = set.vertices[v]
                .samples
                .iter()
                .filter_map(|s| set.views.get(s.view as usize).map(|view| view.frame_id))
                .filter(|id| candidates.contains(id))
                .collect();
            let kept = kept_ids.len();
            for id in &candidates {
                let energy = capture
                    .flash_energy_rel
                    .get(*id as usize)
                    .copied()
                    .unwrap_or(1.0);
                peak.count(energy, kept_ids.contains(id));
            }
            peak.vertices_with_near_mirror_view += 1;
            peak.vertices_with_peak_kept += usize::from(kept > 0);
            peak.near_mirror_views += candidates.len();
            peak.peak_samples_kept += kept;
        }
        scores.peaks.push(peak);
    }
    scores
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_near_mirror_cone_is_the_half_maximum_of_the_lobe() {
        // tan²θ = (√2 − 1)α²/(1 − √2α²) at half maximum.
        for sigma in [0.03f64, 0.08, 0.2] {
            let a2 = sigma * sigma;
            let tan2 = (2f64.sqrt() - 1.0) * a2 / (1.0 - 2f64.sqrt() * a2);
            let theta = tan2.sqrt().atan();
            assert!(is_near_mirror((theta * 0.99).cos(), sigma));
            assert!(!is_near_mirror((theta * 1.01).cos(), sigma));
        }
    }
}
