//! Reading one raw mosaic frame — PNG (8/16-bit grey), TIFF (8/16/32-bit unsigned or 32/64-bit
//! float grey) or NumPy `.npy` (u1/u2/u4/f4/f8, 2-D) — settling its bit depth and its layout.
//!
//! Contract: returns a validated [`RawFrame`] or an error whose message names what is wrong with
//! the file (unknown format, not single-channel, odd size, values above the bit depth, negative
//! or non-finite floats…) in one line, without the path (the caller prefixes it).
//! - Format: from the file's first bytes, not its name.
//! - Bit depth: the flag wins; otherwise 8 for 8-bit containers, **12 for 16-bit ones** (the
//!   IMX250 ADC depth of Mono12/Polarized12), 16 for floats. Integer containers hold DN as the
//!   camera delivered them. Floats are read as *normalised* (full scale 1.0) when every value is
//!   in [0, 1], else as DN; either way rounded to whole DN at the bit depth (the processing is
//!   integer-DN from the sensor on). The maximum value only ever produces warnings or hints,
//!   never a silent change of depth.
//! - Layout: `--layout` wins; without it, a frame inside a session takes the session manifest's,
//!   and any other frame is examined ([`crate::layout::detect`]): a Bayer pattern of
//!   polariser blocks is read as colour, none as mono, and an unclear one is refused — a colour
//!   frame is never silently read as mono.

use std::path::Path;

use ellipso_model::mosaic::SensorLayout;

use crate::layout::{Detection, detect};
use crate::{FrameError, RawFrame, frame::full_scale_dn};

/// Bit depth assumed for 16-bit containers when `--bit-depth` is not given.
pub(super) const DEFAULT_BIT_DEPTH_16_BIT_CONTAINER: u8 = 12;
/// Bit depths a camera can deliver and `--bit-depth` accepts.
pub(super) const BIT_DEPTHS: [u8; 4] = [8, 10, 12, 16];

/// The 8 bytes every PNG file starts with.
const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";

/// A frame read from disk, with how its bit depth and layout were decided.
#[derive(Debug)]
pub(super) struct Loaded {
    pub frame: RawFrame,
    /// The container: format and sample type (`PNG 16-bit`, `TIFF f32`, `npy <u2`, …).
    pub container: String,
    /// Bits per integer sample of the container (8, 16, 32), or 32/64 for floats.
    pub container_bits: u8,
    /// Why the frame has its bit depth (`--bit-depth`, or which default).
    pub bit_depth_source: &'static str,
    /// Why the frame has its layout (`--layout`, the session manifest, or detection).
    pub layout_source: String,
    /// Non-fatal doubts about the data, for the user.
    pub warnings: Vec<String>,
}

/// Samples as decoded from a container, before any bit depth is applied.
enum Samples {
    /// Integer DN.
    Int(Vec<u32>),
    /// Floats (normalised or DN, settled below).
    Float(Vec<f64>),
}

/// A decoded container.
struct Decoded {
    width: u32,
    height: u32,
    container: String,
    bits: u8,
    samples: Samples,
}

fn decode(bytes: &[u8]) -> Result<Decoded, String> {
    if bytes.starts_with(PNG_SIGNATURE) {
        return decode_png(bytes);
    }
    if bytes.starts_with(b"II*\0") || bytes.starts_with(b"MM\0*") {
        return decode_tiff(bytes);
    }
    if bytes.starts_with(b"\x93NUMPY") {
        return decode_npy(bytes);
    }
    Err(match image::guess_format(bytes) {
        Ok(f) => format!(
            "{f:?} is not a raw mosaic container; give a grey PNG, TIFF or .npy exactly as the \
             camera delivered it"
        ),
        Err(_) => "not a PNG, TIFF or .npy file (no known signature); raw frames are grey \
                   PNG/TIFF or .npy mosaics"
            .into(),
    })
}

fn decode_png(bytes: &[u8]) -> Result<Decoded, String> {
    let decoded = image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
        .map_err(|e| format!("corrupt or truncated PNG: {e}"))?;
    let (width, height) = (decoded.width(), decoded.height());
    let (bits, data): (u8, Vec<u32>) = match decoded {
        image::DynamicImage::ImageLuma8(img) => {
            (8, img.into_raw().into_iter().map(u32::from).collect())
        }
        image::DynamicImage::ImageLuma16(img) => {
            (16, img.into_raw().into_iter().map(u32::from).collect())
        }
        other => {
            return Err(format!(
                "{:?} PNG, but a raw mosaic frame is single-channel grey (8 or 16 bit) \
                 exactly as the camera delivered it, not a demosaiced or colour image",
                other.color()
            ));
        }
    };
    Ok(Decoded {
        width,
        height,
        container: format!("PNG {bits}-bit"),
        bits,
        samples: Samples::Int(data),
    })
}

fn decode_tiff(bytes: &[u8]) -> Result<Decoded, String> {
    use tiff::decoder::{Decoder, DecodingResult};
    let mut decoder = Decoder::new(std::io::Cursor::new(bytes))
        .map_err(|e| format!("corrupt or truncated TIFF: {e}"))?;
    let colour = decoder
        .colortype()
        .map_err(|e| format!("corrupt TIFF: {e}"))?;
    if !matches!(colour, tiff::ColorType::Gray(_)) {
        return Err(format!(
            "{colour:?} TIFF, but a raw mosaic frame is single-channel grey exactly as the \
             camera delivered it, not a demosaiced or colour image"
        ));
    }
    let (width, height) = decoder
        .dimensions()
        .map_err(|e| format!("corrupt TIFF: {e}"))?;
    let image = decoder
        .read_image()
        .map_err(|e| format!("corrupt, truncated or unsupported TIFF: {e}"))?;
    let (container, bits, samples) = match image {
        DecodingResult::U8(v) => (
            "TIFF 8-bit",
            8,
            Samples::Int(v.into_iter().map(u32::from).collect()),
        ),
        DecodingResult::U16(v) => (
            "TIFF 16-bit",
            16,
            Samples::Int(v.into_iter().map(u32::from).collect()),
        ),
        DecodingResult::U32(v) => ("TIFF 32-bit", 32, Samples::Int(v)),
        DecodingResult::F32(v) => (
            "TIFF f32",
            32,
            Samples::Float(v.into_iter().map(f64::from).collect()),
        ),
        DecodingResult::F64(v) => ("TIFF f64", 64, Samples::Float(v)),
        other => {
            return Err(format!(
                "TIFF samples of type {} are not supported (unsigned 8/16/32-bit or 32/64-bit \
                 float)",
                match other {
                    DecodingResult::I8(_) => "i8",
                    DecodingResult::I16(_) => "i16",
                    DecodingResult::I32(_) => "i32",
                    DecodingResult::I64(_) => "i64",
                    _ => "u64",
                }
            ));
        }
    };
    Ok(Decoded {
        width,
        height,
        container: container.into(),
        bits,
        samples,
    })
}

fn decode_npy(bytes: &[u8]) -> Result<Decoded, String> {
    let a = ellipso_report::npy::decode(bytes)?;
    let [height, width] = a.shape[..] else {
        return Err(format!(
            ".npy array of shape {:?}, but a raw mosaic frame is 2-D (rows, columns)",
            a.shape
        ));
    };
    let too_big = |n: usize| u32::try_from(n).map_err(|_| format!("{n} px is too large"));
    let bits = match a.descr.trim_start_matches(['<', '>', '|', '=']) {
        "u1" => 8,
        "u2" => 16,
        "u4" | "f4" => 32,
        _ => 64,
    };
    let container = format!("npy {}", a.descr);
    let samples = if a.is_float() {
        Samples::Float(a.data)
    } else {
        Samples::Int(a.data.into_iter().map(|v| v as u32).collect())
    };
    Ok(Decoded {
        width: too_big(width)?,
        height: too_big(height)?,
        container,
        bits,
        samples,
    })
}

/// Float samples → whole DN at `bits` (module contract), or why not.
fn floats_to_dn(values: &[f64], bits: u8) -> Result<(Vec<u16>, &'static str), String> {
    let bad = values
        .iter()
        .filter(|v| !v.is_finite() || **v < 0.0)
        .count();
    if bad > 0 {
        return Err(format!(
            "{bad} float samples are negative, NaN or infinite; a raw mosaic holds light \
             (≥ 0) in every pixel"
        ));
    }
    let full = f64::from(full_scale_dn(bits));
    let max = values.iter().copied().fold(0.0, f64::max);
    let (scale, how) = if max <= 1.0 {
        (full, "normalised floats (full scale 1.0)")
    } else {
        (1.0, "floats in DN")
    };
    if max * scale > full + 0.5 {
        return Err(format!(
            "largest float sample {max} DN is above the {bits}-bit full scale {full}; pass \
             --bit-depth 16 or normalise the frame to [0, 1]"
        ));
    }
    let dn = values
        .iter()
        .map(|v| (v * scale).round().min(full) as u16)
        .collect();
    Ok((dn, how))
}

/// Reads `path` as a raw mosaic; `layout` is `--layout`, `bit_depth` is `--bit-depth`.
pub(super) fn load_frame(
    path: &Path,
    layout: Option<SensorLayout>,
    bit_depth: Option<u8>,
) -> Result<Loaded, String> {
    let bytes = ellipso_model::file_io::read_bounded(path, ellipso_model::file_io::caps::FRAME)
        .map_err(|e| format!("cannot open: {e}"))?;
    let decoded = decode(&bytes)?;
    let (width, height) = (decoded.width, decoded.height);
    let mut warnings = Vec::new();
    let (bits, bit_depth_source, data): (u8, &'static str, Vec<u16>) =
        match (&decoded.samples, bit_depth) {
            (Samples::Float(v), b) => {
                let bits = b.unwrap_or(16);
                let (dn, how) = floats_to_dn(v, bits)?;
                warnings.push(format!(
                    "{} read as {how}, rounded to whole DN at {bits} bits",
                    decoded.container
                ));
                let source = if b.is_some() {
                    "--bit-depth"
                } else {
                    "default for float samples"
                };
                (bits, source, dn)
            }
            (Samples::Int(_), Some(b)) if decoded.bits == 8 && b > 8 => {
                return Err(format!(
                    "{} but --bit-depth {b}: an 8-bit container can only hold 8-bit data",
                    decoded.container
                ));
            }
            (Samples::Int(v), b) => {
                let max = v.iter().copied().max().unwrap_or(0);
                if max > u32::from(u16::MAX) {
                    return Err(format!(
                        "largest sample {max} does not fit 16 bits; raw IMX250 data has at most \
                         16 bits per sample"
                    ));
                }
                let data = v.iter().map(|&x| x as u16).collect();
                match (b, decoded.bits) {
                    (Some(b), _) => (b, "--bit-depth", data),
                    (None, 8) => (8, "default for 8-bit containers", data),
                    (None, _) => (
                        DEFAULT_BIT_DEPTH_16_BIT_CONTAINER,
                        "default for 16-bit containers (12-bit ADC)",
                        data,
                    ),
                }
            }
        };
    let (layout, layout_source) = settle_layout(path, layout, width, height, &data)?;
    let max_dn = data.iter().copied().max().unwrap_or(0);
    let hint = above_depth_hint(&data, bits, max_dn);
    let frame = RawFrame::new(width, height, bits, layout, data).map_err(|e| match e {
        FrameError::ValueAboveBitDepth { .. } => format!("{e}; {hint}"),
        FrameError::Mosaic(_) => format!("{e}; process full-resolution raw frames only"),
        _ => e.to_string(),
    })?;
    if let Some(fits) = BIT_DEPTHS
        .iter()
        .copied()
        .find(|&b| max_dn <= full_scale_dn(b))
        .filter(|&b| b < bits && max_dn > 0 && matches!(decoded.samples, Samples::Int(_)))
    {
        warnings.push(format!(
            "largest value {max_dn} fits in {fits} bits but the frame is taken as {bits}-bit \
             ({bit_depth_source}); if the camera delivered {fits}-bit data pass --bit-depth {fits} \
             (normalisation and the saturation level depend on it)"
        ));
    }
    Ok(Loaded {
        frame,
        container: decoded.container,
        container_bits: decoded.bits,
        bit_depth_source,
        layout_source,
        warnings,
    })
}

/// The layout of a frame given without `--layout` (module contract).
fn settle_layout(
    path: &Path,
    layout: Option<SensorLayout>,
    width: u32,
    height: u32,
    data: &[u16],
) -> Result<(SensorLayout, String), String> {
    if let Some(l) = layout {
        return Ok((l, "--layout".into()));
    }
    let session = path
        .ancestors()
        .skip(1)
        .take(2)
        .find(|d| d.join(ellipso_session::paths::MANIFEST).is_file());
    if let Some(dir) = session {
        let manifest = std::fs::read(dir.join(ellipso_session::paths::MANIFEST))
            .ok()
            .and_then(|b| serde_json::from_slice::<ellipso_session::manifest::Manifest>(&b).ok());
        if let Some(l) = manifest.map(|m| m.sensor.layout) {
            return Ok((l, format!("the session manifest in {}", dir.display())));
        }
    }
    let e = detect(width as usize, height as usize, data);
    let numbers = format!(
        "red/blue vs green block difference {:.3}, green vs green {:.3} (90th percentile {:.3} \
         vs {:.3}), over {} flat tiles",
        e.rg, e.gg, e.rg_upper, e.gg_upper, e.tiles
    );
    match e.detection {
        Detection::Mono => Ok((
            SensorLayout::MonoPolar,
            format!("detected: no colour filter pattern ({numbers}); --layout overrides"),
        )),
        Detection::Colour => Ok((
            SensorLayout::ColourPolar,
            format!("detected: Bayer pattern of polariser blocks ({numbers}); --layout overrides"),
        )),
        Detection::Unsure => Err(format!(
            "cannot tell a mono (IMX250MZR) from a colour (IMX250MYR) mosaic ({numbers}); pass \
             --layout mono or --layout colour"
        )),
    }
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

    #[test]
    fn floats_are_normalised_or_dn_and_bad_ones_named() {
        let (dn, how) = floats_to_dn(&[0.0, 0.5, 1.0], 12).unwrap();
        assert_eq!(dn, vec![0, 2048, 4095]);
        assert!(how.contains("normalised"));
        let (dn, how) = floats_to_dn(&[3.0, 4095.0], 12).unwrap();
        assert_eq!((dn, how), (vec![3, 4095], "floats in DN"));
        assert!(floats_to_dn(&[5000.0], 12).unwrap_err().contains("above"));
        assert!(
            floats_to_dn(&[f64::NAN, -1.0], 16)
                .unwrap_err()
                .contains("2 float")
        );
    }
}
