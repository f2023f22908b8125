//! Colour maps shared by every false-colour picture: viridis for magnitudes, a blue–white–red
//! map for signed values, a cyclic map for angles, grey, and the HSV composite of angle of
//! linear polarisation (hue) and degree of linear polarisation (saturation).
//!
//! Contract: every function takes any value (NaN and infinities included) and returns a valid
//! sRGB colour; a map's argument is clamped to [0, 1]. The sequential and diverging maps are
//! `colorous`' (d3-scale-chromatic's) viridis and RdBu; the cyclic map is colorous' sinebow,
//! whose ends meet.

/// An sRGB colour.
pub type Rgb = [u8; 3];

/// Pixels without a value (background, unfitted, masked): mid-grey, no hue.
pub const NO_DATA: Rgb = [96, 96, 96];

/// A colour map over [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColourMap {
    /// Perceptually uniform, dark blue → yellow.
    Viridis,
    /// Signed values: blue (0) → white (½) → red (1).
    Diverging,
    /// Angles: a cyclic hue wheel whose ends meet (the value is a fraction of the period).
    Cyclic,
    /// Black (0) → white (1).
    Grey,
}

impl ColourMap {
    /// The colour of `t` ∈ [0, 1] (clamped); NaN gives the colour of 0.
    pub fn at(self, t: f64) -> Rgb {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let c = match self {
            ColourMap::Viridis => colorous::VIRIDIS.eval_continuous(t),
            // colorous' RdBu runs red → blue; signed maps read blue for negative
            ColourMap::Diverging => colorous::RED_BLUE.eval_continuous(1.0 - t),
            ColourMap::Cyclic => colorous::SINEBOW.eval_continuous(t),
            ColourMap::Grey => {
                let v = unit_to_u8(t);
                return [v, v, v];
            }
        };
        [c.r, c.g, c.b]
    }
}

/// HSV → sRGB: `hue_turns` in turns (any value, wrapped; NaN is red), saturation and value in
/// [0, 1] (clamped; NaN is 0).
pub fn hsv(hue_turns: f64, saturation: f64, value: f64) -> Rgb {
    let unit = |x: f64| if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    let h = if hue_turns.is_finite() {
        hue_turns.rem_euclid(1.0) * 6.0
    } else {
        0.0
    };
    let (s, v) = (unit(saturation), unit(value));
    let sector = (h.floor() as u8).min(5);
    let f = h - h.floor();
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match sector {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [unit_to_u8(r), unit_to_u8(g), unit_to_u8(b)]
}

/// The AoLP/DoLP composite polarisation-camera users know (polanalyser's `applyColorToAoLP`
/// with saturation = DoLP): hue = AoLP over [0, π) once round the wheel (0 and π meet, red),
/// saturation = DoLP, value = `value` (1 for the plain composite). Unpolarised light is white.
pub fn aolp_dolp(aolp_rad: f64, dolp: f64, value: f64) -> Rgb {
    hsv(aolp_rad / std::f64::consts::PI, dolp, value)
}

/// The one colouring of DoLP every picture and the view use: viridis over [0, 1]; `None` (a
/// masked pixel: dark, saturated, …, whose DoLP is noise) is the pictures' no-data grey
/// ([`NO_DATA`]).
pub fn dolp_colour(dolp: Option<f64>) -> Rgb {
    dolp.filter(|d| d.is_finite())
        .map_or(NO_DATA, |d| ColourMap::Viridis.at(d))
}

/// The one AoLP colouring every picture and the view use: [`aolp_dolp`] with value 1 (hue =
/// AoLP, saturation = DoLP: unpolarised light is white); `None` (a masked pixel) is the
/// no-data grey.
pub fn aolp_colour(aolp_rad: Option<f64>, dolp: Option<f64>) -> Rgb {
    match (aolp_rad, dolp) {
        (Some(a), Some(d)) if a.is_finite() && d.is_finite() => aolp_dolp(a, d, 1.0),
        _ => NO_DATA,
    }
}

/// `round(255·t)` for `t` clamped to [0, 1]; NaN gives 0.
pub fn unit_to_u8(t: f64) -> u8 {
    if t.is_nan() {
        0
    } else {
        (t.clamp(0.0, 1.0) * 255.0).round() as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_are_total_and_ordered() {
        for map in [
            ColourMap::Viridis,
            ColourMap::Diverging,
            ColourMap::Cyclic,
            ColourMap::Grey,
        ] {
            for t in [-1.0, 0.0, 0.3, 1.0, 2.0, f64::NAN, f64::INFINITY] {
                let _ = map.at(t);
            }
        }
        let lum = |c: Rgb| c.iter().map(|&x| u32::from(x)).sum::<u32>();
        let v = ColourMap::Viridis;
        assert!(lum(v.at(0.0)) < lum(v.at(0.5)) && lum(v.at(0.5)) < lum(v.at(1.0)));
        // diverging: near-white in the middle, blue below, red above
        let mid = ColourMap::Diverging.at(0.5);
        assert!(mid.iter().all(|&c| c > 230), "{mid:?}");
        let (lo, hi) = (ColourMap::Diverging.at(0.0), ColourMap::Diverging.at(1.0));
        assert!(lo[2] > lo[0] && hi[0] > hi[2], "{lo:?} {hi:?}");
        // cyclic: the ends meet
        let (a, b) = (ColourMap::Cyclic.at(0.0), ColourMap::Cyclic.at(1.0));
        assert!(
            a.iter().zip(b).all(|(x, y)| x.abs_diff(y) <= 2),
            "{a:?} {b:?}"
        );
        assert_eq!(ColourMap::Grey.at(0.5), [128; 3]);
    }

    #[test]
    fn hsv_hits_primaries_and_aolp_dolp_fades_to_white() {
        assert_eq!(hsv(0.0, 1.0, 1.0), [255, 0, 0]);
        assert_eq!(hsv(1.0, 1.0, 1.0), hsv(0.0, 1.0, 1.0));
        assert_eq!(hsv(1.0 / 3.0, 1.0, 1.0), [0, 255, 0]);
        assert_eq!(hsv(2.0 / 3.0, 1.0, 1.0), [0, 0, 255]);
        assert_eq!(hsv(0.25, 1.0, 0.0), [0, 0, 0]);
        assert_eq!(hsv(f64::NAN, f64::NAN, f64::NAN), [0, 0, 0]);
        // AoLP 0 and π are the same direction: the same colour
        assert_eq!(
            aolp_dolp(0.0, 1.0, 1.0),
            aolp_dolp(std::f64::consts::PI, 1.0, 1.0)
        );
        // DoLP 0: white whatever the angle; DoLP 1 at 90°: cyan (half way round)
        assert_eq!(aolp_dolp(1.0, 0.0, 1.0), [255, 255, 255]);
        assert_eq!(
            aolp_dolp(std::f64::consts::FRAC_PI_2, 1.0, 1.0),
            [0, 255, 255]
        );
    }
}
