//! Procedural meshes for shipped assets and tests: a subdivided icosphere with smooth seeded bumps
//! and per-vertex region ids (spherical Voronoi cells around seeded directions).
//!
//! Contract: output depends only on the arguments (ChaCha8 seeded), so the committed asset
//! `sim/assets/bumpy_blob.ply` can be regenerated and checked. The radius is 1 before bumps; bumps
//! are `amplitude · Σ exp(-(angle/0.35 rad)²)` over eight seeded centres with signs ±1, so the
//! surface stays star-shaped (radius in `[1 - 8·amplitude, 1 + 8·amplitude]`, positive for
//! amplitude < 1/8). Triangles wind counter-clockwise seen from outside.

use super::TriangleMesh;
use nalgebra::{Point3, Unit, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;

/// Subdivision level of the shipped asset `sim/assets/bumpy_blob.ply`.
pub const BLOB_SUBDIVISIONS: u32 = 4;
/// Relative bump amplitude of the shipped asset.
pub const BLOB_AMPLITUDE: f64 = 0.06;
/// Region count of the shipped asset.
pub const BLOB_REGIONS: u32 = 4;
/// Seed of the shipped asset.
pub const BLOB_SEED: u64 = 2022;

/// Unit icosphere after `subdivisions` 4-to-1 splits: `10·4^s + 2` vertices, `20·4^s` faces.
pub fn icosphere(subdivisions: u32) -> (Vec<Unit<Vector3<f64>>>, Vec<[u32; 3]>) {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let raw = [
        (-1.0, phi, 0.0),
        (1.0, phi, 0.0),
        (-1.0, -phi, 0.0),
        (1.0, -phi, 0.0),
        (0.0, -1.0, phi),
        (0.0, 1.0, phi),
        (0.0, -1.0, -phi),
        (0.0, 1.0, -phi),
        (phi, 0.0, -1.0),
        (phi, 0.0, 1.0),
        (-phi, 0.0, -1.0),
        (-phi, 0.0, 1.0),
    ];
    let mut verts: Vec<Unit<Vector3<f64>>> = raw
        .iter()
        .map(|&(x, y, z)| Unit::new_normalize(Vector3::new(x, y, z)))
        .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut cache: HashMap<(u32, u32), u32> = HashMap::new();
        let mut mid = |a: u32, b: u32, verts: &mut Vec<Unit<Vector3<f64>>>| {
            *cache.entry((a.min(b), a.max(b))).or_insert_with(|| {
                verts.push(Unit::new_normalize(
                    verts[a as usize].as_ref() + verts[b as usize].as_ref(),
                ));
                (verts.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = mid(a, b, &mut verts);
            let bc = mid(b, c, &mut verts);
            let ca = mid(c, a, &mut verts);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    (verts, faces)
}

fn random_direction(rng: &mut ChaCha8Rng) -> Unit<Vector3<f64>> {
    // Uniform on the sphere: z uniform in [-1, 1], azimuth uniform.
    let z: f64 = rng.random_range(-1.0..=1.0);
    let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    // Clamp: 1 - z² can round below zero at |z| = 1.
    let r = (1.0 - z * z).max(0.0).sqrt();
    Unit::new_normalize(Vector3::new(r * a.cos(), r * a.sin(), z))
}

/// A bumpy unit blob with `regions` region ids (Voronoi cells around seeded directions).
/// `amplitude` is the relative bump height (see the module doc for the radius bounds).
pub fn bumpy_icosphere(subdivisions: u32, amplitude: f64, regions: u32, seed: u64) -> TriangleMesh {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (dirs, faces) = icosphere(subdivisions);
    let bumps: Vec<(Unit<Vector3<f64>>, f64)> = (0..8)
        .map(|_| {
            (
                random_direction(&mut rng),
                if rng.random::<bool>() { 1.0 } else { -1.0 },
            )
        })
        .collect();
    let centres: Vec<Unit<Vector3<f64>>> = (0..regions.max(1))
        .map(|_| random_direction(&mut rng))
        .collect();
    let radius = |d: &Vector3<f64>| {
        1.0 + amplitude
            * bumps
                .iter()
                .map(|(c, s)| {
                    // Clamp the dot product into acos's domain.
                    let ang = c.dot(d).clamp(-1.0, 1.0).acos();
                    s * (-(ang / 0.35).powi(2)).exp()
                })
                .sum::<f64>()
    };
    let positions: Vec<Point3<f64>> = dirs
        .iter()
        .map(|d| Point3::from(d.into_inner() * radius(d)))
        .collect();
    let region_ids: Vec<u32> = dirs
        .iter()
        .map(|d| {
            (0..centres.len())
                .max_by(|&a, &b| centres[a].dot(d).total_cmp(&centres[b].dot(d)))
                .unwrap_or(0) as u32
        })
        .collect();
    let regions = (regions > 0).then_some(region_ids);
    // The icosphere always has faces and finite vertices, so construction cannot fail.
    TriangleMesh::new(positions, None, regions, faces)
        .unwrap_or_else(|e| unreachable!("procedural mesh is valid by construction: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Intersect;
    use crate::geometry::Ray;

    #[test]
    fn icosphere_counts_and_outward_winding() {
        for s in 0..3 {
            let (v, f) = icosphere(s);
            assert_eq!(v.len(), 10 * 4usize.pow(s) + 2);
            assert_eq!(f.len(), 20 * 4usize.pow(s));
            for [a, b, c] in f {
                let (a, b, c) = (v[a as usize], v[b as usize], v[c as usize]);
                let n = (b.into_inner() - a.into_inner()).cross(&(c.into_inner() - a.into_inner()));
                assert!(n.dot(&(a.into_inner() + b.into_inner() + c.into_inner())) > 0.0);
            }
        }
    }

    #[test]
    fn blob_is_deterministic_closed_and_has_every_region() {
        let a = bumpy_icosphere(3, 0.08, 4, 3);
        let b = bumpy_icosphere(3, 0.08, 4, 3);
        let c = bumpy_icosphere(3, 0.08, 4, 4);
        assert_eq!(a.positions(), b.positions());
        assert_ne!(a.positions(), c.positions());
        assert_eq!(a.region_count(), 4);
        let r = a.regions().expect("regions");
        for k in 0..4 {
            assert!(r.contains(&k), "region {k} present");
        }
        // Star-shaped and closed: every ray from the centre hits exactly once going out.
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..200 {
            let d = random_direction(&mut rng);
            let ray = Ray::new(Point3::origin(), d.into_inner());
            let h = a
                .intersect(&ray, 0.0, f64::INFINITY)
                .expect("closed surface");
            assert!(h.t > 1.0 - 8.0 * 0.08 && h.t < 1.0 + 8.0 * 0.08);
            assert!(h.normal_geometric.dot(&d) > 0.0, "outward normal");
        }
    }
}
