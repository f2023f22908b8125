//! Export tests: files and pictures from a known uniform material on a sphere.

use super::*;
use crate::data::FitFlag;
use ellipso_model::geometry::procedural::icosphere;
use ellipso_model::optics::pbrdf::PbrdfParams;

fn sphere() -> TriangleMesh {
    let (dirs, faces) = icosphere(3);
    let pos = dirs
        .iter()
        .map(|d| Point3::from(d.into_inner() * 0.04))
        .collect();
    TriangleMesh::new(pos, None, None, faces).unwrap()
}

fn material() -> PbrdfParams<f64> {
    PbrdfParams {
        eta: 1.5,
        sigma_s: 0.1,
        sigma_ss: 0.3,
        rho_s: 1.0,
        rho_ss: [0.1, 0.1, 0.1],
        rho_d: [0.5, 0.3, 0.2],
    }
}

fn fits(mesh: &TriangleMesh) -> Vec<VertexFit> {
    (0..mesh.positions().len())
        .map(|v| VertexFit {
            vertex: v as u32,
            params: material(),
            normal_world: mesh.normals()[v].into_inner().into(),
            std_error: [0.01; 10],
            normal_std_error_deg: 0.3,
            samples_used: 50,
            cost: 1.0,
            iterations: 4,
            flags: if v == 0 {
                vec![FitFlag::TooFewViews]
            } else {
                vec![]
            },
            eta_unpooled: None,
            eta_prior_only: false,
            gates: Default::default(),
        })
        .collect()
}

/// Camera 0.5 m above the sphere looking straight down (OpenCV z forward = world −z).
fn pose() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 0.5),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

/// The shipped sphere scene's `[rig]` table, read without the simulator.
fn sphere_rig() -> toml::Value {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../sim/scenes/sphere.toml");
    let text = std::fs::read_to_string(path).expect("sphere scene reads");
    let scene: toml::Table = toml::from_str(&text).expect("sphere scene parses");
    scene["rig"].clone()
}

/// The sphere scene's flash.
fn flash() -> FlashSpec {
    sphere_rig()["flash"]
        .clone()
        .try_into()
        .expect("the sphere scene's flash")
}

/// The sphere scene's camera model.
fn sphere_camera() -> ellipso_model::camera::CameraModel {
    let camera: ellipso_model::rig::CameraSpec = sphere_rig()["camera"]
        .clone()
        .try_into()
        .expect("the sphere scene's camera");
    camera.camera_model()
}

#[test]
fn every_output_is_written_and_readable() {
    let mesh = sphere();
    let fits = fits(&mesh);
    let dir = tempfile::tempdir().unwrap();
    let camera = sphere_camera();
    let config = ExportConfig {
        picture_px: 48,
        ..ExportConfig::default()
    };
    let report = export_all(
        dir.path(),
        &mesh,
        &fits,
        None,
        &camera,
        &pose(),
        &flash(),
        &config,
        None,
    )
    .unwrap();
    let names: Vec<String> = report
        .files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().to_string())
        .collect();
    for want in [
        "fit.ply",
        "maps.exr",
        "fit-view.json",
        "map-eta.png",
        "map-sigma-s.png",
        "map-sigma-ss.png",
        "map-rho-s.png",
        "map-eta-std.png",
        "map-rho-d.png",
        "map-rho-ss.png",
        "map-normal.png",
        "mueller-grid.png",
        "dolp.png",
        "aolp.png",
        "relit.png",
        "novel-view.png",
    ] {
        assert!(
            names.iter().any(|n| n == want),
            "{want} missing from {names:?}"
        );
    }
    for f in report
        .files
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "png"))
    {
        let img = image::open(f).unwrap();
        assert!(img.width() >= 48 && img.height() >= 48, "{}", f.display());
    }
    // The float maps: the PNG maps' view and pixels, model units, read back with the exr crate.
    let maps = ellipso_report::exr_image::FloatImage::read(&dir.path().join("maps.exr")).unwrap();
    assert_eq!((maps.width, maps.height), (48, 48));
    let a = maps.f32_channel("A").unwrap();
    let centre = 24 * 48 + 24;
    assert_eq!(a[centre], 1.0);
    assert_eq!(a[0], 0.0, "corner is background");
    assert!((maps.f32_channel("eta").unwrap()[centre] - 1.5).abs() < 1e-6);
    assert!((maps.f32_channel("rho_d.G").unwrap()[centre] - 0.3).abs() < 1e-6);
    assert!((maps.f32_channel("rho_ss.B").unwrap()[centre] - 0.1).abs() < 1e-6);
    // the top of the sphere faces the camera straight on: N ≈ +z (toward the viewer)
    assert!(maps.f32_channel("N.Z").unwrap()[centre] > 0.99);
    assert_eq!(maps.f32_channel("sigma_s").unwrap()[0], 0.0);
    // The pictures' view round-trips into the camera the maps were rendered with.
    let view = view_file::read(dir.path()).unwrap();
    assert_eq!((view.width, view.height), (48, 48));
    let flash_world = flash().position_world(&pose());
    assert!((Point3::from(view.flash_position_world) - flash_world).norm() < 1e-12);
    // An unwritable directory is named.
    let blocker = dir.path().join("file");
    std::fs::write(&blocker, b"x").unwrap();
    let e = export_all(
        &blocker.join("sub"),
        &mesh,
        &fits,
        None,
        &camera,
        &pose(),
        &flash(),
        &config,
        None,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("file"), "{e}");
}

/// One identifiability rule: vertices with η unidentifiable on one half of the sphere have
/// std_eta = +inf in `fit.ply`, and `maps.exr` has eta NaN, eta_std +inf and the flag bit on
/// exactly the pixels of triangles touching them — the pixels `map-eta.png` draws grey.
#[test]
fn one_rule_for_the_ply_and_the_float_maps() {
    let mesh = sphere();
    let mut fits = fits(&mesh);
    for (f, p) in fits.iter_mut().zip(mesh.positions()) {
        if p.x > 0.01 {
            f.flags = vec![FitFlag::EtaUnidentifiable];
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let camera = sphere_camera();
    let config = ExportConfig {
        picture_px: 48,
        ..ExportConfig::default()
    };
    export_all(
        dir.path(),
        &mesh,
        &fits,
        None,
        &camera,
        &pose(),
        &flash(),
        &config,
        None,
    )
    .unwrap();
    let back = ply::read_fit_ply(&dir.path().join("fit.ply")).unwrap();
    for (b, f) in back.iter().zip(&fits) {
        let withheld = f.flags.contains(&FitFlag::EtaUnidentifiable) || f.vertex == 0;
        assert_eq!(
            b.std_error[0].is_infinite(),
            withheld,
            "vertex {}",
            f.vertex
        );
    }
    let maps = ellipso_report::exr_image::FloatImage::read(&dir.path().join("maps.exr")).unwrap();
    let eta = maps.f32_channel("eta").unwrap();
    let eta_std = maps.f32_channel("eta_std").unwrap();
    let a = maps.f32_channel("A").unwrap();
    let Some(ellipso_report::exr_image::Samples::U32(flags)) = maps.channel("flags") else {
        panic!("no u32 flags channel");
    };
    let view = view_file::read(dir.path()).unwrap().camera();
    let hits = raster::rasterise(&mesh, &view);
    let (mut nan, mut shown) = (0, 0);
    for (i, hit) in hits.iter().enumerate() {
        if a[i] != 1.0 {
            continue;
        }
        let hit = hit.unwrap();
        let touches = hit
            .vertices
            .iter()
            .any(|&v| fits[v as usize].flags.contains(&FitFlag::EtaUnidentifiable));
        assert_eq!(eta[i].is_nan(), touches, "pixel {i}");
        assert_eq!(eta_std[i].is_infinite(), touches, "pixel {i}");
        assert_eq!(flags[i] & FitFlag::EtaUnidentifiable.bit() != 0, touches);
        if touches {
            nan += 1;
        } else {
            shown += 1;
        }
    }
    assert!(nan > 100 && shown > 100, "{nan} {shown}");
}

#[test]
fn mueller_block_has_the_coaxial_sign_pattern_head_on() {
    // The sphere's top point seen from straight above with the flash 3 cm off the lens.
    let view = ViewGeometry::from_rig(0, &pose(), &flash());
    let top = Point3::new(0.0, 0.0, 0.04);
    let mut glossy = material();
    glossy.rho_d = [0.0; 3];
    let m = images::mueller_at(&view, &glossy, [0.0, 0.0, 1.0], &top).unwrap();
    // Specular + single scattering near coaxial: SS·diag(1, 1, −1) (docs/model.md §5).
    assert!(m[1][1] / m[0][0] > 0.95, "{m:?}");
    assert!(m[2][2] / m[0][0] < -0.95, "{m:?}");
    // Physical bounds of a Mueller matrix: |M0j|, |Mi0| ≤ M00.
    let diffuse = material();
    for k in 0..20 {
        let a = k as f64 * 0.07;
        let n = Vector3::new(a.sin() * 0.6, a.cos() * 0.3, 1.0).normalize();
        let p = Point3::from(n * 0.04);
        let m = images::mueller_at(&view, &diffuse, n.into(), &p).unwrap();
        for j in 1..3 {
            assert!(m[0][j].abs() <= m[0][0] * (1.0 + 1e-12));
            assert!(m[j][0].abs() <= m[0][0] * (1.0 + 1e-12));
        }
    }
}

#[test]
fn relit_lambertian_sphere_is_brightest_towards_the_light() {
    let mesh = sphere();
    let mut fits = fits(&mesh);
    for f in &mut fits {
        f.params.rho_s = 0.0;
        f.params.rho_ss = [0.0; 3];
        f.flags.clear();
    }
    let camera = ViewCamera::framing(pose(), 40, 40, &Point3::origin(), 0.04);
    let models = images::pixel_models(&mesh, &fits, &camera);
    // Light far along +x: the brightest pixel sits on the +x side of the disc.
    let light = Point3::new(1.0, 0.0, 0.3);
    let mut best = (0usize, f64::MIN);
    for (k, m) in models.iter().enumerate() {
        if let Some((p, n, point, _)) = m {
            let to_light = (light - point).normalize();
            let v = Vector3::from(*n).dot(&to_light) * p.rho_d[0];
            if v > best.1 {
                best = (k, v);
            }
        }
    }
    let pic = images::relit(&models, 40, 40, &camera, &light, "relit", "t");
    assert!(pic.figure.render().unwrap().width() >= 40);
    let (_, _, point, _) = models[best.0].unwrap();
    assert!(point.x > 0.02, "brightest point {point:?}");
}
