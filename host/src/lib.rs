//! `ellipso-host`: the driver and inverse model behind the `ellipso` binary.
//!
//! - [`polar`]: polarisation-mosaic processing (demosaic, Stokes, DoLP, AoLP, observation channels).
//! - [`report`]: PNG line plots and a small raster canvas for reports.
//! - [`cli`]: the subcommands of the `ellipso` binary, one module each.
//!
//! Later modules: trigger link, camera backends, acquisition, sessions, pose, fitting, export.

pub mod cli;
pub mod polar;
pub mod report;
