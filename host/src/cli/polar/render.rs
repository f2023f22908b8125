//! The pictures of `ellipso polar`: each plane's false-colour image at the frame's own
//! resolution, with its key (colour bar, AoLP × DoLP key or mask swatches) drawn underneath by
//! `ellipso_report::Figure`.
//!
//! Contract: the top `height` rows of every picture are the plane's pixels, unscaled and
//! aligned with the demosaiced output; everything below is the key. Every colour function
//! takes any f32 (NaN included) and returns a valid colour.

use ellipso_report::{ColourMap, Figure, Key, Picture, Rgb};

/// Colour of masked pixels in false-colour images (mid-grey: no hue, not black, not white).
pub(super) const MASKED: Rgb = [128, 128, 128];

/// A `w × h` picture from per-pixel colours.
pub(super) fn picture(w: usize, h: usize, pixels: Vec<Rgb>) -> Picture {
    Picture {
        width: w as u32,
        height: h as u32,
        pixels,
    }
}

/// `picture` with `key` underneath, rendered.
pub(super) fn with_key(picture: Picture, key: Key) -> anyhow::Result<image::RgbImage> {
    Ok(Figure::bare().image("", picture).key(key).render()?)
}

/// Grey level of DoLP `t` in [0, 1] (clamped; NaN is black).
pub(super) fn grey(t: f32) -> Rgb {
    ColourMap::Grey.at(f64::from(t))
}

/// The AoLP picture's colour: hue = AoLP (0 and π meet), and DoLP as saturation (value 1), or
/// as value (saturation 1) when `dolp_as_value`.
pub(super) fn aolp_colour(aolp_rad: f32, dolp: f32, dolp_as_value: bool) -> Rgb {
    let (a, d) = (f64::from(aolp_rad), f64::from(dolp));
    if dolp_as_value {
        ellipso_report::colour::aolp_dolp(a, 1.0, d)
    } else {
        ellipso_report::colour::aolp_dolp(a, d, 1.0)
    }
}

/// Diverging blue–white–red colour for `t` in [−1, 1] (clamped; NaN is the colour of −1).
pub(super) fn diverging(t: f32) -> Rgb {
    ColourMap::Diverging.at((f64::from(t) + 1.0) / 2.0)
}

/// `round(65535·t)` for `t` clamped to [0, 1]; NaN gives 0.
pub(super) fn unit_to_u16(t: f32) -> u16 {
    if t.is_finite() {
        (t.clamp(0.0, 1.0) * 65535.0).round() as u16
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aolp_colours_close_the_wheel_and_follow_dolp() {
        use std::f32::consts::PI;
        assert_eq!(aolp_colour(0.0, 1.0, false), [255, 0, 0]);
        assert_eq!(aolp_colour(PI, 1.0, false), aolp_colour(0.0, 1.0, false));
        assert_eq!(aolp_colour(PI / 3.0, 1.0, false), [0, 255, 0]);
        // unpolarised: white as saturation, black as value
        assert_eq!(aolp_colour(1.0, 0.0, false), [255, 255, 255]);
        assert_eq!(aolp_colour(1.0, 0.0, true), [0, 0, 0]);
        let _ = aolp_colour(f32::NAN, f32::NAN, true);
    }

    #[test]
    fn keys_go_under_unmoved_pixels() {
        let p = picture(10, 4, vec![[1, 2, 3]; 40]);
        let img = with_key(p, Key::Swatches(vec![([255, 0, 0], "saturated".into())])).unwrap();
        assert_eq!(img.get_pixel(9, 3).0, [1, 2, 3]);
        assert!(img.height() > 4 && img.width() >= 10);
        assert!(img.pixels().any(|p| p.0 == [255, 0, 0]));
    }

    #[test]
    fn scaling_clamps() {
        assert_eq!(unit_to_u16(2.0), 65535);
        assert_eq!(unit_to_u16(-1.0), 0);
        assert_eq!(grey(0.5), [128; 3]);
        assert_eq!(grey(f32::INFINITY), [255; 3]);
        let mid = diverging(0.0);
        assert!(mid.iter().all(|&c| c > 230), "{mid:?}");
    }
}
