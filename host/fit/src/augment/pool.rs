//! Pooled η: what one cluster's vertices, each with its own step-A η and standard error, say
//! about the material's η, and how much a single vertex may borrow from it.
//!
//! Contract:
//! - [`random_effects`]: every vertex estimates the material's η plus a vertex-to-vertex spread
//!   τ (texture, model error). τ² is the random-effects moment estimate (DerSimonian & Laird,
//!   "Meta-analysis in clinical trials", Controlled Clinical Trials 7, 1986):
//!   (Q − (k − 1))/(Σw − Σw²/Σw), floored at 0, with w = 1/s². The material's η is the
//!   *median* of the informative vertices (s ≤ [`INFORMATIVE_SE`]; all when none are), with
//!   the standard error 1.2533/√Σ(1/(s² + τ²)) (the median's efficiency against the weighted
//!   mean). Not the DL weighted mean: it gives the few most precise vertices the say, and on a
//!   dark material those are the grazing views, where a small error in the tail of the fitted
//!   specular lobe shifts the measured DoP and biases η (measured on the glass sphere: weighted
//!   mean −0.45 %, median −0.13 %). Before
//!   it, one trimming round drops vertices more than [`TRIM_SIGMAS`] combined standard
//!   deviations √(s² + τ₀²) from the median, τ₀² = (1.4826·MAD)² − median(s²) (floored at 0):
//!   gross outliers (a vertex on an edge, a minority material in the cluster) cannot inflate
//!   the spread they are judged by, as long as they are fewer than half. Vertices without a finite, positive standard error are left
//!   out; with fewer than [`MIN_VERTICES`] usable the result is not [`Pooled::usable`].
//! - [`Pooled::prior_for`] gives a vertex the prior N(mean, τ² + se²) — the distribution of a
//!   new member's η — only when its own estimate agrees with it (within [`AGREE_SIGMAS`] of the
//!   combined spread): a precise vertex of another material keeps its own η.
//! - [`EtaShrink`]: the η a vertex contributes to the clustering features, shrunk towards the
//!   members' median (the fit passes the median of the informative members nearest in colour,
//!   `EtaShrink::apply_towards`) by the empirical-Bayes factor r = τ²/(τ² + s²) (James & Stein 1961;
//!   Efron & Morris 1975), τ the members' between-vertex spread of η ([`random_effects`] over
//!   all of them). On a single material τ ≈ 0, so η's noise cannot split it into clusters of
//!   high and low η (whose pooled values would then be biased by that very selection); with
//!   materials of different η, τ is their spread and precise vertices keep their η.

/// Fewer usable — and fewer informative — vertices than this give no pooled value.
pub const MIN_VERTICES: usize = 5;

/// Vertices whose η standard error is at most this carry information of their own (the
/// solver's default η prior has sd 0.5: at 0.25 the data holds 80 % of the information).
pub const INFORMATIVE_SE: f64 = 0.25;

/// The trimming round drops vertices beyond this many combined standard deviations.
pub const TRIM_SIGMAS: f64 = 4.0;

/// A vertex gets the prior only within this many combined standard deviations of the mean.
pub const AGREE_SIGMAS: f64 = 3.0;

/// The pooled η of one cluster.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pooled {
    /// Whether enough vertices had a usable standard error.
    pub usable: bool,
    /// The material's η: the median of the informative vertices (module doc).
    pub mean: f64,
    /// Its standard error.
    pub se: f64,
    /// Between-vertex standard deviation τ.
    pub tau: f64,
    /// Vertices in the final estimate.
    pub vertices: usize,
    /// Vertices dropped by the trimming round.
    pub trimmed: usize,
    /// Median η of all usable vertices (before trimming).
    pub median: f64,
    /// The standard error of `mean` from the members' spatial blocks (a delete-a-block
    /// jackknife, [`block_jackknife_se`]; NaN where too few blocks): neighbouring vertices
    /// share pixels and the mesh's local errors, so their estimates are not independent and
    /// `se` (which assumes they are) understates the material's uncertainty.
    #[serde(default = "nan")]
    pub se_blocks: f64,
    /// The members' median own standard error of η: what one vertex's data say.
    #[serde(default = "nan")]
    pub member_se_median: f64,
    /// How far the default η prior that every member's step-A solve carried could still pull
    /// the pooled value ([`prior_pull`]): 0 where the members' data dominate that prior or the
    /// material sits at the prior's mean. Part of [`Pooled::se_reported`].
    #[serde(default)]
    pub prior_pull: f64,
}

fn nan() -> f64 {
    f64::NAN
}

impl Pooled {
    /// The material's η standard error as the outputs report it: the larger of the
    /// independent-vertex `se` and the spatial-block jackknife `se_blocks`, combined in
    /// quadrature with the bias the members' default prior could leave (`prior_pull`).
    pub fn se_reported(&self) -> f64 {
        let sampling = if self.se_blocks.is_finite() {
            self.se.max(self.se_blocks)
        } else {
            self.se
        };
        let pull = if self.prior_pull.is_finite() {
            self.prior_pull
        } else {
            0.0
        };
        sampling.hypot(pull)
    }

    /// Whether the pool is no measurement of the material's η: the standard error of a vertex
    /// that takes it — [`Pooled::se_reported`] (the prior's possible pull included) with the
    /// members' between-vertex spread τ — exceeds `max_eta_std_error`, the limit above which a
    /// single vertex's η is withheld too. A large τ is a pool that mixed materials (a
    /// clustering that joined them) as often as texture: its one value is no material's. At high
    /// η the members' data say little each (the diffuse DoP flattens), the default prior pulls
    /// every one of them the same way, and averaging many of them shrinks their noise but not
    /// that shared pull: such a pool is withheld, not reported with a σ it does not have.
    pub fn weak(&self, max_eta_std_error: f64) -> bool {
        // NaN (no spread known) is weak too.
        let sd = self.tau.hypot(self.se_reported());
        sd.is_nan() || sd > max_eta_std_error
    }

    /// Whether two pools may be one material's: both identified and their η within
    /// [`AGREE_SIGMAS`] of their combined spread (standard errors and between-vertex spreads).
    pub fn agrees_with(&self, other: &Pooled) -> bool {
        if !(self.usable && other.usable) {
            return false;
        }
        let spread =
            (self.se.powi(2) + other.se.powi(2) + self.tau.powi(2) + other.tau.powi(2)).sqrt();
        (self.mean - other.mean).abs() <= AGREE_SIGMAS * spread
    }

    /// The prior (mean, sd) for a vertex whose own estimate is `eta` ± `se` (module doc); an
    /// infinite `se` (an estimate the vertex's flags disown) always agrees.
    pub fn prior_for(&self, eta: f64, se: f64) -> Option<[f64; 2]> {
        if !self.usable {
            return None;
        }
        let sd = self.tau.hypot(self.se_reported());
        let own = if se.is_finite() { se } else { f64::INFINITY };
        let spread = (own * own + sd * sd).sqrt();
        let agrees = !eta.is_finite()
            || !spread.is_finite()
            || (eta - self.mean).abs() <= AGREE_SIGMAS * spread;
        (agrees && sd > 0.0 && sd.is_finite()).then_some([self.mean, sd])
    }
}

/// A vertex's own estimate of η from its data alone: the Gaussian prior `prior` = (mean, sd)
/// that its solve carried, removed from its posterior `eta` ± `se` (precisions subtract:
/// 1/s_data² = 1/se² − 1/sd², and the means follow). A posterior no more precise than the
/// prior holds no data about η: its standard error is +∞. A non-finite `se` stays +∞, and a
/// prior of infinite width leaves the estimate as it is.
pub fn without_prior(eta: f64, se: f64, prior: [f64; 2]) -> (f64, f64) {
    let [mean, sd] = prior;
    if !(se.is_finite() && se > 0.0) {
        return (eta, f64::INFINITY);
    }
    if !(sd.is_finite() && sd > 0.0) {
        return (eta, se);
    }
    let (post, prior_precision) = (1.0 / (se * se), 1.0 / (sd * sd));
    let data = post - prior_precision;
    // Below a thousandth of the prior's precision the data say nothing about η.
    if data <= 1e-3 * prior_precision {
        return (eta, f64::INFINITY);
    }
    (
        (eta * post - mean * prior_precision) / data,
        1.0 / data.sqrt(),
    )
}

/// One DerSimonian–Laird estimate over `(η, s)` pairs (all usable): (mean, se, τ).
fn dersimonian_laird(points: &[(f64, f64)]) -> (f64, f64, f64) {
    let w: Vec<f64> = points.iter().map(|p| 1.0 / (p.1 * p.1)).collect();
    let sw: f64 = w.iter().sum();
    let sw2: f64 = w.iter().map(|v| v * v).sum();
    let fixed = points.iter().zip(&w).map(|(p, w)| w * p.0).sum::<f64>() / sw;
    let q: f64 = points
        .iter()
        .zip(&w)
        .map(|(p, w)| w * (p.0 - fixed).powi(2))
        .sum();
    let k = points.len() as f64;
    // C > 0 unless all weights but one vanish; the max keeps the division finite.
    let c = (sw - sw2 / sw).max(1e-300);
    let tau2 = ((q - (k - 1.0)) / c).max(0.0);
    let ws: Vec<f64> = points.iter().map(|p| 1.0 / (p.1 * p.1 + tau2)).collect();
    let sws: f64 = ws.iter().sum();
    let mean = points.iter().zip(&ws).map(|(p, w)| w * p.0).sum::<f64>() / sws;
    (mean, (1.0 / sws).sqrt(), tau2.sqrt())
}

/// The `(η, standard error)` pairs with a finite η and a finite, positive standard error.
fn usable(members: &[(f64, f64)]) -> Vec<(f64, f64)> {
    members
        .iter()
        .copied()
        .filter(|(eta, s)| eta.is_finite() && s.is_finite() && *s > 0.0)
        .collect()
}

/// The pooled η of `(η, standard error)` pairs (module doc).
pub fn random_effects(members: &[(f64, f64)]) -> Pooled {
    let usable = usable(members);
    if usable.len() < MIN_VERTICES {
        return Pooled::default();
    }
    let median = |mut v: Vec<f64>| ellipso_model::stats::median(&mut v);
    let mut etas: Vec<f64> = usable.iter().map(|p| p.0).collect();
    let centre = ellipso_model::stats::median(&mut etas);
    let s2 = median(usable.iter().map(|p| p.1 * p.1).collect());
    let tau2 = (ellipso_model::stats::robust_sigma(&mut etas).powi(2) - s2).max(0.0);
    let kept: Vec<(f64, f64)> = usable
        .iter()
        .copied()
        .filter(|(eta, s)| (eta - centre).abs() <= TRIM_SIGMAS * (s * s + tau2).sqrt())
        .collect();
    if kept.len() < MIN_VERTICES {
        return Pooled::default();
    }
    let (_, se, tau) = dersimonian_laird(&kept);
    let informative: Vec<f64> = kept
        .iter()
        .filter(|p| p.1 <= INFORMATIVE_SE)
        .map(|p| p.0)
        .collect();
    // Without informative members the material's η is not identified: no value at all rather
    // than the median of estimates the data did not fix.
    if informative.len() < MIN_VERTICES {
        return Pooled {
            vertices: kept.len(),
            trimmed: usable.len() - kept.len(),
            median: centre,
            ..Pooled::default()
        };
    }
    let mean = median(informative);
    let se = 1.2533 * se;
    Pooled {
        usable: mean.is_finite() && se.is_finite() && tau.is_finite(),
        mean,
        se,
        tau,
        vertices: kept.len(),
        trimmed: usable.len() - kept.len(),
        median: centre,
        se_blocks: f64::NAN,
        member_se_median: median(kept.iter().map(|p| p.1).collect()),
        prior_pull: 0.0,
    }
}

/// The bias the default η prior `prior` = (mean, sd) could leave in a pool at `pooled_eta`
/// whose members' own (prior-removed) estimates are `members` (`(η, s)` pairs): the median
/// over members of the share of a posterior the prior holds, r = s²/(s² + sd²), times the
/// distance |η − mean|. Each member's estimate has the prior removed
/// ([`without_prior`]), exactly only where its likelihood is Gaussian; where the diffuse DoP
/// flattens (high η) the curvature at the posterior's mode overstates the data's precision and
/// the removal falls short. Its shortfall is at most the prior's whole pull on that member,
/// r·|η − mean|, and it is the same sign for every member, so the pool cannot average it away:
/// this bound is carried in the pool's standard error, never divided by √n. 0 without
/// members or with a prior of infinite width.
pub fn prior_pull(members: &[(f64, f64)], pooled_eta: f64, prior: [f64; 2]) -> f64 {
    let [mean, sd] = prior;
    if !(sd.is_finite() && sd > 0.0 && pooled_eta.is_finite()) {
        return 0.0;
    }
    let mut shares: Vec<f64> = members
        .iter()
        .filter(|(eta, s)| eta.is_finite() && s.is_finite() && *s > 0.0)
        .map(|(_, s)| s * s / (s * s + sd * sd))
        .collect();
    if shares.is_empty() {
        return 0.0;
    }
    ellipso_model::stats::median(&mut shares) * (pooled_eta - mean).abs()
}

/// Fewest vertices a jackknife block holds: a block's median must itself be an estimate.
pub const BLOCK_MIN_VERTICES: usize = 2 * MIN_VERTICES;

/// Most jackknife blocks: more blocks only make each smaller, and spatially correlated errors
/// need blocks larger than the correlation's reach (a few mesh rings).
pub const BLOCK_MAX: usize = 8;

/// The delete-a-block jackknife standard error of [`random_effects`]' η over `members`
/// (`(η, s)` pairs) grouped by `blocks` (one block index per member): the pool recomputed
/// without each block in turn, se² = (B − 1)/B·Σ(η₋ᵦ − η̄)² (Shao & Wu, "A general theory for
/// jackknife variance estimation", Ann. Statist. 17, 1989: deleting large groups makes the
/// jackknife consistent for the median, which deleting one point is not). NaN with fewer than
/// two blocks or when a reduced pool is not usable.
pub fn block_jackknife_se(members: &[(f64, f64)], blocks: &[usize]) -> f64 {
    let count = blocks.iter().copied().max().map_or(0, |b| b + 1);
    if count < 2 || blocks.len() != members.len() {
        return f64::NAN;
    }
    let mut estimates = Vec::with_capacity(count);
    for b in 0..count {
        let rest: Vec<(f64, f64)> = members
            .iter()
            .zip(blocks)
            .filter(|(_, k)| **k != b)
            .map(|(m, _)| *m)
            .collect();
        let p = random_effects(&rest);
        if !p.usable {
            return f64::NAN;
        }
        estimates.push(p.mean);
    }
    let n = estimates.len() as f64;
    let mean = estimates.iter().sum::<f64>() / n;
    ((n - 1.0) / n * estimates.iter().map(|e| (e - mean).powi(2)).sum::<f64>()).sqrt()
}

/// The reliability shrinkage of the η feature (module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EtaShrink {
    /// The members' median η.
    pub median_eta: f64,
    /// The members' between-vertex spread τ (0 when it cannot be estimated).
    pub tau: f64,
}

impl EtaShrink {
    /// The statistics of the members' `(η, standard error)`.
    ///
    /// τ is the DerSimonian–Laird estimate over every usable member, *untrimmed*: the spread
    /// between materials is what it must hold. [`random_effects`]' trimming round (right for one
    /// material's pool) drops a minority material as outliers — a same-colour material on 16 %
    /// of the members was trimmed away, τ came out 0, and every member's feature η collapsed
    /// onto the median, so no partition could separate the two (dev scene 14).
    pub fn from_members(members: &[(f64, f64)]) -> Self {
        let usable = usable(members);
        let mut etas: Vec<f64> = members
            .iter()
            .map(|m| m.0)
            .filter(|v| v.is_finite())
            .collect();
        etas.sort_by(f64::total_cmp);
        let tau = if usable.len() >= MIN_VERTICES {
            dersimonian_laird(&usable).2
        } else {
            0.0
        };
        Self {
            median_eta: etas.get(etas.len() / 2).copied().unwrap_or(1.5),
            tau: if tau.is_finite() { tau } else { 0.0 },
        }
    }

    /// The feature η of a vertex with estimate `eta` ± `se`.
    pub fn apply(&self, eta: f64, se: f64) -> f64 {
        self.apply_towards(eta, se, self.median_eta)
    }

    /// [`EtaShrink::apply`] shrinking towards `target` instead of the members' median (the
    /// fit shrinks towards the median of the members nearest in colour).
    pub fn apply_towards(&self, eta: f64, se: f64, target: f64) -> f64 {
        if !eta.is_finite() || !se.is_finite() {
            return target;
        }
        let t2 = self.tau * self.tau;
        let r = if t2 > 0.0 { t2 / (t2 + se * se) } else { 0.0 };
        target + r * (eta - target)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    fn draw(n: usize, mean: f64, tau: f64, s: &[f64], seed: u64) -> Vec<(f64, f64)> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|i| {
                let se = s[i % s.len()];
                let truth = mean + tau * Normal::new(0.0, 1.0).unwrap().sample(&mut rng);
                (
                    truth + se * Normal::new(0.0, 1.0).unwrap().sample(&mut rng),
                    se,
                )
            })
            .collect()
    }

    #[test]
    fn homogeneous_material_pools_to_its_mean_with_honest_error() {
        // 400 vertices of one η with standard errors 0.01–0.1: the mean lands within 3 se.
        let pts = draw(400, 1.6, 0.0, &[0.01, 0.03, 0.1], 3);
        let p = random_effects(&pts);
        assert!(p.usable);
        assert!((p.mean - 1.6).abs() < 3.0 * p.se, "{p:?}");
        assert!(p.se < 0.002 && p.tau < 0.005, "{p:?}");
        // A vertex with a noisy estimate gets the prior; its sd is about the se of the mean.
        let prior = p.prior_for(1.63, 0.05).unwrap();
        assert_eq!(prior[0], p.mean);
        assert!(prior[1] < 0.005);
    }

    #[test]
    fn spread_is_estimated_and_other_materials_keep_their_eta() {
        let pts = draw(500, 1.5, 0.02, &[0.01], 5);
        let p = random_effects(&pts);
        assert!((p.tau - 0.02).abs() < 0.005, "{p:?}");
        // A second, precisely measured material in the same cluster is trimmed, and its
        // vertices get no prior.
        let mut mixed = draw(300, 1.5, 0.0, &[0.01], 6);
        mixed.extend(draw(30, 1.75, 0.0, &[0.005], 7));
        let p = random_effects(&mixed);
        assert!((p.mean - 1.5).abs() < 0.005, "{p:?}");
        assert!(p.trimmed >= 25, "{p:?}");
        assert!(p.prior_for(1.75, 0.005).is_none());
        assert!(p.prior_for(1.51, 0.02).is_some());
    }

    #[test]
    fn degenerate_inputs_give_no_pooled_value() {
        assert!(!random_effects(&[]).usable);
        assert!(!random_effects(&[(1.5, 0.01); 3]).usable);
        let inf = vec![(1.5, f64::INFINITY); 50];
        assert!(!random_effects(&inf).usable);
        let nan = vec![(f64::NAN, 0.01); 50];
        assert!(!random_effects(&nan).usable);
        assert!(Pooled::default().prior_for(1.5, 0.1).is_none());
    }

    #[test]
    fn shrinkage_follows_reliability_and_the_population_spread() {
        // Two materials (η 1.4 and 1.7): τ is their spread, precise vertices keep their η.
        let mut two = draw(200, 1.4, 0.0, &[0.01], 8);
        two.extend(draw(200, 1.7, 0.0, &[0.01], 9));
        let s = EtaShrink::from_members(&two);
        assert!(s.tau > 0.1, "{s:?}");
        assert!((s.apply(1.7, 0.01) - 1.7).abs() < 0.01);
        assert!((s.apply(2.5, 1.0) - s.median_eta).abs() < 0.05);
        assert_eq!(s.apply(2.5, f64::INFINITY), s.median_eta);
        assert_eq!(s.apply(f64::NAN, 0.01), s.median_eta);
        // A minority material of the same colour (15 %): its spread is not trimmed away.
        let mut minority = draw(255, 1.59, 0.0, &[0.01], 11);
        minority.extend(draw(45, 1.85, 0.0, &[0.01], 12));
        let m = EtaShrink::from_members(&minority);
        assert!(m.tau > 0.05, "{m:?}");
        assert!((m.apply(1.85, 0.01) - 1.85).abs() < 0.01, "{m:?}");
        // One material with noisy η: (almost) no spread, so η's noise is shrunk by > 10×.
        let one = EtaShrink::from_members(&draw(300, 1.5, 0.0, &[0.1], 10));
        assert!(one.tau < 0.04, "{one:?}");
        assert!(
            (one.apply(1.7, 0.1) - one.median_eta).abs() < 0.02,
            "{one:?}"
        );
    }

    #[test]
    fn the_prior_can_pull_only_a_material_away_from_its_mean_and_only_through_weak_members() {
        let prior = [1.5, 0.5];
        // Members as precise as the prior (r = ½), material 1.0 above the prior's mean.
        let weak: Vec<(f64, f64)> = (0..20).map(|i| (2.5 + 0.001 * i as f64, 0.5)).collect();
        assert!((prior_pull(&weak, 2.5, prior) - 0.5).abs() < 1e-12);
        // The same members at the prior's mean: nothing to pull.
        assert_eq!(prior_pull(&weak, 1.5, prior), 0.0);
        // Precise members (s = 0.01): r = 4e-4.
        let precise: Vec<(f64, f64)> = (0..20).map(|i| (2.5 + 0.001 * i as f64, 0.01)).collect();
        assert!(prior_pull(&precise, 2.5, prior) < 1e-3);
        // An infinitely wide prior pulls nothing.
        assert_eq!(prior_pull(&weak, 2.5, [1.5, f64::INFINITY]), 0.0);
    }

    #[test]
    fn a_pool_whose_possible_pull_exceeds_the_vertex_limit_is_weak_and_its_sigma_says_so() {
        let members: Vec<(f64, f64)> = (0..40)
            .map(|i| (2.4 + 0.002 * (i % 7) as f64, 0.2))
            .collect();
        let mut p = random_effects(&members);
        assert!(p.usable);
        // 40 members of s = 0.2 give a pooled se near 0.04: alone it would pass 0.05.
        assert!(p.se < 0.05, "{p:?}");
        p.prior_pull = prior_pull(&members, p.mean, [1.5, 0.5]);
        // r = 0.04/0.29 ≈ 0.14 of a 0.9 distance: 0.12.
        assert!((p.prior_pull - 0.124).abs() < 0.01, "{p:?}");
        assert!(p.se_reported() >= p.prior_pull);
        assert!(p.weak(0.05));
        // The same members at the prior's mean are a measurement.
        let centred: Vec<(f64, f64)> = members.iter().map(|(e, s)| (e - 0.9, *s)).collect();
        let mut q = random_effects(&centred);
        q.prior_pull = prior_pull(&centred, q.mean, [1.5, 0.5]);
        assert!(!q.weak(0.05), "{q:?}");
    }
}
