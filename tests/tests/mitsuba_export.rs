//! `ellipso export mitsuba` and the float outputs across processes, against Mitsuba 3 itself.
//!
//! - A fit directory (an icosphere whose η, σ_s, ρ_s and ρ_d vary over the surface, written by
//!   the fit's own writers) is exported; the scene is rendered by Mitsuba 3 (`scalar_rgb`, a
//!   Python script: `tests/scripts/mitsuba_compare.py`) and compared with ellipso's render of
//!   the same view in `ellipso-s0.exr`: relative RMSE ≤ 5 %.
//! - `ellipso polar`'s `stokes.exr` and the export's EXRs are read back with the `exr` crate
//!   and, by the same script, with Python's OpenEXR bindings.
//! - A fit directory without `fit-view.json` fails with one line naming it.
//!
//! Mitsuba and OpenEXR come from pip (`pip install mitsuba OpenEXR pillow`); the Python is
//! `$ELLIPSO_PYTHON` or `python3`. Without them the Mitsuba part prints `skipped:` and passes,
//! unless `ELLIPSO_REQUIRE_MITSUBA=1` (CI), where it fails.

use std::path::{Path, PathBuf};
use std::process::Command;

use ellipso_fit::data::VertexFit;
use ellipso_fit::export::ply::write_fit_ply;
use ellipso_fit::export::raster::ViewCamera;
use ellipso_fit::export::view_file::{PictureView, write as write_view};
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::procedural::icosphere;
use ellipso_model::optics::pbrdf::PbrdfParams;
use ellipso_report::exr_image::FloatImage;
use ellipso_tests::ellipso_bin;
use nalgebra::{Isometry3, Point3, Vector3};

const ENV_REQUIRE: &str = "ELLIPSO_REQUIRE_MITSUBA";

/// The Python that has mitsuba, OpenEXR and numpy, or why there is none.
fn python() -> Result<String, String> {
    let python = std::env::var("ELLIPSO_PYTHON").unwrap_or_else(|_| "python3".into());
    let probe = Command::new(&python)
        .args(["-c", "import mitsuba, OpenEXR, numpy, PIL, plyfile"])
        .output()
        .map_err(|e| format!("cannot run {python}: {e}"))?;
    if probe.status.success() {
        Ok(python)
    } else {
        Err(format!(
            "{python} lacks mitsuba/OpenEXR/numpy/Pillow/plyfile (pip install mitsuba OpenEXR pillow plyfile): {}",
            String::from_utf8_lossy(&probe.stderr).trim()
        ))
    }
}

/// A fit directory: an icosphere (radius 40 mm at z = 40 mm) whose parameters vary with x and
/// z, every vertex reliable, glossy enough that the highlight matters (with Mitsuba's default
/// Beckmann distribution instead of GGX the comparison fails at 8 % relative RMSE), and the pictures' view from a camera 0.35 m away, above and to
/// the side, with the rig's flash 30 mm above the lens.
fn write_fit_dir(dir: &Path) -> PathBuf {
    let (dirs, faces) = icosphere(3);
    let centre = Point3::new(0.0, 0.0, 0.04);
    let pos: Vec<_> = dirs
        .iter()
        .map(|d| centre + d.into_inner() * 0.04)
        .collect();
    let mesh = TriangleMesh::new(pos, None, None, faces).unwrap();
    let fits: Vec<VertexFit> = dirs
        .iter()
        .enumerate()
        .map(|(v, d)| {
            let x = d.x * 0.5 + 0.5;
            let z = d.z * 0.5 + 0.5;
            VertexFit {
                vertex: v as u32,
                params: PbrdfParams {
                    eta: 1.3 + 0.4 * x,
                    sigma_s: 0.12 + 0.2 * z,
                    sigma_ss: 0.5,
                    rho_s: 0.9 + 1.2 * (1.0 - x),
                    rho_ss: [0.05, 0.04, 0.03],
                    // π·ρd up to 1.7 in red, as a bright fit has (the demo's ceramic: 2.13): the
                    // export must hand a renderer reflectances ≤ 1 (spectral variants clamp)
                    rho_d: [0.5 * x + 0.05, 0.048, 0.1 * (1.0 - x) + 0.008],
                },
                normal_world: d.into_inner().into(),
                std_error: [0.02; 10],
                normal_std_error_deg: 0.8,
                samples_used: 40,
                cost: 1.0,
                iterations: 6,
                flags: vec![],
                eta_unpooled: None,
                eta_prior_only: false,
                gates: Default::default(),
            }
        })
        .collect();
    std::fs::create_dir_all(dir).unwrap();
    write_fit_ply(&dir.join("fit.ply"), &mesh, &fits, None).unwrap();
    let eye = Point3::new(0.2, -0.25, 0.2);
    let world_from_camera = Isometry3::face_towards(&eye, &centre, &Vector3::z());
    // face_towards gives z forward, y up (OpenGL-like): flip y (and x) into OpenCV's y down.
    let world_from_camera = world_from_camera
        * nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI);
    let camera = ViewCamera::framing(world_from_camera, 96, 80, &centre, 0.04);
    let flash = world_from_camera.transform_point(&Point3::new(0.0, -0.03, 0.0));
    // the flash polariser at 30° from image right toward image down (OpenCV y): S1 and S2 both
    let (s, c) = 30f64.to_radians().sin_cos();
    let axis = world_from_camera.rotation * Vector3::new(c, s, 0.0);
    let view = PictureView::new(&camera, &flash, &Point3::new(0.3, 0.3, 0.4))
        .with_polariser(Some(axis.into()));
    write_view(dir, &view).unwrap();
    dir.to_path_buf()
}

fn ellipso(args: &[&str], paths: &[&Path]) -> std::process::Output {
    let mut c = Command::new(ellipso_bin());
    c.args(args);
    for p in paths {
        c.arg(p);
    }
    c.output().expect("spawn ellipso")
}

/// A 16-bit PNG of a 12-bit mono mosaic frame of 30° polarised light (a raw camera PNG).
fn write_mosaic(path: &Path) {
    let (w, h) = (32u32, 16u32);
    let phi = 30f64.to_radians();
    let analysers = [90.0f64, 45.0, 135.0, 0.0]; // 2×2: 90 45 / 135 0
    let img = image::ImageBuffer::from_fn(w, h, |x, y| {
        let a = analysers[(2 * (y % 2) + x % 2) as usize].to_radians();
        let (s0, s1, s2) = (
            2000.0,
            1000.0 * (2.0 * phi).cos(),
            1000.0 * (2.0 * phi).sin(),
        );
        let i = 0.5 * (s0 + s1 * (2.0 * a).cos() + s2 * (2.0 * a).sin());
        image::Luma([i.round() as u16])
    });
    img.save(path).unwrap();
}

#[test]
fn the_mitsuba_scene_renders_what_ellipso_renders() {
    let tmp = tempfile::tempdir().unwrap();
    let fit = write_fit_dir(&tmp.path().join("fit"));
    let out = tmp.path().join("mitsuba");
    let o = ellipso(
        &["export", "mitsuba", "--spp", "32", "--out"],
        &[&out, &fit],
    );
    assert!(
        o.status.success(),
        "export: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    // the scale went from the albedos to the flash (every reflectance ≤ 1)
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("albedos ÷"), "{said}");
    let diffuse = FloatImage::read(&out.join("diffuse.exr")).expect("diffuse.exr");
    let red = diffuse.f32_channel("R").expect("R");
    let top = red.iter().copied().fold(0.0f32, f32::max);
    assert!(top <= 1.0 + 1e-6 && top > 0.5, "largest π·ρd written {top}");
    for f in [
        "scene.xml",
        "mesh.ply",
        "diffuse.exr",
        "specular.exr",
        "ellipso-s0.exr",
        "README.md",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    // ellipso's render reads back: the object covers the middle, radiance finite and positive
    let reference = FloatImage::read(&out.join("ellipso-s0.exr")).expect("ellipso-s0.exr");
    assert_eq!((reference.width, reference.height), (96, 80));
    let a = reference.f32_channel("A").expect("A");
    let covered = a.iter().filter(|v| **v == 1.0).count();
    assert!(covered > 96 * 80 / 4, "object covers {covered} pixels");
    let centre = 40 * 96 + 48;
    assert_eq!(a[centre], 1.0);
    for c in ["R", "G", "B"] {
        let v = reference.f32_channel(c).expect(c)[centre];
        assert!(v.is_finite() && v > 0.0, "{c} = {v}");
    }
    let diffuse = FloatImage::read(&out.join("diffuse.exr")).expect("diffuse.exr");
    assert!(
        diffuse
            .f32_channel("R")
            .expect("R")
            .iter()
            .all(|v| v.is_finite())
    );

    // the float outputs of `ellipso polar`, for the Python read-back below
    let frame = tmp.path().join("frame.png");
    write_mosaic(&frame);
    let polar = tmp.path().join("polar");
    let o = ellipso(&["polar", "--out"], &[&polar, &frame]);
    assert!(
        o.status.success(),
        "polar: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let stokes = polar.join("stokes.exr");
    let s = FloatImage::read(&stokes).expect("stokes.exr");
    let dolp = s.f32_channel("DoLP").expect("DoLP")[0];
    assert!((dolp - 0.5).abs() < 2e-3, "DoLP {dolp}");

    let python = match python() {
        Ok(p) => p,
        Err(why) if std::env::var(ENV_REQUIRE).as_deref() == Ok("1") => {
            panic!("{why}; {ENV_REQUIRE}=1 requires Mitsuba 3")
        }
        Err(why) => {
            eprintln!("skipped: the Mitsuba round trip ({why}; {ENV_REQUIRE}=1 makes this fail)");
            return;
        }
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/mitsuba_compare.py");
    let figure = std::env::var_os("ELLIPSO_MITSUBA_FIGURE")
        .map(PathBuf::from)
        .unwrap_or_else(|| tmp.path().join("compare.png"));
    let compare = |variant: &str, spp: &str, figure: &Path| -> serde_json::Value {
        let o = Command::new(&python)
            .arg(&script)
            .arg(&out)
            .args(["--variant", variant, "--spp", spp, "--figure"])
            .arg(figure)
            .arg("--check-exr")
            .arg(&stokes)
            .arg(out.join("diffuse.exr"))
            .output()
            .expect("spawn python");
        assert!(
            o.status.success(),
            "mitsuba_compare.py --variant {variant}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let stdout = String::from_utf8_lossy(&o.stdout);
        let result: serde_json::Value =
            serde_json::from_str(stdout.lines().last().unwrap_or_default())
                .unwrap_or_else(|e| panic!("{e}: {stdout}"));
        eprintln!("mitsuba vs ellipso ({variant}): {result}");
        let pixels = result["pixels"].as_u64().expect("pixels");
        assert!(
            pixels as usize > covered / 2,
            "{variant}: {pixels} compared of {covered}"
        );
        result
    };
    // the scalar RGB round trip (unpolarised flash, s0); plyfile reads fit.ply alongside
    let o = Command::new(&python)
        .arg(&script)
        .arg(&out)
        .args(["--variant", "scalar_rgb", "--spp", "4", "--check-ply"])
        .arg(fit.join("fit.ply"))
        .output()
        .expect("spawn python");
    let stdout = String::from_utf8_lossy(&o.stdout);
    let ply: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap_or_default())
        .unwrap_or_else(|e| panic!("{e}: {stdout} {}", String::from_utf8_lossy(&o.stderr)));
    let types = &ply["ply"]["types"];
    for (name, ty) in [
        ("x", "float64"),
        ("flags", "int32"),
        ("samples", "int32"),
        ("red", "uint8"),
        ("std_eta", "float32"),
    ] {
        assert_eq!(types[name], ty, "plyfile reads {name} of fit.ply: {ply}");
    }
    // every variant within the export README's 1 % on S0 (measured 0.3–0.6 %); the polarised
    // part, a smaller signal, within 5 %
    let result = compare("scalar_rgb", "64", &figure);
    let rmse = result["relative_rmse"].as_f64().expect("rmse");
    assert!(
        rmse <= 0.01,
        "scalar_rgb: relative RMSE {rmse} > 1 %: {result}"
    );
    // the polarised variants: the rig's polarised flash, S0 and the polarised part (S1, S2)
    // The spectral variant upsamples each RGB albedo to a spectrum, a map that is not linear in
    // the albedo's scale: the albedos divided by k (≤ 1, the emitter × k) come back 1.7 % off in
    // luminance on this fit (measured; 0.5 % where no albedo needed scaling). Its limit is 2 %,
    // not the mono and RGB variants' 1 %.
    for (variant, s0_limit) in [
        ("llvm_ad_mono_polarized", 0.01),
        ("scalar_spectral_polarized", 0.02),
    ] {
        let r = compare(variant, "64", &tmp.path().join(format!("{variant}.png")));
        for (key, limit) in [
            ("relative_rmse", s0_limit),
            ("relative_rmse_polarised", 0.05),
        ] {
            let v = r[key].as_f64().expect(key);
            assert!(v <= limit, "{variant}: {key} {v} > {limit}: {r}");
        }
        // the light is polarised where ellipso says so: a test that a depolarised render fails
        let dolp = r["mean_dolp_ellipso"].as_f64().unwrap_or(0.0);
        assert!(
            dolp > 0.05,
            "{variant}: the scene must be polarised to test it: {r}"
        );
    }
    let channels = &result["exr_channels"][stokes.display().to_string()];
    for name in [
        "S0", "S1", "S2", "DoLP", "AoLP", "I_d", "I_s", "I_alpha", "mask", "Y",
    ] {
        assert!(
            channels
                .as_array()
                .is_some_and(|c| c.iter().any(|c| c == name)),
            "OpenEXR (Python) does not see {name} in stokes.exr: {channels}"
        );
    }
}

#[test]
fn a_fit_directory_without_its_view_is_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let fit = write_fit_dir(&tmp.path().join("fit"));
    std::fs::remove_file(fit.join("fit-view.json")).unwrap();
    let o = ellipso(
        &["export", "mitsuba", "--out"],
        &[&tmp.path().join("out"), &fit],
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("fit-view.json"), "{err}");
    let o = ellipso(
        &["export", "mitsuba", "--out"],
        &[&tmp.path().join("out"), &tmp.path().join("nowhere")],
    );
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("fit.ply"));
}
