//! The flash's specular highlight on a glossy sphere of known size and place, found in a raw
//! frame: the image side of [`super::flash`].
//!
//! Per frame, given the camera model, `camera_from_sphere_frame` (the pose of the frame the
//! sphere centre is given in, e.g. a board) and the sphere:
//! 1. the superpixel image of [`HighlightConfig::image`] (co-polarised `I0` by default: the flash
//!    is polarised and a dielectric's specular reflection keeps that polarisation, while the
//!    board's and the sphere's diffuse light is unpolarised, so `I0` has the best contrast; `s0`
//!    works as well), saturated superpixels set to the image maximum;
//! 2. the sphere's projected disc (centre = projected centre, radius = projected silhouette
//!    radius × [`HighlightConfig::disc_fraction`], so board pixels around the limb never count);
//! 3. the brightest pixel in the disc, the background = the disc's median, the blob = the
//!    8-connected pixels around the peak brighter than background + `threshold`×(peak −
//!    background), its centroid weighted by (value − threshold level): sub-pixel, and symmetric
//!    for a flat-topped saturated blob;
//! 4. the centroid mapped back to raw pixels: superpixel u ↦ t·u + o, with o the mean position
//!    inside the t×t tile of the raw samples that form the chosen image ((t − 1)/2 for s0; for a
//!    single analyser the pixel that carries it, averaged over colour blocks).
//!
//! Rejections ([`HighlightRejection`]) name why a frame gives no highlight: the sphere is behind
//! the camera or its disc is outside the image, the disc is too small, the peak does not stand
//! out of the background, or the blob touches the disc edge (a highlight near the limb is clipped
//! by the silhouette, so its centroid is biased).

use ellipso_model::camera::{CameraModel, Pose};
use ellipso_model::mosaic::{Analyser, SensorLayout};
use nalgebra::{Point3, Vector3};

use crate::track::DetectImage;
use ellipso_polar::PolarConfig;
use ellipso_polar::demosaic::{DemosaicMethod, demosaic};
use ellipso_polar::frame::RawFrame;
use ellipso_polar::mask::MaskReason;

/// A sphere of known radius, centre given in some rigid frame (a board's, or the world of the
/// session's boards).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    /// Radius, m.
    pub radius_m: f64,
    /// Centre in that frame, m.
    pub centre_m: Point3<f64>,
}

/// Settings of [`find_highlight`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HighlightConfig {
    /// Image the highlight is searched in. Default co-polarised `I0`.
    pub image: DetectImage,
    /// Searched disc radius as a fraction of the projected sphere radius. Default 0.9.
    pub disc_fraction: f64,
    /// Blob level between background (0) and peak (1). Default 0.5.
    pub threshold: f64,
    /// The peak must exceed this multiple of the disc's median. Default 3.
    pub min_contrast: f64,
    /// Smallest searched disc radius, superpixels. Default 4.
    pub min_disc_px: f64,
}

impl Default for HighlightConfig {
    fn default() -> Self {
        Self {
            image: DetectImage::I0,
            disc_fraction: 0.9,
            threshold: 0.5,
            min_contrast: 3.0,
            min_disc_px: 4.0,
        }
    }
}

/// A found highlight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Highlight {
    /// Centroid, raw pixels (integer-centre convention).
    pub pixel: [f64; 2],
    /// Pixels in the blob (superpixels).
    pub blob_px: usize,
    /// Saturated pixels in the blob.
    pub saturated_px: usize,
    /// Peak over the disc median.
    pub contrast: f64,
}

/// Why a frame gives no highlight.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HighlightRejection {
    /// The frame could not be demosaiced.
    #[error("frame not processable: {0}")]
    Frame(String),
    /// The sphere centre is not in front of the camera, or projects outside the image.
    #[error("the sphere is not in view")]
    NotInView,
    /// The projected disc is smaller than `min_disc_px`.
    #[error("the sphere's disc is {radius_px:.1} superpixels, too small")]
    TooSmall { radius_px: f64 },
    /// The brightest pixel does not stand out.
    #[error("no highlight: peak {contrast:.2}× the disc median, need {required}×")]
    NoContrast { contrast: f64, required: f64 },
    /// The blob reaches the searched disc's edge.
    #[error("the highlight touches the sphere's limb")]
    AtLimb,
}

/// One image plane at superpixel resolution, with the raw offset of its samples in a tile.
struct PlaneImage {
    values: Vec<f32>,
    saturated: Vec<bool>,
    width: usize,
    height: usize,
    tile: f64,
    offset: [f64; 2],
}

fn analyser_of(image: DetectImage) -> Option<Analyser> {
    match image {
        DetectImage::S0 => None,
        DetectImage::I0 => Some(Analyser::Deg0),
        DetectImage::I90 => Some(Analyser::Deg90),
    }
}

fn plane_image(frame: &RawFrame, image: DetectImage) -> Result<PlaneImage, HighlightRejection> {
    let levels = PolarConfig::default()
        .levels(frame)
        .map_err(|e| HighlightRejection::Frame(e.to_string()))?;
    let d = demosaic(frame, &levels, DemosaicMethod::Superpixel);
    let (w, h) = (
        d.bands[0].intensity[0].width(),
        d.bands[0].intensity[0].height(),
    );
    let mut values = vec![0f32; w * h];
    let mut saturated = vec![false; w * h];
    for band in &d.bands {
        let mask = band.mask.data();
        for (k, v) in values.iter_mut().enumerate() {
            *v += match analyser_of(image) {
                None => band.intensity.iter().map(|p| p.data()[k]).sum::<f32>() * 0.5,
                Some(a) => band.intensity[a.index()].data()[k],
            };
            saturated[k] |= mask[k].has(MaskReason::Saturated);
        }
    }
    let layout = frame.layout();
    let tile = f64::from(layout.tile_px());
    let offset = match analyser_of(image) {
        None => [(tile - 1.0) / 2.0; 2],
        Some(a) => {
            // colour: the bands are summed with equal weight, G's two blocks averaged inside
            // its band, so R's block and B's block weigh 1 and each G block ½
            let (blocks, weights): (&[(usize, usize)], &[f64]) = match layout {
                SensorLayout::MonoPolar => (&[(0, 0)], &[1.0]),
                SensorLayout::ColourPolar => {
                    (&[(0, 0), (1, 0), (0, 1), (1, 1)], &[1.0, 0.5, 0.5, 1.0])
                }
            };
            let total: f64 = weights.iter().sum();
            let mut o = [0.0; 2];
            for (b, w) in blocks.iter().zip(weights) {
                let (dx, dy) = layout.pixel_in_tile(a, *b);
                o[0] += w * dx as f64 / total;
                o[1] += w * dy as f64 / total;
            }
            o
        }
    };
    Ok(PlaneImage {
        values,
        saturated,
        width: w,
        height: h,
        tile,
        offset,
    })
}

/// The sphere's projected centre and silhouette radius, raw pixels.
fn projected_disc(
    camera: &CameraModel,
    camera_from_frame: &Pose,
    sphere: &Sphere,
) -> Option<([f64; 2], f64)> {
    let c = camera_from_frame * sphere.centre_m;
    let dist = c.coords.norm();
    if c.z <= sphere.radius_m || dist <= sphere.radius_m {
        return None;
    }
    let centre = camera.project(&c)?;
    // A silhouette point: rotate the view direction by the half-angle asin(r/d) (d > r above).
    let view = c.coords / dist;
    let perp = view.cross(&Vector3::y()).try_normalize(1e-9)?;
    let half = (sphere.radius_m / dist).asin();
    let edge_dir = view * half.cos() + perp * half.sin();
    let edge = camera.project(&Point3::from(edge_dir * dist))?;
    Some((centre, (edge[0] - centre[0]).hypot(edge[1] - centre[1])))
}

/// Finds the highlight of `sphere` (see the module doc).
pub fn find_highlight(
    frame: &RawFrame,
    camera: &CameraModel,
    camera_from_frame: &Pose,
    sphere: &Sphere,
    config: &HighlightConfig,
) -> Result<Highlight, HighlightRejection> {
    let (centre_raw, radius_raw) =
        projected_disc(camera, camera_from_frame, sphere).ok_or(HighlightRejection::NotInView)?;
    let img = plane_image(frame, config.image)?;
    let t = img.tile;
    let cu = (centre_raw[0] - img.offset[0]) / t;
    let cv = (centre_raw[1] - img.offset[1]) / t;
    let r = radius_raw / t * config.disc_fraction;
    if r < config.min_disc_px {
        return Err(HighlightRejection::TooSmall { radius_px: r });
    }
    let (w, h) = (img.width as i64, img.height as i64);
    if cu + r < 0.0 || cv + r < 0.0 || cu - r > w as f64 || cv - r > h as f64 {
        return Err(HighlightRejection::NotInView);
    }
    let inside = |x: i64, y: i64| {
        x >= 0 && y >= 0 && x < w && y < h && (x as f64 - cu).hypot(y as f64 - cv) <= r
    };
    let top = img
        .values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0f32, f32::max);
    let value = |x: i64, y: i64| -> f64 {
        let k = (y * w + x) as usize;
        // saturated superpixels: at least the image maximum (their true value is unknown)
        let v = if img.saturated[k] {
            top.max(img.values[k])
        } else {
            img.values[k]
        };
        if v.is_finite() { f64::from(v) } else { 0.0 }
    };
    let (x0, x1) = ((cu - r).floor() as i64, (cu + r).ceil() as i64);
    let (y0, y1) = ((cv - r).floor() as i64, (cv + r).ceil() as i64);
    let mut disc = Vec::new();
    let mut peak = (f64::NEG_INFINITY, 0i64, 0i64);
    for y in y0..=y1 {
        for x in x0..=x1 {
            if inside(x, y) {
                let v = value(x, y);
                disc.push(v);
                if v > peak.0 {
                    peak = (v, x, y);
                }
            }
        }
    }
    if disc.is_empty() {
        return Err(HighlightRejection::NotInView);
    }
    let background = ellipso_report::percentile(&mut disc, 0.5).max(0.0);
    // contrast: peak over median, the median floored at 1e-6 (a black disc) to keep it finite
    let contrast = peak.0 / background.max(1e-6);
    // NaN contrast fails too.
    if contrast.is_nan() || contrast < config.min_contrast {
        return Err(HighlightRejection::NoContrast {
            contrast,
            required: config.min_contrast,
        });
    }
    let level = background + config.threshold * (peak.0 - background);
    // flood fill from the peak over pixels above the level
    let mut seen = std::collections::HashSet::new();
    let mut stack = vec![(peak.1, peak.2)];
    seen.insert((peak.1, peak.2));
    let (mut sw, mut sx, mut sy) = (0.0, 0.0, 0.0);
    let (mut blob_px, mut saturated_px) = (0usize, 0usize);
    while let Some((x, y)) = stack.pop() {
        let v = value(x, y);
        let weight = v - level;
        sw += weight;
        sx += weight * x as f64;
        sy += weight * y as f64;
        blob_px += 1;
        saturated_px += usize::from(img.saturated[(y * w + x) as usize]);
        for (dx, dy) in [
            (-1, -1),
            (0, -1),
            (1, -1),
            (-1, 0),
            (1, 0),
            (-1, 1),
            (0, 1),
            (1, 1),
        ] {
            let (nx, ny) = (x + dx, y + dy);
            if nx < 0 || ny < 0 || nx >= w || ny >= h {
                continue;
            }
            let k = (nx, ny);
            if seen.contains(&k) {
                continue;
            }
            let above = value(nx, ny) > level;
            if above && !inside(nx, ny) {
                return Err(HighlightRejection::AtLimb);
            }
            if above {
                seen.insert(k);
                stack.push(k);
            }
        }
    }
    // sw > 0: the peak itself contributes peak − level = (1 − threshold)(peak − background) > 0
    let (u, v) = (sx / sw, sy / sw);
    Ok(Highlight {
        pixel: [t * u + img.offset[0], t * v + img.offset[1]],
        blob_px,
        saturated_px,
        contrast,
    })
}

#[cfg(test)]
mod tests;
