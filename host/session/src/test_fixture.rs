//! The minimal session the crate's tests write: one definition of its manifest and of each
//! frame's pixels, shared by the reader's and the provenance checks' tests.

use crate::manifest::{Manifest, SensorInfo, SessionSource};

/// Frame width, px.
pub const WIDTH: u32 = 8;
/// Frame height, px.
pub const HEIGHT: u32 = 6;

/// The manifest of an 8×6 12-bit mono-polar simulator session.
pub fn manifest() -> Manifest {
    Manifest::new(
        SessionSource::Simulator {
            scene: "sphere.toml".into(),
            seed: 7,
        },
        SensorInfo {
            layout: ellipso_model::mosaic::SensorLayout::MonoPolar,
            width: WIDTH,
            height: HEIGHT,
            bit_depth: 12,
        },
        1_700_000_000_000_000,
    )
}

/// Frame `id`'s pixels: a 12-bit pattern that differs from frame to frame.
pub fn pixels(id: u64) -> Vec<u16> {
    (0..u64::from(WIDTH * HEIGHT))
        .map(|i| ((i * 97 + id * 13) % 4096) as u16)
        .collect()
}
