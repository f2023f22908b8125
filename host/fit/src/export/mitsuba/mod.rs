//! `ellipso export mitsuba FIT_DIR --out DIR`: a fit directory as a Mitsuba 3 scene, with
//! ellipso's own render of the same view beside it, so a user can check the hand-over.
//!
//! Contract: from `fit.ply` and `fit-view.json` alone, [`export`] writes into `out`:
//! - `scene.xml` — the fitted mesh with Mitsuba's `pplastic` BSDF (GGX), η and α per vertex
//!   (`mesh_attribute`), diffuse and specular albedo from bitmaps ([`atlas`]); the pictures'
//!   camera (ideal pinhole at the chosen captured view's pose, `fit-view.json`); the rig's flash
//!   at that pose as an isotropic unpolarised point light of unit intensity; the `direct`
//!   integrator and a box pixel filter;
//! - `mesh.ply`, `diffuse.exr`, `specular.exr` — what the scene loads;
//! - `ellipso-s0.exr` — ellipso's render of the same view, parameters and light with the
//!   single-scattering lobe off (`R`, `G`, `B` = s0 per colour channel where ellipso draws the
//!   object, [`super::images::radiance`], no shadows, in the units Mitsuba's film gets for that
//!   scene; `A` = 1 where the pixel's triangle has three reliable vertices, so ellipso's value
//!   there comes from exactly the exported parameters — compare there);
//! - `README.md` — the parameter mapping and what the hand-over loses.
//!
//! The mapping (`docs/model.md` §3–§4): Mitsuba's `eta` = η; `alpha` = σ_s (the model's GGX α
//! is σ); `diffuse_reflectance` = π·ρ_d (ellipso's ρ_d has 1/π absorbed; `pplastic`
//! divides by π; both attenuate by the unpolarised Fresnel transmissions in and out);
//! `specular_reflectance` = ρ_s. ρ_ss and σ_ss have no `pplastic` counterpart and are dropped.

pub mod atlas;

use std::path::{Path, PathBuf};

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::optics::pbrdf::PbrdfParams;
use ellipso_report::exr_image::FloatImage;
use nalgebra::{Point3, Vector3};

use super::ply::{FLAG_BITS, read_fit_ply};
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
    for (name, values) in [("diffuse.exr", &diffuse), ("specular.exr", &specular)] {
        let baked = atlas::bake(faces, values);
        let mut image = FloatImage::new(baked.width, baked.height)?;
        for (channel, plane) in ["R", "G", "B"].into_iter().zip(baked.rgb) {
            image.push_f32(channel, plane)?;
        }
        put(name, image.encode(&out.join(name))?)?;
    }
    put("scene.xml", scene_xml(&view, options).into_bytes())?;
    let reference = reference_render(&mesh, &vertices, &view)?;
    put(
        "ellipso-s0.exr",
        reference.encode(&out.join("ellipso-s0.exr"))?,
    )?;
    put("README.md", README.as_bytes().to_vec())?;
    Ok(MitsubaReport {
        files,
        vertices: vertices.len(),
        faces: faces.len(),
        clamped,
    })
}

/// ellipso's render of the exported view (see the module doc), single scattering off.
fn reference_render(
    mesh: &TriangleMesh,
    vertices: &[super::ply::FitVertex],
    view: &view_file::PictureView,
) -> Result<FloatImage, MitsubaError> {
    let fits: Vec<VertexFit> = vertices
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
                flags: FLAG_BITS
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| v.flags & (1 << k) != 0)
                    .map(|(_, f)| *f)
                    .collect(),
            }
        })
        .collect();
    let camera = view.camera();
    let models = super::images::pixel_models(mesh, &fits, &camera);
    let light = Point3::from(view.flash_position_world);
    let rgb = super::images::radiance(&models, &camera, &light);
    // A = 1 only where all three vertices of the pixel's triangle are reliable: there ellipso
    // interpolates exactly the exported values (elsewhere its pictures interpolate over the
    // reliable vertices only, and Mitsuba sees every vertex).
    let reliable: Vec<bool> = fits.iter().map(VertexFit::is_reliable).collect();
    let mut planes = [(); 4].map(|_| vec![0.0f32; rgb.len()]);
    for (i, (c, m)) in rgb.iter().zip(&models).enumerate() {
        if let (Some(c), Some((.., hit))) = (c, m) {
            for (plane, v) in planes.iter_mut().zip(c) {
                plane[i] = *v as f32;
            }
            if hit.vertices.iter().all(|&v| reliable[v as usize]) {
                planes[3][i] = 1.0;
            }
        }
    }
    let mut image = FloatImage::new(camera.width as usize, camera.height as usize)?;
    for (name, plane) in ["R", "G", "B", "A"].into_iter().zip(planes) {
        image.push_f32(name, plane)?;
    }
    Ok(image)
}

/// `a, b, c` with enough digits for f64 round trips of the pose.
fn triple(v: &Vector3<f64>) -> String {
    format!("{:e}, {:e}, {:e}", v.x, v.y, v.z)
}

/// The scene file (see the module doc).
fn scene_xml(view: &view_file::PictureView, options: &MitsubaOptions) -> String {
    let camera = view.camera();
    let pose = camera.world_from_camera;
    let origin = pose.translation.vector;
    // OpenCV axes (x right, y down, z forward) → Mitsuba's look-at (forward, up = −y).
    let target = origin + pose.rotation * Vector3::z();
    let up = pose.rotation * -Vector3::y();
    let fov_x_deg = 2.0
        * (f64::from(camera.width) / (2.0 * camera.focal_px))
            .atan()
            .to_degrees();
    let [fx, fy, fz] = view.flash_position_world;
    format!(
        r#"<?xml version="1.0" encoding="utf-8"?>
<!-- Written by `ellipso export mitsuba` (README.md beside this file: the mapping and what is lost).
     Render: mitsuba -m scalar_rgb scene.xml  (or -m llvm_ad_rgb; -Dspp=N to change the samples) -->
<scene version="3.0.0">
    <default name="spp" value="{spp}"/>
    <integrator type="direct">
        <integer name="emitter_samples" value="1"/>
        <integer name="bsdf_samples" value="0"/>
    </integrator>
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
    <!-- the rig's flash at that pose: isotropic, unpolarised, unit intensity (README.md) -->
    <emitter type="point">
        <point name="position" x="{fx:e}" y="{fy:e}" z="{fz:e}"/>
        <rgb name="intensity" value="1, 1, 1"/>
    </emitter>
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
                <boolean name="raw" value="true"/>
                <string name="filter_type" value="bilinear"/>
                <string name="wrap_mode" value="clamp"/>
            </texture>
            <texture type="bitmap" name="specular_reflectance">
                <string name="filename" value="specular.exr"/>
                <boolean name="raw" value="true"/>
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
    )
}

/// The README written beside the scene.
const README: &str = include_str!("README.md");

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::raster::ViewCamera;
    use ellipso_model::geometry::procedural::icosphere;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};

    /// A fit directory of a uniform sphere seen from above, written by the fit's own writers.
    fn fit_dir(dir: &Path) {
        let (dirs, faces) = icosphere(2);
        let pos = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * 0.04))
            .collect();
        let mesh = TriangleMesh::new(pos, None, None, faces).unwrap();
        let fits: Vec<VertexFit> = dirs
            .iter()
            .enumerate()
            .map(|(v, d)| VertexFit {
                vertex: v as u32,
                params: PbrdfParams {
                    eta: if v == 0 { 1.0 } else { 1.5 },
                    sigma_s: 0.2,
                    sigma_ss: 0.4,
                    rho_s: 0.8,
                    rho_ss: [0.3; 3],
                    rho_d: [0.2, 0.1, 0.05],
                },
                normal_world: d.into_inner().into(),
                std_error: [0.01; 10],
                normal_std_error_deg: 0.5,
                samples_used: 30,
                cost: 1.0,
                iterations: 3,
                flags: vec![],
            })
            .collect();
        super::super::ply::write_fit_ply(&dir.join("fit.ply"), &mesh, &fits).unwrap();
        let pose = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        let camera = ViewCamera::framing(pose, 40, 32, &Point3::origin(), 0.04);
        let flash = pose.transform_point(&Point3::new(0.0, -0.03, 0.0));
        let view = view_file::PictureView::new(&camera, &flash, &Point3::new(0.1, 0.1, 0.3));
        view_file::write(dir, &view).unwrap();
    }

    #[test]
    fn a_fit_directory_becomes_a_scene_with_its_reference_render() {
        let tmp = tempfile::tempdir().unwrap();
        fit_dir(tmp.path());
        let out = tmp.path().join("mitsuba");
        let report = export(tmp.path(), &out, &MitsubaOptions { spp: 8 }).unwrap();
        assert_eq!(report.files.len(), 6);
        assert_eq!(report.clamped, 1, "vertex 0 has eta = 1");
        let xml = std::fs::read_to_string(out.join("scene.xml")).unwrap();
        for want in [
            r#"<bsdf type="pplastic">"#,
            r#"value="ggx""#,
            r#"value="vertex_eta""#,
            r#"value="vertex_alpha""#,
            r#"value="diffuse.exr""#,
            r#"<default name="spp" value="8"/>"#,
            r#"<integer name="width" value="40"/>"#,
        ] {
            assert!(xml.contains(want), "{want} not in scene.xml");
        }
        // Looking straight down from z = 0.5: the look-at target is below the origin.
        assert!(xml.contains(r#"origin="0e0, 0e0, 5e-1""#), "{xml}");
        let reference = FloatImage::read(&out.join("ellipso-s0.exr")).unwrap();
        let centre = 16 * 40 + 20;
        let a = reference.f32_channel("A").unwrap();
        assert_eq!((a[centre], a[0]), (1.0, 0.0));
        // Single scattering off: the reference equals ellipso's radiance with ρss = 0 (the
        // fitted 0.3 would brighten the head-on highlight).
        let r = f64::from(reference.f32_channel("R").unwrap()[centre]);
        let g = f64::from(reference.f32_channel("G").unwrap()[centre]);
        assert!(r > g && g > 0.0, "{r} {g}");
        let diffuse = FloatImage::read(&out.join("diffuse.exr")).unwrap();
        let d = diffuse.f32_channel("R").unwrap();
        // a uniform ρd: every texel of a used cell (extension texels too) is π·0.2
        let used: Vec<&f32> = d.iter().filter(|v| **v != 0.0).collect();
        assert_eq!(used.len(), 4 * report.faces);
        assert!(
            used.iter()
                .all(|v| (*v - 0.2 * std::f32::consts::PI).abs() < 1e-5)
        );
    }

    #[test]
    fn missing_inputs_are_named() {
        let tmp = tempfile::tempdir().unwrap();
        let e = export(
            tmp.path(),
            &tmp.path().join("o"),
            &MitsubaOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("fit.ply"), "{e}");
        fit_dir(tmp.path());
        std::fs::remove_file(tmp.path().join(view_file::FILE_NAME)).unwrap();
        let e = export(
            tmp.path(),
            &tmp.path().join("o"),
            &MitsubaOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("fit-view.json") && e.contains("re-run"), "{e}");
    }
}
