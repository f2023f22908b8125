//! Tests of the way in: the shared model helpers, and the import (a model in its own frame aligned
//! to the tracked poses: frames gained, bad frames dropped, a mesh carried into the board frame).
//! The COLMAP model reader's tests are in `tests/reader.rs`; COLMAP's own files are read in the
//! crate's `tests.rs` (`colmap_pipeline_both_ways`).

use std::collections::BTreeSet;
use std::path::Path;

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::procedural::icosphere;
use ellipso_model::geometry::similarity::{AlignConfig, apply_to_pose};
use nalgebra::{Isometry3, Point3, Similarity3, Translation3, Unit, UnitQuaternion, Vector3};

use super::*;
use crate::model::{ModelCamera, ModelImage, ModelPoint, read_model};

/// `n` board-frame cameras on an orbit around the object (0.32 m, 30° and 55° elevation).
pub(super) fn orbit(n: usize) -> Vec<Isometry3<f64>> {
    (0..n)
        .map(|k| {
            let az = k as f64 * std::f64::consts::TAU / n as f64;
            let el = if k % 2 == 0 { 30f64 } else { 55f64 }.to_radians();
            let eye = Point3::new(
                0.32 * el.cos() * az.cos(),
                0.32 * el.cos() * az.sin(),
                0.03 + 0.32 * el.sin(),
            );
            let target = Point3::new(0.0, 0.0, 0.03);
            let q =
                ellipso_sim::scene::capture::look_at(&eye, &target, &Vector3::z(), 0.0).unwrap();
            Isometry3::from_parts(Translation3::from(eye.coords), q)
        })
        .collect()
}

/// A model frame far from the board's: COLMAP's scale ~ 1/0.08, turned and moved.
fn board_from_model() -> Similarity3<f64> {
    Similarity3::from_parts(
        Translation3::new(-0.12, 0.31, 0.05),
        UnitQuaternion::from_axis_angle(&Unit::new_normalize(Vector3::new(1.0, 2.0, -0.5)), 2.6),
        0.08,
    )
}

/// A model of `poses` (frame ids 100…) in the model frame of [`board_from_model`], with two
/// cameras and a few points.
pub(super) fn model_of(poses: &[Isometry3<f64>]) -> ColmapModel {
    let model_from_board = board_from_model().inverse();
    let images = poses
        .iter()
        .enumerate()
        .map(|(k, board_from_camera)| ModelImage {
            image_id: k as u32 + 1,
            camera_id: 1 + (k % 2) as u32,
            name: format!("images/{:08}.png", 100 + k),
            camera_from_model: apply_to_pose(&model_from_board, board_from_camera).inverse(),
            points2d: 3,
            points2d_triangulated: 2,
        })
        .collect();
    ColmapModel {
        dir: Path::new("model").to_path_buf(),
        format: ModelFormat::Text,
        cameras: vec![
            ModelCamera {
                camera_id: 1,
                model: "PINHOLE".into(),
                width: 480,
                height: 384,
                params: vec![912.0, 912.0, 240.0, 192.0],
            },
            ModelCamera {
                camera_id: 2,
                model: "OPENCV".into(),
                width: 960,
                height: 768,
                params: vec![1830.0, 1826.0, 480.0, 384.0, -0.1, 0.01, 1e-4, -2e-4],
            },
        ],
        images,
        points: (0..5)
            .map(|k| ModelPoint {
                point3d_id: 7 + k,
                position: Point3::new(k as f64 * 0.25, -1.5, 2.0 + k as f64),
                rgb: [k as u8, 200, 17],
                error_px: 0.4 + 0.1 * k as f64,
                track_length: 2,
            })
            .collect(),
    }
}

/// The session's camera: the lens of the model's first camera at 480 × 384.
fn session_camera() -> CameraModel {
    CameraModel::pinhole(
        480,
        384,
        ellipso_model::camera::Intrinsics {
            fx: 912.0,
            fy: 912.0,
            cx: 239.5,
            cy: 191.5,
        },
    )
}

/// The sphere of the mesh tests (radius 30 mm at z = 30 mm) as a mesh.
fn sphere() -> TriangleMesh {
    let (dirs, faces) = icosphere(2);
    let positions = dirs
        .iter()
        .map(|d| Point3::new(0.0, 0.0, 0.03) + d.into_inner() * 0.03)
        .collect();
    TriangleMesh::new(positions, None, None, faces).unwrap()
}

#[test]
fn a_model_in_its_own_frame_is_aligned_and_gains_the_frames_tracking_missed() {
    let truth = orbit(12);
    let mut model = model_of(&truth);
    // an image that names no frame of the session, and one frame (111) the model lacks
    model.images[11].name = "IMG_0001.jpg".into();
    let frame_ids: BTreeSet<u64> = (100..112).collect();
    // tracking failed on 103 and 108; 105's tracked pose is 20 mm off
    let mut tracked: Vec<(u64, Isometry3<f64>)> = truth
        .iter()
        .enumerate()
        .map(|(k, p)| (100 + k as u64, *p))
        .filter(|(id, _)| *id != 103 && *id != 108)
        .collect();
    tracked
        .iter_mut()
        .find(|t| t.0 == 105)
        .unwrap()
        .1
        .translation
        .vector
        .x += 0.02;
    let camera = session_camera();
    let import = import_model(
        &model,
        &tracked,
        &frame_ids,
        &camera,
        &AlignConfig::default(),
    )
    .unwrap();
    let r = &import.report;
    assert_eq!(r.images_unmatched, ["IMG_0001.jpg"]);
    assert_eq!(r.frames_common, 9);
    assert_eq!(r.frames_inliers, 8);
    assert_eq!(r.frames_dropped, [105]);
    assert_eq!(r.frames_gained, [103, 108]);
    assert_eq!(r.frames_tracked_only, [111]);
    assert!(
        r.rms_position_mm < 1e-6 && r.rms_rotation_deg < 1e-6,
        "{r:?}"
    );
    assert!(
        (r.per_frame
            .iter()
            .find(|f| f.frame_id == 105)
            .unwrap()
            .residual
            .position_mm
            - 20.0)
            .abs()
            < 1e-6
    );
    assert!((r.board_from_model.scale - 0.08).abs() < 1e-12);
    // the two cameras: the same lens at two image sizes
    assert!((r.cameras[0].focal_ratio - 1.0).abs() < 1e-12);
    assert!((r.cameras[1].focal_ratio - 1830.0 / 1824.0).abs() < 1e-12);

    let poses = import.fit_poses(&tracked);
    let ids: Vec<u64> = poses.iter().map(|p| p.0).collect();
    assert_eq!(ids, [100, 101, 102, 103, 104, 106, 107, 108, 109, 110, 111]);
    for (id, pose) in &poses {
        let d = truth[(*id - 100) as usize].inverse() * pose;
        assert!(
            d.translation.vector.norm() < 1e-9 && d.rotation.angle() < 1e-9,
            "frame {id}"
        );
    }

    // a mesh in the model's frame comes back onto the board, normals and winding with it
    let board = sphere();
    let in_model = transform_mesh(&board, &board_from_model().inverse()).unwrap();
    let back = transform_mesh(&in_model, &import.board_from_model).unwrap();
    for (k, p) in back.positions().iter().enumerate() {
        assert!((p - board.positions()[k]).norm() < 1e-12);
        assert!((back.normals()[k].into_inner() - board.normals()[k].into_inner()).norm() < 1e-12);
    }
    assert_eq!(back.triangles(), board.triangles());
}

#[test]
fn images_that_name_no_frame_or_one_frame_twice_are_refused() {
    let truth = orbit(6);
    let frame_ids: BTreeSet<u64> = (100..106).collect();
    let tracked: Vec<(u64, Isometry3<f64>)> = truth
        .iter()
        .enumerate()
        .map(|(k, p)| (100 + k as u64, *p))
        .collect();
    let camera = session_camera();
    let config = AlignConfig::default();
    let mut model = model_of(&truth);
    for (k, i) in model.images.iter_mut().enumerate() {
        i.name = format!("DSC_{k:04}.JPG");
    }
    let e = import_model(&model, &tracked, &frame_ids, &camera, &config)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("DSC_0000.JPG") && e.contains("00000100.png"),
        "{e}"
    );
    let mut model = model_of(&truth);
    model.images[3].name = "elsewhere/100.jpg".into();
    let e = import_model(&model, &tracked, &frame_ids, &camera, &config)
        .unwrap_err()
        .to_string();
    assert!(e.contains("both name frame 100"), "{e}");
    // three frames in common: too few to check one against the others
    let model = model_of(&truth[..3]);
    let e = import_model(&model, &tracked, &frame_ids, &camera, &config)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("3 posed by both") && e.contains("at least 4"),
        "{e}"
    );
    assert_eq!(
        frame_of_image("sub/dir/00000104.tiff", &frame_ids),
        Some(104)
    );
    assert_eq!(frame_of_image("104", &frame_ids), Some(104));
    assert_eq!(frame_of_image("00000099.png", &frame_ids), None);
    assert_eq!(frame_of_image("a104.png", &frame_ids), None);
}

/// The way back through COLMAP's own reconstruction, called by `tests.rs`'s
/// `colmap_pipeline_both_ways` once COLMAP has extracted and matched the features of the export
/// in `c` (`database.db`, `images/`): `mapper` reconstructs the views in a frame and scale of its
/// own, `model_converter` writes that model as text too; both forms read alike, and the model
/// imported against the true poses — two frames withheld as if tracking had failed on them, one
/// moved 15 mm — gives every frame's pose back, and the model's points and a mesh in its frame
/// land on the true sphere (radius 30 mm at z = 30 mm) and board.
pub(crate) fn mapper_model_comes_back_onto_the_board(
    c: &Path,
    truth: &[(u64, Isometry3<f64>)],
    camera: &CameraModel,
    colmap: &dyn Fn(&[&str]),
    seed: u32,
) {
    let p = |x: &Path| x.display().to_string();
    let mapped = c.join("mapped");
    let mapped_txt = c.join("mapped-txt");
    // a fresh model each call (the caller may try the non-deterministic mapper again)
    let _ = std::fs::remove_dir_all(&mapped);
    let _ = std::fs::remove_dir_all(&mapped_txt);
    std::fs::create_dir_all(&mapped).unwrap();
    std::fs::create_dir_all(&mapped_txt).unwrap();
    // the lens is known: COLMAP keeps the exported camera, as a user with a calibration would
    let seed = seed.to_string();
    colmap(&[
        "mapper",
        "--random_seed",
        &seed,
        "--database_path",
        &p(&c.join("database.db")),
        "--image_path",
        &p(&c.join("images")),
        "--output_path",
        &p(&mapped),
        "--Mapper.ba_refine_focal_length",
        "0",
        "--Mapper.ba_refine_extra_params",
        "0",
    ]);
    let model_dir = mapped.join("0");
    colmap(&[
        "model_converter",
        "--input_path",
        &p(&model_dir),
        "--output_path",
        &p(&mapped_txt),
        "--output_type",
        "TXT",
    ]);
    let model = read_model(&model_dir).unwrap();
    assert_eq!(model.format, ModelFormat::Binary);
    let text = read_model(&mapped_txt).unwrap();
    assert_eq!(text.format, ModelFormat::Text);
    assert_eq!(text.cameras, model.cameras);
    assert_eq!(text.images.len(), model.images.len());
    for (a, b) in text.images.iter().zip(&model.images) {
        assert_eq!(
            (a.image_id, &a.name, a.points2d),
            (b.image_id, &b.name, b.points2d)
        );
        let d = a.camera_from_model.inverse() * b.camera_from_model;
        assert!(d.translation.vector.norm() < 1e-9 && d.rotation.angle() < 1e-9);
    }
    assert_eq!(text.points.len(), model.points.len());
    // mapper is multi-threaded and not deterministic: now and then it leaves a view out
    let frame_ids: BTreeSet<u64> = truth.iter().map(|t| t.0).collect();
    let ids: Vec<u64> = model
        .images
        .iter()
        .filter_map(|i| frame_of_image(&i.name, &frame_ids))
        .collect();
    assert!(ids.len() + 2 >= truth.len(), "mapper registered {ids:?}");

    // COLMAP's frame is not the board's; the frames withheld and moved are registered ones
    let (gone, moved) = ([ids[2], ids[7]], ids[5]);
    let tracked: Vec<(u64, Isometry3<f64>)> = truth
        .iter()
        .filter(|t| !gone.contains(&t.0))
        .map(|&(id, mut pose)| {
            if id == moved {
                pose.translation.vector.y += 0.015;
            }
            (id, pose)
        })
        .collect();
    let import = import_model(
        &model,
        &tracked,
        &frame_ids,
        camera,
        &AlignConfig::default(),
    )
    .unwrap();
    let r = &import.report;
    println!(
        "mapper model: scale {:.5} board m per unit; residual RMS {:.3} mm, {:.4}° (max {:.3} mm, \
         {:.4}°) over {} of {} frames; {} points; focal ratio {:.6}",
        r.board_from_model.scale,
        r.rms_position_mm,
        r.rms_rotation_deg,
        r.max_position_mm,
        r.max_rotation_deg,
        r.frames_inliers,
        r.frames_common,
        r.points,
        r.cameras[0].focal_ratio
    );
    assert!(
        (r.board_from_model.scale - 1.0).abs() > 0.01
            || r.board_from_model.rotation_wxyz[0].abs() < 0.999,
        "mapper picked the board frame itself: nothing was aligned"
    );
    assert_eq!(r.frames_gained, gone);
    assert_eq!(r.frames_dropped, [moved]);
    assert_eq!(r.frames_inliers, ids.len() - 3);
    assert!((r.cameras[0].focal_ratio - 1.0).abs() < 1e-9);
    // every frame's pose, the gained and the dropped one's model pose too, against the truth
    let mut worst = (0.0f64, 0.0f64);
    for (id, pose) in &import.aligned {
        let t = truth.iter().find(|t| t.0 == *id).unwrap().1;
        let d = t.inverse() * pose;
        worst.0 = worst.0.max(d.translation.vector.norm() * 1e3);
        worst.1 = worst.1.max(d.rotation.angle().to_degrees());
    }
    println!(
        "aligned mapper poses vs truth: worst {:.3} mm, {:.4}°",
        worst.0, worst.1
    );
    // measured over runs (mapper's result varies): worst 0.99–1.66 mm, 0.17–0.27°, RMS
    // 0.39–0.69 mm, 0.07–0.12° (a pixel at 480 × 384 is 0.35 mm on the object); the
    // documented limit is 2 mm, 0.5° RMS
    assert!(worst.0 < 3.0 && worst.1 < 0.5, "{worst:?}");
    assert!(r.rms_position_mm < 1.5 && r.rms_rotation_deg < 0.3, "{r:?}");
    let fit_ids: Vec<u64> = import.fit_poses(&tracked).iter().map(|p| p.0).collect();
    assert_eq!(
        fit_ids.len(),
        truth.len() - 1,
        "every frame but the moved one"
    );
    assert!(!fit_ids.contains(&moved) && gone.iter().all(|g| fit_ids.contains(g)));

    // COLMAP's own points, carried into the board frame, lie on the sphere or the board
    let (centre, radius) = (Point3::new(0.0, 0.0, 0.03), 0.03);
    let on_surface = model
        .points
        .iter()
        .map(|q| import.board_from_model.transform_point(&q.position))
        .filter(|b| ((b - centre).norm() - radius).abs().min(b.z.abs()) < 0.002)
        .count();
    println!(
        "{on_surface} of {} mapper points within 2 mm of the sphere or the board",
        model.points.len()
    );
    assert!(model.points.len() >= 100);
    assert!(on_surface as f64 >= 0.9 * model.points.len() as f64);

    // a mesh in COLMAP's frame (the true sphere placed there by the similarity of the true
    // poses, all of them, without the withheld and moved frames' damage) comes back onto the
    // true sphere
    let pairs: Vec<PosePair> = truth
        .iter()
        .filter_map(|(id, t)| {
            let image = model
                .images
                .iter()
                .find(|i| frame_of_image(&i.name, &frame_ids) == Some(*id))?;
            Some(PosePair {
                source_from_camera: image.camera_from_model.inverse(),
                target_from_camera: *t,
            })
        })
        .collect();
    let oracle = ellipso_model::geometry::similarity::umeyama(
        &pairs
            .iter()
            .map(|p| Point3::from(p.source_from_camera.translation.vector))
            .collect::<Vec<_>>(),
        &pairs
            .iter()
            .map(|p| Point3::from(p.target_from_camera.translation.vector))
            .collect::<Vec<_>>(),
    )
    .unwrap();
    let in_model = transform_mesh(&sphere(), &oracle.inverse()).unwrap();
    let back = transform_mesh(&in_model, &import.board_from_model).unwrap();
    let worst_mm = back
        .positions()
        .iter()
        .map(|b| ((b - centre).norm() - radius).abs() * 1e3)
        .fold(0.0, f64::max);
    println!("mesh from COLMAP's frame: worst vertex {worst_mm:.3} mm off the true sphere");
    assert!(worst_mm < 0.5, "{worst_mm} mm");
}

#[test]
fn a_refused_alignment_names_refined_intrinsics_as_the_likely_cause() {
    let camera = |ratio: f64| CameraReport {
        camera_id: 1,
        model: "PINHOLE".into(),
        width: 612,
        height: 512,
        focal_ratio: ratio,
    };
    // the calibration kept: nothing to say
    assert_eq!(intrinsics_hint(&[camera(1.0), camera(1.004)]), "");
    // the mapper run: fx −2.2 %
    let hint = intrinsics_hint(&[camera(0.978)]);
    assert!(
        hint.contains("camera 1 -2.2 %") && hint.contains("--Mapper.ba_refine_focal_length 0"),
        "{hint}"
    );
    assert!(intrinsics_hint(&[camera(f64::NAN)]).contains("likely cause"));
}

mod reader;
