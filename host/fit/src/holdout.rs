//! Held-out views: a deterministic subset of the posed frames that no step of the fit sees, and
//! how well the fitted model re-renders them — the check a user can run on a real capture,
//! where no ground truth exists.
//!
//! Contract:
//! - [`split`] picks ⌊fraction·n⌉ of n views (sorted by frame id), spread evenly along the
//!   capture: view i is held out when ⌊(i + 1)·f⌋ > ⌊i·f⌋ (f = 0.1: views 9, 19, 29, …). The
//!   choice depends only on the sorted ids and f, so a re-run holds out the same frames; f = 0
//!   holds out nothing.
//! - [`score`] compares, per held-out sample (vertex, view) and colour channel, the model's four
//!   analyser pixels (the vertex's fitted parameters and normal, the analysers' effective angles
//!   for that ray) with the observed ones, in DN (× the sample's normaliser N), and reports for
//!   s0 = ½ΣI, I^s = I0 − I90 and I^α = I135 − I45: the relative RMSE √(Σ(model − data)²/Σ data²)
//!   and the PSNR 10·log10(peak²/MSE) with peak = the sensor's full scale (s0: twice it, the
//!   largest s0 a pixel pair can hold), per frame and overall. Samples go through the same gates
//!   as the fit's (saturated ones cannot be compared). Vertices without a fit are skipped.
//! - `overall` and `per_frame` score the vertices the fit trusts
//!   ([`VertexFit::is_reliable`](crate::data::VertexFit::is_reliable): the ones the pictures
//!   draw); `all_vertices` scores every vertex, and `untrusted_samples` counts the samples on
//!   the others — a vertex seen from too few views, or with an albedo at the cap, can predict a
//!   highlight no view constrained, and one such sample can dominate an RMSE.

use std::collections::BTreeMap;

use super::data::{SampleSet, VertexFit};
use super::model::{SampleFrames, observed_pixels, predicted_pixels, unit_sample_at};

/// Indices (into `frame_ids`) of the held-out views for `fraction` (module doc); `frame_ids`
/// need not be sorted, the choice is made on the sorted order.
pub fn split(frame_ids: &[u64], fraction: f64) -> Vec<usize> {
    let f = if fraction.is_finite() {
        fraction.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut order: Vec<usize> = (0..frame_ids.len()).collect();
    order.sort_by_key(|&i| frame_ids[i]);
    let mut held: Vec<usize> = order
        .iter()
        .enumerate()
        .filter(|(rank, _)| ((*rank + 1) as f64 * f).floor() > (*rank as f64 * f).floor())
        .map(|(_, &i)| i)
        .collect();
    held.sort_unstable();
    held
}

/// Errors of one quantity over a set of samples.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Errors {
    /// √(Σ(model − data)²/Σ data²).
    pub relative_rmse: f64,
    /// 10·log10(peak²/MSE), dB.
    pub psnr_db: f64,
}

/// The re-render errors of one frame (or of all held-out frames).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameScore {
    /// Frame id (`None`: all held-out frames together).
    pub frame_id: Option<u64>,
    /// Samples (vertex, view) compared.
    pub samples: usize,
    /// s0 = ½(I0 + I45 + I90 + I135).
    pub s0: Errors,
    /// I^s = I0 − I90.
    pub specular: Errors,
    /// I^α = I135 − I45.
    pub alpha: Errors,
}

/// The held-out evaluation of a fit.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HoldoutReport {
    /// Frames held out (ids).
    pub frames: Vec<u64>,
    /// All held-out frames together.
    pub overall: FrameScore,
    /// Per frame, in frame-id order.
    pub per_frame: Vec<FrameScore>,
    /// All held-out frames together, every vertex included (trusted or not).
    pub all_vertices: FrameScore,
    /// Held-out samples on vertices the fit does not trust (left out of `overall`).
    pub untrusted_samples: usize,
}

#[derive(Clone, Copy, Default)]
struct Sums {
    n: usize,
    err2: [f64; 3],
    data2: [f64; 3],
}

impl Sums {
    fn add(&mut self, other: &Sums) {
        self.n += other.n;
        for k in 0..3 {
            self.err2[k] += other.err2[k];
            self.data2[k] += other.data2[k];
        }
    }

    fn score(&self, frame_id: Option<u64>, full_scale_dn: f64) -> FrameScore {
        let errors = |k: usize, peak: f64| {
            let mse = self.err2[k] / self.n.max(1) as f64;
            Errors {
                relative_rmse: (self.err2[k] / self.data2[k].max(1e-300)).sqrt(),
                psnr_db: 10.0 * (peak * peak / mse.max(1e-300)).log10(),
            }
        };
        FrameScore {
            frame_id,
            samples: self.n,
            s0: errors(0, 2.0 * full_scale_dn),
            specular: errors(1, full_scale_dn),
            alpha: errors(2, full_scale_dn),
        }
    }
}

/// Scores `fits` (indexed like `held.vertices`) on the held-out samples `held` (module doc);
/// `full_scale_dn` is the sensor's largest code.
pub fn score(held: &SampleSet, fits: &[VertexFit], full_scale_dn: f64) -> HoldoutReport {
    let channels = if held.colour { 3 } else { 1 };
    let mut per_view: BTreeMap<u32, Sums> = BTreeMap::new();
    let mut untrusted = Sums::default();
    for (v, fit) in held.vertices.iter().zip(fits) {
        let trusted = fit.is_reliable();
        let p = &fit.params;
        for s in &v.samples {
            let Some(view) = held.views.get(s.view as usize) else {
                continue;
            };
            let Some(frames) = SampleFrames::new(view, v.position_world) else {
                continue;
            };
            let n = f64::from(s.normaliser);
            let sums = if trusted {
                per_view.entry(s.view).or_default()
            } else {
                &mut untrusted
            };
            sums.n += 1;
            let unit = unit_sample_at(&frames, fit.normal_world, p.eta, p.sigma_s, p.sigma_ss);
            for c in 0..channels {
                let observed = observed_pixels(s.channels[c].map(f64::from));
                let model = match &unit {
                    Some(u) => predicted_pixels(
                        &frames.pixel_rows,
                        u.predict(p.rho_d[c], p.rho_ss[c], p.rho_s),
                    ),
                    // Back-facing under the fitted normal: the model predicts no light.
                    None => [0.0; 4],
                };
                let q = |i: [f64; 4]| {
                    [
                        0.5 * (i[0] + i[1] + i[2] + i[3]) * n,
                        (i[0] - i[2]) * n,
                        (i[3] - i[1]) * n,
                    ]
                };
                let (m, o) = (q(model), q(observed));
                for k in 0..3 {
                    sums.err2[k] += (m[k] - o[k]).powi(2);
                    sums.data2[k] += o[k] * o[k];
                }
            }
        }
    }
    let mut overall = Sums::default();
    let mut per_frame = Vec::with_capacity(per_view.len());
    for (view, sums) in &per_view {
        overall.add(sums);
        let id = held.views.get(*view as usize).map(|v| v.frame_id);
        per_frame.push(sums.score(id, full_scale_dn));
    }
    per_frame.sort_by_key(|f| f.frame_id);
    let mut all = overall;
    all.add(&untrusted);
    HoldoutReport {
        frames: held.views.iter().map(|v| v.frame_id).collect(),
        overall: overall.score(None, full_scale_dn),
        per_frame,
        all_vertices: all.score(None, full_scale_dn),
        untrusted_samples: untrusted.n,
    }
}

/// `set` split into the views that are fitted and those held out ([`split`] on its views'
/// frame ids): two sample sets over the same vertices, each with only its own views (samples
/// re-indexed). Gate counts stay with the training set.
pub fn split_set(set: &SampleSet, fraction: f64) -> (SampleSet, SampleSet) {
    let ids: Vec<u64> = set.views.iter().map(|v| v.frame_id).collect();
    let held_idx = split(&ids, fraction);
    let mut is_held = vec![false; set.views.len()];
    for &i in &held_idx {
        is_held[i] = true;
    }
    let mut new_index = vec![0u32; set.views.len()];
    let (mut train_views, mut held_views) = (Vec::new(), Vec::new());
    for (i, v) in set.views.iter().enumerate() {
        let list = if is_held[i] {
            &mut held_views
        } else {
            &mut train_views
        };
        new_index[i] = list.len() as u32;
        list.push(v.clone());
    }
    let mut train = SampleSet {
        views: train_views,
        colour: set.colour,
        vertices: Vec::with_capacity(set.vertices.len()),
        rings: set.rings.clone(),
    };
    let mut held = SampleSet {
        views: held_views,
        colour: set.colour,
        vertices: Vec::with_capacity(set.vertices.len()),
        rings: set.rings.clone(),
    };
    for v in &set.vertices {
        let mut t = v.clone();
        let mut h = v.clone();
        t.samples.clear();
        h.samples.clear();
        h.gates = Default::default();
        for s in &v.samples {
            let Some(&held_view) = is_held.get(s.view as usize) else {
                continue;
            };
            let mut s = *s;
            s.view = new_index[s.view as usize];
            if held_view {
                h.samples.push(s);
            } else {
                t.samples.push(s);
            }
        }
        train.vertices.push(t);
        held.vertices.push(h);
    }
    (train, held)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_is_even_deterministic_and_complete() {
        let ids: Vec<u64> = (0..100).rev().collect();
        let held = split(&ids, 0.1);
        assert_eq!(held.len(), 10);
        let mut held_ids: Vec<u64> = held.iter().map(|&i| ids[i]).collect();
        held_ids.sort_unstable();
        assert_eq!(held_ids, vec![9, 19, 29, 39, 49, 59, 69, 79, 89, 99]);
        assert!(split(&ids, 0.0).is_empty());
        assert!(split(&ids, f64::NAN).is_empty());
        assert_eq!(split(&ids, 1.0).len(), 100);
        assert_eq!(split(&ids[..7], 0.1).len(), 0);
        assert_eq!(split(&ids[..15], 0.1).len(), 1);
    }

    /// A vertex the fit does not trust (an albedo at the cap) predicts a highlight no view
    /// constrained; it is scored apart: `overall` is the trusted vertices' error, `all_vertices`
    /// includes it, and its samples are counted.
    #[test]
    fn untrusted_vertices_are_scored_apart() {
        use crate::solve::tests::{material, synth};
        use crate::synthetic::orbit_views;
        use ellipso_model::optics::pbrdf::PbrdfParams;
        let views = orbit_views(40, 0.5, [20.0, 70.0], 1.0, [0.0; 3], [0.0, 0.03, 0.0]);
        let up = [0.0, 0.0, 1.0];
        let truth = material("ceramic");
        let set = SampleSet {
            vertices: vec![
                synth(&views, up, &truth, None, 1.0, 0),
                synth(&views, up, &truth, None, 1.0, 1),
            ],
            views,
            colour: true,
            rings: Vec::new(),
        };
        let fit = |vertex: u32, params| VertexFit {
            vertex,
            params,
            normal_world: up,
            std_error: [0.0; 10],
            normal_std_error_deg: 0.0,
            samples_used: 0,
            cost: 0.0,
            iterations: 0,
            flags: Vec::new(),
            eta_unpooled: None,
            eta_prior_only: false,
            gates: Default::default(),
        };
        let cap = 5.0;
        let runaway = PbrdfParams {
            rho_s: cap,
            sigma_s: 0.4,
            sigma_ss: 0.6,
            ..truth
        };
        let mut runaway = fit(1, runaway);
        runaway.flags = vec![crate::data::FitFlag::AlbedoAtCap];
        let fits = [fit(0, truth), runaway];
        let r = score(&set, &fits, 4095.0);
        assert_eq!(r.untrusted_samples, set.vertices[1].samples.len());
        assert!(r.untrusted_samples > 0);
        assert!(r.overall.s0.relative_rmse < 1e-3, "{:?}", r.overall);
        assert!(
            r.all_vertices.s0.relative_rmse > 0.01,
            "{:?}",
            r.all_vertices
        );
        assert_eq!(
            r.overall.samples + r.untrusted_samples,
            r.all_vertices.samples
        );
        // Every vertex trusted: both scores agree.
        let r = score(&set, &[fit(0, truth), fit(1, truth)], 4095.0);
        assert_eq!(r.untrusted_samples, 0);
        assert_eq!(r.overall, r.all_vertices);
    }
}
