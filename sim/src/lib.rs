//! `ellipso-sim`: the forward model of the ellipso rig.
//!
//! - [`optics`]: Stokes vectors, Mueller matrices, Fresnel, GGX, the polarimetric BRDF
//!   (diffuse, specular, single scattering) and the polarisation-camera measurement model.
//!   The fit in `ellipso-host` inverts exactly these functions: one model, never two copies.
//! - [`mosaic`]: the sensor mosaic (IMX250MZR/MYR): analyser angle and colour filter per raw pixel.
//! - [`scene`]: scene files (TOML): objects, materials, AprilTag boards, rig, capture path.
//!
//! Later modules (renderer, sensor effects, virtual rig) build on these.

pub mod mosaic;
pub mod optics;
pub mod scene;
