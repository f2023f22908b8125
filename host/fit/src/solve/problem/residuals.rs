//! Evaluation of one vertex's residual vector, in the emission order the `problem` module doc
//! gives for each loss, generic over the scalar (f64 cost, dual-number Jacobians): the unit
//! lobes of every sample and virtual sample at a point, the data rows of the paper and
//! measurement losses, the prior rows, and the albedos by box-constrained projection when they
//! are not given.
//!
//! Contract: [`Problem::evaluate`] emits exactly [`Problem::residual_count`] values; a sample
//! the normal makes back-facing contributes zero lobes (the model returns no light for it).

use ellipso_model::optics::Real;

use crate::model::{
    LobeScalar, TangentNormal, UnitSample, coaxial_unit_specular, predicted_pixels as pixel_pred,
    unit_sample,
};
use crate::solve::LossMode;
use crate::solve::albedos::AlbedoSystem;

use super::{Albedos, Chart, Nonlinear, Problem, Scratch};

impl Problem<'_> {
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
