//! `stokes.exr`: every float plane of `ellipso polar` in one multi-channel OpenEXR file, named
//! as Mitsuba 3's `stokes` integrator names its film channels, so a capture can be diffed
//! against a Mitsuba render channel by channel.
//!
//! Contract: one channel per plane and band, `NAME` for a monochrome sensor and `NAME.R`,
//! `NAME.G`, `NAME.B` for a colour one: `S0`, `S1`, `S2` (Stokes: S0 = I0 + I90, S1 = I0 − I90,
//! S2 = I45 − I135, the reference axis image-right; S3 is not measured and not written),
//! `DoLP`, `AoLP` (radians in [0, π), counter-clockwise from image-right), `I_d` (= 2·I90),
//! `I_s` (= I0 − I90), `I_alpha` (= I135 − I45), `residual` (I0 + I90 − I45 − I135) and `mask`
//! (u32 reason bits, 0 = valid). Values are fractions of the sensor's full scale, exactly the
//! numbers of the `.npy` planes; masked pixels keep their computed values. A viewer's picture
//! comes from `R`, `G`, `B` (colour) or `Y` (mono), copies of S0 as in Mitsuba's output.

use std::path::Path;

use crate::{PolarImage, StokesBand};
use ellipso_report::exr_image::FloatImage;
use ellipso_run_error::{Context, RunError};

/// The channel name of `plane` for `band` (module doc).
fn name(plane: &str, band: &StokesBand) -> String {
    match band.colour {
        None => plane.to_string(),
        Some(c) => format!("{plane}.{}", c.letter().to_ascii_uppercase()),
    }
}

/// The float image of every band of `image` (module doc).
pub fn stokes_image(image: &PolarImage) -> Result<FloatImage, RunError> {
    let mut exr = FloatImage::new(image.width(), image.height())?;
    for band in &image.bands {
        let channels = band.observation_channels();
        let planes: [(&str, &[f32]); 8] = [
            ("S0", band.s0.data()),
            ("S1", band.s1.data()),
            ("S2", band.s2.data()),
            ("DoLP", band.dolp.data()),
            ("AoLP", band.aolp_rad.data()),
            ("I_d", channels.i_d.data()),
            ("I_s", channels.i_s.data()),
            ("I_alpha", channels.i_alpha.data()),
        ];
        for (plane, data) in planes {
            exr.push_f32(&name(plane, band), data.to_vec())?;
        }
        exr.push_f32(&name("residual", band), band.residual.data().to_vec())?;
        let bits = band.mask.data().iter().map(|m| u32::from(m.0)).collect();
        exr.push_u32(&name("mask", band), bits)?;
        // The viewer's picture: S0 under the plain colour names.
        let view = match band.colour {
            None => "Y".to_string(),
            Some(c) => c.letter().to_ascii_uppercase(),
        };
        exr.push_f32(&view, band.s0.data().to_vec())?;
    }
    Ok(exr)
}

/// Writes `stokes.exr` into `out` and returns its name.
pub fn write(out: &Path, image: &PolarImage) -> Result<String, RunError> {
    let name = "stokes.exr";
    let path = out.join(name);
    stokes_image(image)?
        .write(&path)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(name.to_string())
}
