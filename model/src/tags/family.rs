//! AprilTag families and their code tables.
//!
//! Contract: [`TagFamily::code_table`] returns the family's code words and bit layout, the
//! AprilTag library's own tables held as data (`codes.rs`; a test checks them field by field
//! against the C library), so rendering uses exactly the bits the detector decodes. [`TagCodeTable::cells`] reproduces
//! `apriltag_to_image` cell for cell: a `total_width × total_width` grid, row-major, row 0 at the
//! top, `true` = white; for classic families that is a one-cell white ring, a one-cell black
//! ring, then the data bits.

use serde::{Deserialize, Serialize};
use std::sync::OnceLock;

/// The tag families the simulator can print.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Deserialize, Serialize)]
pub enum TagFamily {
    /// 36-bit codes, minimum Hamming distance 11, 587 codes (the default).
    #[default]
    #[serde(rename = "tag36h11")]
    Tag36h11,
    /// 25-bit codes, minimum Hamming distance 9, 35 codes.
    #[serde(rename = "tag25h9")]
    Tag25h9,
    /// 16-bit codes, minimum Hamming distance 5, 30 codes.
    #[serde(rename = "tag16h5")]
    Tag16h5,
}

impl TagFamily {
    /// All supported families.
    pub const ALL: [TagFamily; 3] = [Self::Tag36h11, Self::Tag25h9, Self::Tag16h5];

    /// The family's name as AprilTag spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Tag36h11 => "tag36h11",
            Self::Tag25h9 => "tag25h9",
            Self::Tag16h5 => "tag16h5",
        }
    }

    /// The family's code table (built from the embedded data on first use).
    pub fn code_table(self) -> &'static TagCodeTable {
        static TABLES: [OnceLock<TagCodeTable>; 3] =
            [OnceLock::new(), OnceLock::new(), OnceLock::new()];
        let slot = match self {
            Self::Tag36h11 => 0,
            Self::Tag25h9 => 1,
            Self::Tag16h5 => 2,
        };
        TABLES[slot].get_or_init(|| TagCodeTable::embedded(self))
    }
}

/// Code words and bit layout of one family (a copy of the C `apriltag_family_t`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TagCodeTable {
    /// Which family.
    pub family: TagFamily,
    /// One code word per tag id; bit `nbits - 1 - i` is data bit `i`.
    pub codes: Vec<u64>,
    /// Number of data bits.
    pub nbits: u32,
    /// Column of data bit `i`, counted from the outer edge of the black border.
    pub bit_x: Vec<u32>,
    /// Row of data bit `i`, counted from the outer edge of the black border.
    pub bit_y: Vec<u32>,
    /// Width in cells at the detected border (the tag size AprilTag reports poses for).
    pub width_at_border: u32,
    /// Full width in cells including the white quiet ring.
    pub total_width: u32,
    /// Whether the border is white-inside-black (newer families).
    pub reversed_border: bool,
}

/// A rendered tag: `width × width` cells, row-major, row 0 at the top, `true` = white.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TagCells {
    /// Cells per side (`total_width`).
    pub width: usize,
    /// Row-major cells, `true` = white.
    pub white: Vec<bool>,
}

impl TagCells {
    /// Whether cell (`col`, `row`) is white; out of range counts as white (quiet zone).
    pub fn is_white(&self, col: usize, row: usize) -> bool {
        if col >= self.width || row >= self.width {
            return true;
        }
        self.white[row * self.width + col]
    }
}

impl TagCodeTable {
    fn embedded(family: TagFamily) -> Self {
        let raw = match family {
            TagFamily::Tag36h11 => &super::codes::TAG36H11,
            TagFamily::Tag25h9 => &super::codes::TAG25H9,
            TagFamily::Tag16h5 => &super::codes::TAG16H5,
        };
        Self {
            family,
            codes: raw.codes.to_vec(),
            nbits: raw.nbits,
            bit_x: raw.bit_x.to_vec(),
            bit_y: raw.bit_y.to_vec(),
            width_at_border: raw.width_at_border,
            total_width: raw.total_width,
            reversed_border: raw.reversed_border,
        }
    }

    /// Number of codes (valid ids are `0..len()`).
    pub fn len(&self) -> usize {
        self.codes.len()
    }

    /// Whether the family has no codes (never true for the supported families).
    pub fn is_empty(&self) -> bool {
        self.codes.is_empty()
    }

    /// Width of the white quiet zone printed around the detected border, in cells.
    pub fn quiet_zone_cells(&self) -> u32 {
        ((self.total_width - self.width_at_border) / 2).max(1)
    }

    /// Cells of tag `id`, exactly as `apriltag_to_image` draws them; `None` for an unknown id.
    pub fn cells(&self, id: u32) -> Option<TagCells> {
        let code = *self.codes.get(id as usize)?;
        let tw = self.total_width as usize;
        let mut white = vec![false; tw * tw];
        let white_border_width =
            self.width_at_border as usize + if self.reversed_border { 0 } else { 2 };
        let white_border_start = (tw - white_border_width) / 2;
        // The one-cell white ring (same loop as the C code).
        for i in 0..white_border_width - 1 {
            white[white_border_start * tw + white_border_start + i] = true;
            white[(white_border_start + i) * tw + tw - 1 - white_border_start] = true;
            white[(tw - 1 - white_border_start) * tw + white_border_start + i + 1] = true;
            white[(white_border_start + 1 + i) * tw + white_border_start] = true;
        }
        let border_start = (tw - self.width_at_border as usize) / 2;
        for i in 0..self.nbits as usize {
            if code & (1u64 << (self.nbits as usize - i - 1)) != 0 {
                let row = self.bit_y[i] as usize + border_start;
                let col = self.bit_x[i] as usize + border_start;
                white[row * tw + col] = true;
            }
        }
        Some(TagCells { width: tw, white })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_have_the_documented_shapes() {
        let t = TagFamily::Tag36h11.code_table();
        assert_eq!(
            (t.len(), t.nbits, t.width_at_border, t.total_width),
            (587, 36, 8, 10)
        );
        assert_eq!(t.quiet_zone_cells(), 1);
        assert!(t.cells(587).is_none());
        assert_eq!(TagFamily::Tag25h9.code_table().len(), 35);
        assert_eq!(TagFamily::Tag16h5.code_table().len(), 30);
        // Distinct ids render distinct patterns.
        assert_ne!(t.cells(0), t.cells(1));
    }
}
