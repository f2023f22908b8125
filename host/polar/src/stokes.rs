//! Linear Stokes parameters, DoLP and AoLP from four analyser intensities, per pixel and per row.
//!
//! Formulas (Hagen et al., Opt. Eng. 58(8) 080501, 2019; `elerac/polanalyser: polanalyser/stokes.py`),
//! for intensities behind ideal analysers at 0°, 45°, 90°, 135°:
//!
//! ```text
//! s0 = ½(I0 + I45 + I90 + I135)     s1 = I0 − I90     s2 = I45 − I135
//! DoLP = √(s1² + s2²) / s0  ∈ [0, 1]
//! AoLP = ½·atan2(s2, s1) mod π  ∈ [0, π)
//! residual = I0 + I90 − I45 − I135  (0 for any physical light seen by ideal analysers)
//! ```
//!
//! Guards (documented clamps; no NaN or infinity is ever produced from finite input):
//! - DoLP divides by `max(s0, S0_FLOOR)`; where `s0 <= S0_FLOOR` DoLP is 0. A DoLP above
//!   `1 + DOLP_UNPHYSICAL_TOLERANCE` flags the pixel [`MaskReason::Unphysical`]; the output is
//!   clamped to 1.
//! - AoLP of unpolarised light (s1 = s2 = 0) is 0.
//! - Mean intensity s0/2 below the dark threshold flags [`MaskReason::Dark`] (DoLP is biased
//!   upward by noise there, docs/model.md §12).
//!
//! AoLP uses a polynomial `atan2` (Abramowitz & Stegun 4.4.49, |error| ≤ 2·10⁻⁸ rad before f32
//! rounding) so the row kernel vectorises; it is tested against `f64::atan2`.

use std::f32::consts::{FRAC_PI_2, PI};

use ellipso_model::mosaic::Channel;
use ellipso_model::optics::Stokes as SimStokes;
use ellipso_model::optics::measure::Analyser as SimAnalyser;

use super::calibration::StokesMatrix;
use super::channels::ObservationChannels;
use super::mask::{MaskReason, PixelMask};
use super::plane::Plane;

/// s0 at or below this (normalised units) counts as no light: DoLP 0, no division.
pub const S0_FLOOR: f32 = 1e-9;
/// DoLP may exceed 1 by this much from rounding before a pixel is flagged unphysical.
pub const DOLP_UNPHYSICAL_TOLERANCE: f32 = 1e-4;

/// `[s0, s1, s2]` from intensities `[I0, I45, I90, I135]`.
pub fn stokes_from_intensities(i: [f32; 4]) -> [f32; 3] {
    let [i0, i45, i90, i135] = i;
    [0.5 * (i0 + i45 + i90 + i135), i0 - i90, i45 - i135]
}

/// Degree of linear polarisation √(s1²+s2²)/s0, clamped to [0, 1]; 0 where `s0 <= S0_FLOOR`.
pub fn dolp(s0: f32, s1: f32, s2: f32) -> f32 {
    let raw = (s1 * s1 + s2 * s2).sqrt() / s0.max(S0_FLOOR);
    if s0 > S0_FLOOR { raw.min(1.0) } else { 0.0 }
}

/// Angle of linear polarisation ½·atan2(s2, s1) wrapped to [0, π), in radians; 0 when s1 = s2 = 0.
#[inline(always)]
pub fn aolp_rad(s1: f32, s2: f32) -> f32 {
    let half = 0.5 * atan2_fast(s2, s1);
    // −π/2 ≤ half ≤ π/2; `+ 0.0` turns −0 into +0; rounding of `half + π` can give exactly π.
    let wrapped = half + if half < 0.0 { PI } else { 0.0 };
    if wrapped >= PI { wrapped - PI } else { wrapped }
}

/// Intensity behind an ideal linear analyser at `theta_rad` for linear Stokes `[s0, s1, s2]`:
/// `I_θ = ½(s0 + s1 cos2θ + s2 sin2θ)`. Not a second copy of the model: this delegates to the
/// simulator's measurement model ([`ellipso_model::optics::measure::Analyser::intensity`]), the
/// one the renderer uses and this module inverts.
pub fn intensity_behind_analyser(stokes: [f64; 3], theta_rad: f64) -> f64 {
    let [s0, s1, s2] = stokes;
    SimAnalyser {
        angle_rad: theta_rad,
    }
    .intensity(SimStokes::new(s0, s1, s2, 0.0))
}

/// `atan2(y, x)` in (−π, π], branch-free, from the A&S 4.4.49 polynomial for atan on [0, 1].
/// Exact at 0 and at the axes; no NaN for finite input (0/0 is avoided by a `MIN_POSITIVE` floor).
#[inline(always)]
pub(crate) fn atan2_fast(y: f32, x: f32) -> f32 {
    // Abramowitz & Stegun 4.4.49: atan(a)/a = 1 + Σ c_k a^(2k), 0 ≤ a ≤ 1, |ε| ≤ 2e-8.
    #[expect(
        clippy::excessive_precision,
        reason = "coefficients exactly as published in A&S 4.4.49"
    )]
    const C: [f32; 8] = [
        -0.3333314528,
        0.1999355085,
        -0.1420889944,
        0.1065626393,
        -0.0752896400,
        0.0429096138,
        -0.0161657367,
        0.0028662257,
    ];
    let ax = x.abs();
    let ay = y.abs();
    let a = ax.min(ay) / ax.max(ay).max(f32::MIN_POSITIVE);
    let s = a * a;
    let mut p = C[7];
    for c in C[..7].iter().rev() {
        p = p * s + c;
    }
    let r = a + a * s * p;
    let r = if ay > ax { FRAC_PI_2 - r } else { r };
    let r = if x < 0.0 { PI - r } else { r };
    r.copysign(y)
}

/// Stokes, DoLP, AoLP, consistency residual, observation channels and mask of one image band.
///
/// All planes share one size. Values are in normalised units (1 = full scale minus dark level),
/// so `s0 ∈ [0, 2]` for unclipped data. Masked pixels hold finite values; check `mask`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StokesBand {
    /// Colour filter of this band (`None` for a mono sensor).
    pub colour: Option<Channel>,
    /// Total intensity s0 = ½(I0+I45+I90+I135).
    pub s0: Plane<f32>,
    /// s1 = I0 − I90 (horizontal minus vertical).
    pub s1: Plane<f32>,
    /// s2 = I45 − I135.
    pub s2: Plane<f32>,
    /// Degree of linear polarisation in [0, 1].
    pub dolp: Plane<f32>,
    /// Angle of linear polarisation in [0, π) radians, counter-clockwise from image-right.
    pub aolp_rad: Plane<f32>,
    /// Consistency residual I0 + I90 − I45 − I135.
    pub residual: Plane<f32>,
    /// Observation channel I^d = 2·I90 (cross-polarised: diffuse shading). I^s and I^α are not
    /// stored twice: see [`StokesBand::i_s`] and [`StokesBand::i_alpha_at`].
    pub i_d: Plane<f32>,
    /// Validity of each pixel.
    pub mask: Plane<PixelMask>,
}

impl StokesBand {
    /// Width in output pixels.
    pub fn width(&self) -> usize {
        self.s0.width()
    }

    /// Height in output pixels.
    pub fn height(&self) -> usize {
        self.s0.height()
    }

    /// Observation channel I^s = I0 − I90. It is s1 by definition (the same subtraction of the
    /// same two numbers), so this is the s1 plane, not a copy.
    pub fn i_s(&self) -> &Plane<f32> {
        &self.s1
    }

    /// Observation channel I^α = I135 − I45 at row-major index `i` (0 outside the plane). Equal
    /// to −s2 bit for bit (IEEE subtraction is antisymmetric), so it is not stored.
    pub fn i_alpha_at(&self, i: usize) -> f32 {
        self.s2.data().get(i).map_or(0.0, |v| -v)
    }

    /// The three observation channels as owned planes (allocates I^d, I^s and I^α copies).
    pub fn observation_channels(&self) -> ObservationChannels {
        let i_alpha = self.s2.data().iter().map(|v| -v).collect();
        ObservationChannels {
            i_d: self.i_d.clone(),
            i_s: self.s1.clone(),
            i_alpha: Plane::from_vec(self.width(), self.height(), i_alpha).unwrap_or_default(),
        }
    }

    /// Resizes every plane to `width × height`, keeping allocations.
    pub(crate) fn reshape(&mut self, colour: Option<Channel>, width: usize, height: usize) {
        self.colour = colour;
        for p in [
            &mut self.s0,
            &mut self.s1,
            &mut self.s2,
            &mut self.dolp,
            &mut self.aolp_rad,
            &mut self.residual,
            &mut self.i_d,
        ] {
            p.reshape(width, height);
        }
        self.mask.reshape(width, height);
    }

    /// Mutable row `y` of every output plane, for the row kernel.
    pub(crate) fn row_mut(&mut self, y: usize) -> StokesRow<'_> {
        let w = self.s0.width();
        let r = y * w..(y + 1) * w;
        StokesRow {
            s0: &mut self.s0.data_mut()[r.clone()],
            s1: &mut self.s1.data_mut()[r.clone()],
            s2: &mut self.s2.data_mut()[r.clone()],
            dolp: &mut self.dolp.data_mut()[r.clone()],
            aolp_rad: &mut self.aolp_rad.data_mut()[r.clone()],
            residual: &mut self.residual.data_mut()[r.clone()],
            i_d: &mut self.i_d.data_mut()[r.clone()],
            mask: &mut self.mask.data_mut()[r],
        }
    }
}

/// Thresholds the row kernel applies (normalised units), and the estimator it uses.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Thresholds {
    /// s0 below this is dark (twice the mean-intensity threshold).
    pub dark_s0: f32,
    /// |residual| above this is inconsistent (`f32::INFINITY` disables the check).
    pub max_residual: f32,
    /// Calibrated estimator; `None` is the exact ideal-analyser formulas.
    pub matrix: Option<StokesMatrix>,
}

/// One row of analyser intensities `[I0, I45, I90, I135]` and the mask they carry in.
pub(crate) struct AnalyserRow<'a> {
    pub intensity: [&'a [f32]; 4],
    pub mask: &'a [PixelMask],
}

/// One row of every output plane.
pub(crate) struct StokesRow<'a> {
    pub s0: &'a mut [f32],
    pub s1: &'a mut [f32],
    pub s2: &'a mut [f32],
    pub dolp: &'a mut [f32],
    pub aolp_rad: &'a mut [f32],
    pub residual: &'a mut [f32],
    pub i_d: &'a mut [f32],
    pub mask: &'a mut [PixelMask],
}

/// Computes one output row, with AVX2 where the CPU has it (same operations in the same order,
/// no FMA contraction, so results are bit-identical to the baseline SSE2 build).
pub(crate) fn stokes_row(input: AnalyserRow<'_>, out: StokesRow<'_>, t: Thresholds) {
    if let Some(matrix) = t.matrix {
        calibrated_row(input, out, t, &matrix);
        return;
    }
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above), the only requirement of
            // `stokes_row_avx2`.
            unsafe { stokes_row_avx2(input, out, t) };
            return;
        }
    }
    stokes_row_portable(input, out, t);
}

/// [`stokes_row_portable`] compiled for AVX2 (8 lanes instead of SSE2's 4).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn stokes_row_avx2(input: AnalyserRow<'_>, out: StokesRow<'_>, t: Thresholds) {
    stokes_row_portable(input, out, t);
}

/// The row kernel. All slices are cut to the output row length first, so the loop body has no
/// bounds checks and vectorises.
#[inline(always)]
fn stokes_row_portable(input: AnalyserRow<'_>, out: StokesRow<'_>, t: Thresholds) {
    let n = out.s0.len();
    let [i0, i45, i90, i135] = input.intensity;
    let (i0, i45, i90, i135, m_in) = (&i0[..n], &i45[..n], &i90[..n], &i135[..n], &input.mask[..n]);
    let (s0, s1, s2) = (&mut out.s0[..n], &mut out.s1[..n], &mut out.s2[..n]);
    let (dolp_out, aolp_out, res_out) = (
        &mut out.dolp[..n],
        &mut out.aolp_rad[..n],
        &mut out.residual[..n],
    );
    let (i_d, m_out) = (&mut out.i_d[..n], &mut out.mask[..n]);
    for k in 0..n {
        let (a0, a45, a90, a135) = (i0[k], i45[k], i90[k], i135[k]);
        let v0 = 0.5 * ((a0 + a90) + (a45 + a135));
        let v1 = a0 - a90;
        let v2 = a45 - a135;
        let residual = (a0 + a90) - (a45 + a135);
        let raw_dolp = (v1 * v1 + v2 * v2).sqrt() / v0.max(S0_FLOOR);
        let lit = v0 > S0_FLOOR;
        s0[k] = v0;
        s1[k] = v1;
        s2[k] = v2;
        dolp_out[k] = if lit { raw_dolp.min(1.0) } else { 0.0 };
        aolp_out[k] = aolp_rad(v1, v2);
        res_out[k] = residual;
        i_d[k] = 2.0 * a90;
        let dark = u8::from(v0 < t.dark_s0) * MaskReason::Dark.bit();
        let unphysical = u8::from(lit & (raw_dolp > 1.0 + DOLP_UNPHYSICAL_TOLERANCE))
            * MaskReason::Unphysical.bit();
        let inconsistent =
            u8::from(residual.abs() > t.max_residual) * MaskReason::Inconsistent.bit();
        m_out[k] = PixelMask(m_in[k].0 | dark | unphysical | inconsistent);
    }
}

/// Writes pixel `k` of `out` from an estimator's `[s0, s1, s2, residual]`: DoLP, AoLP, I^d and
/// the mask (the input's reasons with dark, unphysical and inconsistent added), as every
/// estimator's row writes them.
#[inline]
fn write_estimate(
    out: &mut StokesRow<'_>,
    k: usize,
    [v0, v1, v2, residual]: [f32; 4],
    mask_in: PixelMask,
    t: Thresholds,
) {
    let raw_dolp = (v1 * v1 + v2 * v2).sqrt() / v0.max(S0_FLOOR);
    let lit = v0 > S0_FLOOR;
    out.s0[k] = v0;
    out.s1[k] = v1;
    out.s2[k] = v2;
    out.dolp[k] = if lit { raw_dolp.min(1.0) } else { 0.0 };
    out.aolp_rad[k] = aolp_rad(v1, v2);
    out.residual[k] = residual;
    out.i_d[k] = v0 - v1;
    let dark = u8::from(v0 < t.dark_s0) * MaskReason::Dark.bit();
    let unphysical =
        u8::from(lit & (raw_dolp > 1.0 + DOLP_UNPHYSICAL_TOLERANCE)) * MaskReason::Unphysical.bit();
    let inconsistent = u8::from(residual.abs() > t.max_residual) * MaskReason::Inconsistent.bit();
    out.mask[k] = PixelMask(mask_in.0 | dark | unphysical | inconsistent);
}

/// Row kernel for calibrated analysers: `s = A⁺ I`, residual `= nᵀ I`, and the observation
/// channels of ideal analysers reconstructed from the corrected Stokes vector
/// (`I^d = s0 − s1`; I^s = s1 and I^α = −s2 as always).
#[expect(
    clippy::needless_range_loop,
    reason = "one index drives four input and eight output slices of equal length"
)]
fn calibrated_row(input: AnalyserRow<'_>, mut out: StokesRow<'_>, t: Thresholds, m: &StokesMatrix) {
    let n = out.s0.len();
    let [i0, i45, i90, i135] = input.intensity;
    let (i0, i45, i90, i135, m_in) = (&i0[..n], &i45[..n], &i90[..n], &i135[..n], &input.mask[..n]);
    let dot =
        |r: &[f32; 4], k: usize| r[0] * i0[k] + r[1] * i45[k] + r[2] * i90[k] + r[3] * i135[k];
    for k in 0..n {
        let (v0, v1, v2) = (dot(&m.rows[0], k), dot(&m.rows[1], k), dot(&m.rows[2], k));
        let residual = dot(&m.null, k);
        write_estimate(&mut out, k, [v0, v1, v2, residual], m_in[k], t);
    }
}

/// [`calibrated_row`] with each output pixel's own estimator and intensity offsets (a per-pixel
/// sensor calibration: `s = A⁺ (I − δ)`, residual `nᵀ(I − δ)`).
pub(crate) fn per_pixel_row(
    input: AnalyserRow<'_>,
    mut out: StokesRow<'_>,
    t: Thresholds,
    estimators: &[StokesMatrix],
    offsets: &[[f32; 4]],
) {
    let n = out.s0.len();
    let [i0, i45, i90, i135] = input.intensity;
    let (i0, i45, i90, i135, m_in) = (&i0[..n], &i45[..n], &i90[..n], &i135[..n], &input.mask[..n]);
    let (estimators, offsets) = (&estimators[..n], &offsets[..n]);
    for k in 0..n {
        let d = offsets[k];
        let i = [i0[k] - d[0], i45[k] - d[1], i90[k] - d[2], i135[k] - d[3]];
        let m = &estimators[k];
        let dot = |r: &[f32; 4]| r[0] * i[0] + r[1] * i[1] + r[2] * i[2] + r[3] * i[3];
        let (v0, v1, v2) = (dot(&m.rows[0]), dot(&m.rows[1]), dot(&m.rows[2]));
        let residual = dot(&m.null);
        write_estimate(&mut out, k, [v0, v1, v2, residual], m_in[k], t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn intensities(s: [f64; 3]) -> [f32; 4] {
        [0.0f64, 45.0, 90.0, 135.0].map(|deg| intensity_behind_analyser(s, deg.to_radians()) as f32)
    }

    #[test]
    fn textbook_intensities_give_textbook_stokes() {
        // I0 = ½(s0+s1), I45 = ½(s0+s2), I90 = ½(s0−s1), I135 = ½(s0−s2)
        let s = [1.0, 0.3, -0.4];
        let i = intensities(s);
        let expect = [0.65, 0.3, 0.35, 0.7];
        for (got, want) in i.iter().zip(expect) {
            assert!((got - want).abs() < 1e-7, "{i:?}");
        }
        let [s0, s1, s2] = stokes_from_intensities(i);
        assert!((s0 - 1.0).abs() < 1e-6 && (s1 - 0.3).abs() < 1e-6 && (s2 + 0.4).abs() < 1e-6);
        assert!((dolp(s0, s1, s2) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn fast_atan2_matches_f64_everywhere() {
        let mut worst = 0.0f64;
        for iy in -60..=60 {
            for ix in -60..=60 {
                let (y, x) = (iy as f32 * 0.37, ix as f32 * 0.41);
                let got = atan2_fast(y, x) as f64;
                let want = (y as f64).atan2(x as f64);
                worst = worst.max((got - want).abs());
            }
        }
        assert!(worst < 1e-6, "max error {worst} rad");
        assert_eq!(atan2_fast(0.0, 0.0), 0.0);
        assert_eq!(atan2_fast(0.0, -1.0), PI);
        assert_eq!(atan2_fast(1.0, 0.0), FRAC_PI_2);
        assert_eq!(atan2_fast(-1.0, 0.0), -FRAC_PI_2);
        assert!((atan2_fast(1e-30, 1e30)).abs() < 1e-30);
        assert!((atan2_fast(1e30, 1e-30) - FRAC_PI_2).abs() < 1e-7);
    }

    #[test]
    fn aolp_wraps_into_zero_to_pi() {
        for k in 0..3600 {
            let phi = k as f64 * 0.1f64.to_radians() - 1.0; // covers both sides of 0 and π
            let s1 = (2.0 * phi).cos() as f32;
            let s2 = (2.0 * phi).sin() as f32;
            let a = aolp_rad(s1, s2);
            assert!((0.0..PI).contains(&a), "{a} for φ={phi}");
            let want = phi.rem_euclid(std::f64::consts::PI);
            let diff = (a as f64 - want).abs();
            let diff = diff.min(std::f64::consts::PI - diff); // 0 and π are the same angle
            assert!(diff < 1e-6, "φ={phi} got {a}");
        }
        assert_eq!(aolp_rad(0.0, 0.0), 0.0);
        assert_eq!(aolp_rad(0.0, -0.0).to_bits(), 0.0f32.to_bits(), "no −0");
        assert!(aolp_rad(-1.0, -1e-9) < 1e-6 + FRAC_PI_2 && aolp_rad(-1.0, -1e-9) > 0.0);
        // just below the wrap: s2 → −0 with s1 > 0 gives an angle near π that must wrap to ≈ 0
        let a = aolp_rad(1.0, -1e-12);
        assert!(a < PI && (a < 1e-6 || PI - a < 1e-6), "{a}");
    }

    #[test]
    fn dolp_guards_dark_and_negative_s0() {
        assert_eq!(dolp(0.0, 0.0, 0.0), 0.0);
        assert_eq!(dolp(-0.01, 0.005, 0.0), 0.0);
        assert_eq!(dolp(1e-12, 1e-12, 0.0), 0.0);
        assert_eq!(dolp(1.0, 3.0, 4.0), 1.0, "clamped");
        assert!((dolp(2.0, 0.0, 1.0) - 0.5).abs() < 1e-7);
    }

    #[test]
    fn row_kernel_flags_dark_unphysical_and_inconsistent() {
        // pixel 0: fine; 1: dark; 2: unphysical (I0=I45=1, I90=I135=0); 3: inconsistent
        let i0 = [0.6, 0.0001, 1.0, 0.9];
        let i45 = [0.5, 0.0001, 1.0, 0.1];
        let i90 = [0.4, 0.0001, 0.0, 0.1];
        let i135 = [0.5, 0.0001, 0.0, 0.1];
        let m_in = [PixelMask::VALID; 4];
        let mut band = StokesBand::default();
        band.reshape(None, 4, 1);
        stokes_row(
            AnalyserRow {
                intensity: [&i0, &i45, &i90, &i135],
                mask: &m_in,
            },
            band.row_mut(0),
            Thresholds {
                dark_s0: 0.002,
                max_residual: 0.05,
                matrix: None,
            },
        );
        let m = band.mask.data();
        assert!(m[0].is_valid(), "{m:?}");
        assert_eq!(m[1], PixelMask::only(MaskReason::Dark));
        assert!(m[2].has(MaskReason::Unphysical) && !m[2].has(MaskReason::Inconsistent));
        assert!(m[3].has(MaskReason::Inconsistent));
        assert_eq!(band.dolp.data()[2], 1.0);
        assert!((band.residual.data()[3] - 0.8).abs() < 1e-6);
        assert!(
            band.s0
                .data()
                .iter()
                .chain(band.aolp_rad.data())
                .all(|v| v.is_finite())
        );
    }

    #[test]
    fn row_kernel_agrees_with_the_simulator_measurement_model() {
        use ellipso_model::optics::measure::SensorIntensities;
        use rand::{Rng, SeedableRng};
        // one model: the sensor angles and the Stokes/DoLP/AoLP/channel definitions of the
        // simulator are exactly what this module inverts
        let mosaic_deg = ellipso_model::mosaic::Analyser::ALL.map(|a| a.angle_deg());
        assert_eq!(mosaic_deg, SimAnalyser::SENSOR_ANGLES_DEG);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let n = 64;
        let mut stokes = Vec::new();
        let (mut i0, mut i45, mut i90, mut i135) = (vec![], vec![], vec![], vec![]);
        for _ in 0..n {
            let s0: f64 = rng.random_range(0.01..2.0);
            let p: f64 = rng.random_range(0.0..1.0);
            let phi: f64 = rng.random_range(0.0..std::f64::consts::PI);
            let s = SimStokes::new(
                s0,
                s0 * p * (2.0 * phi).cos(),
                s0 * p * (2.0 * phi).sin(),
                0.0,
            );
            let m = SensorIntensities::from_stokes(s);
            i0.push(m.i0 as f32);
            i45.push(m.i45 as f32);
            i90.push(m.i90 as f32);
            i135.push(m.i135 as f32);
            stokes.push((s, m));
        }
        let mut band = StokesBand::default();
        band.reshape(None, n, 1);
        let masks = vec![PixelMask::VALID; n];
        stokes_row(
            AnalyserRow {
                intensity: [&i0, &i45, &i90, &i135],
                mask: &masks,
            },
            band.row_mut(0),
            Thresholds {
                dark_s0: 0.0,
                max_residual: f32::INFINITY,
                matrix: None,
            },
        );
        for (k, (s, m)) in stokes.iter().enumerate() {
            let back = m.to_stokes();
            let obs = m.observation();
            let close = |a: f32, b: f64| (f64::from(a) - b).abs() < 2e-6;
            assert!(close(band.s0.data()[k], back.s0) && close(band.s1.data()[k], back.s1));
            assert!(close(band.s2.data()[k], back.s2));
            assert!((f64::from(band.dolp.data()[k]) - s.dolp()).abs() < 1e-5);
            if s.dolp() > 1e-3 {
                let d = (f64::from(band.aolp_rad.data()[k]) - s.aolp_rad())
                    .rem_euclid(std::f64::consts::PI);
                assert!(d.min(std::f64::consts::PI - d) < 1e-4, "AoLP {k}");
            }
            assert!(
                close(band.i_d.data()[k], obs.diffuse) && close(band.i_s().data()[k], obs.specular)
            );
            assert!(close(band.i_alpha_at(k), obs.alpha));
        }
    }
}
