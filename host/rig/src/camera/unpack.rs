//! Raw sample encodings of mono / polarisation-mosaic cameras, their unpacking to `u16`, and the
//! checks that keep a 2×2 polarisation mosaic intact.
//!
//! Contract:
//! - [`RawEncoding`] names how samples sit in a camera buffer, independent of the transport (GigE
//!   Vision PFNC codes, V4L2 fourccs). Every backend maps its own format ids onto it.
//! - [`unpack_to_u16`] turns a buffer of `width × height` samples into row-major `u16` values,
//!   **unshifted** (a 12-bit sample stays in 0..=4095). A buffer shorter than the frame is an error
//!   naming both sizes; trailing bytes (padding) are ignored.
//! - [`check_mosaic_region`] refuses regions that would shift or cut the 2×2 polariser pattern
//!   (odd offsets or odd sizes); binning and decimation are refused by the backends through
//!   [`check_mosaic_factor`].
//!
//! Bit layouts (PFNC 2.x, GigE Vision 2.0 Annex):
//! - `Mono8`: one byte per sample.
//! - `Mono10`, `Mono12`, `Mono16` (and V4L2 `Y10`, `Y12`, `Y16`): one little-endian `u16` per
//!   sample, MSBs zero for 10/12 bits.
//! - `Mono12Packed` (GigE Vision legacy): 2 samples in 3 bytes,
//!   `b0 = p0[11:4]`, `b1 = p1[3:0] << 4 | p0[3:0]`, `b2 = p1[11:4]`.
//! - `Mono12p` (PFNC LSB-first packing): 2 samples in 3 bytes,
//!   `b0 = p0[7:0]`, `b1 = p1[3:0] << 4 | p0[11:8]`, `b2 = p1[11:4]`.

/// How samples are laid out in a raw camera buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RawEncoding {
    /// 8 bits per sample, one byte each.
    Mono8,
    /// 10 significant bits in a little-endian `u16`.
    Mono10,
    /// 12 significant bits in a little-endian `u16`.
    Mono12,
    /// 12 bits, GigE Vision legacy packing (2 samples in 3 bytes, MSBs first).
    Mono12Packed,
    /// 12 bits, PFNC LSB-first packing (2 samples in 3 bytes).
    Mono12p,
    /// 16 bits in a little-endian `u16`.
    Mono16,
}

impl RawEncoding {
    /// Significant bits of a sample.
    pub fn bit_depth(self) -> u8 {
        match self {
            Self::Mono8 => 8,
            Self::Mono10 => 10,
            Self::Mono12 | Self::Mono12Packed | Self::Mono12p => 12,
            Self::Mono16 => 16,
        }
    }

    /// Bytes needed for `n_samples` samples (packed formats round up to whole bytes).
    pub fn bytes_for(self, n_samples: usize) -> usize {
        match self {
            Self::Mono8 => n_samples,
            Self::Mono10 | Self::Mono12 | Self::Mono16 => n_samples.saturating_mul(2),
            Self::Mono12Packed | Self::Mono12p => n_samples.saturating_mul(3).div_ceil(2),
        }
    }

    /// The PFNC name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Mono8 => "Mono8",
            Self::Mono10 => "Mono10",
            Self::Mono12 => "Mono12",
            Self::Mono12Packed => "Mono12Packed",
            Self::Mono12p => "Mono12p",
            Self::Mono16 => "Mono16",
        }
    }
}

/// Unpacking failures.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UnpackError {
    /// The buffer holds fewer bytes than the frame needs.
    #[error("{encoding} frame of {width}×{height} needs {needed} bytes, buffer holds {got}")]
    Truncated {
        /// Encoding name.
        encoding: &'static str,
        /// Width, px.
        width: u32,
        /// Height, px.
        height: u32,
        /// Bytes needed.
        needed: usize,
        /// Bytes present.
        got: usize,
    },
}

/// Unpacks `width × height` samples of `encoding` from `bytes` into `out` (cleared first).
///
/// `out` is reused across frames so the hot path allocates only when the frame size grows.
pub fn unpack_into(
    encoding: RawEncoding,
    bytes: &[u8],
    width: u32,
    height: u32,
    out: &mut Vec<u16>,
) -> Result<(), UnpackError> {
    let n = (width as usize).saturating_mul(height as usize);
    let needed = encoding.bytes_for(n);
    if bytes.len() < needed {
        return Err(UnpackError::Truncated {
            encoding: encoding.name(),
            width,
            height,
            needed,
            got: bytes.len(),
        });
    }
    let bytes = &bytes[..needed];
    out.clear();
    out.reserve(n);
    match encoding {
        RawEncoding::Mono8 => out.extend(bytes.iter().map(|&b| u16::from(b))),
        RawEncoding::Mono10 | RawEncoding::Mono12 | RawEncoding::Mono16 => out.extend(
            bytes
                .chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]])),
        ),
        RawEncoding::Mono12Packed | RawEncoding::Mono12p => {
            let gige = encoding == RawEncoding::Mono12Packed;
            let decode = |b0: u16, b1: u16, b2: u16| -> (u16, u16) {
                if gige {
                    ((b0 << 4) | (b1 & 0x0f), (b2 << 4) | (b1 >> 4))
                } else {
                    (b0 | ((b1 & 0x0f) << 8), (b1 >> 4) | (b2 << 4))
                }
            };
            let triples = bytes.chunks_exact(3);
            let rest = triples.remainder();
            for c in triples {
                let (p0, p1) = decode(u16::from(c[0]), u16::from(c[1]), u16::from(c[2]));
                out.push(p0);
                out.push(p1);
            }
            // an odd sample count ends with 2 bytes holding one sample
            if let [b0, b1] = *rest {
                out.push(decode(u16::from(b0), u16::from(b1), 0).0);
            }
        }
    }
    debug_assert_eq!(out.len(), n);
    Ok(())
}

/// Unpacks into a fresh vector; see [`unpack_into`].
pub fn unpack_to_u16(
    encoding: RawEncoding,
    bytes: &[u8],
    width: u32,
    height: u32,
) -> Result<Vec<u16>, UnpackError> {
    let mut out = Vec::new();
    unpack_into(encoding, bytes, width, height, &mut out)?;
    Ok(out)
}

/// Refuses a sensor region that breaks the 2×2 polarisation mosaic: offsets and sizes must be
/// even and the size non-zero. Returns the reason as text for the backend's error.
pub fn check_mosaic_region(
    offset_x: u32,
    offset_y: u32,
    width: u32,
    height: u32,
) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err(format!("region {width}×{height} is empty"));
    }
    if offset_x % 2 != 0 || offset_y % 2 != 0 {
        return Err(format!(
            "region offset ({offset_x}, {offset_y}) is odd: it would shift the 2×2 polariser mosaic"
        ));
    }
    if width % 2 != 0 || height % 2 != 0 {
        return Err(format!(
            "region size {width}×{height} is odd: it would cut a 2×2 polariser cell"
        ));
    }
    Ok(())
}

/// Refuses a binning or decimation factor other than 1 (it averages or drops pixels of
/// different polariser angles, destroying the mosaic).
pub fn check_mosaic_factor(what: &str, horizontal: i64, vertical: i64) -> Result<(), String> {
    if horizontal == 1 && vertical == 1 {
        Ok(())
    } else {
        Err(format!(
            "{what} {horizontal}×{vertical} mixes pixels behind different polariser angles; \
             only 1×1 keeps the mosaic"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn mono8_widens_each_byte() {
        let px = unpack_to_u16(RawEncoding::Mono8, &[0, 1, 128, 255], 2, 2).unwrap();
        assert_eq!(px, vec![0, 1, 128, 255]);
    }

    #[test]
    fn mono12_and_mono16_are_little_endian() {
        let bytes = [0xff, 0x0f, 0x34, 0x12, 0x01, 0x00, 0x00, 0x08];
        assert_eq!(
            unpack_to_u16(RawEncoding::Mono12, &bytes, 4, 1).unwrap(),
            vec![0x0fff, 0x1234, 0x0001, 0x0800]
        );
        assert_eq!(
            unpack_to_u16(RawEncoding::Mono16, &bytes, 2, 2).unwrap(),
            vec![0x0fff, 0x1234, 0x0001, 0x0800]
        );
    }

    #[test]
    fn mono12_packed_gige_layout() {
        // p0 = 0xABC, p1 = 0x123: b0 = 0xAB, b1 = 0x3C (p1 low nibble high), b2 = 0x12
        let px = unpack_to_u16(RawEncoding::Mono12Packed, &[0xab, 0x3c, 0x12], 2, 1).unwrap();
        assert_eq!(px, vec![0xabc, 0x123]);
    }

    #[test]
    fn mono12p_pfnc_layout() {
        // p0 = 0xABC, p1 = 0x123: b0 = 0xBC, b1 = 0x3A (p1 low nibble high, p0 high nibble low),
        // b2 = 0x12
        let px = unpack_to_u16(RawEncoding::Mono12p, &[0xbc, 0x3a, 0x12], 2, 1).unwrap();
        assert_eq!(px, vec![0xabc, 0x123]);
    }

    #[test]
    fn packed_odd_sample_count_uses_the_last_two_bytes() {
        let px = unpack_to_u16(
            RawEncoding::Mono12Packed,
            &[0xab, 0x3c, 0x12, 0xff, 0x0e],
            3,
            1,
        )
        .unwrap();
        assert_eq!(px, vec![0xabc, 0x123, 0xffe]);
        let px =
            unpack_to_u16(RawEncoding::Mono12p, &[0xbc, 0x3a, 0x12, 0xfe, 0x0f], 3, 1).unwrap();
        assert_eq!(px, vec![0xabc, 0x123, 0xffe]);
    }

    #[test]
    fn truncated_buffer_is_an_error_naming_sizes() {
        let e = unpack_to_u16(RawEncoding::Mono12, &[0; 7], 2, 2).unwrap_err();
        assert_eq!(
            e,
            UnpackError::Truncated {
                encoding: "Mono12",
                width: 2,
                height: 2,
                needed: 8,
                got: 7
            }
        );
        assert!(e.to_string().contains("needs 8 bytes"));
    }

    #[test]
    fn padding_after_the_frame_is_ignored() {
        let px = unpack_to_u16(RawEncoding::Mono8, &[1, 2, 3, 4, 9, 9], 2, 2).unwrap();
        assert_eq!(px, vec![1, 2, 3, 4]);
    }

    #[test]
    fn mosaic_checks() {
        assert!(check_mosaic_region(0, 0, 2448, 2048).is_ok());
        assert!(check_mosaic_region(2, 4, 256, 192).is_ok());
        assert!(
            check_mosaic_region(1, 0, 256, 192)
                .unwrap_err()
                .contains("odd")
        );
        assert!(
            check_mosaic_region(0, 3, 256, 192)
                .unwrap_err()
                .contains("shift")
        );
        assert!(
            check_mosaic_region(0, 0, 255, 192)
                .unwrap_err()
                .contains("cut")
        );
        assert!(check_mosaic_region(0, 0, 0, 192).is_err());
        assert!(check_mosaic_factor("binning", 1, 1).is_ok());
        assert!(check_mosaic_factor("binning", 2, 2).is_err());
        assert!(check_mosaic_factor("decimation", 1, 2).is_err());
    }

    /// Packs 12-bit samples the GigE way (reference encoder, independent of the decoder above).
    fn pack_gige(px: &[u16]) -> Vec<u8> {
        let mut out = Vec::new();
        for pair in px.chunks(2) {
            let p0 = pair[0];
            let p1 = pair.get(1).copied().unwrap_or(0);
            out.push((p0 >> 4) as u8);
            out.push(((p1 & 0xf) << 4 | (p0 & 0xf)) as u8);
            if pair.len() == 2 {
                out.push((p1 >> 4) as u8);
            }
        }
        out
    }

    /// Packs 12-bit samples the PFNC `Mono12p` way.
    fn pack_12p(px: &[u16]) -> Vec<u8> {
        // bit stream, LSB first
        let mut out = vec![0u8; (px.len() * 12).div_ceil(8)];
        for (i, &p) in px.iter().enumerate() {
            for b in 0..12 {
                if p >> b & 1 == 1 {
                    let bit = i * 12 + b;
                    out[bit / 8] |= 1 << (bit % 8);
                }
            }
        }
        out
    }

    proptest! {
        #[test]
        fn packed_round_trips(px in proptest::collection::vec(0u16..4096, 1..64)) {
            let n = px.len() as u32;
            prop_assert_eq!(
                unpack_to_u16(RawEncoding::Mono12Packed, &pack_gige(&px), n, 1).unwrap(), px.clone()
            );
            prop_assert_eq!(unpack_to_u16(RawEncoding::Mono12p, &pack_12p(&px), n, 1).unwrap(), px);
        }
    }
}
