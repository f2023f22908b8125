//! Acquisition: orchestrates the trigger board and the camera into a recorded session.
//!
//! - [`pairing`]: frame ↔ pulse pairing by id and clock model, with every failure reported.

pub mod pairing;
