//! Applying a sensor calibration: each superpixel's own Stokes estimator.
//!
//! Contract: for every output pixel of the superpixel demosaic, the measurement matrix `A`
//! (row k: the mean analysis vector of the raw pixels behind analyser k in that block; two G
//! blocks of a colour tile averaged, as the demosaic averages their intensities) and the
//! intensity offsets `δ_k` (their mean dark level minus the black level, normalised like the
//! intensities) give `s = A⁺ (I − δ)` ([`crate::StokesMatrix::of_measurement`]) and the
//! residual `nᵀ(I − δ)`. The black level of the calibration replaces the configuration's dark
//! level. Only the superpixel demosaic is calibrated per pixel (the bilinear demosaic mixes
//! pixels of different analysis vectors into one value); asking for bilinear is an error.
//! A block whose measurement matrix cannot be inverted (a dead pixel) is an error naming it.

use ellipso_model::mosaic::{Channel, SensorLayout};

use super::SensorCalibration;
use crate::demosaic::{AnalyserImage, RowBuf, band_colours, superpixel_row};
use crate::stokes::{AnalyserRow, per_pixel_row};
use crate::{
    DemosaicMethod, Levels, PolarConfig, PolarError, PolarImage, RawFrame, StokesBand, StokesMatrix,
};

/// Every output pixel's estimator and offsets, per band, for one calibration and one set of
/// levels (build once, apply to every frame of a session).
#[derive(Debug, Clone)]
pub struct PixelEstimators {
    /// Output size.
    width: usize,
    height: usize,
    /// Per band: estimators and offsets, row-major over the output.
    bands: Vec<(Vec<StokesMatrix>, Vec<[f32; 4]>)>,
    levels: Levels,
}

/// The raw pixels of output pixel `(i, j)` of `colour`, grouped by analyser index.
fn block_pixels(
    layout: SensorLayout,
    colour: Option<Channel>,
    i: usize,
    j: usize,
) -> [Vec<(u32, u32)>; 4] {
    let tile = if colour.is_some() { 4 } else { 2 };
    let mut groups: [Vec<(u32, u32)>; 4] = Default::default();
    for dy in 0..tile {
        for dx in 0..tile {
            let (x, y) = ((tile * i + dx) as u32, (tile * j + dy) as u32);
            if layout.colour_at(x, y) == colour {
                groups[layout.analyser_at(x, y).index()].push((x, y));
            }
        }
    }
    groups
}

impl PixelEstimators {
    /// The estimators of `cal` for frames normalised with `levels` (module doc).
    pub fn new(cal: &SensorCalibration, levels: Levels) -> Result<PixelEstimators, PolarError> {
        let s = &cal.header.sensor;
        let layout = s.layout;
        let (w, h) = DemosaicMethod::Superpixel.output_size(layout, s.width, s.height);
        let per_dn = f64::from(levels.scale_per_dn());
        let black = f64::from(levels.dark_dn());
        let mut bands = Vec::new();
        for colour in band_colours(layout) {
            let mut est = Vec::with_capacity(w * h);
            let mut off = Vec::with_capacity(w * h);
            for j in 0..h {
                for i in 0..w {
                    let groups = block_pixels(layout, colour, i, j);
                    let mut a = [[0.0f64; 3]; 4];
                    let mut d = [0.0f32; 4];
                    for (k, g) in groups.iter().enumerate() {
                        let n = g.len().max(1) as f64;
                        let mut dark = 0.0;
                        for &(x, y) in g {
                            let p = cal.pixel(x, y);
                            for (c, v) in a[k].iter_mut().zip(p.analysis) {
                                *c += f64::from(v) / n;
                            }
                            dark += f64::from(p.dark_dn) / n;
                        }
                        d[k] = ((dark - black) * per_dn) as f32;
                    }
                    let m = StokesMatrix::of_measurement(a).map_err(|e| {
                        PolarError::SensorCalibration(format!(
                            "superpixel ({i}, {j}) of band {}: {e}",
                            colour.map_or("mono".to_string(), |c| format!("{c:?}"))
                        ))
                    })?;
                    est.push(m);
                    off.push(d);
                }
            }
            bands.push((est, off));
        }
        Ok(PixelEstimators {
            width: w,
            height: h,
            bands,
            levels,
        })
    }
}

impl PixelEstimators {
    /// The levels these estimators were built for.
    pub fn levels(&self) -> &Levels {
        &self.levels
    }

    /// Replaces each superpixel's four intensities of `image` (a superpixel demosaic read with
    /// these estimators' levels) by those analysers at exactly 0/45/90/135° with extinction
    /// `e = 1/ER` would record for the superpixel's calibrated Stokes vector, plus the
    /// calibrated residual along their null direction (`super::session`'s contract).
    pub fn reproject(&self, image: &mut AnalyserImage, extinction: f64) -> Result<(), PolarError> {
        if image.method != DemosaicMethod::Superpixel || image.bands.len() != self.bands.len() {
            return Err(PolarError::SensorCalibration(
                "a sensor calibration is applied to a superpixel demosaic of its own sensor".into(),
            ));
        }
        let e = extinction as f32;
        let model = [0.0f32, 45.0, 90.0, 135.0].map(|deg| {
            let (sin2, cos2) = (2.0 * deg.to_radians()).sin_cos();
            [
                0.5 * (1.0 + e),
                0.5 * (1.0 - e) * cos2,
                0.5 * (1.0 - e) * sin2,
            ]
        });
        // the model's unit null vector ½[1, −1, 1, −1]; the estimator's null has norm 2, so
        // the residual's component along its unit vector is residual / 2
        let unit_null = [0.5f32, -0.5, 0.5, -0.5];
        for (band, (est, off)) in image.bands.iter_mut().zip(&self.bands) {
            let n = band.mask.data().len();
            if n != est.len() {
                return Err(PolarError::SensorCalibration(format!(
                    "the frame gives {} superpixels, the calibration {}",
                    n,
                    est.len()
                )));
            }
            let [p0, p45, p90, p135] = &mut band.intensity;
            let planes = [
                p0.data_mut(),
                p45.data_mut(),
                p90.data_mut(),
                p135.data_mut(),
            ];
            let [d0, d45, d90, d135] = planes;
            for k in 0..n {
                let d = off[k];
                let i = [d0[k] - d[0], d45[k] - d[1], d90[k] - d[2], d135[k] - d[3]];
                let m = &est[k];
                let dot = |r: &[f32; 4]| r[0] * i[0] + r[1] * i[1] + r[2] * i[2] + r[3] * i[3];
                let s = [dot(&m.rows[0]), dot(&m.rows[1]), dot(&m.rows[2])];
                let along_null = 0.5 * dot(&m.null);
                let out = std::array::from_fn::<f32, 4, _>(|a| {
                    model[a][0] * s[0]
                        + model[a][1] * s[1]
                        + model[a][2] * s[2]
                        + along_null * unit_null[a]
                });
                d0[k] = out[0];
                d45[k] = out[1];
                d90[k] = out[2];
                d135[k] = out[3];
            }
        }
        Ok(())
    }
}

/// [`crate::process`] with a sensor calibration (module doc); `config.calibration` must be
/// `None` (one calibration at a time) and the demosaic superpixel.
pub fn process_with_sensor<D: AsRef<[u16]>>(
    frame: &RawFrame<D>,
    config: &PolarConfig,
    cal: &SensorCalibration,
) -> Result<PolarImage, PolarError> {
    cal.check_frame(frame)
        .map_err(|e| PolarError::SensorCalibration(e.to_string()))?;
    let config = calibrated_config(config, cal)?;
    let levels = config.levels(frame)?;
    let estimators = PixelEstimators::new(cal, levels)?;
    process_with_estimators(frame, &config, &estimators)
}

/// The configuration a sensor calibration runs with: its black level, no global calibration,
/// superpixel demosaic.
pub fn calibrated_config(
    config: &PolarConfig,
    cal: &SensorCalibration,
) -> Result<PolarConfig, PolarError> {
    if config.calibration.is_some() {
        return Err(PolarError::SensorCalibration(
            "a per-analyser calibration and a sensor calibration were both given".into(),
        ));
    }
    if config.demosaic != DemosaicMethod::Superpixel {
        return Err(PolarError::SensorCalibration(
            "a sensor calibration is applied per superpixel; use the superpixel demosaic".into(),
        ));
    }
    Ok(PolarConfig {
        dark_level_dn: cal.header.figures.black_level_dn as f32,
        ..*config
    })
}

/// [`process_with_sensor`] with estimators built already (a session's frames share them).
pub fn process_with_estimators<D: AsRef<[u16]>>(
    frame: &RawFrame<D>,
    config: &PolarConfig,
    estimators: &PixelEstimators,
) -> Result<PolarImage, PolarError> {
    let frame = &frame.view();
    let levels = config.levels(frame)?;
    if levels != estimators.levels {
        return Err(PolarError::SensorCalibration(
            "the frame's levels differ from those the estimators were built for".into(),
        ));
    }
    let thresholds = config.thresholds()?;
    let layout = frame.layout();
    let (w, h) = DemosaicMethod::Superpixel.output_size(layout, frame.width(), frame.height());
    if (w, h) != (estimators.width, estimators.height) {
        return Err(PolarError::SensorCalibration(format!(
            "the frame gives {w}×{h} superpixels, the calibration {}×{}",
            estimators.width, estimators.height
        )));
    }
    let colours = band_colours(layout);
    let mut out = PolarImage::empty();
    out.method = DemosaicMethod::Superpixel;
    out.layout = layout;
    out.levels = levels;
    out.bands.resize_with(colours.len(), StokesBand::default);
    let mut buf = RowBuf::default();
    for ((band, colour), (est, off)) in out.bands.iter_mut().zip(&colours).zip(&estimators.bands) {
        band.reshape(*colour, w, h);
        for y in 0..h {
            superpixel_row(frame, &levels, band.colour, y, &mut buf);
            let [i0, i45, i90, i135] = &buf.intensity;
            let input = AnalyserRow {
                intensity: [i0, i45, i90, i135],
                mask: &buf.mask,
            };
            let row = y * w..(y + 1) * w;
            per_pixel_row(
                input,
                band.row_mut(y),
                thresholds,
                &est[row.clone()],
                &off[row],
            );
        }
    }
    Ok(out)
}
