//! Distances between two triangle meshes: Chamfer and Hausdorff, for scoring a mesh against the
//! simulator's truth (the mesh bench, the truth at a mesh's vertices) and in the carving's tests.
//!
//! Contract: each mesh is sampled at its vertices plus `samples` area-weighted points (seeded,
//! ChaCha8), and every sample's distance to the other mesh is the exact point–triangle distance
//! (Ericson, *Real-Time Collision Detection*, 2005, §5.1.5) to the nearest triangle, found
//! through the model's bounding-volume hierarchy of the triangles (`Bvh::nearest`). The **Chamfer** distance is the mean of
//! the two one-sided mean distances, the **Hausdorff** distance the larger one-sided maximum;
//! both in metres.

use nalgebra::Point3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::geometry::{Aabb, Bvh, TriangleMesh};

/// Distances between two meshes.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct MeshDistance {
    /// Mean of the two one-sided mean distances, m.
    pub chamfer_m: f64,
    /// Larger of the two one-sided maxima, m.
    pub hausdorff_m: f64,
    /// Mean distance from A's surface to B, m.
    pub a_to_b_mean_m: f64,
    /// Mean distance from B's surface to A, m.
    pub b_to_a_mean_m: f64,
    /// 90th percentile of both directions together, m.
    pub p90_m: f64,
}

/// Closest point to `p` on triangle `abc`.
pub fn closest_on_triangle(
    p: Point3<f64>,
    a: Point3<f64>,
    b: Point3<f64>,
    c: Point3<f64>,
) -> Point3<f64> {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom.abs() < 1e-300 {
        // degenerate (zero-area) triangle: nearest of its corners
        return [a, b, c]
            .into_iter()
            .min_by(|x, y| (p - x).norm_squared().total_cmp(&(p - y).norm_squared()))
            .unwrap_or(a);
    }
    a + ab * (vb / denom) + ac * (vc / denom)
}

/// A mesh's triangles in a bounding-volume hierarchy (the model's [`Bvh`]).
struct TriangleTree<'a> {
    mesh: &'a TriangleMesh,
    bvh: Bvh,
}

impl<'a> TriangleTree<'a> {
    fn new(mesh: &'a TriangleMesh) -> Self {
        let pos = mesh.positions();
        let bounds: Vec<Aabb> = mesh
            .triangles()
            .iter()
            .map(|t| Aabb::from_points(t.iter().map(|&i| &pos[i as usize])))
            .collect();
        Self {
            mesh,
            bvh: Bvh::build(&bounds),
        }
    }

    /// Distance from `p` to the mesh (infinite for a mesh without triangles).
    fn distance(&self, p: Point3<f64>) -> f64 {
        self.closest(p)
            .map_or(f64::INFINITY, |(_, q)| (p - q).norm())
    }

    /// The nearest triangle to `p` and the closest point on it (`None` for a mesh without
    /// triangles).
    fn closest(&self, p: Point3<f64>) -> Option<(usize, Point3<f64>)> {
        let pos = self.mesh.positions();
        let (t, _) = self.bvh.nearest(&p, |t, _| {
            let [a, b, c] = self.mesh.triangles()[t as usize].map(|i| pos[i as usize]);
            (p - closest_on_triangle(p, a, b, c)).norm()
        })?;
        let [a, b, c] = self.mesh.triangles()[t as usize].map(|i| pos[i as usize]);
        Some((t as usize, closest_on_triangle(p, a, b, c)))
    }
}

/// Closest-point queries against one mesh (for carrying per-vertex truth onto another mesh).
pub struct ClosestPoints<'a> {
    tree: TriangleTree<'a>,
}

/// Where a query point lands on the mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closest {
    /// Index of the nearest triangle.
    pub triangle: usize,
    /// The closest point on it.
    pub point: Point3<f64>,
    /// Barycentric weights of `point` for the triangle's three vertices (sum 1).
    pub barycentric: [f64; 3],
    /// Distance from the query to `point`, m.
    pub distance_m: f64,
}

impl<'a> ClosestPoints<'a> {
    /// Bins `mesh`'s triangles for queries.
    pub fn new(mesh: &'a TriangleMesh) -> Self {
        Self {
            tree: TriangleTree::new(mesh),
        }
    }

    /// The closest point of the mesh to `p` (`None` for a mesh without triangles).
    pub fn closest(&self, p: Point3<f64>) -> Option<Closest> {
        let (t, q) = self.tree.closest(p)?;
        let pos = self.tree.mesh.positions();
        let [a, b, c] = self.tree.mesh.triangles()[t].map(|i| pos[i as usize]);
        Some(Closest {
            triangle: t,
            point: q,
            barycentric: barycentric(q, a, b, c),
            distance_m: (p - q).norm(),
        })
    }
}

/// Barycentric weights of `q` (a point of triangle `abc`); a degenerate triangle gives all the
/// weight to its nearest corner.
fn barycentric(q: Point3<f64>, a: Point3<f64>, b: Point3<f64>, c: Point3<f64>) -> [f64; 3] {
    let (v0, v1, v2) = (b - a, c - a, q - a);
    let (d00, d01, d11) = (v0.dot(&v0), v0.dot(&v1), v1.dot(&v1));
    let (d20, d21) = (v2.dot(&v0), v2.dot(&v1));
    let denom = d00 * d11 - d01 * d01;
    // zero-area triangle: no plane to take coordinates in (guard the division)
    if denom.abs() <= 1e-30 * (d00 * d11).max(1e-300) {
        let d = [a, b, c].map(|x| (q - x).norm_squared());
        let k = (0..3).min_by(|&i, &j| d[i].total_cmp(&d[j])).unwrap_or(0);
        let mut w = [0.0; 3];
        w[k] = 1.0;
        return w;
    }
    let v = ((d11 * d20 - d01 * d21) / denom).clamp(0.0, 1.0);
    let w = ((d00 * d21 - d01 * d20) / denom).clamp(0.0, 1.0 - v);
    [1.0 - v - w, v, w]
}

/// Vertices plus `samples` area-weighted surface points of `mesh`.
fn surface_samples(mesh: &TriangleMesh, samples: usize, seed: u64) -> Vec<Point3<f64>> {
    let pos = mesh.positions();
    let tris = mesh.triangles();
    let areas: Vec<f64> = tris
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| pos[i as usize]);
            0.5 * (b - a).cross(&(c - a)).norm()
        })
        .collect();
    let total: f64 = areas.iter().sum();
    let mut cumulative = Vec::with_capacity(areas.len());
    let mut s = 0.0;
    for a in &areas {
        s += a;
        cumulative.push(s);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out: Vec<Point3<f64>> = pos.to_vec();
    for _ in 0..samples {
        let r = rng.random::<f64>() * total;
        let t = cumulative.partition_point(|&c| c < r).min(tris.len() - 1);
        let (mut u, mut v) = (rng.random::<f64>(), rng.random::<f64>());
        if u + v > 1.0 {
            (u, v) = (1.0 - u, 1.0 - v);
        }
        let [a, b, c] = tris[t].map(|i| pos[i as usize]);
        out.push(a + (b - a) * u + (c - a) * v);
    }
    out
}

/// Chamfer and Hausdorff distances between `a` and `b` (module contract).
pub fn mesh_distance(
    a: &TriangleMesh,
    b: &TriangleMesh,
    samples: usize,
    seed: u64,
) -> MeshDistance {
    use rayon::prelude::*;
    let one_sided = |from: &TriangleMesh, to: &TriangleMesh, seed: u64| -> Vec<f64> {
        let tree = TriangleTree::new(to);
        surface_samples(from, samples, seed)
            .par_iter()
            .map(|p| tree.distance(*p))
            .collect()
    };
    let ab = one_sided(a, b, seed);
    let ba = one_sided(b, a, seed ^ 0x5eed);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    let mut all: Vec<f64> = ab.iter().chain(&ba).copied().collect();
    MeshDistance {
        chamfer_m: 0.5 * (mean(&ab) + mean(&ba)),
        hausdorff_m: max(&ab).max(max(&ba)),
        a_to_b_mean_m: mean(&ab),
        b_to_a_mean_m: mean(&ba),
        p90_m: crate::stats::percentile(&mut all, 0.9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::procedural::icosphere;

    fn sphere(radius: f64, subdivisions: u32) -> TriangleMesh {
        let (dirs, tris) = icosphere(subdivisions);
        let pos = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * radius))
            .collect();
        TriangleMesh::new(pos, None, None, tris).unwrap()
    }

    #[test]
    fn concentric_spheres_are_their_radius_difference_apart() {
        let a = sphere(1.0, 4);
        let b = sphere(1.1, 4);
        let d = mesh_distance(&a, &b, 2000, 1);
        // chords sit inside the sphere by at most the sagitta (~0.3 % at 4 subdivisions)
        assert!((d.chamfer_m - 0.1).abs() < 0.005, "{d:?}");
        assert!((d.hausdorff_m - 0.1).abs() < 0.01, "{d:?}");
        let same = mesh_distance(&a, &a, 500, 2);
        assert!(same.hausdorff_m < 1e-12, "{same:?}");
    }

    #[test]
    fn closest_points_land_on_the_sphere_with_consistent_barycentrics() {
        let mesh = sphere(0.05, 3);
        let query = ClosestPoints::new(&mesh);
        for (k, p) in [[0.1, 0.0, 0.0], [0.0, -0.02, 0.03], [0.03, 0.04, -0.07]]
            .into_iter()
            .enumerate()
        {
            let p = Point3::from(p);
            let c = query.closest(p).expect("triangles");
            let tri = mesh.triangles()[c.triangle].map(|i| mesh.positions()[i as usize]);
            let back = tri[0].coords * c.barycentric[0]
                + tri[1].coords * c.barycentric[1]
                + tri[2].coords * c.barycentric[2];
            assert!((back - c.point.coords).norm() < 1e-12, "query {k}");
            assert!(c.barycentric.iter().all(|w| (0.0..=1.0).contains(w)));
            // an icosphere's faces lie inside the sphere, within its sagitta
            let r = p.coords.norm();
            assert!(
                (c.distance_m - (r - 0.05).abs()).abs() < 2e-3,
                "query {k}: {c:?}"
            );
            assert!((c.distance_m - (p - c.point).norm()).abs() < 1e-15);
        }
    }

    #[test]
    fn closest_point_regions() {
        let (a, b, c) = (
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        );
        let q = |x, y, z| closest_on_triangle(Point3::new(x, y, z), a, b, c);
        assert!((q(0.2, 0.2, 1.0) - Point3::new(0.2, 0.2, 0.0)).norm() < 1e-12);
        assert_eq!(q(-1.0, -1.0, 0.0), a);
        assert_eq!(q(2.0, -0.5, 0.0), b);
        assert!((q(1.0, 1.0, 0.0) - Point3::new(0.5, 0.5, 0.0)).norm() < 1e-12);
        assert!((q(0.5, -1.0, 0.0) - Point3::new(0.5, 0.0, 0.0)).norm() < 1e-12);
    }
}
