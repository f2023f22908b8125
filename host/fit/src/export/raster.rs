//! Rasterising the fitted mesh into a view: which surface point, normal and per-vertex values
//! every pixel sees.
//!
//! Contract:
//! - [`ViewCamera`] is an ideal pinhole camera at a pose (`world_from_camera`, OpenCV axes: x
//!   right, y down, z forward) whose focal length frames a given bounding sphere — so pictures
//!   show the object large whatever the capture distance. [`ViewCamera::framing`] builds it. Its
//!   intrinsics are the camera model's [`Intrinsics`] (square pixels, principal point at the
//!   image centre: `cx = w/2 − ½`, pixel centres on integers as everywhere in the model).
//! - [`rasterise`] casts one ray per pixel centre through the mesh's BVH (rayon over rows,
//!   deterministic) and returns, per pixel, the hit triangle's vertex indices and barycentric
//!   weights, the world point and the camera-frame depth, or `None` for background.
//! - Values are interpolated with [`Hit::interpolate`]; normals are renormalised by the caller.
//!
//! The ray–mesh intersection is the model's one (`TriangleMesh`'s BVH and Möller–Trumbore, as
//! the renderer's). The pixel rays stay this module's own, an ideal pinhole without the camera
//! model's undistortion step: `((x − cx)/fx, (y − cy)/fy, 1)` normalised. Every term of `x − cx`
//! is a multiple of ½ far below 2⁵², so it is exact and equals the earlier `x + ½ − w/2` bit for
//! bit (a test checks): pictures and float maps keep their bytes.

use ellipso_model::camera::Intrinsics;
use ellipso_model::geometry::{Intersect, Ray, TriangleMesh};
use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;

/// An ideal pinhole camera for pictures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewCamera {
    /// Camera → world (OpenCV axes).
    pub world_from_camera: Isometry3<f64>,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Focal lengths (equal: square pixels) and principal point (the image centre), px.
    pub intrinsics: Intrinsics,
}

impl ViewCamera {
    /// A `width × height` camera at `world_from_camera` with focal length `focal_px` on both
    /// axes and the principal point at the image centre (`cx = w/2 − ½`, `cy = h/2 − ½`).
    pub fn pinhole(
        world_from_camera: Isometry3<f64>,
        width: u32,
        height: u32,
        focal_px: f64,
    ) -> Self {
        Self {
            world_from_camera,
            width,
            height,
            intrinsics: Intrinsics {
                fx: focal_px,
                fy: focal_px,
                cx: f64::from(width) / 2.0 - 0.5,
                cy: f64::from(height) / 2.0 - 0.5,
            },
        }
    }

    /// A `width × height` camera at `world_from_camera` whose view just contains the sphere
    /// (`centre`, `radius_m`) with a 10 % margin. The camera must be outside the sphere; a
    /// camera inside (or at) it gets a 90° field of view.
    pub fn framing(
        world_from_camera: Isometry3<f64>,
        width: u32,
        height: u32,
        centre: &Point3<f64>,
        radius_m: f64,
    ) -> Self {
        let d = (centre - Point3::from(world_from_camera.translation.vector)).norm();
        // tan of the half-angle the sphere subtends, guarded for a camera inside it.
        let tan_half = if d > radius_m * 1.01 {
            let s = (radius_m / d).clamp(0.0, 0.99);
            s / (1.0 - s * s).sqrt()
        } else {
            1.0
        };
        let half_px = f64::from(width.min(height)) / 2.0;
        Self::pinhole(world_from_camera, width, height, half_px / (1.1 * tan_half))
    }

    /// Focal length, px (square pixels: `fx`, equal to `fy`).
    pub fn focal_px(&self) -> f64 {
        self.intrinsics.fx
    }

    /// The world ray through pixel centre (x, y).
    pub fn ray(&self, x: u32, y: u32) -> Ray {
        let i = &self.intrinsics;
        let u = (f64::from(x) - i.cx) / i.fx;
        let v = (f64::from(y) - i.cy) / i.fy;
        let dir = self
            .world_from_camera
            .transform_vector(&Vector3::new(u, v, 1.0).normalize());
        Ray::new(Point3::from(self.world_from_camera.translation.vector), dir)
    }

    /// The camera centre, world.
    pub fn centre_world(&self) -> Point3<f64> {
        Point3::from(self.world_from_camera.translation.vector)
    }
}

/// What one pixel sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// The hit triangle's vertex indices.
    pub vertices: [u32; 3],
    /// Barycentric weights (sum 1).
    pub barycentric: [f64; 3],
    /// The world point.
    pub point_world: Point3<f64>,
}

impl Hit {
    /// Barycentric interpolation of a per-vertex value.
    pub fn interpolate<const N: usize>(&self, values: &[[f64; N]]) -> [f64; N] {
        let mut out = [0.0; N];
        for (k, &v) in self.vertices.iter().enumerate() {
            let w = self.barycentric[k];
            for (o, x) in out.iter_mut().zip(values[v as usize]) {
                *o += w * x;
            }
        }
        out
    }
}

/// One hit or `None` per pixel, row-major.
pub fn rasterise(mesh: &TriangleMesh, camera: &ViewCamera) -> Vec<Option<Hit>> {
    (0..camera.height)
        .into_par_iter()
        .flat_map_iter(|y| {
            (0..camera.width).map(move |x| {
                let ray = camera.ray(x, y);
                let hit = mesh.intersect(&ray, 0.0, f64::INFINITY)?;
                Some(Hit {
                    vertices: mesh.triangle(hit.primitive),
                    barycentric: hit.barycentric,
                    point_world: ray.at(hit.t),
                })
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::geometry::procedural::icosphere;
    use nalgebra::{Translation3, UnitQuaternion};

    fn sphere() -> TriangleMesh {
        let (dirs, faces) = icosphere(3);
        let pos = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * 0.04))
            .collect();
        TriangleMesh::new(pos, None, None, faces).unwrap()
    }

    #[test]
    fn a_framed_sphere_fills_the_middle_and_leaves_the_corners() {
        // Camera 0.5 m along +z looking down −z (OpenCV z forward = world −z).
        let pose = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        let cam = ViewCamera::framing(pose, 64, 48, &Point3::origin(), 0.04);
        let hits = rasterise(&sphere(), &cam);
        assert_eq!(hits.len(), 64 * 48);
        let centre = hits[24 * 64 + 32].expect("centre hits the sphere");
        assert!((centre.point_world.z - 0.04).abs() < 1e-3);
        assert!(hits[0].is_none() && hits[64 * 48 - 1].is_none());
        let covered = hits.iter().filter(|h| h.is_some()).count() as f64 / (64.0 * 48.0);
        // The disc spans ~1/1.1 of the short side: π·(0.45·48)²/(64·48) ≈ 0.48.
        assert!((0.35..0.6).contains(&covered), "{covered}");
        let w: f64 = centre.barycentric.iter().sum();
        assert!((w - 1.0).abs() < 1e-9);
    }

    #[test]
    fn rays_from_the_intrinsics_equal_the_centred_pixel_form_bit_for_bit() {
        let pose = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 2.5),
        );
        for (w, h) in [(64, 48), (63, 47), (1024, 1024), (2448, 2048)] {
            let cam = ViewCamera::framing(pose, w, h, &Point3::origin(), 0.04);
            let f = cam.focal_px();
            for y in (0..h).step_by(7) {
                for x in (0..w).step_by(5) {
                    // The form the pictures were first made with: pixel centre x + ½ about w/2.
                    let u = (f64::from(x) + 0.5 - f64::from(w) / 2.0) / f;
                    let v = (f64::from(y) + 0.5 - f64::from(h) / 2.0) / f;
                    let dir = pose.transform_vector(&Vector3::new(u, v, 1.0).normalize());
                    let bits = |d: Vector3<f64>| d.map(f64::to_bits);
                    assert_eq!(bits(cam.ray(x, y).dir), bits(dir), "({x}, {y}) of {w}×{h}");
                }
            }
        }
    }
}
