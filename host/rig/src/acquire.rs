//! Acquisition: orchestrates the trigger board and the camera into a recorded session.
//!
//! - [`capture`]: one capture, board + camera → a recorded, paired session.
//! - [`pairing`]: frame ↔ pulse pairing by id and clock model, with every failure reported.

pub mod capture;
pub mod pairing;
