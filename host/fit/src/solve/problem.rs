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

use ellipso_model::optics::{Dual, Real};

use super::super::data::{
    OBSERVATION_CHANNELS, VertexGuide, VertexSamples, ViewGeometry, VirtualSample,
};
pub(super) use super::super::model::Chart;
use super::super::model::{
    LobeScalar, SampleFrames, TangentNormal, UnitSample, coaxial_unit_specular,
    observed_pixels as pixels_of, predicted_pixels as pixel_pred, tangent_basis, unit_sample,
};
use super::albedos::AlbedoSystem;
pub(super) use super::albedos::Albedos;
use super::{LossMode, SolverConfig};

/// The nonlinear unknowns in physical units (η, σ_s, σ_ss, tangent p, q).
#[derive(Clone, Copy, Debug)]
pub(super) struct Nonlinear<T> {
    pub eta: T,
    pub sigma_s: T,
    pub sigma_ss: T,
    pub p: T,
    pub q: T,
}

impl Nonlinear<f64> {
    /// These values as dual variables in `slots` (η, σ_s, σ_ss, p, q), for derivatives with
    /// respect to the physical unknowns.
    pub fn seeded<const N: usize>(&self, slots: [usize; 5]) -> Nonlinear<Dual<N>> {
        let v = |re: f64, k: usize| Dual::variable(re, slots[k]);
        Nonlinear {
            eta: v(self.eta, 0),
            sigma_s: v(self.sigma_s, 1),
            sigma_ss: v(self.sigma_ss, 2),
            p: v(self.p, 3),
            q: v(self.q, 4),
        }
    }
}

/// The box every unknown of one vertex lives in (docs/fit-solver.md, "Bounds").
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Bounds {
    /// η ∈ [eta_min, eta_max].
    pub eta_min: f64,
    pub eta_max: f64,
    /// σ_s ∈ [sigma_s_min, 1] (the solver's floor or the cluster's σs/2, whichever is larger).
    pub sigma_s_min: f64,
    /// ρ_s, ρ_ss and ρ_d ∈ [0, albedo_cap].
    pub albedo_cap: f64,
}

impl Bounds {
    /// The bounds of a vertex under `config` and its `guide`.
    pub fn new(config: &SolverConfig, guide: &VertexGuide) -> Self {
        let [eta_min, eta_max] = config.eta_bounds;
        let floor = if guide.sigma_s_floor.is_finite() {
            guide.sigma_s_floor
        } else {
            0.0
        };
        Self {
            eta_min,
            eta_max: eta_max.max(eta_min + 1e-6),
            // Keep σ_s's interval open: at most 0.9 (a cluster σs/2 is at most 0.5).
            sigma_s_min: config.sigma_min.max(floor).min(0.9),
            albedo_cap: config.albedo_cap.max(1e-6),
        }
    }
}

/// One Gaussian prior row: (value − centre)/sd.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Prior {
    pub centre: f64,
    pub sd: f64,
}

impl Prior {
    fn new(centre: f64, sd: f64) -> Option<Self> {
        (centre.is_finite() && sd.is_finite() && sd > 0.0).then_some(Self { centre, sd })
    }

    fn row<T: Real>(&self, value: T) -> T {
        (value - T::from_f64(self.centre)) / T::from_f64(self.sd)
    }
}

/// The priors of one vertex (measurement mode).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Priors {
    pub eta: Option<Prior>,
    pub ln_sigma_s: Option<Prior>,
    pub ln_sigma_ss: Option<Prior>,
    /// The prior normal's tangent basis and 1/sd (radians⁻¹).
    pub normal: Option<([f64; 3], [f64; 3], f64)>,
}

impl Priors {
    fn count(&self) -> usize {
        usize::from(self.eta.is_some())
            + usize::from(self.ln_sigma_s.is_some())
            + usize::from(self.ln_sigma_ss.is_some())
            + 2 * usize::from(self.normal.is_some())
    }
}

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

/// Huber threshold of [`Problem::downweight_outliers`], in robust standard deviations (3: a
/// Gaussian sample is downweighted with probability 0.3 %).
pub(super) const HUBER_K: f64 = 3.0;

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

    /// Measurement mode: weights from the observations themselves (floored at 0), used only
    /// until [`Problem::reweight`] replaces them with the model's prediction at the start of
    /// every LM run (observation-derived weights correlate with the noise and bias the fit).
    fn with_initial_weights(mut self) -> Self {
        if self.loss == LossMode::Measurement {
            let predicted = self.pixel_obs.clone();
            let _ = self.set_weights(|k, c| predicted[k][c]);
        }
        self
    }

    /// The predicted noise of one sample's four analyser pixels from their predicted
    /// intensities `i` (model units): for a pixel of expected model intensity I,
    /// Var = (g·N·I + σ_floor²)/N² in model units², with g DN per electron (shot noise: g·DN)
    /// and σ_floor² = read noise² + 1/12 (quantisation), DN². Negative predictions are floored
    /// at 0. The prediction is capped at 4× the observation + 3σ_floor, so a model far off the
    /// data cannot buy itself small weights (a cap that only acts on gross misfits).
    fn inverse_sigma(&self, k: usize, c: usize, i: [f64; 4]) -> [f64; 4] {
        let n = self.normalisers[k];
        let g = self.dn_per_electron;
        let f = self.floor_variance_dn2;
        let o = &self.pixel_obs[k][c];
        // f > 0 and n > 0 (non-positive N are skipped in `new`): var > 0.
        core::array::from_fn(|j| {
            let pred = i[j].min(4.0 * o[j].max(0.0) + 3.0 * f.sqrt() / n).max(0.0);
            let var = (g * n * pred + f) / (n * n);
            1.0 / var.sqrt()
        })
    }

    /// Sets the weights from `predicted(sample, channel)`; returns the largest relative change
    /// of any 1/σ.
    fn set_weights(&mut self, predicted: impl Fn(usize, usize) -> [f64; 4]) -> f64 {
        let mut change: f64 = 0.0;
        for k in 0..self.len() {
            for c in 0..self.channels {
                let w = self.inverse_sigma(k, c, predicted(k, c));
                for (new, old) in w.iter().zip(&self.inv_sigma[k][c]) {
                    change = change.max(if *old > 0.0 {
                        (new / old - 1.0).abs()
                    } else {
                        1.0
                    });
                }
                self.inv_sigma[k][c] = w;
            }
        }
        change
    }

    /// Measurement mode: re-derives every residual's noise from the model's prediction at the
    /// point whose unit lobes are in `scratch` (an f64 evaluation just done) with `albedos`
    /// (ρ_s among them) — iteratively reweighted least squares, the weights held fixed inside each
    /// LM run (quasi-likelihood: consistent, unlike weights from the noisy data). No-op in
    /// paper mode. Returns the largest relative change of any 1/σ (0 in paper mode).
    pub fn reweight(&mut self, scratch: &Scratch<f64>, albedos: &Albedos<f64>) -> f64 {
        if self.loss != LossMode::Measurement || scratch.pixels.len() != self.len() {
            return 0.0;
        }
        let predicted: Vec<[[f64; 4]; 3]> = scratch
            .pixels
            .iter()
            .map(|[a, b, s]| {
                core::array::from_fn(|c| {
                    core::array::from_fn(|j| {
                        albedos.rho_d[c] * a[j] + albedos.rho_ss[c] * b[j] + albedos.rho_s * s[j]
                    })
                })
            })
            .collect();
        let change = self.set_weights(|k, c| predicted[k][c]);
        if self.robust {
            self.downweight_outliers(&predicted);
        }
        change
    }

    /// Huber downweighting of whole samples (Huber, *Robust Statistics*, 1981): a sample's
    /// standardised residual z_k = RMS over its pixel rows of the whitened residual at the
    /// current prediction is compared with the vertex's robust scale s = 1.4826·median(z)
    /// (floored at 1, the value at a perfect fit); beyond [`HUBER_K`]·s every 1/σ of the sample
    /// is scaled by √(k·s/z_k), the Huber weight k·s/z_k on its squared residual. A pixel that
    /// sees something the model of one surface point cannot explain — the board behind a
    /// silhouette, a neighbouring material across a boundary a misplaced vertex straddles —
    /// then costs linearly, not quadratically, and cannot drag the lobe and η to a bound.
    fn downweight_outliers(&mut self, predicted: &[[[f64; 4]; 3]]) {
        let n = self.len();
        if n == 0 {
            return;
        }
        let z: Vec<f64> = (0..n)
            .map(|k| {
                let mut sum = 0.0;
                let rows = predicted[k]
                    .iter()
                    .zip(&self.pixel_obs[k])
                    .zip(&self.inv_sigma[k])
                    .take(self.channels);
                for ((pred, obs), w) in rows {
                    for ((p, o), w) in pred.iter().zip(obs).zip(w) {
                        let r = w * (p - o);
                        sum += r * r;
                    }
                }
                (sum / (4 * self.channels) as f64).sqrt()
            })
            .collect();
        let scale = (1.4826 * median(z.clone())).max(1.0);
        let limit = HUBER_K * scale;
        for (k, zk) in z.iter().enumerate() {
            if *zk > limit && zk.is_finite() {
                let factor = (limit / zk).sqrt();
                for c in 0..self.channels {
                    self.inv_sigma[k][c].iter_mut().for_each(|w| *w *= factor);
                }
            }
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

    /// Evaluates every residual into `sink` (in the documented order) and returns the albedos
    /// used: `given`, or the per-channel box-constrained least-squares projection
    /// (docs/model.md §11 "Unknowns") of the data (+ virtual) residuals when `given` is `None`.
    pub fn evaluate<T: LobeScalar>(
        &self,
        chart: &Chart,
        x: &Nonlinear<T>,
        given: Option<Albedos<T>>,
        scratch: &mut Scratch<T>,
        sink: &mut impl FnMut(T),
    ) -> Albedos<T> {
        let normal = chart.normal(x.p, x.q);
        self.units_at(chart, x, self.loss == LossMode::Paper, scratch);
        self.virtuals_at(x, scratch);
        let albedos = match given {
            Some(a) => a,
            None => self.project(scratch),
        };
        let k = T::from_f64;
        match self.loss {
            LossMode::Paper => {
                for (i, u) in scratch.units.iter().enumerate() {
                    self.paper_residuals(i, u, &albedos, sink);
                }
            }
            LossMode::Measurement => {
                for (i, [a, b, s]) in scratch.pixels.iter().enumerate() {
                    for c in 0..self.channels {
                        let (o, w) = (&self.pixel_obs[i][c], &self.inv_sigma[i][c]);
                        let (rd, rss) = (albedos.rho_d[c], albedos.rho_ss[c]);
                        for j in 0..4 {
                            let pred = rd * a[j] + rss * b[j] + albedos.rho_s * s[j];
                            sink(k(w[j]) * (pred - k(o[j])));
                        }
                    }
                }
            }
        }
        for (m, v) in self.virtuals.iter().enumerate() {
            let (b, s) = scratch.virt[m];
            let w = k(self.virtual_weight[m].sqrt());
            for c in 0..self.channels {
                sink(w * (albedos.rho_ss[c] * b + albedos.rho_s * s - k(v.specular[c])));
            }
        }
        self.prior_rows(x, normal, sink);
        albedos
    }

    /// Fills `scratch.units` with every sample's unit lobes at `chart` and `x` (zero where the
    /// normal makes the sample back-facing: the model returns no light); `with_dop` also fills
    /// their DoP fields (`UnitSample::dop_diffuse`, `cos_theta_o`).
    pub fn units_at<T: LobeScalar>(
        &self,
        chart: &Chart,
        x: &Nonlinear<T>,
        with_dop: bool,
        scratch: &mut Scratch<T>,
    ) {
        let tangent = TangentNormal {
            chart: *chart,
            p: x.p,
            q: x.q,
        };
        let zero = T::zero();
        let none = UnitSample {
            diffuse: [zero; 3],
            single_scattering: [zero; 3],
            specular: [zero; 3],
            cos_theta_o: zero,
            dop_diffuse: zero,
            front_facing: false,
        };
        scratch.units.clear();
        scratch.units.extend(self.frames.iter().map(|f| {
            unit_sample(f, &tangent, x.eta, x.sigma_s, x.sigma_ss, with_dop).unwrap_or(none)
        }));
        scratch.pixels.clear();
        if self.loss == LossMode::Measurement {
            scratch
                .pixels
                .extend(self.frames.iter().zip(&scratch.units).map(|(f, u)| {
                    let rows = &f.pixel_rows;
                    [
                        pixel_pred(rows, u.diffuse),
                        pixel_pred(rows, u.single_scattering),
                        pixel_pred(rows, u.specular),
                    ]
                }));
        }
    }

    /// Fills `scratch.virt` with every virtual sample's two unit reflection lobes at `x`.
    pub fn virtuals_at<T: LobeScalar>(&self, x: &Nonlinear<T>, scratch: &mut Scratch<T>) {
        scratch.virt.clear();
        scratch.virt.extend(self.virtuals.iter().map(|v| {
            coaxial_unit_specular(v.cos_theta_h.clamp(0.0, 1.0), x.eta, x.sigma_s, x.sigma_ss)
        }));
    }

    /// The prior rows (module doc), in standard deviations.
    pub fn prior_rows<T: Real>(
        &self,
        x: &Nonlinear<T>,
        normal: ellipso_model::optics::Vec3<T>,
        sink: &mut impl FnMut(T),
    ) {
        let p = &self.priors;
        if let Some(prior) = &p.eta {
            sink(prior.row(x.eta));
        }
        if let Some(prior) = &p.ln_sigma_s {
            sink(prior.row(x.sigma_s.ln()));
        }
        if let Some(prior) = &p.ln_sigma_ss {
            sink(prior.row(x.sigma_ss.ln()));
        }
        if let Some((t1, t2, inv_sd)) = &p.normal {
            // |n0 + p t1 + q t2| ≥ 1 (the chart's tangents are orthogonal to its unit n0).
            let len = normal.norm_squared().sqrt();
            let k = T::from_f64;
            let along = |t: &[f64; 3]| {
                (normal.x * k(t[0]) + normal.y * k(t[1]) + normal.z * k(t[2])) / len * k(*inv_sd)
            };
            sink(along(t1));
            sink(along(t2));
        }
    }

    /// The diffuse-only observation of sample `i` (the data minus the model's reflection: the
    /// paper's I^β = I^s − SS_model generalised to all three channels, docs/model.md §6
    /// "Observation channels"; monochrome projection of §11 "Monochrome projection"):
    /// (I^d_D, I^β, I^α_D, DP = √(I^α_D² + I^β²)).
    fn diffuse_only<T: Real>(&self, i: usize, u: &UnitSample<T>, albedos: &Albedos<T>) -> [T; 4] {
        let rho_s = albedos.rho_s;
        let k = T::from_f64;
        let rho_ss_mono = (0..self.channels).fold(T::zero(), |acc, c| {
            acc + albedos.rho_ss[c] * k(self.colour_weights[c])
        });
        let m = &self.mono[i];
        let refl = |j: usize| rho_ss_mono * u.single_scattering[j] + rho_s * u.specular[j];
        let d_obs = k(m[0]) - refl(0);
        let beta = k(m[1]) - refl(1);
        let alpha = k(m[2]) - refl(2);
        let dp = (alpha.sq() + beta.sq()).sqrt_clamped();
        [d_obs, beta, alpha, dp]
    }

    /// The observed diffuse DoP of sample `i` (DP over s0 of the diffuse-only light
    /// s0 = I^d_D + I^β), `None` below 1e-12 model units of s0.
    fn observed_dop<T: Real>(
        &self,
        i: usize,
        u: &UnitSample<T>,
        albedos: &Albedos<T>,
    ) -> Option<T> {
        let [d_obs, beta, _, dp] = self.diffuse_only(i, u, albedos);
        let s0 = d_obs + beta;
        (s0.re() > 1e-12).then(|| dp / s0)
    }

    /// The paper-mode residuals of sample `i` (module doc).
    #[expect(
        clippy::needless_range_loop,
        reason = "observations and albedos are parallel arrays indexed by channel"
    )]
    fn paper_residuals<T: Real>(
        &self,
        i: usize,
        u: &UnitSample<T>,
        albedos: &Albedos<T>,
        sink: &mut impl FnMut(T),
    ) {
        let k = T::from_f64;
        let rho_s = albedos.rho_s;
        let o = &self.obs[i];
        let wd = k((self.lambda_d * self.w_int[i]).sqrt());
        let ws = k((self.lambda_s_real * self.w_int[i]).sqrt());
        for c in 0..self.channels {
            let pred = u.predict(albedos.rho_d[c], albedos.rho_ss[c], rho_s);
            sink(wd * (pred[0] - k(o[c][0])));
            sink(ws * (pred[1] - k(o[c][1])));
        }
        let [_, beta, alpha, dp] = self.diffuse_only(i, u, albedos);
        let w_psi = k((self.lambda_psi * self.w_dop[i]).sqrt());
        match self.observed_dop(i, u, albedos) {
            Some(dop) => sink(w_psi * (u.dop_diffuse - dop)),
            None => sink(T::zero()),
        }
        // Predicted direction of (I^α, I^β) of the diffuse lobe; ε = 1e-12 keeps it finite at
        // normal incidence, where DP → 0 and the residual carries no azimuth weight anyway.
        let (a_alpha, a_beta) = (u.diffuse[2], u.diffuse[1]);
        let norm = (a_alpha.sq() + a_beta.sq() + k(1e-24)).sqrt();
        let wp = k((self.lambda_phi * self.w_int[i]).sqrt());
        sink(wp * (alpha - a_alpha / norm * dp));
        sink(wp * (beta - a_beta / norm * dp));
    }

    /// Unweighted (model − observed) diffuse DoP of every sample with a defined DoP, at a
    /// point evaluated in f64 into `scratch` (both modes; for the polarisation-SNR flag).
    pub fn dop_residuals<'s>(
        &'s self,
        scratch: &'s Scratch<f64>,
        albedos: &Albedos<f64>,
    ) -> impl Iterator<Item = f64> + 's {
        let albedos = *albedos;
        scratch.units.iter().enumerate().filter_map(move |(i, u)| {
            self.observed_dop(i, u, &albedos)
                .map(|dop| u.dop_diffuse - dop)
        })
    }

    /// The albedos ρ_d, ρ_ss per colour channel and the shared ρ_s by exact box-constrained
    /// least squares over [0, cap] given the nonlinear unknowns (whose unit lobes are in
    /// `scratch`): the data (+ virtual) residuals, which are linear in them (`albedos.rs`).
    fn project<T: Real>(&self, scratch: &Scratch<T>) -> Albedos<T> {
        let k = T::from_f64;
        let mut sys = AlbedoSystem::new();
        match self.loss {
            LossMode::Paper => {
                for (i, u) in scratch.units.iter().enumerate() {
                    let wd = k(self.lambda_d * self.w_int[i]);
                    let ws = k(self.lambda_s_real * self.w_int[i]);
                    let (a, b, c) = (u.diffuse, u.single_scattering, u.specular);
                    for ch in 0..self.channels {
                        let o = &self.obs[i][ch];
                        sys.add_row(ch, wd, a[0], b[0], c[0], k(o[0]));
                        sys.add_row(ch, ws, a[1], b[1], c[1], k(o[1]));
                    }
                }
                for (m, v) in self.virtuals.iter().enumerate() {
                    let (b, s) = scratch.virt[m];
                    let w = k(self.virtual_weight[m]);
                    for ch in 0..self.channels {
                        sys.add_specular_row(ch, w, b, s, k(v.specular[ch]));
                    }
                }
            }
            LossMode::Measurement => self.measurement_rows(scratch, |c, w, [a, b, s], o| {
                sys.add_row(c, k(w), a, b, s, k(o))
            }),
        }
        sys.solve(self.channels, self.bounds.albedo_cap)
    }

    /// Measurement mode: every data and virtual row of the loss in emission order, as
    /// `row(c, w, [a, b, s], o)` with c the colour channel, w the weight of the squared
    /// residual (1/σ² of an analyser pixel; W_m of a virtual sample), the unit lobes' values at
    /// the row (diffuse, single scattering, specular; no diffuse for a virtual sample) and the
    /// observation. Reads the lobes of the last `units_at` and `virtuals_at` in `scratch`.
    pub fn measurement_rows<T: Real>(
        &self,
        scratch: &Scratch<T>,
        mut row: impl FnMut(usize, f64, [T; 3], f64),
    ) {
        for (i, [a, b, s]) in scratch.pixels.iter().enumerate() {
            for c in 0..self.channels {
                let (o, w) = (&self.pixel_obs[i][c], &self.inv_sigma[i][c]);
                for j in 0..4 {
                    row(c, w[j] * w[j], [a[j], b[j], s[j]], o[j]);
                }
            }
        }
        for (m, v) in self.virtuals.iter().enumerate() {
            let (b, s) = scratch.virt[m];
            for c in 0..self.channels {
                row(c, self.virtual_weight[m], [T::zero(), b, s], v.specular[c]);
            }
        }
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
