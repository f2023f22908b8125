//! The shape update of the outer loop (docs/model.md §11 "Steps A, B, C and the outer loop";
//! docs/fit-shape.md): move the mesh vertices so the surface agrees with the refined per-vertex
//! normals, keeping the connectivity.
//!
//! # Choice: normal-guided vertex optimisation, not screened Poisson
//! The paper re-meshes with screened Poisson reconstruction from the refined oriented points and
//! carries parameters to the new mesh by nearest-neighbour lookup. We instead solve the
//! positions+normals least squares of Nehab, Rusinkiewicz, Davis and Ramamoorthi ("Efficiently
//! Combining Positions and Normals for Precise 3D Geometry", SIGGRAPH 2005) on the fixed
//! connectivity:
//! - vertex identity is kept, so per-vertex parameters, samples and visibility carry over with no
//!   resampling and no nearest-neighbour transfer error;
//! - open meshes (a scan's unseen bottom) stay open — Poisson closes them or needs trimming;
//! - it is one sparse SPD solve, linear in the vertex count, with no octree depth to choose;
//! - positions fix the low spatial frequencies (where normals integrate drift), normals the high
//!   ones (where positions are noisy) — the crossover is set by `lambda_position`.
//!
//! What it gives up: connectivity never changes, so topology errors of the scanned mesh (holes,
//! bridges) are not repaired and resolution is not adapted to detail; large corrections need
//! several outer iterations (each call is clamped, see [`ShapeConfig::max_displacement_m`]).
//! `docs/fit-shape.md` has the measured numbers.
//!
//! # Energy (over displacements d = p − p⁰ from the current positions p⁰)
//! ```text
//! E(d) = λ_pos Σ_v (a_v/D²) ‖d_v‖²                         (anchor, area-weighted)
//!      + Σ_edges(u,v) c_uv (n̄_uv · (p_u − p_v))²            (edges ⟂ the refined normals)
//!      + λ_smooth Σ_edges(u,v) ‖d_u − d_v‖²                (uniform Laplacian of the displacement)
//! ```
//! - `n̄_uv = normalise(n_u + n_v)`, the mean of the two refined end normals. A chord between two
//!   surface points is perpendicular to the normal at its midpoint up to O(h²) in angle, whereas
//!   the end normals are off by half the angle the edge subtends: the end-normal form
//!   `c_v (n_v·e)² + c_u (n_u·e)²` flattens every curved surface (on a sphere it is never zero;
//!   with a weak anchor it shrinks the sphere by percents), the midpoint form is exact on a sphere.
//!   An edge whose end normals are 90° or more apart defines no tangent and is skipped (counted).
//! - `c_uv = 2 c_u c_v / (c_u + c_v)` (harmonic mean; 0 when either end has confidence 0), so an
//!   untrusted normal drives no edge and its vertex is held only by its anchor and the smoothness
//!   term. Per-vertex confidence is `1 / (1 + (σ_n/σ_ref)²)` from the solver's normal standard
//!   error, 0 for flags that void the normal ([`ShapeConfig::confidence`], [`normal_targets`]).
//! - The smoothness term penalises the difference of neighbouring displacements (zero at d = 0:
//!   no shrinkage bias), which keeps the existing triangle shapes and suppresses vertex-scale
//!   noise from noisy normals. The uniform (graph) Laplacian is used; cotangent weights can be
//!   negative on obtuse triangles and would break positive definiteness.
//!
//! - The anchor is area-weighted (`a_v`: a third of the vertex's triangle areas, `D`: bounding-box
//!   diagonal; every vertex keeps the same anchor, w_v = 1 — the normal's confidence does not
//!   enter here). The normal term of a smooth displacement field does not change with mesh
//!   resolution (more, shorter edges), so a per-vertex anchor would trust the normals less and less
//!   as the mesh is refined (measured: the correction fell from 3.6× at 2.5k vertices to 1.1× at
//!   164k). With `a_v/D²` the position/normal crossover is a fixed fraction of the object size.
//!
//! All terms are squared lengths in m² (`a_v/D²` is dimensionless), so the weights are
//! dimensionless and the solution is scale invariant (a mesh in mm and the same mesh in m move
//! identically, scaled).
//!
//! # Solver
//! E is quadratic: the normal equations `A d = b` (3V×3V, sparse, SPD since λ_pos > 0) are solved
//! by conjugate gradient preconditioned with the inverse 3×3 diagonal blocks (block Jacobi),
//! in-crate over a block-CSR matrix ([`sparse`]), warm-started at d = 0 (the current positions).
//! Deterministic: the same input gives bit-identical output for any thread count.
//! Afterwards each vertex's move is clamped to [`ShapeConfig::max_displacement_m`].
//!
//! # Contract
//! - Input errors (empty mesh, length mismatches, indices out of range, non-finite positions, an
//!   invalid configuration) are a [`ShapeError`]. Degenerate but usable input is skipped and
//!   counted in [`ShapeUpdate`]: a non-finite or zero normal, a confidence outside [0, 1]
//!   (vertex gets no normal constraint), an edge with opposing normals, triangles with a repeated
//!   index or zero area (counted; their proper edges still take part).
//! - Returned positions are always finite.

pub mod combine;
mod energy;
pub mod hull;
pub mod integrate;
mod perturb;
mod sparse;
pub mod surface;
#[cfg(test)]
mod tests;

pub use perturb::perturb_mesh;

use super::data::{FitFlag, VertexFit};
use ellipso_model::geometry::{MeshError, TriangleMesh};
use energy::{MeshGraph, Problem, anchor_weights, check_inputs, usable_normals};
use nalgebra::{Point3, Vector3};
use sparse::{Block, BlockCsr, IDENTITY, pcg};

/// Weights and limits of the shape update.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ShapeConfig {
    /// λ_pos: weight of the anchor to the current positions (dimensionless, > 0), per unit of
    /// `a_v/D²`. Smaller trusts the normals over longer wavelengths. The default 25 equals a
    /// per-vertex weight of 0.01 on a 2 562-vertex sphere; it removes ~3.6× of smooth noise per
    /// update at any resolution while staying stable under 3° normal noise.
    pub lambda_position: f64,
    /// λ_smooth: weight of the uniform Laplacian of the displacement (dimensionless, ≥ 0).
    pub lambda_smooth: f64,
    /// σ_ref of the confidence `1 / (1 + (σ_n/σ_ref)²)`, degrees (> 0): a normal with this
    /// standard error gets half the weight of a perfect one.
    pub normal_sigma_ref_deg: f64,
    /// Conjugate-gradient iteration limit (≥ 1). Iterations grow like √vertices (≈ 160 at 2.5k,
    /// 1 350 at 164k vertices with the default weights).
    pub max_cg_iterations: u32,
    /// Conjugate-gradient stop: `‖b − A d‖ ≤ tolerance · ‖b‖` (> 0).
    pub tolerance: f64,
    /// Largest move of one vertex in one call, metres (> 0; `f64::INFINITY` disables). Guards
    /// the mesh against a bad normal batch in one outer iteration; a clamped vertex keeps its
    /// direction of motion and continues in the next outer iteration. Set it to a few times the
    /// expected scan error (default 2 mm for objects of a few centimetres).
    pub max_displacement_m: f64,
}

impl Default for ShapeConfig {
    fn default() -> Self {
        Self {
            lambda_position: 25.0,
            lambda_smooth: 0.02,
            normal_sigma_ref_deg: 2.0,
            max_cg_iterations: 3000,
            tolerance: 1e-8,
            max_displacement_m: 0.002,
        }
    }
}

/// Flags that void a vertex's refined normal for the shape update (its confidence is 0):
/// the normal is the prior or under-determined, or the solver did not converge.
pub const NORMAL_VOIDING_FLAGS: [FitFlag; 5] = [
    FitFlag::TooFewViews,
    FitFlag::UnderDetermined,
    FitFlag::Dark,
    FitFlag::GrazingOnly,
    FitFlag::NotConverged,
];

/// Whether a refined normal is a measurement the shape steps may use: no flag of
/// [`NORMAL_VOIDING_FLAGS`] and a finite, non-negative standard error (an unidentifiable normal
/// reports `f64::INFINITY`). The one rule behind [`ShapeConfig::confidence`] and
/// [`combine::combine_with_surface`].
pub fn normal_trusted(normal_std_error_deg: f64, flags: &[FitFlag]) -> bool {
    !flags.iter().any(|f| NORMAL_VOIDING_FLAGS.contains(f))
        && normal_std_error_deg.is_finite()
        && normal_std_error_deg >= 0.0
}

impl ShapeConfig {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ShapeError> {
        let bad = |field: &'static str, value: f64| Err(ShapeError::InvalidConfig { field, value });
        if !(self.lambda_position.is_finite() && self.lambda_position > 0.0) {
            return bad("lambda_position", self.lambda_position);
        }
        if !(self.lambda_smooth.is_finite() && self.lambda_smooth >= 0.0) {
            return bad("lambda_smooth", self.lambda_smooth);
        }
        if !(self.normal_sigma_ref_deg.is_finite() && self.normal_sigma_ref_deg > 0.0) {
            return bad("normal_sigma_ref_deg", self.normal_sigma_ref_deg);
        }
        if self.max_cg_iterations == 0 {
            return bad("max_cg_iterations", 0.0);
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return bad("tolerance", self.tolerance);
        }
        if self.max_displacement_m.is_nan() || self.max_displacement_m <= 0.0 {
            return bad("max_displacement_m", self.max_displacement_m);
        }
        Ok(())
    }

    /// Confidence of a refined normal: `1 / (1 + (σ_n/σ_ref)²)`, 0 when any flag in
    /// [`NORMAL_VOIDING_FLAGS`] is set or σ_n is not a finite non-negative number (an
    /// unidentifiable normal reports `f64::INFINITY`).
    pub fn confidence(&self, normal_std_error_deg: f64, flags: &[FitFlag]) -> f64 {
        if !normal_trusted(normal_std_error_deg, flags) {
            return 0.0;
        }
        // σ_ref > 0 (validated), so the ratio is finite.
        let ratio = normal_std_error_deg / self.normal_sigma_ref_deg;
        1.0 / (1.0 + ratio * ratio)
    }
}

/// Why the shape update could not run.
#[derive(Debug, thiserror::Error)]
pub enum ShapeError {
    /// No vertices or no triangles.
    #[error("shape update: the mesh is empty ({vertices} vertices, {triangles} triangles)")]
    EmptyMesh {
        /// Vertex count.
        vertices: usize,
        /// Triangle count.
        triangles: usize,
    },
    /// A per-vertex input has the wrong length.
    #[error("shape update: {what} has {got} entries for {expected} vertices")]
    LengthMismatch {
        /// Which input.
        what: &'static str,
        /// The vertex count.
        expected: usize,
        /// The input's length.
        got: usize,
    },
    /// A triangle references a vertex that does not exist.
    #[error("shape update: triangle {triangle} references vertex {vertex} of {vertices}")]
    IndexOutOfRange {
        /// Triangle index.
        triangle: usize,
        /// The offending vertex index.
        vertex: u32,
        /// The vertex count.
        vertices: usize,
    },
    /// A vertex position is NaN or infinite.
    #[error("shape update: vertex {vertex} has a non-finite position")]
    NonFinitePosition {
        /// Vertex index.
        vertex: usize,
    },
    /// A per-vertex fit names a vertex that does not exist, or a vertex twice.
    #[error("shape update: fit for vertex {vertex} ({reason}; the mesh has {vertices} vertices)")]
    BadFitVertex {
        /// The fit's vertex index.
        vertex: u32,
        /// "out of range" or "duplicate".
        reason: &'static str,
        /// The vertex count.
        vertices: usize,
    },
    /// A configuration field is out of range.
    #[error("shape update: config field {field} = {value} is out of range")]
    InvalidConfig {
        /// Field name.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// The solve produced a non-finite displacement (cannot happen with validated input; kept
    /// so that no NaN position ever leaves this module).
    #[error("shape update: the solve produced a non-finite displacement at vertex {vertex}")]
    NonFiniteSolution {
        /// Vertex index.
        vertex: usize,
    },
    /// Rebuilding the mesh failed.
    #[error("shape update: rebuilding the mesh: {0}")]
    Mesh(#[from] MeshError),
}

/// The result of one shape update.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeUpdate {
    /// New vertex positions, same order and frame as the input (always finite).
    pub positions: Vec<Point3<f64>>,
    /// RMS vertex move, metres (after clamping).
    pub rms_displacement_m: f64,
    /// Largest vertex move, metres (after clamping).
    pub max_displacement_m: f64,
    /// Conjugate-gradient iterations.
    pub cg_iterations: u32,
    /// The CG reached its tolerance.
    pub cg_converged: bool,
    /// `‖b − A d‖ / ‖b‖` of the unclamped CG solution (recomputed, not the recursive estimate).
    pub cg_relative_residual: f64,
    /// Normal misfit before: confidence-weighted RMS over constrained edges of
    /// `n̄_uv · e / ‖e‖` (the sine of the angle between the edge and the plane ⟂ n̄), 0 without
    /// constrained edges.
    pub residual_before: f64,
    /// Normal misfit after (same measure, new positions).
    pub residual_after: f64,
    /// Energy E at the current positions (m²).
    pub energy_before: f64,
    /// Energy E at the returned positions (m²); ≤ `energy_before` unless clamping intervened.
    pub energy_after: f64,
    /// Edges with a normal constraint (c_uv > 0).
    pub constrained_edges: usize,
    /// Vertices whose normal or confidence was unusable (non-finite or zero normal, confidence
    /// outside [0, 1]); they get no normal constraint.
    pub skipped_vertices: usize,
    /// Edges dropped because their end normals are 90° or more apart.
    pub skipped_edges: usize,
    /// Triangles with a repeated vertex index or zero area.
    pub degenerate_triangles: usize,
    /// Vertices whose move was clamped to `max_displacement_m`.
    pub clamped_vertices: usize,
}

/// Target normals and confidences per mesh vertex, from the per-vertex fits.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalTargets {
    /// Unit normal per vertex, world (the mesh normal where no fit exists).
    pub normals_world: Vec<[f64; 3]>,
    /// Confidence per vertex in [0, 1] (0 where no fit exists).
    pub confidence: Vec<f64>,
}

/// The normals and confidences [`refine_positions`] takes, from the solver's per-vertex fits
/// (any order, any subset of the vertices): confidence from [`ShapeConfig::confidence`];
/// vertices without a fit keep the mesh normal with confidence 0.
pub fn normal_targets(
    mesh: &TriangleMesh,
    fits: &[VertexFit],
    config: &ShapeConfig,
) -> Result<NormalTargets, ShapeError> {
    config.validate()?;
    let n = mesh.positions().len();
    let mut normals_world: Vec<[f64; 3]> = mesh.normals().iter().map(|v| (**v).into()).collect();
    let mut confidence = vec![0.0; n];
    let mut seen = vec![false; n];
    for fit in fits {
        let v = fit.vertex as usize;
        if v >= n {
            return Err(ShapeError::BadFitVertex {
                vertex: fit.vertex,
                reason: "out of range",
                vertices: n,
            });
        }
        if std::mem::replace(&mut seen[v], true) {
            return Err(ShapeError::BadFitVertex {
                vertex: fit.vertex,
                reason: "duplicate",
                vertices: n,
            });
        }
        normals_world[v] = fit.normal_world;
        confidence[v] = config.confidence(fit.normal_std_error_deg, &fit.flags);
    }
    Ok(NormalTargets {
        normals_world,
        confidence,
    })
}

/// One shape update of `mesh` towards the refined `normals_world` (one per vertex, world, need
/// not be exactly unit) weighted by `confidence` (one per vertex, in [0, 1]). See the module doc
/// for the energy and the contract.
pub fn refine_positions(
    mesh: &TriangleMesh,
    normals_world: &[[f64; 3]],
    confidence: &[f64],
    config: &ShapeConfig,
) -> Result<ShapeUpdate, ShapeError> {
    refine_vertex_positions(
        mesh.positions(),
        mesh.triangles(),
        normals_world,
        confidence,
        config,
    )
}

/// [`refine_positions`] on raw arrays (positions and counter-clockwise triangles), for callers
/// that hold no [`TriangleMesh`]; validates what `TriangleMesh::new` would.
pub fn refine_vertex_positions(
    positions: &[Point3<f64>],
    triangles: &[[u32; 3]],
    normals_world: &[[f64; 3]],
    confidence: &[f64],
    config: &ShapeConfig,
) -> Result<ShapeUpdate, ShapeError> {
    config.validate()?;
    check_inputs(
        triangles,
        &[
            ("normals_world", normals_world.len()),
            ("confidence", confidence.len()),
        ],
        &[positions],
    )?;
    let n = positions.len();
    let graph = MeshGraph::new(positions, triangles)?;
    let (normals, weights, skipped_vertices) = usable_normals(normals_world, confidence);
    let anchor = anchor_weights(positions, triangles, config.lambda_position);
    let problem = Problem::new(positions, &graph.edges, &normals, &weights, anchor, config);

    let mut a = BlockCsr::from_edges(n, &graph.edges);
    for (v, &w) in problem.anchor.iter().enumerate() {
        a.add_diagonal(v as u32, &scaled(&IDENTITY, w));
    }
    let mut b = vec![0.0; 3 * n];
    problem.add_edge_terms(&mut a, &mut b);

    let mut d = vec![0.0; 3 * n];
    let report = pcg(&a, &b, &mut d, config.max_cg_iterations, config.tolerance);
    if let Some(i) = d.iter().position(|x| !x.is_finite()) {
        return Err(ShapeError::NonFiniteSolution { vertex: i / 3 });
    }
    let clamped_vertices = clamp_moves(&mut d, config.max_displacement_m);
    let new_positions: Vec<Point3<f64>> = positions
        .iter()
        .zip(d.chunks(3))
        .map(|(p, dv)| p + Vector3::new(dv[0], dv[1], dv[2]))
        .collect();
    let moves: Vec<f64> = d
        .chunks(3)
        .map(|dv| (dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2]).sqrt())
        .collect();
    let rms_displacement_m = (moves.iter().map(|m| m * m).sum::<f64>() / n as f64).sqrt();
    let max_displacement_m = moves.iter().copied().fold(0.0, f64::max);
    Ok(ShapeUpdate {
        residual_before: problem.normal_misfit(positions),
        residual_after: problem.normal_misfit(&new_positions),
        energy_before: problem.energy(positions, &vec![0.0; 3 * n]),
        energy_after: problem.energy(positions, &d),
        positions: new_positions,
        rms_displacement_m,
        max_displacement_m,
        cg_iterations: report.iterations,
        cg_converged: report.converged,
        cg_relative_residual: report.relative_residual_end,
        constrained_edges: problem.constraints.len(),
        skipped_vertices,
        skipped_edges: problem.skipped_edges,
        degenerate_triangles: graph.degenerate_triangles,
        clamped_vertices,
    })
}

/// A copy of `mesh` with new `positions` (same triangles and region ids), vertex normals
/// recomputed from the new geometry. Region names (OBJ `usemtl`) are not carried: the simulator
/// crate keeps their setter private.
pub fn mesh_with_positions(
    mesh: &TriangleMesh,
    positions: Vec<Point3<f64>>,
) -> Result<TriangleMesh, ShapeError> {
    if positions.len() != mesh.positions().len() {
        return Err(ShapeError::LengthMismatch {
            what: "positions",
            expected: mesh.positions().len(),
            got: positions.len(),
        });
    }
    Ok(TriangleMesh::new(
        positions,
        None,
        mesh.regions().map(<[u32]>::to_vec),
        mesh.triangles().to_vec(),
    )?)
}

/// `s·m`.
fn scaled(m: &Block, s: f64) -> Block {
    m.map(|row| row.map(|x| x * s))
}

/// Shortens every per-vertex move longer than `limit_m` to `limit_m`; returns how many.
fn clamp_moves(d: &mut [f64], limit_m: f64) -> usize {
    let mut clamped = 0;
    for dv in d.chunks_mut(3) {
        let len = (dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2]).sqrt();
        if len > limit_m {
            // len > limit_m > 0, so the ratio is finite and < 1.
            let s = limit_m / len;
            dv.iter_mut().for_each(|x| *x *= s);
            clamped += 1;
        }
    }
    clamped
}
