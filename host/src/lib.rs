//! `ellipso-host`: the driver and inverse model behind the `ellipso` binary.
//!
//! - [`polar`]: polarisation-mosaic processing (demosaic, Stokes, DoLP, AoLP, observation channels).
//! - [`link`]: the trigger link (serial/pty/socket), version handshake, pulse events, clock model.
//! - [`session`]: the on-disk session format (manifest, event log, raw frames), crash-safe.
//! - [`camera`]: the camera trait, frame ids, counters; backends.
//! - [`acquire`]: capture orchestration and frame ↔ pulse pairing.
//! - [`pose`]: AprilTag detection and joint board pose (IPPE + LM with distortion, flip checks).
//! - [`calibrate`]: camera calibration (Zhang + bundle LM) and flash position from sphere highlights.
//! - [`report`]: PNG line plots and a small raster canvas for reports.
//! - [`track`]: pose tracking of recorded frames (detection image, tags, joint PnP, world pose).
//! - [`process`]: the stages after capture on a recorded session (pose tracking; later the fit).
//! - [`rig_file`]: rig files (trigger port, sensor backend, camera model, capture, boards).
//! - [`cli`]: the subcommands of the `ellipso` binary, one module each.
//!
//! - [`fit`]: the per-vertex polarimetric SVBRDF fit (observations, solver, augmentation, shape).
//! - [`export`]: the fit's outputs (PLY with per-vertex parameters, maps, Mueller grid, relit).
//! - [`view`]: `ellipso view`, the local web page (live capture follower, fitted material).

pub mod acquire;
pub mod calibrate;
pub mod camera;
pub mod cli;
pub mod export;
pub mod fit;
pub mod link;
pub mod polar;
pub mod pose;
pub mod process;
pub mod report;
pub mod rig_file;
pub mod session;
pub mod track;
pub mod view;
