//! Scene tests: every shipped scene and board loads; each class of bad input yields an error
//! naming the key and the right line; capture paths are deterministic per seed; scene files round
//! trip through TOML and feed the optics and camera models. World-space queries (surfaces,
//! materials, rendered tags) are tested in `tests/world.rs`.

use super::*;
use nalgebra::{Point3, Vector3};
use std::path::PathBuf;

pub(super) fn sim_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A scene path inside `sim/scenes/` so relative asset paths resolve.
fn scene_path() -> PathBuf {
    sim_dir().join("scenes/inline_test.toml")
}

pub(super) const BASE: &str = r#"seed = 5

[materials.glass]
eta = 1.5
sigma_s = 0.05
sigma_ss = 0.15
rho_s = 1.0
rho_ss = [0.05, 0.05, 0.05]
rho_d = [0.02, 0.02, 0.02]

[[objects]]
name = "ball"
shape = "sphere"
radius_m = 0.04
pose = { translation_m = [0.0, 0.0, 0.04] }
material = "glass"

[[boards]]
pose = {}

[boards.inline]
tag_size_m = 0.03
origin = "sheet_centre"
axes = "x_right_y_up"
tags = [{ id = 4, centre_m = [0.03, 0.03] }, { id = 5, centre_m = [0.2, 0.03] }]

[rig.camera]
resolution_px = [640, 480]
fx_px = 900.0
fy_px = 900.0
cx_px = 319.5
cy_px = 239.5
sensor = "mono_polar"
exposure_us = 5000.0

[capture]
path = "random_walk"
photo_count = 50
look_at_m = [0.0, 0.0, 0.04]
elevation_deg = [20.0, 70.0]
distance_m = [0.4, 0.6]

[effects]
shot_noise = {}
"#;

pub(super) fn load(text: &str) -> Result<Scene, SceneError> {
    Scene::from_toml_str(text, &scene_path())
}

/// Replaces `from` (must occur exactly once) and returns the new text.
pub(super) fn edit(from: &str, to: &str) -> String {
    assert_eq!(
        BASE.matches(from).count(),
        1,
        "`{from}` must be unique in BASE"
    );
    BASE.replace(from, to)
}

/// 1-based line of the first occurrence of `needle` in `text`.
fn line_of(text: &str, needle: &str) -> usize {
    let at = text
        .find(needle)
        .unwrap_or_else(|| panic!("`{needle}` not in text"));
    text[..at].matches('\n').count() + 1
}

#[test]
fn base_scene_loads() {
    let s = load(BASE).expect("valid");
    assert_eq!(s.camera_poses.len(), 50);
    assert_eq!(s.effects.listed(), vec![EffectKind::ShotNoise]);
    assert_eq!(s.rig.camera.bit_depth, 12);
    assert!(s.rig.flash.polarised);
}

#[test]
fn every_shipped_scene_and_board_loads() {
    let mut n = 0;
    for dir in ["scenes", "boards"] {
        for entry in std::fs::read_dir(sim_dir().join(dir)).expect("folder exists") {
            let path = entry.expect("entry").path();
            if path.extension().and_then(|e| e.to_str()) != Some("toml") {
                continue;
            }
            if dir == "scenes" {
                let s = Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
                assert!(!s.camera_poses.is_empty());
            } else {
                load_board_file(&path).unwrap_or_else(|e| panic!("{e}"));
            }
            n += 1;
        }
    }
    assert!(n >= 7, "4 scenes and 3 boards expected, found {n}");
    let sphere = Scene::load(&sim_dir().join("scenes/sphere.toml")).expect("sphere");
    assert_eq!(sphere.camera_poses.len(), 150);
    let multi = Scene::load(&sim_dir().join("scenes/multi_material.toml")).expect("multi");
    assert_eq!(
        (
            multi.materials.len(),
            multi.boards.len(),
            multi.camera_poses.len()
        ),
        (4, 2, 200)
    );
    assert_eq!(multi.effects.listed().len(), 11, "all but lens_distortion");
    assert!(multi.capture.bracket.is_empty());
    let bracketed =
        Scene::load(&sim_dir().join("scenes/multi_material_bracket.toml")).expect("bracket");
    assert_eq!(bracketed.capture.bracket, [1.0, 0.25, 0.0625]);
    assert_eq!(bracketed.camera_poses.len(), 600);
    // Everything but the capture is the one-exposure scene's.
    assert_eq!(
        (&bracketed.materials, &bracketed.rig, &bracketed.effects),
        (&multi.materials, &multi.rig, &multi.effects)
    );
    let calib = Scene::load(&sim_dir().join("scenes/calibration.toml")).expect("calibration");
    assert!(calib.objects.is_empty() && calib.camera_poses.len() == 40);
    let s0 = Scene::load(&sim_dir().join("scenes/s0_only.toml")).expect("s0");
    assert!(!s0.rig.flash.polarised && !s0.rig.camera.analysers && s0.effects.listed().is_empty());
}

/// Each bad-input class names its key and the line it is on.
#[test]
fn bad_inputs_name_key_and_line() {
    #[rustfmt::skip]
    let cases: Vec<(String, &str, &str, &str)> = vec![
        // (scene text, expected key, text on the expected line, message fragment)
        (edit("eta = 1.5", "eta = 0.8"), "materials.glass.eta", "eta = 0.8", "≥ 1"),
        (edit("sigma_s = 0.05", "sigma_s = 0.3"), "materials.glass.sigma_s", "sigma_s = 0.3", "σss"),
        (edit("rho_d = [0.02, 0.02, 0.02]", "rho_d = [0.02, 1.5, 0.02]"), "materials.glass.rho_d[1]", "rho_d = [0.02, 1.5", "[0, 1]"),
        (edit("radius_m = 0.04", "radius_m = -0.04"), "objects[0].radius_m", "radius_m = -0.04", "positive"),
        (edit("radius_m = 0.04", "radius_m = \"big\""), "objects[0].radius_m", "radius_m = \"big\"", "invalid type"),
        (edit("material = \"glass\"", "material = \"steel\""), "objects[0].material", "material = \"steel\"", "unknown material"),
        (edit("material = \"glass\"", "material = \"glass\"\ncolour = 3"), "objects[0].colour", "colour = 3", "unknown field"),
        (edit("shape = \"sphere\"", "shape = \"cube\""), "objects[0].shape", "shape = \"cube\"", "unknown variant"),
        (edit("id = 4,", "id = 587,"), "boards[0].inline.tags[0].id", "id = 587", "not in tag36h11"),
        (edit("id = 5,", "id = 4,"), "boards[0].inline.tags[1].id", "tags = [", "appears twice"),
        (edit("tag_size_m = 0.03", "tag_size_m = 0.0"), "boards[0].inline.tag_size_m", "tag_size_m = 0.0", "positive"),
        (edit("photo_count = 50", "photo_count = 0"), "capture.photo_count", "photo_count = 0", "zero photos"),
        (edit("distance_m = [0.4, 0.6]", "distance_m = [0.6, 0.4]"), "capture.distance_m", "distance_m = [0.6", "min ≤ max"),
        (edit("path = \"random_walk\"", "path = \"orbit\""), "capture.distance_m", "distance_m", "only applies"),
        (edit("fx_px = 900.0\n", ""), "rig.camera", "[rig.camera]", "missing field `fx_px`"),
        (edit("sensor = \"mono_polar\"", "sensor = \"mono_polar\"\nbit_depth = 10"), "rig.camera.bit_depth", "bit_depth = 10", "8, 12, 16"),
        (edit("sensor = \"mono_polar\"", "sensor = \"mono_polar\"\nk1 = -0.1"), "rig.camera", "[rig.camera]", "lens_distortion is not listed"),
        (edit("shot_noise = {}", "link_disconnect = { at_frame = 50 }"), "effects.link_disconnect.at_frame", "at_frame = 50", "past the last photo"),
        (edit("shot_noise = {}", "frame_drops = { probability = 1.5 }"), "effects.frame_drops.probability", "probability = 1.5", "p < 1"),
        (edit("pose = { translation_m = [0.0, 0.0, 0.04] }", "pose = { quaternion_wxyz = [0.0, 0.0, 0.0, 0.0] }"), "objects[0].pose.quaternion_wxyz", "quaternion_wxyz", "normalised"),
        (edit("shape = \"sphere\"\nradius_m = 0.04", "shape = \"mesh\"\nmesh = \"../assets/missing.ply\""), "objects[0].mesh", "missing.ply", "does not exist"),
        (edit("shape = \"sphere\"\nradius_m = 0.04", "shape = \"mesh\"\nmesh = \".\""), "objects[0].mesh", "mesh = \".\"", "is a directory, not a file"),
        (edit("[capture]", "[capture\n"), "", "[capture", "unclosed table"),
        (edit("photo_count = 50", "photo_count = 50\ninterval_ms = 2.0"), "capture.interval_ms", "interval_ms = 2.0", "shorter than the 5000 µs exposure"),
        (edit("photo_count = 50", "photo_count = 50\nbracket = [1.0, 0.0]"), "capture.bracket", "bracket = [1.0, 0.0]", "step 1 is 0; relative energies must be in (0, 1]"),
        (edit("photo_count = 50", "photo_count = 50\nbracket = [0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5]"), "capture.bracket", "bracket = [0.5", "at most 8"),
        (edit("shape = \"sphere\"\n", ""), "objects[0]", "[[objects]]", "missing field `shape`"),
        (edit("tag_size_m = 0.03\n", ""), "boards[0].inline", "[boards.inline]", "missing field `tag_size_m`"),
        (edit("rho_d = [0.02, 0.02, 0.02]", "rho_d = [0.02, \"x\", 0.02]"), "materials.glass.rho_d[1]", "rho_d = [0.02, \"x\"", "invalid type"),
        (edit("seed = 5", "seed = -5"), "seed", "seed = -5", "expected u64"),
        (edit("exposure_us = 5000.0", "exposure_us = 5000.0\nexposure_us = 1.0"), "", "exposure_us = 1.0", "duplicate key"),
    ];
    for (text, key, line_text, fragment) in cases {
        let e = load(&text).expect_err(&format!("must fail: expected `{key}`"));
        let msg = e.to_string();
        assert_eq!(e.key(), key, "{msg}");
        assert_eq!(e.line(), Some(line_of(&text, line_text)), "{msg}");
        assert!(
            msg.contains(fragment),
            "`{msg}` should contain `{fragment}`"
        );
        assert!(
            msg.starts_with(&scene_path().display().to_string()),
            "{msg}"
        );
    }
}

#[test]
fn board_file_errors_point_into_the_board_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let board = dir.path().join("bad_board.toml");
    std::fs::write(
        &board,
        "tag_size_m = 0.03\n\n[grid]\ncols = 2\nrows = 2\nspacing_m = 0.031\n",
    )
    .expect("write");
    let scene = BASE.replace(
        "[[boards]]\npose = {}\n\n[boards.inline]",
        &format!(
            "[[boards]]\nfile = \"{}\"\n\n[boards.unused]",
            board.display()
        ),
    );
    // The rest of the inline table becomes an unknown key: drop it to reach the board file.
    let scene = scene.replace("[boards.unused]\ntag_size_m = 0.03\norigin = \"sheet_centre\"\naxes = \"x_right_y_up\"\ntags = [{ id = 4, centre_m = [0.03, 0.03] }, { id = 5, centre_m = [0.2, 0.03] }]\n", "");
    let e = load(&scene).expect_err("bad board file");
    assert_eq!(e.path(), board.as_path(), "{e}");
    assert_eq!((e.key(), e.line()), ("grid.spacing_m", Some(6)), "{e}");
}

fn walk_scene(seed: u64, path: &str) -> Scene {
    let text = edit("seed = 5", &format!("seed = {seed}"));
    let text = if path == "orbit" {
        text.replace("path = \"random_walk\"", "path = \"orbit\"")
            .replace("distance_m = [0.4, 0.6]", "radius_m = 0.5")
    } else {
        text
    };
    load(&text).expect("valid")
}

#[test]
fn capture_paths_are_deterministic_per_seed_and_differ_across_seeds() {
    for path in ["random_walk", "orbit"] {
        let a = walk_scene(11, path).camera_poses;
        let b = walk_scene(11, path).camera_poses;
        let c = walk_scene(12, path).camera_poses;
        assert_eq!(a, b, "{path}: same seed, same poses");
        assert_ne!(a, c, "{path}: different seed, different poses");
    }
    let poses = walk_scene(3, "random_walk").camera_poses;
    for (i, p) in poses.iter().enumerate() {
        assert_eq!(
            (p.index as usize, p.t_trigger_us),
            (i, i as u64 * 500_000),
            "default 500 ms cadence"
        );
    }
    let target = Point3::new(0.0, 0.0, 0.04);
    for p in poses {
        let eye = p.world_from_camera.translation.vector;
        let d = (Point3::from(eye) - target).norm();
        assert!((0.4 - 1e-9..=0.6 + 1e-9).contains(&d), "distance {d}");
        // Aim jitter is small: the optical axis passes near the target.
        let axis = p.world_from_camera.rotation * Vector3::z();
        let to_target = (target - Point3::from(eye)).normalize();
        assert!(axis.dot(&to_target) > 0.99, "camera looks at the target");
    }
    for p in walk_scene(3, "orbit").camera_poses {
        let v = Point3::from(p.world_from_camera.translation.vector) - target;
        assert!((v.norm() - 0.5).abs() < 1e-12);
        let el = (v.z / v.norm()).asin().to_degrees();
        assert!((20.0..=70.0).contains(&el), "elevation {el}");
        // Image up is world up: camera y (down) has a negative world z component.
        assert!((p.world_from_camera.rotation * Vector3::y()).z < 0.0);
    }
}

#[test]
fn shipped_blob_matches_its_generator() {
    use ellipso_model::geometry::procedural::*;
    let path = sim_dir().join("assets/bumpy_blob.ply");
    let bytes = std::fs::metadata(&path).expect("asset exists").len();
    assert!(bytes < 200 * 1024, "asset is {bytes} bytes");
    let shipped = ellipso_model::geometry::TriangleMesh::load(&path).expect("loads");
    let fresh = bumpy_icosphere(BLOB_SUBDIVISIONS, BLOB_AMPLITUDE, BLOB_REGIONS, BLOB_SEED);
    assert_eq!(shipped.triangles(), fresh.triangles());
    assert_eq!(shipped.regions(), fresh.regions());
    let max_err = shipped
        .positions()
        .iter()
        .zip(fresh.positions())
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    assert!(max_err < 1e-6, "f32 storage error {max_err}");
}

/// The minimal example in `docs/scene.md` loads (as if it lived in `sim/scenes/`).
#[test]
fn documented_minimal_example_loads() {
    let doc = std::fs::read_to_string(sim_dir().join("../docs/scene.md")).expect("docs/scene.md");
    let start = doc.find("## Minimal example").expect("section");
    let body = &doc[start..];
    let open = body.find("```toml\n").expect("code block") + "```toml\n".len();
    let close = body[open..].find("```").expect("closed block");
    let s = load(&body[open..open + close]).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.camera_poses.len(), 100);
}

mod robustness {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        /// Random edits of a valid scene load or fail with a located error; never panic. Errors
        /// other than I/O always carry a line inside the file.
        #[test]
        fn mutated_scenes_never_panic(
            edits in proptest::collection::vec((0usize..2000, "[-0-9a-z.=\\[\\]{}\"\n ,]"), 1..4),
        ) {
            let mut text = BASE.to_string();
            for (at, with) in edits {
                let mut at = at % text.len();
                while !text.is_char_boundary(at) {
                    at -= 1;
                }
                let end = (at + 1..=text.len()).find(|&i| text.is_char_boundary(i)).unwrap_or(text.len());
                text.replace_range(at..end, &with);
            }
            if let Err(e) = load(&text) {
                let lines = text.lines().count().max(1) + 1;
                let line = e.line().expect("scene errors are located");
                prop_assert!((1..=lines).contains(&line), "line {line} of {lines}: {e}");
            }
        }
    }
}

/// Errors inside arrays of sub-tables (`[[capture.poses]]`) name the element index.
#[test]
fn errors_in_arrays_of_tables_name_the_index() {
    let path = sim_dir().join("scenes/calibration.toml");
    let text = std::fs::read_to_string(&path).expect("calibration scene");
    let marker = "roll_deg = 15.0";
    let bad = text.replace(marker, "roll_deg = 15.0\nfov_deg = 40.0");
    let e = Scene::from_toml_str(&bad, &path).expect_err("unknown key");
    assert_eq!(
        (e.key(), e.line()),
        ("capture.poses[2].fov_deg", Some(line_of(&bad, "fov_deg"))),
        "{e}"
    );
    let bad = text.replace(
        "position_m = [0.0, 0.25, 0.45]\nlook_at_m = [0.02, 0.0, 0.0]",
        "position_m = [0.0, 0.25, 0.45]\nlook_at_m = [0.0, 0.25, 0.45]",
    );
    let e = Scene::from_toml_str(&bad, &path).expect_err("degenerate look-at");
    assert_eq!(e.key(), "capture.poses[3].look_at_m", "{e}");
    assert_eq!(
        e.line(),
        Some(line_of(&bad, "look_at_m = [0.0, 0.25, 0.45]")),
        "{e}"
    );
}

/// A parsed scene file serialises back to TOML that parses to the same thing (sessions can
/// record the exact scene they were simulated from).
#[test]
fn scene_files_round_trip_through_toml() {
    for name in [
        "sphere",
        "multi_material",
        "multi_material_bracket",
        "calibration",
        "s0_only",
    ] {
        let text =
            std::fs::read_to_string(sim_dir().join(format!("scenes/{name}.toml"))).expect("scene");
        let file: SceneFile = toml::from_str(&text).expect("parses");
        let written = toml::to_string(&file).unwrap_or_else(|e| panic!("{name}: {e}"));
        let back: SceneFile =
            toml::from_str(&written).unwrap_or_else(|e| panic!("{name}: {e}\n{written}"));
        assert_eq!(file, back, "{name}");
    }
}

/// Scene types convert into the shared optics and camera models: every shipped material passes
/// `PbrdfParams::validate`, every camera model validates, and an orbit camera (no aim jitter)
/// images its look-at point exactly at the principal point.
#[test]
fn scene_types_feed_the_optics_and_camera_models() {
    for name in ["sphere", "multi_material", "calibration", "s0_only"] {
        let s = Scene::load(&sim_dir().join(format!("scenes/{name}.toml"))).expect("scene");
        for m in &s.materials {
            m.params
                .to_pbrdf()
                .validate()
                .unwrap_or_else(|e| panic!("{name}/{}: {e}", m.name));
        }
        let model = s.rig.camera.camera_model();
        model.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(
            (model.width, model.height),
            (s.rig.camera.resolution_px[0], s.rig.camera.resolution_px[1])
        );
    }
    let s = Scene::load(&sim_dir().join("scenes/sphere.toml")).expect("sphere");
    let model = s.rig.camera.camera_model();
    let target = Point3::from(s.capture.look_at_m);
    for pose in &s.camera_poses {
        let p = model
            .project(&(pose.world_from_camera.inverse() * target))
            .expect("in front");
        assert!(
            (p[0] - s.rig.camera.intrinsics.cx).abs() < 1e-9
                && (p[1] - s.rig.camera.intrinsics.cy).abs() < 1e-9,
            "{p:?}"
        );
    }
}

mod world;
