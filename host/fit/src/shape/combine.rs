//! The reported normal after the outer loop: each vertex's refined normal combined with the
//! normal of the surface the loop moved the mesh to, weighted by their precisions
//! (docs/fit-shape.md "The reported normal").
//!
//! Why. A vertex's refined normal comes from its own samples alone; with few photos (~25
//! samples a vertex at 60 photos) it scatters by 1–2°. The surface update integrates the
//! refined normals of every vertex's neighbours and the silhouettes into one surface, so the
//! surface's normal is that scatter averaged over a neighbourhood — and where the data are
//! dense the refined normal sees detail finer than the surface follows. Precision weighting
//! takes whichever is better at each vertex without a switch.
//!
//! Contract:
//! - [`surface_normal_std_deg`] is the surface normal's 1σ: the last *applied* surface step's
//!   misfit (median angle between the refined normals and the stepped mesh's normals), `None`
//!   when no step was applied (the mesh is the input's, whose accuracy only the solve's normal
//!   prior speaks for). The misfit holds both errors, so it overstates the surface's own: the
//!   combination leans towards the refined normal, never past what the data say.
//! - [`combine_with_surface`] replaces `normal_world` of every fit by
//!   `normalise(n_r/σ_r² + n_s/σ_s²)` (σ_r the fit's `normal_std_error_deg`, σ_s the surface's).
//!   Left as they are, and counted: a refined normal the shape update does not trust either
//!   ([`super::normal_trusted`]: a flag of [`super::NORMAL_VOIDING_FLAGS`], a non-finite or
//!   negative σ_r; or no direction) — the vertex's parameters were fitted with it, and its
//!   normal is no measurement to improve;
//!   a pair 90° or more apart (no tangent plane to average in); σ_r < 10⁻⁹° (exact).
//! - `normal_std_error_deg` is left as the refined normal's own: the surface was built from
//!   the same samples, so the two are not independent and the textbook combined σ would claim
//!   more than the data give.
//! - Errors: `surface_normals` not one per fitted vertex, or σ_s not finite and > 0.

use super::{ShapeError, normal_trusted};
use crate::data::VertexFit;
use crate::shape::surface::SurfaceIteration;
use nalgebra::{Unit, Vector3};

/// What [`combine_with_surface`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NormalCombination {
    /// The surface normal's 1σ used, degrees.
    pub surface_std_deg: f64,
    /// Fits whose normal was combined.
    pub combined: usize,
    /// Fits whose refined normal the shape update does not trust, left as they were.
    pub untrusted: usize,
    /// Pairs 90° or more apart, left as they were.
    pub opposed: usize,
    /// Median angle the combination turned a normal by, degrees (0 without any).
    pub median_turn_deg: f64,
}

impl NormalCombination {
    /// One line for progress output.
    pub fn describe(&self) -> String {
        format!(
            "normals: refined normals combined with the refined surface's (σ {:.2}°) at {} \
             vertices, turned {:.2}° at the median ({} untrusted and {} opposed left as they were)",
            self.surface_std_deg, self.combined, self.median_turn_deg, self.untrusted, self.opposed
        )
    }
}

/// The surface normal's 1σ from the outer loop's steps: the last applied step's misfit after
/// it, degrees; `None` when no step was applied or that misfit is not a positive number.
pub fn surface_normal_std_deg(steps: &[SurfaceIteration]) -> Option<f64> {
    steps
        .iter()
        .rev()
        .find(|s| s.applied)
        .map(|s| s.misfit_after_deg)
        .filter(|m| m.is_finite() && *m > 0.0)
}

/// Combines every fit's refined normal with `surface_normals[fit.vertex]` (see the module
/// contract).
pub fn combine_with_surface(
    fits: &mut [VertexFit],
    surface_normals: &[Unit<Vector3<f64>>],
    surface_std_deg: f64,
) -> Result<NormalCombination, ShapeError> {
    if !(surface_std_deg.is_finite() && surface_std_deg > 0.0) {
        return Err(ShapeError::InvalidConfig {
            field: "surface_std_deg",
            value: surface_std_deg,
        });
    }
    let weight_surface = surface_std_deg.powi(-2);
    let mut report = NormalCombination {
        surface_std_deg,
        ..Default::default()
    };
    let mut turns = Vec::with_capacity(fits.len());
    for fit in fits.iter_mut() {
        let Some(surface) = surface_normals.get(fit.vertex as usize) else {
            return Err(ShapeError::BadFitVertex {
                vertex: fit.vertex,
                reason: "out of range",
                vertices: surface_normals.len(),
            });
        };
        let sigma = fit.normal_std_error_deg;
        let refined = Unit::try_new(Vector3::from(fit.normal_world), 1e-12);
        let Some(refined) = refined.filter(|_| normal_trusted(sigma, &fit.flags)) else {
            report.untrusted += 1;
            continue;
        };
        if sigma < 1e-9 {
            // exact for any use (and 1/σ² would overflow)
            continue;
        }
        if refined.dot(surface) <= 0.0 {
            report.opposed += 1;
            continue;
        }
        let weight_refined = sigma.powi(-2);
        // Both weights are finite and positive (σ_s > 0 checked, σ_r > 0 here), the unit vectors
        // less than 90° apart: the sum has a positive length.
        let sum = refined.into_inner() * weight_refined + surface.into_inner() * weight_surface;
        let combined = Unit::new_normalize(sum);
        turns.push(refined.dot(&combined).clamp(-1.0, 1.0).acos().to_degrees());
        fit.normal_world = combined.into_inner().into();
        report.combined += 1;
    }
    if !turns.is_empty() {
        report.median_turn_deg = ellipso_model::stats::median(&mut turns);
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::FitFlag;
    use crate::shape::tests::fit;

    const UP: [f64; 3] = [0.0, 0.0, 1.0];

    /// A unit normal tilted `deg` from +z towards +x.
    fn tilted(deg: f64) -> [f64; 3] {
        let t = deg.to_radians();
        [t.sin(), 0.0, t.cos()]
    }

    fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
        ellipso_model::geometry::angle_between_deg(&Vector3::from(a), &Vector3::from(b))
    }

    fn surface(n: usize) -> Vec<Unit<Vector3<f64>>> {
        vec![Vector3::z_axis(); n]
    }

    #[test]
    fn equal_precisions_meet_halfway_and_the_more_precise_normal_wins() {
        // refined 2° off, both 1σ = 1°: halfway (1°); refined σ 0.2° against the surface's
        // 1°: weights 25 : 1, so 2°·25/26 ≈ 1.92°; refined σ 3°: 2°·(1/9)/(1/9 + 1) = 0.2°.
        let mut fits = vec![
            fit(0, tilted(2.0), 1.0, vec![]),
            fit(1, tilted(2.0), 0.2, vec![]),
            fit(2, tilted(2.0), 3.0, vec![]),
        ];
        let report = combine_with_surface(&mut fits, &surface(3), 1.0).unwrap();
        assert_eq!((report.combined, report.untrusted), (3, 0));
        let off: Vec<f64> = fits.iter().map(|f| angle_deg(f.normal_world, UP)).collect();
        assert!((off[0] - 1.0).abs() < 1e-3, "{off:?}");
        assert!((off[1] - 2.0 * 25.0 / 26.0).abs() < 1e-3, "{off:?}");
        assert!((off[2] - 0.2).abs() < 1e-3, "{off:?}");
        // the reported standard error stays the solve's own
        assert_eq!(fits[1].normal_std_error_deg, 0.2);
        for f in &fits {
            let n = Vector3::from(f.normal_world);
            assert!((n.norm() - 1.0).abs() < 1e-12);
            // the combination turns within the plane of the two normals
            assert!(n.y.abs() < 1e-12);
        }
    }

    #[test]
    fn a_normal_the_data_do_not_fix_is_left_as_it_is() {
        let mut fits = vec![
            fit(
                0,
                tilted(20.0),
                f64::INFINITY,
                vec![FitFlag::NormalUnconstrained],
            ),
            fit(1, tilted(20.0), 0.5, vec![FitFlag::GrazingOnly]),
            fit(2, tilted(20.0), f64::NAN, vec![]),
            fit(3, [0.0; 3], 0.5, vec![]),
        ];
        let before: Vec<[f64; 3]> = fits.iter().map(|f| f.normal_world).collect();
        let report = combine_with_surface(&mut fits, &surface(4), 1.0).unwrap();
        assert_eq!((report.combined, report.untrusted), (0, 4));
        let after: Vec<[f64; 3]> = fits.iter().map(|f| f.normal_world).collect();
        assert_eq!(before, after);
    }

    #[test]
    fn exact_and_opposed_normals_are_left_alone() {
        let mut fits = vec![
            fit(0, tilted(2.0), 0.0, vec![]),
            fit(1, tilted(120.0), 1.0, vec![]),
        ];
        let report = combine_with_surface(&mut fits, &surface(2), 1.0).unwrap();
        assert_eq!((report.combined, report.opposed), (0, 1));
        assert_eq!(fits[0].normal_world, tilted(2.0));
        assert_eq!(fits[1].normal_world, tilted(120.0));
        assert_eq!(report.median_turn_deg, 0.0);
    }

    #[test]
    fn noisy_normals_on_a_good_surface_come_closer_to_it() {
        // refined normals scattered ~1.5° about the truth (+z), the surface's 0.5° off: the
        // combination lands nearer the truth than either alone would at most vertices.
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let n = 500;
        let mut fits: Vec<VertexFit> = (0..n)
            .map(|v| {
                let (a, b): (f64, f64) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
                let t = [a * 2.6f64.to_radians(), b * 2.6f64.to_radians(), 1.0];
                let t = Vector3::from(t).normalize();
                fit(v as u32, t.into(), 1.5, vec![])
            })
            .collect();
        let before: Vec<f64> = fits.iter().map(|f| angle_deg(f.normal_world, UP)).collect();
        let surface_off = Unit::new_normalize(Vector3::from(tilted(0.5)));
        let normals = vec![surface_off; n];
        let report = combine_with_surface(&mut fits, &normals, 1.0).unwrap();
        let mut after: Vec<f64> = fits.iter().map(|f| angle_deg(f.normal_world, UP)).collect();
        let mut before = before;
        let (b, a) = (
            ellipso_model::stats::median(&mut before),
            ellipso_model::stats::median(&mut after),
        );
        assert_eq!(report.combined, n);
        assert!(a < 0.6 * b, "median error {b:.2}° → {a:.2}°");
        assert!(report.median_turn_deg > 0.5, "{report:?}");
    }

    #[test]
    fn bad_inputs_are_errors() {
        let mut fits = vec![fit(3, UP, 1.0, vec![])];
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                combine_with_surface(&mut fits, &surface(4), bad),
                Err(ShapeError::InvalidConfig { .. })
            ));
        }
        assert!(matches!(
            combine_with_surface(&mut fits, &surface(3), 1.0),
            Err(ShapeError::BadFitVertex { vertex: 3, .. })
        ));
    }

    #[test]
    fn the_surface_sigma_is_the_last_applied_steps_misfit() {
        let step = |applied: bool, misfit: f64| SurfaceIteration {
            applied,
            misfit_after_deg: misfit,
            ..Default::default()
        };
        assert_eq!(surface_normal_std_deg(&[]), None);
        assert_eq!(surface_normal_std_deg(&[step(false, 0.4)]), None);
        assert_eq!(
            surface_normal_std_deg(&[step(true, 0.9), step(true, 0.6), step(false, 0.3)]),
            Some(0.6)
        );
        assert_eq!(surface_normal_std_deg(&[step(true, 0.0)]), None);
        assert_eq!(surface_normal_std_deg(&[step(true, f64::NAN)]), None);
    }
}
