//! The unknowns of one vertex's problem in physical units ([`Nonlinear`]: η, σ_s, σ_ss and the
//! normal's tangent coordinates p, q), the box they live in ([`Bounds`], docs/fit-solver.md
//! "Bounds") and the Gaussian priors on them ([`Prior`], [`Priors`]; measurement mode only).
//!
//! Contract: [`Bounds::new`] always gives a non-empty box (η_max > η_min, σ_s's floor ≤ 0.9,
//! a positive albedo cap); a [`Prior`] exists only with a finite centre and a finite positive
//! width, and its row is (value − centre)/sd, in standard deviations.

use ellipso_model::optics::{Dual, Real};

use crate::data::VertexGuide;
use crate::solve::SolverConfig;

/// The nonlinear unknowns in physical units (η, σ_s, σ_ss, tangent p, q).
#[derive(Clone, Copy, Debug)]
pub(in super::super) struct Nonlinear<T> {
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
pub(in super::super) struct Bounds {
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
pub(in super::super) struct Prior {
    pub centre: f64,
    pub sd: f64,
}

impl Prior {
    pub(super) fn new(centre: f64, sd: f64) -> Option<Self> {
        (centre.is_finite() && sd.is_finite() && sd > 0.0).then_some(Self { centre, sd })
    }

    pub(super) fn row<T: Real>(&self, value: T) -> T {
        (value - T::from_f64(self.centre)) / T::from_f64(self.sd)
    }
}

/// The priors of one vertex (measurement mode).
#[derive(Clone, Copy, Debug, Default)]
pub(in super::super) struct Priors {
    pub eta: Option<Prior>,
    pub ln_sigma_s: Option<Prior>,
    pub ln_sigma_ss: Option<Prior>,
    /// The prior normal's tangent basis and 1/sd (radians⁻¹).
    pub normal: Option<([f64; 3], [f64; 3], f64)>,
}

impl Priors {
    pub(super) fn count(&self) -> usize {
        usize::from(self.eta.is_some())
            + usize::from(self.ln_sigma_s.is_some())
            + usize::from(self.ln_sigma_ss.is_some())
            + 2 * usize::from(self.normal.is_some())
    }
}
