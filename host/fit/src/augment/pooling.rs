//! Pooling η over a partition: which clusters pool together, the pooled value each cluster
//! gives, and what each member vertex may borrow from it ([`pool_eta`]). The statistics of one
//! cluster's pool (random effects, the prior removed, agreement) are [`super::pool`]'s.

use super::cluster::{self, Feature};
use super::model::{Augmentation, POOL_COLOUR_DISTANCE, eta_trusted};
use super::pool;
use super::seed::stream_seed;
use crate::data::{SampleSet, VertexFit};

/// Pools η per cluster from `fits` (indexed like the set's vertices: step A's results, whose
/// η carries the solver's weak default prior `eta_prior` = (mean, sd)) and gives each vertex
/// inside its cluster's kernel whose own η agrees the pooled prior ([`pool`]); the cluster's
/// `eta_pooled` and `vertices_with_eta_prior` are updated. Members are the vertices with
/// virtual samples from the cluster.
///
/// - **Likelihoods, not posteriors.** Each member enters with its data's own estimate: the
///   default prior removed from its step-A posterior ([`pool::without_prior`]). Pooling the
///   posteriors would count the default prior once per vertex and pull a material whose
///   vertices each say little towards the prior's mean — the start value every cold start
///   uses — until the material came back at exactly that value.
/// - **Identified or nothing.** A pool needs [`pool::MIN_VERTICES`] informative members
///   ([`pool::random_effects`]); a cluster without them gives no prior, its vertices keep their
///   own η and their own flags (`EtaUnidentifiable` where their data leave it open), and the
///   cluster's `eta_pooled.usable` says so.
/// - **Merging.** Clusters whose colour (the ρ_d part of their centroids) lies within the
///   kernel's reach of each other ([`POOL_COLOUR_DISTANCE`]) pool together only when their own
///   pooled η agree (within [`pool::AGREE_SIGMAS`] of the combined spread): k-means may split one
///   material by the noise of its η, and pooling each half alone would return the bias that
///   split selected — but two materials of one colour and different η stay apart, and a
///   vertex whose own η agrees with both (its data cannot tell which it is of) borrows from
///   neither.
pub fn pool_eta(
    a: &mut Augmentation,
    set: &SampleSet,
    fits: &[VertexFit],
    eta_prior: [f64; 2],
    max_eta_std_error: f64,
) {
    let k = a.clusters.len();
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); k];
    for (v, (j, g)) in a.assignment.iter().zip(&a.guides).enumerate() {
        if let Some(j) = j
            && !g.virtual_samples.is_empty()
            && v < fits.len()
        {
            members[*j].push(v);
        }
    }
    let points_of = |list: &[usize]| -> Vec<(f64, f64)> {
        list.iter()
            .map(|&v| pool::without_prior(fits[v].params.eta, fits[v].std_error[0], eta_prior))
            .collect()
    };
    let own: Vec<pool::Pooled> = members
        .iter()
        .map(|list| pool::random_effects(&points_of(list)))
        .collect();
    // Clusters of one colour whose identified η agree pool together.
    let roots = cluster::join_pairs(k, |i, j| {
        let (ci, cj) = (&a.clusters[i].centroid, &a.clusters[j].centroid);
        let d2: f64 = (0..3).map(|c| (ci[c] - cj[c]).powi(2)).sum();
        d2.sqrt() < POOL_COLOUR_DISTANCE && own[i].agrees_with(&own[j])
    });
    let mut pooled_members: Vec<Vec<usize>> = vec![Vec::new(); k];
    for (j, list) in members.iter().enumerate() {
        pooled_members[roots[j]].extend(list);
    }
    let pools: Vec<Option<pool::Pooled>> = pooled_members
        .iter()
        .map(|list| {
            if list.is_empty() {
                return None;
            }
            let points = points_of(list);
            let mut p = pool::random_effects(&points);
            p.se_blocks = pool::block_jackknife_se(&points, &spatial_blocks(set, list));
            p.prior_pull = pool::prior_pull(&points, p.mean, eta_prior);
            // Members whose data did not move η from the default prior (whatever their σ,
            // which a uniformly inflated recorded noise shrinks with the data: s² = cost/(m − p)
            // scales the prior's row too) are the start value, not a measurement: a pool most
            // of whose members are such repeats the start value with a small σ.
            // (counted among the members whose own σ makes them informative,
            // `pool::INFORMATIVE_SE`: those the pooled value is the median of; a vertex with too
            // few samples is prior-only too, but its large own σ keeps it out of that median, so
            // it must not withhold a pool its informative neighbours determine)
            let entering: Vec<usize> = list
                .iter()
                .zip(&points)
                .filter(|(_, (eta, se))| eta.is_finite() && *se <= pool::INFORMATIVE_SE)
                .map(|(&v, _)| v)
                .collect();
            let prior_only = entering.iter().filter(|&&v| fits[v].eta_prior_only).count();
            if p.usable && 2 * prior_only > entering.len() {
                p.usable = false;
            }
            if p.usable && p.weak(max_eta_std_error) {
                // A pool whose σ, the prior's possible pull included, exceeds what a vertex
                // may report is no measurement (`Pooled::weak`): no prior, and no value for
                // the vertices that would take the material's.
                p.usable = false;
            }
            Some(p)
        })
        .collect();
    for c in 0..k {
        if let Some(p) = pools[roots[c]] {
            a.clusters[c].eta_pooled = p;
        }
    }
    // The pools of one colour as cluster `j`'s, other than its own.
    let same_colour = |j: usize| -> Vec<usize> {
        let mut r: Vec<usize> = (0..k)
            .filter(|&c| roots[c] != roots[j])
            .filter(|&c| {
                let (cj, cc) = (&a.clusters[j].centroid, &a.clusters[c].centroid);
                (0..3).map(|i| (cj[i] - cc[i]).powi(2)).sum::<f64>().sqrt() < POOL_COLOUR_DISTANCE
            })
            .map(|c| roots[c])
            .collect();
        r.sort_unstable();
        r.dedup();
        r
    };
    let neighbours: Vec<Vec<usize>> = (0..k).map(same_colour).collect();
    // Every member's own estimate (the default prior removed) and its pool.
    let mut own: Vec<Option<(usize, f64, f64)>> = vec![None; fits.len()];
    for (j, list) in members.iter().enumerate() {
        for &v in list {
            let (eta, se) = own_estimate(&fits[v], eta_prior);
            own[v] = Some((roots[j], eta, se));
        }
    }
    let mut priors = Vec::new();
    for (j, list) in members.iter().enumerate() {
        let Some(pooled) = pools[roots[j]] else {
            continue;
        };
        for &v in list {
            let (eta, se) = own_estimate(&fits[v], eta_prior);
            // Nor may a vertex borrow where its surroundings disagree with the pool: a patch
            // of another η too small to be a cluster of its own (a vertex of it may say too
            // little alone, its patch does not).
            if local_eta(&set.rings, &own, v, roots[j])
                .is_some_and(|(e, s)| pooled.prior_for(e, s).is_none())
            {
                priors.push((v, None));
                continue;
            }
            // A vertex whose own η would agree with another pool of its colour as well cannot
            // say which material it is of: it borrows from neither.
            let ambiguous = neighbours[j]
                .iter()
                .any(|&r| pools[r].is_some_and(|p| p.prior_for(eta, se).is_some()));
            priors.push((
                v,
                if ambiguous {
                    None
                } else {
                    pooled.prior_for(eta, se)
                },
            ));
        }
    }
    for (v, prior) in priors {
        a.guides[v].eta_prior = prior;
    }
    a.vertices_with_eta_prior = a.guides.iter().filter(|g| g.eta_prior.is_some()).count();
}

/// A member's own η and its standard error: its step-A estimate with the default prior
/// `eta_prior` removed ([`pool::without_prior`]); a vertex whose η its own flags disown gives
/// an infinite standard error, so it takes the material's η without the agreement test.
fn own_estimate(f: &VertexFit, eta_prior: [f64; 2]) -> (f64, f64) {
    if eta_trusted(f) {
        pool::without_prior(f.params.eta, f.std_error[0], eta_prior)
    } else {
        (f.params.eta, f64::INFINITY)
    }
}

/// Rings of a vertex's surroundings the local η reads ([`local_eta`]): two rings hold about
/// 19 vertices on a regular mesh — a patch of the 2 % of the surface the smallest cluster may
/// be, and few enough that a patch's own vertices outnumber its border's.
pub const LOCAL_RINGS: usize = 2;

/// The inverse-variance weighted η of the members of pool `root` within [`LOCAL_RINGS`] of
/// `v` (their own estimates `own`: pool, η, s) and its standard error; `None` with fewer
/// than [`pool::MIN_VERTICES`] of them or without rings.
fn local_eta(
    rings: &[Vec<u32>],
    own: &[Option<(usize, f64, f64)>],
    v: usize,
    root: usize,
) -> Option<(f64, f64)> {
    if rings.len() != own.len() {
        return None;
    }
    let (mut sw, mut swe, mut n) = (0.0, 0.0, 0usize);
    for u in crate::neighbours::within(rings, v, LOCAL_RINGS) {
        if let Some((r, eta, se)) = own[u]
            && r == root
            && se.is_finite()
            && se > 0.0
        {
            let w = 1.0 / (se * se);
            sw += w;
            swe += w * eta;
            n += 1;
        }
    }
    (n >= pool::MIN_VERTICES && sw > 0.0).then(|| (swe / sw, sw.sqrt().recip()))
}

/// The jackknife blocks of `members` (vertex indices into `set`): k-means on their positions
/// into ⌊n / [`pool::BLOCK_MIN_VERTICES`]⌋ blocks, at most [`pool::BLOCK_MAX`] (seeded, so
/// deterministic); one block (no jackknife) for fewer members.
fn spatial_blocks(set: &SampleSet, members: &[usize]) -> Vec<usize> {
    let k = (members.len() / pool::BLOCK_MIN_VERTICES).min(pool::BLOCK_MAX);
    if k < 2 {
        return vec![0; members.len()];
    }
    let points: Vec<Feature> = members
        .iter()
        .map(|&v| {
            let p = set.vertices[v].position_world;
            [p[0], p[1], p[2], 0.0]
        })
        .collect();
    cluster::kmeans(
        &points,
        k,
        1,
        50,
        stream_seed(BLOCK_SEED, 20, members.len() as u64),
    )
    .labels
}

/// Seed of the jackknife blocks' k-means.
const BLOCK_SEED: u64 = 0xb10c_5eed;
