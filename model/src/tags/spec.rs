//! Board descriptions as written in TOML: a `sim/boards/*.toml` file or a scene's
//! `[boards.inline]` table. Plain serde structs with `deny_unknown_fields`; the frames and the
//! meaning of every field are documented in [`super::board`] and `docs/scene.md`.
//! [`super::Board::from_spec`] validates them.

use super::family::TagFamily;
use serde::{Deserialize, Serialize};

/// Where the board frame's origin sits on the sheet.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BoardOrigin {
    /// Top-left corner of the sheet (default).
    #[default]
    SheetTopLeft,
    /// Centre of the sheet.
    SheetCentre,
}

/// Orientation of the board frame's axes relative to the sheet.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BoardAxes {
    /// x right, y down, z into the board (AprilTag / OpenCV; default).
    #[default]
    XRightYDown,
    /// x right, y up, z out of the board towards the viewer.
    XRightYUp,
}

/// A regular grid of tags, filled row by row from the top-left.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    /// Tags per row.
    pub cols: u32,
    /// Rows of tags.
    pub rows: u32,
    /// Centre-to-centre distance between neighbouring tags, metres.
    pub spacing_m: f64,
    /// Id of the top-left tag; ids increase row by row (ignored when `ids` is given).
    #[serde(default)]
    pub first_id: u32,
    /// Explicit ids, row-major, `cols × rows` of them.
    #[serde(default)]
    pub ids: Option<Vec<u32>>,
    /// Centre of the top-left tag in sheet coordinates, metres (default: one margin plus the
    /// quiet zone plus half a tag from the sheet's top-left corner).
    #[serde(default)]
    pub first_centre_m: Option<[f64; 2]>,
}

/// One explicitly placed tag.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TagPlacementSpec {
    /// Tag id in the family.
    pub id: u32,
    /// Tag centre in sheet coordinates (x right, y down from the top-left corner), metres.
    pub centre_m: [f64; 2],
    /// In-plane rotation of the printed tag, degrees, clockwise as seen from the front.
    #[serde(default)]
    pub rotation_deg: f64,
}

fn default_white() -> f64 {
    0.85
}
fn default_black() -> f64 {
    0.04
}
fn default_margin() -> f64 {
    0.01
}

/// A board as written in TOML (a `sim/boards/*.toml` file or an inline scene table).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BoardSpec {
    /// Free-form name.
    #[serde(default)]
    pub name: Option<String>,
    /// Tag family (default `tag36h11`).
    #[serde(default)]
    pub family: TagFamily,
    /// Tag size in metres: outer edge of the black border (AprilTag's `tagsize`).
    pub tag_size_m: f64,
    /// Sheet `[width, height]` in metres (default: just large enough for all tags plus margin).
    #[serde(default)]
    pub sheet_size_m: Option<[f64; 2]>,
    /// Blank border used for the default sheet size and grid position, metres (default 0.01).
    #[serde(default = "default_margin")]
    pub margin_m: f64,
    /// Diffuse albedo of white print (default 0.85).
    #[serde(default = "default_white")]
    pub white_albedo: f64,
    /// Diffuse albedo of black print (default 0.04).
    #[serde(default = "default_black")]
    pub black_albedo: f64,
    /// Board frame origin (default `sheet_top_left`).
    #[serde(default)]
    pub origin: BoardOrigin,
    /// Board frame axes (default `x_right_y_down`).
    #[serde(default)]
    pub axes: BoardAxes,
    /// Regular grid layout.
    #[serde(default)]
    pub grid: Option<GridSpec>,
    /// Explicit placements (may be combined with a grid).
    #[serde(default)]
    pub tags: Vec<TagPlacementSpec>,
}
