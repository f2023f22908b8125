//! Per-object placement: `world_from_object = translation · rotation · scale` (scale applied first,
//! per axis), and the ray/point/normal mappings the renderer needs.
//!
//! Contract: rays are mapped into object space without renormalising the direction, so the hit
//! parameter `t` is the same in both frames. Normals map with the inverse transpose
//! (`R · S⁻¹ · n`, renormalised), which keeps them perpendicular to surfaces under non-uniform scale.
//! Scale components must be finite and non-zero (the scene validator guarantees it).

use super::{Aabb, Ray, SurfaceHit};
use nalgebra::{Isometry3, Point3, Unit, Vector3};

/// Rigid pose plus per-axis scale of an object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectTransform {
    /// Rigid part: object frame to world frame.
    pub world_from_object: Isometry3<f64>,
    /// Per-axis scale applied in the object frame before the rigid part.
    pub scale: Vector3<f64>,
}

impl Default for ObjectTransform {
    fn default() -> Self {
        Self {
            world_from_object: Isometry3::identity(),
            scale: Vector3::repeat(1.0),
        }
    }
}

impl ObjectTransform {
    /// A transform from a rigid pose and per-axis scale.
    pub fn new(world_from_object: Isometry3<f64>, scale: Vector3<f64>) -> Self {
        Self {
            world_from_object,
            scale,
        }
    }

    /// Maps a world ray into the (unscaled) object frame; `t` is preserved.
    #[inline]
    pub fn ray_to_object(&self, ray: &Ray) -> Ray {
        let o = self.world_from_object.inverse_transform_point(&ray.origin);
        let d = self.world_from_object.inverse_transform_vector(&ray.dir);
        Ray::new(
            Point3::from(o.coords.component_div(&self.scale)),
            d.component_div(&self.scale),
        )
    }

    /// Maps an object-frame point to the world.
    pub fn point_to_world(&self, p: &Point3<f64>) -> Point3<f64> {
        self.world_from_object
            .transform_point(&Point3::from(p.coords.component_mul(&self.scale)))
    }

    /// Maps an object-frame normal to a world normal (inverse transpose).
    pub fn normal_to_world(&self, n: &Unit<Vector3<f64>>) -> Unit<Vector3<f64>> {
        let scaled = n.component_div(&self.scale);
        let world = self.world_from_object.transform_vector(&scaled);
        // Non-zero scale keeps `scaled` non-zero; fall back to the unscaled normal if it underflows.
        Unit::try_new(world, 0.0)
            .unwrap_or_else(|| Unit::new_unchecked(self.world_from_object.transform_vector(n)))
    }

    /// Maps a hit computed on the object-space ray back to the world ray.
    pub fn hit_to_world(&self, world_ray: &Ray, hit: &SurfaceHit) -> SurfaceHit {
        SurfaceHit {
            t: hit.t,
            point: world_ray.at(hit.t),
            normal_geometric: self.normal_to_world(&hit.normal_geometric),
            normal_shading: self.normal_to_world(&hit.normal_shading),
            barycentric: hit.barycentric,
            primitive: hit.primitive,
        }
    }

    /// World bounds of an object-space box (the box around its eight transformed corners).
    pub fn bounds_to_world(&self, b: &Aabb) -> Aabb {
        if b.is_empty() {
            return Aabb::empty();
        }
        let mut out = Aabb::empty();
        for i in 0..8 {
            let c = Point3::new(
                if i & 1 == 0 { b.min.x } else { b.max.x },
                if i & 2 == 0 { b.min.y } else { b.max.y },
                if i & 4 == 0 { b.min.z } else { b.max.z },
            );
            out.grow_point(&self.point_to_world(&c));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_stay_perpendicular_under_nonuniform_scale() {
        let xf = ObjectTransform::new(
            Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.3, -0.2, 0.9)),
            Vector3::new(2.0, 0.5, 3.0),
        );
        // Tangent plane of the object-space plane x + y + z = 0 spanned by t1, t2.
        let n = Unit::new_normalize(Vector3::new(1.0, 1.0, 1.0));
        let t1 = Vector3::new(1.0, -1.0, 0.0);
        let t2 = Vector3::new(0.0, 1.0, -1.0);
        let map = |v: Vector3<f64>| {
            xf.world_from_object
                .transform_vector(&v.component_mul(&xf.scale))
        };
        let nw = xf.normal_to_world(&n);
        assert!(nw.dot(&map(t1)).abs() < 1e-12);
        assert!(nw.dot(&map(t2)).abs() < 1e-12);
    }

    #[test]
    fn ray_mapping_preserves_t() {
        let xf = ObjectTransform::new(
            Isometry3::new(Vector3::new(0.1, 0.0, -0.2), Vector3::new(0.0, 0.4, 0.0)),
            Vector3::new(1.5, 1.5, 0.5),
        );
        let ray = Ray::new(Point3::new(0.3, -0.2, 1.0), Vector3::new(-0.1, 0.2, -1.0));
        let obj = xf.ray_to_object(&ray);
        for t in [0.0, 0.5, 2.0] {
            let back = xf.point_to_world(&obj.at(t));
            assert!((back - ray.at(t)).norm() < 1e-12);
        }
    }
}
