//! Fixtures shared by the tests of this crate and of the crates above it (feature
//! `test-support`, off in every build that is not a test): one definition of each, so two
//! test modules cannot drift apart on what "the test board" is.

use crate::tags::{BoardAxes, BoardOrigin, BoardSpec, GridSpec, TagFamily};

/// A `cols × rows` grid board of tag36h11 tags of side `size` (m; ids 3…), `spacing` (m)
/// apart, 10 mm of margin, no sheet size, the paper's usual albedos.
pub fn grid_spec(cols: u32, rows: u32, size: f64, spacing: f64) -> BoardSpec {
    BoardSpec {
        name: None,
        family: TagFamily::Tag36h11,
        tag_size_m: size,
        sheet_size_m: None,
        margin_m: 0.01,
        white_albedo: 0.85,
        black_albedo: 0.04,
        origin: BoardOrigin::SheetTopLeft,
        axes: BoardAxes::XRightYDown,
        grid: Some(GridSpec {
            cols,
            rows,
            spacing_m: spacing,
            first_id: 3,
            ids: None,
            first_centre_m: None,
        }),
        tags: Vec::new(),
    }
}
