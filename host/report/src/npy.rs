//! `.npy` (NumPy format 1.0) encoding, so results reach Python at full precision: arrays of any
//! shape in C order, little-endian, header padded so the data starts on a 64-byte boundary
//! (format spec: numpy.lib.format). Used by `ellipso polar --npy` and `ellipso sim render --truth`.

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

#[cfg(test)]
mod tests {
    use super::*;

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
