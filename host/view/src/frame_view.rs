//! The latest frame for the live page: s0, DoLP and AoLP pictures and the frame's statistics.
//!
//! Contract: [`render`] runs the polarisation processing of `ellipso_polar` (superpixel
//! demosaic, default levels; ideal analysers, or per superpixel the sensor calibration the
//! session names) on one raw frame and returns small PNGs, at most
//! [`MAX_WIDTH_PX`] wide (nearest superpixel, no smoothing so that masked pixels stay visible):
//! - `s0`: grey, s0/2 (the mean analyser intensity) with an sRGB curve; saturated pixels red;
//! - `dolp`: viridis over [0, 1] (`ellipso_report::colour::dolp_colour`);
//! - `aolp`: hue = AoLP (0° and 180° meet), saturation = DoLP, value 1
//!   (`ellipso_report::colour::aolp_colour`, the convention of every AoLP picture);
//!
//! in both, masked pixels (dark, saturated, … — their DoLP is noise) are the pictures' no-data
//! grey.
//!
//! Colour frames use the mean of the three bands. Statistics: the saturated and dark fractions
//! (polar's mask), the valid fraction, the mean s0 and DoLP over valid pixels.

use std::io::Cursor;

use ellipso_polar::frame::RawFrame;
use ellipso_polar::mask::MaskReason;
use ellipso_polar::sensor_calibration::{SensorCalibration, process_with_sensor};
use ellipso_polar::{PolarConfig, PolarImage, process};

/// Widest picture sent to the page, px.
pub const MAX_WIDTH_PX: usize = 480;

/// The pictures and statistics of one frame.
#[derive(Clone, Debug)]
pub struct FrameView {
    /// Frame id.
    pub frame_id: u64,
    /// `s0.png`, `dolp.png`, `aolp.png`.
    pub pngs: [Vec<u8>; 3],
    /// Statistics for the page.
    pub stats: serde_json::Value,
}

/// Processes one frame.
pub fn render(
    frame_id: u64,
    frame: &RawFrame,
    sensor: Option<&SensorCalibration>,
) -> Result<FrameView, String> {
    let image = match sensor {
        Some(cal) => process_with_sensor(frame, &PolarConfig::default(), cal),
        None => process(frame, &PolarConfig::default()),
    }
    .map_err(|e| e.to_string())?;
    let (w, h) = (image.width(), image.height());
    if w == 0 || h == 0 {
        return Err("empty frame".into());
    }
    let step = w.div_ceil(MAX_WIDTH_PX).max(1);
    let (ow, oh) = (w.div_ceil(step), h.div_ceil(step));
    let mut s0_rgb = Vec::with_capacity(ow * oh * 3);
    let mut dolp_rgb = Vec::with_capacity(ow * oh * 3);
    let mut aolp_rgb = Vec::with_capacity(ow * oh * 3);
    for y in (0..h).step_by(step) {
        for x in (0..w).step_by(step) {
            let px = pixel(&image, y * w + x);
            let saturated = px.mask & MaskReason::Saturated.bit() != 0;
            let g = ellipso_model::colour::srgb_u8(f64::from(px.s0) / 2.0);
            s0_rgb.extend(if saturated { [255, 40, 40] } else { [g, g, g] });
            let valid = px.mask == 0;
            let dolp = valid.then_some(f64::from(px.dolp));
            let aolp = valid.then_some(f64::from(px.aolp_rad));
            dolp_rgb.extend(ellipso_report::colour::dolp_colour(dolp));
            aolp_rgb.extend(ellipso_report::colour::aolp_colour(aolp, dolp));
        }
    }
    let mut valid = 0usize;
    let (mut sum_s0, mut sum_dolp) = (0f64, 0f64);
    let (mut saturated, mut dark) = (0usize, 0usize);
    for i in 0..w * h {
        let px = pixel(&image, i);
        saturated += usize::from(px.mask & MaskReason::Saturated.bit() != 0);
        dark += usize::from(px.mask & MaskReason::Dark.bit() != 0);
        if px.mask == 0 {
            valid += 1;
            sum_s0 += f64::from(px.s0);
            sum_dolp += f64::from(px.dolp);
        }
    }
    let n = (w * h) as f64;
    let stats = serde_json::json!({
        "frame_id": frame_id,
        "width": w,
        "height": h,
        "saturated_fraction": saturated as f64 / n,
        "dark_fraction": dark as f64 / n,
        "valid_fraction": valid as f64 / n,
        "mean_s0_valid": if valid > 0 { sum_s0 / valid as f64 } else { 0.0 },
        "mean_dolp_valid": if valid > 0 { sum_dolp / valid as f64 } else { 0.0 },
    });
    Ok(FrameView {
        frame_id,
        pngs: [
            png(ow, oh, &s0_rgb)?,
            png(ow, oh, &dolp_rgb)?,
            png(ow, oh, &aolp_rgb)?,
        ],
        stats,
    })
}

struct Px {
    s0: f32,
    dolp: f32,
    aolp_rad: f32,
    mask: u8,
}

/// Pixel `i` averaged over the bands (mask: union of the bands' reasons).
fn pixel(image: &PolarImage, i: usize) -> Px {
    let k = image.bands.len().max(1) as f32;
    let mut p = Px {
        s0: 0.0,
        dolp: 0.0,
        aolp_rad: 0.0,
        mask: 0,
    };
    let (mut s1, mut s2) = (0f32, 0f32);
    for b in &image.bands {
        p.s0 += b.s0.data()[i] / k;
        s1 += b.s1.data()[i] / k;
        s2 += b.s2.data()[i] / k;
        p.mask |= b.mask.data()[i].0;
    }
    if image.bands.len() == 1 {
        p.dolp = image.bands[0].dolp.data()[i];
        p.aolp_rad = image.bands[0].aolp_rad.data()[i];
    } else {
        // colour: DoLP and AoLP of the band-mean Stokes vector (guarded against s0 ≤ 0)
        p.dolp = if p.s0 > 0.0 {
            ((s1 * s1 + s2 * s2).sqrt() / p.s0).min(1.0)
        } else {
            0.0
        };
        p.aolp_rad = (0.5 * s2.atan2(s1)).rem_euclid(std::f32::consts::PI);
    }
    p
}

fn png(w: usize, h: usize, rgb: &[u8]) -> Result<Vec<u8>, String> {
    let img =
        image::RgbImage::from_raw(w as u32, h as u32, rgb.to_vec()).ok_or("picture buffer size")?;
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_polarised_frame_renders_with_its_statistics() {
        let layout = ellipso_model::mosaic::SensorLayout::MonoPolar;
        // I0 bright, I90 dark: horizontally polarised, DoLP high; one saturated tile
        let (w, h) = (64u32, 32u32);
        let mut px = vec![0u16; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let angle = match (x % 2, y % 2) {
                    (0, 0) => 90,
                    (1, 0) => 45,
                    (0, 1) => 135,
                    _ => 0,
                };
                px[(y * w + x) as usize] = match angle {
                    0 => 3000,
                    90 => 200,
                    _ => 1600,
                };
            }
        }
        px[0] = 4095;
        let frame = RawFrame::new(w, h, 12, layout, px).unwrap();
        let v = render(7, &frame, None).unwrap();
        for p in &v.pngs {
            assert_eq!(&p[1..4], b"PNG");
        }
        let sat = v.stats["saturated_fraction"].as_f64().unwrap();
        assert!((sat - 1.0 / 512.0).abs() < 1e-9, "{sat}");
        assert!(v.stats["mean_dolp_valid"].as_f64().unwrap() > 0.8);
    }

    fn decode(png: &[u8]) -> image::RgbImage {
        image::load_from_memory(png).unwrap().to_rgb8()
    }

    #[test]
    fn dark_pixels_are_grey_in_dolp_and_aolp() {
        let layout = ellipso_model::mosaic::SensorLayout::MonoPolar;
        // left half: a few DN of noise with a strongly polarised pattern (DoLP ≈ 1 computed, but
        // the pixels are dark); right half: bright, DoLP ≈ 0.88
        let (w, h) = (64u32, 32u32);
        let mut px = vec![0u16; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let i0 = (x % 2, y % 2) == (1, 1);
                px[(y * w + x) as usize] = match (x < w / 2, i0) {
                    (true, true) => 3,
                    (true, false) => 0,
                    (false, true) => 3000,
                    (false, false) => 1600 - 1400 * u16::from((x % 2, y % 2) == (0, 0)),
                };
            }
        }
        let frame = RawFrame::new(w, h, 12, layout, px).unwrap();
        let v = render(1, &frame, None).unwrap();
        assert!((v.stats["dark_fraction"].as_f64().unwrap() - 0.5).abs() < 1e-9);
        let [_, dolp, aolp] = v.pngs.each_ref().map(|p| decode(p));
        let (ow, oh) = dolp.dimensions();
        for y in 0..oh {
            for x in 0..ow {
                let (d, a) = (dolp.get_pixel(x, y).0, aolp.get_pixel(x, y).0);
                let grey = ellipso_report::figure::NO_DATA;
                if x < ow / 2 {
                    assert_eq!(d, grey, "dark DoLP at {x},{y}");
                    assert_eq!(a, grey, "dark AoLP at {x},{y}");
                } else {
                    // DoLP ≈ 0.88: the yellow-green end of viridis
                    assert!(d[1] > 200 && d[2] < 100, "bright DoLP at {x},{y}: {d:?}");
                }
            }
        }
    }
}
