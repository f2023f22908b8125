//! The limits of numeric command-line flags, checked when a flag is parsed so a bad value is one
//! error naming the flag (clap adds the flag's name) before anything is loaded or allocated.
//!
//! Limits are the same as the files that carry the same quantity:
//! - frame sides: even, `2..=16384` px, as `rig.camera.resolution_px` in scene files
//!   ([`ellipso_sim::scene::rig::MAX_SIDE_PX`]);
//! - supersampling: `1..=8` rays per axis ([`ellipso_sim::render::MAX_SUPERSAMPLING`]);
//! - counts of photos or frames: at least 1 (0 would do nothing and look like success);
//! - the photo interval: a finite number of ms in `(0, 3_600_000]`; the board then checks it
//!   against the exposure before anything is recorded;
//! - outer iterations of the fit: `1..=20` (each is a full solve and shape update);
//! - mesh vertex counts: `100..=2_000_000`;
//! - real-valued settings: finite, inside the range their help text states.

use std::fmt::Display;
use std::str::FromStr;

use ellipso_sim::render::MAX_SUPERSAMPLING;
use ellipso_sim::scene::rig::MAX_SIDE_PX;

/// Largest count of photos or frames a flag may ask for.
pub const MAX_COUNT: u64 = 1_000_000;
/// Largest number of outer fit iterations.
pub const MAX_OUTER: u64 = 20;
/// Largest mesh vertex count a flag may ask for (the fit holds ~60 samples of 56 B per vertex:
/// two million vertices are several GB).
pub const MAX_VERTICES: u64 = 2_000_000;
/// Longest photo interval, ms (one hour).
pub const MAX_INTERVAL_MS: f64 = 3_600_000.0;

/// An integer in `lo..=hi`.
fn integer_in<T>(s: &str, lo: u64, hi: u64) -> Result<T, String>
where
    T: TryFrom<u64>,
{
    let v: u64 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a whole number in {lo}..={hi}"))?;
    if !(lo..=hi).contains(&v) {
        return Err(format!("{v} is outside {lo}..={hi}"));
    }
    T::try_from(v).map_err(|_| format!("{v} is too large for this machine"))
}

/// A finite real in `[lo, hi]`.
pub fn real_in<T>(s: &str, lo: T, hi: T) -> Result<T, String>
where
    T: FromStr + PartialOrd + Display + Copy,
{
    let v: T = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number"))?;
    // NaN fails both comparisons; ±inf fails one
    if !(v >= lo && v <= hi) {
        return Err(format!("{s} is outside [{lo}, {hi}]"));
    }
    Ok(v)
}

/// A frame side, px: even, in `2..=16384`.
pub fn side_px(s: &str) -> Result<u32, String> {
    let v: u32 = integer_in(s, 2, u64::from(MAX_SIDE_PX))?;
    if v % 2 != 0 {
        return Err(format!(
            "{v} is odd: the 2×2 polariser mosaic needs even sizes"
        ));
    }
    Ok(v)
}

/// `WIDTHxHEIGHT`, each side as [`side_px`].
pub fn resolution(s: &str) -> Result<[u32; 2], String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or("expected WIDTHxHEIGHT, e.g. 1224x1024")?;
    Ok([side_px(w)?, side_px(h)?])
}

/// Rays per raw pixel per axis, `1..=8`.
pub fn supersampling(s: &str) -> Result<u32, String> {
    integer_in(s, 1, u64::from(MAX_SUPERSAMPLING))
}

/// A count of photos or frames, `1..=1_000_000`.
pub fn count<T: TryFrom<u64>>(s: &str) -> Result<T, String> {
    integer_in(s, 1, MAX_COUNT)
}

/// Outer fit iterations, `1..=20`.
pub fn outer_iterations(s: &str) -> Result<usize, String> {
    integer_in(s, 1, MAX_OUTER)
}

/// Views that must agree to carve a voxel, `1..=100`.
pub fn votes(s: &str) -> Result<usize, String> {
    integer_in(s, 1, 100)
}

/// Worker threads, `1..=256`.
pub fn threads(s: &str) -> Result<usize, String> {
    integer_in(s, 1, 256)
}

/// A mesh's target vertex count, `100..=2_000_000` (fewer cannot hold an object's shape; more
/// is beyond [`MAX_VERTICES`]).
pub fn vertices(s: &str) -> Result<usize, String> {
    integer_in(s, 100, MAX_VERTICES)
}

/// The silhouette edge inset of `ellipso mesh`, superpixels: finite, in `[0, 2]` (beyond two
/// pixels it would carve the object itself).
pub fn edge_inset_px(s: &str) -> Result<f64, String> {
    real_in(s, 0.0, 2.0)
}

/// The photo interval, ms: finite, in `(0, 3_600_000]`.
pub fn interval_ms(s: &str) -> Result<f64, String> {
    let v = real_in(s, 0.0, MAX_INTERVAL_MS)?;
    if v <= 0.0 {
        return Err(format!("{s}: the interval must be longer than 0 ms"));
    }
    Ok(v)
}

/// A fraction in `[0, 1]`.
pub fn unit_f32(s: &str) -> Result<f32, String> {
    real_in(s, 0.0, 1.0)
}

/// A non-negative DN level up to the 16-bit container's full scale.
pub fn dn_level(s: &str) -> Result<f32, String> {
    real_in(s, 0.0, 65_535.0)
}

/// A clock rate error, ppm, within ±1000 (no crystal is worse).
pub fn drift_ppm(s: &str) -> Result<f64, String> {
    real_in(s, -1_000.0, 1_000.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_match_the_files() {
        assert_eq!(resolution("320x256"), Ok([320, 256]));
        assert!(
            resolution("100000x100000")
                .unwrap_err()
                .contains("2..=16384")
        );
        assert!(resolution("321x256").unwrap_err().contains("odd"));
        assert!(resolution("0x0").is_err());
        assert!(resolution("-4x4").is_err());
        assert_eq!(supersampling("8"), Ok(8));
        assert!(supersampling("9").is_err() && supersampling("0").is_err());
        assert!(count::<usize>("0").is_err());
        assert_eq!(count::<u32>("12"), Ok(12));
        assert!(count::<u32>("4294967296").is_err());
        assert!(outer_iterations("4294967295").is_err());
        assert_eq!(outer_iterations("2"), Ok(2));
        assert_eq!(vertices("300000"), Ok(300_000));
        assert!(vertices("8").is_err() && vertices("3000000").is_err());
        for bad in ["0", "-5", "nan", "inf", "1e300", "abc"] {
            assert!(interval_ms(bad).is_err(), "{bad}");
        }
        assert_eq!(interval_ms("50"), Ok(50.0));
        assert!(unit_f32("NaN").is_err() && unit_f32("1.5").is_err());
        assert!(drift_ppm("-inf").is_err());
        for bad in ["0", "99", "10000000", "-1"] {
            assert!(vertices(bad).is_err(), "{bad}");
        }
        assert!(threads("100000").is_err() && threads("0").is_err());
        assert_eq!(votes("3"), Ok(3));
    }
}
