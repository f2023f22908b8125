//! `ellipso export mitsuba FIT_DIR --out DIR`: a fit directory as a Mitsuba 3 scene that renders
//! in the polarised variants as the rig sees it, with ellipso's own renders of the same view
//! beside it, so a user can check the hand-over.
//!
//! Contract: from `fit.ply` and `fit-view.json` alone, [`export`] writes into `out`:
//! - `objects.xml` — what both scenes share: the fitted mesh with Mitsuba's `pplastic` BSDF
//!   (GGX), η and α per vertex (`mesh_attribute`), diffuse and specular albedo from bitmaps
//!   ([`atlas`]); the pictures' camera (ideal pinhole at the chosen captured view's pose,
//!   `fit-view.json`); the rig's flash at that pose as an isotropic point light of intensity 2
//!   behind an ideal linear polariser (a 20 × 20 mm `polarizer` sheet 5 mm in front of it,
//!   perpendicular to the optical axis, its transmission axis the flash polariser's), so the
//!   light leaving the sheet is a unit-intensity beam polarised as the rig's flash; a box pixel
//!   filter;
//! - `scene.xml` — for the `*_polarized` variants (`scalar_spectral_polarized`,
//!   `llvm_ad_mono_polarized`, …): the `stokes` integrator around `volpath` (the integrator
//!   that carries light through the polariser, a null surface, on its shadow rays), so the
//!   film holds S0–S3 per pixel in the sensor's frame (x image right, y image up);
//! - `scene-rgb.xml` — the same scene for the RGB variants (`scalar_rgb`): `volpath` alone
//!   (there the polariser is a 50 % neutral filter, so the flash is unpolarised of intensity 1);
//! - `mesh.ply`, `diffuse.exr` (RGB, colour-converted by Mitsuba: spectral upsampling, or
//!   luminance in mono variants), `specular.exr` (one channel `Y`) — what the scenes load;
//! - `ellipso-stokes.exr` — ellipso's render of the same view, parameters and polarised flash
//!   with the single-scattering lobe off: `S0.R/G/B`, `S1.R/G/B`, `S2.R/G/B` (the Stokes vector
//!   reaching the camera in its frame: x image right, y image up; [`stokes_render`]) and `A`;
//! - `ellipso-s0.exr` — the same under the unpolarised flash of `scene-rgb.xml` (`R G B A`,
//!   [`super::images::radiance`]);
//!
//!   in both, `A` = 1 where the pixel's triangle has three reliable vertices, so ellipso's value
//!   there comes from exactly the exported parameters — compare there; no shadows;
//! - `README.md` — the parameter mapping and what the hand-over loses.
//!
//! The mapping (`docs/model.md` §3–§4): Mitsuba's `eta` = η; `alpha` = σ_s (the model's GGX α
//! is σ); `diffuse_reflectance` = π·ρ_d / k (ellipso's ρ_d has 1/π absorbed; `pplastic`
//! divides by π; both attenuate by the Fresnel transmissions in and out, as Mueller matrices in
//! the polarised variants); `specular_reflectance` = ρ_s / k. ρ_ss and σ_ss have no `pplastic`
//! counterpart and are dropped.
//!
//! Radiometric scale: the fit's albedos are relative to the rig's radiometric normaliser, and
//! can exceed 1 (the demo's ceramic: π·ρ_d 2.13, ρ_s up to 1.88); a renderer's reflectances
//! cannot (spectral variants clamp the RGB they upsample to [0, 1]). So every reflectance is
//! divided by k = [`albedo_scale`] (the largest π·ρ_d channel or ρ_s, at least 1) and the
//! emitter's intensity multiplied by k: both lobes are linear in their albedo and the render in
//! the light, so the radiance is the fit's, in every variant.

pub mod atlas;

use std::path::{Path, PathBuf};

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::optics::pbrdf::PbrdfParams;
use ellipso_report::exr_image::FloatImage;
use nalgebra::{Point3, Vector3};

use super::ply::read_fit_ply;
use super::view_file;
use crate::data::VertexFit;

/// Settings of the exported scene.
#[derive(Clone, Debug)]
pub struct MitsubaOptions {
    /// Samples per pixel written into the scene (`spp` default, overridable at load time).
    pub spp: u32,
}

impl Default for MitsubaOptions {
    fn default() -> Self {
        Self { spp: 64 }
    }
}

/// What [`export`] wrote.
#[derive(Clone, Debug)]
pub struct MitsubaReport {
    /// Every file, in writing order.
    pub files: Vec<PathBuf>,
    /// Vertices and faces of the fitted mesh.
    pub vertices: usize,
    /// Faces.
    pub faces: usize,
    /// Vertices whose parameters were clamped into Mitsuba's domain (η > 1, α > 0).
    pub clamped: usize,
    /// The factor the albedos were divided by and the emitter's intensity multiplied by
    /// ([`albedo_scale`]; 1 where every reflectance was already at most 1).
    pub albedo_scale: f64,
}

/// Errors of the export; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum MitsubaError {
    /// A file of the fit directory is missing or unreadable.
    #[error("{0}")]
    Input(String),
    /// Writing a file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// Writing an EXR file.
    #[error(transparent)]
    Exr(#[from] ellipso_report::exr_image::ExrError),
}

/// Mitsuba's relative index must differ from 1; η at the model's lower bound becomes this.
const ETA_MIN: f32 = 1.001;
/// GGX α below this is a numerical delta in single precision; σ_s below becomes this.
const ALPHA_MIN: f32 = 1e-3;

/// Exports `fit_dir` to `out` (see the module doc).
pub fn export(
    fit_dir: &Path,
    out: &Path,
    options: &MitsubaOptions,
) -> Result<MitsubaReport, MitsubaError> {
    let ply_path = fit_dir.join("fit.ply");
    let vertices = read_fit_ply(&ply_path).map_err(|e| MitsubaError::Input(e.to_string()))?;
    let mesh = TriangleMesh::load(&ply_path)
        .map_err(|e| MitsubaError::Input(format!("{}: {e}", ply_path.display())))?;
    if mesh.positions().len() != vertices.len() || mesh.triangles().is_empty() {
        return Err(MitsubaError::Input(format!(
            "{}: {} vertices with parameters, {} mesh vertices, {} faces",
            ply_path.display(),
            vertices.len(),
            mesh.positions().len(),
            mesh.triangles().len()
        )));
    }
    let view = view_file::read(fit_dir).map_err(MitsubaError::Input)?;
    std::fs::create_dir_all(out).map_err(|source| MitsubaError::Io {
        path: out.display().to_string(),
        source,
    })?;
    let mut files = Vec::new();
    let mut put = |name: &str, bytes: Vec<u8>| -> Result<(), MitsubaError> {
        let path = out.join(name);
        ellipso_report::atomic_file::write(&path, bytes).map_err(|source| MitsubaError::Io {
            path: path.display().to_string(),
            source,
        })?;
        files.push(path);
        Ok(())
    };

    let faces = mesh.triangles();
    let eta: Vec<f32> = vertices.iter().map(|v| v.params[0].max(ETA_MIN)).collect();
    let alpha: Vec<f32> = vertices
        .iter()
        .map(|v| v.params[1].max(ALPHA_MIN))
        .collect();
    let clamped = vertices
        .iter()
        .filter(|v| v.params[0] < ETA_MIN || v.params[1] < ALPHA_MIN)
        .count();
    let positions: Vec<[f32; 3]> = vertices.iter().map(|v| v.position).collect();
    let normals: Vec<[f32; 3]> = vertices.iter().map(|v| v.normal).collect();
    let split = atlas::split(&positions, &normals, faces, &eta, &alpha);
    put("mesh.ply", split.ply_bytes())?;
    let pi = std::f32::consts::PI;
    let diffuse: Vec<[f32; 3]> = vertices
        .iter()
        .map(|v| [v.params[7] * pi, v.params[8] * pi, v.params[9] * pi])
        .collect();
    let specular: Vec<[f32; 3]> = vertices.iter().map(|v| [v.params[3]; 3]).collect();
    let baked = [atlas::bake(faces, &diffuse), atlas::bake(faces, &specular)];
    // Reflectances a renderer accepts (≤ 1, every texel the bilinear lookup reads); the fit's
    // scale goes on the emitter instead (module doc, "Radiometric scale").
    let scale = albedo_scale(baked.iter().flat_map(|b| b.rgb.iter()).flatten().copied());
    for ((name, channels), baked) in [
        ("diffuse.exr", &["R", "G", "B"][..]),
        // ρ_s is grey: one channel, which no variant colour-converts
        ("specular.exr", &["Y"][..]),
    ]
    .into_iter()
    .zip(baked)
    {
        let mut image = FloatImage::new(baked.width, baked.height)?;
        for (channel, plane) in channels.iter().zip(baked.rgb) {
            image.push_f32(channel, plane.into_iter().map(|v| v / scale).collect())?;
        }
        put(name, image.encode(&out.join(name))?)?;
    }
    let axis = polariser_axis(&view)?;
    put(
        "objects.xml",
        objects_xml(&view, &axis, options, scale).into_bytes(),
    )?;
    put("scene.xml", scene_xml(true).into_bytes())?;
    put("scene-rgb.xml", scene_xml(false).into_bytes())?;
    let fits = fits_of(&vertices);
    let reference = reference_render(&mesh, &fits, &view)?;
    put(
        "ellipso-s0.exr",
        reference.encode(&out.join("ellipso-s0.exr"))?,
    )?;
    let stokes = stokes_render(&mesh, &fits, &view, &axis)?;
    put(
        "ellipso-stokes.exr",
        stokes.encode(&out.join("ellipso-stokes.exr"))?,
    )?;
    put("README.md", README.as_bytes().to_vec())?;
    Ok(MitsubaReport {
        files,
        vertices: vertices.len(),
        faces: faces.len(),
        clamped,
        albedo_scale: f64::from(scale),
    })
}

/// The factor that brings every exported reflectance to at most 1: the largest π·ρ_d channel
/// or ρ_s texel of the baked atlases (vertex values and each cell's affine fourth texel, which
/// the bilinear lookup reads too), 1 where none exceeds 1 (non-finite values are left out; the
/// export writes them as the fit has them). Both lobes are linear in their albedo and the
/// render linear in the light, so albedos ÷ k under an emitter × k render the same radiance.
pub fn albedo_scale(texels: impl IntoIterator<Item = f32>) -> f32 {
    texels
        .into_iter()
        .filter(|v| v.is_finite())
        .fold(1.0, f32::max)
}

/// The exported vertices as fits with the single-scattering lobe off (what `pplastic` renders).
fn fits_of(vertices: &[super::ply::FitVertex]) -> Vec<VertexFit> {
    vertices
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let p = v.params.map(f64::from);
            VertexFit {
                vertex: i as u32,
                params: PbrdfParams {
                    eta: p[0],
                    sigma_s: p[1],
                    sigma_ss: p[2],
                    rho_s: p[3],
                    rho_ss: [0.0; 3],
                    rho_d: [p[7], p[8], p[9]],
                },
                normal_world: v.normal.map(f64::from),
                std_error: v.std_error.map(f64::from),
                normal_std_error_deg: f64::from(v.normal_std_deg),
                samples_used: v.samples,
                cost: 0.0,
                iterations: 0,
                flags: crate::data::FitFlag::from_mask(v.flags),
                eta_unpooled: None,
                eta_prior_only: false,
                gates: Default::default(),
            }
        })
        .collect()
}

/// The flash polariser's transmission axis of `view` (an unpolarised rig cannot be exported as
/// the rig: the error says so).
fn polariser_axis(view: &view_file::PictureView) -> Result<Vector3<f64>, MitsubaError> {
    view.flash_polariser_axis_world
        .map(Vector3::from)
        .ok_or_else(|| {
            MitsubaError::Input(format!(
                "{}: no flash_polariser_axis_world (an unpolarised flash, or a fit directory \
                 written by an older ellipso: re-run `ellipso fit`)",
                view_file::FILE_NAME
            ))
        })
}

/// `A` of the reference renders: 1 where all three vertices of the pixel's triangle are
/// reliable (there ellipso interpolates exactly the exported values; elsewhere its pictures
/// interpolate over the reliable vertices only, and Mitsuba sees every vertex).
fn coverage(models: &[super::images::PixelModel], fits: &[VertexFit]) -> Vec<f32> {
    let reliable: Vec<bool> = fits.iter().map(VertexFit::is_reliable).collect();
    models
        .iter()
        .map(|m| match m {
            Some((.., hit)) if hit.vertices.iter().all(|&v| reliable[v as usize]) => 1.0,
            _ => 0.0,
        })
        .collect()
}

/// ellipso's render of the exported view under the unpolarised flash (see the module doc).
fn reference_render(
    mesh: &TriangleMesh,
    fits: &[VertexFit],
    view: &view_file::PictureView,
) -> Result<FloatImage, MitsubaError> {
    let camera = view.camera();
    let models = super::images::pixel_models(mesh, fits, &camera);
    let light = Point3::from(view.flash_position_world);
    let rgb = super::images::radiance(&models, &camera, &light);
    let mut planes = [(); 3].map(|_| vec![0.0f32; rgb.len()]);
    for (i, c) in rgb.iter().enumerate() {
        if let Some(c) = c {
            for (plane, v) in planes.iter_mut().zip(c) {
                plane[i] = *v as f32;
            }
        }
    }
    let mut image = FloatImage::new(camera.width as usize, camera.height as usize)?;
    for (name, plane) in ["R", "G", "B"].into_iter().zip(planes) {
        image.push_f32(name, plane)?;
    }
    image.push_f32("A", coverage(&models, fits))?;
    Ok(image)
}

/// ellipso's Stokes render of the exported view under the polarised flash: per pixel and colour
/// channel the Stokes vector the camera receives, `P·s_flash/d²` with `s_flash` = (1, 1, 0, 0)
/// in the light frame whose x is the polariser axis (`docs/model.md` §4, the renderer's own
/// geometry: [`crate::data::ViewGeometry::geometry_at`]), expressed in the camera frame
/// (x image right, y image up, z toward the camera) — the basis of Mitsuba's `stokes`
/// integrator.
pub fn stokes_render(
    mesh: &TriangleMesh,
    fits: &[VertexFit],
    view: &view_file::PictureView,
    polariser_axis: &Vector3<f64>,
) -> Result<FloatImage, MitsubaError> {
    use ellipso_model::optics::measure::FlashPolariser;
    let camera = view.camera();
    let models = super::images::pixel_models(mesh, fits, &camera);
    let pose = camera.world_from_camera;
    let rig = crate::data::ViewGeometry {
        frame_id: 0,
        camera_position_world: pose.translation.vector.into(),
        camera_up_world: (pose.rotation * -Vector3::y()).into(),
        flash_position_world: view.flash_position_world,
        polariser_axis_world: Some((*polariser_axis).into()),
        camera_axis_world: None,
    };
    let mut planes = [(); 9].map(|_| vec![0.0f32; models.len()]);
    for (i, m) in models.iter().enumerate() {
        let Some((p, n, point, _)) = m else {
            continue;
        };
        let Some(g) = rig.geometry_at(point) else {
            continue;
        };
        let Ok(model) = g.model::<f64>(ellipso_model::optics::Vec3::from_f64(*n)) else {
            continue;
        };
        let d2 = g.light_distance_m.powi(2).max(1e-12);
        let s =
            ellipso_model::optics::pbrdf::apply(&model, p, FlashPolariser::default().stokes(1.0));
        for (c, stokes) in s.iter().enumerate() {
            for (k, v) in [stokes.s0, stokes.s1, stokes.s2].into_iter().enumerate() {
                planes[3 * k + c][i] = (v / d2) as f32;
            }
        }
    }
    let mut image = FloatImage::new(camera.width as usize, camera.height as usize)?;
    let names = [
        "S0.R", "S0.G", "S0.B", "S1.R", "S1.G", "S1.B", "S2.R", "S2.G", "S2.B",
    ];
    for (name, plane) in names.into_iter().zip(planes) {
        image.push_f32(name, plane)?;
    }
    image.push_f32("A", coverage(&models, fits))?;
    Ok(image)
}

/// `a, b, c` with enough digits for f64 round trips of the pose.
fn triple(v: &Vector3<f64>) -> String {
    format!("{:e}, {:e}, {:e}", v.x, v.y, v.z)
}

/// The scene file of the polarised (`polarised`) or the RGB variants: the integrator, then
/// `objects.xml`.
fn scene_xml(polarised: bool) -> String {
    let (variants, integrator) = if polarised {
        (
            "a *_polarized variant: mitsuba -m scalar_spectral_polarized scene.xml -o ../renders/stokes.exr (or llvm_ad_mono_polarized; renders beside this folder, not in it)",
            r#"<integrator type="stokes">
        <integrator type="volpath">
            <integer name="max_depth" value="2"/>
        </integrator>
    </integrator>"#,
        )
    } else {
        (
            "an RGB variant: mitsuba -m scalar_rgb scene-rgb.xml -o ../renders/rgb.exr (the polarised scene is scene.xml)",
            r#"<integrator type="volpath">
        <integer name="max_depth" value="2"/>
    </integrator>"#,
        )
    };
    format!(
        r#"<?xml version="1.0" encoding="utf-8"?>
<!-- Written by `ellipso export mitsuba` (README.md beside this file: the mapping and what is lost).
     Render in {variants}; -Dspp=N changes the samples.
     volpath (direct light only: max_depth 2) carries the flash's light through the polariser sheet. -->
<scene version="3.0.0">
    {integrator}
    <include filename="objects.xml"/>
</scene>
"#
    )
}

/// The camera, the polarised flash and the fitted object (see the module doc).
fn objects_xml(
    view: &view_file::PictureView,
    polariser_axis: &Vector3<f64>,
    options: &MitsubaOptions,
    albedo_scale: f32,
) -> String {
    let intensity = 2.0 * f64::from(albedo_scale);
    let camera = view.camera();
    let pose = camera.world_from_camera;
    let origin = pose.translation.vector;
    // OpenCV axes (x right, y down, z forward) → Mitsuba's look-at (forward, up = −y).
    let forward = pose.rotation * Vector3::z();
    let target = origin + forward;
    let up = pose.rotation * -Vector3::y();
    let fov_x_deg = 2.0
        * (f64::from(camera.width) / (2.0 * camera.focal_px()))
            .atan()
            .to_degrees();
    let flash = Vector3::from(view.flash_position_world);
    let [fx, fy, fz] = view.flash_position_world;
    // The polariser sheet: a `rectangle` (local x, y ∈ [−1, 1], normal z) whose local x is the
    // transmission axis (Mitsuba's polarizer absorbs along the surface's v = local y), facing
    // along the optical axis, 5 mm in front of the flash, 20 × 20 mm: it covers every ray from
    // the flash to the object (within 60° of the axis) and none from the object to the camera
    // (tens of millimetres to the side of it).
    let half = 0.010;
    let normal = (forward - polariser_axis * polariser_axis.dot(&forward)).normalize();
    let x_axis = polariser_axis.normalize();
    let y_axis = normal.cross(&x_axis);
    let centre = flash + normal * 0.005;
    let m = [x_axis * half, y_axis * half, normal];
    let matrix: Vec<String> = (0..3)
        .flat_map(|r| {
            let row = [m[0][r], m[1][r], m[2][r], centre[r]];
            row.map(|v| format!("{v:e}"))
        })
        .chain(["0", "0", "0", "1"].map(String::from))
        .collect();
    format!(
        r#"<?xml version="1.0" encoding="utf-8"?>
<!-- Written by `ellipso export mitsuba`: the camera, flash and object that scene.xml (polarised variants)
     and scene-rgb.xml (RGB variants) share. -->
<scene version="3.0.0">
    <default name="spp" value="{spp}"/>
    <!-- the fit pictures' camera: ideal pinhole at the chosen captured view's pose (board frame, metres) -->
    <sensor type="perspective">
        <string name="fov_axis" value="x"/>
        <float name="fov" value="{fov_x_deg:.9}"/>
        <float name="near_clip" value="0.001"/>
        <float name="far_clip" value="1000"/>
        <transform name="to_world">
            <lookat origin="{origin}" target="{target}" up="{up}"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="$spp"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="{width}"/>
            <integer name="height" value="{height}"/>
            <rfilter type="box"/>
            <string name="pixel_format" value="rgba"/>
        </film>
    </sensor>
    <!-- the rig's flash at that pose: an isotropic point light of intensity 2 × {albedo_scale} behind an
         ideal linear polariser, whose transmission axis is the flash polariser's: {albedo_scale} × unit
         intensity, polarised; the albedos in diffuse.exr and specular.exr are the fit's ÷ {albedo_scale}, so
         every reflectance is at most 1 and the render is the fit's -->
    <emitter type="point">
        <point name="position" x="{fx:e}" y="{fy:e}" z="{fz:e}"/>
        <rgb name="intensity" value="{intensity:e}, {intensity:e}, {intensity:e}"/>
    </emitter>
    <shape type="rectangle">
        <transform name="to_world">
            <matrix value="{matrix}"/>
        </transform>
        <bsdf type="polarizer"/>
    </shape>
    <shape type="ply">
        <string name="filename" value="mesh.ply"/>
        <bsdf type="pplastic">
            <string name="distribution" value="ggx"/>
            <texture type="mesh_attribute" name="eta">
                <string name="name" value="vertex_eta"/>
            </texture>
            <texture type="mesh_attribute" name="alpha">
                <string name="name" value="vertex_alpha"/>
            </texture>
            <texture type="bitmap" name="diffuse_reflectance">
                <string name="filename" value="diffuse.exr"/>
                <string name="filter_type" value="bilinear"/>
                <string name="wrap_mode" value="clamp"/>
            </texture>
            <texture type="bitmap" name="specular_reflectance">
                <string name="filename" value="specular.exr"/>
                <string name="filter_type" value="bilinear"/>
                <string name="wrap_mode" value="clamp"/>
            </texture>
        </bsdf>
    </shape>
</scene>
"#,
        spp = options.spp.max(1),
        origin = triple(&origin),
        target = triple(&target),
        up = triple(&up),
        width = camera.width,
        height = camera.height,
        matrix = matrix.join(" "),
    )
}

/// The README written beside the scene.
const README: &str = include_str!("mitsuba/README.md");

#[cfg(test)]
mod tests;
