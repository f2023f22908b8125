//! One vertex's least-squares problem: the prepared samples and the residual vector, generic
//! over the scalar so one source gives the cost (`f64`), the LM Jacobian (duals over the box
//! coordinates, albedos projected inside) and the covariance Jacobian (duals over all
//! parameters, albedos given); the measurement loss's Jacobians are also written out from the
//! same unit lobes (`jacobian.rs`, tested equal).
//!
//! Residuals, in emission order (docs/fit-solver.md; module doc of `solve` for the weights):
//! - [`LossMode::Paper`]: per real sample, per colour channel: L_d `√(λd·w)·(Î^d − I^d)`,
//!   L_s `√(λs'·w)·(Î^s − I^s)`; then L_ψ `√(λψ·w_ψ)·(DoP_d(η, θ_o) − DoP_obs)` and L_φ
//!   `√(λφ·w)·(I^α_D − u_α·DP, I^β − u_β·DP)`.
//! - [`LossMode::Measurement`]: per real sample, per colour channel, the four analyser pixels
//!   I0, I45, I90, I135 (recovered exactly from the stored I^d, I^s, I^α, I^t) each whitened by
//!   its own predicted sensor noise (see [`Problem::reweight`]); the prediction reads each
//!   pixel at its analyser's effective angle for the ray (`SampleFrames::pixel_rows`). The four
//!   pixels are independent measurements, so this is the exact Mahalanobis form; no ratio of
//!   noisy quantities.
//! - Both: per virtual sample, per channel `√W_m·(Î^s_coax − Ĩ^s)` (paper: W_m = λs·N_real·w_m;
//!   measurement: the virtual value whitened by the noise an I^s measurement of it would have at
//!   the vertex's median normaliser, scaled so the virtual samples carry λg/(1 − λg) of the
//!   real samples' count, the paper's proportion).
//! - Measurement mode only, the priors (one row each, in standard deviations): η about its
//!   centre (the solver's weak default or the cluster's pooled value), ln σs and ln σss about
//!   theirs, and the normal's two tangent components about the mesh normal (the prior cone).
//!
//! Here: the prepared data ([`Problem`], [`Scratch`]) and the counts; the unknowns, their box and
//! priors are in `unknowns`, the measurement loss's noise weights in `weights`, the evaluation of
//! the residuals in `residuals`.

mod residuals;
mod unknowns;
mod weights;

use super::super::data::{
    OBSERVATION_CHANNELS, VertexGuide, VertexSamples, ViewGeometry, VirtualSample,
};
pub(super) use super::super::model::Chart;
use super::super::model::{SampleFrames, UnitSample, observed_pixels as pixels_of, tangent_basis};
pub(super) use super::albedos::Albedos;
use super::{LossMode, SolverConfig};
pub(super) use unknowns::{Bounds, Nonlinear};
use unknowns::{Prior, Priors};

/// Prepared data of one vertex.
pub(super) struct Problem<'a> {
    pub frames: Vec<SampleFrames>,
    /// Per sample, per colour channel: [I^d, I^s, I^α, I^t] (model units).
    pub obs: Vec<[[f64; OBSERVATION_CHANNELS]; 3]>,
    /// Per sample: the monochrome projection of [I^d, I^s, I^α] (docs/model.md §11
    /// "Monochrome projection").
    pub mono: Vec<[f64; 3]>,
    /// Per-sample weight of the intensity and azimuth residuals (paper mode).
    pub w_int: Vec<f64>,
    /// Per-sample weight of the DoP residual (paper mode).
    pub w_dop: Vec<f64>,
    /// Per sample: the normaliser N (DN per model unit).
    pub normalisers: Vec<f64>,
    pub virtuals: &'a [VirtualSample],
    /// 3 (colour) or 1 (monochrome: channel 0 only).
    pub channels: usize,
    pub colour_weights: [f64; 3],
    pub lambda_psi: f64,
    pub lambda_d: f64,
    /// λs for real specular residuals ((1 − λg)·λs when virtual samples are present).
    pub lambda_s_real: f64,
    pub lambda_phi: f64,
    /// Σ of squared observations (scale for the absolute convergence test).
    pub data_scale: f64,
    /// Which loss [`Problem::evaluate`] emits.
    pub loss: LossMode,
    /// Measurement mode: per sample, per channel, the four analyser pixels [I0, I45, I90, I135]
    /// (model units).
    pub pixel_obs: Vec<[[f64; 4]; 3]>,
    /// Measurement mode: per sample, per channel, 1/σ of the four pixels (model units⁻¹).
    pub inv_sigma: Vec<[[f64; 4]; 3]>,
    /// Per virtual sample, the weight W_m of its squared residual (module doc).
    pub virtual_weight: Vec<f64>,
    /// The box of the unknowns.
    pub bounds: Bounds,
    /// Measurement-mode priors.
    pub priors: Priors,
    /// Huber-downweight outlying samples ([`Problem::downweight_outliers`]): only with the
    /// clusters' virtual samples, which anchor the lobe — without them, a highlight the current
    /// lobe misses would itself look like an outlier and the lobe could run away from it.
    pub robust: bool,
    /// Sensor gain, DN per electron (measurement-mode variances).
    dn_per_electron: f64,
    /// Signal-independent variance per analyser pixel, DN² (read noise² + 1/12 quantisation).
    floor_variance_dn2: f64,
}

/// Reusable per-vertex buffers (no allocation inside the LM loop).
pub(super) struct Scratch<T> {
    pub units: Vec<UnitSample<T>>,
    /// Measurement mode: per sample, the four analyser pixels of each unit lobe (diffuse,
    /// single scattering, specular), from `units` and the sample's pixel rows.
    pub pixels: Vec<[[T; 4]; 3]>,
    pub virt: Vec<(T, T)>,
}

impl<T> Scratch<T> {
    pub fn new(samples: usize, virtuals: usize) -> Self {
        Self {
            units: Vec::with_capacity(samples),
            pixels: Vec::with_capacity(samples),
            virt: Vec::with_capacity(virtuals),
        }
    }
}

/// The shared median of an owned vector, 0 when empty (a scale that then stays at its floor).
fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    ellipso_model::stats::median(&mut v)
}

impl<'a> Problem<'a> {
    /// Prepares `vertex`'s samples; samples whose view index is out of range or whose geometry
    /// is degenerate are skipped.
    pub fn new(
        views: &[ViewGeometry],
        vertex: &VertexSamples,
        colour: bool,
        guide: &'a VertexGuide,
        config: &SolverConfig,
    ) -> Self {
        let virtuals = guide.virtual_samples.as_slice();
        let channels = if colour { 3 } else { 1 };
        let mut frames = Vec::with_capacity(vertex.samples.len());
        let mut obs = Vec::with_capacity(vertex.samples.len());
        let mut normalisers = Vec::with_capacity(vertex.samples.len());
        for s in &vertex.samples {
            let finite = s.channels.iter().flatten().all(|v| v.is_finite())
                && s.normaliser.is_finite()
                && s.normaliser > 0.0;
            let Some(view) = views.get(s.view as usize) else {
                continue;
            };
            let Some(f) = SampleFrames::new(view, vertex.position_world) else {
                continue;
            };
            if !finite {
                continue;
            }
            frames.push(f);
            obs.push(s.channels.map(|c| c.map(f64::from)));
            normalisers.push(f64::from(s.normaliser));
        }
        // Colour weights: the vertex's mean diffuse colour, normalised (docs/model.md §11
        // "Monochrome projection").
        let mut colour_weights = [1.0, 0.0, 0.0];
        if colour {
            let sums: [f64; 3] =
                core::array::from_fn(|c| obs.iter().map(|o| o[c][0].max(0.0)).sum::<f64>());
            let total: f64 = sums.iter().sum();
            colour_weights = if total > 0.0 {
                sums.map(|v| v / total)
            } else {
                [1.0 / 3.0; 3]
            };
        }
        let mono: Vec<[f64; 3]> = obs
            .iter()
            .map(|o| core::array::from_fn(|k| (0..3).map(|c| colour_weights[c] * o[c][k]).sum()))
            .collect();
        let n = obs.len();
        let (mut w_int, mut w_dop) = (vec![1.0; n], vec![1.0; n]);
        if config.noise_weighting && n > 0 {
            // Shot-noise-limited variances in model units, up to one common gain constant:
            // a channel ∝ s0/N, the DoP ratio ∝ 2/(s0·N) (two noisy channels over s0). Both are
            // divided by the same constant (mean of N/s0), so the losses keep their statistical
            // proportion and the λ's act on top. s0 floored at 1e-6 model units.
            for k in 0..n {
                let s0 = (mono[k][0] + mono[k][1]).max(1e-6);
                w_int[k] = normalisers[k] / s0;
                w_dop[k] = 0.5 * normalisers[k] * s0;
            }
            let mean = w_int.iter().sum::<f64>() / n as f64;
            for w in [&mut w_int, &mut w_dop] {
                w.iter_mut().for_each(|v| *v /= mean);
            }
        }
        let pixel_obs: Vec<[[f64; 4]; 3]> = obs.iter().map(|o| o.map(pixels_of)).collect();
        let has_virtual = !virtuals.is_empty();
        let data_scale = obs
            .iter()
            .flat_map(|o| o.iter().take(channels))
            .flat_map(|c| c[..3].iter())
            .map(|v| v * v)
            .sum::<f64>();
        let measurement = config.loss == LossMode::Measurement;
        let dn_per_electron = config.sensor.dn_per_electron.max(1e-12);
        let floor_variance_dn2 = config.sensor.read_noise_dn.powi(2) + 1.0 / 12.0;
        // Virtual-sample weights (module doc).
        let lambda_g = config.lambda_g.clamp(0.0, 0.99);
        let virtual_weight: Vec<f64> = if measurement {
            let n_bar = median(normalisers.clone()).max(1e-12);
            let s0_bar = median(mono.iter().map(|m| (m[0] + m[1]).max(0.0)).collect());
            let rows = (n * channels).max(1) as f64;
            virtuals
                .iter()
                .map(|v| {
                    let value = v.specular.iter().take(channels).sum::<f64>() / channels as f64;
                    let var = (dn_per_electron * n_bar * (s0_bar + value.max(0.0))
                        + 2.0 * floor_variance_dn2)
                        / (n_bar * n_bar);
                    rows / channels as f64 * v.weight.max(0.0) / (1.0 - lambda_g) / var
                })
                .collect()
        } else {
            virtuals
                .iter()
                .map(|v| config.lambda_s * n as f64 * v.weight.max(0.0))
                .collect()
        };
        let bounds = Bounds::new(config, guide);
        let priors = if measurement {
            let eta = match guide.eta_prior {
                Some([c, sd]) => Prior::new(c, sd),
                None => Prior::new(config.eta_prior[0], config.eta_prior[1]),
            };
            let ln_prior = |p: [f64; 2]| Prior::new(p[0].max(1e-6).ln(), p[1]);
            let normal = unit3(vertex.normal_world)
                .filter(|_| config.normal_prior_deg > 0.0)
                .map(|n0| {
                    let (t1, t2) = tangent_basis(n0);
                    (t1, t2, 1.0 / config.normal_prior_deg.to_radians())
                });
            Priors {
                eta,
                ln_sigma_s: ln_prior(config.sigma_s_prior),
                ln_sigma_ss: ln_prior(config.sigma_ss_prior),
                normal,
            }
        } else {
            Priors::default()
        };
        Self {
            frames,
            obs,
            mono,
            w_int,
            w_dop,
            normalisers,
            virtuals,
            channels,
            colour_weights,
            lambda_psi: config.lambda_psi,
            lambda_d: config.lambda_d,
            lambda_s_real: if has_virtual {
                config.lambda_s * (1.0 - lambda_g)
            } else {
                config.lambda_s
            },
            lambda_phi: config.lambda_phi,
            data_scale,
            loss: config.loss,
            inv_sigma: vec![[[0.0; 4]; 3]; n],
            pixel_obs,
            virtual_weight,
            bounds,
            priors,
            robust: measurement && !virtuals.is_empty(),
            dn_per_electron,
            floor_variance_dn2,
        }
        .with_initial_weights()
    }

    /// The same problem on the samples `keep` (indices into this one, in order): a coarse
    /// level for the solver's first iterations. Weights, priors and bounds carry over.
    pub fn subset(&self, keep: &[usize]) -> Self {
        let obs: Vec<[[f64; OBSERVATION_CHANNELS]; 3]> =
            keep.iter().map(|&k| self.obs[k]).collect();
        let data_scale = obs
            .iter()
            .flat_map(|o| o.iter().take(self.channels))
            .flat_map(|c| c[..3].iter())
            .map(|v| v * v)
            .sum::<f64>();
        Self {
            frames: keep.iter().map(|&k| self.frames[k]).collect(),
            obs,
            mono: pick(keep, &self.mono),
            w_int: pick(keep, &self.w_int),
            w_dop: pick(keep, &self.w_dop),
            normalisers: pick(keep, &self.normalisers),
            virtuals: self.virtuals,
            channels: self.channels,
            colour_weights: self.colour_weights,
            lambda_psi: self.lambda_psi,
            lambda_d: self.lambda_d,
            lambda_s_real: self.lambda_s_real,
            lambda_phi: self.lambda_phi,
            data_scale,
            loss: self.loss,
            pixel_obs: pick(keep, &self.pixel_obs),
            inv_sigma: pick(keep, &self.inv_sigma),
            virtual_weight: self.virtual_weight.clone(),
            bounds: self.bounds,
            priors: self.priors,
            robust: self.robust,
            dn_per_electron: self.dn_per_electron,
            floor_variance_dn2: self.floor_variance_dn2,
        }
    }

    /// Number of real samples.
    pub fn len(&self) -> usize {
        self.obs.len()
    }

    /// Number of parameters (6 nonlinear + 2 albedos per colour channel).
    pub fn parameter_count(&self) -> usize {
        6 + 2 * self.channels
    }

    /// Number of residuals [`Problem::evaluate`] emits.
    pub fn residual_count(&self) -> usize {
        let per_sample = match self.loss {
            LossMode::Paper => 2 * self.channels + 3,
            LossMode::Measurement => 4 * self.channels,
        };
        self.len() * per_sample + self.virtuals.len() * self.channels + self.priors.count()
    }
}

/// The entries `keep` of `v`, in order.
fn pick<T: Copy>(keep: &[usize], v: &[T]) -> Vec<T> {
    keep.iter().map(|&k| v[k]).collect()
}

/// A unit vector, or `None` for a zero or non-finite one.
fn unit3(v: [f64; 3]) -> Option<[f64; 3]> {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (l.is_finite() && l > 1e-12).then(|| v.map(|x| x / l))
}
