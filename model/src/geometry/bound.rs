//! A world-space bounding sphere that rejects rays before they are mapped into an object's frame.
//!
//! Contract: [`BoundingSphere::around`] encloses every point of a placed object whose object-frame
//! bounds are finite (the box's eight corners mapped to the world, so the rigid placement and the
//! per-axis scale are both covered); [`BoundingSphere::around_points`] encloses the convex hull
//! of a mesh's placed vertices (a tighter sphere for a round object: a blob's box corners lie
//! √3 of its radius out). Both widen the radius by [`RADIUS_MARGIN_REL`].
//! [`BoundingSphere::may_hit`] is conservative: it returns `false` only when the ray's line misses
//! the sphere or the whole sphere lies behind a non-negative `t_min`; a ray that hits the object
//! always passes. A NaN in the ray fails every comparison and so passes, leaving the decision to
//! the exact test. Rejecting a ray here gives exactly the result the exact test would have given
//! (no hit), so a render is bit-identical with or without it; the renderer uses it because most
//! rays of a frame (the board, the background, shadow rays from the board) never come near the
//! object.

use super::{Aabb, ObjectTransform, Ray};
use nalgebra::Point3;

/// Relative widening of the sphere's radius. The exact test runs on the ray mapped into the
/// object's frame, whose rounding moves a point by ~1e-16 of the distances involved (metres over
/// at most a few metres of scene); 1e-6 of the radius (40 nm on a 4 cm object) is ten orders above
/// that, and costs nothing measurable in rejected rays.
pub const RADIUS_MARGIN_REL: f64 = 1e-6;

/// A sphere enclosing a placed object, in the world frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundingSphere {
    /// Centre, world frame, metres.
    pub centre_world: Point3<f64>,
    /// Squared radius, m².
    pub radius_sq_m2: f64,
}

impl BoundingSphere {
    /// The sphere around `bounds_object` (object frame) placed by `transform`; `None` when the
    /// bounds are not finite (an infinite plane), where no sphere can reject anything.
    pub fn around(transform: &ObjectTransform, bounds_object: &Aabb) -> Option<Self> {
        let (lo, hi) = (bounds_object.min, bounds_object.max);
        if !(lo.coords.iter().chain(hi.coords.iter())).all(|v| v.is_finite()) {
            return None;
        }
        let corners: Vec<Point3<f64>> = (0..8)
            .map(|k| {
                let pick = |axis: usize| {
                    if k >> axis & 1 == 0 {
                        lo[axis]
                    } else {
                        hi[axis]
                    }
                };
                Point3::new(pick(0), pick(1), pick(2))
            })
            .collect();
        Self::around_points(transform, &corners)
    }

    /// The sphere around `points_object` (object frame) placed by `transform`: centred on the
    /// middle of their world box, reaching the farthest; `None` without points or with a
    /// non-finite one. Encloses their convex hull (so every triangle of a mesh's vertices).
    pub fn around_points(
        transform: &ObjectTransform,
        points_object: &[Point3<f64>],
    ) -> Option<Self> {
        let world: Vec<Point3<f64>> = points_object
            .iter()
            .map(|p| transform.point_to_world(p))
            .collect();
        let first = world.first()?;
        let (lo, hi) = world.iter().fold((*first, *first), |(lo, hi), p| {
            (
                lo.coords.inf(&p.coords).into(),
                hi.coords.sup(&p.coords).into(),
            )
        });
        let centre = nalgebra::center(&lo, &hi);
        let radius = world
            .iter()
            .map(|p| (p - centre).norm())
            .fold(0.0, f64::max)
            * (1.0 + RADIUS_MARGIN_REL);
        (radius.is_finite() && centre.coords.iter().all(|v| v.is_finite())).then_some(Self {
            centre_world: centre,
            radius_sq_m2: radius * radius,
        })
    }

    /// Whether the world ray may meet what the sphere encloses at some `t > t_min` (module
    /// contract: conservative).
    #[inline]
    pub fn may_hit(&self, ray: &Ray, t_min: f64) -> bool {
        let oc = ray.origin - self.centre_world;
        let c = oc.norm_squared() - self.radius_sq_m2;
        if c <= 0.0 {
            // The origin is inside the sphere.
            return true;
        }
        let b = oc.dot(&ray.dir);
        if b > 0.0 && t_min >= 0.0 {
            // Outside and moving away: both roots are negative.
            return false;
        }
        // The line misses the sphere when the quadratic's discriminant is negative; a NaN
        // discriminant is no proof of a miss.
        let discriminant = b * b - ray.dir.norm_squared() * c;
        discriminant >= 0.0 || discriminant.is_nan()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intersect, Sphere};
    use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn every_ray_that_hits_a_placed_sphere_passes_and_far_rays_are_rejected() {
        let shape = Sphere { radius_m: 0.7 };
        let transform = ObjectTransform::new(
            Isometry3::from_parts(
                Translation3::new(0.1, -0.2, 0.3),
                UnitQuaternion::from_euler_angles(0.3, -0.5, 1.1),
            ),
            Vector3::new(0.05, 0.03, 0.04),
        );
        let bound = BoundingSphere::around(&transform, &shape.bounds()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (mut hits, mut rejected) = (0, 0);
        for _ in 0..20_000 {
            let origin = Point3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
            );
            let target = Point3::new(0.1, -0.2, 0.3)
                + Vector3::new(
                    rng.random_range(-0.08..0.08),
                    rng.random_range(-0.08..0.08),
                    rng.random_range(-0.08..0.08),
                );
            let ray = Ray::new(origin, (target - origin) * rng.random_range(0.1..10.0));
            let exact = shape
                .intersect(&transform.ray_to_object(&ray), 0.0, f64::INFINITY)
                .is_some();
            let may = bound.may_hit(&ray, 0.0);
            assert!(may || !exact, "a hit was rejected: {ray:?}");
            hits += usize::from(exact);
            rejected += usize::from(!may);
        }
        assert!(
            hits > 1000 && rejected > 1000,
            "hits {hits}, rejected {rejected}"
        );
    }

    #[test]
    fn the_sphere_around_a_meshs_vertices_keeps_every_hit_and_is_tighter_than_its_box() {
        let mesh = crate::geometry::procedural::bumpy_icosphere(3, 0.15, 4, 7);
        let transform = ObjectTransform::new(
            Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 0.04),
                UnitQuaternion::from_euler_angles(0.0, 0.0, 0.5),
            ),
            Vector3::repeat(0.04),
        );
        let tight = BoundingSphere::around_points(&transform, mesh.positions()).unwrap();
        let boxed = BoundingSphere::around(&transform, &mesh.bounds()).unwrap();
        assert!(tight.radius_sq_m2 < 0.6 * boxed.radius_sq_m2);
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut hits = 0;
        for _ in 0..20_000 {
            let origin = Point3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(0.0..0.5),
            );
            let target = Point3::new(
                rng.random_range(-0.06..0.06),
                rng.random_range(-0.06..0.06),
                rng.random_range(-0.02..0.1),
            );
            let ray = Ray::new(origin, target - origin);
            let exact = mesh
                .intersect(&transform.ray_to_object(&ray), 0.0, f64::INFINITY)
                .is_some();
            assert!(
                tight.may_hit(&ray, 0.0) || !exact,
                "a hit was rejected: {ray:?}"
            );
            hits += usize::from(exact);
        }
        assert!(hits > 1000, "hits {hits}");
    }

    #[test]
    fn rays_from_inside_or_with_nan_pass_and_infinite_bounds_give_none() {
        let shape = Sphere { radius_m: 1.0 };
        let bound = BoundingSphere::around(&ObjectTransform::default(), &shape.bounds()).unwrap();
        let inside = Ray::new(Point3::new(0.1, 0.0, 0.0), Vector3::x());
        assert!(bound.may_hit(&inside, 0.0));
        let nan = Ray::new(Point3::new(f64::NAN, 5.0, 0.0), Vector3::x());
        assert!(bound.may_hit(&nan, 0.0));
        let behind = Ray::new(Point3::new(5.0, 0.0, 0.0), Vector3::x());
        assert!(!bound.may_hit(&behind, 0.0));
        // A negative t_min reaches behind the origin: not rejected.
        assert!(bound.may_hit(&behind, -10.0));
        let plane = crate::geometry::Plane { size_m: None };
        assert!(BoundingSphere::around(&ObjectTransform::default(), &plane.bounds()).is_none());
        assert!(BoundingSphere::around_points(&ObjectTransform::default(), &[]).is_none());
    }
}
