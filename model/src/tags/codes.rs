//! The code words and bit layouts of the tag families the simulator prints, as data.
//!
//! These are the tables of the AprilTag 3 library (Olson 2011; Wang & Olson 2016, BSD-2), copied
//! once so the simulator — and every crate that renders a scene — builds without the C library.
//! `ellipso-sim`'s `tag_checks::tables_match_the_c_library` compares every field with the C
//! library's `apriltag_family_t` (apriltag-sys is a dev-dependency of that crate only), so a drift
//! cannot go unnoticed. One file per family under `codes/`, re-exported here.

mod tag16h5;
mod tag25h9;
mod tag36h11;

pub(super) use tag16h5::TAG16H5;
pub(super) use tag25h9::TAG25H9;
pub(super) use tag36h11::TAG36H11;

/// One family's table, laid out as the C `apriltag_family_t`.
pub(super) struct RawTable {
    pub nbits: u32,
    pub width_at_border: u32,
    pub total_width: u32,
    pub reversed_border: bool,
    pub bit_x: &'static [u32],
    pub bit_y: &'static [u32],
    pub codes: &'static [u64],
}
