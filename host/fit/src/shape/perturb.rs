//! A seeded, smooth perturbation of a mesh along its vertex normals: the simulator's exact mesh
//! turned into a stand-in for an imperfect scanned mesh (tests and the accuracy benchmark).
//!
//! Contract:
//! - The offset field is a sum of [`BUMPS`] Gaussian bumps in space, centred on seeded vertices,
//!   of width [`BUMP_WIDTH_FRACTION`] of the bounding-box diagonal, with seeded coefficients
//!   uniform in [−1, 1]. Its vertex mean is removed (the perturbation changes the shape, not the
//!   overall size, which normals could never recover) and it is scaled so that the RMS offset
//!   over the vertices is `|amplitude_m|`.
//! - Each vertex moves by its offset along its mesh normal. Triangles and region ids are kept;
//!   normals are recomputed from the new positions.
//! - The result depends only on the mesh, `amplitude_m` and `seed` (ChaCha8).
//! - A zero or non-finite amplitude, or a mesh whose offsets all vanish, gives an unchanged copy.

use ellipso_model::geometry::TriangleMesh;
use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Number of Gaussian bumps in the offset field.
pub const BUMPS: usize = 32;
/// Bump width (Gaussian σ) as a fraction of the bounding-box diagonal.
pub const BUMP_WIDTH_FRACTION: f64 = 0.1;

/// `mesh` with its vertices moved along their normals by smooth seeded noise of RMS
/// `|amplitude_m|` metres (see the module doc).
pub fn perturb_mesh(mesh: &TriangleMesh, amplitude_m: f64, seed: u64) -> TriangleMesh {
    let positions = mesh.positions();
    let n = positions.len();
    if n == 0 || !amplitude_m.is_finite() || amplitude_m == 0.0 {
        return mesh.clone();
    }
    let (lo, hi) = positions.iter().fold(
        (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.inf(&p.coords), hi.sup(&p.coords)),
    );
    let diagonal = (hi - lo).norm();
    // Guard: a mesh collapsed to a point has no length scale.
    if diagonal.is_nan() || diagonal <= 0.0 {
        return mesh.clone();
    }
    let width = BUMP_WIDTH_FRACTION * diagonal;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let bumps: Vec<(Point3<f64>, f64)> = (0..BUMPS)
        .map(|_| {
            let centre = positions[rng.random_range(0..n)];
            (centre, rng.random_range(-1.0..=1.0))
        })
        .collect();
    let mut offsets: Vec<f64> = positions
        .iter()
        .map(|p| {
            bumps
                .iter()
                .map(|(c, k)| k * (-(p - c).norm_squared() / (2.0 * width * width)).exp())
                .sum()
        })
        .collect();
    let mean = offsets.iter().sum::<f64>() / n as f64;
    offsets.iter_mut().for_each(|o| *o -= mean);
    let rms = (offsets.iter().map(|o| o * o).sum::<f64>() / n as f64).sqrt();
    // Guard the scaling: an all-zero field cannot be scaled to the amplitude.
    if rms.is_nan() || rms <= 0.0 {
        return mesh.clone();
    }
    let scale = amplitude_m.abs() / rms;
    let moved: Vec<Point3<f64>> = positions
        .iter()
        .zip(mesh.normals())
        .zip(&offsets)
        .map(|((p, normal), o)| p + normal.into_inner() * (o * scale))
        .collect();
    // Finite positions moved by finite offsets stay finite and the triangles are unchanged, so
    // construction cannot fail; an unchanged copy is the safe answer if it ever did.
    TriangleMesh::new(
        moved,
        None,
        mesh.regions().map(<[u32]>::to_vec),
        mesh.triangles().to_vec(),
    )
    .unwrap_or_else(|_| mesh.clone())
}

#[cfg(test)]
mod tests {
    use ellipso_model::geometry::procedural::bumpy_icosphere;

    /// The perturbation is seeded, moves along the normals with the requested RMS and zero mean, and
    /// is smooth (neighbouring offsets differ by a small fraction of the amplitude).
    #[test]
    fn perturbation_is_seeded_smooth_and_has_the_requested_rms() {
        let sphere = bumpy_icosphere(4, 0.0, 0, 0);
        let a = super::perturb_mesh(&sphere, 0.01, 42);
        let b = super::perturb_mesh(&sphere, 0.01, 42);
        let c = super::perturb_mesh(&sphere, 0.01, 43);
        assert_eq!(a.positions(), b.positions());
        assert_ne!(a.positions(), c.positions());
        let offsets: Vec<f64> = a
            .positions()
            .iter()
            .zip(sphere.positions())
            .zip(sphere.normals())
            .map(|((p, q), normal)| {
                let d = p - q;
                // Along the mesh normal only.
                assert!(d.cross(normal).norm() < 1e-12);
                d.dot(normal)
            })
            .collect();
        let n = offsets.len() as f64;
        let mean = offsets.iter().sum::<f64>() / n;
        let rms = (offsets.iter().map(|o| o * o).sum::<f64>() / n).sqrt();
        assert!(
            mean.abs() < 1e-12 && (rms - 0.01).abs() < 1e-12,
            "{mean} {rms}"
        );
        let worst_jump = sphere
            .triangles()
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .map(|(u, v)| (offsets[u as usize] - offsets[v as usize]).abs())
            .fold(0.0, f64::max);
        assert!(worst_jump < 0.01, "jump {worst_jump} for RMS 0.01");
        assert_eq!(
            super::perturb_mesh(&sphere, f64::NAN, 1).positions(),
            sphere.positions()
        );
    }
}
