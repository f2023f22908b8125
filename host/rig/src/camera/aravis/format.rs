//! GigE Vision pixel formats: PFNC codes and GenICam `PixelFormat` names ↔ [`RawEncoding`].
//!
//! Contract:
//! - [`encoding_of_pfnc`] decodes the pixel format a GVSP leader carries (the buffer's own format,
//!   which is what the bytes really are) into a [`RawEncoding`]; anything else is `None` and the
//!   frame is counted as a failure by the backend.
//! - [`encoding_of_name`] maps a GenICam `PixelFormat` entry name, including the polarisation
//!   cameras' names for the raw mosaic (`Polarized8`, `Polarized12p`, `Polarized16`,
//!   `PolarizeMono8` …), onto the same encodings.
//! - [`refused_name`] explains why on-camera processed polarisation formats
//!   (`PolarizedAngles_*`, `PolarizedStokes_*`, `PolarizedDolp*`, `PolarizedAolp*`) are refused:
//!   ellipso needs the raw 2×2 mosaic, and those formats re-sample or combine it on the camera.
//! - [`preferred_names`] lists, per requested bit depth, the names tried in order (raw-mosaic
//!   polarisation names first, then the plain mono names).

use crate::camera::unpack::RawEncoding;

/// PFNC `Mono8`.
pub const PFNC_MONO8: u32 = 0x0108_0001;
/// PFNC `Mono10` (unpacked, 16-bit container).
pub const PFNC_MONO10: u32 = 0x0110_0003;
/// PFNC `Mono12` (unpacked, 16-bit container).
pub const PFNC_MONO12: u32 = 0x0110_0005;
/// GigE Vision `Mono12Packed`.
pub const PFNC_MONO12_PACKED: u32 = 0x010c_0006;
/// PFNC `Mono12p`.
pub const PFNC_MONO12P: u32 = 0x010c_0047;
/// PFNC `Mono16`.
pub const PFNC_MONO16: u32 = 0x0110_0007;

/// The encoding of a PFNC pixel-format code, if ellipso reads it.
pub fn encoding_of_pfnc(code: u32) -> Option<RawEncoding> {
    match code {
        PFNC_MONO8 => Some(RawEncoding::Mono8),
        PFNC_MONO10 => Some(RawEncoding::Mono10),
        PFNC_MONO12 => Some(RawEncoding::Mono12),
        PFNC_MONO12_PACKED => Some(RawEncoding::Mono12Packed),
        PFNC_MONO12P => Some(RawEncoding::Mono12p),
        PFNC_MONO16 => Some(RawEncoding::Mono16),
        _ => None,
    }
}

/// The encoding behind a GenICam `PixelFormat` entry name, if it is a raw mono / mosaic format.
pub fn encoding_of_name(name: &str) -> Option<RawEncoding> {
    match name {
        "Mono8" | "Polarized8" | "PolarizeMono8" => Some(RawEncoding::Mono8),
        "Mono10" | "Polarized10" | "PolarizeMono10" => Some(RawEncoding::Mono10),
        "Mono12" | "Polarized12" | "PolarizeMono12" => Some(RawEncoding::Mono12),
        "Mono12Packed" | "PolarizeMono12Packed" => Some(RawEncoding::Mono12Packed),
        "Mono12p" | "Polarized12p" | "PolarizeMono12p" => Some(RawEncoding::Mono12p),
        "Mono16" | "Polarized16" | "PolarizeMono16" => Some(RawEncoding::Mono16),
        _ => None,
    }
}

/// Why a camera-processed polarisation format is refused, or `None` if `name` is not one.
pub fn refused_name(name: &str) -> Option<String> {
    let processed = [
        "PolarizedAngles_",
        "PolarizedStokes",
        "PolarizedDolp",
        "PolarizedAolp",
    ];
    processed.iter().any(|p| name.starts_with(p)).then(|| {
        format!(
            "pixel format {name} is processed on the camera (angle channels / Stokes / DoLP at \
             half resolution); ellipso needs the raw 2×2 mosaic: use Polarized8/12p/16 or Mono*"
        )
    })
}

/// GenICam names to try for a requested bit depth, best first.
pub fn preferred_names(bit_depth: u8) -> &'static [&'static str] {
    match bit_depth {
        8 => &["Polarized8", "PolarizeMono8", "Mono8"],
        10 => &["Polarized10", "PolarizeMono10", "Mono10"],
        12 => &[
            "Polarized12p",
            "PolarizeMono12p",
            "Mono12p",
            "Mono12Packed",
            "PolarizeMono12Packed",
            "Polarized12",
            "PolarizeMono12",
            "Mono12",
        ],
        16 => &["Polarized16", "PolarizeMono16", "Mono16"],
        _ => &[],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pfnc_codes_carry_their_bit_width() {
        // bits 16..23 of a PFNC code are the bits per pixel in the buffer
        for (code, bits) in [
            (PFNC_MONO8, 8),
            (PFNC_MONO10, 16),
            (PFNC_MONO12, 16),
            (PFNC_MONO12_PACKED, 12),
            (PFNC_MONO12P, 12),
            (PFNC_MONO16, 16),
        ] {
            assert_eq!((code >> 16) & 0xff, bits, "{code:#x}");
            let enc = encoding_of_pfnc(code).unwrap();
            assert_eq!(enc.bytes_for(2) * 8, 2 * bits as usize, "{enc:?}");
        }
        assert_eq!(encoding_of_pfnc(0x0108_0009), None); // BayerRG8
    }

    #[test]
    fn names_agree_with_codes_and_depths() {
        for depth in [8u8, 10, 12, 16] {
            for name in preferred_names(depth) {
                let enc = encoding_of_name(name).unwrap_or_else(|| panic!("{name}"));
                assert_eq!(enc.bit_depth(), depth, "{name}");
            }
        }
        assert!(preferred_names(14).is_empty());
        assert_eq!(encoding_of_name("RGB8"), None);
    }

    #[test]
    fn processed_polarisation_formats_are_refused() {
        for n in [
            "PolarizedAngles_0d_45d_90d_135d_Mono12p",
            "PolarizedAngles_0d_45d_90d_135d_Mono8",
            "PolarizedStokes_S0_S1_S2_S3_Mono12p",
            "PolarizedDolp_Mono8",
        ] {
            assert!(refused_name(n).unwrap().contains("raw 2×2 mosaic"), "{n}");
            assert_eq!(encoding_of_name(n), None);
        }
        assert_eq!(refused_name("Polarized12p"), None);
    }
}
