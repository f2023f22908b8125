//! `.npy` (NumPy format 1.0) encoding, so results reach Python at full precision: arrays of any
//! shape in C order, little-endian, header padded so the data starts on a 64-byte boundary
//! (format spec: numpy.lib.format). Used by `ellipso polar --npy` and `ellipso sim render --truth`.
//! [`decode`] reads C-order arrays of unsigned integers and floats (format 1.0–3.0, either byte
//! order): `ellipso polar` takes raw mosaics as `.npy`.

use std::path::Path;

/// Element types we write.
pub trait NpyElement: Copy {
    /// NumPy dtype descriptor.
    const DESCR: &'static str;
    /// Appends the little-endian bytes of `self`.
    fn push_le(self, out: &mut Vec<u8>);
}

impl NpyElement for f32 {
    const DESCR: &'static str = "<f4";
    fn push_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl NpyElement for u16 {
    const DESCR: &'static str = "<u2";
    fn push_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl NpyElement for u8 {
    const DESCR: &'static str = "|u1";
    fn push_le(self, out: &mut Vec<u8>) {
        out.push(self);
    }
}

/// The bytes of a `.npy` file holding `data` with `shape` (the product of `shape` must equal
/// `data.len()`; callers build both from one image).
pub fn encode<T: NpyElement>(shape: &[usize], data: &[T]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': {shape_text}, }}",
        T::DESCR
    );
    // magic (6) + version (2) + header length (2) + header, padded with spaces, ends in '\n'
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + std::mem::size_of_val(data));
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    // the header is < 200 bytes, so its length always fits in u16
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in data {
        v.push_le(&mut out);
    }
    out
}

/// Writes `data` with `shape` to `path`.
pub fn write<T: NpyElement>(path: &Path, shape: &[usize], data: &[T]) -> std::io::Result<()> {
    crate::atomic_file::write(path, encode(shape, data))
}

/// Numbers decoded from a `.npy` file, widened to f64 (every u8/u16/u32 and f32 value is exact).
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// The dtype descriptor as written (`<u2`, `<f4`, …).
    pub descr: String,
    /// The shape.
    pub shape: Vec<usize>,
    /// The values in C order.
    pub data: Vec<f64>,
}

impl NpyArray {
    /// Whether the dtype is a float type.
    pub fn is_float(&self) -> bool {
        self.descr.contains('f')
    }
}

/// Decodes a `.npy` file: C order, dtype `u1 u2 u4 f4 f8` (little- or big-endian); errors say
/// what is wrong in one line.
pub fn decode(bytes: &[u8]) -> Result<NpyArray, String> {
    if !bytes.starts_with(b"\x93NUMPY") || bytes.len() < 10 {
        return Err("not a .npy file (no \\x93NUMPY magic)".into());
    }
    let (header_len, start) = match bytes[6] {
        1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!(".npy format version {v} is not supported")),
    };
    let header = bytes
        .get(start..start + header_len)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or("truncated or non-text .npy header")?;
    let field = |key: &str| -> Option<&str> {
        let at = header.find(&format!("'{key}'"))? + key.len() + 2;
        Some(header[at..].trim_start().strip_prefix(':')?.trim_start())
    };
    let descr = field("descr")
        .and_then(|v| v.strip_prefix('\''))
        .and_then(|v| v.split('\'').next())
        .ok_or("no 'descr' in the .npy header")?
        .to_string();
    if field("fortran_order").is_some_and(|v| v.starts_with("True")) {
        return Err(
            "Fortran-order .npy arrays are not supported (save with np.ascontiguousarray)".into(),
        );
    }
    let shape_text = field("shape")
        .and_then(|v| v.strip_prefix('('))
        .and_then(|v| v.split(')').next())
        .ok_or("no 'shape' in the .npy header")?;
    let shape: Vec<usize> = shape_text
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.parse()
                .map_err(|_| format!("bad .npy shape `({shape_text})`"))
        })
        .collect::<Result<_, _>>()?;
    let little = !descr.starts_with('>');
    let kind = descr.trim_start_matches(['<', '>', '|', '=']);
    let size = match kind {
        "u1" => 1,
        "u2" => 2,
        "u4" | "f4" => 4,
        "f8" => 8,
        other => {
            return Err(format!(
                ".npy dtype `{other}` is not supported (unsigned integers u1/u2/u4 or floats f4/f8)"
            ));
        }
    };
    let count: usize = shape.iter().product();
    let body = &bytes[start + header_len..];
    if body.len() < count * size {
        return Err(format!(
            "truncated .npy data: shape {shape:?} needs {} bytes, {} present",
            count * size,
            body.len()
        ));
    }
    let data = body[..count * size]
        .chunks_exact(size)
        .map(|c| {
            let mut b = [0u8; 8];
            b[..size].copy_from_slice(c);
            if !little {
                b[..size].reverse();
            }
            match kind {
                "u1" => f64::from(b[0]),
                "u2" => f64::from(u16::from_le_bytes([b[0], b[1]])),
                "u4" => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                "f4" => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                _ => f64::from_le_bytes(b),
            }
        })
        .collect();
    Ok(NpyArray { descr, shape, data })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decode_reads_what_encode_writes_and_refuses_the_rest() {
        let a = decode(&encode(&[2, 3], &[0.5f32, 1.0, 2.0, 3.0, 4.0, 5.0])).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert!(a.is_float());
        assert_eq!(a.data, vec![0.5, 1.0, 2.0, 3.0, 4.0, 5.0]);
        let b = decode(&encode(&[2, 2], &[1u16, 4095, 7, 65535])).unwrap();
        assert_eq!((b.descr.as_str(), b.data[3]), ("<u2", 65535.0));
        assert!(decode(b"PNG").unwrap_err().contains("not a .npy"));
        let mut bad = encode(&[2], &[1u16, 2]);
        bad.truncate(bad.len() - 1);
        assert!(decode(&bad).unwrap_err().contains("truncated"));
        let mut signed = encode(&[1], &[1u8]);
        let at = signed.windows(3).position(|w| w == b"|u1").unwrap();
        signed[at..at + 3].copy_from_slice(b"<i1");
        assert!(decode(&signed).unwrap_err().contains("not supported"));
    }

    #[test]
    fn header_is_aligned_and_describes_the_array() {
        let bytes = encode(&[2, 3], &[0.5f32, 1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
        let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + header_len) % 64, 0, "data 64-byte aligned");
        let header = std::str::from_utf8(&bytes[10..10 + header_len]).expect("ascii");
        assert!(header.contains("'descr': '<f4'") && header.contains("'shape': (2, 3)"));
        assert!(header.ends_with('\n'));
        let data = &bytes[10 + header_len..];
        assert_eq!(data.len(), 6 * 4);
        assert_eq!(
            f32::from_le_bytes([data[0], data[1], data[2], data[3]]),
            0.5
        );
        assert!(encode(&[1, 2], &[1u8, 0]).ends_with(&[1, 0]));
        assert!(encode(&[2], &[7u16, 9]).ends_with(&[7, 0, 9, 0]));
        let one_d = encode(&[4], &[0u8; 4]);
        let len = u16::from_le_bytes([one_d[8], one_d[9]]) as usize;
        assert!(
            std::str::from_utf8(&one_d[10..10 + len])
                .expect("ascii")
                .contains("'shape': (4,)")
        );
    }
}
