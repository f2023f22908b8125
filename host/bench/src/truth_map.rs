//! The simulator's truth at the vertices of any mesh: what a fitted vertex is scored against
//! when the fit ran on a mesh other than the truth's (carved, refined, perturbed).
//!
//! Contract: [`truth_at`] gives each position the closest point of the true surface
//! ([`ellipso_mesh::distance::ClosestPoints`]): the material and parameters of that triangle's
//! nearest corner (materials are regions, and the renderer's `region_blend = "nearest"` picks
//! the nearest corner too), the true normal interpolated over the triangle and normalised, and
//! the distance. A position with no closest point (empty truth) gets `None`.

use crate::truth::TruthObject;
use ellipso_mesh::distance::ClosestPoints;
use ellipso_model::optics::pbrdf::PbrdfParams;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

/// The truth at one vertex.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VertexTruth {
    /// Material index into [`TruthObject::material_names`].
    pub material: usize,
    /// True parameters.
    pub params: PbrdfParams<f64>,
    /// True unit normal, world.
    pub normal_world: [f64; 3],
    /// Distance to the true surface, metres.
    pub distance_m: f64,
}

/// The truth at every position (module doc).
pub fn truth_at(truth: &TruthObject, positions: &[Point3<f64>]) -> Vec<Option<VertexTruth>> {
    let query = ClosestPoints::new(&truth.mesh);
    let normals = truth.mesh.normals();
    positions
        .par_iter()
        .map(|p| {
            let c = query.closest(*p)?;
            let tri = truth.mesh.triangles()[c.triangle];
            let corner = (0..3)
                .max_by(|&i, &j| c.barycentric[i].total_cmp(&c.barycentric[j]))
                .unwrap_or(0);
            let v = tri[corner] as usize;
            let n: Vector3<f64> = (0..3)
                .map(|k| normals[tri[k] as usize].into_inner() * c.barycentric[k])
                .sum();
            // A degenerate interpolated normal (opposite corners) falls back to the corner's.
            let n = n
                .try_normalize(1e-12)
                .unwrap_or_else(|| normals[v].into_inner());
            let material = truth.material[v];

            Some(VertexTruth {
                material,
                params: truth.params[v],
                normal_world: n.into(),
                distance_m: c.distance_m,
            })
        })
        .collect()
}
