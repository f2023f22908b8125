//! `ellipso-vision`: what the host sees in a session's frames — AprilTag detection and board
//! poses, pose tracking of recorded frames, camera and flash calibration. It is the one crate
//! (with the binary) that links the AprilTag C library, and it depends on neither the simulator
//! nor the wire protocol: a recorded session's frames are tracked from its own record.
//!
//! - [`pose`]: AprilTag detection and joint board pose (IPPE + LM with distortion, flip checks).
//! - [`track`]: pose tracking of recorded frames (detection image, tags, joint PnP, world pose).
//! - [`process`]: the stages after capture on a recorded session (pose tracking, appended poses).
//! - [`short_pulse_poses`]: poses for short-pulse frames of a bracketed capture that tracking
//!   refused, from their tracked neighbours.
//! - [`calibrate`]: camera calibration (Zhang + bundle LM) and flash position from sphere
//!   highlights.
//! - `lm`: the one Levenberg–Marquardt loop of pose refinement and the calibration bundle.
//! - [`replay`]: the replay report of a recorded session (`ellipso replay`).
#![cfg_attr(not(test), forbid(unsafe_code))] // a detector test reads a tag image through apriltag-sys

pub mod calibrate;
pub mod flat_raw;
mod lm;
pub mod pose;
pub mod process;
pub mod replay;
pub mod short_pulse_poses;
pub mod track;
mod tracked;
