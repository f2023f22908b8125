//! Standard errors at the solution: covariance = s²·(JᵀJ)⁻¹, s² = cost/(m − p), with J the
//! Jacobian of the residuals over ALL parameters in their physical units (η, σ_s, σ_ss, ρ_s,
//! ρ_ss RGB, ρ_d RGB, normal tangent p, q; the albedos as free parameters, not projected).
//!
//! Differentiating directly in physical units equals propagating the raw-parameter covariance
//! through the reparameterisation wherever that map is invertible, and stays honest where a
//! sigmoid/softplus saturates (a propagated variance would collapse to 0 at a bound).
//! Identifiability: JᵀJ is Jacobi-scaled and eigen-decomposed; directions with eigenvalue below
//! [`NULL_RELATIVE`]·λ_max are null, and any parameter with a non-negligible component
//! (squared loading > 1e-6) in a null direction, or a zero column, gets `f64::INFINITY`.

use ellipso_model::optics::Dual;
use nalgebra::{DMatrix, SMatrix};

use super::LossMode;
use super::problem::{Albedos, Chart, Nonlinear, Problem, Scratch};

const N_ALL: usize = 12;
type AllDual = Dual<N_ALL>;

/// Eigenvalues below this fraction of the largest (after Jacobi scaling) are null directions:
/// a condition number above 1e12 leaves fewer than ~4 significant digits in f64.
pub(super) const NULL_RELATIVE: f64 = 1e-12;

/// The standard errors: the 10 material parameters (layout of `VertexFit::std_error`) and the
/// normal's 1σ angle in degrees.
pub(super) struct Uncertainty {
    pub std_error: [f64; 10],
    pub normal_std_error_deg: f64,
    /// (JᵀJ)⁻¹ of η without the s² scale: in the measurement loss, whose rows are whitened by
    /// the claimed noise and include the prior's row, the variance the data and the prior
    /// together leave η. Compared with the prior's own variance it says whether the data moved
    /// η at all (`solve/finish.rs`, `EtaUnidentifiable`); +inf where η is null.
    pub eta_variance_unscaled: f64,
}

/// Standard errors at (`x`, `albedos`) on `chart` (p = q = 0 at the solution).
pub(super) fn standard_errors(
    problem: &Problem,
    chart: &Chart,
    x: &Nonlinear<f64>,
    albedos: &Albedos<f64>,
) -> Uncertainty {
    let (cost, m, jtj) = if problem.loss == LossMode::Measurement {
        super::jacobian::physical_normal_matrix(problem, chart, x, albedos)
    } else {
        all_duals(problem, chart, x, albedos)
    };
    // Monochrome: only the R entries of ρ_ss and ρ_d are parameters; G, B copy them.
    let active: Vec<usize> = if problem.channels == 3 {
        (0..N_ALL).collect()
    } else {
        vec![0, 1, 2, 3, 4, 7, 10, 11]
    };
    let p = active.len();
    let (variance, unscaled) = covariance_diagonal(&jtj, &active, cost, m, p);
    let at = |k: usize| variance[k].sqrt();
    let mut std_error = [f64::INFINITY; 10];
    for (k, e) in std_error.iter_mut().enumerate() {
        let src = if problem.channels == 3 {
            k
        } else {
            match k {
                5 | 6 => 4,
                8 | 9 => 7,
                _ => k,
            }
        };
        *e = at(src);
    }
    let normal_var = variance[10] + variance[11];
    Uncertainty {
        std_error,
        normal_std_error_deg: normal_var.sqrt().to_degrees(),
        eta_variance_unscaled: unscaled[0],
    }
}

/// Cost, residual count and JᵀJ over all 12 parameters by dual numbers through every residual
/// (the paper loss; the measurement loss has them written out, `jacobian.rs`).
pub(super) fn all_duals(
    problem: &Problem,
    chart: &Chart,
    x: &Nonlinear<f64>,
    albedos: &Albedos<f64>,
) -> (f64, usize, SMatrix<f64, N_ALL, N_ALL>) {
    let v = |re: f64, k: usize| AllDual::variable(re, k);
    let xd: Nonlinear<AllDual> = x.seeded(super::jacobian::PHYSICAL_SLOTS);
    let ad = Albedos {
        rho_ss: core::array::from_fn(|c| v(albedos.rho_ss[c], 4 + c)),
        rho_d: core::array::from_fn(|c| v(albedos.rho_d[c], 7 + c)),
        rho_s: v(albedos.rho_s, 3),
    };
    let mut scratch = Scratch::new(problem.len(), problem.virtuals.len());
    let mut ne = super::jacobian::NormalEquations::<N_ALL>::new();
    problem.evaluate(chart, &xd, Some(ad), &mut scratch, &mut |r: AllDual| {
        ne.add(r)
    });
    (ne.cost, ne.rows, ne.jtj)
}

/// Diagonal of s²·(JᵀJ)⁻¹ restricted to `active` (others INFINITY), with the null-direction rule
/// of the module doc; second, the same diagonal without the factor s².
#[expect(
    clippy::needless_range_loop,
    reason = "eigenvector rows, live and active indices are parallel arrays"
)]
fn covariance_diagonal(
    jtj: &SMatrix<f64, N_ALL, N_ALL>,
    active: &[usize],
    cost: f64,
    m: usize,
    p: usize,
) -> ([f64; N_ALL], [f64; N_ALL]) {
    let mut out = [f64::INFINITY; N_ALL];
    let mut unscaled = [f64::INFINITY; N_ALL];
    if m <= p || !cost.is_finite() {
        return (out, unscaled);
    }
    let s2 = cost / (m - p) as f64;
    let scale: Vec<f64> = active.iter().map(|&i| jtj[(i, i)].sqrt()).collect();
    let live: Vec<usize> = (0..p)
        .filter(|&a| scale[a] > 0.0 && scale[a].is_finite())
        .collect();
    if live.is_empty() {
        return (out, unscaled);
    }
    let n = live.len();
    let h = DMatrix::from_fn(n, n, |r, c| {
        let (i, j) = (active[live[r]], active[live[c]]);
        jtj[(i, j)] / (scale[live[r]] * scale[live[c]])
    });
    if !h.iter().all(|v| v.is_finite()) {
        return (out, unscaled);
    }
    let eig = h.symmetric_eigen();
    let lambda_max = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    if lambda_max <= 0.0 {
        return (out, unscaled);
    }
    for r in 0..n {
        let mut var = 0.0;
        let mut null_loading = 0.0;
        for j in 0..n {
            let vj = eig.eigenvectors[(r, j)];
            let l = eig.eigenvalues[j];
            if l > NULL_RELATIVE * lambda_max {
                var += vj * vj / l;
            } else {
                null_loading += vj * vj;
            }
        }
        let a = live[r];
        if null_loading <= 1e-6 {
            unscaled[active[a]] = var / (scale[a] * scale[a]);
            out[active[a]] = s2 * unscaled[active[a]];
        }
    }
    (out, unscaled)
}
