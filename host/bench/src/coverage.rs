//! What a fit covers of the surface its views see, and how well, judged against the simulator's
//! truth: every accuracy figure beside the share of the visible surface it stands for.
//!
//! Contract:
//! - **Visible** is decided from the truth's geometry alone, never from what a gate kept: a
//!   fitted vertex's closest point on the true surface ([`crate::truth_map::truth_at`]) is seen
//!   by a fitted frame when, at the frame's *true* pose, it projects inside the image, its true
//!   normal faces the camera within the grazing cut-off the fit uses, the segment to the camera
//!   crosses no other part of the true surface, and the flash lights it (facing the flash, the
//!   segment to the flash unblocked). [`visible_frames`] counts those frames per vertex; a
//!   vertex is visible when at least one frame sees it ([`VISIBLE_MIN_FRAMES`]).
//! - **Full parameter set**: the vertex's flags let every output report all its parameters and
//!   its η (`Identifiable::of_mask`). Of those, **from material** are the vertices whose
//!   parameters the fit took from their material (`FitFlag::FromMaterial`), **own** the rest.
//! - **Per material** (the truth's): visible vertices, how many of them have a full set (own and
//!   from material apart) and the coverage (full set / visible); over the visible vertices with
//!   a full set: the median signed η error (the paper's measure), the 90th percentile of the
//!   per-vertex |η error|, the median normal error; and the **σ calibration**: the share of those
//!   vertices whose true error is within their reported 1σ, for η, the normal and ρd (each RGB
//!   channel a case), own and from-material vertices apart.
//! - A normal's reported σ is the RMS angle of its two tangent components (`fit::solve`), so an
//!   honest normal σ holds 1 − e⁻¹ = 63 % of its errors within 1σ, η and ρd (one Gaussian
//!   component each) 68 %.

use ellipso_fit::data::{FitFlag, Identifiable};
use ellipso_fit::export::ply::FitVertex;
use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::{Intersect, Ray, TriangleMesh};
use ellipso_model::rig::FlashSpec;
use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use crate::truth_map::VertexTruth;

mod session_fit;

pub use session_fit::{VertexRow, score_fit_dir, score_fit_vertices, score_session_fit};

/// Frames that must see a vertex for it to count as visible: one — a surface any fitted frame
/// sees lit is surface the user photographed, and the result owes it a value.
pub const VISIBLE_MIN_FRAMES: u32 = 1;

/// Relative margin at both ends of a visibility segment: a ray ending on the true surface must
/// not be stopped by the triangle it ends on (0.5 µm at 0.5 m, far below a pixel's footprint).
const SEGMENT_EPS: f64 = 1e-6;

/// Per point (`closest_world`, `normal_world`), the number of `poses` (`world_from_camera`) that
/// see it lit (module doc), against `surface` (the true mesh).
pub fn visible_frames(
    surface: &TriangleMesh,
    points: &[([f64; 3], [f64; 3])],
    camera: &CameraModel,
    flash: &FlashSpec,
    poses: &[Isometry3<f64>],
    grazing_cutoff_deg: f64,
) -> Vec<u32> {
    let cos_cutoff = grazing_cutoff_deg.to_radians().cos();
    let rigs: Vec<(Isometry3<f64>, Point3<f64>, Point3<f64>)> = poses
        .iter()
        .map(|p| {
            (
                p.inverse(),
                Point3::from(p.translation.vector),
                flash.position_world(p),
            )
        })
        .collect();
    let blocked = |from: &Point3<f64>, to: &Point3<f64>| {
        surface.occluded(&Ray::new(*from, to - from), SEGMENT_EPS, 1.0 - SEGMENT_EPS)
    };
    points
        .par_iter()
        .map(|(p, n)| {
            let p = Point3::from(*p);
            let n = Vector3::from(*n);
            rigs.iter()
                .filter(|(camera_from_world, centre, light)| {
                    let Some(pixel) = camera.project(&(camera_from_world * p)) else {
                        return false;
                    };
                    if !camera.contains_pixel(pixel) {
                        return false;
                    }
                    let to_camera = (centre - p).normalize();
                    if n.dot(&to_camera) < cos_cutoff || n.dot(&(light - p)) <= 0.0 {
                        return false;
                    }
                    !blocked(centre, &p) && !blocked(&p, light)
                })
                .count() as u32
        })
        .collect()
}

/// The share of cases within 1σ, own-fit and from-material vertices apart (NaN: no case).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct SigmaCalibration {
    /// Own-fit vertices: fraction of |error| ≤ σ.
    pub own: f64,
    /// Cases counted (own).
    pub own_cases: usize,
    /// From-material vertices: fraction of |error| ≤ σ.
    pub from_material: f64,
    /// Cases counted (from material).
    pub from_material_cases: usize,
}

/// One material's coverage and accuracy.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MaterialCoverage {
    /// Material name (the scene's).
    pub name: String,
    /// True η.
    pub eta_true: f64,
    /// Fitted vertices whose true point is visible.
    pub visible: usize,
    /// Of those, with a full parameter set.
    pub full_set: usize,
    /// Of those, from their material's values.
    pub from_material: usize,
    /// `full_set / visible` (NaN: none visible).
    pub coverage: f64,
    /// Median signed η error over the visible full-set vertices, %.
    pub eta_error_pct: f64,
    /// 90th percentile of the per-vertex |η error| over the same, %.
    pub eta_vertex_p90_pct: f64,
    /// Median normal error over the same, degrees.
    pub normal_median_deg: f64,
}

/// A fit's coverage and accuracy against the truth (module doc).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CoverageScores {
    /// Fitted vertices.
    pub vertices: usize,
    /// Of those, visible.
    pub visible: usize,
    /// Visible with a full parameter set.
    pub full_set: usize,
    /// Of those, from their material's values.
    pub from_material: usize,
    /// `full_set / visible`.
    pub coverage_visible: f64,
    /// Smallest per-material coverage.
    pub coverage_material_min: f64,
    /// Per material.
    pub materials: Vec<MaterialCoverage>,
    /// Mean over materials of |per-material η error|, %.
    pub eta_material_mean_pct: f64,
    /// Largest |per-material η error|, %.
    pub eta_material_max_pct: f64,
    /// Median normal error over the visible full-set vertices, degrees.
    pub normal_median_deg: f64,
    /// σ calibration of η.
    pub sigma_eta: SigmaCalibration,
    /// σ calibration of the normal (expected 63 %, module doc).
    pub sigma_normal: SigmaCalibration,
    /// σ calibration of ρd (every channel a case).
    pub sigma_rho_d: SigmaCalibration,
}

fn median(mut v: Vec<f64>) -> f64 {
    ellipso_model::stats::median(&mut v)
}

fn percentile(mut v: Vec<f64>, p: f64) -> f64 {
    ellipso_model::stats::percentile(&mut v, p)
}

fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    ellipso_model::geometry::angle_between_deg(&Vector3::from(a), &Vector3::from(b))
}

/// Counts of (within 1σ, cases) for own and from-material vertices.
#[derive(Default)]
struct Tally {
    own: (usize, usize),
    material: (usize, usize),
}

impl Tally {
    fn add(&mut self, from_material: bool, error: f64, sigma: f64) {
        if !error.is_finite() || !sigma.is_finite() {
            return;
        }
        let t = if from_material {
            &mut self.material
        } else {
            &mut self.own
        };
        t.1 += 1;
        if error.abs() <= sigma {
            t.0 += 1;
        }
    }

    fn calibration(&self) -> SigmaCalibration {
        let frac = |(k, n): (usize, usize)| {
            if n == 0 {
                f64::NAN
            } else {
                k as f64 / n as f64
            }
        };
        SigmaCalibration {
            own: frac(self.own),
            own_cases: self.own.1,
            from_material: frac(self.material),
            from_material_cases: self.material.1,
        }
    }
}

/// Scores `fit` (the vertices of a `fit.ply`) against `truth` (one entry per vertex) and the
/// per-vertex visible frame counts `visible` (module doc); `names` are the truth's materials,
/// `colour` whether the sensor resolves colour (else ρd is scored against the grey mean).
pub fn score(
    fit: &[FitVertex],
    truth: &[Option<VertexTruth>],
    visible: &[u32],
    names: &[String],
    colour: bool,
) -> CoverageScores {
    let from_material_bit = FitFlag::FromMaterial.bit();
    let mut out = CoverageScores {
        vertices: fit.len(),
        ..Default::default()
    };
    let mut tally_eta = Tally::default();
    let mut tally_normal = Tally::default();
    let mut tally_rho_d = Tally::default();
    let mut normal_errors = Vec::new();
    for (m, name) in names.iter().enumerate() {
        let mut mc = MaterialCoverage {
            name: name.clone(),
            eta_true: f64::NAN,
            ..Default::default()
        };
        let mut eta_err = Vec::new();
        let mut normal_err = Vec::new();
        for ((f, t), &seen) in fit.iter().zip(truth).zip(visible) {
            let Some(t) = t.as_ref().filter(|t| t.material == m) else {
                continue;
            };
            mc.eta_true = t.params.eta;
            if seen < VISIBLE_MIN_FRAMES {
                continue;
            }
            mc.visible += 1;
            let id = Identifiable::of_mask(f.flags);
            if !(id.vertex && id.eta) {
                continue;
            }
            mc.full_set += 1;
            let from_material = f.flags & from_material_bit != 0;
            mc.from_material += usize::from(from_material);
            let e = 100.0 * (f64::from(f.params[0]) - t.params.eta) / t.params.eta;
            eta_err.push(e);
            tally_eta.add(
                from_material,
                f64::from(f.params[0]) - t.params.eta,
                f64::from(f.std_error[0]),
            );
            let normal = f.normal.map(f64::from);
            let a = angle_deg(normal, t.normal_world);
            normal_err.push(a);
            tally_normal.add(from_material, a, f64::from(f.normal_std_deg));
            let grey = t.params.rho_d.iter().sum::<f64>() / 3.0;
            for c in 0..3 {
                let truth_c = if colour { t.params.rho_d[c] } else { grey };
                tally_rho_d.add(
                    from_material,
                    f64::from(f.params[7 + c]) - truth_c,
                    f64::from(f.std_error[7 + c]),
                );
            }
        }
        if mc.eta_true.is_nan() {
            // No fitted vertex of this material at all.
            continue;
        }
        mc.coverage = if mc.visible == 0 {
            f64::NAN
        } else {
            mc.full_set as f64 / mc.visible as f64
        };
        mc.eta_vertex_p90_pct = percentile(eta_err.iter().map(|e| e.abs()).collect(), 0.9);
        mc.eta_error_pct = median(eta_err);
        mc.normal_median_deg = median(normal_err.clone());
        normal_errors.extend(normal_err);
        out.visible += mc.visible;
        out.full_set += mc.full_set;
        out.from_material += mc.from_material;
        out.materials.push(mc);
    }
    out.coverage_visible = if out.visible == 0 {
        f64::NAN
    } else {
        out.full_set as f64 / out.visible as f64
    };
    let seen: Vec<&MaterialCoverage> = out.materials.iter().filter(|m| m.visible > 0).collect();
    out.coverage_material_min = seen
        .iter()
        .map(|m| m.coverage)
        .fold(f64::NAN, |a, b| if a.is_nan() { b } else { a.min(b) });
    let errors: Vec<f64> = seen
        .iter()
        .map(|m| m.eta_error_pct.abs())
        .filter(|e| e.is_finite())
        .collect();
    out.eta_material_mean_pct = if errors.is_empty() {
        f64::NAN
    } else {
        errors.iter().sum::<f64>() / errors.len() as f64
    };
    out.eta_material_max_pct = errors.iter().copied().fold(f64::NAN, f64::max);
    out.normal_median_deg = median(normal_errors);
    out.sigma_eta = tally_eta.calibration();
    out.sigma_normal = tally_normal.calibration();
    out.sigma_rho_d = tally_rho_d.calibration();
    out
}

/// The scores as text lines: one per material, then the totals and the σ calibration.
pub fn describe(s: &CoverageScores) -> Vec<String> {
    let mut lines = Vec::new();
    for m in &s.materials {
        lines.push(format!(
            "  {:<16} η {:+.2} % (p90 |err| {:.2} %) · normals {:.2}° · coverage {:.3} ({} of {} \
             visible vertices, {} from the material)",
            m.name,
            m.eta_error_pct,
            m.eta_vertex_p90_pct,
            m.normal_median_deg,
            m.coverage,
            m.full_set,
            m.visible,
            m.from_material
        ));
    }
    lines.push(format!(
        "  all              coverage {:.3} of {} visible vertices (lowest material {:.3}); η \
         per material mean {:.2} %, max {:.2} %; normals {:.2}°",
        s.coverage_visible,
        s.visible,
        s.coverage_material_min,
        s.eta_material_mean_pct,
        s.eta_material_max_pct,
        s.normal_median_deg
    ));
    let cal = |c: &SigmaCalibration| {
        format!(
            "own {:.2} ({}), from material {:.2} ({})",
            c.own, c.own_cases, c.from_material, c.from_material_cases
        )
    };
    lines.push(format!(
        "  within 1σ       η {} · normal {} · ρd {}",
        cal(&s.sigma_eta),
        cal(&s.sigma_normal),
        cal(&s.sigma_rho_d)
    ));
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::camera::{CameraModel, Intrinsics};
    use ellipso_model::geometry::procedural::icosphere;
    use nalgebra::{Point3, Translation3, UnitQuaternion};

    fn sphere(radius: f64) -> TriangleMesh {
        let (dirs, faces) = icosphere(3);
        let pos = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * radius))
            .collect();
        TriangleMesh::new(pos, None, None, faces).unwrap()
    }

    /// A camera 0.5 m up the +z axis looking down (OpenCV axes: z forward = −z world).
    fn looking_down() -> Isometry3<f64> {
        let rotation = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.5), rotation)
    }

    #[test]
    fn only_the_lit_facing_half_of_a_sphere_is_visible() {
        let mesh = sphere(0.05);
        let camera = CameraModel::pinhole(
            640,
            480,
            Intrinsics {
                fx: 800.0,
                fy: 800.0,
                cx: 319.5,
                cy: 239.5,
            },
        );
        let flash = FlashSpec::default();
        let points: Vec<([f64; 3], [f64; 3])> = [
            ([0.0, 0.0, 0.05], [0.0, 0.0, 1.0]),
            ([0.0, 0.0, -0.05], [0.0, 0.0, -1.0]),
            // 79.5° from the pole is ≈ 85.2° from the ray to the camera 0.5 m up (perspective):
            // beyond an 80° cut-off, inside an 89° one (asserted below).
            (
                [
                    0.05 * 79.5f64.to_radians().sin(),
                    0.0,
                    0.05 * 79.5f64.to_radians().cos(),
                ],
                [79.5f64.to_radians().sin(), 0.0, 79.5f64.to_radians().cos()],
            ),
        ]
        .to_vec();
        let (p, n) = (Vector3::from(points[2].0), Vector3::from(points[2].1));
        let to_camera = Vector3::new(0.0, 0.0, 0.5) - p;
        let view_deg = n.angle(&to_camera).to_degrees();
        assert!((84.0..86.0).contains(&view_deg), "{view_deg}");
        let poses = [looking_down()];
        let v = visible_frames(&mesh, &points, &camera, &flash, &poses, 80.0);
        assert_eq!(v, vec![1, 0, 0]);
        let v = visible_frames(&mesh, &points, &camera, &flash, &poses, 89.0);
        assert_eq!(v[2], 1);
    }

    #[test]
    fn coverage_counts_visible_vertices_without_a_full_set() {
        let truth = VertexTruth {
            material: 0,
            params: ellipso_model::optics::pbrdf::PbrdfParams {
                eta: 1.5,
                sigma_s: 0.1,
                sigma_ss: 0.2,
                rho_s: 1.0,
                rho_ss: [0.1; 3],
                rho_d: [0.5; 3],
            },
            normal_world: [0.0, 0.0, 1.0],
            closest_world: [0.0; 3],
            distance_m: 0.0,
            signed_distance_m: 0.0,
        };
        let vertex = |eta: f32, flags: u32| FitVertex {
            position: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            params: [eta, 0.1, 0.2, 1.0, 0.1, 0.1, 0.1, 0.5, 0.5, 0.5],
            std_error: [0.01; 10],
            normal_std_deg: 1.0,
            samples: 20,
            flags,
            material: None,
        };
        let fit = vec![
            vertex(1.505, 0),
            vertex(1.52, 0),
            vertex(1.5, FitFlag::TooFewViews.bit()),
            vertex(1.5, FitFlag::FromMaterial.bit()),
            vertex(1.0, FitFlag::TooFewViews.bit()),
        ];
        let truth = vec![Some(truth); 5];
        // The last vertex is not visible: it does not count against the coverage.
        let visible = [3, 5, 2, 1, 0];
        let s = score(&fit, &truth, &visible, &["m".into()], true);
        assert_eq!((s.visible, s.full_set, s.from_material), (4, 3, 1));
        assert!((s.coverage_visible - 0.75).abs() < 1e-12);
        // η errors +0.33 %, +1.33 %, 0 %: the median is +0.33 %.
        assert!((s.materials[0].eta_error_pct - 100.0 * 0.005 / 1.5).abs() < 1e-4);
        // Own vertices: 1.505 is within 0.01 of 1.5, 1.52 is not.
        assert!((s.sigma_eta.own - 0.5).abs() < 1e-12);
        assert_eq!(s.sigma_eta.from_material_cases, 1);
    }
}
