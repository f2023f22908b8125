//! The relit pictures: the fitted model's radiance under a new unpolarised point light
//! ([`radiance`], linear, also the Mitsuba export's reference) and its tone mapping for display
//! (Reinhard's global operator, [`tone_map`]), drawn as one picture by [`relit`].

use ellipso_model::optics::Vec3;
use ellipso_model::optics::pbrdf::{Geometry, evaluate_s0};
use ellipso_model::optics::{Frame, Stokes};
use ellipso_report::Figure;
use nalgebra::Point3;
use rayon::prelude::*;

use super::super::colour::srgb;
use super::super::raster::ViewCamera;
use super::{Picture, PixelModel, rgb_pixels};

/// s0 under an unpolarised point light at `light_world`, seen by `camera`.
pub fn relit(
    at: &[PixelModel],
    w: u32,
    h: u32,
    camera: &ViewCamera,
    light_world: &Point3<f64>,
    name: &'static str,
    title: &str,
) -> Picture {
    let rgb = radiance(at, camera, light_world);
    let mapped = tone_map(&rgb);
    let pixels = rgb_pixels(w, h, mapped.iter().map(|v| v.map(|c| c.map(srgb))));
    Picture {
        name,
        figure: Figure::new(title).image("", pixels),
    }
}

/// Linear s0 per colour channel at every pixel under an isotropic unpolarised point light of
/// unit intensity at `light_world`: P·s/d² (`docs/model.md` §4, P includes the foreshortening),
/// no shadowing; `None` for background. The relit pictures tone-map it; the Mitsuba export
/// writes it as the reference of its scene.
pub fn radiance(
    at: &[PixelModel],
    camera: &ViewCamera,
    light_world: &Point3<f64>,
) -> Vec<Option<[f64; 3]>> {
    let eye = camera.centre_world();
    at.par_iter()
        .map(|a| {
            let (p, n, point, _) = a.as_ref()?;
            let to_light = light_world - point;
            let d2 = to_light.norm_squared().max(1e-12);
            let to_light = Vec3::from_f64(to_light.normalize().into());
            let to_camera = Vec3::from_f64((eye - point).normalize().into());
            let up = Vec3::from_f64([0.0, 0.0, 1.0]);
            let alt = Vec3::from_f64([1.0, 0.0, 0.0]);
            // Any frame serves for unpolarised light; pick an up not parallel to the beam.
            let light = Frame::light(to_light, up)
                .or_else(|_| Frame::light(to_light, alt))
                .ok()?;
            let cam = Frame::camera(to_camera, up)
                .or_else(|_| Frame::camera(to_camera, alt))
                .ok()?;
            let g = Geometry::new(Vec3::from_f64(*n), to_light, to_camera, light, cam).ok()?;
            let s0 = evaluate_s0(&g, p, Stokes::unpolarised(1.0));
            Some(s0.map(|v| v / d2))
        })
        .collect()
}

/// Reinhard's global photographic operator (Reinhard, Stark, Shirley & Ferwerda,
/// "Photographic tone reproduction for digital images", SIGGRAPH 2002, eqs. 1–4) on linear RGB:
/// luminance L = 0.2126 R + 0.7152 G + 0.0722 B (Rec. 709) is scaled so its log-average over
/// the object maps to the key 0.18, then L_d = L(1 + L/L_white²)/(1 + L) with L_white the 99.5th
/// percentile of the scaled luminance, and every channel is scaled by L_d/L. The exposure comes
/// from the whole object (not its brightest pixel), and highlights are compressed, not clipped:
/// a sharp highlight stays bright without turning the rest of the object black.
pub fn tone_map(rgb: &[Option<[f64; 3]>]) -> Vec<Option<[f64; 3]>> {
    let lum = |c: &[f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    let lums: Vec<f64> = rgb
        .iter()
        .flatten()
        .map(lum)
        .filter(|l| l.is_finite() && *l > 0.0)
        .collect();
    if lums.is_empty() {
        return rgb.iter().map(|v| v.map(|_| [0.0; 3])).collect();
    }
    // δ keeps the log finite for black pixels (Reinhard's eq. 1), relative to the median.
    let mut sorted = lums.clone();
    let median = ellipso_report::percentile(&mut sorted, 0.5);
    let delta = 1e-4 * median.max(1e-300);
    let log_average =
        (lums.iter().map(|l| (delta + l).ln()).sum::<f64>() / lums.len() as f64).exp();
    let scale = 0.18 / log_average.max(1e-300);
    let white = (scale * ellipso_report::percentile(&mut sorted, 0.995)).max(1e-9);
    rgb.iter()
        .map(|v| {
            v.map(|c| {
                let l = scale * lum(&c).max(0.0);
                if l.is_nan() || l <= 0.0 || !l.is_finite() {
                    return [0.0; 3];
                }
                let ld = l * (1.0 + l / (white * white)) / (1.0 + l);
                c.map(|x| (x.max(0.0) * scale * ld / l).min(1.0))
            })
        })
        .collect()
}
