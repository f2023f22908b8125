//! `ellipso-model`: the shared core of ellipso — the physics and geometry the simulator renders
//! with and the fit inverts (one model, never two copies). It depends on no C library, so the fit
//! and anything that only reads sessions build from the Rust registry alone.
//!
//! - [`optics`]: Stokes vectors, Mueller matrices, Fresnel, GGX, the polarimetric BRDF
//!   (diffuse, specular, single scattering) and the polarisation-camera measurement model, each
//!   equation with its source in `docs/model.md`.
//! - [`camera`]: the pinhole + Brown–Conrady camera model (OpenCV conventions) with analytic
//!   Jacobians, shared by the renderer, pose estimation, calibration and the fit.
//! - [`geometry`]: rays, BVH, triangle meshes (PLY/OBJ), analytic shapes, object transforms.
//! - [`mosaic`]: the sensor mosaic (IMX250MZR/MYR): analyser angle and colour filter per raw
//!   pixel.
//! - [`stats`]: the one median and percentile (nearest rank) every crate reports with.
//! - [`colour`]: the one sRGB encoder (linear → 8-bit code) for every picture.
//! - [`file_io`]: reading an input file whole with a size bound, refusing special files.
//! - [`tags`]: AprilTag families (code tables as data) and boards: albedo, corners, ray hits;
//!   what the simulator renders and the tracker detects.
//! - [`rig`]: the camera settings and the flash of a rig, as scene files and session
//!   manifests spell them.
//! - [`radiometry`]: the camera equation from model intensity to electrons and DN (the
//!   normaliser N), shared by the renderer and the fit.
#![cfg_attr(not(test), forbid(unsafe_code))] // a test makes a FIFO with libc

pub mod camera;
pub mod colour;
pub mod file_io;
pub mod geometry;
pub mod mosaic;
pub mod optics;
pub mod radiometry;
pub mod rig;
pub mod stats;
pub mod tags;
#[cfg(any(test, feature = "test-support"))]
pub mod test_support;
