//! `RawFrame`: one raw polarisation-mosaic frame as the camera delivers it, validated.
//!
//! Contract: a `RawFrame` that exists has a non-empty size that is a whole number of mosaic tiles
//! (even for mono, multiples of 4 for colour), exactly `width * height` samples, a bit depth in
//! 1..=16 and no sample above `2^bit_depth − 1`. Everything downstream relies on this and never
//! re-checks it. Samples are right-aligned DN (a 12-bit camera's values lie in 0..=4095); data
//! left-aligned in a 16-bit container is 16-bit data as far as this type is concerned.
//!
//! Storage: a frame owns its samples (`RawFrame`, a `Vec<u16>`) or borrows them
//! ([`RawFrameView`], a `&[u16]`: a camera's or numpy's buffer, checked in place, never
//! copied). Both are the same type over a different store and pass the same checks; the
//! processing code reads every frame through a view ([`RawFrame::view`]), so an owned and a
//! borrowed frame of the same samples run the same code and give bit-identical results.

use ellipso_model::mosaic::{MosaicError, SensorLayout};

/// Why raw data cannot be a mosaic frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Bit depth outside 1..=16.
    #[error("bit depth {bit_depth} is not supported (1..=16 bits per sample)")]
    BitDepth {
        /// The rejected bit depth.
        bit_depth: u8,
    },
    /// Width or height not a whole number of mosaic tiles (odd, zero, binned…).
    #[error(transparent)]
    Mosaic(#[from] MosaicError),
    /// The sample buffer does not hold `width * height` samples.
    #[error("frame is {width}×{height} = {expected} samples but {actual} were given")]
    Length {
        /// Frame width.
        width: u32,
        /// Frame height.
        height: u32,
        /// `width * height`.
        expected: usize,
        /// Samples given.
        actual: usize,
    },
    /// A sample above the largest value of the bit depth.
    #[error(
        "sample {value} at (x={x}, y={y}) exceeds the {bit_depth}-bit maximum {max}; \
         {count} samples are out of range (is the bit depth right, or is the data left-aligned?)"
    )]
    ValueAboveBitDepth {
        /// Column of the first offending sample.
        x: u32,
        /// Row of the first offending sample.
        y: u32,
        /// Its value.
        value: u16,
        /// Declared bit depth.
        bit_depth: u8,
        /// `2^bit_depth − 1`.
        max: u16,
        /// Number of offending samples.
        count: usize,
    },
}

/// A validated raw mosaic frame: `width × height` DN samples, row-major, rows growing downward,
/// stored in `D` (owned `Vec<u16>` by default; `&[u16]` for a [`RawFrameView`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RawFrame<D = Vec<u16>> {
    width: u32,
    height: u32,
    bit_depth: u8,
    layout: SensorLayout,
    data_dn: D,
}

/// A validated frame over samples it borrows (a camera's or numpy's buffer): no copy.
pub type RawFrameView<'a> = RawFrame<&'a [u16]>;

impl<D: AsRef<[u16]>> RawFrame<D> {
    /// Validates and wraps raw samples (see the module contract for what is checked).
    pub fn new(
        width: u32,
        height: u32,
        bit_depth: u8,
        layout: SensorLayout,
        data_dn: D,
    ) -> Result<RawFrame<D>, FrameError> {
        if !(1..=16).contains(&bit_depth) {
            return Err(FrameError::BitDepth { bit_depth });
        }
        layout.check_frame_size(width, height)?;
        let expected = width as usize * height as usize;
        let data = data_dn.as_ref();
        if data.len() != expected {
            return Err(FrameError::Length {
                width,
                height,
                expected,
                actual: data.len(),
            });
        }
        let max = full_scale_dn(bit_depth);
        // one pass for the common case (nothing out of range), a second only to name the first
        if let Some(index) = data.iter().position(|&v| v > max) {
            let count = data.iter().filter(|&&v| v > max).count();
            return Err(FrameError::ValueAboveBitDepth {
                x: (index % width as usize) as u32,
                y: (index / width as usize) as u32,
                value: data[index],
                bit_depth,
                max,
                count,
            });
        }
        Ok(RawFrame {
            width,
            height,
            bit_depth,
            layout,
            data_dn,
        })
    }

    /// Width in raw pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in raw pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Bits per sample of the sensor data (not of the container).
    pub fn bit_depth(&self) -> u8 {
        self.bit_depth
    }

    /// The largest DN the bit depth can hold, `2^bit_depth − 1`.
    pub fn full_scale_dn(&self) -> u16 {
        full_scale_dn(self.bit_depth)
    }

    /// The sensor mosaic.
    pub fn layout(&self) -> SensorLayout {
        self.layout
    }

    /// All samples, row-major.
    pub fn data_dn(&self) -> &[u16] {
        self.data_dn.as_ref()
    }

    /// The same frame over borrowed samples (no copy, no re-check).
    pub fn view(&self) -> RawFrameView<'_> {
        RawFrame {
            width: self.width,
            height: self.height,
            bit_depth: self.bit_depth,
            layout: self.layout,
            data_dn: self.data_dn.as_ref(),
        }
    }

    /// Row `y` of samples (`None` past the last row).
    pub fn row(&self, y: u32) -> Option<&[u16]> {
        self.data_dn()
            .chunks_exact(self.width as usize)
            .nth(y as usize)
    }

    /// The sample at `(x, y)`, or `None` outside the frame.
    pub fn get(&self, x: u32, y: u32) -> Option<u16> {
        if x < self.width && y < self.height {
            self.data_dn()
                .get(y as usize * self.width as usize + x as usize)
                .copied()
        } else {
            None
        }
    }

    /// The largest sample in the frame (0 for an all-black frame).
    pub fn max_dn(&self) -> u16 {
        self.data_dn().iter().copied().max().unwrap_or(0)
    }
}

impl RawFrame {
    /// Consumes the frame, returning its samples.
    pub fn into_data(self) -> Vec<u16> {
        self.data_dn
    }
}

/// `2^bit_depth − 1` for `bit_depth` in 1..=16 (saturating to `u16::MAX` above).
pub fn full_scale_dn(bit_depth: u8) -> u16 {
    if bit_depth >= 16 {
        u16::MAX
    } else {
        (1u16 << bit_depth) - 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MONO: SensorLayout = SensorLayout::MonoPolar;

    #[test]
    fn accepts_a_valid_frame() {
        let f = RawFrame::new(4, 2, 12, MONO, vec![0, 1, 2, 3, 4, 5, 6, 4095]).expect("valid");
        assert_eq!((f.width(), f.height(), f.bit_depth()), (4, 2, 12));
        assert_eq!(f.full_scale_dn(), 4095);
        assert_eq!(f.get(3, 1), Some(4095));
        assert_eq!(f.get(4, 0), None);
        assert_eq!(f.row(1), Some(&[4, 5, 6, 4095][..]));
        assert_eq!(f.max_dn(), 4095);
    }

    #[test]
    fn rejects_odd_and_empty_sizes() {
        let err = RawFrame::new(3, 2, 12, MONO, vec![0; 6]).unwrap_err();
        assert!(matches!(err, FrameError::Mosaic(_)), "{err}");
        assert!(err.to_string().contains("3×2"), "{err}");
        assert!(RawFrame::new(0, 0, 12, MONO, vec![]).is_err());
        assert!(RawFrame::new(2, 3, 12, MONO, vec![0; 6]).is_err());
        // colour needs whole 4×4 tiles
        assert!(RawFrame::new(6, 4, 12, SensorLayout::ColourPolar, vec![0; 24]).is_err());
        assert!(RawFrame::new(8, 4, 12, SensorLayout::ColourPolar, vec![0; 32]).is_ok());
    }

    #[test]
    fn rejects_wrong_length() {
        let err = RawFrame::new(4, 2, 12, MONO, vec![0; 7]).unwrap_err();
        assert_eq!(
            err,
            FrameError::Length {
                width: 4,
                height: 2,
                expected: 8,
                actual: 7
            }
        );
    }

    #[test]
    fn rejects_values_above_bit_depth_naming_the_first() {
        let mut data = vec![0u16; 8];
        data[5] = 4096;
        data[7] = 5000;
        let err = RawFrame::new(4, 2, 12, MONO, data).unwrap_err();
        assert_eq!(
            err,
            FrameError::ValueAboveBitDepth {
                x: 1,
                y: 1,
                value: 4096,
                bit_depth: 12,
                max: 4095,
                count: 2
            }
        );
        assert!(err.to_string().contains("left-aligned"));
    }

    #[test]
    fn rejects_bad_bit_depths() {
        assert!(RawFrame::new(2, 2, 0, MONO, vec![0; 4]).is_err());
        assert!(RawFrame::new(2, 2, 17, MONO, vec![0; 4]).is_err());
        assert!(RawFrame::new(2, 2, 16, MONO, vec![u16::MAX; 4]).is_ok());
        assert_eq!(full_scale_dn(8), 255);
        assert_eq!(full_scale_dn(16), 65535);
    }
}
