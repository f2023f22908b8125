//! The visual hull as a constraint on the surface: the carved field of `ellipso-mesh` (every
//! node's k-th largest signed silhouette distance, docs/mesh.md "Voting and the signed
//! distance"), interpolated trilinearly, with the board plane under it.
//!
//! Contract:
//! - The field lives on a regular grid in the **volume frame** (board plane z = 0, z toward the
//!   cameras), metres; [`HullField::world_from_volume`] places it in the world (board) frame.
//!   Positive values are outside the hull (some k views see the board through the point),
//!   negative inside; near the surface the values are distances in metres (|∇φ| ≈ 1).
//! - [`HullField::value_volume`] is `max(φ(p), −p.z)`: outside where the silhouettes say so or
//!   below the board, so the object is closed from below by the board plane. Beyond the grid φ
//!   is [`HullField::outside_m`] (outside).
//! - [`trilinear`] is the one interpolation of a grid field (the mesh crate's implicit surface
//!   uses it too); its gradient is the exact gradient of the trilinear interpolant.

use nalgebra::{Isometry3, Point3, Vector3};

/// A grid field's geometry: node (0, 0, 0) at `origin_m`, `spacing_m` apart, `n` nodes per
/// axis, values x fastest then y then z.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GridGeometry {
    /// Position of node (0, 0, 0), metres.
    pub origin_m: [f64; 3],
    /// Node spacing, metres (> 0).
    pub spacing_m: f64,
    /// Nodes along x, y, z (each ≥ 2).
    pub n: [usize; 3],
}

impl GridGeometry {
    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.n[0] * self.n[1] * self.n[2]
    }

    /// True for a grid without nodes.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Linear index of node `(i, j, k)`.
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        (k * self.n[1] + j) * self.n[0] + i
    }
}

/// The trilinear interpolant of `field` on `grid` at `p` and its gradient, or `None` outside
/// the grid (or on a grid with fewer than 2 nodes along an axis).
pub fn trilinear(
    grid: &GridGeometry,
    field: &[f32],
    p: Vector3<f64>,
) -> Option<(f64, Vector3<f64>)> {
    let h = grid.spacing_m;
    if grid.n.iter().any(|&n| n < 2) || field.len() < grid.len() || h.is_nan() || h <= 0.0 {
        return None;
    }
    // h > 0 (checked), so the division is finite.
    let u: [f64; 3] = std::array::from_fn(|a| (p[a] - grid.origin_m[a]) / h);
    if (0..3).any(|a| !(u[a] >= 0.0 && u[a] <= (grid.n[a] - 1) as f64)) {
        return None;
    }
    let i: [usize; 3] = std::array::from_fn(|a| (u[a] as usize).min(grid.n[a] - 2));
    let f: [f64; 3] = std::array::from_fn(|a| u[a] - i[a] as f64);
    let w = |d: usize, t: f64| if d == 0 { 1.0 - t } else { t };
    // d/du of (1 − u) is −1, of u is +1
    let s = |d: usize| if d == 0 { -1.0 } else { 1.0 };
    let mut value = 0.0;
    let mut grad = Vector3::zeros();
    for di in 0..2 {
        for dj in 0..2 {
            for dk in 0..2 {
                let v = f64::from(field[grid.index(i[0] + di, i[1] + dj, i[2] + dk)]);
                let (wx, wy, wz) = (w(di, f[0]), w(dj, f[1]), w(dk, f[2]));
                value += wx * wy * wz * v;
                grad.x += s(di) * wy * wz * v / h;
                grad.y += wx * s(dj) * wz * v / h;
                grad.z += wx * wy * s(dk) * v / h;
            }
        }
    }
    Some((value, grad))
}

/// Why a hull field cannot be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HullError {
    /// The value count does not match the grid.
    #[error("hull field: {got} values for a grid of {expected} nodes")]
    Length {
        /// Nodes of the grid.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// The grid has fewer than 2 nodes along an axis or a spacing that is not positive.
    #[error("hull field: grid of {n:?} nodes spaced {spacing_m} m cannot be interpolated")]
    Grid {
        /// Nodes per axis.
        n: [usize; 3],
        /// Spacing, metres.
        spacing_m: f64,
    },
    /// A value is NaN or infinite.
    #[error("hull field: node {node} is not finite")]
    NonFinite {
        /// Linear node index.
        node: usize,
    },
}

/// The carved visual hull with the board plane under it (module contract).
#[derive(Clone, Debug, PartialEq)]
pub struct HullField {
    /// Volume frame → world frame (the volume frame's z = 0 is the board plane).
    pub world_from_volume: Isometry3<f64>,
    /// The grid, volume frame.
    pub grid: GridGeometry,
    /// φ per node, metres, > 0 outside.
    pub values: Vec<f32>,
    /// φ beyond the grid, metres (> 0: outside).
    pub outside_m: f64,
    /// φ at a node is the `votes`-th largest of the views' signed silhouette distances
    /// (docs/mesh.md "Voting and the signed distance"; 1 for the classic hull, the largest):
    /// its zero set touches the object only where at least this many views' silhouettes do,
    /// and lies outside it elsewhere.
    pub votes: usize,
}

impl HullField {
    /// Checks the grid and the values (`votes` below 1 counts as 1).
    pub fn new(
        world_from_volume: Isometry3<f64>,
        grid: GridGeometry,
        values: Vec<f32>,
        outside_m: f64,
        votes: usize,
    ) -> Result<Self, HullError> {
        if grid.n.iter().any(|&n| n < 2) || !(grid.spacing_m.is_finite() && grid.spacing_m > 0.0) {
            return Err(HullError::Grid {
                n: grid.n,
                spacing_m: grid.spacing_m,
            });
        }
        if values.len() != grid.len() {
            return Err(HullError::Length {
                expected: grid.len(),
                got: values.len(),
            });
        }
        if let Some(node) = values.iter().position(|v| !v.is_finite()) {
            return Err(HullError::NonFinite { node });
        }
        Ok(Self {
            world_from_volume,
            grid,
            values,
            outside_m,
            votes: votes.max(1),
        })
    }

    /// The hull field φ alone (no board) at `p` (volume frame) and its gradient; beyond the grid
    /// [`HullField::outside_m`] with a zero gradient.
    pub fn silhouette_volume(&self, p: Vector3<f64>) -> (f64, Vector3<f64>) {
        trilinear(&self.grid, &self.values, p).unwrap_or((self.outside_m, Vector3::zeros()))
    }

    /// `max(φ(p), −p.z)` and its gradient at `p`, volume frame (module contract).
    pub fn value_volume(&self, p: Vector3<f64>) -> (f64, Vector3<f64>) {
        let (phi, grad) = self.silhouette_volume(p);
        if -p.z > phi {
            (-p.z, -Vector3::z())
        } else {
            (phi, grad)
        }
    }

    /// [`HullField::value_volume`] at a world point, the gradient in the world frame.
    pub fn value_world(&self, p_world: &Point3<f64>) -> (f64, Vector3<f64>) {
        let p = self.world_from_volume.inverse_transform_point(p_world);
        let (v, g) = self.value_volume(p.coords);
        (v, self.world_from_volume.transform_vector(&g))
    }

    /// Height of a world point above the board plane, metres.
    pub fn height_world(&self, p_world: &Point3<f64>) -> f64 {
        self.world_from_volume.inverse_transform_point(p_world).z
    }

    /// The board's upward normal in the world.
    pub fn board_up_world(&self) -> Vector3<f64> {
        self.world_from_volume.transform_vector(&Vector3::z())
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A sphere's signed distance on a grid (volume frame = world).
    pub(crate) fn sphere_hull(centre: Vector3<f64>, radius: f64, spacing: f64) -> HullField {
        let lo = centre - Vector3::repeat(radius + 4.0 * spacing);
        let n = [(2.0 * (radius + 4.0 * spacing) / spacing).ceil() as usize + 1; 3];
        let grid = GridGeometry {
            origin_m: lo.into(),
            spacing_m: spacing,
            n,
        };
        let mut values = vec![0.0f32; grid.len()];
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let p = lo + Vector3::new(i as f64, j as f64, k as f64) * spacing;
                    values[grid.index(i, j, k)] = ((p - centre).norm() - radius) as f32;
                }
            }
        }
        HullField::new(Isometry3::identity(), grid, values, 1.0, 1).unwrap()
    }

    #[test]
    fn trilinear_reproduces_a_linear_field_and_its_gradient() {
        let grid = GridGeometry {
            origin_m: [-1.0, -1.0, -1.0],
            spacing_m: 0.5,
            n: [5, 5, 5],
        };
        let mut field = vec![0.0f32; grid.len()];
        for k in 0..5 {
            for j in 0..5 {
                for i in 0..5 {
                    let p = Vector3::new(i as f64, j as f64, k as f64) * 0.5 - Vector3::repeat(1.0);
                    field[grid.index(i, j, k)] = (0.3 * p.x - 0.2 * p.y + 0.5 * p.z + 0.1) as f32;
                }
            }
        }
        let p = Vector3::new(0.13, -0.41, 0.77);
        let (v, g) = trilinear(&grid, &field, p).unwrap();
        assert!((v - (0.3 * p.x - 0.2 * p.y + 0.5 * p.z + 0.1)).abs() < 1e-6);
        assert!((g - Vector3::new(0.3, -0.2, 0.5)).norm() < 1e-6);
        assert!(trilinear(&grid, &field, Vector3::new(1.2, 0.0, 0.0)).is_none());
    }

    #[test]
    fn the_board_closes_the_hull_from_below_and_outside_the_grid_is_outside() {
        let hull = sphere_hull(Vector3::new(0.0, 0.0, 0.01), 0.02, 0.001);
        // inside the sphere but below the board: outside
        let (v, g) = hull.value_volume(Vector3::new(0.0, 0.0, -0.002));
        assert!((v - 0.002).abs() < 1e-12 && g == -Vector3::z());
        // at the centre the board (1 cm below) is nearer than the sphere's surface (2 cm)
        let (v, _) = hull.value_volume(Vector3::new(0.0, 0.0, 0.01));
        assert!((v + 0.01).abs() < 1e-9, "{v}");
        let (v, _) = hull.value_volume(Vector3::new(0.0, 0.0, 0.025));
        assert!((v + 0.005).abs() < 1e-6, "{v}");
        assert_eq!(hull.value_volume(Vector3::new(1.0, 0.0, 0.01)).0, 1.0);
        let bad = HullField::new(Isometry3::identity(), hull.grid, vec![0.0; 3], 1.0, 1);
        assert!(matches!(bad, Err(HullError::Length { .. })));
    }
}
