//! `ellipso-host`: the driver and inverse model behind the `ellipso` binary.
//!
//! - [`polar`]: polarisation-mosaic processing (demosaic, Stokes, DoLP, AoLP, observation channels).
//! - [`pose`]: AprilTag detection and joint board pose (IPPE + LM with distortion, flip checks).
//! - [`calibrate`]: camera calibration (Zhang + bundle LM) and flash position from sphere highlights.
//! - [`cli`]: the subcommands of the `ellipso` binary, one module each.
//!
//! Later modules: trigger link, camera backends, acquisition, sessions, fitting, export.

pub mod calibrate;
pub mod cli;
pub mod polar;
pub mod pose;
