//! AprilTag detection (the AprilRobotics C library through the `apriltag` crate, vendored and
//! statically linked): an 8-bit grayscale image in, tag detections out.
//!
//! Contract:
//! - **Pixel convention.** AprilTag puts pixel centres at (i + 0.5, j + 0.5); ellipso (like
//!   OpenCV and [`ellipso_model::camera`]) puts them at (i, j). Every corner and centre returned
//!   here has had **0.5 px subtracted** in x and y, so it can go straight into the PnP. Without
//!   the shift a 600 mm pose is biased ≈0.09 mm sideways (see docs/pose.md §1 "Conventions").
//! - **Corner order** is the library's: for a tag seen upright, corner 0 is bottom-left, then
//!   bottom-right, top-right, top-left — counter-clockwise on screen (y down). The corners are
//!   those of the tag's outer black square. [`super::board::BoardCorners`] uses the same order.
//! - Decimation affects quad finding only; decoding and edge refinement use full resolution.
//!
//! Detection is slow on 5 MP frames (≈5 ms clean, ≈75–150 ms cluttered at decimate 2): run it
//! off the capture path.

use apriltag::{DetectorBuilder, Family, Image};

/// A tag family supported by the AprilTag library.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TagFamily {
    /// tag36h11 (587 codes; the default and the most robust to false positives).
    Tag36h11,
    /// tag25h9.
    Tag25h9,
    /// tag16h5 (prone to false positives).
    Tag16h5,
    /// tagStandard41h12 (recommended by the AprilTag 3 README).
    TagStandard41h12,
    /// tagStandard52h13.
    TagStandard52h13,
    /// tagCircle21h7.
    TagCircle21h7,
    /// tagCircle49h12.
    TagCircle49h12,
    /// tagCustom48h12.
    TagCustom48h12,
}

impl TagFamily {
    /// The library's name of the family, e.g. `"tag36h11"`.
    pub fn name(self) -> &'static str {
        match self {
            TagFamily::Tag36h11 => "tag36h11",
            TagFamily::Tag25h9 => "tag25h9",
            TagFamily::Tag16h5 => "tag16h5",
            TagFamily::TagStandard41h12 => "tagStandard41h12",
            TagFamily::TagStandard52h13 => "tagStandard52h13",
            TagFamily::TagCircle21h7 => "tagCircle21h7",
            TagFamily::TagCircle49h12 => "tagCircle49h12",
            TagFamily::TagCustom48h12 => "tagCustom48h12",
        }
    }

    fn library_family(self) -> Family {
        match self {
            TagFamily::Tag36h11 => Family::tag_36h11(),
            TagFamily::Tag25h9 => Family::tag_25h9(),
            TagFamily::Tag16h5 => Family::tag_16h5(),
            TagFamily::TagStandard41h12 => Family::tag_standard_41h12(),
            TagFamily::TagStandard52h13 => Family::tag_standard_52h13(),
            TagFamily::TagCircle21h7 => Family::tag_circle_21h7(),
            TagFamily::TagCircle49h12 => Family::tag_circle_49h12(),
            TagFamily::TagCustom48h12 => Family::tag_custom_48h12(),
        }
    }
}

/// Detector settings. Defaults are the library's except `max_hamming`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorConfig {
    /// Tag family to look for. Default tag36h11.
    pub family: TagFamily,
    /// Most bit errors corrected when decoding. Default 1: 2+ raises false positives sharply
    /// (AprilTag issues #54, #57) and costs memory for the lookup table.
    pub max_hamming: usize,
    /// Quad-detection decimation factor (≥ 1). Default 2.0.
    pub decimation: f32,
    /// Worker threads (≥ 1). Default 1.
    pub threads: u8,
    /// Gaussian blur σ (px) before quad detection; 0 = none. Default 0.
    pub blur_sigma: f32,
    /// Snap quad edges to strong gradients at full resolution. Default true.
    pub refine_edges: bool,
    /// Sharpening of the decoded image. Default 0.25.
    pub decode_sharpening: f64,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        DetectorConfig {
            family: TagFamily::Tag36h11,
            max_hamming: 1,
            decimation: 2.0,
            threads: 1,
            blur_sigma: 0.0,
            refine_edges: true,
            decode_sharpening: 0.25,
        }
    }
}

/// The fewest pixels a side of an image must have for any tag to fit in it: the smallest family
/// (tag16h5) is 8 cells across with its white border, and the decoder samples each cell at
/// least once, so a tag under 8 px across cannot be decoded. An image narrower than that holds
/// no tag; it is refused before the library sees it (the library's quad search itself crashes
/// on images under 3 px a side after decimation, see [`quad_image_side`]).
pub const MIN_TAG_SIDE_PX: usize = 8;

/// The smallest side of the decimated image the library's quad search handles: its gradient
/// clustering splits rows `1 .. side − 1` into tasks and reads the first task's result, so it
/// needs at least one such row (side ≥ 3); below that it reads unallocated memory.
const MIN_QUAD_IMAGE_SIDE_PX: usize = 3;

/// A side of the image the library's quad search works on, as `image_u8_decimate` computes it:
/// `side / 3 · 2` at decimation 1.5, `1 + (side − 1) / ⌊decimation⌋` above 1, the side itself
/// otherwise.
fn quad_image_side(side: usize, decimation: f32) -> usize {
    if decimation == 1.5 {
        side / 3 * 2
    } else if decimation > 1.0 {
        1 + (side - 1) / (decimation as usize).max(1)
    } else {
        side
    }
}

/// Why detection could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DetectError {
    /// A setting is out of range.
    #[error("invalid detector setting {name} = {value}")]
    InvalidSetting { name: &'static str, value: String },
    /// The library refused to create the detector.
    #[error("AprilTag detector could not be created: {0}")]
    Create(String),
    /// Buffer length does not match width × height.
    #[error("grayscale buffer has {len} bytes, expected {width}×{height} = {expected}")]
    BufferSize {
        len: usize,
        width: usize,
        height: usize,
        expected: usize,
    },
    /// The image is empty or too large for the library (dimensions must fit in i32).
    #[error("image size {width}×{height} is not supported")]
    ImageSize { width: usize, height: usize },
    /// The image is too small to hold a tag (and too small for the library's quad search,
    /// which reads past its buffers on images under 3 px a side after decimation).
    #[error(
        "the image is {width}×{height} px: too small to hold a tag (a tag needs at least \
         {MIN_TAG_SIDE_PX} px a side); capture at a higher --resolution"
    )]
    TooSmall { width: usize, height: usize },
    /// The library could not allocate the image.
    #[error("AprilTag image allocation failed: {0}")]
    Allocate(String),
}

/// One detected tag, in ellipso's pixel convention (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TagDetection {
    /// Family of the tag.
    pub family: TagFamily,
    /// Tag id within the family.
    pub id: u32,
    /// Bits corrected to decode it.
    pub hamming: u32,
    /// The library's decision margin (mean intensity margin of the bits; higher is surer).
    pub decision_margin: f32,
    /// Corners of the outer black square, px, integer-centre convention, library order.
    pub corners_px: [[f64; 2]; 4],
    /// Tag centre, px, integer-centre convention.
    pub centre_px: [f64; 2],
}

/// A configured AprilTag detector. Not thread-safe: use one per thread.
pub struct TagDetector {
    inner: apriltag::Detector,
    config: DetectorConfig,
    /// The quad decimation in use ([`TagDetector::set_decimation`]; `config.decimation` at
    /// first).
    decimation: f32,
}

impl std::fmt::Debug for TagDetector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TagDetector")
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

impl TagDetector {
    /// Creates a detector; errors name the invalid setting.
    pub fn new(config: DetectorConfig) -> Result<Self, DetectError> {
        if !(config.decimation >= 1.0 && config.decimation.is_finite()) {
            return Err(DetectError::InvalidSetting {
                name: "decimation",
                value: config.decimation.to_string(),
            });
        }
        if config.threads == 0 {
            return Err(DetectError::InvalidSetting {
                name: "threads",
                value: "0".into(),
            });
        }
        if !(config.blur_sigma >= 0.0 && config.blur_sigma.is_finite()) {
            return Err(DetectError::InvalidSetting {
                name: "blur_sigma",
                value: config.blur_sigma.to_string(),
            });
        }
        if config.max_hamming > 3 {
            return Err(DetectError::InvalidSetting {
                name: "max_hamming",
                value: config.max_hamming.to_string(),
            });
        }
        if !config.decode_sharpening.is_finite() {
            return Err(DetectError::InvalidSetting {
                name: "decode_sharpening",
                value: config.decode_sharpening.to_string(),
            });
        }
        let mut inner = DetectorBuilder::new()
            .add_family_bits(config.family.library_family(), config.max_hamming)
            .build()
            .map_err(|e| DetectError::Create(e.to_string()))?;
        inner.set_thread_number(config.threads);
        inner.set_decimation(config.decimation);
        inner.set_sigma(config.blur_sigma);
        inner.set_refine_edges(config.refine_edges);
        inner.set_shapening(config.decode_sharpening);
        Ok(TagDetector {
            inner,
            decimation: config.decimation,
            config,
        })
    }

    /// The settings this detector was built with.
    pub fn config(&self) -> &DetectorConfig {
        &self.config
    }

    /// Sets the quad-detection decimation (≥ 1 and finite; anything else is ignored) for the
    /// next detections: an image of a different resolution may need another.
    pub fn set_decimation(&mut self, decimation: f32) {
        if decimation >= 1.0 && decimation.is_finite() && decimation != self.decimation {
            self.inner.set_decimation(decimation);
            self.decimation = decimation;
        }
    }

    /// Detects tags in a row-major 8-bit grayscale image without padding (`gray.len() == w·h`).
    pub fn detect(
        &mut self,
        gray: &[u8],
        width: usize,
        height: usize,
    ) -> Result<Vec<TagDetection>, DetectError> {
        if width == 0 || height == 0 || width > i32::MAX as usize || height > i32::MAX as usize {
            return Err(DetectError::ImageSize { width, height });
        }
        let expected = width
            .checked_mul(height)
            .ok_or(DetectError::ImageSize { width, height })?;
        if gray.len() != expected {
            return Err(DetectError::BufferSize {
                len: gray.len(),
                width,
                height,
                expected,
            });
        }
        let decimation = self.decimation;
        if width.min(height) < MIN_TAG_SIDE_PX
            || quad_image_side(width, decimation).min(quad_image_side(height, decimation))
                < MIN_QUAD_IMAGE_SIDE_PX
        {
            return Err(DetectError::TooSmall { width, height });
        }
        let mut image =
            Image::zeros_with_alignment(width, height, apriltag::image_buf::DEFAULT_ALIGNMENT_U8)
                .map_err(|e| DetectError::Allocate(e.to_string()))?;
        // Rows in the library's image are padded to its alignment: copy row by row.
        let stride = image.stride();
        let buf = image.as_slice_mut();
        for (y, row) in gray.chunks_exact(width).enumerate() {
            buf[y * stride..y * stride + width].copy_from_slice(row);
        }
        let shift = |[x, y]: [f64; 2]| [x - 0.5, y - 0.5];
        Ok(self
            .inner
            .detect(&image)
            .into_iter()
            .map(|d| TagDetection {
                family: self.config.family,
                // Ids are < 2^16 in every family; saturate rather than wrap if not.
                id: u32::try_from(d.id()).unwrap_or(u32::MAX),
                hamming: u32::try_from(d.hamming()).unwrap_or(u32::MAX),
                decision_margin: d.decision_margin(),
                corners_px: d.corners().map(shift),
                centre_px: shift(d.center()),
            })
            .collect())
    }
}

#[cfg(test)]
pub(crate) mod tests;
