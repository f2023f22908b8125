//! One intensity picture of a raw frame at superpixel resolution, colour bands summed: what a
//! tag detector and the fit's comparison picture look at.
//!
//! Contract: values are in fractions of full scale (the [`PolarConfig`] levels, no dark level);
//! `S0` is the total intensity ½(I0 + I45 + I90 + I135), `I0`/`I90` one analyser's plane.

use crate::PolarConfig;
use crate::PolarError;
use crate::demosaic::{DemosaicMethod, demosaic};
use crate::frame::RawFrame;

/// Which picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IntensityPlane {
    /// Total intensity s0 (all four analysers).
    S0,
    /// The 90° analyser (cross-polarised to the rig's flash).
    I90,
    /// The 0° analyser (co-polarised to the rig's flash).
    I0,
}

/// The picture `kind` of `frame`: `(plane, width, height)`, row-major.
pub fn intensity_plane<D: AsRef<[u16]>>(
    frame: &RawFrame<D>,
    kind: IntensityPlane,
) -> Result<(Vec<f32>, usize, usize), PolarError> {
    let levels = PolarConfig::default().levels(frame)?;
    let demosaiced = demosaic(frame, &levels, DemosaicMethod::Superpixel);
    let (w, h) = (
        demosaiced.bands[0].intensity[0].width(),
        demosaiced.bands[0].intensity[0].height(),
    );
    let mut plane = vec![0f32; w * h];
    for band in &demosaiced.bands {
        let [i0, i45, i90, i135] = &band.intensity;
        for (k, v) in plane.iter_mut().enumerate() {
            *v += match kind {
                IntensityPlane::S0 => {
                    0.5 * (i0.data()[k] + i45.data()[k] + i90.data()[k] + i135.data()[k])
                }
                IntensityPlane::I90 => i90.data()[k],
                IntensityPlane::I0 => i0.data()[k],
            };
        }
    }
    Ok((plane, w, h))
}
