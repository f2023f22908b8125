//! Distances between two triangle meshes: Chamfer and Hausdorff, for scoring a mesh against the
//! simulator's truth.
//!
//! Contract: each mesh is sampled at its vertices plus `samples` area-weighted points (seeded,
//! ChaCha8), and every sample's distance to the other mesh is the exact point–triangle distance
//! (Ericson, *Real-Time Collision Detection*, 2005, §5.1.5) to the nearest triangle, found
//! through a uniform grid of triangle bounding boxes. The **Chamfer** distance is the mean of
//! the two one-sided mean distances, the **Hausdorff** distance the larger one-sided maximum;
//! both in metres.

use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use ellipso_model::geometry::TriangleMesh;

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

/// Triangles binned in a uniform grid.
struct TriangleGrid<'a> {
    mesh: &'a TriangleMesh,
    origin: Vector3<f64>,
    cell: f64,
    n: [usize; 3],
    cells: Vec<Vec<u32>>,
}

impl<'a> TriangleGrid<'a> {
    fn new(mesh: &'a TriangleMesh) -> Self {
        let pos = mesh.positions();
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for p in pos {
            lo = lo.inf(&p.coords);
            hi = hi.sup(&p.coords);
        }
        let extent = (hi - lo).max().max(1e-9);
        // about 4 triangles per cell on a surface
        let cells_per_axis =
            ((mesh.triangles().len() as f64 / 4.0).sqrt().ceil()).clamp(1.0, 256.0);
        let cell = extent / cells_per_axis;
        let n: [usize; 3] = std::array::from_fn(|a| ((hi[a] - lo[a]) / cell).floor() as usize + 1);
        let mut cells = vec![Vec::new(); n[0] * n[1] * n[2]];
        for (t, tri) in mesh.triangles().iter().enumerate() {
            let ps = tri.map(|i| pos[i as usize].coords);
            let tlo = ps[0].inf(&ps[1]).inf(&ps[2]);
            let thi = ps[0].sup(&ps[1]).sup(&ps[2]);
            let a: [usize; 3] =
                std::array::from_fn(|k| (((tlo[k] - lo[k]) / cell) as usize).min(n[k] - 1));
            let b: [usize; 3] =
                std::array::from_fn(|k| (((thi[k] - lo[k]) / cell) as usize).min(n[k] - 1));
            for z in a[2]..=b[2] {
                for y in a[1]..=b[1] {
                    for x in a[0]..=b[0] {
                        cells[(z * n[1] + y) * n[0] + x].push(t as u32);
                    }
                }
            }
        }
        Self {
            mesh,
            origin: lo,
            cell,
            n,
            cells,
        }
    }

    /// Distance from `p` to the mesh.
    fn distance(&self, p: Point3<f64>) -> f64 {
        let pos = self.mesh.positions();
        let c: [isize; 3] =
            std::array::from_fn(|a| ((p[a] - self.origin[a]) / self.cell).floor() as isize);
        let mut best = f64::INFINITY;
        let max_ring = (0..3)
            .map(|a| c[a].abs().max(self.n[a] as isize - c[a]))
            .max()
            .unwrap_or(1)
            + 1;
        for ring in 0..=max_ring {
            // p lies in cell c, so every cell of this ring and beyond is ≥ (ring − 1) cells away
            if best <= (ring as f64 - 1.0) * self.cell {
                break;
            }
            for z in c[2] - ring..=c[2] + ring {
                for y in c[1] - ring..=c[1] + ring {
                    for x in c[0] - ring..=c[0] + ring {
                        let on_shell = [x - c[0], y - c[1], z - c[2]]
                            .iter()
                            .any(|d| d.abs() == ring);
                        if !on_shell
                            || x < 0
                            || y < 0
                            || z < 0
                            || x >= self.n[0] as isize
                            || y >= self.n[1] as isize
                            || z >= self.n[2] as isize
                        {
                            continue;
                        }
                        let cell = (z as usize * self.n[1] + y as usize) * self.n[0] + x as usize;
                        for &t in &self.cells[cell] {
                            let [a, b, cc] =
                                self.mesh.triangles()[t as usize].map(|i| pos[i as usize]);
                            best = best.min((p - closest_on_triangle(p, a, b, cc)).norm());
                        }
                    }
                }
            }
        }
        best
    }
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
        let grid = TriangleGrid::new(to);
        surface_samples(from, samples, seed)
            .par_iter()
            .map(|p| grid.distance(*p))
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
        p90_m: ellipso_report::percentile(&mut all, 0.9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::geometry::procedural::icosphere;

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
