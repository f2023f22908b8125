//! The carved hull as an implicit surface: the grid field interpolated trilinearly, cut by the
//! board plane, and the projection of a point onto its zero level.
//!
//! Contract: `value(p) = max(φ(p), −p.z)` (volume frame): outside where the hull's field says
//! so or below the board, so the bottom of the object is the board plane. Outside the grid φ is
//! the grid's outside value. [`Implicit::project`] takes up to 4 Newton steps along the
//! gradient, each at most one grid spacing, and returns the point unchanged where the
//! gradient vanishes.

use nalgebra::Vector3;

use super::carve::Grid;
use ellipso_fit::shape::hull::trilinear;

/// The implicit surface of a grid field.
pub struct Implicit<'a> {
    grid: &'a Grid,
    field: &'a [f32],
    outside: f64,
}

impl<'a> Implicit<'a> {
    /// The surface of `field` on `grid`; `outside` beyond the grid.
    pub fn new(grid: &'a Grid, field: &'a [f32], outside: f64) -> Self {
        Self {
            grid,
            field,
            outside,
        }
    }

    /// φ and its gradient at `p` (trilinear, the fit's interpolation of a grid field).
    fn hull(&self, p: Vector3<f64>) -> (f64, Vector3<f64>) {
        trilinear(&self.grid.geometry(), self.field, p).unwrap_or((self.outside, Vector3::zeros()))
    }

    /// The value and gradient of the implicit function (module contract).
    pub fn value(&self, p: Vector3<f64>) -> (f64, Vector3<f64>) {
        let (phi, grad) = self.hull(p);
        if -p.z > phi {
            (-p.z, -Vector3::z())
        } else {
            (phi, grad)
        }
    }

    /// `p` moved onto the zero level (module contract).
    pub fn project(&self, mut p: Vector3<f64>) -> Vector3<f64> {
        let h = self.grid.spacing_m;
        for _ in 0..4 {
            let (v, g) = self.value(p);
            let g2 = g.norm_squared();
            // (a NaN gradient fails `g2 > 1e-12` too)
            if g2.is_nan() || g2 <= 1e-12 || !v.is_finite() {
                return p;
            }
            let mut step = g * (v / g2);
            let len = step.norm();
            if len > h {
                step *= h / len;
            }
            p -= step;
            if v.abs() < 1e-7 * h {
                break;
            }
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn projects_onto_a_sphere_field_and_onto_the_board() {
        let grid = Grid::covering(
            Point3::new(-0.05, -0.05, -0.005),
            Point3::new(0.05, 0.05, 0.08),
            0.002,
        );
        // a sphere cut by the board: its field is negative just below the contact
        let centre = Vector3::new(0.0, 0.0, 0.02);
        let field: Vec<f32> = (0..grid.len())
            .map(|n| ((grid.point(grid.ijk(n)).coords - centre).norm() - 0.03) as f32)
            .collect();
        let s = Implicit::new(&grid, &field, 1.0);
        let p = s.project(centre + Vector3::new(0.031, 0.004, 0.005));
        assert!(
            ((p - centre).norm() - 0.03).abs() < 2e-5,
            "{}",
            (p - centre).norm()
        );
        // the gradient of a distance field is a unit vector
        let (_, g) = s.value(centre + Vector3::new(0.0, 0.02, 0.0));
        assert!((g.norm() - 1.0).abs() < 0.05, "{}", g.norm());
        // a point just below the board goes up onto it
        let q = s.project(Vector3::new(0.0, 0.0, -0.001));
        assert!(q.z.abs() < 1e-9, "{}", q.z);
    }
}
