//! The analyser stage of a sensor measurement (step 3 of the parent's doc): the polariser-sheet
//! flats fitted per pixel, divided by the vignetting and normalised per band into analysis
//! vectors, then each pixel's record and the analysers' figures (extinction ratio per band,
//! angle errors per analyser). A pixel clipped in any flat or sheet frame, or whose fit is not
//! usable, keeps the ideal analysis vector of its nominal analyser.

use super::radiometry::{Darks, Vignetting};
use super::{Frames, Grid, MeasureError, band_of};
use crate::sensor_calibration::PixelRecord;

/// What the polariser-sheet flats give.
pub(super) struct Analysers {
    /// One record per raw pixel.
    pub pixels: Vec<PixelRecord>,
    /// Pixels that kept their nominal analyser's ideal vector.
    pub ideal_kept: u64,
    /// Extinction ratio per band, from its mean diattenuation (infinite at 1 or above).
    pub extinction_ratio: Vec<f64>,
    /// Mean angle error per analyser (0°, 45°, 90°, 135°), radians.
    pub angle_mean_rad: [f64; 4],
    /// Sd of the angle errors about their analyser's mean, radians.
    pub angle_sd_rad: f64,
}

impl Analysers {
    /// Reads the sheet frames `sheets` (`(polariser_deg, file)`), marking the pixels they clip
    /// in `clipped`, and makes every pixel's analysis vector and the analysers' figures.
    pub fn measure(
        frames: &Frames,
        sheets: &[(f64, &str)],
        grid: Grid,
        darks: &Darks,
        clipped: &mut [bool],
        vignetting: &Vignetting,
    ) -> Result<Self, MeasureError> {
        let vectors = analysis_vectors(frames, sheets, grid, darks, clipped, vignetting)?;
        Ok(pixel_records(grid, darks, clipped, &vectors))
    }
}

/// The analysis vectors before the band normalisation.
struct Unnormalised {
    /// Each pixel's sheet fit ÷ its vignetting.
    analysis: Vec<[f64; 3]>,
    /// Per band: the sum of the usable pixels' parallel transmissions `a0 + |(a1, a2)|` and
    /// their count.
    norm: Vec<(f64, f64)>,
}

/// Fits each pixel's sheet signal above dark against `[1, cos2φ, sin2φ]` and divides out the
/// vignetting; a singular design is [`MeasureError::Degenerate`].
fn analysis_vectors(
    frames: &Frames,
    sheets: &[(f64, &str)],
    grid: Grid,
    darks: &Darks,
    clipped: &mut [bool],
    vignetting: &Vignetting,
) -> Result<Unnormalised, MeasureError> {
    let (w, n, full_scale, layout) = (grid.width, grid.n, grid.full_scale, grid.layout);
    let dark = &darks.dark;
    let mut design = [[0.0f64; 3]; 3];
    let mut acc = vec![[0.0f64; 3]; n];
    for (deg, file) in sheets {
        let (s2, c2) = (2.0 * deg.to_radians()).sin_cos();
        let v = [1.0, c2, s2];
        for r in 0..3 {
            for c in 0..3 {
                design[r][c] += v[r] * v[c];
            }
        }
        let x = frames.read(file)?;
        for i in 0..n {
            let val = f64::from(x[i]);
            if val >= full_scale {
                clipped[i] = true;
            }
            let y = val - dark[i];
            for (a, vr) in acc[i].iter_mut().zip(v) {
                *a += y * vr;
            }
        }
    }
    let inv = invert3(design).ok_or_else(|| {
        MeasureError::Degenerate("the polariser-sheet angles do not separate s1 from s2".into())
    })?;
    let bands = if layout.colour_at(0, 0).is_some() {
        3
    } else {
        1
    };
    let mut analysis = vec![[0.0f64; 3]; n];
    let mut norm = vec![(0.0f64, 0.0f64); bands];
    for i in 0..n {
        let b: [f64; 3] = std::array::from_fn(|r| (0..3).map(|c| inv[r][c] * acc[i][c]).sum());
        let v = vignetting.cos_field[i].powf(vignetting.exponent);
        analysis[i] = b.map(|c| c / v);
        if darks.cold(i) && !clipped[i] {
            let (x, y) = ((i % w) as u32, (i / w) as u32);
            let a = analysis[i];
            let e = &mut norm[band_of(layout, x, y)];
            e.0 += a[0] + a[1].hypot(a[2]);
            e.1 += 1.0;
        }
    }
    Ok(Unnormalised { analysis, norm })
}

/// Normalises each pixel's analysis vector by its band's `norm` (or keeps its nominal
/// analyser's ideal vector), makes its record and gathers the analysers' figures.
fn pixel_records(grid: Grid, darks: &Darks, clipped: &[bool], vectors: &Unnormalised) -> Analysers {
    let (w, n, layout) = (grid.width, grid.n, grid.layout);
    let (analysis, norm) = (&vectors.analysis, &vectors.norm);
    let mut diattenuation = vec![(0.0f64, 0.0f64); norm.len()];
    let mut angle_sum = [(0.0f64, 0.0f64); 4];
    let mut angle_errors = Vec::with_capacity(n);
    let mut ideal_kept = 0u64;
    let mut pixels = Vec::with_capacity(n);
    for i in 0..n {
        let (x, y) = ((i % w) as u32, (i / w) as u32);
        let band = band_of(layout, x, y);
        let analyser = layout.analyser_at(x, y);
        let (t, count) = norm[band];
        let mut a = analysis[i].map(|c| c * count / t);
        if clipped[i] || !a.iter().all(|c| c.is_finite()) || a[0] <= 0.0 {
            let (s2, c2) = (2.0 * analyser.angle_rad()).sin_cos();
            a = [0.5, 0.5 * c2, 0.5 * s2];
            ideal_kept += 1;
        } else if darks.cold(i) {
            let amp = a[1].hypot(a[2]);
            let d = &mut diattenuation[band];
            d.0 += amp / a[0];
            d.1 += 1.0;
            let angle = 0.5 * a[2].atan2(a[1]);
            let err = (angle - analyser.angle_rad() + std::f64::consts::FRAC_PI_2)
                .rem_euclid(std::f64::consts::PI)
                - std::f64::consts::FRAC_PI_2;
            let k = analyser.index();
            angle_sum[k].0 += err;
            angle_sum[k].1 += 1.0;
            angle_errors.push((k, err));
        }
        pixels.push(PixelRecord {
            dark_dn: darks.dark[i] as f32,
            analysis: a.map(|c| c as f32),
        });
    }
    let angle_mean: [f64; 4] = angle_sum.map(|(s, c)| if c > 0.0 { s / c } else { 0.0 });
    let angle_sd = (angle_errors
        .iter()
        .map(|(k, e)| (e - angle_mean[*k]).powi(2))
        .sum::<f64>()
        / (angle_errors.len() as f64).max(1.0))
    .sqrt();
    let extinction_ratio = diattenuation
        .iter()
        .map(|(s, c)| {
            let d = s / c.max(1.0);
            if d < 1.0 {
                (1.0 + d) / (1.0 - d)
            } else {
                f64::INFINITY
            }
        })
        .collect();
    Analysers {
        pixels,
        ideal_kept,
        extinction_ratio,
        angle_mean_rad: angle_mean,
        angle_sd_rad: angle_sd,
    }
}

/// Inverse of a symmetric 3×3 matrix by cofactors (`None` when singular: |det| at most 1e-9 of
/// the scale).
fn invert3(m: [[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let det = crate::calibration::det3(m);
    let scale = m
        .iter()
        .flatten()
        .fold(0.0f64, |a, v| a.max(v.abs()))
        .powi(3);
    if det.is_nan() || det.abs() <= 1e-9 * scale {
        return None;
    }
    Some(crate::calibration::adjugate_over(m, det))
}
