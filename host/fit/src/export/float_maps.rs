//! `maps.exr`: the fitted parameters per pixel of the pictures' view as float channels, for
//! users who compute with the maps rather than look at them.
//!
//! Contract: the same camera, pixels and reliable-vertex interpolation as the PNG maps
//! ([`super::images`]); one OpenEXR file of f32 channels `eta`, `eta_std`, `sigma_s`,
//! `sigma_ss`, `rho_s`, `rho_d.R/G/B`, `rho_ss.R/G/B` (linear, model units: no display gain),
//! `N.X/N.Y/N.Z` (the refined normal in the camera frame: x image right, y image up, z toward
//! the viewer), `A` (1 where the PNG maps draw the object, 0 for background and grey pixels,
//! where every float channel is 0) and the u32 channel `flags` (the OR of the output flags of
//! the pixel's triangle's three vertices, `fit.ply`'s bit order; 0 for background). The
//! identifiability rule is the PNG maps': where `map-eta.png` is grey on the object, `eta` is
//! NaN and `eta_std` +inf.

use ellipso_report::exr_image::{ExrError, FloatImage};
use nalgebra::Vector3;

use super::raster::{Hit, ViewCamera};
use crate::data::VertexFit;

/// The float maps of `fits` seen by `camera`, from the mesh's rasterisation in that camera
/// (`hits`, [`super::raster::rasterise`]: the one the PNG maps draw) (module doc).
pub fn maps_image(
    hits: &[Option<Hit>],
    fits: &[VertexFit],
    camera: &ViewCamera,
) -> Result<FloatImage, ExrError> {
    let models = super::images::pixel_models_of(hits, fits);
    let eta_std: Vec<[f64; 1]> = fits.iter().map(|f| [f.reported_std_error()[0]]).collect();
    let eta_ok: Vec<bool> = fits.iter().map(|f| f.identifiable().eta).collect();
    let masks: Vec<u32> = fits.iter().map(VertexFit::output_mask).collect();
    let camera_from_world = camera.world_from_camera.inverse();
    let n = models.len();
    let names = [
        "eta", "eta_std", "sigma_s", "sigma_ss", "rho_s", "rho_d.R", "rho_d.G", "rho_d.B",
        "rho_ss.R", "rho_ss.G", "rho_ss.B", "N.X", "N.Y", "N.Z", "A",
    ];
    let mut planes = vec![vec![0.0f32; n]; names.len()];
    let mut flags = vec![0u32; n];
    for (i, hit) in hits.iter().enumerate() {
        if let Some(hit) = hit {
            flags[i] = hit.vertices.iter().fold(0, |m, &v| m | masks[v as usize]);
        }
    }
    for (i, m) in models.iter().enumerate() {
        let Some((p, normal, _, hit)) = m else {
            continue;
        };
        let c = camera_from_world.transform_vector(&Vector3::from(*normal));
        let eta_reported = hit.vertices.iter().all(|&v| eta_ok[v as usize]);
        let values = [
            if eta_reported { p.eta } else { f64::NAN },
            if eta_reported {
                hit.interpolate(&eta_std)[0]
            } else {
                f64::INFINITY
            },
            p.sigma_s,
            p.sigma_ss,
            p.rho_s,
            p.rho_d[0],
            p.rho_d[1],
            p.rho_d[2],
            p.rho_ss[0],
            p.rho_ss[1],
            p.rho_ss[2],
            c.x,
            -c.y,
            -c.z,
            1.0,
        ];
        for (plane, v) in planes.iter_mut().zip(values) {
            plane[i] = v as f32;
        }
    }
    let mut image = FloatImage::new(camera.width as usize, camera.height as usize)?;
    for (name, plane) in names.iter().zip(planes) {
        image.push_f32(name, plane)?;
    }
    image.push_u32("flags", flags)?;
    Ok(image)
}
