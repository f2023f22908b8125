//! Measuring a sensor calibration from a captures folder (`ellipso calibrate sensor`).
//!
//! Method (docs/sensor-calibration.md; EMVA 1288 Release 4 for the radiometry, the
//! analysis-matrix calibration of division-of-focal-plane polarimeters for the analysers):
//! 1. **Dark frames** (≥ 2): each pixel's mean is its dark level; the median and robust sd of
//!    those give the hot pixels (above median + max(10 σ, 5 DN)); the black level is the mean
//!    of the others, the DSNU their spatial sd with the temporal part `σ²_d / n` removed; the
//!    temporal dark variance σ²_d is the mean per-pixel variance.
//! 2. **Flats** (≥ 2 levels, ≥ 2 frames each): per level the mean signal above dark μ and the
//!    temporal variance σ² from differences of frame pairs (`½(x₁ − x₂)²`, which cancels every
//!    fixed pattern); the conversion gain K is the least-squares slope through the origin of
//!    `σ² − σ²_d` against μ over the levels below 70 % of the range with no clipped pixel
//!    (EMVA's linear range). Read noise = `√(σ²_d − 1/12)` DN (quantisation removed), ÷ K in e⁻.
//!    Each pixel's response r_p is the slope through the origin of its mean signal against the
//!    level; `ln r_p = c_(band, analyser) + n · ln cos θ_p + ln PRNU_p` fitted within the
//!    (band, analyser) groups gives the vignetting exponent n (θ_p the field angle of the
//!    pixel's centre through the lens model of the captures), the residual's sd, less the
//!    temporal noise of r_p, the PRNU.
//! 3. **Polariser-sheet flats** (≥ 4 distinct angles): per pixel, least squares of its signal
//!    above dark against `[1, cos2φ, sin2φ]` gives `L · v_p · a_p`; dividing by the vignetting
//!    `cos^n θ_p` and normalising each band's mean parallel transmission `a0 + |(a1, a2)|` to 1
//!    gives the analysis vectors (the sheet is taken as ideal: its own extinction ratio, if
//!    finite, lowers every pixel's measured diattenuation alike).
//!
//! Contract: every frame is read once, in manifest order, with accumulators of a few f64 per
//! pixel (no frame kept but the previous flat of a pair). Missing captures are an error that
//! names the photos to take; a pixel clipped in any flat or sheet frame keeps the ideal
//! analysis vector of its nominal analyser and is counted.

use std::collections::BTreeMap;
use std::path::Path;

use ellipso_model::mosaic::SensorLayout;
use ellipso_session::calibration_captures::{CaptureKind, CaptureSet};

use super::{
    FORMAT, PhotonTransferPoint, PixelRecord, SensorCalibration, SensorFigures, SensorHeader,
    VERSION,
};

/// Settings of a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasureOptions {
    /// Upper end of the photon transfer fit, fraction of the range above the black level
    /// (EMVA 1288 fits the linear part, below about 70 % of saturation).
    pub photon_transfer_max_fraction: f64,
}

impl Default for MeasureOptions {
    fn default() -> Self {
        MeasureOptions {
            photon_transfer_max_fraction: 0.7,
        }
    }
}

/// Why a measurement cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum MeasureError {
    /// A frame cannot be read or does not match the manifest's sensor.
    #[error("{file}: {what}")]
    Frame {
        /// The frame file.
        file: String,
        /// What is wrong.
        what: String,
    },
    /// Captures are missing; says which photos to take.
    #[error("{what}; take: {photos}")]
    Missing {
        /// What cannot be measured.
        what: String,
        /// The photos to take.
        photos: String,
    },
    /// The data does not determine a figure.
    #[error("{0}")]
    Degenerate(String),
}

struct Frames<'a> {
    dir: &'a Path,
    set: &'a CaptureSet,
}

impl Frames<'_> {
    fn read(&self, file: &str) -> Result<Vec<u16>, MeasureError> {
        let s = &self.set.sensor;
        let (w, h, px) = ellipso_session::frame_png::read(&self.dir.join(file)).map_err(|e| {
            MeasureError::Frame {
                file: file.into(),
                what: e.to_string(),
            }
        })?;
        if (w, h) != (s.width, s.height) {
            return Err(MeasureError::Frame {
                file: file.into(),
                what: format!(
                    "{w}×{h} px, the manifest's sensor is {}×{}",
                    s.width, s.height
                ),
            });
        }
        Ok(px)
    }
}

fn band_of(layout: SensorLayout, x: u32, y: u32) -> usize {
    layout.colour_at(x, y).map_or(0, |c| c.index())
}

/// Measures the calibration of the captures in `dir` described by `set` (module doc).
pub fn measure(
    dir: &Path,
    set: &CaptureSet,
    options: MeasureOptions,
) -> Result<SensorCalibration, MeasureError> {
    let frames = Frames { dir, set };
    let s = &set.sensor;
    let (w, h) = (s.width as usize, s.height as usize);
    let n = w * h;
    let full_scale = f64::from((1u32 << u32::from(s.bit_depth)) - 1);
    let layout = s.layout;
    let mut darks = Vec::new();
    let mut flats: BTreeMap<u64, (f64, Vec<&str>)> = BTreeMap::new();
    let mut sheets = Vec::new();
    for f in &set.frames {
        match f.kind {
            CaptureKind::Dark => darks.push(f.file.as_str()),
            CaptureKind::Flat { level_rel } => flats
                .entry(level_rel.to_bits())
                .or_insert((level_rel, Vec::new()))
                .1
                .push(f.file.as_str()),
            CaptureKind::Polariser { polariser_deg } => {
                sheets.push((polariser_deg, f.file.as_str()))
            }
        }
    }
    if darks.len() < 2 {
        return Err(MeasureError::Missing {
            what: format!("{} dark frame(s): black level, DSNU and read noise need ≥ 2", darks.len()),
            photos: "16 frames with the lens capped and the flash off, at the object capture's exposure and gain".into(),
        });
    }
    let levels: Vec<&(f64, Vec<&str>)> = flats.values().filter(|(_, f)| f.len() >= 2).collect();
    if levels.len() < 2 {
        return Err(MeasureError::Missing {
            what: format!("{} flat level(s) with ≥ 2 frames: the photon transfer needs ≥ 2", levels.len()),
            photos: "a light panel filling the view, 4 frames at each of 8 exposures from dim to about 70 % of saturation".into(),
        });
    }
    let mut angles: Vec<f64> = sheets.iter().map(|(a, _)| a.rem_euclid(180.0)).collect();
    angles.sort_by(f64::total_cmp);
    angles.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    if angles.len() < 4 {
        return Err(MeasureError::Missing {
            what: format!("{} polariser-sheet angle(s): the analysis vectors need ≥ 4", angles.len()),
            photos: "the light panel through a linear polariser sheet in front of the lens, 16 frames at each of 8 angles 22.5° apart".into(),
        });
    }

    // 1. darks
    let mut sum = vec![0.0f64; n];
    let mut sum2 = vec![0.0f64; n];
    for file in &darks {
        for (i, v) in frames.read(file)?.into_iter().enumerate() {
            let v = f64::from(v);
            sum[i] += v;
            sum2[i] += v * v;
        }
    }
    let nd = darks.len() as f64;
    let dark: Vec<f64> = sum.iter().map(|s| s / nd).collect();
    let var_t: Vec<f64> = sum2
        .iter()
        .zip(&dark)
        .map(|(s2, m)| ((s2 - nd * m * m) / (nd - 1.0)).max(0.0))
        .collect();
    drop((sum, sum2));
    let mut sorted = dark.clone();
    let median = ellipso_model::stats::median(&mut sorted);
    let sigma = ellipso_model::stats::robust_sigma(&mut sorted);
    let hot_threshold = median + (10.0 * sigma).max(5.0);
    let hot: Vec<bool> = dark.iter().map(|d| *d > hot_threshold).collect();
    let cold = |i: usize| !hot[i];
    let n_cold = (0..n).filter(|&i| cold(i)).count().max(1) as f64;
    let black = (0..n).filter(|&i| cold(i)).map(|i| dark[i]).sum::<f64>() / n_cold;
    let var_dark_t = (0..n).filter(|&i| cold(i)).map(|i| var_t[i]).sum::<f64>() / n_cold;
    let var_spatial = (0..n)
        .filter(|&i| cold(i))
        .map(|i| (dark[i] - black).powi(2))
        .sum::<f64>()
        / (n_cold - 1.0).max(1.0);
    let dsnu = (var_spatial - var_dark_t / nd).max(0.0).sqrt();

    // 2. flats
    let mut clipped = vec![false; n];
    let mut resp = vec![0.0f64; n];
    let mut sum_l2 = 0.0;
    let mut points = Vec::new();
    let mut level_frames = Vec::new();
    for (level, files) in &levels {
        let nl = files.len() as f64;
        sum_l2 += level * level;
        let (mut mu, mut mu_n) = (0.0f64, 0.0f64);
        let (mut var, mut var_n) = (0.0f64, 0.0f64);
        let mut clipped_here = 0usize;
        let mut previous: Option<Vec<u16>> = None;
        for file in files {
            let x = frames.read(file)?;
            for i in 0..n {
                let v = f64::from(x[i]);
                if v >= full_scale {
                    clipped[i] = true;
                    clipped_here += 1;
                }
                resp[i] += level * (v - dark[i]) / nl;
                if cold(i) {
                    mu += v - dark[i];
                    mu_n += 1.0;
                }
            }
            match previous.take() {
                Some(p) => {
                    for i in (0..n).filter(|&i| cold(i)) {
                        let d = f64::from(x[i]) - f64::from(p[i]);
                        var += 0.5 * d * d;
                        var_n += 1.0;
                    }
                }
                None => previous = Some(x),
            }
        }
        points.push(PhotonTransferPoint {
            level_rel: *level,
            mean_dn: mu / mu_n.max(1.0),
            variance_dn2: var / var_n.max(1.0),
        });
        level_frames.push((*level, nl, clipped_here));
    }
    let range = full_scale - black;
    let usable: Vec<&PhotonTransferPoint> = points
        .iter()
        .zip(&level_frames)
        .filter(|(p, (_, _, c))| {
            *c == 0 && p.mean_dn <= options.photon_transfer_max_fraction * range
        })
        .map(|(p, _)| p)
        .collect();
    if usable.len() < 2 {
        return Err(MeasureError::Missing {
            what: format!(
                "{} flat level(s) below {:.0} % of the range without clipping: the gain needs ≥ 2",
                usable.len(),
                100.0 * options.photon_transfer_max_fraction
            ),
            photos: "more flat levels between 5 % and 70 % of saturation (shorter exposures)"
                .into(),
        });
    }
    let k_num: f64 = usable
        .iter()
        .map(|p| p.mean_dn * (p.variance_dn2 - var_dark_t))
        .sum();
    let k_den: f64 = usable.iter().map(|p| p.mean_dn * p.mean_dn).sum();
    let gain = k_num / k_den;
    if !(gain.is_finite() && gain > 0.0) {
        return Err(MeasureError::Degenerate(format!(
            "photon transfer gives a conversion gain of {gain} DN/e⁻: the flats' variance does not rise with their signal"
        )));
    }
    let read_noise_dn = (var_dark_t - 1.0 / 12.0).max(0.0).sqrt();
    let saturation_dn = match points
        .iter()
        .zip(&level_frames)
        .filter(|(_, (_, _, c))| *c > 0)
        .count()
    {
        0 => range,
        _ => points
            .iter()
            .max_by(|a, b| a.variance_dn2.total_cmp(&b.variance_dn2))
            .map_or(range, |p| p.mean_dn),
    };
    for r in &mut resp {
        *r /= sum_l2;
    }

    // vignetting and PRNU
    let cos_field: Vec<f64> = (0..n)
        .map(|i| {
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            set.camera
                .unproject_to_ray([x, y])
                .map_or(1.0, |d| d.z.clamp(1e-6, 1.0))
        })
        .collect();
    let group = |i: usize| {
        let (x, y) = ((i % w) as u32, (i / w) as u32);
        band_of(layout, x, y) * 4 + layout.analyser_at(x, y).index()
    };
    let good = |i: usize| cold(i) && !clipped[i] && resp[i] > 0.0;
    let mut gx = [0.0f64; 12];
    let mut gy = [0.0f64; 12];
    let mut gn = [0.0f64; 12];
    for i in (0..n).filter(|&i| good(i)) {
        let g = group(i);
        gx[g] += cos_field[i].ln();
        gy[g] += resp[i].ln();
        gn[g] += 1.0;
    }
    for g in 0..12 {
        if gn[g] > 0.0 {
            gx[g] /= gn[g];
            gy[g] /= gn[g];
        }
    }
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for i in (0..n).filter(|&i| good(i)) {
        let g = group(i);
        let dx = cos_field[i].ln() - gx[g];
        sxy += dx * (resp[i].ln() - gy[g]);
        sxx += dx * dx;
    }
    // a lens with no field (sxx = 0) cannot show vignetting: exponent 0
    let exponent = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let (mut res2, mut noise2, mut m) = (0.0f64, 0.0f64, 0.0f64);
    for i in (0..n).filter(|&i| good(i)) {
        let g = group(i);
        let r = resp[i].ln() - gy[g] - exponent * (cos_field[i].ln() - gx[g]);
        res2 += r * r;
        // var(r_p) = Σ_L L² var(mean_L) / (Σ L²)², var(mean_L) = (K r_p L + σ²_d) / n_L
        let var_r: f64 = level_frames
            .iter()
            .map(|(l, nl, _)| l * l * (gain * resp[i] * l + var_dark_t) / nl)
            .sum::<f64>()
            / (sum_l2 * sum_l2);
        noise2 += var_r / (resp[i] * resp[i]);
        m += 1.0;
    }
    let prnu = ((res2 - noise2) / m.max(1.0)).max(0.0).sqrt();

    // 3. polariser-sheet flats
    let mut design = [[0.0f64; 3]; 3];
    let mut acc = vec![[0.0f64; 3]; n];
    for (deg, file) in &sheets {
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
        let v = cos_field[i].powf(exponent);
        analysis[i] = b.map(|c| c / v);
        if cold(i) && !clipped[i] {
            let (x, y) = ((i % w) as u32, (i / w) as u32);
            let a = analysis[i];
            let e = &mut norm[band_of(layout, x, y)];
            e.0 += a[0] + a[1].hypot(a[2]);
            e.1 += 1.0;
        }
    }
    let mut diattenuation = vec![(0.0f64, 0.0f64); bands];
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
        } else if cold(i) {
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
            dark_dn: dark[i] as f32,
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
    let figures = SensorFigures {
        gain_dn_per_e: gain,
        gain_e_per_dn: 1.0 / gain,
        read_noise_dn,
        read_noise_e: read_noise_dn / gain,
        black_level_dn: black,
        dsnu_dn: dsnu,
        prnu_rel: prnu,
        saturation_dn,
        saturation_e: saturation_dn / gain,
        vignetting_exponent: exponent,
        extinction_ratio,
        analyser_angle_mean_error_deg: angle_mean.map(f64::to_degrees),
        analyser_angle_sd_deg: angle_sd.to_degrees(),
        hot_pixels: hot.iter().filter(|h| **h).count() as u64,
        photon_transfer: points,
    };
    Ok(SensorCalibration {
        header: SensorHeader {
            format: FORMAT.into(),
            version: VERSION,
            sensor: set.sensor.clone(),
            gain_db: set.gain_db,
            figures,
            source: format!(
                "{} dark, {} flat, {} polariser-sheet frames from {}; {ideal_kept} clipped \
                 pixel(s) keep their nominal analyser",
                darks.len(),
                levels.iter().map(|(_, f)| f.len()).sum::<usize>(),
                sheets.len(),
                set.source
            ),
        },
        pixels,
        checksum: 0,
    })
}

/// Inverse of a symmetric 3×3 matrix by cofactors (`None` when singular).
fn invert3(m: [[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    let scale = m
        .iter()
        .flatten()
        .fold(0.0f64, |a, v| a.max(v.abs()))
        .powi(3);
    if det.is_nan() || det.abs() <= 1e-9 * scale {
        return None;
    }
    let c =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let cof = [
        [c(1, 2, 1, 2), -c(1, 2, 0, 2), c(1, 2, 0, 1)],
        [-c(0, 2, 1, 2), c(0, 2, 0, 2), -c(0, 2, 0, 1)],
        [c(0, 1, 1, 2), -c(0, 1, 0, 2), c(0, 1, 0, 1)],
    ];
    Some(std::array::from_fn(|i| {
        std::array::from_fn(|j| cof[j][i] / det)
    }))
}
