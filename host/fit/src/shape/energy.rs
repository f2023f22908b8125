//! The terms of the shape-update energy (see the parent module doc): the mesh's edge graph, the
//! usable normals and confidences, the per-edge midpoint-normal constraints, and the energy and
//! normal-misfit evaluations reported before and after the solve.
//!
//! Contract: everything here is deterministic and in input order — edges sorted `(u, v)` with
//! `u < v`, constraints in edge order — so the assembled system is identical run to run.

use super::sparse::{BlockCsr, IDENTITY};
use super::{ShapeConfig, ShapeError, scaled};
use nalgebra::{Point3, Vector3};

/// The undirected edges of a triangle list, and its degenerate-triangle count.
pub(super) struct MeshGraph {
    /// Unique edges `(u, v)` with `u < v`, sorted.
    pub(super) edges: Vec<(u32, u32)>,
    /// Triangles with a repeated index or zero area.
    pub(super) degenerate_triangles: usize,
}

impl MeshGraph {
    pub(super) fn new(
        positions: &[Point3<f64>],
        triangles: &[[u32; 3]],
    ) -> Result<Self, ShapeError> {
        let n = positions.len();
        let mut edges = Vec::with_capacity(3 * triangles.len());
        let mut degenerate_triangles = 0;
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&vertex) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(ShapeError::IndexOutOfRange {
                    triangle: t,
                    vertex,
                    vertices: n,
                });
            }
            let [a, b, c] = tri.map(|i| positions[i as usize]);
            let (e1, e2) = (b - a, c - a);
            let scale = e1.norm_squared().max(e2.norm_squared());
            // Zero area relative to the triangle's own size (collinear or coincident corners).
            if e1.cross(&e2).norm() <= 1e-12 * scale || scale == 0.0 {
                degenerate_triangles += 1;
            }
            for (u, v) in [(tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])] {
                if u != v {
                    edges.push((u.min(v), u.max(v)));
                }
            }
        }
        edges.sort_unstable();
        edges.dedup();
        Ok(Self {
            edges,
            degenerate_triangles,
        })
    }
}

/// The per-vertex input checks every solve of this module makes: a mesh with vertices and
/// triangles, each `(name, length)` of `per_vertex` one entry per vertex, and every point of
/// `points` (the positions first) finite — the error names the vertex.
pub(super) fn check_inputs(
    triangles: &[[u32; 3]],
    per_vertex: &[(&'static str, usize)],
    points: &[&[Point3<f64>]],
) -> Result<(), ShapeError> {
    let n = points.first().map_or(0, |p| p.len());
    if n == 0 || triangles.is_empty() {
        return Err(ShapeError::EmptyMesh {
            vertices: n,
            triangles: triangles.len(),
        });
    }
    for &(what, got) in per_vertex {
        if got != n {
            return Err(ShapeError::LengthMismatch {
                what,
                expected: n,
                got,
            });
        }
    }
    for set in points {
        if let Some(vertex) = set
            .iter()
            .position(|p| !p.coords.iter().all(|c| c.is_finite()))
        {
            return Err(ShapeError::NonFinitePosition { vertex });
        }
    }
    Ok(())
}

/// Unit normals and confidences with unusable entries zeroed: `(normals, weights, skipped)`.
pub(super) fn usable_normals(
    normals_world: &[[f64; 3]],
    confidence: &[f64],
) -> (Vec<[f64; 3]>, Vec<f64>, usize) {
    let mut skipped = 0;
    let mut normals = Vec::with_capacity(normals_world.len());
    let mut weights = Vec::with_capacity(normals_world.len());
    for (n, &c) in normals_world.iter().zip(confidence) {
        let v = Vector3::from(*n);
        let len = v.norm();
        // Guard the normalisation: a zero or non-finite normal gives no direction.
        let normal_ok = len.is_finite() && len > 1e-12;
        let confidence_ok = (0.0..=1.0).contains(&c);
        if normal_ok && confidence_ok {
            normals.push((v / len).into());
            weights.push(c);
        } else {
            skipped += 1;
            normals.push([0.0; 3]);
            weights.push(0.0);
        }
    }
    (normals, weights, skipped)
}

/// One edge's normal constraint `c (a · (p_u − p_v))²`.
pub(super) struct EdgeConstraint {
    pub(super) u: u32,
    pub(super) v: u32,
    /// Unit midpoint normal n̄_uv.
    pub(super) axis: [f64; 3],
    /// c_uv > 0.
    pub(super) weight: f64,
    /// a · (p⁰_u − p⁰_v).
    pub(super) axis_dot_edge0: f64,
}

/// The quadratic problem, for evaluating the energy and the misfit.
pub(super) struct Problem<'a> {
    edges: &'a [(u32, u32)],
    /// Constrained edges, in the order of `edges`.
    pub(super) constraints: Vec<EdgeConstraint>,
    pub(super) skipped_edges: usize,
    /// Anchor weight per vertex (λ_pos · a_v / D², see [`anchor_weights`]).
    pub(super) anchor: Vec<f64>,
    lambda_smooth: f64,
}

impl<'a> Problem<'a> {
    pub(super) fn new(
        positions: &[Point3<f64>],
        edges: &'a [(u32, u32)],
        normals: &[[f64; 3]],
        weights: &[f64],
        anchor: Vec<f64>,
        config: &ShapeConfig,
    ) -> Self {
        let mut constraints = Vec::new();
        let mut skipped_edges = 0;
        for &(u, v) in edges {
            let (cu, cv) = (weights[u as usize], weights[v as usize]);
            if !(cu > 0.0 && cv > 0.0) {
                continue;
            }
            let (nu, nv) = (
                Vector3::from(normals[u as usize]),
                Vector3::from(normals[v as usize]),
            );
            // Normals 90° or more apart across one edge define no common tangent plane.
            if nu.dot(&nv) <= 0.0 {
                skipped_edges += 1;
                continue;
            }
            // |nu + nv| > √2 here, so the division is safe.
            let axis = (nu + nv).normalize();
            let e0 = positions[u as usize] - positions[v as usize];
            constraints.push(EdgeConstraint {
                u,
                v,
                axis: axis.into(),
                // Harmonic mean; cu + cv > 0.
                weight: 2.0 * cu * cv / (cu + cv),
                axis_dot_edge0: axis.dot(&e0),
            });
        }
        Self {
            edges,
            constraints,
            skipped_edges,
            anchor,
            lambda_smooth: config.lambda_smooth,
        }
    }

    /// Adds the edge terms of E to the normal equations `a d = b`: the smoothness block of every
    /// edge and, on a constrained edge, ½∇ of c (a·(e⁰ + d_u − d_v))² — the c a aᵀ coupling and
    /// the right-hand side ∓ c a (a·e⁰). `a` holds `edges`' pattern.
    pub(super) fn add_edge_terms(&self, a: &mut BlockCsr, b: &mut [f64]) {
        let smooth = scaled(&IDENTITY, self.lambda_smooth);
        let mut next_constraint = self.constraints.iter().peekable();
        for &(u, v) in self.edges {
            let mut m = smooth;
            if let Some(c) = next_constraint.next_if(|c| (c.u, c.v) == (u, v)) {
                for (r, row) in m.iter_mut().enumerate() {
                    for (col, x) in row.iter_mut().enumerate() {
                        *x += c.weight * c.axis[r] * c.axis[col];
                    }
                }
                let g = c.weight * c.axis_dot_edge0;
                for k in 0..3 {
                    b[3 * u as usize + k] -= g * c.axis[k];
                    b[3 * v as usize + k] += g * c.axis[k];
                }
            }
            a.add_edge(u, v, &m);
        }
    }

    /// E at displacement `d` from `positions` (m²).
    pub(super) fn energy(&self, positions: &[Point3<f64>], d: &[f64]) -> f64 {
        let dv = |i: u32| {
            Vector3::new(
                d[3 * i as usize],
                d[3 * i as usize + 1],
                d[3 * i as usize + 2],
            )
        };
        let anchor: f64 = d
            .chunks(3)
            .zip(&self.anchor)
            .map(|(dv, w)| w * (dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2]))
            .sum();
        let smooth: f64 = self
            .edges
            .iter()
            .map(|&(u, v)| (dv(u) - dv(v)).norm_squared())
            .sum::<f64>()
            * self.lambda_smooth;
        let normal: f64 = self
            .constraints
            .iter()
            .map(|c| {
                let e = positions[c.u as usize] - positions[c.v as usize] + dv(c.u) - dv(c.v);
                c.weight * Vector3::from(c.axis).dot(&e).powi(2)
            })
            .sum();
        anchor + smooth + normal
    }

    /// Confidence-weighted RMS of `n̄ · e / ‖e‖` over constrained edges of non-zero length.
    pub(super) fn normal_misfit(&self, positions: &[Point3<f64>]) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for c in &self.constraints {
            let e = positions[c.u as usize] - positions[c.v as usize];
            let len = e.norm();
            // Guard: a zero-length edge has no direction and no misfit.
            if len > 0.0 {
                num += c.weight * (Vector3::from(c.axis).dot(&e) / len).powi(2);
                den += c.weight;
            }
        }
        if den > 0.0 { (num / den).sqrt() } else { 0.0 }
    }
}

/// Smallest vertex area used in the anchor, as a fraction of the mean vertex area: a vertex in no
/// triangle of positive area keeps a positive anchor, so the system stays positive definite.
pub(super) const MIN_AREA_FRACTION: f64 = 1e-3;

/// The anchor weight of each vertex: `λ_pos · a_v / D²`, with `a_v` a third of the area of the
/// vertex's triangles and `D` the bounding-box diagonal, so the weight per unit surface area is
/// the same at every mesh resolution and scale. `a_v` is floored at [`MIN_AREA_FRACTION`] of the
/// mean vertex area; a mesh without extent (D = 0 or no area at all) gets λ_pos per vertex.
pub(super) fn anchor_weights(
    positions: &[Point3<f64>],
    triangles: &[[u32; 3]],
    lambda_position: f64,
) -> Vec<f64> {
    let n = positions.len();
    let mut area = vec![0.0; n];
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let third = (b - a).cross(&(c - a)).norm() / 6.0;
        for &i in t {
            area[i as usize] += third;
        }
    }
    let (lo, hi) = positions.iter().fold(
        (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.inf(&p.coords), hi.sup(&p.coords)),
    );
    let diagonal_sq = (hi - lo).norm_squared();
    let mean_area = area.iter().sum::<f64>() / n.max(1) as f64;
    // Guard the divisions: without extent or area there is no length scale to normalise by.
    if diagonal_sq.is_nan() || diagonal_sq <= 0.0 || mean_area.is_nan() || mean_area <= 0.0 {
        return vec![lambda_position; n];
    }
    let floor = MIN_AREA_FRACTION * mean_area;
    area.iter()
        .map(|a| lambda_position * a.max(floor) / diagonal_sq)
        .collect()
}
