//! `ellipso-colmap`: the COLMAP formats, both ways, for users who prefer photogrammetry for the
//! geometry (docs/mesh.md, "COLMAP export" and "The way in").
//!
//! - [`export`]: a session seen from its poses as a COLMAP sparse model with undistorted
//!   full-resolution s0 images and the feature database COLMAP's own pipeline needs
//!   (`ellipso export colmap`, whose command body is `ellipso_pipeline::colmap_export`).
//! - [`model`]: a COLMAP model read (text or binary).
//! - [`import`]: its poses, and a mesh in its frame, aligned to the board frame through the
//!   session's own AprilTag poses (`ellipso fit --poses`, `--mesh-frame colmap`).
//! - [`recipe`]: docs/mesh.md's COLMAP recipes as steps, which the tests run verbatim.
//!
//! Contract: the export reads the session (frames streamed) and writes only into the folder it
//! is given; reading and aligning never touch the session.
#![forbid(unsafe_code)]

pub mod export;
pub mod import;
pub mod model;
pub mod recipe;

#[cfg(test)]
mod tests;
