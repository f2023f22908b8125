//! The session's one checksum, CRC-64/XZ: of each frame file's bytes as written and read
//! ([`crate::frame_png`]) and of the records that prove what a pose was computed from
//! ([`crate::provenance`]).

use crc::{CRC_64_XZ, Crc, Table};

/// Slice-by-16 tables (the same checksum as the byte-wise table, several times faster: every
/// frame file of a session is hashed by every stage that reads it).
const CRC64: Crc<u64, Table<16>> = Crc::<u64, Table<16>>::new(&CRC_64_XZ);

/// CRC-64/XZ of `bytes`.
pub fn crc64(bytes: &[u8]) -> u64 {
    CRC64.checksum(bytes)
}
