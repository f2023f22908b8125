//! The solver's settings: which loss it minimises ([`LossMode`]), how much effort it spends on
//! starts and passes ([`Effort`]), the sensor noise the measurement loss whitens by
//! ([`SensorNoiseModel`]), and every tolerance, weight, bound, prior and flag threshold in
//! [`SolverConfig`].
//!
//! Contract: `Default` gives the documented values (each field's doc names its default and why);
//! the presets ([`SolverConfig::reference`], [`SolverConfig::paper`], [`SolverConfig::fast`])
//! and modifiers ([`SolverConfig::without_priors`], [`SolverConfig::with_fast_effort`]) change
//! only the fields they name. How the solver uses each field is in the `solve` module doc.

/// Which least-squares loss the solver minimises (docs/fit-solver.md, docs/model.md §11 "Loss
/// terms").
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum LossMode {
    /// The paper's four terms L_d, L_s, L_ψ (DoP ratio), L_φ (azimuth with the observed DP),
    /// weighted by the λ's (reproduction; the DoP ratio is Rice-biased on dark samples).
    Paper,
    /// The observation channels I^d, I^s, I^α themselves, each residual whitened by its
    /// predicted shot + read noise (iteratively reweighted); no ratio of noisy quantities, so the
    /// estimate is asymptotically unbiased. λψ, λd, λφ and `noise_weighting` do not apply.
    Measurement,
}

/// How much effort the solver spends on starts and passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Effort {
    /// Every cold start is run to convergence and every pass is run (the first solver's
    /// behaviour; ~4 LM runs per cold vertex).
    Exhaustive,
    /// Cold starts are ranked by their initial cost and LM runs from the best; the others are
    /// tried only when that run ends unconverged, with a roughness at its bound (`AtBound`'s σ
    /// margins), or (measurement mode) with a reduced χ² above `restart_reduced_chi2`. A later pass runs only when the previous one did not converge.
    Adaptive,
}

/// The sensor's noise, for the measurement-mode weights (DN = N × model units).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SensorNoiseModel {
    /// DN per photo-electron (shot-noise variance of a pixel = g·DN).
    pub dn_per_electron: f64,
    /// Read noise, DN RMS (quantisation's 1/12 DN² is added to its square).
    pub read_noise_dn: f64,
}

impl Default for SensorNoiseModel {
    /// The shipped IMX250 scenes at 0 dB: 4095 DN / 10 500 e⁻ full well ≈ 0.39 DN/e⁻, 2.3 e⁻
    /// read noise ≈ 0.9 DN. Only the ratio of read to shot noise matters for the fit (the
    /// overall scale cancels), so a gain off by 2× changes the weights of the darkest samples
    /// only.
    fn default() -> Self {
        Self {
            dn_per_electron: 0.39,
            read_noise_dn: 0.9,
        }
    }
}

/// Solver settings. `Default` gives the documented values.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolverConfig {
    /// The loss (default [`LossMode::Measurement`]; docs/fit-solver.md has the measurement).
    pub loss: LossMode,
    /// Starts and passes (default [`Effort::Adaptive`]).
    pub effort: Effort,
    /// Sensor noise for the measurement-mode weights.
    pub sensor: SensorNoiseModel,
    /// LM iteration cap per pass (default 50).
    pub max_iterations: u32,
    /// LM passes from the best start; each later pass restarts the damping (default 2; with
    /// [`Effort::Adaptive`] a later pass runs only after an unconverged one).
    pub passes: u32,
    /// Samples of the coarse level of a cold start (default 24; 0 disables): a vertex with at
    /// least twice as many first runs its starts on that many samples spread along the capture,
    /// then LM on all of them from the result (coarse to fine).
    pub coarse_samples: usize,
    /// Cold starts (η, σ_s, σ_ss) tried without `init` (default (1.5, 0.1, 0.3) and
    /// (1.5, 0.4, 0.8)); see [`Effort`].
    pub cold_starts: Vec<[f64; 3]>,
    /// Adaptive effort, measurement mode: a cold-start result with reduced χ² above this tries
    /// the other cold starts (default 4: ≈ 1 at a good fit with the right sensor model; 4 leaves
    /// room for a gain off by 2× and mild model error).
    pub restart_reduced_chi2: f64,
    /// LM also stops when the Gauss–Newton decrement (the cost decrease the undamped step
    /// predicts) is below this × s², s² = cost/(m − p): the parameters are then within ~√tol
    /// standard errors of the local optimum (default 1e-3; 0 disables).
    pub chi2_tolerance: f64,
    /// Weight of L_ψ (DoP) (default 10).
    pub lambda_psi: f64,
    /// Weight of L_d (default 1).
    pub lambda_d: f64,
    /// Weight of L_s (default 1).
    pub lambda_s: f64,
    /// Weight of L_φ (azimuth) (default 1).
    pub lambda_phi: f64,
    /// λg: total weight of virtual samples relative to real specular ones (default 0.1).
    pub lambda_g: f64,
    /// Floor of both roughnesses (default 0.01; docs/model.md §12, σ → 0).
    pub sigma_min: f64,
    /// Range of η (default [1.1, 3], the paper's bounds; dielectrics of everyday materials lie
    /// in it, and η → 1 — no polarisation — is flagged at the lower end).
    pub eta_bounds: [f64; 2],
    /// Upper bound of ρ_s, ρ_ss and ρ_d, model units (default 5: the paper caps ρ_s at 5·mean N
    /// in raw units; our samples are divided by N, so 5 is the same cap. Physical albedos are
    /// ≤ 1, so 5 leaves room for a radiometric calibration off by that much).
    pub albedo_cap: f64,
    /// Weak prior on η, (mean, sd) (default (1.5, 0.5)); replaced by a guide's pooled prior.
    pub eta_prior: [f64; 2],
    /// Prior on σ_s, (median, sd of ln σ_s) (default (0.2, 1.2): 95 % within ×10.5 of 0.2).
    pub sigma_s_prior: [f64; 2],
    /// Prior on σ_ss, (median, sd of ln σ_ss) (default (0.4, 1.2)).
    pub sigma_ss_prior: [f64; 2],
    /// 1σ width of the prior cone of the normal about the mesh normal, degrees (default 10;
    /// 0 disables).
    pub normal_prior_deg: f64,
    /// Weight residuals by shot-noise inverse variance from N (default false: the paper's
    /// uniform weights).
    pub noise_weighting: bool,
    /// Minimum usable samples (default 12 = `GateConfig::default().min_views`).
    pub min_views: usize,
    /// LM stops when the relative cost decrease of an accepted step is below this (1e-10).
    pub relative_tolerance: f64,
    /// LM stops when the step is below this relative to the raw parameters (1e-9).
    pub step_tolerance: f64,
    /// Initial Marquardt damping (1e-3).
    pub initial_damping: f64,
    /// `EtaUnidentifiable` when max |∂DoP/∂η| is below this (0.02 ≈ 25° view at η = 1.5).
    pub min_eta_sensitivity: f64,
    /// `EtaUnidentifiable` when the std error of η exceeds this (0.05).
    pub max_eta_std_error: f64,
    /// `GrazingOnly` when all views are beyond this angle from the normal, degrees (65).
    pub grazing_only_deg: f64,
    /// `Dark` when the mean diffuse signal is below this many DN (8).
    pub dark_signal_dn: f64,
    /// `Saturated` when saturated samples exceed this fraction of kept + saturated (0.05).
    pub saturated_fraction: f64,
    /// `AtBound` margin on η from either end of its range (0.005).
    pub bound_margin_eta: f64,
    /// `AtBound` margin on σ_s above σ_min and σ_ss below 1 (1e-3).
    pub bound_margin_sigma: f64,
    /// Prior (η, σ_s, σ_ss, ρ_s, ρ_ss) for vertices that cannot be fitted (1.5, 0.2, 0.5, 0.5, 0).
    pub prior: [f64; 5],
}

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            loss: LossMode::Measurement,
            effort: Effort::Adaptive,
            sensor: SensorNoiseModel::default(),
            max_iterations: 50,
            passes: 2,
            coarse_samples: 24,
            cold_starts: vec![[1.5, 0.1, 0.3], [1.5, 0.4, 0.8]],
            restart_reduced_chi2: 4.0,
            chi2_tolerance: 1e-3,
            lambda_psi: 10.0,
            lambda_d: 1.0,
            lambda_s: 1.0,
            lambda_phi: 1.0,
            lambda_g: 0.1,
            sigma_min: 0.01,
            eta_bounds: [1.1, 3.0],
            albedo_cap: 5.0,
            eta_prior: [1.5, 0.5],
            sigma_s_prior: [0.2, 1.2],
            sigma_ss_prior: [0.4, 1.2],
            normal_prior_deg: 10.0,
            noise_weighting: true,
            min_views: 12,
            relative_tolerance: 1e-10,
            step_tolerance: 1e-9,
            initial_damping: 1e-3,
            min_eta_sensitivity: 0.02,
            max_eta_std_error: 0.05,
            grazing_only_deg: 65.0,
            dark_signal_dn: 8.0,
            saturated_fraction: 0.05,
            bound_margin_eta: 0.005,
            bound_margin_sigma: 1e-3,
            prior: [1.5, 0.2, 0.5, 0.5, 0.0],
        }
    }
}

impl SolverConfig {
    /// The first solver's settings, for reproduction and before/after comparisons: paper loss
    /// (noise-weighted), every cold start and pass run, 100 iterations, only the relative and
    /// step tolerances.
    pub fn reference() -> Self {
        Self {
            loss: LossMode::Paper,
            effort: Effort::Exhaustive,
            max_iterations: 100,
            chi2_tolerance: 0.0,
            ..Self::default()
        }
    }

    /// The paper's loss with the default (adaptive) effort.
    pub fn paper() -> Self {
        Self {
            loss: LossMode::Paper,
            ..Self::default()
        }
    }

    /// Throughput preset (docs/fit-solver.md has its measured cost in accuracy): measurement
    /// loss, one start and one pass, at most 12 iterations, χ² tolerance 1e-2 (~0.1 σ), no
    /// fallback restart. Meant for many-vertex runs and warm-started passes.
    pub fn fast() -> Self {
        Self::default().with_fast_effort()
    }

    /// These settings without any prior (infinite widths, no normal cone): the data alone
    /// decides (tests of exact recovery, reproductions of the first solver).
    pub fn without_priors(&self) -> Self {
        Self {
            eta_prior: [self.eta_prior[0], f64::INFINITY],
            sigma_s_prior: [self.sigma_s_prior[0], f64::INFINITY],
            sigma_ss_prior: [self.sigma_ss_prior[0], f64::INFINITY],
            normal_prior_deg: 0.0,
            ..self.clone()
        }
    }

    /// These settings with the [`SolverConfig::fast`] preset's effort (iterations, passes,
    /// tolerance, no fallback restart); loss, sensor, bounds and priors unchanged.
    pub fn with_fast_effort(&self) -> Self {
        Self {
            max_iterations: 12,
            passes: 1,
            chi2_tolerance: 1e-2,
            restart_reduced_chi2: f64::INFINITY,
            ..self.clone()
        }
    }
}
