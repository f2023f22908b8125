//! The scores of a fit against a simulated capture's truth ([`evaluate`], the parent module's
//! doc says what each figure is): η, normal, ρd and roughness errors per material and over every
//! scored vertex, and the re-render RMSE over the kept observations.
//!
//! Contract: vertices flagged `TooFewViews` are left out of the errors and counted.

use std::collections::BTreeMap;

use ellipso_fit::data::{FitFlag, SampleSet, VertexFit};
use nalgebra::Vector3;
use rayon::prelude::*;

use super::{SimulatedCapture, predict_vertex};
use crate::truth::TruthObject;

/// Errors of one material.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct MaterialErrors {
    /// Material name.
    pub name: String,
    /// True η.
    pub eta_true: f64,
    /// Vertices scored.
    pub vertices: usize,
    /// Mean |η − η_true| / η_true, %.
    pub eta_mean_pct: f64,
    /// Median fitted η.
    pub eta_median: f64,
    /// Median over the material's vertices of |η − η_true| / η_true, %.
    pub eta_vertex_median_pct: f64,
    /// Median fitted σs.
    pub sigma_s_median: f64,
    /// Median fitted σss.
    pub sigma_ss_median: f64,
    /// Mean relative ρd error over RGB, %.
    pub rho_d_mean_pct: f64,
    /// Mean |σs − σs_true|.
    pub sigma_s_abs: f64,
    /// Mean |σss − σss_true|.
    pub sigma_ss_abs: f64,
    /// Median normal error, degrees.
    pub normal_median_deg: f64,
}

/// The scores of one fit.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Scores {
    /// Vertices in the object.
    pub vertices: usize,
    /// Vertices scored (not `TooFewViews`).
    pub scored: usize,
    /// Vertices some view sees lit (not `Unobserved`): what the coverage is of.
    pub observed: usize,
    /// `scored / observed`: the share of the seen surface the figures stand for (this
    /// fit-only bench runs steps A–C without the completion from materials).
    pub coverage: f64,
    /// Kept observations.
    pub samples: usize,
    /// Mean η error over scored vertices, %.
    pub eta_mean_pct: f64,
    /// Median η error over scored vertices, %.
    pub eta_median_pct: f64,
    /// Mean over materials of the error of the material's η (median over its vertices), % —
    /// the paper's measure (one η per object, 1.49 % on real objects).
    pub eta_material_pct: f64,
    /// Median normal error, degrees.
    pub normal_median_deg: f64,
    /// 90th percentile normal error, degrees.
    pub normal_p90_deg: f64,
    /// Median initial (input) normal error, degrees.
    pub normal_input_median_deg: f64,
    /// Mean relative ρd error, %.
    pub rho_d_mean_pct: f64,
    /// Median relative ρd error, % (robust to the few vertices whose ρd absorbs a highlight).
    pub rho_d_median_pct: f64,
    /// Mean |σs − σs_true|.
    pub sigma_s_abs: f64,
    /// Mean |σss − σss_true|.
    pub sigma_ss_abs: f64,
    /// Relative re-render RMSE over all observation channels.
    pub rerender_rmse: f64,
    /// Per material.
    pub materials: Vec<MaterialErrors>,
    /// Flag histogram.
    pub flags: BTreeMap<String, usize>,
}

/// Scores `fits` against `capture`'s truth (the figures: [`crate::accuracy`]'s module doc).
pub fn evaluate(capture: &SimulatedCapture, fits: &[VertexFit]) -> Scores {
    let truth = &capture.truth;
    let set = &capture.set;
    let mut flags = BTreeMap::new();
    for f in fits {
        for flag in &f.flags {
            *flags.entry(format!("{flag:?}")).or_insert(0) += 1;
        }
    }
    let mut per_material: Vec<Vec<usize>> = vec![Vec::new(); truth.material_names.len()];
    for (v, f) in fits.iter().enumerate() {
        if !f.flags.contains(&FitFlag::TooFewViews) {
            per_material[truth.material[v]].push(v);
        }
    }
    let errors = VertexErrors { truth, set, fits };
    let materials = material_errors(&errors, &per_material);
    let scored: Vec<usize> = per_material.iter().flatten().copied().collect();
    let mut normals: Vec<f64> = scored.iter().map(|&v| errors.normal_deg(v)).collect();
    let mut inputs: Vec<f64> = scored.iter().map(|&v| errors.input_normal_deg(v)).collect();
    let (sq_err, sq_obs) = rerender_sums(set, fits, &scored);
    let eta_material_pct = mean(
        &materials
            .iter()
            .map(|m| 100.0 * (m.eta_median - m.eta_true).abs() / m.eta_true)
            .collect::<Vec<_>>(),
    );
    let observed = fits
        .iter()
        .filter(|f| !f.flags.contains(&FitFlag::Unobserved))
        .count();
    Scores {
        eta_material_pct,
        vertices: fits.len(),
        scored: scored.len(),
        observed,
        coverage: if observed == 0 {
            f64::NAN
        } else {
            scored.len() as f64 / observed as f64
        },
        samples: set.vertices.iter().map(|v| v.samples.len()).sum(),
        eta_mean_pct: mean(
            &scored
                .iter()
                .map(|&v| errors.eta_pct(v))
                .collect::<Vec<_>>(),
        ),
        eta_median_pct: ellipso_report::percentile(
            &mut scored
                .iter()
                .map(|&v| errors.eta_pct(v))
                .collect::<Vec<_>>(),
            0.5,
        ),
        normal_median_deg: ellipso_report::percentile(&mut normals, 0.5),
        normal_p90_deg: ellipso_report::percentile(&mut normals, 0.9),
        normal_input_median_deg: ellipso_report::percentile(&mut inputs, 0.5),
        rho_d_mean_pct: mean(
            &scored
                .iter()
                .map(|&v| errors.rho_d_pct(v))
                .collect::<Vec<_>>(),
        ),
        rho_d_median_pct: ellipso_report::percentile(
            &mut scored
                .iter()
                .map(|&v| errors.rho_d_pct(v))
                .collect::<Vec<_>>(),
            0.5,
        ),
        sigma_s_abs: mean(
            &scored
                .iter()
                .map(|&v| (fits[v].params.sigma_s - truth.params[v].sigma_s).abs())
                .collect::<Vec<_>>(),
        ),
        sigma_ss_abs: mean(
            &scored
                .iter()
                .map(|&v| (fits[v].params.sigma_ss - truth.params[v].sigma_ss).abs())
                .collect::<Vec<_>>(),
        ),
        rerender_rmse: (sq_err / sq_obs.max(1e-300)).sqrt(),
        materials,
        flags,
    }
}

/// One vertex's errors: the fitted `fits` against the `truth` of the capture `set`.
struct VertexErrors<'a> {
    truth: &'a TruthObject,
    set: &'a SampleSet,
    fits: &'a [VertexFit],
}

impl VertexErrors<'_> {
    /// The fitted normal's angle to the true normal, degrees.
    fn normal_deg(&self, v: usize) -> f64 {
        angle_deg(
            &Vector3::from(self.fits[v].normal_world),
            &self.truth.mesh.normals()[v].into_inner(),
        )
    }

    /// The initial (input) normal's angle to the true normal, degrees.
    fn input_normal_deg(&self, v: usize) -> f64 {
        angle_deg(
            &Vector3::from(self.set.vertices[v].normal_world),
            &self.truth.mesh.normals()[v].into_inner(),
        )
    }

    /// |η − η_true| / η_true, %.
    fn eta_pct(&self, v: usize) -> f64 {
        100.0 * (self.fits[v].params.eta - self.truth.params[v].eta).abs()
            / self.truth.params[v].eta
    }

    /// The true ρd of colour channel `c`: a monochrome sensor sees the mean of the colour
    /// channels.
    fn true_rho_d(&self, v: usize, c: usize) -> f64 {
        let rho = self.truth.params[v].rho_d;
        if self.set.colour {
            rho[c]
        } else {
            rho.iter().sum::<f64>() / 3.0
        }
    }

    /// Mean relative ρd error over RGB, %.
    fn rho_d_pct(&self, v: usize) -> f64 {
        (0..3)
            .map(|c| {
                let t = self.true_rho_d(v, c);
                100.0 * (self.fits[v].params.rho_d[c] - t).abs() / t.max(1e-6)
            })
            .sum::<f64>()
            / 3.0
    }
}

/// The mean of `xs` (NaN when empty).
fn mean(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        f64::NAN
    } else {
        xs.iter().sum::<f64>() / xs.len() as f64
    }
}

/// The errors of each material with scored vertices (`per_material`: the scored vertices of
/// each of the truth's materials).
fn material_errors(errors: &VertexErrors, per_material: &[Vec<usize>]) -> Vec<MaterialErrors> {
    let (truth, fits) = (errors.truth, errors.fits);
    let mut materials = Vec::new();
    for (m, members) in per_material.iter().enumerate() {
        if members.is_empty() {
            continue;
        }
        let tp = &truth.params[members[0]];
        let mut etas: Vec<f64> = members.iter().map(|&v| fits[v].params.eta).collect();
        let mut normals: Vec<f64> = members.iter().map(|&v| errors.normal_deg(v)).collect();
        let mut sigma_s: Vec<f64> = members.iter().map(|&v| fits[v].params.sigma_s).collect();
        let mut sigma_ss: Vec<f64> = members.iter().map(|&v| fits[v].params.sigma_ss).collect();
        materials.push(MaterialErrors {
            name: truth.material_names[m].clone(),
            eta_true: tp.eta,
            vertices: members.len(),
            eta_mean_pct: mean(
                &members
                    .iter()
                    .map(|&v| errors.eta_pct(v))
                    .collect::<Vec<_>>(),
            ),
            eta_median: ellipso_report::percentile(&mut etas, 0.5),
            eta_vertex_median_pct: ellipso_report::percentile(
                &mut members
                    .iter()
                    .map(|&v| errors.eta_pct(v))
                    .collect::<Vec<_>>(),
                0.5,
            ),
            sigma_s_median: ellipso_report::percentile(&mut sigma_s, 0.5),
            sigma_ss_median: ellipso_report::percentile(&mut sigma_ss, 0.5),
            rho_d_mean_pct: mean(
                &members
                    .iter()
                    .map(|&v| errors.rho_d_pct(v))
                    .collect::<Vec<_>>(),
            ),
            sigma_s_abs: mean(
                &members
                    .iter()
                    .map(|&v| (fits[v].params.sigma_s - truth.params[v].sigma_s).abs())
                    .collect::<Vec<_>>(),
            ),
            sigma_ss_abs: mean(
                &members
                    .iter()
                    .map(|&v| (fits[v].params.sigma_ss - truth.params[v].sigma_ss).abs())
                    .collect::<Vec<_>>(),
            ),
            normal_median_deg: ellipso_report::percentile(&mut normals, 0.5),
        });
    }
    materials
}

/// Re-render sums over every kept observation of the `scored` vertices: Σ(model − observed)²
/// and Σ observed², all channels.
fn rerender_sums(set: &SampleSet, fits: &[VertexFit], scored: &[usize]) -> (f64, f64) {
    // Re-render RMSE over every kept observation of scored vertices.
    scored
        .par_iter()
        .map(|&v| {
            let vs = &set.vertices[v];
            let pred = predict_vertex(&set.views, vs, &fits[v].params, fits[v].normal_world);
            let mut e = 0.0;
            let mut o = 0.0;
            for (s, p) in vs.samples.iter().zip(pred) {
                let Some(p) = p else { continue };
                for (pc, sc) in p.iter().zip(&s.channels) {
                    for (pk, sk) in pc.iter().zip(sc) {
                        let obs = f64::from(*sk);
                        e += (pk - obs).powi(2);
                        o += obs * obs;
                    }
                }
            }
            (e, o)
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// Angle between two vectors, degrees: the model's one [`ellipso_model::geometry::angle_between_deg`].
fn angle_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    ellipso_model::geometry::angle_between_deg(a, b)
}
