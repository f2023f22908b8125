//! AprilTag boards for the simulator and the host's pose tracker.
//!
//! - [`family`]: tag families and their code tables, read from the AprilTag C library so printed
//!   tags carry exactly the bits the detector decodes.
//! - [`board`]: board descriptions (TOML), validation, albedo lookup, tag corners, ray hits.
//! - [`placed`]: a board posed in the world (`world_from_board`) for world-space rays.
//!
//! Frame conventions and the corner order are documented in [`board`].

pub mod board;
pub mod family;
pub mod placed;

#[cfg(test)]
pub(crate) mod detect_for_tests;
#[cfg(test)]
mod tests;

pub use board::{
    Board, BoardAxes, BoardError, BoardHit, BoardOrigin, BoardSpec, BoardTag, GridSpec,
    TagPlacementSpec,
};
pub use family::{TagCells, TagCodeTable, TagFamily};
pub use placed::PlacedBoard;
