//! The surface update of the outer loop (docs/fit-shape.md "Surface update"): after each
//! per-vertex solve, the mesh moves to the surface its refined normals describe, screened
//! towards the carved mesh and kept inside the visual hull and above the board
//! ([`super::integrate`]); every step is checked, reported and, when it goes wrong, refused.
//!
//! Contract:
//! - [`SurfaceState::new`] remembers the input mesh's positions as the anchors (the carved
//!   hull is an upper bound of the surface: the screening presses outward, the hull stops it
//!   where the silhouettes touch the object).
//! - [`SurfaceState::step`] takes the mesh, the solve's per-vertex fits and which vertices the
//!   views observe (a kept sample; [`observed_vertices`]). Unobserved vertices (the underside,
//!   the contact with the board) get neither a normal constraint nor screening: they follow the
//!   displacement of their observed neighbours, and the board plane under the hull closes the
//!   object from below.
//! - Each step is reported ([`SurfaceIteration`]): surface change (RMS and largest move), the
//!   change of the refined normals since the previous iteration, the misfit between refined
//!   normals and the mesh before and after, the hull's hold. A step is **refused** — the mesh
//!   stays the last good one and no later step runs — when it diverges (its RMS move grows by
//!   more than [`SurfaceConfig::divergence_ratio`] over the previous step's, or it increases the
//!   median angle between refined normals and mesh by more than
//!   [`SurfaceConfig::misfit_increase_deg`]), or when a vertex would end further outside the
//!   hull than it was by more than [`SurfaceConfig::hull_tolerance_m`]. The reason is kept in
//!   words ([`SurfaceIteration::stopped`]).
//! - A step never turns a triangle over: where the full step would, the folding triangles'
//!   corners move only part of the way ([`BACKTRACK_FRACTIONS`], down to not at all: such a
//!   corner stays exactly where the last good mesh had it), every other vertex the whole step,
//!   and the report says so.
//! - Once a step moves less than [`SurfaceConfig::converged_rms_m`] (RMS) the surface has
//!   converged and no later step runs.
//! - Without a hull (a caller that has none) the screening is
//!   [`SurfaceConfig::lambda_position_without_hull`]: the positions then hold the long
//!   wavelengths, as in the one-call update.
//! - Connectivity is kept, so per-vertex results carry over by index.

use ellipso_model::geometry::TriangleMesh;
use nalgebra::{Point3, Vector3};

#[cfg(test)]
mod tests;
mod unfold;

pub use unfold::BACKTRACK_FRACTIONS;
use unfold::{left_hull_by, turned_over, unfolded_step};

use super::hull::HullField;
use super::integrate::{IntegrateConfig, Integrated, Targets, integrate, step_size};
use super::{ShapeError, mesh_with_positions};
use crate::data::{SampleSet, VertexFit};

/// Settings of the surface update.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SurfaceConfig {
    /// The integration (screening, smoothness, hull weight, per-step move clamp).
    pub integrate: IntegrateConfig,
    /// A step whose RMS move is below this has converged, metres.
    pub converged_rms_m: f64,
    /// A step whose RMS move exceeds this multiple of the previous step's diverges.
    pub divergence_ratio: f64,
    /// A vertex that ends a step further outside the hull than this, beyond where it was
    /// before the step, has left it, metres.
    pub hull_tolerance_m: f64,
    /// λ_pos without a hull: with no silhouettes the positions are the only position
    /// information, so they hold the long wavelengths as in the one-call update (its default).
    pub lambda_position_without_hull: f64,
    /// A view sees a vertex on its silhouette when its ray runs within this angle of the
    /// vertex's tangent plane, degrees.
    pub silhouette_angle_deg: f64,
    /// The hull's surface normal and the refined normal of a vertex on a silhouette agree
    /// within this, degrees.
    pub silhouette_normal_deg: f64,
    /// A step that increases the median angle between the refined normals and the mesh
    /// normals by more than this diverges, degrees.
    pub misfit_increase_deg: f64,
}

impl Default for SurfaceConfig {
    fn default() -> Self {
        Self {
            integrate: IntegrateConfig::default(),
            converged_rms_m: 2e-5,
            divergence_ratio: 1.5,
            hull_tolerance_m: 5e-5,
            misfit_increase_deg: 0.5,
            lambda_position_without_hull: 25.0,
            silhouette_angle_deg: 3.0,
            silhouette_normal_deg: 3.0,
        }
    }
}

/// What one surface step did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SurfaceIteration {
    /// Outer iteration (1-based).
    pub iteration: usize,
    /// Vertices observed (a kept sample) / all vertices.
    pub observed: usize,
    /// All vertices.
    pub vertices: usize,
    /// Whether the step was applied.
    pub applied: bool,
    /// RMS vertex move of the step, metres.
    pub rms_move_m: f64,
    /// Largest vertex move, metres.
    pub max_move_m: f64,
    /// Median angle between this iteration's refined normals and the previous iteration's,
    /// degrees, over vertices with a trusted normal in both (`None` on the first step).
    pub normal_change_deg: Option<f64>,
    /// Median angle between the refined normals and the mesh normals before the step, degrees.
    pub misfit_before_deg: f64,
    /// The same after the step.
    pub misfit_after_deg: f64,
    /// Vertices held by the hull or the board.
    pub hull_active: usize,
    /// Vertices on a silhouette (held from both sides).
    pub on_silhouette: usize,
    /// Largest hull value over the vertices after the step, metres (≤ 0 inside).
    pub max_outside_m: f64,
    /// CG iterations (all active-set rounds).
    pub cg_iterations: u32,
    /// Active-set rounds.
    pub rounds: usize,
    /// Vertices whose move was clamped.
    pub clamped: usize,
    /// Vertices the solve left outside the hull, projected onto it.
    #[serde(default)]
    pub projected: usize,
    /// The smallest fraction of its solved move a vertex was given: 1, or less where the full
    /// step would have turned triangles over ([`BACKTRACK_FRACTIONS`]).
    #[serde(default = "full_step")]
    pub step_fraction: f64,
    /// Vertices whose move was cut back so that no triangle turns over (the others moved the
    /// whole solved step).
    #[serde(default)]
    pub shortened_vertices: usize,
    /// Triangles the full step would have turned over (0 when none would).
    #[serde(default)]
    pub turned_over_full_step: usize,
    /// Seconds.
    pub seconds: f64,
    /// Why the update stopped here (refused step or convergence), in words.
    pub stopped: Option<String>,
}

impl SurfaceIteration {
    /// One line for progress output.
    pub fn describe(&self) -> String {
        let mut s = format!(
            "surface step {}: moved {:.3} mm RMS ({:.3} mm max), normals vs mesh {:.2}° → {:.2}°",
            self.iteration,
            self.rms_move_m * 1e3,
            self.max_move_m * 1e3,
            self.misfit_before_deg,
            self.misfit_after_deg
        );
        if let Some(c) = self.normal_change_deg {
            s += &format!(", normals changed {c:.2}°");
        }
        s += &format!(
            ", {} of {} vertices observed, {} held by the hull ({} on a silhouette)",
            self.observed, self.vertices, self.hull_active, self.on_silhouette
        );
        if self.projected > 0 {
            s += &format!(", {} projected onto it", self.projected);
        }
        if self.turned_over_full_step > 0 && self.applied {
            let down_to = if self.step_fraction > 0.0 {
                format!("down to {:.1} %", self.step_fraction * 100.0)
            } else {
                "some not at all".into()
            };
            s += &format!(
                ", {} vertices moved only part of the way, {down_to} (the whole step would turn \
                 {} triangles over)",
                self.shortened_vertices, self.turned_over_full_step
            );
        }
        if let Some(why) = &self.stopped {
            s += &format!(" — {why}");
        }
        s
    }
}

/// The surface update's state over the outer loop.
#[derive(Clone, Debug)]
pub struct SurfaceState {
    anchors: Vec<Point3<f64>>,
    previous_normals: Option<Vec<Option<Vector3<f64>>>>,
    previous_rms_m: Option<f64>,
    done: bool,
    /// One entry per step.
    pub iterations: Vec<SurfaceIteration>,
}

/// Which vertices of `set` the views observe: at least one kept sample.
pub fn observed_vertices(set: &SampleSet, vertices: usize) -> Vec<bool> {
    let mut observed = vec![false; vertices];
    for v in &set.vertices {
        if let Some(o) = observed.get_mut(v.vertex as usize) {
            *o = !v.samples.is_empty();
        }
    }
    observed
}

/// Median of the angles between `a[i]` and `b[i]` where both exist, degrees (0 without any).
fn median_angle_deg(pairs: impl Iterator<Item = (Vector3<f64>, Vector3<f64>)>) -> f64 {
    let mut angles: Vec<f64> = pairs
        .map(|(a, b)| ellipso_model::geometry::angle_between_deg(&a, &b))
        .filter(|x| x.is_finite())
        .collect();
    if angles.is_empty() {
        return 0.0;
    }
    ellipso_model::stats::median(&mut angles)
}

/// Whether the hull touches the surface at `p` (refined normal `n`): `p` lies on the hull's
/// surface (within half a grid spacing), the hull's normal there agrees with `n`, and at least
/// [`HullField::votes`] cameras look past `p` along the tangent plane with nothing of the hull
/// on their rays on either side of `p` — silhouette rays. A hull of k votes is the k-th
/// largest of the views' silhouette distances, so it touches the object only where k views'
/// silhouettes do; where fewer are tangent it stands outside by what the k-th view leaves
/// (measured on the glass sphere's cap, which only the highest views' silhouettes reach:
/// vertices held with one tangent view stood 0.6 mm outside and held the cap 0.57 mm loose).
fn on_silhouette(
    hull: &HullField,
    p: &Point3<f64>,
    n: &Vector3<f64>,
    cameras: &[Point3<f64>],
    config: &SurfaceConfig,
) -> bool {
    let h = hull.grid.spacing_m;
    let (value, grad) = hull.value_world(p);
    if value.abs() > 0.5 * h || grad.norm() < 1e-9 {
        return false;
    }
    let n = n.normalize();
    if grad.normalize().dot(&n) < config.silhouette_normal_deg.to_radians().cos() {
        return false;
    }
    let tangent = config.silhouette_angle_deg.to_radians().sin();
    let tangent_views = cameras.iter().filter(|&c| {
        let r = (c - p).normalize();
        r.dot(&n).abs() < tangent
            && [3.0, 6.0, 12.0, 24.0, 48.0]
                .iter()
                .flat_map(|t| [t * h, -t * h])
                .all(|t| {
                    hull.silhouette_volume(
                        hull.world_from_volume
                            .inverse_transform_point(&(p + r * t))
                            .coords,
                    )
                    .0 > 0.0
                })
    });
    tangent_views.take(hull.votes).count() >= hull.votes
}

fn full_step() -> f64 {
    1.0
}

impl SurfaceState {
    /// The state for a fit starting on `mesh` (its positions are the anchors).
    pub fn new(mesh: &TriangleMesh) -> Self {
        Self {
            anchors: mesh.positions().to_vec(),
            previous_normals: None,
            previous_rms_m: None,
            done: false,
            iterations: Vec::new(),
        }
    }

    /// Whether the update has converged or was stopped (no later step runs).
    pub fn done(&self) -> bool {
        self.done
    }

    /// Why the update stopped, if it did before converging.
    pub fn stopped(&self) -> Option<&str> {
        self.iterations
            .iter()
            .rev()
            .find_map(|i| i.stopped.as_deref())
    }

    /// One step (module contract): the new mesh, or `None` when the step is refused or the
    /// update is done.
    pub fn step(
        &mut self,
        mesh: &TriangleMesh,
        fits: &[VertexFit],
        observed: &[bool],
        cameras: &[Point3<f64>],
        hull: Option<&HullField>,
        config: &SurfaceConfig,
    ) -> Result<Option<TriangleMesh>, ShapeError> {
        if self.done {
            return Ok(None);
        }
        let started = std::time::Instant::now();
        let n = mesh.positions().len();
        if observed.len() != n || self.anchors.len() != n {
            return Err(ShapeError::LengthMismatch {
                what: "observed vertices",
                expected: n,
                got: observed.len().min(self.anchors.len()),
            });
        }
        let inputs = step_inputs(mesh, fits, observed, cameras, hull, config)?;
        let step = self.solve(mesh, &inputs, hull, config)?;
        let new_mesh = mesh_with_positions(mesh, step.solved.positions.clone())?;
        let mut report = self.report(mesh, &new_mesh, observed, &inputs.trusted, &step);
        let refused = self.refusal(mesh, hull, &step, &report, config);
        report.on_silhouette = inputs.on_silhouette.iter().filter(|s| **s).count();
        report.seconds = started.elapsed().as_secs_f64();
        if let Some(why) = refused {
            report.stopped = Some(why);
            self.done = true;
            self.iterations.push(report);
            return Ok(None);
        }
        report.applied = true;
        if step.full_step_rms_m < config.converged_rms_m {
            report.stopped = Some(format!(
                "converged: the step moved {:.4} mm RMS (< {:.4} mm)",
                step.full_step_rms_m * 1e3,
                config.converged_rms_m * 1e3
            ));
            self.done = true;
        }
        self.previous_normals = Some(inputs.trusted);
        // After a shortened step the next one also carries what this one left out, so its
        // size is not compared with this one's (the misfit and hull tests still apply).
        self.previous_rms_m = (step.step_fraction == 1.0).then_some(step.full_step_rms_m);
        self.iterations.push(report);
        Ok(Some(new_mesh))
    }

    /// The screened integration towards `inputs`' normals, cut back where the whole step would
    /// turn triangles over ([`unfolded_step`]).
    fn solve(
        &self,
        mesh: &TriangleMesh,
        inputs: &StepInputs,
        hull: Option<&HullField>,
        config: &SurfaceConfig,
    ) -> Result<SolvedStep, ShapeError> {
        let mut integrate_config = config.integrate.clone();
        if hull.is_none() {
            integrate_config.weights.lambda_position = config.lambda_position_without_hull;
        }
        let mut solved = integrate(
            mesh.positions(),
            mesh.triangles(),
            &Targets {
                normals_world: &inputs.normals_world,
                confidence: &inputs.confidence,
                anchors: &self.anchors,
                screening: &inputs.screening,
                on_silhouette: &inputs.on_silhouette,
            },
            hull,
            &integrate_config,
        )?;
        // The divergence and convergence tests judge the whole solved step.
        let full_step_rms_m = solved.rms_displacement_m;
        let turned_over_full_step =
            turned_over(mesh.triangles(), mesh.positions(), &solved.positions);
        let mut step_fraction = 1.0;
        let mut shortened_vertices = 0;
        if turned_over_full_step > 0 {
            let u = unfolded_step(mesh.triangles(), mesh.positions(), &solved.positions, hull);
            let size = step_size(mesh.positions(), &u.positions, hull);
            solved.projected_vertices = u.projected;
            solved.rms_displacement_m = size.rms_m;
            solved.max_displacement_m = size.max_m;
            solved.max_outside_m = size.max_outside_m;
            solved.positions = u.positions;
            step_fraction = u.fraction;
            shortened_vertices = u.shortened;
        }
        Ok(SolvedStep {
            solved,
            full_step_rms_m,
            turned_over_full_step,
            step_fraction,
            shortened_vertices,
        })
    }

    /// The step's report, not yet applied, stopped or timed (`on_silhouette` still 0).
    fn report(
        &self,
        mesh: &TriangleMesh,
        new_mesh: &TriangleMesh,
        observed: &[bool],
        trusted: &[Option<Vector3<f64>>],
        step: &SolvedStep,
    ) -> SurfaceIteration {
        let solved = &step.solved;
        let misfit = |m: &TriangleMesh| {
            median_angle_deg(
                trusted
                    .iter()
                    .zip(m.normals())
                    .filter_map(|(t, nm)| t.map(|t| (t, nm.into_inner()))),
            )
        };
        SurfaceIteration {
            iteration: self.iterations.len() + 1,
            observed: observed.iter().filter(|o| **o).count(),
            vertices: mesh.positions().len(),
            applied: false,
            rms_move_m: solved.rms_displacement_m,
            max_move_m: solved.max_displacement_m,
            normal_change_deg: self.previous_normals.as_ref().map(|prev| {
                median_angle_deg(
                    prev.iter()
                        .zip(trusted)
                        .filter_map(|(a, b)| Some(((*a)?, (*b)?))),
                )
            }),
            misfit_before_deg: misfit(mesh),
            misfit_after_deg: misfit(new_mesh),
            hull_active: solved.active_vertices,
            on_silhouette: 0,
            max_outside_m: solved.max_outside_m,
            cg_iterations: solved.cg_iterations,
            rounds: solved.rounds,
            clamped: solved.clamped_vertices,
            projected: solved.projected_vertices,
            step_fraction: step.step_fraction,
            shortened_vertices: step.shortened_vertices,
            turned_over_full_step: step.turned_over_full_step,
            seconds: 0.0,
            stopped: None,
        }
    }

    /// Why the step is refused (module contract: it leaves the hull, or diverges in size or in
    /// misfit), in words; `None` when it may be applied.
    fn refusal(
        &self,
        mesh: &TriangleMesh,
        hull: Option<&HullField>,
        step: &SolvedStep,
        report: &SurfaceIteration,
        config: &SurfaceConfig,
    ) -> Option<String> {
        let full_step_rms_m = step.full_step_rms_m;
        let left_m = hull.map_or(0.0, |h| {
            left_hull_by(h, mesh.positions(), &step.solved.positions)
        });
        if left_m > config.hull_tolerance_m {
            Some(format!(
                "stopped: the surface would leave the visual hull by {:.3} mm (tolerance {:.3} mm); \
                 the last good mesh is kept",
                left_m * 1e3,
                config.hull_tolerance_m * 1e3
            ))
        } else if let Some(prev) = self
            .previous_rms_m
            .filter(|p| full_step_rms_m > config.divergence_ratio * p.max(config.converged_rms_m))
        {
            Some(format!(
                "stopped: diverging — this step would move the surface {:.3} mm RMS after {:.3} mm \
                 in the previous one; the last good mesh is kept",
                full_step_rms_m * 1e3,
                prev * 1e3
            ))
        } else if report.misfit_after_deg > report.misfit_before_deg + config.misfit_increase_deg {
            Some(format!(
                "stopped: diverging — the step would turn the surface away from the refined \
                 normals (median angle {:.2}° → {:.2}°); the last good mesh is kept",
                report.misfit_before_deg, report.misfit_after_deg
            ))
        } else {
            None
        }
    }
}

/// What a step integrates towards: the refined normals and their confidence (0 where no view
/// observes the vertex), the screening (observed vertices only), the normals trusted (confidence
/// above 0) and the vertices held on a silhouette (empty without a hull).
struct StepInputs {
    normals_world: Vec<[f64; 3]>,
    confidence: Vec<f64>,
    screening: Vec<f64>,
    trusted: Vec<Option<Vector3<f64>>>,
    on_silhouette: Vec<bool>,
}

/// The [`StepInputs`] of a step on `mesh` from the solve's `fits`.
fn step_inputs(
    mesh: &TriangleMesh,
    fits: &[VertexFit],
    observed: &[bool],
    cameras: &[Point3<f64>],
    hull: Option<&HullField>,
    config: &SurfaceConfig,
) -> Result<StepInputs, ShapeError> {
    let n = mesh.positions().len();
    let targets = super::normal_targets(mesh, fits, &config.integrate.weights)?;
    let mut confidence = targets.confidence;
    for (c, o) in confidence.iter_mut().zip(observed) {
        if !o {
            *c = 0.0;
        }
    }
    let screening: Vec<f64> = observed
        .iter()
        .map(|&o| if o { 1.0 } else { 0.0 })
        .collect();
    let trusted: Vec<Option<Vector3<f64>>> = (0..n)
        .map(|v| (confidence[v] > 0.0).then(|| Vector3::from(targets.normals_world[v])))
        .collect();
    let on_silhouette: Vec<bool> = match hull {
        Some(h) => (0..n)
            .map(|v| {
                trusted[v]
                    .is_some_and(|nv| on_silhouette(h, &mesh.positions()[v], &nv, cameras, config))
            })
            .collect(),
        None => Vec::new(),
    };
    Ok(StepInputs {
        normals_world: targets.normals_world,
        confidence,
        screening,
        trusted,
        on_silhouette,
    })
}

/// The solved step: the integration's result (positions and sizes after any cut-back), the
/// whole solved step's RMS move, the triangles it would turn over, and the cut-back applied.
struct SolvedStep {
    solved: Integrated,
    full_step_rms_m: f64,
    turned_over_full_step: usize,
    step_fraction: f64,
    shortened_vertices: usize,
}
