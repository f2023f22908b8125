//! The flash polariser's transmission axis from the polarisation of its specular highlights on a
//! glossy sphere: the image side and the estimate ([`super::flash`] gives the flash position
//! from the same highlights).
//!
//! Physics. The flash sits a few centimetres from the lens (≈ 3.5° at 0.5 m), so the highlight's
//! angle of incidence is under 2°. There a dielectric's Fresnel coefficients for the s and p
//! components are equal to second order in the angle (|r_p/r_s| = 0.998 at 2° for η = 1.5,
//! turning light polarised at 45° to the plane of incidence by 0.05°), so specular reflection
//! keeps the flash's linear polarisation, with DoLP ≈ 1 where the specular lobe outshines the
//! (nearly unpolarised) diffuse light. Two frame conventions meet, checked against the
//! simulator by the tests (a sign error reads a 7° polariser as −7°):
//! - the rig file's `polariser_deg` is measured from camera x towards camera **y** (OpenCV,
//!   image down: [`ellipso_model::rig::FlashSpec::polariser_deg`]);
//! - `ellipso-polar`'s AoLP is measured from image-right towards image-**up**.
//!
//! So a highlight with AoLP `a` reads `polariser_deg = −a` (mod 180°) on the optical axis. Off
//! it the reading turns: the flash's light is polarised across its own ray, and the sensor's
//! wire-grid analysers act on an oblique ray with effective axes that differ from their nominal
//! angles at second order in the field angle (docs/model.md, "Analysers off the optical axis").
//! On 816×680 renders of the sphere (highlights up to ~10° off axis) the readings scatter by
//! 6.6–7.8° for a 7° polariser, with the highlight's place in the image. [`model_reading_deg`] predicts a view's
//! reading with `ellipso_model` — the specular Mueller matrix between the light frame (x = the
//! polariser axis) and the camera frame, then the analysers' effective axes for the ray, the
//! functions the simulator renders with and the fit inverts (one model) — and
//! [`estimate_polariser_angle_corrected`] subtracts each view's predicted deviation: the
//! corrected readings lie within 0.17° of their mean, 7.025° (measured by the tests).
//!
//! Per view ([`highlight_stokes`]): the valid (unsaturated, lit) pixels of the processed
//! Stokes image (bilinear demosaic, [`stokes_config`]) within a window around the highlight whose polarised intensity √(s1² + s2²) is
//! at least [`POLARISED_LEVEL`] of the window's largest; their s0, s1, s2 are summed. Summing
//! Stokes vectors is the intensity-and-DoLP-weighted circular mean of 2·AoLP (s1 + i·s2 =
//! s0·DoLP·e^{2i·AoLP}); a saturated core (its Stokes unknown) is masked by `ellipso-polar` and
//! never enters.
//!
//! Across views ([`estimate_polariser_angle`]): the same weighted circular mean of the views'
//! doubled angles, each view weighted by its polarised intensity w = |Σs1 + iΣs2|. The 1σ is the
//! sandwich (scatter) estimate of a weighted mean, σ² = n/(n − 1) · Σ wᵢ²Δᵢ² / (Σ wᵢ)², Δᵢ the
//! view's angle less the mean (wrapped into ±90°): the spread the views show, not a model of the
//! noise.

use ellipso_model::optics::measure::AnalyserAngles;
use ellipso_model::optics::pbrdf::{self, Geometry};
use ellipso_model::optics::{Stokes, Vec3};
use ellipso_polar::PolarImage;
use nalgebra::{Point3, Vector3};

use super::flash::SpherePoint;

/// Refractive index the correction takes for the sphere (glass, glazed ceramic: 1.45–1.6). It
/// enters only through the ratio of the s and p Fresnel coefficients at < 2° incidence, which
/// turns the polarisation by < 0.05° for any η in that range (module doc): the correction is
/// the geometry's, not the material's.
pub const SPHERE_ETA: f64 = 1.5;

/// A window pixel counts when its polarised intensity is at least this fraction of the window's
/// largest: the specular lobe, not the sphere's diffuse light or the board behind its limb (half
/// the blob threshold of [`super::highlight`], so the unsaturated ring around a saturated core
/// is kept).
pub const POLARISED_LEVEL: f64 = 0.25;

/// Least DoLP of a view's summed highlight Stokes vector: a polarised flash's highlight on a
/// dielectric reads DoLP ≈ 1 less the diffuse share (0.8–1 measured on the shipped sphere); an
/// unpolarised flash (or a metal sphere's highlight seen through a crossed polariser) reads
/// near 0.
pub const MIN_DOLP: f64 = 0.5;

/// One view's summed highlight Stokes vector (`ellipso-polar`'s normalised units and frame:
/// s1 + i·s2 = s0·DoLP·e^{2i·AoLP}, AoLP from image-right towards image-up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HighlightStokes {
    /// Σ s0.
    pub s0: f64,
    /// Σ s1.
    pub s1: f64,
    /// Σ s2.
    pub s2: f64,
    /// Superpixels summed.
    pub pixels: usize,
}

impl HighlightStokes {
    /// DoLP of the sum.
    pub fn dolp(&self) -> f64 {
        self.s1.hypot(self.s2) / self.s0.max(f64::MIN_POSITIVE)
    }

    /// AoLP of the sum, degrees in [0, 180), from image-right towards image-up.
    pub fn aolp_deg(&self) -> f64 {
        (0.5 * self.s2.atan2(self.s1).to_degrees()).rem_euclid(180.0)
    }

    /// The flash polariser angle this view says, degrees in (−90, 90], the rig convention (from
    /// camera x towards camera y = image down): the negated AoLP (see the module doc).
    pub fn polariser_deg(&self) -> f64 {
        wrap_half_turn(-self.aolp_deg())
    }
}

/// `deg` wrapped into (−90°, 90°] (a polariser axis is a line: θ and θ + 180° are one axis).
pub fn wrap_half_turn(deg: f64) -> f64 {
    let w = deg.rem_euclid(180.0);
    if w > 90.0 { w - 180.0 } else { w }
}

/// Why a highlight's polarisation (or the polariser angle) could not be measured.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolariserError {
    /// No valid superpixel in the window: the highlight is saturated throughout, or outside.
    #[error(
        "no unsaturated pixel around the highlight at ({x:.1}, {y:.1}) px: lower the exposure or the flash power until the highlight's edge is below saturation"
    )]
    NoValidPixels { x: f64, y: f64 },
    /// The highlight is (nearly) unpolarised.
    #[error(
        "the highlight at ({x:.1}, {y:.1}) px has DoLP {dolp:.2}, need ≥ {MIN_DOLP}: is the flash polariser fitted, and is the light at the highlight the flash's own reflection (a glossy sphere, no lamp reflected there)?"
    )]
    NotPolarised { x: f64, y: f64, dolp: f64 },
    /// Fewer than two views.
    #[error("the polariser angle needs at least 2 highlight views, got {0}")]
    TooFewViews(usize),
}

/// The estimated polariser angle.
#[derive(Debug, Clone, PartialEq)]
pub struct PolariserEstimate {
    /// Transmission axis, degrees in (−90, 90], from camera x towards camera y.
    pub polariser_deg: f64,
    /// Its 1σ, degrees (scatter of the views, see the module doc).
    pub std_deg: f64,
    /// Per view: its angle less the estimate, degrees, wrapped into ±90°.
    pub residuals_deg: Vec<f64>,
    /// Smallest DoLP among the views.
    pub min_dolp: f64,
    /// Largest geometric correction applied to a view, degrees (0: uncorrected).
    pub max_correction_deg: f64,
}

/// The window radius, raw pixels, for a highlight blob of `blob_px` superpixels
/// ([`super::highlight::Highlight::blob_px`], pixels above half the peak): twice the blob's
/// equivalent radius plus 2 — a Gaussian lobe falls from ½ to [`POLARISED_LEVEL`] of its peak
/// between 1.18σ and 1.67σ, so twice the half-level radius holds every pixel that counts, with
/// room for a saturated (flat-topped) core; `tile_px` raw pixels per superpixel side.
pub fn window_radius_px(blob_px: usize, tile_px: u32) -> f64 {
    f64::from(tile_px) * (2.0 * (blob_px as f64 / std::f64::consts::PI).sqrt() + 2.0)
}

/// The `ellipso-polar` settings the highlight's Stokes image is made with: the defaults with the
/// bilinear demosaic. The highlight is a few superpixels across, and a superpixel samples its
/// four analysers at four points of that steep lobe (the instantaneous-field-of-view error):
/// on a synthetic Gaussian spot 3 superpixels wide it reads the angle 0.1° off, on the rendered
/// sphere the 12 views' uncorrected readings of a 7° polariser span 6.3–8.4° (mean 7.34°)
/// against 6.6–7.8° (mean 7.15°) bilinear.
pub fn stokes_config() -> ellipso_polar::PolarConfig {
    ellipso_polar::PolarConfig {
        demosaic: ellipso_polar::DemosaicMethod::Bilinear,
        ..ellipso_polar::PolarConfig::default()
    }
}

/// Sums the highlight's Stokes vector in `image` (the `ellipso-polar` output of the frame whose
/// raw size is `raw_width` pixels wide) around `highlight_px` (raw pixels, integer-centre
/// convention) within `radius_px` raw pixels; colour bands are summed (see the module doc).
pub fn highlight_stokes(
    image: &PolarImage,
    raw_width: u32,
    highlight_px: [f64; 2],
    radius_px: f64,
) -> Result<HighlightStokes, PolariserError> {
    let (w, h) = (image.width(), image.height());
    let [x, y] = highlight_px;
    let none = PolariserError::NoValidPixels { x, y };
    if w == 0 || h == 0 {
        return Err(none);
    }
    // output pixel u covers raw t·u … t·u + t − 1: its centre is t·u + (t − 1)/2
    let t = f64::from(raw_width) / w as f64;
    let (cu, cv) = ((x - (t - 1.0) / 2.0) / t, (y - (t - 1.0) / 2.0) / t);
    let r = (radius_px / t).max(1.0);
    let (u0, u1) = (
        (cu - r).floor().max(0.0),
        (cu + r).ceil().min(w as f64 - 1.0),
    );
    let (v0, v1) = (
        (cv - r).floor().max(0.0),
        (cv + r).ceil().min(h as f64 - 1.0),
    );
    if u0 > u1 || v0 > v1 {
        return Err(none);
    }
    // per window pixel: (s0, s1, s2) summed over the bands, valid in every band
    let mut window = Vec::new();
    for v in v0 as usize..=v1 as usize {
        for u in u0 as usize..=u1 as usize {
            if (u as f64 - cu).hypot(v as f64 - cv) > r {
                continue;
            }
            let k = v * w + u;
            if !image.bands.iter().all(|b| b.mask.data()[k].is_valid()) {
                continue;
            }
            let s = image.bands.iter().fold([0.0f64; 3], |a, b| {
                [
                    a[0] + f64::from(b.s0.data()[k]),
                    a[1] + f64::from(b.s1.data()[k]),
                    a[2] + f64::from(b.s2.data()[k]),
                ]
            });
            window.push(s);
        }
    }
    let top = window
        .iter()
        .map(|s| s[1].hypot(s[2]))
        .filter(|p| p.is_finite())
        .fold(0.0, f64::max);
    if top <= 0.0 {
        return Err(none);
    }
    let mut sum = HighlightStokes {
        s0: 0.0,
        s1: 0.0,
        s2: 0.0,
        pixels: 0,
    };
    for s in window {
        if s[1].hypot(s[2]) >= POLARISED_LEVEL * top {
            sum.s0 += s[0];
            sum.s1 += s[1];
            sum.s2 += s[2];
            sum.pixels += 1;
        }
    }
    let dolp = sum.dolp();
    // NaN DoLP fails too.
    if dolp.is_nan() || dolp < MIN_DOLP {
        return Err(PolariserError::NotPolarised { x, y, dolp });
    }
    Ok(sum)
}

/// The polariser angle from the views' highlight Stokes sums, without the geometric correction
/// (see the module doc).
pub fn estimate_polariser_angle(
    views: &[HighlightStokes],
) -> Result<PolariserEstimate, PolariserError> {
    let readings: Vec<f64> = views.iter().map(HighlightStokes::polariser_deg).collect();
    weighted_mean(views, &readings, 0.0)
}

/// The polariser angle with each view's reading corrected by the model: the view at
/// `points[i]` on its sphere, the flash at `flash_camera_m` (from [`super::flash`]). The
/// correction is evaluated at the current estimate and the mean re-taken, twice (it changes by
/// < 1e-3° per degree of polariser angle, so one round would do; the second checks it).
pub fn estimate_polariser_angle_corrected(
    views: &[HighlightStokes],
    points: &[SpherePoint],
    flash_camera_m: &Point3<f64>,
) -> Result<PolariserEstimate, PolariserError> {
    let mut estimate = estimate_polariser_angle(views)?;
    for _ in 0..2 {
        let p = estimate.polariser_deg;
        let mut readings = Vec::with_capacity(views.len());
        let mut largest: f64 = 0.0;
        for (v, at) in views.iter().zip(points) {
            let c = model_reading_deg(at, flash_camera_m, p).map_or(0.0, |m| wrap_half_turn(m - p));
            largest = largest.max(c.abs());
            readings.push(v.polariser_deg() - c);
        }
        estimate = weighted_mean(views, &readings, largest)?;
    }
    Ok(estimate)
}

/// The weighted circular mean of `readings` (degrees, one per view) with the views' polarised
/// intensities as weights, and its scatter σ (see the module doc).
fn weighted_mean(
    views: &[HighlightStokes],
    readings: &[f64],
    max_correction_deg: f64,
) -> Result<PolariserEstimate, PolariserError> {
    let n = views.len();
    if n < 2 {
        return Err(PolariserError::TooFewViews(n));
    }
    let weights: Vec<f64> = views.iter().map(|s| s.s1.hypot(s.s2)).collect();
    let (c, s) = weights
        .iter()
        .zip(readings)
        .fold((0.0, 0.0), |(c, s), (w, deg)| {
            let a = 2.0 * deg.to_radians();
            (c + w * a.cos(), s + w * a.sin())
        });
    let polariser_deg = wrap_half_turn(0.5 * s.atan2(c).to_degrees());
    let residuals_deg: Vec<f64> = readings
        .iter()
        .map(|r| wrap_half_turn(r - polariser_deg))
        .collect();
    let sw: f64 = weights.iter().sum();
    let sw2d2: f64 = weights
        .iter()
        .zip(&residuals_deg)
        .map(|(w, d)| (w * d).powi(2))
        .sum();
    let std_deg = (n as f64 / (n - 1) as f64 * sw2d2).sqrt() / sw.max(f64::MIN_POSITIVE);
    let min_dolp = views.iter().map(HighlightStokes::dolp).fold(1.0, f64::min);
    Ok(PolariserEstimate {
        polariser_deg,
        std_deg,
        residuals_deg,
        min_dolp,
        max_correction_deg,
    })
}

/// What a view's highlight reads ([`HighlightStokes::polariser_deg`] of noise-free data) by the
/// model, for the highlight at `at` and the flash at `flash_camera_m` behind a polariser at
/// `polariser_deg` — `ellipso_model`'s specular Mueller matrix between the light frame (x the
/// polariser axis) and the camera frame, then the sensor's wire-grid analysers for the ray
/// ([`AnalyserAngles::for_ray`]), as the simulator renders and the fit inverts. `None` when the
/// geometry has no frames (the flash on the sphere, a grazing ray).
pub fn model_reading_deg(
    at: &SpherePoint,
    flash_camera_m: &Point3<f64>,
    polariser_deg: f64,
) -> Option<f64> {
    let v = |v: &Vector3<f64>| Vec3::new(v.x, v.y, v.z);
    let p = at.point_camera_m.coords;
    let to_camera = (-p).try_normalize(1e-12)?;
    let to_light = (flash_camera_m.coords - p).try_normalize(1e-12)?;
    let (sin, cos) = polariser_deg.to_radians().sin_cos();
    // light frame x = the polariser axis: up = z × x with z = −ω_i (as the renderer builds it)
    let light_up = (-to_light).cross(&Vector3::new(cos, sin, 0.0));
    // OpenCV camera frame: image right +x, image up −y
    let camera_up = Vector3::new(0.0, -1.0, 0.0);
    let g = Geometry::from_up_vectors(
        v(&at.normal_camera),
        v(&to_light),
        v(&to_camera),
        v(&light_up),
        v(&camera_up),
    )
    .ok()?;
    let s = pbrdf::reflection_unit(&g, SPHERE_ETA).apply(Stokes::new(1.0, 1.0, 0.0, 0.0));
    let i = AnalyserAngles::for_ray(
        [1.0, 0.0, 0.0],
        [0.0, -1.0, 0.0],
        [to_camera.x, to_camera.y, to_camera.z],
    )
    .intensities(s);
    let (s1, s2) = (i.i0 - i.i90, i.i45 - i.i135);
    // nothing reflected (back-facing): no reading
    if s1.hypot(s2) <= 0.0 {
        return None;
    }
    Some(wrap_half_turn(-0.5 * s2.atan2(s1).to_degrees()))
}

#[cfg(test)]
mod tests;
