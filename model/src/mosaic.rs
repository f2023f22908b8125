//! The sensor mosaic: which micro-polariser (and which colour filter) sits over each raw pixel.
//!
//! This module is the single source of truth for the pixel pattern of the Sony IMX250MZR (mono)
//! and IMX250MYR (colour) polarisation sensors. The simulator renders raw frames with it and the
//! host demosaics with it, so the two can never disagree about the phase.
//!
//! # Layouts
//!
//! Pixel coordinates are `(x, y)` with `x` growing to image-right and `y` (rows) growing
//! **downward**, origin at the first pixel the camera delivers (no ReverseX/ReverseY flips).
//!
//! [`SensorLayout::MonoPolar`] (IMX250MZR): a 2×2 polariser superpixel repeats over the frame
//! (JAI GO-5100MP-USB manual p.24; Beckhoff `F_VN_DemosaicPolarizedImage`):
//!
//! ```text
//!          x even  x odd
//! y even:   90°     45°
//! y odd:   135°      0°
//! ```
//!
//! [`SensorLayout::ColourPolar`] (IMX250MYR): each 2×2 polariser block (same angle pattern as
//! above) sits under a single colour filter, and the blocks form a Bayer RGGB pattern, giving a
//! 4×4 tile:
//!
//! ```text
//!   90R  45R |  90G  45G
//!  135R   0R | 135G   0G
//!  ----------+----------
//!   90G  45G |  90B  45B
//!  135G   0G | 135B   0B
//! ```
//!
//! The colour arrangement is an assumption taken from the vendor pixel format name
//! `BayerRGPolarized8` (FLIR Spinnaker) and has not been checked against the Sony datasheet;
//! everything that depends on it goes through [`SensorLayout::colour_at`], so a correction is a
//! one-place change.
//!
//! # Angles
//!
//! An analyser angle θ is measured from image-right toward image-up, as seen in the unflipped
//! displayed image (looking back along the direction of propagation). A sensor mirror flip
//! (ReverseX or ReverseY) shifts the mosaic phase *and* swaps 45° and 135°; this crate assumes
//! no flips.
//!
//! # Regions of interest
//!
//! A region of interest (ROI) offset that is not a multiple of the tile size shifts the pattern:
//! an odd offset swaps analyser angles, an offset of 2 on the colour sensor swaps colours. Such
//! offsets are rejected by [`SensorLayout::check_roi_offset`] rather than silently re-phased.
//! Frame sizes must likewise be whole tiles ([`SensorLayout::check_frame_size`]), so every
//! superpixel is complete.

use serde::{Deserialize, Serialize};

/// The micro-polariser pattern of a polarisation sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SensorLayout {
    /// Sony IMX250MZR: monochrome, 2×2 polariser superpixel `90 45 / 135 0`.
    #[serde(alias = "mono")]
    MonoPolar,
    /// Sony IMX250MYR: each 2×2 polariser block under one colour filter, blocks in Bayer RGGB.
    #[serde(alias = "colour", alias = "color")]
    ColourPolar,
}

/// One of the four micro-polariser orientations of the sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Analyser {
    /// Transmission axis along image-right (the flash polariser is parallel to this one).
    Deg0,
    /// Transmission axis 45° from image-right toward image-up.
    Deg45,
    /// Transmission axis along image-up.
    Deg90,
    /// Transmission axis 135° from image-right toward image-up.
    Deg135,
}

impl Analyser {
    /// All four analysers, in the order 0°, 45°, 90°, 135° (the order of [`Analyser::index`]).
    pub const ALL: [Analyser; 4] = [
        Analyser::Deg0,
        Analyser::Deg45,
        Analyser::Deg90,
        Analyser::Deg135,
    ];

    /// The transmission-axis angle in degrees: 0, 45, 90 or 135.
    pub fn angle_deg(self) -> f64 {
        match self {
            Analyser::Deg0 => 0.0,
            Analyser::Deg45 => 45.0,
            Analyser::Deg90 => 90.0,
            Analyser::Deg135 => 135.0,
        }
    }

    /// The transmission-axis angle in radians.
    pub fn angle_rad(self) -> f64 {
        self.angle_deg().to_radians()
    }

    /// Position in [`Analyser::ALL`]: 0°→0, 45°→1, 90°→2, 135°→3.
    pub fn index(self) -> usize {
        match self {
            Analyser::Deg0 => 0,
            Analyser::Deg45 => 1,
            Analyser::Deg90 => 2,
            Analyser::Deg135 => 3,
        }
    }

    /// Offset `(dx, dy)` of this analyser inside a 2×2 polariser block (both layouts).
    pub const fn offset_in_block(self) -> (usize, usize) {
        match self {
            Analyser::Deg90 => (0, 0),
            Analyser::Deg45 => (1, 0),
            Analyser::Deg135 => (0, 1),
            Analyser::Deg0 => (1, 1),
        }
    }
}

/// A colour-filter channel of the colour-polarisation sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Channel {
    /// Red filter.
    Red,
    /// Green filter (two blocks per 4×4 tile).
    Green,
    /// Blue filter.
    Blue,
}

impl Channel {
    /// All channels in R, G, B order (the order of [`Channel::index`]).
    pub const ALL: [Channel; 3] = [Channel::Red, Channel::Green, Channel::Blue];

    /// Position in [`Channel::ALL`]: R→0, G→1, B→2.
    pub fn index(self) -> usize {
        match self {
            Channel::Red => 0,
            Channel::Green => 1,
            Channel::Blue => 2,
        }
    }

    /// Lowercase one-letter name (`r`, `g`, `b`), used in file names.
    pub fn letter(self) -> &'static str {
        match self {
            Channel::Red => "r",
            Channel::Green => "g",
            Channel::Blue => "b",
        }
    }

    /// Offsets `(bx, by)`, in 2×2 blocks, of this colour's blocks inside the 4×4 tile.
    pub fn blocks_in_tile(self) -> &'static [(usize, usize)] {
        match self {
            Channel::Red => &[(0, 0)],
            Channel::Green => &[(1, 0), (0, 1)],
            Channel::Blue => &[(1, 1)],
        }
    }
}

/// Why a frame geometry does not fit the mosaic.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MosaicError {
    /// A ROI offset that would shift the mosaic phase.
    #[error(
        "ROI offset ({offset_x}, {offset_y}) is not a multiple of the {tile_px}-pixel {layout:?} tile: \
         it would shift the mosaic phase (odd offsets swap analyser angles)"
    )]
    RoiOffsetBreaksMosaic {
        /// The layout checked against.
        layout: SensorLayout,
        /// Horizontal ROI offset in pixels.
        offset_x: u32,
        /// Vertical ROI offset in pixels.
        offset_y: u32,
        /// Tile size the offsets must be multiples of.
        tile_px: u32,
    },
    /// A frame size that leaves incomplete superpixels or tiles.
    #[error(
        "frame size {width}×{height} is not a whole number of {tile_px}×{tile_px} {layout:?} tiles \
         (binning, decimation or an odd ROI breaks the mosaic)"
    )]
    SizeBreaksMosaic {
        /// The layout checked against.
        layout: SensorLayout,
        /// Frame width in pixels.
        width: u32,
        /// Frame height in pixels.
        height: u32,
        /// Tile size the dimensions must be multiples of.
        tile_px: u32,
    },
}

impl SensorLayout {
    /// Both layouts.
    pub const ALL: [SensorLayout; 2] = [SensorLayout::MonoPolar, SensorLayout::ColourPolar];

    /// Side of the repeating tile in pixels: 2 (mono) or 4 (colour).
    pub fn tile_px(self) -> u32 {
        match self {
            SensorLayout::MonoPolar => 2,
            SensorLayout::ColourPolar => 4,
        }
    }

    /// The colour channels the layout delivers: none for mono, R, G, B for colour.
    pub fn channels(self) -> &'static [Channel] {
        match self {
            SensorLayout::MonoPolar => &[],
            SensorLayout::ColourPolar => &Channel::ALL,
        }
    }

    /// The analyser over raw pixel `(x, y)` (rows grow downward, no sensor flips).
    pub fn analyser_at(self, x: u32, y: u32) -> Analyser {
        // Same 2×2 block pattern in both layouts.
        match (x & 1, y & 1) {
            (0, 0) => Analyser::Deg90,
            (1, 0) => Analyser::Deg45,
            (0, _) => Analyser::Deg135,
            _ => Analyser::Deg0,
        }
    }

    /// The analyser angle over raw pixel `(x, y)` in degrees (0, 45, 90 or 135).
    pub fn analyser_deg_at(self, x: u32, y: u32) -> f64 {
        self.analyser_at(x, y).angle_deg()
    }

    /// The colour filter over raw pixel `(x, y)`: `None` for the mono sensor.
    pub fn colour_at(self, x: u32, y: u32) -> Option<Channel> {
        match self {
            SensorLayout::MonoPolar => None,
            SensorLayout::ColourPolar => Some(match ((x >> 1) & 1, (y >> 1) & 1) {
                (0, 0) => Channel::Red,
                (1, 1) => Channel::Blue,
                _ => Channel::Green,
            }),
        }
    }

    /// Offset `(dx, dy)` inside one tile of the raw pixel carrying `analyser` in the block at
    /// block offset `(bx, by)` (each 0 or 1; must be 0 for mono).
    pub fn pixel_in_tile(self, analyser: Analyser, block: (usize, usize)) -> (usize, usize) {
        let (dx, dy) = analyser.offset_in_block();
        (2 * block.0 + dx, 2 * block.1 + dy)
    }

    /// Accepts a ROI offset only if it keeps the mosaic phase (a multiple of [`Self::tile_px`]).
    pub fn check_roi_offset(self, offset_x: u32, offset_y: u32) -> Result<(), MosaicError> {
        let tile_px = self.tile_px();
        if offset_x % tile_px == 0 && offset_y % tile_px == 0 {
            Ok(())
        } else {
            Err(MosaicError::RoiOffsetBreaksMosaic {
                layout: self,
                offset_x,
                offset_y,
                tile_px,
            })
        }
    }

    /// Accepts a frame size only if it is a non-empty whole number of tiles.
    pub fn check_frame_size(self, width: u32, height: u32) -> Result<(), MosaicError> {
        let tile_px = self.tile_px();
        if width > 0 && height > 0 && width % tile_px == 0 && height % tile_px == 0 {
            Ok(())
        } else {
            Err(MosaicError::SizeBreaksMosaic {
                layout: self,
                width,
                height,
                tile_px,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mono_superpixel_matches_imx250mzr_datasheet_order() {
        let l = SensorLayout::MonoPolar;
        assert_eq!(l.analyser_deg_at(0, 0), 90.0);
        assert_eq!(l.analyser_deg_at(1, 0), 45.0);
        assert_eq!(l.analyser_deg_at(0, 1), 135.0);
        assert_eq!(l.analyser_deg_at(1, 1), 0.0);
        // periodic with period 2
        for y in 0..6 {
            for x in 0..6 {
                assert_eq!(l.analyser_at(x, y), l.analyser_at(x + 2, y + 4));
                assert_eq!(l.colour_at(x, y), None);
            }
        }
    }

    #[test]
    fn every_block_holds_each_analyser_exactly_once() {
        for layout in SensorLayout::ALL {
            for by in 0..4 {
                for bx in 0..4 {
                    let mut seen = [0u8; 4];
                    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        seen[layout.analyser_at(2 * bx + dx, 2 * by + dy).index()] += 1;
                    }
                    assert_eq!(seen, [1, 1, 1, 1], "{layout:?} block ({bx},{by})");
                }
            }
        }
    }

    #[test]
    fn colour_tile_is_bayer_rggb_of_uniform_blocks() {
        let l = SensorLayout::ColourPolar;
        let expect = [
            [Channel::Red, Channel::Green],
            [Channel::Green, Channel::Blue],
        ];
        for y in 0..8u32 {
            for x in 0..8u32 {
                let c = l.colour_at(x, y).expect("colour layout has colours");
                assert_eq!(c, expect[((y / 2) % 2) as usize][((x / 2) % 2) as usize]);
            }
        }
        // a tile holds 4 R, 8 G, 4 B pixels, each colour with all four analysers
        let mut count = [[0u8; 4]; 3];
        for y in 0..4 {
            for x in 0..4 {
                let c = l.colour_at(x, y).unwrap_or(Channel::Red);
                count[c.index()][l.analyser_at(x, y).index()] += 1;
            }
        }
        assert_eq!(count, [[1; 4], [2; 4], [1; 4]]);
    }

    #[test]
    fn pixel_in_tile_inverts_analyser_and_colour_lookup() {
        let l = SensorLayout::ColourPolar;
        for c in Channel::ALL {
            for &block in c.blocks_in_tile() {
                for a in Analyser::ALL {
                    let (x, y) = l.pixel_in_tile(a, block);
                    assert_eq!(l.analyser_at(x as u32, y as u32), a);
                    assert_eq!(l.colour_at(x as u32, y as u32), Some(c));
                }
            }
        }
        for a in Analyser::ALL {
            let (x, y) = SensorLayout::MonoPolar.pixel_in_tile(a, (0, 0));
            assert_eq!(SensorLayout::MonoPolar.analyser_at(x as u32, y as u32), a);
        }
    }

    #[test]
    fn roi_offsets_and_sizes_must_keep_the_phase() {
        let m = SensorLayout::MonoPolar;
        let c = SensorLayout::ColourPolar;
        assert!(m.check_roi_offset(0, 0).is_ok());
        assert!(m.check_roi_offset(2, 8).is_ok());
        assert!(m.check_roi_offset(1, 0).is_err());
        assert!(m.check_roi_offset(0, 3).is_err());
        assert!(c.check_roi_offset(4, 8).is_ok());
        assert!(
            c.check_roi_offset(2, 0).is_err(),
            "colour offset 2 swaps R and G"
        );
        assert!(m.check_frame_size(2448, 2048).is_ok());
        assert!(c.check_frame_size(2448, 2048).is_ok());
        assert!(m.check_frame_size(2447, 2048).is_err());
        assert!(m.check_frame_size(0, 2).is_err());
        assert!(c.check_frame_size(1226, 1024).is_err());
        let msg = m.check_roi_offset(1, 0).unwrap_err().to_string();
        assert!(msg.contains("phase"), "{msg}");
    }

    #[test]
    fn odd_offset_would_swap_angles() {
        // Documents why odd offsets are refused: reading from x+1 pairs 90° with 45° etc.
        let l = SensorLayout::MonoPolar;
        assert_ne!(l.analyser_at(1, 0), l.analyser_at(0, 0));
        assert_ne!(l.analyser_at(0, 1), l.analyser_at(0, 0));
    }

    #[test]
    fn analyser_angles_and_indices_are_consistent() {
        for (i, a) in Analyser::ALL.iter().enumerate() {
            assert_eq!(a.index(), i);
            assert_eq!(a.angle_deg(), 45.0 * i as f64);
            assert!((a.angle_rad() - (45.0 * i as f64).to_radians()).abs() < 1e-15);
        }
        for (i, c) in Channel::ALL.iter().enumerate() {
            assert_eq!(c.index(), i);
        }
    }
}

#[cfg(test)]
mod serde_tests {
    use super::*;

    #[test]
    fn layouts_serialise_with_lowercase_names_and_accept_short_aliases() {
        assert_eq!(
            serde_json::to_string(&SensorLayout::MonoPolar)
                .ok()
                .as_deref(),
            Some("\"monopolar\"")
        );
        assert_eq!(
            serde_json::to_string(&SensorLayout::ColourPolar)
                .ok()
                .as_deref(),
            Some("\"colourpolar\"")
        );
        let mono: SensorLayout = serde_json::from_str("\"mono\"").expect("alias mono");
        let colour: SensorLayout = serde_json::from_str("\"colour\"").expect("alias colour");
        assert_eq!(
            (mono, colour),
            (SensorLayout::MonoPolar, SensorLayout::ColourPolar)
        );
        assert!(serde_json::from_str::<SensorLayout>("\"MonoPolar\"").is_err());
        assert_eq!(
            serde_json::to_string(&Channel::Green).ok().as_deref(),
            Some("\"green\"")
        );
    }
}
