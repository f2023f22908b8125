//! The COLMAP model reader: a model written in COLMAP's text and binary forms reads back alike,
//! and each malformed input is refused naming its file and the line or byte.

use std::fmt::Write as _;
use std::path::Path;

use super::super::tests::{model_of, orbit};
use super::super::*;
use crate::model::read_model;

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
