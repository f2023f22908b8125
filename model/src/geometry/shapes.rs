//! Analytic shapes in their own object frame: a sphere centred at the origin and the plane `z = 0`
//! (optionally a finite rectangle centred at the origin).
//!
//! Contract: see [`super`]; the sphere's normal points outward, the plane's normal is `+z`. The
//! sphere uses the cancellation-free quadratic (the perpendicular-distance discriminant of
//! Haines et al., *Ray Tracing Gems* ch. 7) so grazing and distant rays stay accurate.

use super::{Aabb, Intersect, Ray, SurfaceHit};
use nalgebra::{Point3, Unit, Vector3};

/// Sphere of radius `radius_m` centred at the object origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Radius in metres (positive; validated by the scene loader).
    pub radius_m: f64,
}

impl Intersect for Sphere {
    fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<SurfaceHit> {
        let a = ray.dir.norm_squared();
        // Guard: a zero direction cannot hit anything.
        if a.is_nan() || a <= 0.0 {
            return None;
        }
        let oc = ray.origin.coords;
        let b = oc.dot(&ray.dir);
        let r2 = self.radius_m * self.radius_m;
        // Perpendicular offset of the line from the centre: stable discriminant.
        let perp = oc - ray.dir * (b / a);
        let disc = a * (r2 - perp.norm_squared());
        if disc < 0.0 {
            return None;
        }
        let c = oc.norm_squared() - r2;
        // Roots of a t² + 2 b t + c = 0 without cancellation: q = -(b + sign(b)·√disc).
        let sign_b = if b >= 0.0 { 1.0 } else { -1.0 };
        let q = -(b + sign_b * disc.sqrt());
        let (mut t0, mut t1) = if q != 0.0 {
            (q / a, c / q)
        } else {
            (-b / a, -b / a)
        };
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        let t = if t0 > t_min && t0 < t_max {
            t0
        } else if t1 > t_min && t1 < t_max {
            t1
        } else {
            return None;
        };
        let point = ray.at(t);
        let n = Unit::try_new(point.coords, 0.0).unwrap_or_else(Vector3::z_axis);
        Some(SurfaceHit {
            t,
            point,
            normal_geometric: n,
            normal_shading: n,
            barycentric: [1.0, 0.0, 0.0],
            primitive: 0,
        })
    }

    fn bounds(&self) -> Aabb {
        let r = Vector3::repeat(self.radius_m);
        Aabb {
            min: Point3::from(-r),
            max: Point3::from(r),
        }
    }
}

/// The plane `z = 0` with normal `+z`; infinite, or the rectangle `|x| ≤ w/2, |y| ≤ h/2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// `Some([w, h])` in metres for a finite rectangle, `None` for an infinite plane.
    pub size_m: Option<[f64; 2]>,
}

impl Intersect for Plane {
    fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<SurfaceHit> {
        // Guard: a ray parallel to the plane never hits it.
        if ray.dir.z == 0.0 {
            return None;
        }
        let t = -ray.origin.z / ray.dir.z;
        if !(t > t_min && t < t_max) {
            return None;
        }
        let mut point = ray.at(t);
        point.z = 0.0;
        if let Some([w, h]) = self.size_m {
            if point.x.abs() > 0.5 * w || point.y.abs() > 0.5 * h {
                return None;
            }
        }
        Some(SurfaceHit {
            t,
            point,
            normal_geometric: Vector3::z_axis(),
            normal_shading: Vector3::z_axis(),
            barycentric: [1.0, 0.0, 0.0],
            primitive: 0,
        })
    }

    fn bounds(&self) -> Aabb {
        let (hw, hh) = match self.size_m {
            Some([w, h]) => (0.5 * w, 0.5 * h),
            None => (f64::INFINITY, f64::INFINITY),
        };
        Aabb {
            min: Point3::new(-hw, -hh, 0.0),
            max: Point3::new(hw, hh, 0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_hit_from_outside_and_inside() {
        let s = Sphere { radius_m: 0.5 };
        let ray = Ray::new(Point3::new(0.0, 0.0, -3.0), Vector3::new(0.0, 0.0, 2.0));
        let h = s.intersect(&ray, 0.0, f64::INFINITY).expect("hit");
        assert!((h.t - 1.25).abs() < 1e-12);
        assert!((h.normal_geometric.z + 1.0).abs() < 1e-12);
        let inside = Ray::new(Point3::origin(), Vector3::new(1.0, 0.0, 0.0));
        let h = s
            .intersect(&inside, 0.0, f64::INFINITY)
            .expect("hit from inside");
        assert!((h.t - 0.5).abs() < 1e-12);
        assert!(s.intersect(&ray, 0.0, 1.0).is_none());
    }

    #[test]
    fn sphere_distant_grazing_ray_lands_on_surface() {
        let s = Sphere { radius_m: 0.01 };
        let ray = Ray::new(
            Point3::new(-1.0e4, 0.00999, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
        );
        let h = s.intersect(&ray, 0.0, f64::INFINITY).expect("grazing hit");
        assert!(
            (h.point.coords.norm() - 0.01).abs() < 1e-9,
            "{}",
            h.point.coords.norm()
        );
        let miss = Ray::new(
            Point3::new(-1.0e4, 0.01001, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
        );
        assert!(s.intersect(&miss, 0.0, f64::INFINITY).is_none());
    }

    #[test]
    fn finite_plane_clips_and_parallel_rays_miss() {
        let p = Plane {
            size_m: Some([1.0, 0.5]),
        };
        let down = Vector3::new(0.0, 0.0, -1.0);
        assert!(
            p.intersect(&Ray::new(Point3::new(0.4, 0.2, 1.0), down), 0.0, 10.0)
                .is_some()
        );
        assert!(
            p.intersect(&Ray::new(Point3::new(0.4, 0.3, 1.0), down), 0.0, 10.0)
                .is_none()
        );
        let flat = Ray::new(Point3::new(0.0, 0.0, 1.0), Vector3::x());
        assert!(p.intersect(&flat, 0.0, 10.0).is_none());
        let inf = Plane { size_m: None };
        assert!(
            inf.intersect(&Ray::new(Point3::new(1e3, 1e3, 1.0), down), 0.0, 10.0)
                .is_some()
        );
    }
}

#[cfg(test)]
mod properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Sphere hits lie on the surface, are the first crossing after t_min, and the normal is
        /// radial.
        #[test]
        fn sphere_hits_are_on_the_surface_and_first(
            r in 0.001f64..10.0,
            o in proptest::array::uniform3(-20.0f64..20.0),
            d in proptest::array::uniform3(-1.0f64..1.0),
        ) {
            let s = Sphere { radius_m: r };
            let ray = Ray::new(Point3::from(o), Vector3::from(d));
            prop_assume!(ray.dir.norm() > 1e-3);
            if let Some(h) = s.intersect(&ray, 0.0, f64::INFINITY) {
                let rel = (h.point.coords.norm() - r).abs() / r;
                prop_assert!(rel < 1e-9, "off surface by {rel}");
                prop_assert!((h.normal_geometric.into_inner() - h.point.coords / h.point.coords.norm()).norm() < 1e-9);
                // Nothing on the sphere is crossed before t: the midpoint of [0, t) is not a
                // surface crossing from outside to inside and back.
                let inside_at = |t: f64| ray.at(t).coords.norm() < r;
                let starts_inside = inside_at(0.0);
                prop_assert_eq!(inside_at(h.t * 0.5), starts_inside);
            } else {
                // A miss means the line stays outside (or the sphere is behind the origin).
                let t_close = -ray.origin.coords.dot(&ray.dir) / ray.dir.norm_squared();
                let closest = ray.at(t_close.max(0.0)).coords.norm();
                prop_assert!(closest >= r * (1.0 - 1e-9), "missed a sphere the ray passes through");
            }
        }
    }
}
