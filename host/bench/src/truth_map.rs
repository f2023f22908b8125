//! The simulator's truth at the vertices of any mesh: what a fitted vertex is scored against
//! when the fit ran on a mesh other than the truth's (carved, refined, perturbed).
//!
//! Contract: [`truth_at`] gives each position the closest point of the true surface
//! ([`ellipso_model::geometry::distance::ClosestPoints`]): the material and parameters of that triangle's
//! nearest corner (materials are regions, and the renderer's `region_blend = "nearest"` picks
//! the nearest corner too), the true normal interpolated over the triangle and normalised, and
//! the distance, unsigned and signed (positive outside: along the true triangle's outward face
//! normal, the side its interpolated normal points to). A position with no closest point
//! (empty truth) gets `None`.

use crate::truth::TruthObject;
use ellipso_model::geometry::distance::ClosestPoints;
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
    /// The same, positive outside the true surface and negative inside, metres.
    pub signed_distance_m: f64,
    /// The closest point of the true surface, world, metres.
    pub closest_world: [f64; 3],
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
            // The side: the offset along the closest triangle's face normal, turned to the
            // interpolated normal's side; an offset in its plane (0) takes the normal's own.
            let [a, b, cc] = tri.map(|i| truth.mesh.positions()[i as usize]);
            let face = (b - a).cross(&(cc - a));
            let face = if face.dot(&n) < 0.0 { -face } else { face };
            let along = (*p - c.point).dot(&face);
            let side = if along != 0.0 {
                along.signum()
            } else {
                (*p - c.point).dot(&n).signum()
            };

            Some(VertexTruth {
                material,
                params: truth.params[v],
                normal_world: n.into(),
                distance_m: c.distance_m,
                signed_distance_m: side * c.distance_m,
                closest_world: c.point.into(),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::geometry::TriangleMesh;
    use ellipso_model::geometry::procedural::icosphere;

    /// A unit icosphere of radius 20 mm as the truth, one material.
    fn sphere_truth() -> TruthObject {
        let (dirs, triangles) = icosphere(3);
        let positions: Vec<Point3<f64>> = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * 0.02))
            .collect();
        let normals: Vec<Vector3<f64>> = dirs.iter().map(|d| d.into_inner()).collect();
        let n = positions.len();
        let mesh = TriangleMesh::new(positions, Some(normals), None, triangles).expect("mesh");
        let params = PbrdfParams {
            eta: 1.5,
            sigma_s: 0.2,
            sigma_ss: 0.5,
            rho_s: 1.0,
            rho_ss: [0.1; 3],
            rho_d: [0.5; 3],
        };
        TruthObject {
            mesh,
            params: vec![params; n],
            material: vec![0; n],
            material_names: vec!["m".into()],
            convex: true,
        }
    }

    #[test]
    fn signed_distance_is_positive_outside_and_negative_inside() {
        let truth = sphere_truth();
        let (dirs, _) = icosphere(1);
        // Points 0.2 mm outside the vertices' radius and 0.5 mm inside it: the facets sag
        // about 0.04 mm below it at this resolution, far less than either offset.
        let outside: Vec<Point3<f64>> = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * 0.0202))
            .collect();
        let inside: Vec<Point3<f64>> = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * 0.0195))
            .collect();
        for (points, sign) in [(outside, 1.0), (inside, -1.0)] {
            for t in truth_at(&truth, &points) {
                let t = t.expect("truth");
                assert!(t.distance_m > 1e-5, "{t:?}");
                assert_eq!(t.signed_distance_m, sign * t.distance_m, "{t:?}");
            }
        }
    }
}
