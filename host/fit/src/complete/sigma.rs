//! The standard errors of what a completed vertex takes from its surface rather than its
//! data ([`super::complete`]): its normal is the surface's, so its σ is how far the input
//! mesh's normals stray from the fitted ones where the data pin them
//! ([`mesh_normal_std_deg`]); and its own ρd, estimated from a few samples at that normal,
//! carries that normal's uncertainty ([`normal_tilt_rho_d_se`]) besides the residuals'.
//! Measured on generated scenes (docs/generalize.md): completed vertices' normals were off by
//! 3.6° (68th percentile) against a claimed 0.34°, their own ρd by −25 % against a claimed 3 %.

use crate::data::{SampleSet, VertexFit};

/// The part of a completed vertex's ρd standard error that its normal's uncertainty makes:
/// the RMS change of the estimate when the normal tilts by `normal_std_deg` towards each of
/// four tangent directions (the diffuse term goes as cos θi, so a tilt δ changes the estimate
/// by about tan θi·δ relative: 10 % at θi = 70° and 2°; the residuals of the few samples a
/// completed vertex has cannot show it). 0 where σ is 0 or not finite; a tilt the samples'
/// geometry rejects counts as the whole estimate.
pub(super) fn normal_tilt_rho_d_se(
    set: &SampleSet,
    vertex: &crate::data::VertexSamples,
    params: &ellipso_model::optics::pbrdf::PbrdfParams<f64>,
    normal: [f64; 3],
    normal_std_deg: f64,
    albedo_cap: f64,
    rho: [f64; 3],
) -> [f64; 3] {
    if !(normal_std_deg.is_finite() && normal_std_deg > 0.0) {
        return [0.0; 3];
    }
    if nalgebra::Unit::try_new(nalgebra::Vector3::from(normal), 1e-12).is_none() {
        return [0.0; 3];
    }
    let mut sum2 = [0.0f64; 3];
    for tilted in &tilted_normals(normal, normal_std_deg)[1..] {
        let changed = super::rho_d_of(set, vertex, &vertex.samples, params, *tilted, albedo_cap)
            .map(|(r, _)| r);
        for c in 0..3 {
            let d = changed.map_or(rho[c], |r| r[c] - rho[c]);
            sum2[c] += d * d;
        }
    }
    sum2.map(|s| (s / 4.0).sqrt())
}

/// `normal` (the first entry), then tilted by `sigma_deg` towards each of four tangent
/// directions ±t1, ±t2 (any two: the axis least aligned with the normal, orthogonalised). All
/// five are `normal` where it is not a direction or σ is 0 or not finite.
pub(super) fn tilted_normals(normal: [f64; 3], sigma_deg: f64) -> [[f64; 3]; 5] {
    let mut out = [normal; 5];
    let Some(n) = nalgebra::Unit::try_new(nalgebra::Vector3::from(normal), 1e-12) else {
        return out;
    };
    if !(sigma_deg.is_finite() && sigma_deg > 0.0) {
        return out;
    }
    let helper = if n.x.abs() < 0.9 {
        nalgebra::Vector3::x()
    } else {
        nalgebra::Vector3::y()
    };
    let t1 = n.cross(&helper).normalize();
    let t2 = n.cross(&t1);
    let delta = sigma_deg.to_radians();
    for (o, dir) in out.iter_mut().skip(1).zip([t1, -t1, t2, -t2]) {
        *o = (n.into_inner() * delta.cos() + dir * delta.sin())
            .normalize()
            .into();
    }
    out
}

/// Fewest vertices with their own normal [`mesh_normal_std_deg`] reads a spread from: the
/// 68th percentile of 20 draws lies within about ±0.3 of its quantile level's neighbours
/// (binomial sd √(0.68·0.32/20) ≈ 0.10 in level), enough for a σ that sets a limit.
pub const MESH_NORMAL_MIN_VERTICES: usize = 20;

/// How far the input mesh's normals stray from the surface, measured where the data pin the
/// normal: the 68th percentile (1σ of a two-sided spread) of the angle between the mesh's
/// normal `mesh_normals[v]` and the fitted normal over the vertices whose own data identified
/// their parameters (their fitted normal is ~10× more precise than that angle, so the angle is
/// the mesh's error). A completed vertex's normal is the surface's where its own data say
/// nothing, so this — not the refined surface's σ at the fitted vertices — is its σ.
/// `None` with fewer than [`MESH_NORMAL_MIN_VERTICES`] such vertices.
pub fn mesh_normal_std_deg(fits: &[VertexFit], mesh_normals: &[[f64; 3]]) -> Option<f64> {
    let mut angles: Vec<f64> = fits
        .iter()
        .zip(mesh_normals)
        .filter(|(f, _)| super::own_vertex(f))
        .map(|(f, m)| {
            ellipso_model::geometry::angle_between_deg(
                &nalgebra::Vector3::from(f.normal_world),
                &nalgebra::Vector3::from(*m),
            )
        })
        .filter(|a| a.is_finite())
        .collect();
    if angles.len() < MESH_NORMAL_MIN_VERTICES {
        return None;
    }
    angles.sort_by(f64::total_cmp);
    let k = ((0.68 * angles.len() as f64).ceil() as usize).clamp(1, angles.len()) - 1;
    Some(angles[k])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::FitFlag;
    use crate::solve::tests::{material, synth};
    use crate::synthetic::orbit_views;

    fn fit(normal_world: [f64; 3], flags: Vec<FitFlag>) -> VertexFit {
        VertexFit {
            vertex: 0,
            params: material("ceramic"),
            normal_world,
            std_error: [0.01; 10],
            normal_std_error_deg: 0.1,
            samples_used: 50,
            cost: 0.0,
            iterations: 1,
            flags,
            eta_unpooled: None,
            eta_prior_only: false,
            gates: Default::default(),
        }
    }

    fn tilted(deg: f64) -> [f64; 3] {
        let r = deg.to_radians();
        [r.sin(), 0.0, r.cos()]
    }

    #[test]
    fn the_mesh_normal_sigma_is_the_68th_percentile_of_the_own_vertices_stray() {
        let up = [0.0, 0.0, 1.0];
        // 30 own vertices whose fitted normals are 0°, 1°, …, 29° off the mesh's.
        let mut fits: Vec<VertexFit> = (0..30).map(|k| fit(tilted(k as f64), vec![])).collect();
        let mut mesh = vec![up; 30];
        // Completed vertices (their normal is the mesh's) say nothing about the mesh.
        fits.push(fit(tilted(80.0), vec![FitFlag::FromMaterial]));
        mesh.push(up);
        let sigma = mesh_normal_std_deg(&fits, &mesh).expect("30 own vertices");
        // ⌈0.68·30⌉ = 21st smallest: 20°.
        assert!((sigma - 20.0).abs() < 1e-9, "{sigma}");
        // Fewer own vertices than the minimum: no σ.
        let few = MESH_NORMAL_MIN_VERTICES - 1;
        assert_eq!(mesh_normal_std_deg(&fits[..few], &mesh[..few]), None);
    }

    #[test]
    fn a_completed_vertex_rho_d_carries_its_normal_uncertainty() {
        let views = orbit_views(40, 0.5, [20.0, 70.0], 1.0, [0.0; 3], [0.0, 0.03, 0.0]);
        let truth = material("ceramic");
        let up = [0.0, 0.0, 1.0];
        // A vertex facing the cameras and one the views and flash see at grazing angles.
        let side = tilted(75.0);
        let set = SampleSet {
            vertices: vec![
                synth(&views, up, &truth, None, 1.0, 0),
                synth(&views, side, &truth, None, 1.0, 1),
            ],
            views,
            colour: true,
            rings: Vec::new(),
        };
        let cap = 5.0;
        for (v, normal) in [(0, up), (1, side)] {
            let (rho, se) =
                crate::complete::own_rho_d(&set, v, &truth, normal, 0.0, cap).expect("samples");
            // Noise-free samples at the true normal: the estimate is the truth, no spread.
            for c in 0..3 {
                assert!(
                    (rho[c] - truth.rho_d[c]).abs() < 1e-6 * truth.rho_d[c],
                    "{v} {c}"
                );
                assert!(se[c] < 1e-6, "{v} {c}: {}", se[c]);
            }
        }
        let relative = |v: usize, normal: [f64; 3]| {
            let (rho, se) =
                crate::complete::own_rho_d(&set, v, &truth, normal, 2.0, cap).expect("samples");
            se[1] / rho[1]
        };
        let (head_on, grazing) = (relative(0, up), relative(1, side));
        // A 2° tilt moves cos θi by tan θi · 2°: a few per cent where the light comes in
        // steeply, more at grazing incidence.
        assert!(head_on > 1e-3 && head_on < 0.05, "{head_on}");
        assert!(grazing > 2.0 * head_on, "{grazing} vs {head_on}");
    }
}
