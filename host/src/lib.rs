//! `ellipso-host`: the driver and inverse model behind the `ellipso` binary.
//!
//! - [`polar`]: polarisation-mosaic processing (demosaic, Stokes, DoLP, AoLP, observation channels).
//! - [`link`]: the trigger link (serial/pty/socket), version handshake, pulse events, clock model.
//! - [`session`]: the on-disk session format (manifest, event log, raw frames), crash-safe.
//! - [`camera`]: the camera trait, frame ids, counters; backends.
//! - [`acquire`]: capture orchestration and frame ↔ pulse pairing.
//! - [`cli`]: the subcommands of the `ellipso` binary, one module each.
//!
//! Later modules: trigger link, camera backends, acquisition, sessions, pose, fitting, export.

pub mod acquire;
pub mod camera;
pub mod cli;
pub mod link;
pub mod polar;
pub mod session;
