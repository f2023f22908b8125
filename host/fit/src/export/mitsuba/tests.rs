//! Tests of the Mitsuba export: the scene files, the references, the albedo scale.

use super::*;
use crate::export::raster::ViewCamera;
use ellipso_model::geometry::procedural::icosphere;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

/// A fit directory of a uniform sphere seen from above, written by the fit's own writers,
/// with ρd's red channel `rho_d_red`.
fn fit_dir(dir: &Path, rho_d_red: f64) {
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
                rho_d: [rho_d_red, 0.1, 0.05],
            },
            normal_world: d.into_inner().into(),
            std_error: [0.01; 10],
            normal_std_error_deg: 0.5,
            samples_used: 30,
            cost: 1.0,
            iterations: 3,
            flags: vec![],
            eta_unpooled: None,
            eta_prior_only: false,
            gates: Default::default(),
        })
        .collect();
    super::super::ply::write_fit_ply(&dir.join("fit.ply"), &mesh, &fits, None).unwrap();
    let pose = Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 0.5),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    );
    let camera = ViewCamera::framing(pose, 40, 32, &Point3::origin(), 0.04);
    let flash = pose.transform_point(&Point3::new(0.0, -0.03, 0.0));
    let view = view_file::PictureView::new(&camera, &flash, &Point3::new(0.1, 0.1, 0.3))
        .with_polariser(Some((pose.rotation * Vector3::x()).into()));
    view_file::write(dir, &view).unwrap();
}

#[test]
fn a_fit_directory_becomes_a_scene_with_its_reference_render() {
    let tmp = tempfile::tempdir().unwrap();
    fit_dir(tmp.path(), 0.2);
    let out = tmp.path().join("mitsuba");
    let report = export(tmp.path(), &out, &MitsubaOptions { spp: 8 }).unwrap();
    assert_eq!(report.files.len(), 9);
    assert_eq!(report.clamped, 1, "vertex 0 has eta = 1");
    let scene = std::fs::read_to_string(out.join("scene.xml")).unwrap();
    assert!(scene.contains(r#"<integrator type="stokes">"#) && scene.contains("volpath"));
    assert!(scene.contains(r#"<include filename="objects.xml"/>"#));
    let xml = std::fs::read_to_string(out.join("objects.xml")).unwrap();
    assert!(xml.contains(r#"<bsdf type="polarizer"/>"#));
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
fn albedos_above_one_go_to_the_emitter() {
    let tmp = tempfile::tempdir().unwrap();
    // π·ρd = 1.571 in red: above what a renderer takes as a reflectance
    fit_dir(tmp.path(), 0.5);
    let out = tmp.path().join("mitsuba");
    let report = export(tmp.path(), &out, &MitsubaOptions { spp: 8 }).unwrap();
    let k = 0.5 * std::f64::consts::PI;
    assert!(
        (report.albedo_scale - k).abs() < 1e-5,
        "{}",
        report.albedo_scale
    );
    let diffuse = FloatImage::read(&out.join("diffuse.exr")).unwrap();
    let red = diffuse.f32_channel("R").unwrap();
    let green = diffuse.f32_channel("G").unwrap();
    let top = red.iter().copied().fold(0.0f32, f32::max);
    assert!((top - 1.0).abs() < 1e-5, "{top}");
    // the ratios stay: green is π·0.1/k
    let g = green.iter().copied().fold(0.0f32, f32::max);
    assert!((f64::from(g) - 0.1 * std::f64::consts::PI / k).abs() < 1e-5);
    let specular = FloatImage::read(&out.join("specular.exr")).unwrap();
    let s = specular
        .f32_channel("Y")
        .unwrap()
        .iter()
        .copied()
        .fold(0.0f32, f32::max);
    assert!((f64::from(s) - 0.8 / k).abs() < 1e-5, "{s}");
    // and the flash is k times brighter
    let xml = std::fs::read_to_string(out.join("objects.xml")).unwrap();
    let intensity = format!("{:e}", 2.0 * f64::from(k as f32));
    assert!(xml.contains(&format!(r#"value="{intensity}, "#)), "{xml}");
    // ellipso's own references are the fit's, unscaled
    let reference = FloatImage::read(&out.join("ellipso-s0.exr")).unwrap();
    assert!(reference.f32_channel("R").unwrap().iter().any(|v| *v > 0.0));
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
    fit_dir(tmp.path(), 0.2);
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
