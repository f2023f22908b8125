//! The η that a completed vertex's surroundings' own samples say ([`Curves`], [`Curves::local`]).
//!
//! Why. A vertex is completed because its samples are too few for the per-vertex solve's
//! eleven unknowns (`min_views`), not because they say nothing: with the material's lobes and
//! the surface's normal given, each sample still shows how its light is polarised, which η
//! decides. Where a whole material lies where the views see it only near a silhouette (the
//! side and underside of an object seen from 20–30° of elevation: dev scenes 3, 4, 7 and 13,
//! 4–11 kept samples per vertex, none fitted), completion took the nearest material's η — a
//! same-colour neighbour's, or any neighbour's when every sample was gated — 9–49 % off.
//! Summed over a neighbourhood, the material's own samples contradict that.
//!
//! Contract:
//! - **Per vertex** ([`Curves::new`]): on a grid of η over the solver's range
//!   ([`ETA_MIN`]..=[`ETA_MAX`], step [`ETA_STEP`]), the weighted residual sum of its kept
//!   samples with ρd refitted by least squares at each η (`super::diffuse::fit`) and every other
//!   parameter given (the material's lobes for a completed vertex); once at its normal and
//!   once at each of four normals tilted by the normal's σ.
//! - **Local** ([`Curves::local`]): the curves of the vertices of the same material within
//!   [`crate::augment::LOCAL_RINGS`] rings are summed per normal (independent samples: their
//!   log-likelihoods add); at least [`crate::augment::pool::MIN_VERTICES`] vertices must
//!   contribute. The normal is a nuisance: at each η the lowest of the five sums (a profile
//!   over the tilts — the completed vertices' normals are the surface's, off by several
//!   degrees, and at grazing views the polarisation changes fast with the angle). The minimum,
//!   refined by a parabola through its neighbours, is the estimate; one at either end of the
//!   grid is at a bound and gives none. The noise scale is the residual variance there,
//!   s² = C_min / (m − p) (m residual values, p the albedos plus η), and the standard error
//!   the Δχ² = 1 half-width of the parabola, √(2 s² / C″).
//! - **What it is worth.** On the development scenes (seeds 0–19, 612×512) the estimate's
//!   median error on completed vertices is 0.08 against a median σ of 0.02: a neighbourhood's
//!   samples share its normal's and its lobes' error, which the residuals cannot show (tilting
//!   the normals by their σ and a delete-one-vertex jackknife were tried and widen it by
//!   less than 30 %). So it is used only as evidence against the material's η, and a vertex
//!   that takes it reports a σ that spans the gap between the two (`super::complete`).
//! - Deterministic: each vertex's curves are its own (computed in parallel), the sums serial.

use ellipso_model::optics::pbrdf::PbrdfParams;

use super::diffuse;
use crate::data::SampleSet;

/// Lowest η on the grid: the solver's lower bound (docs/fit-solver.md "Bounds").
pub const ETA_MIN: f64 = 1.1;
/// Highest η on the grid: the solver's upper bound.
pub const ETA_MAX: f64 = 3.0;
/// Grid step. A parabola through three points of a smooth curve is exact to third order in
/// the step; 0.04 is below the per-vertex identifiability limit (`max_eta_std_error`, 0.05),
/// so a curve narrow enough to pass that limit still spans three grid points within ±1σ.
pub const ETA_STEP: f64 = 0.04;

fn grid_len() -> usize {
    ((ETA_MAX - ETA_MIN) / ETA_STEP).round() as usize + 1
}

fn grid_eta(g: usize) -> f64 {
    ETA_MIN + g as f64 * ETA_STEP
}

/// One vertex's residual curve over the η grid.
#[derive(Clone, Debug, PartialEq)]
struct Curve {
    cost: Vec<f64>,
    values: usize,
    unknowns: usize,
}

/// The residual curves of the vertices that need one (module doc): at the given normal
/// (`curves[0]`) and at that normal tilted by its σ towards four tangent directions.
#[derive(Clone, Debug, Default)]
pub struct Curves {
    curves: [Vec<Option<Curve>>; TILTS],
}

/// The normal as given, then tilted by its σ towards ±t1 and ±t2 (`super::sigma::tilted_normals`).
const TILTS: usize = 5;

fn curve_of(
    set: &SampleSet,
    v: usize,
    params: PbrdfParams<f64>,
    normal: [f64; 3],
    albedo_cap: f64,
) -> Option<Curve> {
    let vertex = &set.vertices[v];
    if vertex.samples.is_empty() {
        return None;
    }
    let mut cost = Vec::with_capacity(grid_len());
    let (mut values, mut unknowns) = (0, 0);
    for g in 0..grid_len() {
        let mut p = params;
        p.eta = grid_eta(g);
        let d = diffuse::fit(set, vertex, &vertex.samples, &p, normal, albedo_cap)?;
        cost.push(d.rss);
        values = d.values;
        unknowns = d.unknowns;
    }
    Some(Curve {
        cost,
        values,
        unknowns,
    })
}

impl Curves {
    /// Curves for every vertex `v` of `set` for which `params_of(v)` gives its parameters
    /// (η replaced along the grid), its normal and that normal's σ in degrees; `None`
    /// elsewhere, and where a grid point has no diffuse fit. Vertices run in parallel (each
    /// curve is its vertex's alone, so the result does not depend on the order).
    pub fn new(
        set: &SampleSet,
        albedo_cap: f64,
        params_of: impl Fn(usize) -> Option<(PbrdfParams<f64>, [f64; 3], f64)> + Sync,
    ) -> Curves {
        use rayon::prelude::*;
        let per_vertex: Vec<[Option<Curve>; TILTS]> = (0..set.vertices.len())
            .into_par_iter()
            .map(|v| {
                let Some((params, normal, sigma_deg)) = params_of(v) else {
                    return std::array::from_fn(|_| None);
                };
                let normals = super::sigma::tilted_normals(normal, sigma_deg);
                std::array::from_fn(|k| curve_of(set, v, params, normals[k], albedo_cap))
            })
            .collect();
        let mut curves: [Vec<Option<Curve>>; TILTS] = std::array::from_fn(|_| Vec::new());
        for row in per_vertex {
            for (k, c) in row.into_iter().enumerate() {
                curves[k].push(c);
            }
        }
        Curves { curves }
    }

    /// The η of the vertices within [`crate::augment::LOCAL_RINGS`] of `v` whose material
    /// (`material_of`) is `j`, and its residual standard error (module doc: the summed curves
    /// profiled over the normal's tilts). `None` where fewer than
    /// [`crate::augment::pool::MIN_VERTICES`] contribute, the minimum is at the grid's end, or
    /// the curve is not convex there.
    pub fn local(
        &self,
        rings: &[Vec<u32>],
        v: usize,
        j: usize,
        material_of: impl Fn(usize) -> Option<usize>,
    ) -> Option<[f64; 2]> {
        let near: Vec<usize> = crate::neighbours::within(rings, v, crate::augment::LOCAL_RINGS)
            .into_iter()
            .filter(|&u| material_of(u) == Some(j))
            .filter(|&u| matches!(self.curves[0].get(u), Some(Some(_))))
            .collect();
        if near.len() < crate::augment::pool::MIN_VERTICES {
            return None;
        }
        let [eta, se] = self.profile_minimum(&near)?;
        (eta.is_finite() && se.is_finite() && se >= 0.0).then_some([eta, se])
    }

    /// The minimum of the summed curves of `near` (their own curves' sum per normal tilt, the
    /// best tilt at each η: the normal is a nuisance, profiled out) and its residual σ.
    fn profile_minimum(&self, near: &[usize]) -> Option<[f64; 2]> {
        let sums: Vec<Vec<f64>> = self.curves.iter().filter_map(|c| summed(c, near)).collect();
        let first = sums.first()?;
        let profile: Vec<f64> = (0..first.len())
            .map(|g| sums.iter().map(|s| s[g]).fold(f64::INFINITY, f64::min))
            .collect();
        let (values, unknowns) = near.iter().try_fold((0, 0), |(m, p), &u| {
            let c = self.curves[0].get(u)?.as_ref()?;
            Some((m + c.values, p + c.unknowns))
        })?;
        minimum_of(&profile, values, unknowns)
    }
}

fn summed(curves: &[Option<Curve>], near: &[usize]) -> Option<Vec<f64>> {
    let mut sum = vec![0.0; grid_len()];
    for &u in near {
        // A vertex whose tilted normal leaves no diffuse fit has no curve there: the sum
        // would compare unlike sets of samples.
        let c = curves.get(u)?.as_ref()?;
        for (s, c) in sum.iter_mut().zip(&c.cost) {
            *s += c;
        }
    }
    Some(sum)
}

/// The minimum of `sum` (a summed curve of `values` residuals and `unknowns` albedos) and its
/// residual standard error (module doc); `None` at the grid's end or where the curve is not
/// convex there.
fn minimum_of(sum: &[f64], values: usize, unknowns: usize) -> Option<[f64; 2]> {
    let n = sum.len();
    let dof = values.checked_sub(unknowns + 1).filter(|&d| d > 0)?;
    let g = (0..n).min_by(|&a, &b| sum[a].total_cmp(&sum[b]))?;
    if g == 0 || g + 1 == n {
        return None;
    }
    let (lo, mid, hi) = (sum[g - 1], sum[g], sum[g + 1]);
    let second = lo - 2.0 * mid + hi;
    // Not convex at the minimum (flat to rounding): η is not fixed there.
    if second.is_nan() || second <= 0.0 {
        return None;
    }
    let offset = (0.5 * (lo - hi) / second).clamp(-0.5, 0.5);
    let eta = grid_eta(g) + offset * ETA_STEP;
    let c_min = mid - 0.125 * (lo - hi) * (lo - hi) / second;
    let s2 = c_min.max(0.0) / dof as f64;
    let curvature = second / (ETA_STEP * ETA_STEP);
    Some([eta, (2.0 * s2 / curvature).sqrt()])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::tests::{material, synth};
    use crate::synthetic::{SensorNoise, orbit_views};

    /// A 5 × 5 grid of vertices (4-neighbour rings), all at the origin facing `normal`, each
    /// keeping `keep` of its samples: too few for the per-vertex solve alone.
    fn patch(
        truth: &PbrdfParams<f64>,
        normal: [f64; 3],
        keep: usize,
        noise: Option<&SensorNoise>,
    ) -> SampleSet {
        let views = orbit_views(40, 0.5, [20.0, 70.0], 1.0, [0.0; 3], [0.0, 0.03, 0.0]);
        let vertices = (0..25u64)
            .map(|v| {
                let mut s = synth(&views, normal, truth, noise, 1.0, v);
                // A different few samples per vertex: every fifth, from its own start.
                let start = v as usize % 5;
                s.samples = s
                    .samples
                    .iter()
                    .skip(start)
                    .step_by(5)
                    .take(keep)
                    .copied()
                    .collect();
                s
            })
            .collect();
        let rings = (0..25usize)
            .map(|v| {
                let (x, y) = (v % 5, v / 5);
                let mut r = Vec::new();
                if x > 0 {
                    r.push((v - 1) as u32);
                }
                if x < 4 {
                    r.push((v + 1) as u32);
                }
                if y > 0 {
                    r.push((v - 5) as u32);
                }
                if y < 4 {
                    r.push((v + 5) as u32);
                }
                r
            })
            .collect();
        SampleSet {
            vertices,
            views,
            colour: true,
            rings,
        }
    }

    fn tilted(deg: f64) -> [f64; 3] {
        let r = deg.to_radians();
        [r.sin(), 0.0, r.cos()]
    }

    #[test]
    fn a_neighbourhood_of_few_samples_each_identifies_its_eta() {
        let mut truth = material("ceramic");
        truth.eta = 1.9;
        let normal = tilted(40.0);
        let set = patch(&truth, normal, 4, None);
        assert!(
            set.vertices
                .iter()
                .all(|v| v.samples.len() <= 4 && !v.samples.is_empty())
        );
        let curves = Curves::new(&set, 5.0, |_| Some((truth, normal, 0.0)));
        let rings = set.rings.clone();
        // The centre's two rings hold 13 vertices of the grid.
        let [eta, se] = curves
            .local(&rings, 12, 0, |_| Some(0))
            .expect("identified");
        // Noise-free samples of the model: the minimum is the truth, to the parabola's
        // third-order error on the grid.
        assert!((eta - 1.9).abs() < 2e-3, "{eta}");
        assert!(se.is_finite() && se < 1e-3, "{se}");
    }

    #[test]
    fn noise_widens_the_local_eta_and_other_materials_do_not_enter() {
        let mut truth = material("ceramic");
        truth.eta = 1.7;
        let normal = tilted(35.0);
        let noise = SensorNoise {
            dn_per_electron: 0.39,
            read_noise_e: 2.3,
            full_scale_dn: 4095.0,
            shot_noise: true,
        };
        let set = patch(&truth, normal, 6, Some(&noise));
        let curves = Curves::new(&set, 5.0, |_| Some((truth, normal, 0.0)));
        let rings = set.rings.clone();
        let [eta, se] = curves
            .local(&rings, 12, 0, |_| Some(0))
            .expect("identified");
        assert!(se > 1e-4, "noise must show in σ: {se}");
        assert!((eta - 1.7).abs() < 4.0 * se + 2e-3, "{eta} ± {se}");
        // Only the centre's own group counts: with the rest of another material, too few.
        assert_eq!(
            curves.local(&rings, 12, 0, |u| Some(usize::from(u != 12))),
            None
        );
    }

    #[test]
    fn a_minimum_at_the_end_of_the_range_is_no_estimate() {
        // A flat curve has no interior minimum; one falling to the grid's end is at a bound.
        let n = grid_len();
        assert_eq!(minimum_of(&vec![1.0; n], 100, 3), None);
        let falling: Vec<f64> = (0..n).map(|g| (n - g) as f64).collect();
        assert_eq!(minimum_of(&falling, 100, 3), None);
        // A parabola about 1.5: found, its σ the Δχ² = 1 half-width at s² = C_min/dof.
        let parabola: Vec<f64> = (0..n)
            .map(|g| 10.0 + 1e4 * (grid_eta(g) - 1.5).powi(2))
            .collect();
        let [eta, se] = minimum_of(&parabola, 104, 3).expect("interior minimum");
        assert!((eta - 1.5).abs() < 1e-9, "{eta}");
        // s² = 10/100, C″ = 2e4: σ = √(2·0.1/2e4) = 3.16e-3.
        assert!((se - (0.2f64 / 2e4).sqrt()).abs() < 1e-9, "{se}");
    }
}
