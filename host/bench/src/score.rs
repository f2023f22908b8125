//! Scores of one fit against the simulator's truth, in the paper's measure and beside the noise
//! floor.
//!
//! Contract:
//! - Vertices scored: every vertex whose parameters the outputs report (the identifiability
//!   rule, `VertexFit::is_reliable`: own fits and those completed from their material) with a
//!   truth ([`VertexTruth`]); what share of the visible surface that is, `crate::coverage`.
//! - **Per material** (the paper's measure): the median fitted η over the material's scored
//!   vertices whose η the identifiability rule reports (`VertexFit::eta_identified`; NaN
//!   when none does) and its signed error against the truth, %; the same for the vertices' unpooled η
//!   (their own estimate before the material's pool, [`ellipso_fit::data::VertexFit::eta_unpooled`],
//!   else their η); the median relative ρd error (RGB mean), the median σs and σss, the median
//!   normal error; and whether the material's median sits at the solver's start value η = 1.5
//!   (to 1e-4): a material that never left its start is not a measurement.
//! - **Per vertex**: the median |η error| % after and before pooling, the median and 90th
//!   percentile normal error, the median ρd error, the mean |σs|, |σss| errors.
//! - **Held-out re-render**: the fit's relative RMSE of s0, I^s and I^α on the held-out views
//!   over the vertices the fit trusts, and the same figure for the *true* parameters and normals
//!   on exactly those samples — the floor that sensor noise and the chain's sampling leave
//!   ([`holdout_beside_truth`]).
//! - **Residuals at the truth** ([`truth_residuals`]): per material and observation channel
//!   (I^d, I^s, I^α, I^t), the mean of (observed − true model)/σ over the fitted samples, σ the
//!   sensor noise the solver assumes; a chain stage that biases the observations shows here as
//!   a mean far from 0, before any fit.

use ellipso_fit::data::{SampleSet, VertexFit};
use ellipso_fit::holdout::{FrameScore, score};
use ellipso_fit::model::{SampleFrames, observed_pixels, predicted_pixels, unit_sample_at};
use ellipso_fit::solve::SensorNoiseModel;
use nalgebra::Vector3;
use serde::Serialize;

use crate::truth_map::VertexTruth;

/// The start value of η of every cold start and of the weak default prior.
pub const ETA_START: f64 = 1.5;

/// One material's scores.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MaterialScore {
    /// Material name.
    pub name: String,
    /// True η.
    pub eta_true: f64,
    /// Vertices scored whose η the identifiability rule reports (the median's sample).
    pub vertices: usize,
    /// Median fitted η over those (NaN: none reports η — the material is unidentified).
    pub eta_median: f64,
    /// (median − truth)/truth, %, signed.
    pub eta_error_pct: f64,
    /// Median unpooled η.
    pub eta_unpooled_median: f64,
    /// (unpooled median − truth)/truth, %, signed.
    pub eta_unpooled_error_pct: f64,
    /// Standard error of the material's η from its own data, % of the true η: that of the median
    /// of the reporting vertices' unpooled η (`ellipso_model::stats::median_standard_error`) —
    /// the pooled η is shrunk to that median, so its own spread would understate it. NaN below
    /// two vertices.
    pub eta_median_se_pct: f64,
    /// The median sits at the start value η = 1.5 (to 1e-4).
    pub at_start_value: bool,
    /// Scored vertices of the material whose η the rule withholds.
    pub unidentified_vertices: usize,
    /// Median relative ρd error (mean over RGB), %.
    pub rho_d_error_pct: f64,
    /// Median fitted σs (truth beside it).
    pub sigma_s_median: f64,
    /// True σs.
    pub sigma_s_true: f64,
    /// Median fitted σss.
    pub sigma_ss_median: f64,
    /// True σss.
    pub sigma_ss_true: f64,
    /// Median normal error, degrees.
    pub normal_median_deg: f64,
}

/// The scores of one fit.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FitScores {
    /// Vertices scored.
    pub scored: usize,
    /// Per material, in the truth's material order (materials without a scored vertex left out).
    pub materials: Vec<MaterialScore>,
    /// Mean over materials of |per-material η error|, %.
    pub eta_material_mean_pct: f64,
    /// Largest |per-material η error|, %.
    pub eta_material_max_pct: f64,
    /// Median |η error| over the scored vertices that report η, after pooling, %.
    pub eta_vertex_median_pct: f64,
    /// Mean |η error| over the same vertices, %.
    pub eta_vertex_mean_pct: f64,
    /// Median |η error| over vertices before pooling, %.
    pub eta_vertex_unpooled_median_pct: f64,
    /// Median normal error, degrees.
    pub normal_median_deg: f64,
    /// 90th percentile normal error, degrees.
    pub normal_p90_deg: f64,
    /// Median relative ρd error, %.
    pub rho_d_median_pct: f64,
    /// Mean |σs − truth|.
    pub sigma_s_abs: f64,
    /// Mean |σss − truth|.
    pub sigma_ss_abs: f64,
}

fn median(mut v: Vec<f64>) -> f64 {
    ellipso_model::stats::median(&mut v)
}

fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    ellipso_model::geometry::angle_between_deg(&Vector3::from(a), &Vector3::from(b))
}

fn rho_d_error_pct(fit: &VertexFit, truth: &VertexTruth, colour: bool) -> f64 {
    let t = truth.params.rho_d;
    let mono = (t[0] + t[1] + t[2]) / 3.0;
    (0..3)
        .map(|c| {
            let tc = if colour { t[c] } else { mono };
            100.0 * (fit.params.rho_d[c] - tc).abs() / tc.max(1e-6)
        })
        .sum::<f64>()
        / 3.0
}

/// Scores `fits` against `truth` (one entry per fitted vertex, module doc); `names` are the
/// truth's material names, `colour` whether the sensor resolves colour.
pub fn score_fit(
    fits: &[VertexFit],
    truth: &[Option<VertexTruth>],
    names: &[String],
    colour: bool,
) -> FitScores {
    let scored: Vec<(usize, &VertexTruth)> = fits
        .iter()
        .zip(truth)
        .enumerate()
        .filter(|(_, (f, _))| f.is_reliable())
        .filter_map(|(v, (_, t))| t.as_ref().map(|t| (v, t)))
        .collect();
    let eta_err = |eta: f64, t: &VertexTruth| 100.0 * (eta - t.params.eta) / t.params.eta;
    let unpooled = |f: &VertexFit| f.eta_unpooled.map_or(f.params.eta, |u| u[0]);
    let mut materials = Vec::new();
    for (m, name) in names.iter().enumerate() {
        let members: Vec<(usize, &VertexTruth)> = scored
            .iter()
            .copied()
            .filter(|(_, t)| t.material == m)
            .collect();
        let Some(&(_, first)) = members.first() else {
            continue;
        };
        let eta_true = first.params.eta;
        // η is a measurement only where the identifiability rule reports it.
        let identified: Vec<usize> = members
            .iter()
            .map(|&(v, _)| v)
            .filter(|&v| fits[v].eta_identified())
            .collect();
        let eta_median = median(identified.iter().map(|&v| fits[v].params.eta).collect());
        let mut unpooled_etas: Vec<f64> = identified.iter().map(|&v| unpooled(&fits[v])).collect();
        let eta_unpooled_median = ellipso_model::stats::median(&mut unpooled_etas);
        materials.push(MaterialScore {
            name: name.clone(),
            eta_true,
            vertices: identified.len(),
            eta_median,
            eta_error_pct: 100.0 * (eta_median - eta_true) / eta_true,
            eta_unpooled_median,
            eta_unpooled_error_pct: 100.0 * (eta_unpooled_median - eta_true) / eta_true,
            eta_median_se_pct: 100.0
                * ellipso_model::stats::median_standard_error(&mut unpooled_etas)
                / eta_true,
            at_start_value: (eta_median - ETA_START).abs() < 1e-4,
            unidentified_vertices: members.len() - identified.len(),
            rho_d_error_pct: median(
                members
                    .iter()
                    .map(|&(v, t)| rho_d_error_pct(&fits[v], t, colour))
                    .collect(),
            ),
            sigma_s_median: median(
                members
                    .iter()
                    .map(|&(v, _)| fits[v].params.sigma_s)
                    .collect(),
            ),
            sigma_s_true: first.params.sigma_s,
            sigma_ss_median: median(
                members
                    .iter()
                    .map(|&(v, _)| fits[v].params.sigma_ss)
                    .collect(),
            ),
            sigma_ss_true: first.params.sigma_ss,
            normal_median_deg: median(
                members
                    .iter()
                    .map(|&(v, t)| angle_deg(fits[v].normal_world, t.normal_world))
                    .collect(),
            ),
        });
    }
    let abs_errors: Vec<f64> = materials.iter().map(|m| m.eta_error_pct.abs()).collect();
    let mean = |xs: &[f64]| {
        if xs.is_empty() {
            f64::NAN
        } else {
            xs.iter().sum::<f64>() / xs.len() as f64
        }
    };
    let normals: Vec<f64> = scored
        .iter()
        .map(|&(v, t)| angle_deg(fits[v].normal_world, t.normal_world))
        .collect();
    FitScores {
        scored: scored.len(),
        eta_material_mean_pct: mean(&abs_errors),
        eta_material_max_pct: abs_errors.iter().copied().fold(f64::NAN, f64::max),
        materials,
        eta_vertex_median_pct: median(
            scored
                .iter()
                .filter(|&&(v, _)| fits[v].eta_identified())
                .map(|&(v, t)| eta_err(fits[v].params.eta, t).abs())
                .collect(),
        ),
        eta_vertex_mean_pct: mean(
            &scored
                .iter()
                .filter(|&&(v, _)| fits[v].eta_identified())
                .map(|&(v, t)| eta_err(fits[v].params.eta, t).abs())
                .collect::<Vec<_>>(),
        ),
        eta_vertex_unpooled_median_pct: median(
            scored
                .iter()
                .filter(|&&(v, _)| fits[v].eta_identified())
                .map(|&(v, t)| eta_err(unpooled(&fits[v]), t).abs())
                .collect(),
        ),
        normal_median_deg: median(normals.clone()),
        normal_p90_deg: ellipso_report::percentile(&mut normals.clone(), 0.9),
        rho_d_median_pct: median(
            scored
                .iter()
                .map(|&(v, t)| rho_d_error_pct(&fits[v], t, colour))
                .collect(),
        ),
        sigma_s_abs: mean(
            &scored
                .iter()
                .map(|&(v, t)| (fits[v].params.sigma_s - t.params.sigma_s).abs())
                .collect::<Vec<_>>(),
        ),
        sigma_ss_abs: mean(
            &scored
                .iter()
                .map(|&(v, t)| (fits[v].params.sigma_ss - t.params.sigma_ss).abs())
                .collect::<Vec<_>>(),
        ),
    }
}

/// The fit's held-out re-render errors and the truth's on the same samples.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct HoldoutBeside {
    /// The fitted parameters and normals.
    pub fit: FrameScore,
    /// The true parameters and normals, on the same held-out samples of the same vertices.
    pub truth: FrameScore,
}

/// The held-out score of `fits` and of the truth on the samples of `held` that belong to
/// vertices the fit trusts and that have a truth (module doc).
pub fn holdout_beside_truth(
    held: &SampleSet,
    fits: &[VertexFit],
    truth: &[Option<VertexTruth>],
    full_scale_dn: f64,
) -> HoldoutBeside {
    let mut held = held.clone();
    let mut truth_fits = fits.to_vec();
    for ((vs, f), (tf, t)) in held
        .vertices
        .iter_mut()
        .zip(fits)
        .zip(truth_fits.iter_mut().zip(truth))
    {
        match t {
            Some(t) if f.is_reliable() => {
                tf.params = t.params;
                tf.normal_world = t.normal_world;
                // The truth is trusted wherever the fit is (the samples are already those).
                tf.flags.clear();
            }
            _ => vs.samples.clear(),
        }
    }
    HoldoutBeside {
        fit: score(&held, fits, full_scale_dn).overall,
        truth: score(&held, &truth_fits, full_scale_dn).overall,
    }
}

/// Per material, the observations' mean deviation from the true model in units of the assumed
/// noise, per observation channel [I^d, I^s, I^α, I^t] (module doc).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MaterialResiduals {
    /// Material name.
    pub name: String,
    /// Samples (vertex, view) compared.
    pub samples: usize,
    /// The gates' counts over the material's vertices.
    pub gates: ellipso_fit::data::GateCounts,
    /// Mean (observed − model)/σ per channel.
    pub mean_z: [f64; 4],
    /// RMS of (observed − model)/σ per channel (1 when the noise model holds).
    pub rms_z: [f64; 4],
    /// Σ(observed − model)/Σ|model| per channel: the relative bias.
    pub relative_bias: [f64; 4],
    /// Σ observed·model / Σ model² per channel: the observations' gain on the true model (1:
    /// unbiased; < 1 on I^s and I^α: the chain depolarises).
    pub gain: [f64; 4],
}

/// The residuals of the observations in `set` against the true model at every scored vertex
/// (module doc); `sensor` is the noise model the solver assumes.
pub fn truth_residuals(
    set: &SampleSet,
    truth: &[Option<VertexTruth>],
    names: &[String],
    sensor: &SensorNoiseModel,
) -> Vec<MaterialResiduals> {
    let channels = if set.colour { 3 } else { 1 };
    let floor = sensor.read_noise_dn.powi(2) + 1.0 / 12.0;
    #[derive(Clone, Default)]
    struct Acc {
        n: usize,
        z: [f64; 4],
        z2: [f64; 4],
        diff: [f64; 4],
        model: [f64; 4],
        om: [f64; 4],
        mm: [f64; 4],
        gates: ellipso_fit::data::GateCounts,
    }
    let mut acc = vec![Acc::default(); names.len()];
    for (vs, t) in set.vertices.iter().zip(truth) {
        let Some(t) = t else { continue };
        let p = &t.params;
        let a = &mut acc[t.material];
        a.gates.add(&vs.gates);
        for s in &vs.samples {
            let Some(view) = set.views.get(s.view as usize) else {
                continue;
            };
            let Some(frames) = SampleFrames::new(view, vs.position_world) else {
                continue;
            };
            let Some(unit) = unit_sample_at(&frames, t.normal_world, p.eta, p.sigma_s, p.sigma_ss)
            else {
                continue;
            };
            let n = f64::from(s.normaliser);
            a.n += 1;
            for c in 0..channels {
                let obs = observed_pixels(s.channels[c].map(f64::from));
                let model = predicted_pixels(
                    &frames.pixel_rows,
                    unit.predict(p.rho_d[c], p.rho_ss[c], p.rho_s),
                );
                // Per-pixel variance in model units (shot + floor), floored at the model's 0.
                let var: [f64; 4] = core::array::from_fn(|j| {
                    (sensor.dn_per_electron * n * model[j].max(0.0) + floor) / (n * n)
                });
                // [I^d, I^s, I^α, I^t] and their variances from the four pixels.
                let ch = |i: [f64; 4]| [2.0 * i[2], i[0] - i[2], i[3] - i[1], i[1] + i[3]];
                let vars = [
                    4.0 * var[2],
                    var[0] + var[2],
                    var[3] + var[1],
                    var[1] + var[3],
                ];
                let (o, m) = (ch(obs), ch(model));
                for k in 0..4 {
                    let z = (o[k] - m[k]) / vars[k].sqrt();
                    a.z[k] += z;
                    a.z2[k] += z * z;
                    a.diff[k] += o[k] - m[k];
                    a.model[k] += m[k].abs();
                    a.om[k] += o[k] * m[k];
                    a.mm[k] += m[k] * m[k];
                }
            }
        }
    }
    acc.iter()
        .zip(names)
        .filter(|(a, _)| a.n > 0)
        .map(|(a, name)| {
            let k = (a.n * channels) as f64;
            MaterialResiduals {
                name: name.clone(),
                samples: a.n,
                gates: a.gates.clone(),
                mean_z: a.z.map(|z| z / k),
                rms_z: a.z2.map(|z| (z / k).sqrt()),
                relative_bias: core::array::from_fn(|i| a.diff[i] / a.model[i].max(1e-300)),
                gain: core::array::from_fn(|i| a.om[i] / a.mm[i].max(1e-300)),
            }
        })
        .collect()
}
