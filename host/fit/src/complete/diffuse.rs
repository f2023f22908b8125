//! The diffuse albedo of a vertex's samples with every other parameter given ([`fit`]): per
//! colour channel the weighted least-squares ρd, its standard error and the weighted residual
//! sum it leaves — what a completed vertex's own ρd is (`super::own_rho_d`) and what the local
//! η of its surroundings compares (`super::local_eta`).
//!
//! Contract: weights are the samples' normalisers N (their inverse variance at a given model
//! intensity); the estimate is clamped to `[0, albedo_cap]` and the residual sum is taken at
//! the clamped value; `None` without a usable sample or where a channel's normal equation is
//! degenerate (no diffuse signal).

use crate::data::{Sample, SampleSet, VertexSamples};
use crate::model::{SampleFrames, UnitSample, unit_sample_at};
use ellipso_model::optics::pbrdf::PbrdfParams;

/// What [`fit`] returns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiffuseFit {
    /// ρd per colour channel (a mono set repeats its one channel).
    pub rho: [f64; 3],
    /// Its standard error from the residuals.
    pub se: [f64; 3],
    /// Weighted residual sum Σ N·r² over every fitted channel value, at `rho`.
    pub rss: f64,
    /// Number of residual values in `rss`.
    pub values: usize,
    /// Number of albedos fitted (1 mono, 3 colour).
    pub unknowns: usize,
}

/// The samples' diffuse albedo with every other parameter `params`'s at `normal` (module doc).
pub fn fit(
    set: &SampleSet,
    vertex: &VertexSamples,
    samples: &[Sample],
    params: &PbrdfParams<f64>,
    normal: [f64; 3],
    albedo_cap: f64,
) -> Option<DiffuseFit> {
    let channels = if set.colour { 3 } else { 1 };
    let mut units: Vec<(&Sample, UnitSample<f64>)> = Vec::with_capacity(samples.len());
    for s in samples {
        let Some(view) = set.views.get(s.view as usize) else {
            continue;
        };
        let Some(frames) = SampleFrames::new(view, vertex.position_world) else {
            continue;
        };
        let Some(u) = unit_sample_at(&frames, normal, params.eta, params.sigma_s, params.sigma_ss)
        else {
            continue;
        };
        units.push((s, u));
    }
    if units.is_empty() {
        return None;
    }
    let mut rho = [0.0; 3];
    let mut se = [f64::INFINITY; 3];
    let (mut rss_all, mut values) = (0.0, 0usize);
    for c in 0..channels {
        let rest = |u: &UnitSample<f64>| u.predict(0.0, params.rho_ss[c], params.rho_s);
        let (mut num, mut den) = (0.0, 0.0);
        for (s, u) in &units {
            let w = f64::from(s.normaliser);
            let r = rest(u);
            for ((a, obs), r) in u.diffuse.iter().zip(&s.channels[c]).zip(r) {
                num += w * a * (f64::from(*obs) - r);
                den += w * a * a;
            }
        }
        if !(den > 0.0 && num.is_finite()) {
            return None;
        }
        let estimate = num / den;
        let clamped = estimate.clamp(0.0, albedo_cap);
        let (mut rss, mut rss_clamped, mut m) = (0.0, 0.0, 0usize);
        for (s, u) in &units {
            let w = f64::from(s.normaliser);
            let r = rest(u);
            for ((a, obs), r) in u.diffuse.iter().zip(&s.channels[c]).zip(r) {
                let res = f64::from(*obs) - r - estimate * a;
                rss += w * res * res;
                let res_clamped = f64::from(*obs) - r - clamped * a;
                rss_clamped += w * res_clamped * res_clamped;
                m += 1;
            }
        }
        // m ≥ 3 (one sample's three channels) against one unknown.
        let s2 = rss / (m.saturating_sub(1)).max(1) as f64;
        rho[c] = clamped;
        se[c] = (s2 / den).sqrt();
        rss_all += rss_clamped;
        values += m;
    }
    if channels == 1 {
        rho = [rho[0]; 3];
        se = [se[0]; 3];
    }
    rss_all.is_finite().then_some(DiffuseFit {
        rho,
        se,
        rss: rss_all,
        values,
        unknowns: channels,
    })
}
