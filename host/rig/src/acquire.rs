//! Acquisition: orchestrates the trigger board and the camera into a recorded session.
//!
//! - [`capture`]: one capture, board + camera → a recorded, paired session.
//! - [`board_record`]: the capture timing sent to the board, as the session records it.
//! - [`pairing`]: frame ↔ pulse pairing by id and clock model, with every failure reported.
//! - [`ready`]: a capture connected, checked and ready to run (link, camera, new session, plan);
//!   how a caller records it (its stop flag, its progress: [`ready::Recorder`]) and its summary.
//! - [`sim_rig`]: the simulated rig of `ellipso capture --sim` (virtual board on a pty or an
//!   external `ellipso sim serve`, simulated camera rendering the scene).
//! - [`hardware`]: the physical rig of `ellipso capture --rig` (serial trigger board, camera
//!   backends).

pub mod board_record;
pub mod capture;
pub mod hardware;
pub mod pairing;
pub mod ready;
pub mod sim_rig;
