//! A fitted surface against the simulator's truth, split into what the views observe and what
//! they do not (docs/mesh-bench.md): the carved mesh before the fit and the refined mesh after
//! it are scored on the same vertex labels (the surface update keeps vertex identity).
//!
//! Contract: distances are from each vertex to the closest point of the true surface
//! ([`crate::truth_map::truth_at`]), in metres; normal errors are angles between the fit's
//! refined normal (or the mesh's own normal) and the true normal there, degrees, over the
//! observed vertices. Empty sets give 0.

use crate::truth::TruthObject;
use ellipso_fit::data::VertexFit;
use ellipso_model::geometry::TriangleMesh;
use nalgebra::Vector3;
use serde::Serialize;

use crate::truth_map::truth_at;

/// One mesh's distance and normal errors, observed and unobserved apart.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct SurfaceScore {
    /// Vertices the fit observed.
    pub observed_vertices: usize,
    /// Vertices no fitted view observed.
    pub unobserved_vertices: usize,
    /// Mean distance of the observed vertices to the true surface, m.
    pub observed_mean_m: f64,
    /// 90th percentile of the same, m.
    pub observed_p90_m: f64,
    /// Median signed distance of the observed vertices (negative: inside the true surface),
    /// m: the bias the mean distance hides.
    pub observed_signed_median_m: f64,
    /// Mean distance of the unobserved vertices, m.
    pub unobserved_mean_m: f64,
    /// Median angle between the mesh's normals and the truth at observed vertices, degrees.
    pub mesh_normal_median_deg: f64,
    /// Median angle between the fit's refined normals and the truth at observed vertices,
    /// degrees (`None` when no fit was given).
    pub fit_normal_median_deg: Option<f64>,
    /// 90th percentile of the same.
    pub fit_normal_p90_deg: Option<f64>,
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    ellipso_report::percentile(v, q)
}

fn angle_deg(a: Vector3<f64>, b: Vector3<f64>) -> f64 {
    ellipso_model::geometry::angle_between_deg(&a, &b)
}

/// Scores `mesh` (and the refined normals of `fits`, one per vertex in order, if given) against
/// `truth` with the labels `observed` (module contract).
pub fn surface_score(
    truth: &TruthObject,
    mesh: &TriangleMesh,
    fits: Option<&[VertexFit]>,
    observed: &[bool],
) -> SurfaceScore {
    let at = truth_at(truth, mesh.positions());
    let (mut seen, mut unseen, mut mesh_n, mut fit_n) = (vec![], vec![], vec![], vec![]);
    let mut seen_signed = vec![];
    for (v, t) in at.iter().enumerate() {
        let Some(t) = t else { continue };
        let truth_n = Vector3::from(t.normal_world);
        if observed.get(v).copied().unwrap_or(false) {
            seen.push(t.distance_m);
            seen_signed.push(t.signed_distance_m);
            mesh_n.push(angle_deg(mesh.normals()[v].into_inner(), truth_n));
            if let Some(f) = fits.and_then(|f| f.get(v)) {
                fit_n.push(angle_deg(Vector3::from(f.normal_world), truth_n));
            }
        } else {
            unseen.push(t.distance_m);
        }
    }
    SurfaceScore {
        observed_vertices: seen.len(),
        unobserved_vertices: unseen.len(),
        observed_mean_m: mean(&seen),
        observed_p90_m: percentile(&mut seen, 0.9),
        observed_signed_median_m: percentile(&mut seen_signed, 0.5),
        unobserved_mean_m: mean(&unseen),
        mesh_normal_median_deg: percentile(&mut mesh_n, 0.5),
        fit_normal_median_deg: fits.map(|_| percentile(&mut fit_n, 0.5)),
        fit_normal_p90_deg: fits.map(|_| percentile(&mut fit_n, 0.9)),
    }
}

/// Per-material η error of a fit on the carved-and-refined mesh beside the fit of the same
/// session on the true mesh, percent.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EtaBeside {
    /// Material name.
    pub name: String,
    /// True η.
    pub eta_true: f64,
    /// Error of the material's median η on the carved mesh, %.
    pub carved_pct: f64,
    /// The same on the true mesh, %.
    pub true_mesh_pct: f64,
    /// Vertices whose η is reported (identified), carved mesh / true mesh: the median's sample.
    pub vertices: [usize; 2],
    /// 1σ of the difference from the two medians' own standard errors, points:
    /// √(se_carved² + se_true²) (`MaterialScore::eta_median_se_pct`). Both fits read the same
    /// frames but mostly at different points, so they are treated as independent.
    pub noise_points: f64,
}

impl EtaBeside {
    /// |carved − true mesh|, points: what issue 27's 0.2-point target is about.
    pub fn difference_points(&self) -> f64 {
        (self.carved_pct - self.true_mesh_pct).abs()
    }
}

/// The materials of two scores side by side (materials missing from either are left out).
pub fn eta_beside(
    carved: &crate::score::FitScores,
    true_mesh: &crate::score::FitScores,
) -> Vec<EtaBeside> {
    carved
        .materials
        .iter()
        .filter_map(|c| {
            let t = true_mesh.materials.iter().find(|t| t.name == c.name)?;
            Some(EtaBeside {
                name: c.name.clone(),
                eta_true: c.eta_true,
                carved_pct: c.eta_error_pct,
                true_mesh_pct: t.eta_error_pct,
                vertices: [c.vertices, t.vertices],
                noise_points: c.eta_median_se_pct.hypot(t.eta_median_se_pct),
            })
        })
        .collect()
}

/// How far the fitted vertices that a fitted view sees lie from the true surface (the rows of
/// [`crate::coverage::score_fit_vertices`], visible ones only), metres; NaN when none is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct VisibleDistance {
    /// Visible vertices with a truth.
    pub vertices: usize,
    /// Mean |distance|.
    pub mean_m: f64,
    /// 90th percentile of |distance|.
    pub p90_m: f64,
    /// Median signed distance (negative: inside the true surface).
    pub signed_median_m: f64,
}

/// [`VisibleDistance`] of `rows`.
pub fn visible_distance(rows: &[crate::coverage::VertexRow]) -> VisibleDistance {
    let mut signed: Vec<f64> = rows
        .iter()
        .filter(|r| r.visible_frames >= crate::coverage::VISIBLE_MIN_FRAMES)
        .map(|r| r.distance_m)
        .filter(|d| d.is_finite())
        .collect();
    if signed.is_empty() {
        return VisibleDistance {
            vertices: 0,
            mean_m: f64::NAN,
            p90_m: f64::NAN,
            signed_median_m: f64::NAN,
        };
    }
    let mut abs: Vec<f64> = signed.iter().map(|d| d.abs()).collect();
    VisibleDistance {
        vertices: signed.len(),
        mean_m: mean(&abs),
        p90_m: percentile(&mut abs, 0.9),
        signed_median_m: percentile(&mut signed, 0.5),
    }
}
