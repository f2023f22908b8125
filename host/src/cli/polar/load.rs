//! Reading one raw mosaic frame from a grayscale PNG, and settling its bit depth.
//!
//! Contract: returns a validated [`RawFrame`] or an error whose message names what is wrong with
//! the file (not a PNG, not grayscale, odd size, values above the bit depth…) in one line, without
//! the path (the caller prefixes it). Bit depth: the flag wins; otherwise 8 for 8-bit PNGs and
//! **12 for 16-bit PNGs** (the IMX250 ADC depth used by Mono12/Polarized12 formats). The maximum
//! value only ever produces warnings or hints, never a silent change of depth.

use std::path::Path;

use ellipso_model::mosaic::SensorLayout;

use ellipso_polar::{FrameError, RawFrame, frame::full_scale_dn};

/// Bit depth assumed for 16-bit PNG containers when `--bit-depth` is not given.
pub(super) const DEFAULT_BIT_DEPTH_16_BIT_CONTAINER: u8 = 12;
/// Bit depths a camera can deliver and `--bit-depth` accepts.
pub(super) const BIT_DEPTHS: [u8; 4] = [8, 10, 12, 16];

/// The 8 bytes every PNG file starts with.
const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";

/// A frame read from disk, with how its bit depth was decided.
#[derive(Debug)]
pub(super) struct Loaded {
    pub frame: RawFrame,
    /// Bits per sample of the PNG (8 or 16).
    pub container_bits: u8,
    /// Why the frame has its bit depth (`--bit-depth`, or which default).
    pub bit_depth_source: &'static str,
    /// Non-fatal doubts about the data, for the user.
    pub warnings: Vec<String>,
}

/// Reads `path` as a raw `layout` mosaic; `bit_depth` is the `--bit-depth` flag.
pub(super) fn load_frame(
    path: &Path,
    layout: SensorLayout,
    bit_depth: Option<u8>,
) -> Result<Loaded, String> {
    let bytes = ellipso_model::file_io::read_bounded(path, ellipso_model::file_io::caps::FRAME)
        .map_err(|e| format!("cannot open: {e}"))?;
    if !bytes.starts_with(PNG_SIGNATURE) {
        return Err(match image::guess_format(&bytes) {
            Ok(f) => format!("not a PNG file (looks like {f:?}); raw frames are grayscale PNGs"),
            Err(_) => "not a PNG file (no PNG signature); raw frames are grayscale PNGs".into(),
        });
    }
    let decoded = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
        .map_err(|e| format!("corrupt or truncated PNG: {e}"))?;
    let (width, height) = (decoded.width(), decoded.height());
    let (container_bits, data): (u8, Vec<u16>) = match decoded {
        image::DynamicImage::ImageLuma8(img) => {
            (8, img.into_raw().into_iter().map(u16::from).collect())
        }
        image::DynamicImage::ImageLuma16(img) => (16, img.into_raw()),
        other => {
            return Err(format!(
                "{:?} PNG, but a raw mosaic frame is single-channel grayscale (8 or 16 bit) \
                 exactly as the camera delivered it, not a demosaiced or colour image",
                other.color()
            ));
        }
    };
    let (bits, bit_depth_source) = match (bit_depth, container_bits) {
        (Some(b), 8) if b > 8 => {
            return Err(format!(
                "8-bit PNG but --bit-depth {b}: an 8-bit container can only hold 8-bit data"
            ));
        }
        (Some(b), _) => (b, "--bit-depth"),
        (None, 8) => (8, "default for 8-bit PNG"),
        (None, _) => (
            DEFAULT_BIT_DEPTH_16_BIT_CONTAINER,
            "default for 16-bit PNG (12-bit ADC)",
        ),
    };
    let max_dn = data.iter().copied().max().unwrap_or(0);
    let hint = above_depth_hint(&data, bits, max_dn);
    let frame = RawFrame::new(width, height, bits, layout, data).map_err(|e| match e {
        FrameError::ValueAboveBitDepth { .. } => format!("{e}; {hint}"),
        FrameError::Mosaic(_) => format!("{e}; process full-resolution raw frames only"),
        _ => e.to_string(),
    })?;
    let mut warnings = Vec::new();
    if let Some(fits) = BIT_DEPTHS
        .iter()
        .copied()
        .find(|&b| max_dn <= full_scale_dn(b))
        .filter(|&b| b < bits && max_dn > 0)
    {
        warnings.push(format!(
            "largest value {max_dn} fits in {fits} bits but the frame is taken as {bits}-bit \
             ({bit_depth_source}); if the camera delivered {fits}-bit data pass --bit-depth {fits} \
             (normalisation and the saturation level depend on it)"
        ));
    }
    Ok(Loaded {
        frame,
        container_bits,
        bit_depth_source,
        warnings,
    })
}

/// Advice for data above the declared depth: left-aligned data or a deeper ADC.
fn above_depth_hint(data: &[u16], bits: u8, max_dn: u16) -> String {
    if bits >= 16 || max_dn <= full_scale_dn(bits) {
        return String::new();
    }
    let shift = 16 - u32::from(bits);
    let step = 1u16 << shift;
    if data.iter().all(|v| v % step == 0) {
        format!(
            "all values are multiples of {step}: the {bits}-bit data looks left-aligned in the \
             16-bit container; pass --bit-depth 16"
        )
    } else {
        "pass --bit-depth 16 if the camera delivered 16-bit data".into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hint_detects_left_aligned_twelve_bit_data() {
        let data = [4096u16, 65520, 16];
        assert!(above_depth_hint(&data, 12, 65520).contains("left-aligned"));
        assert!(above_depth_hint(&[5000, 3], 12, 5000).contains("--bit-depth 16"));
        assert!(above_depth_hint(&[4000], 12, 4000).is_empty());
    }
}
