//! Which material a vertex to be completed takes ([`assign`]), and how sure that choice is
//! ([`membership_sd`]).
//!
//! Contract:
//! - **Candidates.** The clusters whose colour lies within the virtual-sample kernel's reach
//!   ([`POOL_COLOUR_DISTANCE`]) of the vertex's own colour (its fit's ρd from its samples);
//!   every cluster when the vertex has no sample (its colour is unknown); the nearest by colour
//!   when none is that close.
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
use crate::augment::{Augmentation, POOL_COLOUR_DISTANCE};
use crate::data::{SampleSet, VertexFit};

/// A vertex's material ([`assign`]): the chosen cluster and every cluster it could be of.
#[derive(Clone, Debug, PartialEq)]
pub struct Assigned {
    /// The chosen cluster.
    pub material: usize,
    /// The candidates (the chosen one among them), in cluster order.
    pub candidates: Vec<usize>,
}

/// The material of every vertex that needs one (module doc): `None` where there is no cluster
/// or the vertex is not to be completed.
pub fn assign(
    set: &SampleSet,
    fits: &[VertexFit],
    a: &Augmentation,
    mesh: &TriangleMesh,
    needs: &[bool],
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
    // A vertex's colour: its fit's ρd where it has samples (fitted, or at the prior lobe for a
    // vertex with too few). A vertex whose every sample was mixed has none: what its mixed
    // samples show is dominated, on the underside and at silhouettes, by the board and the
    // neighbours its footprint reached.
    let colours: Vec<Option<[f64; 3]>> = (0..fits.len())
        .map(|v| {
            let vertex = set.vertices.get(v)?;
            (needs[v] && !vertex.samples.is_empty()).then_some(fits[v].params.rho_d)
        })
        .collect();
    let colour_distance = |v: usize, j: usize| {
        let Some(rho_d) = colours[v] else {
            return f64::INFINITY;
        };
        let f = scaling.feature(rho_d, 1.5);
        let c = &a.clusters[j].centroid;
        (0..3).map(|i| (f[i] - c[i]).powi(2)).sum::<f64>().sqrt()
    };
    (0..fits.len())
        .map(|v| {
            if !needs[v] {
                return None;
            }
            let mut candidates: Vec<usize> = if colours[v].is_some() {
                (0..k)
                    .filter(|&j| colour_distance(v, j) < POOL_COLOUR_DISTANCE)
                    .collect()
            } else {
                (0..k).collect()
            };
            if candidates.is_empty() {
                candidates = vec![
                    (0..k)
                        .min_by(|&i, &j| colour_distance(v, i).total_cmp(&colour_distance(v, j)))
                        .unwrap_or(0),
                ];
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
