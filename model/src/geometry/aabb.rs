//! Axis-aligned bounding boxes and the ray–slab test used by the BVH.
//!
//! An empty box has `min = +inf`, `max = -inf`; growing it by a point or box works without special
//! cases. The slab test uses precomputed reciprocal directions: a zero direction component gives an
//! infinite reciprocal, and that axis is then handled explicitly (the ray is inside the slab, with
//! its boundary included, or misses), so no `0 * inf = NaN` reaches the interval arithmetic.

use nalgebra::{Point3, Vector3};

/// An axis-aligned box `[min, max]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Point3<f64>,
    /// Upper corner.
    pub max: Point3<f64>,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::empty()
    }
}

impl Aabb {
    /// The empty box (grows to whatever is added).
    pub fn empty() -> Self {
        Self {
            min: Point3::from(Vector3::repeat(f64::INFINITY)),
            max: Point3::from(Vector3::repeat(f64::NEG_INFINITY)),
        }
    }

    /// The box around a set of points.
    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a Point3<f64>>) -> Self {
        let mut b = Self::empty();
        for p in points {
            b.grow_point(p);
        }
        b
    }

    /// Whether nothing has been added.
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    /// Grow to contain `p`.
    pub fn grow_point(&mut self, p: &Point3<f64>) {
        self.min = self.min.inf(p);
        self.max = self.max.sup(p);
    }

    /// Grow to contain `other`.
    pub fn grow(&mut self, other: &Aabb) {
        self.min = self.min.inf(&other.min);
        self.max = self.max.sup(&other.max);
    }

    /// Union of two boxes.
    pub fn union(&self, other: &Aabb) -> Aabb {
        let mut b = *self;
        b.grow(other);
        b
    }

    /// Centre point (meaningless for an empty box).
    pub fn centre(&self) -> Point3<f64> {
        nalgebra::center(&self.min, &self.max)
    }

    /// Edge lengths (zero for an empty box).
    pub fn extent(&self) -> Vector3<f64> {
        if self.is_empty() {
            Vector3::zeros()
        } else {
            self.max - self.min
        }
    }

    /// Surface area (zero for an empty box), the SAH cost weight.
    pub fn surface_area(&self) -> f64 {
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// Ray parameter interval `[t_enter, t_exit]` clipped to `[t_min, t_max]`, or `None` if the ray
    /// misses. `inv_dir` is the component-wise reciprocal of the ray direction.
    pub fn slab(
        &self,
        origin: &Point3<f64>,
        inv_dir: &Vector3<f64>,
        t_min: f64,
        t_max: f64,
    ) -> Option<f64> {
        let mut t0 = t_min;
        let mut t1 = t_max;
        for axis in 0..3 {
            if !inv_dir[axis].is_finite() {
                // Direction parallel to this slab: inside (boundary inclusive) or a miss.
                if origin[axis] < self.min[axis] || origin[axis] > self.max[axis] {
                    return None;
                }
                continue;
            }
            let a = (self.min[axis] - origin[axis]) * inv_dir[axis];
            let b = (self.max[axis] - origin[axis]) * inv_dir[axis];
            let (near, far) = if a <= b { (a, b) } else { (b, a) };
            t0 = t0.max(near);
            t1 = t1.min(far);
            if t0 > t1 {
                return None;
            }
        }
        Some(t0)
    }

    /// [`Aabb::slab`] for a ray whose `inv_dir` is finite on every axis (no component of the
    /// direction is zero): the same interval without a branch per axis (each axis only raises
    /// `t0` and lowers `t1`, so testing `t0 > t1` once at the end decides as the per-axis test
    /// does).
    #[inline]
    pub fn slab_finite(
        &self,
        origin: &Point3<f64>,
        inv_dir: &Vector3<f64>,
        t_min: f64,
        t_max: f64,
    ) -> Option<f64> {
        let mut t0 = t_min;
        let mut t1 = t_max;
        for axis in 0..3 {
            let a = (self.min[axis] - origin[axis]) * inv_dir[axis];
            let b = (self.max[axis] - origin[axis]) * inv_dir[axis];
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        (t0 <= t1).then_some(t0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slab_hits_and_misses() {
        let b = Aabb {
            min: Point3::new(-1.0, -1.0, -1.0),
            max: Point3::new(1.0, 1.0, 1.0),
        };
        let o = Point3::new(-5.0, 0.0, 0.0);
        let d = Vector3::new(1.0, 0.0, 0.0);
        let inv = d.map(|c| 1.0 / c);
        assert_eq!(b.slab(&o, &inv, 0.0, f64::INFINITY), Some(4.0));
        assert_eq!(b.slab(&o, &inv, 0.0, 3.0), None);
        let o2 = Point3::new(-5.0, 2.0, 0.0);
        assert_eq!(b.slab(&o2, &inv, 0.0, f64::INFINITY), None);
        // Origin exactly on a slab plane with a zero direction component.
        let o3 = Point3::new(-5.0, 1.0, 0.0);
        assert_eq!(b.slab(&o3, &inv, 0.0, f64::INFINITY), Some(4.0));
    }

    #[test]
    fn empty_box_area_is_zero() {
        assert!(Aabb::empty().is_empty());
        assert_eq!(Aabb::empty().surface_area(), 0.0);
        let b = Aabb::from_points(&[Point3::origin(), Point3::new(1.0, 2.0, 3.0)]);
        assert!((b.surface_area() - 22.0).abs() < 1e-12);
    }
}
