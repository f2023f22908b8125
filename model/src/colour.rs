//! The sRGB transfer function: linear light → 8-bit sRGB code value, for every picture ellipso
//! writes or serves (fit colours in `fit.ply`, the live view's frames).
//!
//! Contract: [`srgb_u8`] encodes with the IEC 61966-2-1 piecewise curve — `12.92·L` for
//! `L ≤ 0.0031308`, `1.055·L^(1/2.4) − 0.055` above — after clamping `L` to [0, 1] (NaN and ±∞
//! give 0), then rounds `255·V` to the nearest code. It is total: any f64 gives a code.
//!
//! Not a crate dependency: `palette` would bring a colour-space framework for one curve.

/// The 8-bit sRGB code of a linear value (IEC 61966-2-1; clamped to [0, 1], non-finite → 0).
pub fn srgb_u8(linear: f64) -> u8 {
    let l = if linear.is_finite() {
        linear.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if l <= 0.003_130_8 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_is_total_and_monotone() {
        assert_eq!(srgb_u8(0.0), 0);
        assert_eq!(srgb_u8(1.0), 255);
        assert_eq!(srgb_u8(f64::NAN), 0);
        assert_eq!(srgb_u8(f64::INFINITY), 0);
        assert_eq!(srgb_u8(-3.0), 0);
        assert_eq!(srgb_u8(7.0), 255);
        // linear 18 % grey is code 118, linear ½ is 188
        assert_eq!(srgb_u8(0.18), 118);
        assert_eq!(srgb_u8(0.5), 188);
        let mut last = 0;
        for i in 0..=1000 {
            let c = srgb_u8(f64::from(i) / 1000.0);
            assert!(c >= last);
            last = c;
        }
    }
}
