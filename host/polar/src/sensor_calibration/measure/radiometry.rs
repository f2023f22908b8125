//! The radiometric stages of a sensor measurement (steps 1 and 2 of the parent's doc): the
//! darks (dark levels, hot pixels, black level, DSNU, temporal dark variance), the flats'
//! photon transfer (conversion gain, read noise, saturation, each pixel's response) and the
//! vignetting exponent and PRNU fitted to those responses. Each stage reads its frames once,
//! in manifest order.

use ellipso_model::camera::CameraModel;

use super::{Frames, Grid, MeasureError, MeasureOptions, band_of};
use crate::sensor_calibration::PhotonTransferPoint;

/// What the dark frames give.
pub(super) struct Darks {
    /// Each pixel's mean dark level, DN.
    pub dark: Vec<f64>,
    /// Hot pixels: dark level above median + max(10 σ, 5 DN).
    pub hot: Vec<bool>,
    /// Black level: the mean dark level of the other pixels, DN.
    pub black: f64,
    /// Temporal dark variance σ²_d: their mean per-pixel variance, DN².
    pub var_dark_t: f64,
    /// DSNU: their dark levels' spatial sd less the temporal part, DN.
    pub dsnu: f64,
}

impl Darks {
    /// Whether pixel `i` is not hot (the pixels every figure is taken over).
    pub fn cold(&self, i: usize) -> bool {
        !self.hot[i]
    }

    /// Reads the dark frames `files` (≥ 2) and takes their figures.
    pub fn measure(frames: &Frames, files: &[&str], grid: Grid) -> Result<Self, MeasureError> {
        let n = grid.n;
        let mut sum = vec![0.0f64; n];
        let mut sum2 = vec![0.0f64; n];
        for file in files {
            for (i, v) in frames.read(file)?.into_iter().enumerate() {
                let v = f64::from(v);
                sum[i] += v;
                sum2[i] += v * v;
            }
        }
        let nd = files.len() as f64;
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
        Ok(Darks {
            dark,
            hot,
            black,
            var_dark_t,
            dsnu,
        })
    }
}

/// What the flats give: the photon transfer curve and its figures, each pixel's response.
pub(super) struct PhotonTransfer {
    /// Pixels clipped in a flat frame (the sheet stage adds its own).
    pub clipped: Vec<bool>,
    /// Each pixel's response r_p: slope through the origin of its mean signal above dark
    /// against the level, DN per unit level.
    pub resp: Vec<f64>,
    /// Σ level² over the levels.
    pub sum_l2: f64,
    /// One point per level, in level order.
    pub points: Vec<PhotonTransferPoint>,
    /// Per level: `(level_rel, frame count, clipped samples)`.
    pub level_frames: Vec<(f64, f64, usize)>,
    /// Conversion gain K, DN per electron.
    pub gain: f64,
    /// Read noise, DN.
    pub read_noise_dn: f64,
    /// Saturation above dark, DN.
    pub saturation_dn: f64,
}

impl PhotonTransfer {
    /// Reads the flat levels `levels` (each `(level_rel, files)`, ≥ 2 frames) and fits the
    /// photon transfer; too few usable levels are [`MeasureError::Missing`], a gain that is
    /// not positive [`MeasureError::Degenerate`].
    pub fn measure(
        frames: &Frames,
        levels: &[(f64, Vec<&str>)],
        darks: &Darks,
        grid: Grid,
        options: MeasureOptions,
    ) -> Result<Self, MeasureError> {
        let (n, full_scale) = (grid.n, grid.full_scale);
        let (dark, var_dark_t) = (&darks.dark, darks.var_dark_t);
        let cold = |i: usize| darks.cold(i);
        let mut clipped = vec![false; n];
        let mut resp = vec![0.0f64; n];
        let mut sum_l2 = 0.0;
        let mut points = Vec::new();
        let mut level_frames = Vec::new();
        for (level, files) in levels {
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
        let range = full_scale - darks.black;
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
        Ok(PhotonTransfer {
            clipped,
            resp,
            sum_l2,
            points,
            level_frames,
            gain,
            read_noise_dn,
            saturation_dn,
        })
    }
}

/// The vignetting `cos^n θ` and the PRNU left once it and the analysers are divided out.
pub(super) struct Vignetting {
    /// Each pixel's `cos θ_p` (its centre's ray through `camera`), in `[1e-6, 1]`.
    pub cos_field: Vec<f64>,
    /// The exponent n (0 for a lens with no field).
    pub exponent: f64,
    /// Photo-response non-uniformity, relative.
    pub prnu: f64,
}

impl Vignetting {
    /// Fits `ln r_p = c_(band, analyser) + n · ln cos θ_p + ln PRNU_p` over the cold, unclipped
    /// pixels with a positive response.
    pub fn fit(camera: &CameraModel, grid: Grid, darks: &Darks, flats: &PhotonTransfer) -> Self {
        let (w, n, layout) = (grid.width, grid.n, grid.layout);
        let (clipped, resp) = (&flats.clipped, &flats.resp);
        let (gain, var_dark_t, sum_l2) = (flats.gain, darks.var_dark_t, flats.sum_l2);
        let cos_field: Vec<f64> = (0..n)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                camera
                    .unproject_to_ray([x, y])
                    .map_or(1.0, |d| d.z.clamp(1e-6, 1.0))
            })
            .collect();
        let group = |i: usize| {
            let (x, y) = ((i % w) as u32, (i / w) as u32);
            band_of(layout, x, y) * 4 + layout.analyser_at(x, y).index()
        };
        let good = |i: usize| darks.cold(i) && !clipped[i] && resp[i] > 0.0;
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
            let var_r: f64 = flats
                .level_frames
                .iter()
                .map(|(l, nl, _)| l * l * (gain * resp[i] * l + var_dark_t) / nl)
                .sum::<f64>()
                / (sum_l2 * sum_l2);
            noise2 += var_r / (resp[i] * resp[i]);
            m += 1.0;
        }
        let prnu = ((res2 - noise2) / m.max(1.0)).max(0.0).sqrt();
        Vignetting {
            cos_field,
            exponent,
            prnu,
        }
    }
}
