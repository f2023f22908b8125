//! AprilTag boards: what the simulator renders, a rig file or a scene places, and the pose
//! tracker detects (as a session records it: `ellipso_session::rig::TrackedBoard`). Here, in the
//! shared core, so the tracker reaches them without the simulator.
//!
//! - [`family`]: tag families and their code tables, as data taken from the AprilTag C library
//!   (checked against it in `ellipso-sim`'s tests), so printed tags carry exactly the bits the
//!   detector decodes.
//! - [`spec`]: board descriptions as written in TOML (board files and inline tables).
//! - [`board`]: validation and the built board: albedo lookup, tag corners, ray hits.
//! - [`placed`]: a board posed in the world (`world_from_board`) for world-space rays.
//! - [`texture`]: a printed sheet's raster laid over a board (the simulator renders prints).
//!
//! Frame conventions and the corner order are documented in [`board`].

pub mod board;
mod codes;
pub mod family;
pub mod placed;
pub mod spec;
pub mod texture;

#[cfg(test)]
mod tests;

pub use board::{
    Board, BoardAxes, BoardError, BoardHit, BoardOrigin, BoardSpec, BoardTag, GridSpec,
    TagPlacementSpec,
};
pub use family::{TagCells, TagCodeTable, TagFamily};
pub use placed::PlacedBoard;
pub use texture::{SheetTexture, TextureError};
