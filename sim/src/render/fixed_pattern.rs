//! The sensor's fixed pattern: what differs from pixel to pixel but not from frame to frame —
//! dark-signal non-uniformity around the black level, hot pixels, photo-response
//! non-uniformity, and each pixel's own analyser angle error and extinction ratio.
//!
//! Contract:
//! - [`FixedPattern::pixel`] is a pure function of (sensor seed, effect, x, y): no map is
//!   stored, every frame of every scene with the same `effects.sensor_seed` sees the same
//!   physical sensor (what a calibration measured on one capture holds on the next). Each draw
//!   is a SplitMix64 hash of the seed, a per-effect tag and the pixel, turned into a standard
//!   normal by Box–Muller on two hashes; the per-pixel cost is a few hashes per planned effect.
//! - A stage not in the plan contributes its neutral value (offset 0, gain 1, no angle error,
//!   the render's global extinction).
//! - Extinction ratios are drawn as `ER · (1 + σ·z)`, clamped to ≥ 2 (a wire grid never
//!   passes the crossed polarisation more than half as well as the parallel one).
//! - Hot pixels are the pixels whose uniform draw falls below `fraction`; their extra dark
//!   signal is added in DN with the black level, before quantisation and clipping.
//!
//! This module is also the truth a calibration bench compares against (`ellipso bench
//! sensor-calibration`).

use ellipso_model::mosaic::SensorLayout;

use crate::effects::{EffectPlan, Stage, StageParams};
use crate::scene::effects::{AnalyserErrors, BlackLevel, HotPixels, Prnu};

use super::mix;

/// One pixel's fixed-pattern values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelPattern {
    /// Offset added to the pixel's DN: black level + DSNU + hot-pixel signal.
    pub offset_dn: f64,
    /// Whether the pixel is hot.
    pub hot: bool,
    /// Response gain (1 + PRNU draw).
    pub gain: f64,
    /// Analyser angle error, radians (added to the nominal angle).
    pub angle_error_rad: f64,
    /// The pixel's own 1/ER (`None`: the render's global extinction).
    pub inverse_extinction: Option<f64>,
}

impl PixelPattern {
    /// The ideal pixel.
    pub const IDEAL: PixelPattern = PixelPattern {
        offset_dn: 0.0,
        hot: false,
        gain: 1.0,
        angle_error_rad: 0.0,
        inverse_extinction: None,
    };
}

/// The planned fixed-pattern effects of one sensor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixedPattern {
    seed: u64,
    layout: SensorLayout,
    black_level: Option<BlackLevel>,
    hot_pixels: Option<HotPixels>,
    prnu: Option<Prnu>,
    analyser_errors: Option<AnalyserErrors>,
}

const TAG_DSNU: u64 = 0x6473_6e75;
const TAG_HOT: u64 = 0x686f_7470;
const TAG_PRNU: u64 = 0x7072_6e75;
const TAG_ANGLE: u64 = 0x616e_676c;
const TAG_EXTINCTION: u64 = 0x6578_7469;

impl FixedPattern {
    /// The pattern a plan asks for on a sensor of `layout` (seed: `effects.sensor_seed`).
    pub fn new(plan: &EffectPlan, layout: SensorLayout, seed: u64) -> Self {
        let mut p = FixedPattern {
            seed,
            layout,
            black_level: None,
            hot_pixels: None,
            prnu: None,
            analyser_errors: None,
        };
        for stage in [
            Stage::BlackLevel,
            Stage::HotPixels,
            Stage::Prnu,
            Stage::AnalyserErrors,
        ] {
            match plan.params(stage) {
                Some(StageParams::BlackLevel(b)) => p.black_level = Some(b),
                Some(StageParams::HotPixels(h)) => p.hot_pixels = Some(h),
                Some(StageParams::Prnu(r)) => p.prnu = Some(r),
                Some(StageParams::AnalyserErrors(a)) => p.analyser_errors = Some(a),
                _ => {}
            }
        }
        p
    }

    /// Whether any fixed-pattern stage is planned.
    pub fn is_active(&self) -> bool {
        self.black_level.is_some()
            || self.hot_pixels.is_some()
            || self.prnu.is_some()
            || self.analyser_errors.is_some()
    }

    /// The planned analyser errors.
    pub fn analyser_errors(&self) -> Option<AnalyserErrors> {
        self.analyser_errors
    }

    /// The planned black level.
    pub fn black_level(&self) -> Option<BlackLevel> {
        self.black_level
    }

    /// The planned PRNU.
    pub fn prnu(&self) -> Option<Prnu> {
        self.prnu
    }

    /// The planned hot pixels.
    pub fn hot_pixels(&self) -> Option<HotPixels> {
        self.hot_pixels
    }

    fn hash(&self, tag: u64, x: u32, y: u32) -> u64 {
        mix(self.seed ^ mix(tag ^ mix((u64::from(x) << 32) | u64::from(y))))
    }

    /// Uniform in (0, 1).
    fn uniform(&self, tag: u64, x: u32, y: u32) -> f64 {
        ((self.hash(tag, x, y) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller on two independent uniforms).
    fn normal(&self, tag: u64, x: u32, y: u32) -> f64 {
        let u1 = self.uniform(tag, x, y);
        let u2 = self.uniform(tag ^ 0x5555_5555, x, y);
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// The fixed-pattern values of raw pixel `(x, y)`.
    pub fn pixel(&self, x: u32, y: u32) -> PixelPattern {
        let mut p = PixelPattern::IDEAL;
        if let Some(b) = self.black_level {
            p.offset_dn += b.dn + b.dsnu_dn * self.normal(TAG_DSNU, x, y);
        }
        if let Some(h) = self.hot_pixels
            && self.uniform(TAG_HOT, x, y) < h.fraction
        {
            p.offset_dn += h.dn;
            p.hot = true;
        }
        if let Some(r) = self.prnu {
            p.gain = (1.0 + r.sigma_rel * self.normal(TAG_PRNU, x, y)).max(0.0);
        }
        if let Some(a) = self.analyser_errors {
            p.angle_error_rad = a.angle_sigma_deg.to_radians() * self.normal(TAG_ANGLE, x, y);
            let band = self.layout.colour_at(x, y).map_or(1, |c| c.index());
            let er = a.extinction_ratio_rgb[band]
                * (1.0 + a.extinction_sigma_rel * self.normal(TAG_EXTINCTION, x, y));
            p.inverse_extinction = Some(1.0 / er.max(2.0));
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan_with(effects: &str) -> EffectPlan {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sphere.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let scene = crate::scene::Scene::from_toml_str(
            &text.replace("[effects]", &format!("[effects]\n{effects}")),
            &path,
        )
        .unwrap();
        EffectPlan::from_scene(&scene)
    }

    #[test]
    fn pattern_is_fixed_and_has_the_asked_statistics() {
        let plan = plan_with(
            "black_level = { dn = 64.0, dsnu_dn = 1.5 }\nprnu = { sigma_rel = 0.01 }\n\
             analyser_errors = { angle_sigma_deg = 1.0, extinction_ratio_rgb = [80.0, 150.0, 40.0] }\n\
             hot_pixels = { fraction = 0.001, dn = 300.0 }",
        );
        let p = FixedPattern::new(&plan, SensorLayout::MonoPolar, 7);
        assert!(p.is_active());
        assert_eq!(
            p.pixel(10, 20),
            p.pixel(10, 20),
            "a pure function of the pixel"
        );
        let other = FixedPattern::new(&plan, SensorLayout::MonoPolar, 8);
        assert_ne!(p.pixel(10, 20), other.pixel(10, 20), "another sensor");
        let n = 200 * 200;
        let (mut sum, mut sum2, mut g2, mut a2, mut hot) = (0.0, 0.0, 0.0, 0.0, 0);
        for y in 0..200 {
            for x in 0..200 {
                let q = p.pixel(x, y);
                if q.hot {
                    hot += 1;
                    continue;
                }
                sum += q.offset_dn;
                sum2 += q.offset_dn * q.offset_dn;
                g2 += (q.gain - 1.0).powi(2);
                a2 += q.angle_error_rad.to_degrees().powi(2);
                assert!((1.0 / q.inverse_extinction.unwrap() - 150.0).abs() < 1e-9);
            }
        }
        let m = f64::from(n - hot);
        let mean = sum / m;
        let sd = (sum2 / m - mean * mean).sqrt();
        // 40 000 draws: the sample mean is within 4σ/√n, the sd within a few per cent
        assert!((mean - 64.0).abs() < 4.0 * 1.5 / m.sqrt(), "{mean}");
        assert!((sd / 1.5 - 1.0).abs() < 0.03, "{sd}");
        assert!(((g2 / m).sqrt() / 0.01 - 1.0).abs() < 0.03);
        assert!(((a2 / m).sqrt() - 1.0).abs() < 0.03);
        assert!((20..=60).contains(&hot), "{hot} hot pixels of {n}");
    }

    #[test]
    fn unplanned_pattern_is_ideal() {
        let p = FixedPattern::new(&plan_with(""), SensorLayout::ColourPolar, 1);
        assert!(!p.is_active());
        assert_eq!(p.pixel(3, 4), PixelPattern::IDEAL);
    }
}
