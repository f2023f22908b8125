//! The fit's outputs: `fit.ply` (per-vertex parameters, standard errors, flags) and the
//! pictures of the fitted model from a chosen captured view — parameter maps, the 3×3 Mueller
//! grid, DoLP and AoLP under the rig's flash, a relit image under a new point light, a novel
//! view, and the captured frame beside its re-rendering — with the parameter maps also as float
//! OpenEXR ([`float_maps`]) and the pictures' camera and lights as `fit-view.json`
//! ([`view_file`]); [`mitsuba`] turns a fit directory into a Mitsuba 3 scene.
//! `docs/fit-outputs.md` says how to read each one.
//!
//! Contract: [`export_all`] writes into an existing or new directory and returns every file it
//! wrote; every error names the path. Pictures use an ideal pinhole camera at the chosen view's
//! pose framing the mesh's bounding sphere ([`raster::ViewCamera::framing`]), so the object fills
//! the picture whatever the capture distance; the comparison with the captured frame projects
//! each pictured surface point into the captured frame with the rig's real camera model.

pub mod colour;
pub mod float_maps;
pub mod images;
pub mod mitsuba;
pub mod ply;
pub mod raster;
pub mod view_file;

#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::optics::measure::FlashPolariser;
use ellipso_model::optics::pbrdf::apply;
use ellipso_model::rig::FlashSpec;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::data::{VertexFit, ViewGeometry};
use ellipso_report::{ColourMap, Figure, Key, Picture as Pixels};
use raster::ViewCamera;

/// Settings of the pictures.
#[derive(Clone, Debug)]
pub struct ExportConfig {
    /// Picture size, px (square): 512 by default, a size a screen shows whole and an eye reads
    /// without zooming (the figures are a little wider: margins, title and keys around it).
    pub picture_px: u32,
    /// The new point light of each relit picture, relative to the mesh's bounding-sphere
    /// centre, in units of its radius, in the picture camera's axes (image right, image up,
    /// toward the camera; default: a key light above, to the right of and in front of the
    /// object, so the side the picture shows is lit).
    pub light_offset_radii: [f64; 3],
    /// The novel view: the chosen view turned by this angle about the world z axis through the
    /// bounding-sphere centre, degrees.
    pub novel_view_turn_deg: f64,
}

impl Default for ExportConfig {
    fn default() -> Self {
        Self {
            picture_px: 512,
            light_offset_radii: [2.0, 2.5, 4.0],
            novel_view_turn_deg: 70.0,
        }
    }
}

/// What [`export_all`] wrote.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ExportReport {
    /// Every file, in writing order.
    pub files: Vec<PathBuf>,
    /// RMS of (captured − re-rendered s0) over the pictured object pixels divided by the RMS of
    /// the captured s0, the re-rendering in DN through the frame's own radiometry (when a
    /// captured frame was given).
    pub rerender_rmse: Option<f64>,
    /// The frame of the comparison picture (`rerender-vs-captured.png`).
    pub comparison_frame: Option<ComparisonFrame>,
    /// Per picture view, the observed surface it shows and the grey pixels on it
    /// ([`images::Holes`]; zero where every observed vertex has a full parameter set).
    pub holes: Vec<images::Holes>,
}

/// Which captured frame `rerender-vs-captured.png` shows.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct ComparisonFrame {
    /// The session's frame id.
    pub frame_id: u64,
    /// Whether the fit never saw the frame (a held-out view; else the pictures' view).
    pub held_out: bool,
}

/// Errors of the export.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Creating or writing a file.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// Writing the PLY.
    #[error(transparent)]
    Ply(#[from] ply::PlyError),
    /// Writing a PNG.
    #[error(transparent)]
    Png(#[from] ellipso_report::ReportError),
    /// Building or writing an OpenEXR file.
    #[error(transparent)]
    Exr(#[from] ellipso_report::exr_image::ExrError),
}

/// A captured s0 image (superpixel resolution) with the camera that took it and the
/// radiometry that turns the model into its DN.
#[derive(Clone, Debug)]
pub struct CapturedS0 {
    /// The frame's id.
    pub frame_id: u64,
    /// Whether the fit never saw this frame (a held-out view).
    pub held_out: bool,
    /// N at any world point of this frame (DN per model unit).
    pub normaliser: crate::observe::PointNormaliser,
    /// Colour bands summed into `s0` (3 colour, 1 monochrome).
    pub bands: usize,
    /// Superpixel columns.
    pub width: usize,
    /// Superpixel rows.
    pub height: usize,
    /// Raw pixels per superpixel side (2 for the IMX250 mosaics).
    pub tile_px: usize,
    /// s0, DN, row-major (summed over colour bands).
    pub s0: Vec<f32>,
    /// Camera → world of the frame.
    pub world_from_camera: Isometry3<f64>,
    /// The fit's held-out score, s0 relative RMSE over the samples of every held-out frame
    /// (`fit-summary.json`'s `held_out.overall`), named in the picture's title beside its own
    /// per-pixel figure; `None` without held-out frames.
    pub held_out_samples_rmse: Option<f64>,
}

impl CapturedS0 {
    /// Bilinear s0 at raw pixel `(u, v)` (integer-centre convention); `None` outside.
    pub fn at_raw(&self, u: f64, v: f64) -> Option<f64> {
        // Superpixel k covers raw t·k … t·k + t − 1; its centre is raw t·k + (t − 1)/2.
        let t = self.tile_px as f64;
        let x = (u - (t - 1.0) / 2.0) / t;
        let y = (v - (t - 1.0) / 2.0) / t;
        if !(x >= 0.0 && y >= 0.0 && x <= (self.width - 1) as f64 && y <= (self.height - 1) as f64)
        {
            return None;
        }
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let p = |x: usize, y: usize| f64::from(self.s0[y * self.width + x]);
        Some(
            p(x0, y0) * (1.0 - fx) * (1.0 - fy)
                + p(x1, y0) * fx * (1.0 - fy)
                + p(x0, y1) * (1.0 - fx) * fy
                + p(x1, y1) * fx * fy,
        )
    }
}

/// The s0 image of a recorded frame (superpixel demosaic) with its pose and radiometry;
/// `held_out` says whether the fit saw it.
pub fn captured_s0(
    session: &ellipso_session::reader::Session,
    frame_id: u64,
    world_from_camera: Isometry3<f64>,
    held_out: bool,
) -> Result<CapturedS0, String> {
    let normaliser = crate::observe::point_normaliser(session, frame_id, &world_from_camera)
        .map_err(|e| e.to_string())?;
    let entry = session
        .frames
        .iter()
        .find(|f| f.frame_id == frame_id)
        .ok_or_else(|| format!("frame {frame_id} is not in the session"))?;
    let (w, h, px) = session.load_frame(entry).map_err(|e| e.to_string())?;
    let layout = session.manifest.sensor.layout;
    let raw =
        ellipso_polar::frame::RawFrame::new(w, h, session.manifest.sensor.bit_depth, layout, px)
            .map_err(|e| e.to_string())?;
    let (s0, sw, sh) = ellipso_polar::intensity::intensity_plane(
        &raw,
        ellipso_polar::intensity::IntensityPlane::S0,
    )
    .map_err(|e| e.to_string())?;
    // The detection plane is in fractions of full scale (the polar levels, no dark level).
    let full_scale = f32::from(raw.full_scale_dn());
    let s0 = s0.into_iter().map(|v| v * full_scale).collect();
    Ok(CapturedS0 {
        frame_id,
        held_out,
        normaliser,
        bands: raw.layout().channels().len(),
        width: sw,
        height: sh,
        tile_px: raw.layout().tile_px() as usize,
        s0,
        world_from_camera,
        held_out_samples_rmse: None,
    })
}

/// The mesh's bounding sphere (centre of the bounding box, farthest vertex).
fn bounding_sphere(mesh: &TriangleMesh) -> (Point3<f64>, f64) {
    let b = ellipso_model::geometry::Aabb::from_points(mesh.positions());
    let c = b.centre();
    let r = mesh
        .positions()
        .iter()
        .map(|p| (p - c).norm())
        .fold(0.0, f64::max);
    (c, r.max(1e-6))
}

/// Writes `fit.ply` (with each vertex's `material`, [`ply::write_fit_ply`]) and every picture
/// into `out` (see the module doc).
#[expect(
    clippy::too_many_arguments,
    reason = "the export's inputs are independent values"
)]
pub fn export_all(
    out: &Path,
    mesh: &TriangleMesh,
    fits: &[VertexFit],
    material: Option<&[Option<usize>]>,
    camera: &CameraModel,
    world_from_camera: &Isometry3<f64>,
    flash: &FlashSpec,
    config: &ExportConfig,
    captured: Option<&CapturedS0>,
) -> Result<ExportReport, ExportError> {
    std::fs::create_dir_all(out).map_err(|source| ExportError::Io {
        path: out.display().to_string(),
        source,
    })?;
    let mut report = ExportReport::default();
    let ply_path = out.join("fit.ply");
    ply::write_fit_ply(&ply_path, mesh, fits, material)?;
    report.files.push(ply_path);
    let (centre, radius) = bounding_sphere(mesh);
    let px = config.picture_px.max(16);
    let view = ViewCamera::framing(*world_from_camera, px, px, &centre, radius);
    // The key light in a picture camera's axes (OpenCV: x right, y down, z forward).
    let light_for = |camera: &ViewCamera| {
        let [r, u, t] = config.light_offset_radii;
        let offset_camera = Vector3::new(r, -u, -t) * radius;
        centre + camera.world_from_camera.rotation * offset_camera
    };
    let light = light_for(&view);
    // one rasterisation of the view for the float maps and the PNG pictures
    let hits = raster::rasterise(mesh, &view);
    let maps_path = out.join("maps.exr");
    float_maps::maps_image(&hits, fits, &view)?.write(&maps_path)?;
    report.files.push(maps_path);
    let record =
        view_file::PictureView::new(&view, &flash.position_world(world_from_camera), &light)
            .with_polariser(
                flash
                    .polariser_axis_world(world_from_camera)
                    .map(|a| a.into_inner().into()),
            );
    let view_path = view_file::write(out, &record).map_err(|source| ExportError::Io {
        path: out.join(view_file::FILE_NAME).display().to_string(),
        source,
    })?;
    report.files.push(view_path);
    let (mut pictures, holes) = images::pictures(&hits, fits, &view, flash, &light);
    report.holes.push(holes);
    // The novel view: the chosen view turned about the world z axis through the centre.
    let turn = UnitQuaternion::from_axis_angle(
        &Vector3::z_axis(),
        config.novel_view_turn_deg.to_radians(),
    );
    let about_centre =
        Translation3::from(centre.coords) * turn * Translation3::from(-centre.coords);
    let novel = ViewCamera::framing(about_centre * world_from_camera, px, px, &centre, radius);
    let (models, holes) = images::pixel_models_and_holes(mesh, fits, &novel, "novel-view");
    report.holes.push(holes);
    pictures.push(images::relit(
        &models,
        px,
        px,
        &novel,
        &light_for(&novel),
        "novel-view",
        &format!(
            "novel view ({:.0}° about z), key light",
            config.novel_view_turn_deg
        ),
    ));
    if let Some(c) = captured {
        // Framed from the captured frame's own pose, so the three panels line up with it.
        let framing = ViewCamera::framing(c.world_from_camera, px, px, &centre, radius);
        let (pic, rmse) = comparison(mesh, fits, &framing, camera, flash, c);
        pictures.push(pic);
        report.rerender_rmse = rmse;
        report.comparison_frame = Some(ComparisonFrame {
            frame_id: c.frame_id,
            held_out: c.held_out,
        });
    }
    for p in pictures {
        let path = out.join(format!("{}.png", p.name));
        p.figure.save_png(&path)?;
        report.files.push(path);
    }
    Ok(report)
}

/// Captured s0 beside the re-rendered s0 and their difference. The re-rendering is absolute:
/// the model's s0 times the frame's normaliser N at each surface point (DN), summed over colour
/// bands as the captured s0 is (a monochrome pixel sees the mean of the bands), clipped where
/// the sensor clips. No fitted scale: a wrong albedo or radiometry shows.
fn comparison(
    mesh: &TriangleMesh,
    fits: &[VertexFit],
    view: &ViewCamera,
    camera: &CameraModel,
    flash: &FlashSpec,
    captured: &CapturedS0,
) -> (images::Picture, Option<f64>) {
    let models = images::pixel_models(mesh, fits, view);
    let rig_view = ViewGeometry::from_rig(captured.frame_id, &captured.world_from_camera, flash);
    let camera_from_world = captured.world_from_camera.inverse();
    let band_weight = if captured.bands >= 3 { 1.0 } else { 1.0 / 3.0 };
    let pairs: Vec<Option<(f64, f64)>> = models
        .par_iter()
        .map(|m| {
            let (p, n, point, hit) = m.as_ref()?;
            // Vertices whose highlight was clipped never saw their specular peak: their lobe is
            // extrapolated, so they are left out (grey) rather than compared with clipped data.
            if hit.vertices.iter().any(|&v| {
                fits[v as usize]
                    .flags
                    .contains(&crate::data::FitFlag::Saturated)
            }) {
                return None;
            }
            let p_cam = camera_from_world.transform_point(point);
            let px = camera.project(&p_cam)?;
            // The surface must face the captured camera (the framing camera is the same pose).
            let to_camera = (Point3::from(rig_view.camera_position_world) - point).normalize();
            if Vector3::from(*n).dot(&to_camera) <= 0.0 {
                return None;
            }
            let observed = captured.at_raw(px[0], px[1])?;
            let g = rig_view
                .geometry_at(point)?
                .model::<f64>(ellipso_model::optics::Vec3::from_f64(*n))
                .ok()?;
            let normaliser = captured.normaliser.at(point);
            if !(normaliser.is_finite() && normaliser >= 0.0) {
                return None;
            }
            let s = apply(&g, p, FlashPolariser::default().stokes(1.0));
            let predicted: f64 = band_weight * s.iter().map(|s| s.s0).sum::<f64>() * normaliser;
            Some((observed, predicted))
        })
        .collect();
    // The sensor clips: a re-rendered value above the brightest captured one (a sharp
    // highlight the model puts where the sampled frames never resolved it) is clipped there too.
    let hi = pairs.iter().flatten().map(|p| p.0).fold(1e-9, f64::max);
    let rendered = |p: f64| p.min(hi);
    let (mut e2, mut c2) = (0.0, 0.0);
    for (c, p) in pairs.iter().flatten() {
        e2 += (c - rendered(*p)).powi(2);
        c2 += c * c;
    }
    let rmse = (c2 > 0.0).then(|| (e2 / c2).sqrt());
    let w = view.width;
    let h = view.height;
    let captured_v: Vec<Option<f64>> = pairs.iter().map(|p| p.map(|p| p.0)).collect();
    let rendered_v: Vec<Option<f64>> = pairs.iter().map(|p| p.map(|p| rendered(p.1))).collect();
    let error_v: Vec<Option<f64>> = pairs
        .iter()
        .map(|p| p.map(|p| (p.0 - rendered(p.1)) / hi))
        .collect();
    // This picture's RMSE is over its pixels (the model interpolated between vertices, edges
    // and one frame only); the fit's headline score is over the held-out frames' samples at
    // the vertices. Both are named, so the two numbers are not taken for one.
    let title = format!(
        "frame {}{}: captured and re-rendered s0 · relative RMSE {} over this picture's pixels{}",
        captured.frame_id,
        if captured.held_out { " (held out)" } else { "" },
        rmse.map_or("n/a".into(), |r| format!("{r:.3}")),
        captured
            .held_out_samples_rmse
            .map_or(String::new(), |r| format!(
                ", {r:.3} over all held-out samples (the fit's score)"
            ))
    );
    let figure = Figure::new(title)
        .columns(3)
        .image(
            "captured s0",
            Pixels::scalar(w, h, &captured_v, ColourMap::Viridis, 0.0, hi),
        )
        .image(
            "re-rendered s0",
            Pixels::scalar(w, h, &rendered_v, ColourMap::Viridis, 0.0, hi),
        )
        .image(
            "difference / max s0",
            Pixels::scalar(w, h, &error_v, ColourMap::Diverging, -0.25, 0.25),
        )
        .key(Key::Bar {
            map: ColourMap::Viridis,
            lo: 0.0,
            hi,
            label: "s0 (DN, summed over colour bands)".into(),
        })
        .key(Key::Bar {
            map: ColourMap::Diverging,
            lo: -0.25,
            hi: 0.25,
            label: "(captured − re-rendered) / max s0".into(),
        });
    (
        images::Picture {
            name: "rerender-vs-captured",
            figure,
        },
        rmse,
    )
}
