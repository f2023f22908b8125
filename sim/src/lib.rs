//! `ellipso-sim`: the forward model of the ellipso rig.
//!
//! - [`camera`]: the pinhole + Brown–Conrady camera model (OpenCV conventions) with analytic
//!   Jacobians, shared by the renderer and the host's pose estimation and calibration.
//! - [`optics`]: Stokes vectors, Mueller matrices, Fresnel, GGX, the polarimetric BRDF
//!   (diffuse, specular, single scattering) and the polarisation-camera measurement model.
//!   The fit in `ellipso-host` inverts exactly these functions: one model, never two copies.
//! - [`geometry`]: rays, BVH, triangle meshes (PLY/OBJ), analytic shapes, object transforms.
//! - [`tags`]: AprilTag families (real code tables) and boards: albedo, corners, ray hits.
//! - [`mosaic`]: the sensor mosaic (IMX250MZR/MYR): analyser angle and colour filter per raw pixel.
//! - [`scene`]: scene files (TOML): objects, materials, AprilTag boards, rig, capture path.
//!
//! - [`effects`]: effects on demand — the plan of stages a scene needs, with reasons, and the
//!   per-frame stage execution counts that prove it.
//! - [`render`]: the polarimetric renderer (raw mosaic frames + ground truth) and the
//!   radiometry shared with the fit.
//!
//! Later modules (virtual rig) build on these.

pub mod camera;
pub mod effects;
pub mod geometry;
pub mod mosaic;
pub mod optics;
pub mod render;
pub mod rig;
pub mod scene;
pub mod tags;
