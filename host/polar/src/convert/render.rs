//! The pictures of `ellipso polar`: each plane's false-colour image at the frame's own
//! resolution, with its key (colour bar, AoLP × DoLP key or mask swatches) drawn underneath by
//! `ellipso_report::Figure`.
//!
//! Contract: the top `height` rows of every picture are the plane's pixels, unscaled and
//! aligned with the demosaiced output; everything below is the key. Every colour function
//! takes any f32 (NaN included) and returns a valid colour.

use ellipso_report::{ColourMap, Figure, Key, Picture, Rgb};

/// Colour of masked pixels in false-colour images: the no-data grey of every picture.
pub(super) const MASKED: Rgb = ellipso_report::figure::NO_DATA;

/// A `w × h` picture from per-pixel colours.
pub(super) fn picture(w: usize, h: usize, pixels: Vec<Rgb>) -> Picture {
    Picture {
        width: w as u32,
        height: h as u32,
        pixels,
    }
}

/// `picture` with `key` underneath, rendered.
pub(super) fn with_key(
    picture: Picture,
    key: Key,
) -> Result<image::RgbImage, ellipso_run_error::RunError> {
    Ok(Figure::bare().image("", picture).key(key).render()?)
}

/// Diverging blue–white–red colour for `t` in [−1, 1] (clamped; NaN is the colour of −1).
pub(super) fn diverging(t: f32) -> Rgb {
    ColourMap::Diverging.at((f64::from(t) + 1.0) / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aolp_colours_close_the_wheel_and_unpolarised_is_white() {
        use ellipso_report::colour::aolp_colour;
        use std::f64::consts::PI;
        assert_eq!(aolp_colour(Some(0.0), Some(1.0)), [255, 0, 0]);
        assert_eq!(aolp_colour(Some(PI), Some(1.0)), [255, 0, 0]);
        assert_eq!(aolp_colour(Some(PI / 3.0), Some(1.0)), [0, 255, 0]);
        assert_eq!(aolp_colour(Some(1.0), Some(0.0)), [255, 255, 255]);
        assert_eq!(aolp_colour(None, Some(0.5)), MASKED);
        assert_eq!(aolp_colour(Some(f64::NAN), Some(f64::NAN)), MASKED);
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
        let mid = diverging(0.0);
        assert!(mid.iter().all(|&c| c > 230), "{mid:?}");
    }
}
