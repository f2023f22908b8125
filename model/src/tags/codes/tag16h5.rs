//! The `tag16h5` table: 16-bit codes, minimum Hamming distance 5, as the AprilTag 3 library's
//! `tag16h5.c` holds it. Data only, checked against the C library by `ellipso-sim`'s
//! tag checks (the parent's doc).

use super::RawTable;

/// `tag16h5`: 30 codes.
pub(in crate::tags) const TAG16H5: RawTable = RawTable {
    nbits: 16,
    width_at_border: 6,
    total_width: 8,
    reversed_border: false,
    bit_x: &[1, 2, 3, 2, 4, 4, 4, 3, 4, 3, 2, 3, 1, 1, 1, 2],
    bit_y: &[1, 1, 1, 2, 1, 2, 3, 2, 4, 4, 4, 3, 4, 3, 2, 3],
    codes: &[
        0x00000000000027c8,
        0x00000000000031b6,
        0x0000000000003859,
        0x000000000000569c,
        0x0000000000006c76,
        0x0000000000007ddb,
        0x000000000000af09,
        0x000000000000f5a1,
        0x000000000000fb8b,
        0x0000000000001cb9,
        0x00000000000028ca,
        0x000000000000e8dc,
        0x0000000000001426,
        0x0000000000005770,
        0x0000000000009253,
        0x000000000000b702,
        0x000000000000063a,
        0x0000000000008f34,
        0x000000000000b4c0,
        0x00000000000051ec,
        0x000000000000e6f0,
        0x0000000000005fa4,
        0x000000000000dd43,
        0x0000000000001aaa,
        0x000000000000e62f,
        0x0000000000006dbc,
        0x000000000000b6eb,
        0x000000000000de10,
        0x000000000000154d,
        0x000000000000b57a,
    ],
};
