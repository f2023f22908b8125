//! Geometry for the simulator: rays, hits, bounding boxes and spheres, a binned-SAH BVH, triangle meshes
//! (PLY / OBJ loading, procedural assets), analytic shapes, per-object affine transforms and the
//! similarity between two reconstructions of the same cameras, the error between two poses, and
//! the distances between two meshes (Chamfer, Hausdorff: [`distance`], for scoring a mesh).
//!
//! Contract:
//! - All geometry is `f64`. Lengths are metres wherever a scene supplies them.
//! - A [`Ray`] direction need not be unit length; hit distances `t` are in units of the direction's
//!   length, so with a unit direction `t` is a distance in metres. Transforms into object space keep
//!   `t` unchanged (the direction is not renormalised), so world and object `t` agree.
//! - Intersections report the nearest hit with `t_min < t < t_max`.
//! - Geometric normals are the outward normals of the surface (triangle winding counter-clockwise
//!   seen from outside, sphere outward, plane +z); they are *not* flipped towards the ray. Shading
//!   normals are interpolated vertex normals for meshes and equal the geometric normal for analytic
//!   shapes. Callers that need a front-facing normal flip both with `dot(dir, n) > 0`.

pub mod aabb;
pub mod bound;
pub mod bvh;
pub mod distance;
pub mod mesh;
pub mod obj;
pub mod ply;
pub mod pose_error;
pub mod procedural;
pub mod shapes;
pub mod similarity;
pub mod transform;

use nalgebra::{Point3, Unit, Vector3};

pub use aabb::Aabb;
pub use bound::BoundingSphere;
pub use bvh::Bvh;
pub use mesh::{MeshError, TriangleMesh};
pub use pose_error::{PoseError, angle_between_deg, pose_error};
pub use shapes::{Plane, Sphere};
pub use transform::ObjectTransform;

/// A ray `origin + t * dir`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: Point3<f64>,
    /// Direction; not necessarily unit length (see the module contract).
    pub dir: Vector3<f64>,
}

impl Ray {
    /// A ray from `origin` along `dir`.
    #[inline]
    pub fn new(origin: Point3<f64>, dir: Vector3<f64>) -> Self {
        Self { origin, dir }
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f64) -> Point3<f64> {
        self.origin + self.dir * t
    }
}

/// Where a ray meets a surface, in the frame of the ray that was intersected.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// Ray parameter of the hit (metres for a unit-length direction).
    pub t: f64,
    /// Hit point.
    pub point: Point3<f64>,
    /// Outward geometric normal (face normal for triangles).
    pub normal_geometric: Unit<Vector3<f64>>,
    /// Shading normal (barycentric interpolation of vertex normals for meshes).
    pub normal_shading: Unit<Vector3<f64>>,
    /// Barycentric weights `[w0, w1, w2]` of the triangle's vertices (sum 1). Analytic shapes
    /// report `[1, 0, 0]`.
    pub barycentric: [f64; 3],
    /// Triangle index for meshes; 0 for analytic shapes.
    pub primitive: u32,
}

/// Something a ray can hit.
pub trait Intersect {
    /// Nearest hit with `t_min < t < t_max`, or `None`.
    fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<SurfaceHit>;

    /// Whether anything is hit with `t_min < t < t_max` (shadow rays); may stop at the first hit.
    fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        self.intersect(ray, t_min, t_max).is_some()
    }

    /// Bounds in the shape's own frame.
    fn bounds(&self) -> Aabb;
}
