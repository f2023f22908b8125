//! Which material a vertex to be completed takes ([`assign`]), and how sure that choice is
//! ([`membership_sd`]).
//!
//! Contract:
//! - **Candidates.** The clusters whose colour lies within the virtual-sample kernel's reach
//!   ([`POOL_COLOUR_DISTANCE`]) plus 1.96 standard errors ([`colour_within_reach`]) of the
//!   vertex's own colour *under that cluster's model*: its least-squares ρd from its samples
//!   with the cluster's η and lobes at the surface normal (`super::own_rho_d`), so a glossy
//!   material's vertex is not judged by a colour fitted with another's lobe (the step-A fit of
//!   a vertex with too few samples sits at the prior lobe: on dev scene 8, 342 of the 487 zinc
//!   sulfide vertices took polystyrene's η, −33 %). Every cluster when the vertex has no
//!   sample (its colour is unknown), and every cluster too when none is that close: a colour
//!   no material has (a blend across a border, a material no own-fit vertex represents)
//!   cannot choose between them, and the choice's σ (below) then spans them all. (Taking the
//!   nearest colour instead gave a dark grey patch of dev scene 12, η 1.491, a blue
//!   material's η 2.02 with that material's σ 0.009; now the same value with σ spanning every
//!   material's η.)
//! - **The choice.** Of the candidates, the one whose own-fit members are nearest along the
//!   mesh's edges (multi-source Dijkstra per cluster): a vertex takes the material of its
//!   surroundings that its colour allows.
//! - **How sure.** A vertex with one candidate is of that material as far as its colour can
//!   tell. With several, its own data do not say which (that is why it is completed): nearness
//!   picks one, but on the underside and along material boundaries — where completed vertices
//!   lie — the nearest identified material is not reliably the vertex's (measured on the
//!   generated scenes, docs/generalize.md: underside patches of a material that no own-fit
//!   vertex represents took a neighbour's η, 9–25 % off, with the neighbour's 0.01 as σ).
//!   With no evidence between them, each candidate is as likely as another (the
//!   maximum-entropy choice): [`membership_sd`] is the RMS difference between the candidates'
//!   η and the chosen one's, the standard deviation of η under that uniform distribution about
//!   the reported value, and the completed η's σ adds it in quadrature. A material no vertex
//!   was fitted on is no candidate: a patch of a material the views never isolated, of the
//!   same colour as its surroundings, cannot be told from them (a limit of the data, stated in
//!   docs/fit-augment.md).

use ellipso_model::geometry::TriangleMesh;

use super::{MaterialValues, own_vertex};
use crate::augment::cluster::FeatureScaling;
use crate::augment::{Augmentation, POOL_COLOUR_DISTANCE};
use crate::data::VertexFit;

/// A vertex's material ([`assign`]): the chosen cluster and every cluster it could be of.
#[derive(Clone, Debug, PartialEq)]
pub struct Assigned {
    /// The chosen cluster.
    pub material: usize,
    /// The candidates (the chosen one among them), in cluster order.
    pub candidates: Vec<usize>,
}

/// The material of every vertex that needs one (module doc): `None` where there is no cluster
/// or the vertex is not to be completed. `own_colour(v, j)` is vertex `v`'s ρd and its standard
/// error from its samples under cluster `j`'s model, `None` without a usable sample.
pub fn assign(
    fits: &[VertexFit],
    a: &Augmentation,
    mesh: &TriangleMesh,
    needs: &[bool],
    own_colour: impl Fn(usize, usize) -> Option<([f64; 3], [f64; 3])>,
) -> Vec<Option<Assigned>> {
    let k = a.clusters.len();
    if k == 0 {
        return vec![None; fits.len()];
    }
    let adj = crate::neighbours::adjacency(mesh);
    let distances: Vec<Vec<f64>> = (0..k)
        .map(|j| {
            let sources: Vec<usize> = (0..fits.len())
                .filter(|&v| a.assignment.get(v) == Some(&Some(j)) && own_vertex(&fits[v]))
                .collect();
            crate::neighbours::graph_distance(&adj, &sources)
        })
        .collect();
    let scaling = a.partition.scaling;
    (0..fits.len())
        .map(|v| {
            if !needs[v] {
                return None;
            }
            // Its colour under each cluster's own lobes, within reach of the cluster's or not
            // (module doc). A vertex whose every sample was mixed has no colour (`own_colour`
            // gives none): what its mixed samples show is dominated, on the underside and at
            // silhouettes, by the board and the neighbours its footprint reached.
            let mut candidates: Vec<usize> = (0..k)
                .filter(|&j| match own_colour(v, j) {
                    Some((rho, se)) => {
                        colour_within_reach(scaling, &a.clusters[j].centroid, rho, se)
                    }
                    None => true,
                })
                .collect();
            if candidates.is_empty() {
                candidates = (0..k).collect();
            }
            let material = candidates
                .iter()
                .copied()
                .min_by(|&i, &j| distances[i][v].total_cmp(&distances[j][v]))
                .unwrap_or(candidates[0]);
            Some(Assigned {
                material,
                candidates,
            })
        })
        .collect()
}

/// Two-sided 95 % normal quantile: how many standard errors of a vertex's own ρd its colour
/// may lie from a material's and still be of it ([`colour_within_reach`]).
const COLOUR_Z: f64 = 1.96;

/// Distance of the colour `rho` from a cluster's `centroid` in the clustering's scaled units.
fn colour_distance(scaling: FeatureScaling, centroid: &[f64], rho: [f64; 3]) -> f64 {
    let f = scaling.colour(rho);
    (0..3)
        .map(|i| (f[i] - centroid[i]).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Whether the colour `rho` ± `se` (per channel) lies within the kernel's reach
/// ([`POOL_COLOUR_DISTANCE`], in the clustering's scaled units) of the cluster's `centroid`
/// plus [`COLOUR_Z`] of its standard error there. A non-finite standard error is within reach
/// (that colour cannot rule a material out).
pub fn colour_within_reach(
    scaling: FeatureScaling,
    centroid: &[f64],
    rho: [f64; 3],
    se: [f64; 3],
) -> bool {
    let se_scaled = se.iter().map(|s| s * s).sum::<f64>().sqrt() * scaling.rho_d_scale;
    if !se_scaled.is_finite() {
        return true;
    }
    colour_distance(scaling, centroid, rho) <= POOL_COLOUR_DISTANCE + COLOUR_Z * se_scaled
}

/// The spread of η over a vertex's candidate materials about `eta` (the value it reports): the
/// RMS of (η_c − `eta`) over the candidates `c` whose material has an η (module doc, "How
/// sure"); 0 with fewer than two such candidates.
pub fn membership_sd(eta: f64, candidates: &[usize], materials: &[MaterialValues]) -> f64 {
    let etas: Vec<f64> = candidates
        .iter()
        .filter_map(|&c| materials.get(c)?.eta.map(|e| e[0]))
        .filter(|e| e.is_finite())
        .collect();
    if etas.len() < 2 || !eta.is_finite() {
        return 0.0;
    }
    let sum2: f64 = etas.iter().map(|e| (e - eta).powi(2)).sum();
    (sum2 / etas.len() as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material(eta: Option<f64>) -> MaterialValues {
        MaterialValues {
            eta: eta.map(|e| [e, 0.01]),
            eta_withheld_se: None,
            lobe: [0.1; 6],
            lobe_spread: [0.01; 6],
            rho_d: [0.5; 3],
            rho_d_spread: [0.01; 3],
        }
    }

    #[test]
    fn a_colour_is_out_of_reach_only_beyond_the_kernel_and_its_own_error() {
        let scaling = FeatureScaling {
            rho_d_clip: f64::MAX,
            rho_d_scale: 3.0,
        };
        // A blue material, scaled ×3.
        let blue = [0.15, 0.57, 1.29, 3.0];
        let grey = [0.04, 0.04, 0.045];
        // A well-measured dark grey is not the blue.
        assert!(!colour_within_reach(scaling, &blue, grey, [0.005; 3]));
        // Measured too loosely to tell, it may be.
        assert!(colour_within_reach(scaling, &blue, grey, [0.3; 3]));
        // An unknown error cannot rule a material out.
        assert!(colour_within_reach(
            scaling,
            &blue,
            grey,
            [f64::INFINITY; 3]
        ));
        // The blue itself is within reach.
        assert!(colour_within_reach(
            scaling,
            &blue,
            [0.05, 0.19, 0.43],
            [0.005; 3]
        ));
    }

    #[test]
    fn one_candidate_leaves_the_material_spread_alone() {
        let m = [material(Some(1.5)), material(Some(2.0))];
        assert_eq!(membership_sd(1.5, &[0], &m), 0.0);
        // A second candidate without an η says nothing about it.
        assert_eq!(
            membership_sd(1.5, &[0], &[material(Some(1.5)), material(None)]),
            0.0
        );
    }

    #[test]
    fn candidates_of_other_eta_widen_it_by_their_rms_difference() {
        let m = [
            material(Some(1.4)),
            material(Some(1.45)),
            material(Some(2.0)),
        ];
        let sd = membership_sd(1.4, &[0, 1, 2], &m);
        let expected = ((0.0f64 + 0.05 * 0.05 + 0.6 * 0.6) / 3.0).sqrt();
        assert!((sd - expected).abs() < 1e-12, "{sd} vs {expected}");
        // A candidate of the same η (one material split in two clusters) adds nothing.
        let same = [material(Some(1.5)), material(Some(1.5))];
        assert_eq!(membership_sd(1.5, &[0, 1], &same), 0.0);
        // A wrong pick between two materials 0.6 apart is within 1.5σ: an honest σ.
        let pair = [material(Some(1.4)), material(Some(2.0))];
        let sd = membership_sd(1.4, &[0, 1], &pair);
        assert!(0.6 / sd <= 1.5, "{sd}");
    }
}
