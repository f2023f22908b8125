//! The per-cluster model of the augmentation (optics.md §7.7): η_cluster from the diffuse DoP,
//! then the two-lobe specular model (σ_s ≤ σ_ss, ρ_s, ρ_ss RGB) from the I^s channel.
//!
//! Contract:
//! - Samples are real (vertex, view) samples of the cluster's members, drawn seeded-uniformly
//!   without replacement ([`draw_pairs`]), evaluated at their real geometry with the vertex's
//!   fitted normal ([`sample_geometry`]; views with an unpolarised flash are skipped: the
//!   channels then carry no I^s/I^α of the polarised model).
//! - η: each sample's diffuse-only Stokes vector is the observation minus the vertex's own
//!   fitted specular + single-scattering prediction (`measure::observe` with ρ_d = 0); channels
//!   are combined with weights ρ_d/Σρ_d (optics.md §5.4) and DoP = (s1·u1 + s2·u2)/s0 with
//!   s0 = I^d + I^s, s1 = I^s, s2 = −I^α of that diffuse part and (u1, u2) the unit direction
//!   of the model's diffuse polarisation at the fitted normal: the polarised part projected on
//!   its predicted direction, linear in the data, so unlike √(s1² + s2²) it carries no Rice
//!   bias on dark samples (optics.md §9). Noiseless it is exactly |T−|/T+ of the rank-one
//!   diffuse lobe, i.e. `dop_diffuse(θ_o, η)` with no τ² bias (the paper uses raw I^s as β
//!   and DP/I^d). Samples with s0 ≤ 0, |DoP| > 2 (gross outliers; a one-sided cut would bias),
//!   a degenerate direction (normal incidence) or a specular prediction larger than the
//!   diffuse s0 are dropped. η ∈ [1, 3] minimises Σ(DoP − DoP_d(θ_o, η))²: a grid
//!   (step 0.01) then Gauss–Newton with the closed-form ∂DoP/∂η and step halving.
//! - Two lobes: target t_c = I^s_c − (the vertex's diffuse-only I^s_c), model
//!   ρ_s·a(σ_s) + ρ_ss,c·a(σ_ss) with a(σ) = [I^s of `reflection_unit(g, η_cluster)` under the
//!   flash]·`microfacet_weight(cosθ_i, cosθ_o, cosθ_h, σ)` (= `lobe_weight`, the cosines taken
//!   once from the sample's `Geometry`). Loss (model units, no N):
//!   L = mean_{samples, channels}(model − t)² + 1e-6·ρ_s²·mean_samples(a(σ_s)²).
//!   - The ridge only breaks the ρ_s/ρ_ss tie when σ_s ≈ σ_ss. Deliberate difference: the
//!     paper's absolute 1e-6·ρ_s² lives in its raw-intensity units; in model units I^s is
//!     ~1e-2, where the absolute ridge biased ρ_s by −7 % on noiseless data (measured), so it
//!     is made relative to the ρ_s lobe's own mean square (a shrinkage of ρ_s by ~1e-6).
//!   - Deliberate difference from the paper: the paper fits a curve distance in
//!     (log tan(θ_h/2), I^s) space without N; we fit every sample at its real geometry in
//!     model units, so the lobe model is the same function the solver evaluates and the
//!     virtual samples need no mean-N bridge.
//!   - Initialisation: a 12-value geometric grid of σ from σ_min to 1 for (σ_s ≤ σ_ss), each
//!     pair with (ρ_s, ρ_ss) by exact 4-variable NNLS (all 16 active sets). Then
//!     Levenberg–Marquardt over u with σ_s = σ_min + (1 − σ_min)·sigmoid(u₀),
//!     σ_ss = σ_s + (1 − σ_s)·sigmoid(u₁), ρ_s = softplus(u₂), ρ_ss per channel by clipped LS
//!     (exact NNLS for one scalar) inside every evaluation; the Jacobian is exact through the
//!     inner solve (`Dual<3>`). Finally (ρ_s, ρ_ss) are re-solved by exact NNLS at the final
//!     σ's (the cost can only fall).

use ellipso_sim::optics::measure::{
    FlashPolariser, SensorIntensities, dop_diffuse, dop_diffuse_with_d_eta, observe,
};
use ellipso_sim::optics::microfacet::microfacet_weight;
use ellipso_sim::optics::pbrdf::{Geometry, PbrdfParams, reflection_unit};
use ellipso_sim::optics::{Dual, Real, Vec3};
use nalgebra::{DMatrix, DVector, Matrix3, Point3, Vector3};
use rand_chacha::ChaCha8Rng;

use crate::fit::data::{Sample, SampleSet, VertexFit};

/// Bounds of η_cluster.
pub const ETA_RANGE: (f64, f64) = (1.0, 3.0);
/// Fewer usable DoP samples than this: η_cluster falls back to the members' median η.
pub const MIN_ETA_SAMPLES: usize = 16;
/// Fewer usable I^s samples than this: the cluster gets no model.
pub const MIN_LOBE_SAMPLES: usize = 32;
/// Relative ridge on the ρ_s lobe: RIDGE·ρ_s²·mean(a(σ_s)²) is added to the mean squared
/// residual (module doc).
pub const RIDGE: f64 = 1e-6;
/// Grid values of σ in the initialisation.
const SIGMA_GRID: usize = 12;
/// Levenberg–Marquardt iteration limit.
const MAX_LM_ITERATIONS: usize = 200;

/// Draws up to `max` (vertex, sample index) pairs uniformly without replacement from the
/// samples of `members` (ascending), in ascending order.
pub fn draw_pairs(
    set: &SampleSet,
    members: &[usize],
    max: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<(usize, usize)> {
    let mut starts = Vec::with_capacity(members.len() + 1);
    let mut total = 0usize;
    for &v in members {
        starts.push(total);
        total += set.vertices[v].samples.len();
    }
    starts.push(total);
    let picks: Vec<usize> = if total <= max {
        (0..total).collect()
    } else {
        let mut v = rand::seq::index::sample(rng, total, max).into_vec();
        v.sort_unstable();
        v
    };
    picks
        .into_iter()
        .map(|i| {
            let m = starts.partition_point(|&s| s <= i) - 1;
            (members[m], i - starts[m])
        })
        .collect()
}

/// The model geometry of one real sample with the vertex's fitted normal and the view's flash,
/// or `None` (unpolarised flash, undefined geometry, or back-facing).
pub fn sample_geometry(
    set: &SampleSet,
    vertex: usize,
    sample: &Sample,
    fit: &VertexFit,
) -> Option<(Geometry<f64>, FlashPolariser)> {
    let view = set.views.get(sample.view as usize)?;
    if !view.polarised() {
        return None;
    }
    let sg = view.geometry_at(&Point3::from(set.vertices[vertex].position_world))?;
    let g = sg.model(Vec3::from_f64(fit.normal_world)).ok()?;
    g.front_facing.then_some((g, view.flash_polariser()))
}

/// One sample's diffuse DoP and view angle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DopSample {
    /// cosθ_o (fitted normal · direction to the camera).
    pub cos_theta_o: f64,
    /// Observed diffuse DoP (module doc).
    pub dop: f64,
}

/// The channel weights ρ_d/Σρ_d (equal when Σρ_d is not positive).
fn channel_weights(rho_d: [f64; 3]) -> [f64; 3] {
    let sum: f64 = rho_d.iter().map(|v| v.max(0.0)).sum();
    if sum > 0.0 && sum.is_finite() {
        rho_d.map(|v| v.max(0.0) / sum)
    } else {
        [1.0 / 3.0; 3]
    }
}

/// The diffuse DoP of one sample (module doc), or `None` when unusable.
pub fn dop_sample(
    g: &Geometry<f64>,
    flash: FlashPolariser,
    sample: &Sample,
    fit: &VertexFit,
) -> Option<DopSample> {
    let spec_params = PbrdfParams {
        rho_d: [0.0; 3],
        ..fit.params
    };
    let spec = observe(g, &spec_params, flash);
    let w = channel_weights(fit.params.rho_d);
    let (mut i_d, mut i_s, mut i_a, mut spec_s0) = (0.0, 0.0, 0.0, 0.0);
    for c in 0..3 {
        let [d, s, a] = sample.channels[c].map(f64::from);
        i_d += w[c] * (d - spec[c].diffuse);
        i_s += w[c] * (s - spec[c].specular);
        i_a += w[c] * (a - spec[c].alpha);
        spec_s0 += w[c] * (spec[c].diffuse + spec[c].specular);
    }
    let s0 = i_d + i_s;
    if s0.is_nan() || s0 <= 0.0 || spec_s0 > s0 {
        return None;
    }
    // The diffuse lobe's own polarisation direction in (I^s, I^α) at the fitted normal: the
    // observed DP is projected on it (linear in the data, so no Rice bias, optics.md §9);
    // √(I^s² + I^α²) is biased up by the noise on dark samples.
    let diffuse_params = PbrdfParams {
        rho_s: 0.0,
        rho_ss: [0.0; 3],
        rho_d: [1.0; 3],
        ..fit.params
    };
    let u = observe(g, &diffuse_params, flash)[0];
    let norm = u.specular.hypot(u.alpha);
    if norm.is_nan() || norm <= 1e-12 * u.diffuse.abs() {
        return None;
    }
    let dop = (i_s * u.specular + i_a * u.alpha) / (norm * s0);
    // A symmetric guard against gross outliers only (a one-sided DoP ≤ 1 cut would bias).
    (dop.is_finite() && dop.abs() <= 2.0).then_some(DopSample {
        cos_theta_o: g.cos_theta_o,
        dop,
    })
}

/// Σ(DoP − DoP_d(θ_o, η))².
fn eta_cost(samples: &[DopSample], eta: f64) -> f64 {
    samples
        .iter()
        .map(|s| (s.dop - dop_diffuse(s.cos_theta_o, eta)).powi(2))
        .sum()
}

/// η ∈ [1, 3] minimising the DoP residuals, or `None` with fewer than [`MIN_ETA_SAMPLES`].
pub fn fit_eta(samples: &[DopSample]) -> Option<f64> {
    if samples.len() < MIN_ETA_SAMPLES {
        return None;
    }
    let (lo, hi) = ETA_RANGE;
    let steps = ((hi - lo) / 0.01).round() as usize;
    let (mut eta, mut cost) = (0..=steps)
        .map(|k| lo + (hi - lo) * k as f64 / steps as f64)
        .map(|e| (e, eta_cost(samples, e)))
        .fold((lo, f64::INFINITY), |b, c| if c.1 < b.1 { c } else { b });
    for _ in 0..50 {
        let (mut num, mut den) = (0.0, 0.0);
        for s in samples {
            let (model, d) = dop_diffuse_with_d_eta(s.cos_theta_o, eta);
            num += (model - s.dop) * d;
            den += d * d;
        }
        if den.is_nan() || den <= 0.0 {
            break;
        }
        let mut step = -num / den;
        let mut accepted = false;
        for _ in 0..20 {
            let next = (eta + step).clamp(lo, hi);
            let c = eta_cost(samples, next);
            if c < cost {
                (eta, cost, accepted) = (next, c, true);
                break;
            }
            step *= 0.5;
        }
        if !accepted || step.abs() < 1e-13 {
            break;
        }
    }
    Some(eta)
}

/// One sample prepared for the two-lobe fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LobeSample {
    /// n·ω_i, n·ω_o, n·h of the sample's `Geometry` (clamped there).
    pub cos_theta: [f64; 3],
    /// I^s of `reflection_unit(g, η_cluster)` under the view's flash (unit lobe weight).
    pub reflection_is: f64,
    /// Observed I^s minus the vertex's diffuse-only I^s, per channel, model units.
    pub target: [f64; 3],
}

impl LobeSample {
    /// From one real sample (module doc); `None` when not finite.
    pub fn new(
        g: &Geometry<f64>,
        flash: FlashPolariser,
        sample: &Sample,
        fit: &VertexFit,
        eta_cluster: f64,
    ) -> Option<Self> {
        let diffuse_params = PbrdfParams {
            rho_s: 0.0,
            rho_ss: [0.0; 3],
            ..fit.params
        };
        let diffuse = observe(g, &diffuse_params, flash);
        let reflected = reflection_unit(g, eta_cluster).apply(flash.stokes(1.0));
        let reflection_is = SensorIntensities::from_stokes(reflected)
            .observation()
            .specular;
        let target: [f64; 3] =
            core::array::from_fn(|c| f64::from(sample.channels[c][1]) - diffuse[c].specular);
        (reflection_is.is_finite() && target.iter().all(|t| t.is_finite())).then_some(Self {
            cos_theta: [g.cos_theta_i, g.cos_theta_o, g.cos_theta_h],
            reflection_is,
            target,
        })
    }

    /// The unit-albedo lobe of roughness `sigma` at this sample.
    pub fn lobe<T: Real>(&self, sigma: T) -> T {
        let [ci, co, ch] = self.cos_theta.map(T::from_f64);
        T::from_f64(self.reflection_is) * microfacet_weight(ci, co, ch, sigma)
    }

    /// The model's I^s per channel (specular + single scattering only).
    pub fn model(&self, sigma_s: f64, sigma_ss: f64, rho_s: f64, rho_ss: [f64; 3]) -> [f64; 3] {
        let (a, b) = (self.lobe(sigma_s), self.lobe(sigma_ss));
        rho_ss.map(|r| rho_s * a + r * b)
    }
}

/// The fitted two-lobe model of one cluster.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LobeFit {
    /// σ_s.
    pub sigma_s: f64,
    /// σ_ss ≥ σ_s.
    pub sigma_ss: f64,
    /// ρ_s ≥ 0.
    pub rho_s: f64,
    /// ρ_ss ≥ 0 per channel.
    pub rho_ss: [f64; 3],
    /// √(mean squared residual), model units (no ridge).
    pub rms: f64,
    /// Levenberg–Marquardt iterations.
    pub iterations: usize,
}

/// Sums for the linear part at fixed σ's: a = lobe(σ_s), b = lobe(σ_ss).
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    aa: f64,
    ab: f64,
    bb: f64,
    at: f64,
    bt: [f64; 3],
    tt: f64,
    m: f64,
}

impl Sums {
    fn new(samples: &[LobeSample], a: &[f64], b: &[f64]) -> Self {
        let mut s = Sums {
            m: 3.0 * samples.len() as f64,
            ..Sums::default()
        };
        for ((x, &a), &b) in samples.iter().zip(a).zip(b) {
            s.aa += a * a;
            s.ab += a * b;
            s.bb += b * b;
            for c in 0..3 {
                s.at += a * x.target[c];
                s.bt[c] += b * x.target[c];
                s.tt += x.target[c] * x.target[c];
            }
        }
        s
    }

    /// Exact NNLS for x = (ρ_s, ρ_ss RGB) minimising Σ(ρ_s a + ρ_ss,c b − t_c)² + RIDGE·ρ_s²·3Σa²;
    /// returns x, the loss (divided by the residual count m) and the data SSE.
    fn solve(&self) -> ([f64; 4], f64, f64) {
        let h = [
            [3.0 * self.aa * (1.0 + RIDGE), self.ab, self.ab, self.ab],
            [self.ab, self.bb, 0.0, 0.0],
            [self.ab, 0.0, self.bb, 0.0],
            [self.ab, 0.0, 0.0, self.bb],
        ];
        let g = [self.at, self.bt[0], self.bt[1], self.bt[2]];
        let x = nnls4(&h, &g);
        let sse = self.sse(&x);
        (x, (sse + 3.0 * RIDGE * self.aa * x[0] * x[0]) / self.m, sse)
    }

    fn sse(&self, x: &[f64; 4]) -> f64 {
        let quad = 3.0 * self.aa * x[0] * x[0]
            + (1..4)
                .map(|c| 2.0 * self.ab * x[0] * x[c] + self.bb * x[c] * x[c])
                .sum::<f64>();
        let lin = self.at * x[0] + (0..3).map(|c| self.bt[c] * x[c + 1]).sum::<f64>();
        (self.tt - 2.0 * lin + quad).max(0.0)
    }
}

/// min xᵀHx − 2gᵀx subject to x ≥ 0 for a 4×4 symmetric positive semi-definite H: the
/// optimum is the unconstrained minimiser on one face, so the best feasible face solution
/// among all 16 active sets is exact.
fn nnls4(h: &[[f64; 4]; 4], g: &[f64; 4]) -> [f64; 4] {
    let mut best = ([0.0; 4], 0.0);
    for mask in 1u32..16 {
        let free: Vec<usize> = (0..4).filter(|i| mask & (1 << i) != 0).collect();
        let k = free.len();
        let hm = DMatrix::from_fn(k, k, |r, c| h[free[r]][free[c]]);
        let gv = DVector::from_fn(k, |r, _| g[free[r]]);
        let Some(chol) = hm.cholesky() else { continue };
        let xf = chol.solve(&gv);
        if xf.iter().any(|v| !v.is_finite() || *v < 0.0) {
            continue;
        }
        let mut x = [0.0; 4];
        for (i, &f) in free.iter().enumerate() {
            x[f] = xf[i];
        }
        // Objective at the face optimum: −gᵀx.
        let obj = -(0..4).map(|i| g[i] * x[i]).sum::<f64>();
        if obj < best.1 {
            best = (x, obj);
        }
    }
    best.0
}

fn sigmoid<T: Real>(x: T) -> T {
    if x.re() >= 0.0 {
        T::one() / (T::one() + (-x).exp())
    } else {
        let e = x.exp();
        e / (T::one() + e)
    }
}

/// softplus(x) = ln(1 + eˣ); x itself above 30 (where they agree to 1e-13).
fn softplus<T: Real>(x: T) -> T {
    if x.re() > 30.0 {
        x
    } else {
        (T::one() + x.exp()).ln()
    }
}

/// (σ_s, σ_ss, ρ_s) from the unconstrained u (module doc).
fn unpack<T: Real>(u: [T; 3], sigma_min: f64) -> (T, T, T) {
    let sigma_s = T::from_f64(sigma_min) + T::from_f64(1.0 - sigma_min) * sigmoid(u[0]);
    let sigma_ss = sigma_s + (T::one() - sigma_s) * sigmoid(u[1]);
    (sigma_s, sigma_ss, softplus(u[2]))
}

/// Inverse of [`unpack`], with the sigmoid fractions kept in [1e-3, 1 − 1e-3] so the start
/// is not on a flat tail, and ρ_s ≥ 1e-8.
fn pack(sigma_s: f64, sigma_ss: f64, rho_s: f64, sigma_min: f64) -> [f64; 3] {
    let logit = |f: f64| {
        let f = f.clamp(1e-3, 1.0 - 1e-3);
        (f / (1.0 - f)).ln()
    };
    let fs = (sigma_s - sigma_min) / (1.0 - sigma_min);
    let fss = if sigma_s < 1.0 {
        (sigma_ss - sigma_s) / (1.0 - sigma_s)
    } else {
        0.0
    };
    let rho = rho_s.max(1e-8);
    let inv_softplus = if rho > 30.0 {
        rho
    } else {
        rho + (-(-rho).exp_m1()).ln()
    };
    [logit(fs), logit(fss), inv_softplus]
}

/// Feeds every scaled residual of the variable-projection loss at `u` to `sink`.
fn residuals<T: Real>(
    samples: &[LobeSample],
    u: [T; 3],
    sigma_min: f64,
    scratch: &mut Vec<(T, T)>,
    mut sink: impl FnMut(T),
) {
    let (sigma_s, sigma_ss, rho_s) = unpack(u, sigma_min);
    scratch.clear();
    let (mut aa, mut bb) = (T::zero(), T::zero());
    let mut bt = [T::zero(); 3];
    for s in samples {
        let (a, b) = (s.lobe(sigma_s), s.lobe(sigma_ss));
        scratch.push((a, b));
        aa += a * a;
        bb += b * b;
        for (acc, t) in bt.iter_mut().zip(s.target) {
            *acc += b * (T::from_f64(t) - rho_s * a);
        }
    }
    // ρ_ss per channel: LS clipped at 0 (exact NNLS for one scalar); 0 without signal.
    let rho_ss = bt.map(|v| {
        if bb.re() > 0.0 {
            (v / bb).max_re(T::zero())
        } else {
            T::zero()
        }
    });
    let scale = T::from_f64((3.0 * samples.len() as f64).sqrt().recip());
    for (s, &(a, b)) in samples.iter().zip(scratch.iter()) {
        for (r, t) in rho_ss.iter().zip(s.target) {
            sink((rho_s * a + *r * b - T::from_f64(t)) * scale);
        }
    }
    // The relative ridge: RIDGE × the mean squared ρ_s-lobe signal.
    sink(rho_s * (aa * T::from_f64(RIDGE / samples.len() as f64)).sqrt_clamped());
}

fn cost(samples: &[LobeSample], u: [f64; 3], sigma_min: f64, scratch: &mut Vec<(f64, f64)>) -> f64 {
    let mut sum = 0.0;
    residuals(samples, u, sigma_min, scratch, |r| sum += r * r);
    sum
}

fn normal_equations(
    samples: &[LobeSample],
    u: [f64; 3],
    sigma_min: f64,
    scratch: &mut Vec<(Dual<3>, Dual<3>)>,
) -> (f64, Matrix3<f64>, Vector3<f64>) {
    let ud = core::array::from_fn(|i| Dual::variable(u[i], i));
    let (mut sum, mut jtj, mut jtr) = (0.0, Matrix3::zeros(), Vector3::zeros());
    residuals(samples, ud, sigma_min, scratch, |r: Dual<3>| {
        let j = Vector3::from(r.du);
        sum += r.re * r.re;
        jtj += j * j.transpose();
        jtr += j * r.re;
    });
    (sum, jtj, jtr)
}

/// Fits the two-lobe model (module doc); `None` with fewer than [`MIN_LOBE_SAMPLES`] samples
/// or no finite solution.
pub fn fit_lobes(samples: &[LobeSample], sigma_min: f64) -> Option<LobeFit> {
    if samples.len() < MIN_LOBE_SAMPLES {
        return None;
    }
    let sigma_min = sigma_min.clamp(1e-4, 0.5);
    // Grid initialisation with exact NNLS for the albedos.
    let grid: Vec<f64> = (0..SIGMA_GRID)
        .map(|k| sigma_min * (1.0 / sigma_min).powf(k as f64 / (SIGMA_GRID - 1) as f64))
        .collect();
    let lobes: Vec<Vec<f64>> = grid
        .iter()
        .map(|&s| samples.iter().map(|x| x.lobe(s)).collect())
        .collect();
    let mut start = (f64::INFINITY, [0.0; 3]);
    for i in 0..SIGMA_GRID {
        for l in i..SIGMA_GRID {
            let (x, loss, _) = Sums::new(samples, &lobes[i], &lobes[l]).solve();
            if loss < start.0 {
                start = (loss, pack(grid[i], grid[l], x[0], sigma_min));
            }
        }
    }
    // Levenberg–Marquardt in u.
    let mut u = start.1;

    let mut scratch_f = Vec::with_capacity(samples.len());
    let mut scratch_d = Vec::with_capacity(samples.len());
    let (mut f, mut jtj, mut jtr) = normal_equations(samples, u, sigma_min, &mut scratch_d);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    while iterations < MAX_LM_ITERATIONS {
        iterations += 1;
        let mut accepted = None;
        while lambda < 1e12 {
            let mut a = jtj;
            for d in 0..3 {
                a[(d, d)] += lambda * jtj[(d, d)].max(1e-12 * (1.0 + jtj.diagonal().max()));
            }
            let Some(step) = a.cholesky().map(|c| -c.solve(&jtr)) else {
                lambda *= 10.0;
                continue;
            };
            let next = [u[0] + step[0], u[1] + step[1], u[2] + step[2]];
            let fn_next = cost(samples, next, sigma_min, &mut scratch_f);
            if fn_next < f {
                accepted = Some((next, fn_next, step.amax()));
                lambda = (lambda * 0.3).max(1e-12);
                break;
            }
            lambda *= 10.0;
        }
        let Some((next, fn_next, step)) = accepted else {
            break;
        };
        let decrease = (f - fn_next) / f.max(f64::MIN_POSITIVE);

        u = next;
        (f, jtj, jtr) = normal_equations(samples, u, sigma_min, &mut scratch_d);
        if decrease < 1e-14 || step < 1e-12 {
            break;
        }
    }
    let (sigma_s, sigma_ss, _) = unpack(u, sigma_min);
    let a: Vec<f64> = samples.iter().map(|x| x.lobe(sigma_s)).collect();
    let b: Vec<f64> = samples.iter().map(|x| x.lobe(sigma_ss)).collect();
    let sums = Sums::new(samples, &a, &b);
    let (x, _, sse) = sums.solve();
    let fit = LobeFit {
        sigma_s,
        sigma_ss,
        rho_s: x[0],
        rho_ss: [x[1], x[2], x[3]],
        rms: (sse / sums.m).sqrt(),
        iterations,
    };
    let finite = [fit.sigma_s, fit.sigma_ss, fit.rho_s, fit.rms]
        .iter()
        .chain(&fit.rho_ss)
        .all(|v| v.is_finite());
    finite.then_some(fit)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nnls4_matches_unconstrained_and_clips() {
        // Diagonal H: NNLS = clipped solution.
        let h = [
            [2.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 4.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let x = nnls4(&h, &[2.0, -1.0, 2.0, 0.5]);
        for (a, b) in x.iter().zip([1.0, 0.0, 0.5, 0.5]) {
            assert!((a - b).abs() < 1e-15, "{x:?}");
        }
        // Coupled: the unconstrained optimum is feasible and found.
        let h = [
            [3.0, 1.0, 1.0, 1.0],
            [1.0, 2.0, 0.0, 0.0],
            [1.0, 0.0, 2.0, 0.0],
            [1.0, 0.0, 0.0, 2.0],
        ];
        let want = [0.3, 0.2, 0.1, 0.4];
        let g: [f64; 4] = core::array::from_fn(|r| (0..4).map(|c| h[r][c] * want[c]).sum());
        let x = nnls4(&h, &g);
        for (a, b) in x.iter().zip(want) {
            assert!((a - b).abs() < 1e-12);
        }
        assert_eq!(nnls4(&h, &[-1.0; 4]), [0.0; 4]);
    }

    #[test]
    fn reparameterisation_round_trips_and_keeps_the_order() {
        for (s, ss, r) in [(0.1, 0.4, 0.7), (0.03, 0.9, 1e-3), (0.5, 0.6, 40.0)] {
            let u = pack(s, ss, r, 0.02);
            let (a, b, c) = unpack(u, 0.02);
            assert!((a - s).abs() < 1e-12 && (b - ss).abs() < 1e-12 && (c - r).abs() < 1e-12);
        }
        // Starts on the bounds are moved 1e-3 (of the free range) inside them.
        let (a, b, c) = unpack(pack(0.02, 0.02, 0.0, 0.02), 0.02);
        assert!((a - 0.02098).abs() < 1e-12 && (b - a - 1e-3 * (1.0 - a)).abs() < 1e-12);
        assert!((c - 1e-8).abs() < 1e-15);
        for u0 in [-50.0, -3.0, 0.0, 3.0, 50.0] {
            for u1 in [-50.0, 0.0, 50.0] {
                let (a, b, c) = unpack([u0, u1, -800.0], 0.02);
                assert!((0.02..=1.0).contains(&a) && a <= b && b <= 1.0 && c >= 0.0);
            }
        }
    }

    #[test]
    fn eta_fit_recovers_eta_from_exact_dop() {
        for eta in [1.05, 1.33, 1.5, 2.3, 2.95] {
            let samples: Vec<DopSample> = (0..40)
                .map(|k| {
                    let c = (2.0 * k as f64).to_radians().cos();
                    DopSample {
                        cos_theta_o: c,
                        dop: dop_diffuse(c, eta),
                    }
                })
                .collect();
            let got = fit_eta(&samples).unwrap();
            assert!((got - eta).abs() < 1e-9, "η={eta}: {got}");
        }
        assert!(fit_eta(&[]).is_none());
    }
}
