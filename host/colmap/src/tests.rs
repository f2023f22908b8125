//! Tests of the COLMAP export on small sessions rendered by the simulator (low resolution, a
//! ring of explicit views around a sphere), and COLMAP's own pipeline both ways on it.

use std::path::Path;

use ellipso_session::reader::{self, Session};
use ellipso_sim::test_support::{render_session, render_session_with};
use nalgebra::{Isometry3, Point3};

/// A4 under a 9 × 6 grid of 22 mm tag36h11 tags (ids 300…), the object standing on it: texture
/// over the whole sheet. COLMAP's `mapper` finds no initial pair on the shipped base board, a
/// ring of 16 tags round a blank centre, from a dozen views at 480 × 384 (a few hundred SIFT
/// features per view, and views from opposite sides alike).
pub const TAG_GRID_BOARD: &str = "name = \"tag_grid\"\nfamily = \"tag36h11\"\n\
    tag_size_m = 0.022\nsheet_size_m = [0.297, 0.210]\nwhite_albedo = 0.85\n\
    black_albedo = 0.04\norigin = \"sheet_centre\"\naxes = \"x_right_y_up\"\n\
    [grid]\ncols = 9\nrows = 6\nspacing_m = 0.032\nfirst_id = 300\n\
    first_centre_m = [0.0205, 0.025]\n";

fn open(dir: &Path) -> Session {
    reader::open(dir).unwrap()
}

/// One image line of COLMAP's `images.txt`: id, pose (qw qx qy qz tx ty tz) and name.
type ColmapImage = (usize, [f64; 7], String);

/// A minimal reader of COLMAP's text model: the camera line and, per image, its id, pose and
/// name (the format the writer must meet).
fn read_colmap(sparse: &Path) -> (Vec<String>, Vec<ColmapImage>, usize) {
    let data_lines = |name: &str| -> Vec<String> {
        std::fs::read_to_string(sparse.join(name))
            .unwrap()
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(str::to_string)
            .collect()
    };
    let cameras: Vec<String> = data_lines("cameras.txt")
        .into_iter()
        .filter(|l| !l.trim().is_empty())
        .collect();
    let lines = data_lines("images.txt");
    // two lines per image: the pose line, then the (here empty) 2-D points line
    assert_eq!(lines.len() % 2, 0, "images.txt needs two lines per image");
    let images = lines
        .chunks(2)
        .map(|pair| {
            let f: Vec<&str> = pair[0].split_whitespace().collect();
            assert_eq!(f.len(), 10, "{}", pair[0]);
            let v: [f64; 7] = std::array::from_fn(|k| f[1 + k].parse().unwrap());
            assert_eq!(f[8], "1");
            (f[0].parse().unwrap(), v, f[9].to_string())
        })
        .collect();
    let points = data_lines("points3D.txt")
        .iter()
        .filter(|l| !l.trim().is_empty())
        .count();
    (cameras, images, points)
}

#[test]
fn colmap_files_round_trip_with_the_poses_and_the_pixel_centre_convention() {
    use crate::export::{ColmapOptions, export_colmap};
    let tmp = tempfile::tempdir().unwrap();
    let (dir, scene, poses) = render_session(tmp.path(), &[([0.0, 0.0, 0.03], 0.03)], 4, 160, 128);
    let session = open(&dir);
    let out = tmp.path().join("colmap");
    let report = export_colmap(&session, &poses, &out, ColmapOptions::default()).unwrap();
    assert_eq!(report.images, 4);
    let (cameras, images, points) = read_colmap(&out.join("sparse"));
    assert_eq!(points, 0);
    assert_eq!(cameras.len(), 1);
    let c: Vec<&str> = cameras[0].split_whitespace().collect();
    assert_eq!(&c[..4], ["1", "PINHOLE", "160", "128"], "{}", cameras[0]);
    let p: Vec<f64> = c[4..].iter().map(|x| x.parse().unwrap()).collect();
    let camera = scene.rig.camera.camera_model();
    assert_eq!(images.len(), 4);
    for ((id, v, name), (frame_id, world_from_camera)) in images.iter().zip(&poses) {
        assert_eq!(name, &format!("{frame_id:08}.png"));
        assert!(out.join("images").join(name).is_file());
        assert!(*id >= 1);
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            v[0], v[1], v[2], v[3],
        ));
        assert!(v[0] >= 0.0);
        let camera_from_world =
            Isometry3::from_parts(nalgebra::Translation3::new(v[4], v[5], v[6]), q);
        let expected = world_from_camera.inverse();
        assert!((camera_from_world.to_homogeneous() - expected.to_homogeneous()).norm() < 1e-9);
        // a board point projected COLMAP's way (pixel centres at +0.5) lands 0.5 px from our
        // superpixel projection of the same ray
        for x in [
            Point3::new(0.05, -0.02, 0.0),
            Point3::new(-0.03, 0.04, 0.01),
        ] {
            let pc = camera_from_world * x;
            let colmap = [p[0] * pc.x / pc.z + p[2], p[1] * pc.y / pc.z + p[3]];
            let i = camera.intrinsics;
            let raw = [i.fx * pc.x / pc.z + i.cx, i.fy * pc.y / pc.z + i.cy];
            let ours = raw;
            assert!(
                (colmap[0] - ours[0] - 0.5).abs() < 1e-9
                    && (colmap[1] - ours[1] - 0.5).abs() < 1e-9
            );
        }
    }
    // with the lens kept, the model is OpenCV's with the calibration's coefficients
    let kept = tmp.path().join("kept");
    let r = export_colmap(
        &session,
        &poses,
        &kept,
        ColmapOptions {
            keep_distortion: true,
        },
    )
    .unwrap();
    assert!(r.camera.starts_with("1 OPENCV 160 128 "), "{}", r.camera);
}

/// COLMAP both ways. Out: its own documented pipeline on the export, to the end:
/// `feature_extractor`, `exhaustive_matcher`, `point_triangulator` on the known-pose model (the
/// database the export wrote keeps COLMAP's image ids equal to the model's), then
/// `model_converter` to read the triangulated points back: many points, sub-pixel reprojection
/// error, and the points lie in the board frame (on or above the board plane z = 0, within the
/// views). Back: `mapper` on the same features reconstructs the views in a frame of its own, and
/// the import brings it onto the board (`import`'s tests).
#[test]
fn colmap_pipeline_both_ways() {
    let Ok(o) = std::process::Command::new("colmap").arg("help").output() else {
        // CI installs it and sets ELLIPSO_REQUIRE_COLMAP, so there a missing program fails
        assert!(
            std::env::var_os("ELLIPSO_REQUIRE_COLMAP").is_none(),
            "ELLIPSO_REQUIRE_COLMAP is set but the `colmap` program is not installed"
        );
        println!("skipped: the `colmap` program is not installed (apt-get install colmap)");
        return;
    };
    assert!(o.status.success() || !o.stdout.is_empty());
    let tmp = tempfile::tempdir().unwrap();
    let board = tmp.path().join("tag_grid.toml");
    std::fs::write(&board, TAG_GRID_BOARD).unwrap();
    let (dir, _, poses) = render_session_with(
        tmp.path(),
        &[([0.0, 0.0, 0.03], 0.03)],
        12,
        480,
        384,
        &board,
    );
    let session = open(&dir);
    let c = tmp.path().join("colmap");
    let report = crate::export::export_colmap(&session, &poses, &c, Default::default()).unwrap();
    assert_eq!(report.images, 12);
    let colmap = |args: &[&str]| {
        let o = std::process::Command::new("colmap")
            .env("QT_QPA_PLATFORM", "offscreen")
            .args(args)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "colmap {}: {}{}",
            args.join(" "),
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
    };
    let p = |x: &Path| x.display().to_string();
    // COLMAP's results beside the export, as docs/mesh.md's recipe has them
    let results = tmp.path().join("results");
    let tri = results.join("triangulated");
    let txt = results.join("txt");
    std::fs::create_dir_all(&txt).unwrap();
    // features and matches of an export in `dir`, the matcher's RANSAC seeded with `seed`
    let features = |dir: &Path, seed: u32| {
        let db = p(&dir.join("database.db"));
        colmap(&[
            "feature_extractor",
            "--database_path",
            &db,
            "--image_path",
            &p(&dir.join("images")),
            "--SiftExtraction.use_gpu",
            "0",
        ]);
        colmap(&[
            "exhaustive_matcher",
            "--database_path",
            &db,
            "--SiftMatching.use_gpu",
            "0",
            "--random_seed",
            &seed.to_string(),
        ]);
    };
    // docs/mesh.md's route, word for word: features, matches, point_triangulator
    let steps = crate::recipe::recipe(crate::recipe::MESH_DOC, crate::recipe::ROUTE);
    assert!(!steps.is_empty(), "docs/mesh.md has no COLMAP route recipe");
    for step in steps {
        match step.substituted(&c, &results) {
            crate::recipe::Step::Env(k, v) => assert_eq!(
                (k.as_str(), v.as_str()),
                ("QT_QPA_PLATFORM", "offscreen"),
                "the runner sets this variable for every colmap call"
            ),
            crate::recipe::Step::Mkdir(dirs) => {
                dirs.iter()
                    .for_each(|d| std::fs::create_dir_all(d).unwrap());
            }
            crate::recipe::Step::Colmap(args) => {
                colmap(&args.iter().map(String::as_str).collect::<Vec<_>>());
            }
        }
    }
    colmap(&[
        "model_converter",
        "--input_path",
        &p(&tri),
        "--output_path",
        &p(&txt),
        "--output_type",
        "TXT",
    ]);
    let (cameras, images, _) = read_colmap(&txt);
    assert_eq!(cameras.len(), 1);
    assert_eq!(images.len(), 12);
    // the poses are the ones exported (ids and names matched)
    let (_, exported, _) = read_colmap(&c.join("sparse"));
    for a in &exported {
        let b = images
            .iter()
            .find(|b| b.0 == a.0)
            .expect("every exported image id");
        assert_eq!(a.2, b.2, "image {} keeps its name", a.0);
        for k in 0..7 {
            assert!((a.1[k] - b.1[k]).abs() < 1e-6, "{a:?} vs {b:?}");
        }
    }
    let points: Vec<[f64; 4]> = std::fs::read_to_string(txt.join("points3D.txt"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let f: Vec<f64> = l
                .split_whitespace()
                .take(8)
                .map(|v| v.parse().unwrap())
                .collect();
            [f[1], f[2], f[3], f[7]]
        })
        .collect();
    let n = points.len();
    let mean_error = points.iter().map(|p| p[3]).sum::<f64>() / n.max(1) as f64;
    let above_board = points.iter().filter(|p| p[2] > -0.002).count();
    println!(
        "colmap: {n} points, mean reprojection error {mean_error:.3} px, {above_board} on or above the board"
    );
    assert!(n >= 100, "{n} points triangulated");
    assert!(mean_error < 1.0, "mean reprojection error {mean_error} px");
    assert!(
        above_board as f64 >= 0.95 * n as f64,
        "{above_board} of {n} points on or above the board plane"
    );
    let camera = ellipso_fit::observe::camera_of(&session).unwrap();
    // COLMAP is not deterministic here: its feature pipeline differs from run to run (757 and
    // 758 points triangulated from the same images, one thread or two), and now and then
    // (measured: 1 of 2 runs on a loaded 2-core machine, 0 of 10 unloaded) the matches it keeps
    // let the mapper register two of the twelve views of this symmetric scene 324 mm and 59°
    // away, sit 2–3 mm RMS off the tracked poses, or keep too few poses within 5 mm / 1° of
    // them; the import rightly refuses such a model or drops the frame. Every mapper try on one
    // database failed alike (the last CI run: five of five), so a try after the first starts
    // again from a fresh export with its own features and matches (the matcher's RANSAC seeded
    // by the try) and its own mapper seed; the import's checks are the same on each.
    let mut tries = 0;
    loop {
        tries += 1;
        let dir = if tries == 1 {
            c.clone()
        } else {
            let dir = tmp.path().join(format!("colmap-try{tries}"));
            crate::export::export_colmap(&session, &poses, &dir, Default::default()).unwrap();
            features(&dir, tries);
            dir
        };
        let attempt = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            crate::import::tests::mapper_model_comes_back_onto_the_board(
                &dir, &poses, &camera, &colmap, tries,
            )
        }));
        match attempt {
            Ok(()) => break,
            Err(e) if tries >= 5 => std::panic::resume_unwind(e),
            Err(_) => println!("mapper try {tries} failed; extracting, matching and mapping again"),
        }
    }
}
