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

use super::hull::HullField;
use super::integrate::{IntegrateConfig, Targets, integrate, project_inside, step_size};
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

/// The fractions of its solved move a vertex may be cut back to, in turn, where the whole
/// step would turn one of its triangles over. Only the corners of the triangles that fold are
/// cut back (and then the corners of any triangle the cut folds): a sliver next to a
/// silhouette can fold under a step that moves the rest of the surface as it should. Refusing
/// the whole step had ended the update after one step on the demo at 9 389 vertices (observed
/// surface 0.25 mm); shortening the whole step for one sliver applied half of every step there
/// (0.131 mm). The last fraction is 0: the corner stays exactly where it was (not even
/// projected onto the hull), so a triangle with every corner there is the last good mesh's and
/// cannot fold. Refusing the step when ⅛ still folded ended the update before its first step
/// on a 60-photo capture of the demo, where the projection onto the hull folded two slivers of
/// the unobserved underside (observed surface 0.521 mm, normals 1.80°).
pub const BACKTRACK_FRACTIONS: [f64; 4] = [0.5, 0.25, 0.125, 0.0];

fn full_step() -> f64 {
    1.0
}

/// The step `before → after` with the move of the corners of folding triangles cut back
/// ([`BACKTRACK_FRACTIONS`]) until no triangle turns over, projected inside the hull (except
/// the corners that do not move): the smallest fraction applied, the vertices cut back, the
/// positions and the vertices projected. Ends: each round raises a corner's level, and a
/// triangle with every corner at the last level is the one `before` had.
fn unfolded_step(
    triangles: &[[u32; 3]],
    before: &[Point3<f64>],
    after: &[Point3<f64>],
    hull: Option<&HullField>,
) -> Unfolded {
    let fractions = |level: u8| match level {
        0 => 1.0,
        l => BACKTRACK_FRACTIONS[usize::from(l) - 1],
    };
    let last = BACKTRACK_FRACTIONS.len() as u8;
    let mut level = vec![0u8; before.len()];
    loop {
        let mut positions: Vec<Point3<f64>> = before
            .iter()
            .zip(after)
            .zip(&level)
            .map(|((b, a), &l)| b + (a - b) * fractions(l))
            .collect();
        // Between two surfaces inside a hull that is not convex lies a surface that may leave
        // it: projected back as the solve's own result is.
        let projected = hull.map_or(0, |h| project_inside(h, &mut positions));
        for ((p, b), &l) in positions.iter_mut().zip(before).zip(&level) {
            if l == last {
                *p = *b;
            }
        }
        let folded: Vec<&[u32; 3]> = triangles
            .iter()
            .filter(|t| turns_over(before, &positions, t))
            .collect();
        if folded.is_empty() {
            let shortened = level.iter().filter(|&&l| l > 0).count();
            let deepest = level.iter().copied().max().unwrap_or(0);
            return Unfolded {
                fraction: fractions(deepest),
                shortened,
                positions,
                projected,
            };
        }
        for t in folded {
            for &v in t {
                let l = &mut level[v as usize];
                // A folded triangle has a corner below the last level (module doc).
                *l = (*l + 1).min(last);
            }
        }
    }
}

/// How far a step `before → after` takes a vertex further outside the hull than it was (or
/// than the hull's surface, for one that was inside), metres; ≤ 0 when none goes out. A vertex
/// of the input mesh that lies outside (a mesh from elsewhere, the carved mesh's own
/// extraction error, a corner held in place by [`unfolded_step`]) is not a step leaving it.
fn left_hull_by(hull: &HullField, before: &[Point3<f64>], after: &[Point3<f64>]) -> f64 {
    before
        .iter()
        .zip(after)
        .map(|(b, a)| hull.value_world(a).0 - hull.value_world(b).0.max(0.0))
        .filter(|d| !d.is_nan())
        .fold(f64::NEG_INFINITY, f64::max)
}

/// What [`unfolded_step`] applied.
struct Unfolded {
    /// The smallest fraction of a vertex's move applied.
    fraction: f64,
    /// Vertices whose move was cut back.
    shortened: usize,
    positions: Vec<Point3<f64>>,
    projected: usize,
}

/// Whether triangle `t` reverses its orientation between `before` and `after`.
fn turns_over(before: &[Point3<f64>], after: &[Point3<f64>], t: &[u32; 3]) -> bool {
    let normal = |p: &[Point3<f64>]| {
        let [a, b, c] = t.map(|i| p[i as usize]);
        (b - a).cross(&(c - a))
    };
    normal(before).dot(&normal(after)) < 0.0
}

/// Triangles whose orientation reverses between `before` and `after`.
fn turned_over(triangles: &[[u32; 3]], before: &[Point3<f64>], after: &[Point3<f64>]) -> usize {
    triangles
        .iter()
        .filter(|t| turns_over(before, after, t))
        .count()
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
                    trusted[v].is_some_and(|nv| {
                        on_silhouette(h, &mesh.positions()[v], &nv, cameras, config)
                    })
                })
                .collect(),
            None => Vec::new(),
        };
        let mut integrate_config = config.integrate.clone();
        if hull.is_none() {
            integrate_config.weights.lambda_position = config.lambda_position_without_hull;
        }
        let mut solved = integrate(
            mesh.positions(),
            mesh.triangles(),
            &Targets {
                normals_world: &targets.normals_world,
                confidence: &confidence,
                anchors: &self.anchors,
                screening: &screening,
                on_silhouette: &on_silhouette,
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
        let new_mesh = mesh_with_positions(mesh, solved.positions.clone())?;
        let misfit = |m: &TriangleMesh| {
            median_angle_deg(
                trusted
                    .iter()
                    .zip(m.normals())
                    .filter_map(|(t, nm)| t.map(|t| (t, nm.into_inner()))),
            )
        };
        let mut report = SurfaceIteration {
            iteration: self.iterations.len() + 1,
            observed: observed.iter().filter(|o| **o).count(),
            vertices: n,
            applied: false,
            rms_move_m: solved.rms_displacement_m,
            max_move_m: solved.max_displacement_m,
            normal_change_deg: self.previous_normals.as_ref().map(|prev| {
                median_angle_deg(
                    prev.iter()
                        .zip(&trusted)
                        .filter_map(|(a, b)| Some(((*a)?, (*b)?))),
                )
            }),
            misfit_before_deg: misfit(mesh),
            misfit_after_deg: misfit(&new_mesh),
            hull_active: solved.active_vertices,
            on_silhouette: 0,
            max_outside_m: solved.max_outside_m,
            cg_iterations: solved.cg_iterations,
            rounds: solved.rounds,
            clamped: solved.clamped_vertices,
            projected: solved.projected_vertices,
            step_fraction,
            shortened_vertices,
            turned_over_full_step,
            seconds: 0.0,
            stopped: None,
        };
        let left_m = hull.map_or(0.0, |h| {
            left_hull_by(h, mesh.positions(), &solved.positions)
        });
        let refused = if left_m > config.hull_tolerance_m {
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
        };
        report.on_silhouette = on_silhouette.iter().filter(|s| **s).count();
        report.seconds = started.elapsed().as_secs_f64();
        if let Some(why) = refused {
            report.stopped = Some(why);
            self.done = true;
            self.iterations.push(report);
            return Ok(None);
        }
        report.applied = true;
        if full_step_rms_m < config.converged_rms_m {
            report.stopped = Some(format!(
                "converged: the step moved {:.4} mm RMS (< {:.4} mm)",
                full_step_rms_m * 1e3,
                config.converged_rms_m * 1e3
            ));
            self.done = true;
        }
        self.previous_normals = Some(trusted);
        // After a shortened step the next one also carries what this one left out, so its
        // size is not compared with this one's (the misfit and hull tests still apply).
        self.previous_rms_m = (step_fraction == 1.0).then_some(full_step_rms_m);
        self.iterations.push(report);
        Ok(Some(new_mesh))
    }
}
