//! `.npy` (NumPy format 1.0) encoding of the renderer's per-pixel truth: f32 and u16 arrays of
//! any shape, C order, little-endian, header padded so the data starts on a 64-byte boundary
//! (numpy.lib.format).

/// Element types the truth files use.
pub(super) trait NpyElement: Copy {
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

/// The bytes of a `.npy` file holding `data` with `shape` (the product of `shape` must equal
/// `data.len()`; the caller builds both from one frame).
pub(super) fn encode<T: NpyElement>(shape: &[usize], data: &[T]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': {shape_text}, }}",
        T::DESCR
    );
    // magic (6) + version (2) + header length (2) + header, padded with spaces, ends in '\n'.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + data.len() * 4);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    // The header is well under 65 536 bytes for any shape we write.
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in data {
        v.push_le(&mut out);
    }
    out
}
