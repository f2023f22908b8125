//! Synthetic raw mosaics from known Stokes fields, for tests and benchmarks.
//!
//! Each raw pixel gets `I_θ = ½(s0 + s1 cos2θ + s2 sin2θ)` for its analyser θ (from
//! [`ellipso_model::mosaic`]), in DN, rounded to the nearest integer and clamped to
//! `[0, 2^bit_depth − 1]` (clamping is how a real sensor saturates). Choose Stokes values whose
//! intensities are whole DN to make round-trips exact.

use ellipso_model::mosaic::{Channel, SensorLayout};

use super::frame::{FrameError, RawFrame, full_scale_dn};
use super::stokes::intensity_behind_analyser;

/// A `width × height` frame of `layout` whose pixel `(x, y)` sees Stokes `stokes_dn(x, y, colour)`
/// (in DN, i.e. s0 = 2·mean intensity in DN).
pub fn mosaic_from_stokes(
    layout: SensorLayout,
    width: u32,
    height: u32,
    bit_depth: u8,
    stokes_dn: impl Fn(u32, u32, Option<Channel>) -> [f64; 3],
) -> Result<RawFrame, FrameError> {
    let max = f64::from(full_scale_dn(bit_depth.min(16)));
    let mut data = Vec::with_capacity(width as usize * height as usize);
    for y in 0..height {
        for x in 0..width {
            let s = stokes_dn(x, y, layout.colour_at(x, y));
            let theta_rad = layout.analyser_at(x, y).angle_rad();
            let dn = intensity_behind_analyser(s, theta_rad)
                .round()
                .clamp(0.0, max);
            data.push(dn as u16); // in [0, 65535] after the clamp
        }
    }
    RawFrame::new(width, height, bit_depth, layout, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_follow_the_mosaic_and_clip_like_a_sensor() {
        let f = mosaic_from_stokes(SensorLayout::MonoPolar, 4, 2, 12, |_, _, _| {
            [2000.0, 600.0, -400.0]
        })
        .expect("valid");
        // row 0: 90° 45°; row 1: 135° 0°
        assert_eq!(f.row(0), Some(&[700, 800, 700, 800][..]));
        assert_eq!(f.row(1), Some(&[1200, 1300, 1200, 1300][..]));
        let clipped = mosaic_from_stokes(SensorLayout::MonoPolar, 2, 2, 8, |_, _, _| {
            [1000.0, 0.0, 0.0]
        })
        .expect("valid");
        assert_eq!(clipped.data_dn(), &[255; 4]);
    }
}
