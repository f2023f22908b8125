//! Tests of the way in: the COLMAP model reader (text and binary read alike; each malformed
//! input refused naming file and place) and the import (a model in its own frame aligned to the
//! tracked poses: frames gained, bad frames dropped, a mesh carried into the board frame).
//! COLMAP's own files are read in `tests.rs` (`colmap_pipeline_both_ways`).

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::Path;

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::procedural::icosphere;
use ellipso_model::geometry::similarity::{AlignConfig, apply_to_pose};
use nalgebra::{Isometry3, Point3, Similarity3, Translation3, Unit, UnitQuaternion, Vector3};

use super::*;
use crate::model::{ModelCamera, ModelImage, ModelPoint, read_model};

/// `n` board-frame cameras on an orbit around the object (0.32 m, 30° and 55° elevation).
fn orbit(n: usize) -> Vec<Isometry3<f64>> {
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
fn model_of(poses: &[Isometry3<f64>]) -> ColmapModel {
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

/// COLMAP's text form of `model` (as its `model_converter` writes it).
fn write_text(model: &ColmapModel, dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let mut cameras = String::from("# Camera list with one line of data per camera:\n");
    for c in &model.cameras {
        let params: Vec<String> = c.params.iter().map(|p| format!("{p:?}")).collect();
        let _ = writeln!(
            cameras,
            "{} {} {} {} {}",
            c.camera_id,
            c.model,
            c.width,
            c.height,
            params.join(" ")
        );
    }
    let mut images = String::from("# Image list with two lines of data per image:\n");
    for i in &model.images {
        let q = i.camera_from_model.rotation;
        let t = i.camera_from_model.translation.vector;
        let _ = writeln!(
            images,
            "{} {:?} {:?} {:?} {:?} {:?} {:?} {:?} {} {}",
            i.image_id, q.w, q.i, q.j, q.k, t.x, t.y, t.z, i.camera_id, i.name
        );
        let _ = writeln!(images, "1.5 2.5 7 10.0 20.0 -1 3.25 4.75 8");
    }
    let mut points = String::from("# 3D point list with one line of data per point:\n");
    for p in &model.points {
        let _ = writeln!(
            points,
            "{} {:?} {:?} {:?} {} {} {} {:?} 1 0 2 1",
            p.point3d_id,
            p.position.x,
            p.position.y,
            p.position.z,
            p.rgb[0],
            p.rgb[1],
            p.rgb[2],
            p.error_px
        );
    }
    for (name, text) in [
        ("cameras.txt", cameras),
        ("images.txt", images),
        ("points3D.txt", points),
    ] {
        std::fs::write(dir.join(name), text).unwrap();
    }
}

/// COLMAP's binary form of `model` (the layout of the module contract of `colmap_model`).
fn write_binary(model: &ColmapModel, dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let ids = [
        "SIMPLE_PINHOLE",
        "PINHOLE",
        "SIMPLE_RADIAL",
        "RADIAL",
        "OPENCV",
    ];
    let mut b = (model.cameras.len() as u64).to_le_bytes().to_vec();
    for c in &model.cameras {
        b.extend(c.camera_id.to_le_bytes());
        let id = ids.iter().position(|m| *m == c.model).unwrap() as i32;
        b.extend(id.to_le_bytes());
        b.extend(c.width.to_le_bytes());
        b.extend(c.height.to_le_bytes());
        c.params.iter().for_each(|p| b.extend(p.to_le_bytes()));
    }
    std::fs::write(dir.join("cameras.bin"), b).unwrap();
    let mut b = (model.images.len() as u64).to_le_bytes().to_vec();
    for i in &model.images {
        b.extend(i.image_id.to_le_bytes());
        let q = i.camera_from_model.rotation;
        let t = i.camera_from_model.translation.vector;
        for v in [q.w, q.i, q.j, q.k, t.x, t.y, t.z] {
            b.extend(v.to_le_bytes());
        }
        b.extend(i.camera_id.to_le_bytes());
        b.extend(i.name.as_bytes());
        b.push(0);
        b.extend(3u64.to_le_bytes());
        for (x, y, id) in [(1.5, 2.5, 7u64), (10.0, 20.0, u64::MAX), (3.25, 4.75, 8)] {
            b.extend(f64::to_le_bytes(x));
            b.extend(f64::to_le_bytes(y));
            b.extend(id.to_le_bytes());
        }
    }
    std::fs::write(dir.join("images.bin"), b).unwrap();
    let mut b = (model.points.len() as u64).to_le_bytes().to_vec();
    for p in &model.points {
        b.extend(p.point3d_id.to_le_bytes());
        for v in p.position.coords.iter() {
            b.extend(v.to_le_bytes());
        }
        b.extend(p.rgb);
        b.extend(p.error_px.to_le_bytes());
        b.extend(2u64.to_le_bytes());
        for v in [1u32, 0, 2, 1] {
            b.extend(v.to_le_bytes());
        }
    }
    std::fs::write(dir.join("points3D.bin"), b).unwrap();
}

/// `read` equals `model` up to the directory, the form and the last bits of the pose.
fn assert_same(read: &ColmapModel, model: &ColmapModel) {
    assert_eq!(read.cameras, model.cameras);
    assert_eq!(read.points, model.points);
    assert_eq!(read.images.len(), model.images.len());
    for (a, b) in read.images.iter().zip(&model.images) {
        assert_eq!(
            (
                a.image_id,
                a.camera_id,
                &a.name,
                a.points2d,
                a.points2d_triangulated
            ),
            (
                b.image_id,
                b.camera_id,
                &b.name,
                b.points2d,
                b.points2d_triangulated
            )
        );
        let d = a.camera_from_model.inverse() * b.camera_from_model;
        assert!(d.translation.vector.norm() < 1e-12 && d.rotation.angle() < 1e-12);
    }
}

#[test]
fn text_and_binary_models_read_alike() {
    let tmp = tempfile::tempdir().unwrap();
    let model = model_of(&orbit(6));
    write_text(&model, &tmp.path().join("txt"));
    write_binary(&model, &tmp.path().join("bin"));
    let text = read_model(&tmp.path().join("txt")).unwrap();
    assert_eq!(text.format, ModelFormat::Text);
    assert_same(&text, &model);
    let binary = read_model(&tmp.path().join("bin")).unwrap();
    assert_eq!(binary.format, ModelFormat::Binary);
    assert_same(&binary, &model);
    // a folder with both reads the binary files, as COLMAP does
    write_text(&model, &tmp.path().join("bin"));
    assert_eq!(
        read_model(&tmp.path().join("bin")).unwrap().format,
        ModelFormat::Binary
    );
    // no points3D: a model without points
    std::fs::remove_file(tmp.path().join("txt/points3D.txt")).unwrap();
    assert!(
        read_model(&tmp.path().join("txt"))
            .unwrap()
            .points
            .is_empty()
    );
}

#[test]
fn malformed_models_are_refused_naming_file_and_place() {
    let tmp = tempfile::tempdir().unwrap();
    let model = model_of(&orbit(4));
    let err = |dir: &Path| read_model(dir).unwrap_err().to_string();

    // the parent of COLMAP's sparse/0: not a model, with a hint where one is
    let sparse = tmp.path().join("sparse");
    write_binary(&model, &sparse.join("0"));
    let e = err(&sparse);
    assert!(
        e.contains("no COLMAP model here") && e.contains("sparse/0"),
        "{e}"
    );
    let e = err(&tmp.path().join("absent"));
    assert!(e.contains("absent") && e.contains("not a directory"), "{e}");

    // binary: a truncated images.bin, an unknown camera model, trailing bytes
    let bin = sparse.join("0");
    let images = std::fs::read(bin.join("images.bin")).unwrap();
    std::fs::write(bin.join("images.bin"), &images[..images.len() - 5]).unwrap();
    let e = err(&bin);
    assert!(
        e.contains("images.bin, byte 592") && e.contains("2-D points cannot fit"),
        "{e}"
    );
    std::fs::write(bin.join("images.bin"), &images).unwrap();
    let mut cameras = std::fs::read(bin.join("cameras.bin")).unwrap();
    cameras[12] = 99;
    std::fs::write(bin.join("cameras.bin"), &cameras).unwrap();
    let e = err(&bin);
    assert!(
        e.contains("cameras.bin, byte 12") && e.contains("unknown camera model id 99"),
        "{e}"
    );
    let mut images_plus = images.clone();
    images_plus.push(0);
    write_binary(&model, &bin);
    std::fs::write(bin.join("images.bin"), &images_plus).unwrap();
    assert!(err(&bin).contains("1 bytes after the last record"));
    // a corrupt count does not allocate: it is refused against the file's length
    let mut huge = images.clone();
    huge[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    std::fs::write(bin.join("images.bin"), &huge).unwrap();
    assert!(err(&bin).contains("cannot fit"), "{}", err(&bin));

    // text: a bad number, a rotation that is not one, a camera missing, a repeated name
    let txt = tmp.path().join("txt");
    write_text(&model, &txt);
    let images = std::fs::read_to_string(txt.join("images.txt")).unwrap();
    std::fs::write(
        txt.join("images.txt"),
        images.replacen(" 1 images/", " x images/", 1),
    )
    .unwrap();
    let e = err(&txt);
    assert!(
        e.contains("images.txt, line 2") && e.contains("CAMERA_ID `x`"),
        "{e}"
    );
    let first = images.lines().nth(1).unwrap();
    let f: Vec<&str> = first.split_whitespace().collect();
    let scaled = first.replacen(f[1], "2.0", 1);
    std::fs::write(txt.join("images.txt"), images.replacen(first, &scaled, 1)).unwrap();
    assert!(err(&txt).contains("not a unit quaternion"), "{}", err(&txt));
    std::fs::write(
        txt.join("images.txt"),
        images.replacen(" 1 images/", " 9 images/", 1),
    )
    .unwrap();
    assert!(
        err(&txt).contains("camera 9 is not in the model"),
        "{}",
        err(&txt)
    );
    let renamed = images.replacen("images/00000101.png", "images/00000100.png", 1);
    std::fs::write(txt.join("images.txt"), renamed).unwrap();
    assert!(
        err(&txt).contains("00000100.png is repeated"),
        "{}",
        err(&txt)
    );
    std::fs::write(txt.join("images.txt"), &images).unwrap();
    let cameras = std::fs::read_to_string(txt.join("cameras.txt")).unwrap();
    std::fs::write(txt.join("cameras.txt"), cameras.replacen(" 192.0", "", 1)).unwrap();
    let e = err(&txt);
    assert!(
        e.contains("cameras.txt, line 2") && e.contains("PINHOLE has 4 parameters"),
        "{e}"
    );
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
