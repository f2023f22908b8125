//! World-space queries on loaded scenes: rays find the sphere, the board and shadows; mesh
//! regions (by index or by OBJ `usemtl` name) resolve to materials and blend; scaled spheres and
//! plane objects are hit where they are; and tags detected in images rendered from the scene's
//! own poses land where its boards say.

use super::super::tests::{BASE, edit, load, sim_dir};
use super::super::*;
use ellipso_model::geometry::Ray;
use nalgebra::{Point3, Vector3};

#[test]
fn world_queries_find_sphere_board_and_shadows() {
    let s = load(BASE).expect("valid");
    let down = Vector3::new(0.0, 0.0, -1.0);
    let h = s
        .intersect(
            &Ray::new(Point3::new(0.0, 0.0, 1.0), down),
            0.0,
            f64::INFINITY,
        )
        .expect("hit");
    assert!((h.hit.point.z - 0.08).abs() < 1e-12);
    assert_eq!(
        h.kind,
        SurfaceKind::Object {
            index: 0,
            material: MaterialSample::Uniform(0)
        }
    );
    assert_eq!(s.material_params(&MaterialSample::Uniform(0)).eta, 1.5);
    // Tag 4's centre on the board (sheet centre origin, y up): black border? sample white margin.
    let board = &s.boards[0];
    let off = Point3::new(-board.board.sheet_size_m[0] / 2.0 + 0.002, 0.0, 1.0);
    let h = s
        .intersect(&Ray::new(off, down), 0.0, f64::INFINITY)
        .expect("board");
    match h.kind {
        SurfaceKind::Board {
            index: 0,
            albedo,
            front: true,
        } => assert_eq!(albedo, 0.85),
        other => panic!("expected the board front, got {other:?}"),
    }
    assert!((h.hit.normal_geometric.z - 1.0).abs() < 1e-12);
    // The sphere shadows the board point under it from a light straight above.
    let shadow = Ray::new(Point3::new(0.0, 0.0, 1e-6), Vector3::z());
    assert!(s.occluded(&shadow, 1e-9, 2.0));
    assert!(!s.occluded(
        &Ray::new(Point3::new(0.09, 0.0, 1e-6), Vector3::z()),
        1e-9,
        2.0
    ));
}

#[test]
fn mesh_regions_resolve_to_materials_and_blend() {
    let s = Scene::load(&sim_dir().join("scenes/multi_material.toml")).expect("multi");
    let obj = &s.objects[0];
    let mut seen = std::collections::BTreeSet::new();
    for k in 0..400 {
        let a = k as f64 * 0.7;
        let z = -0.9 + 1.8 * (k as f64 / 400.0);
        let r = (1.0 - z * z).sqrt();
        let dir = Vector3::new(r * a.cos(), r * a.sin(), z);
        let centre = Point3::new(0.0, 0.0, 0.0396);
        let ray = Ray::new(centre + dir * 0.5, -dir);
        if let Some((_, MaterialSample::Uniform(m))) = obj.intersect(&ray, 0.0, 1.0) {
            seen.insert(m);
        }
    }
    assert_eq!(seen.len(), 4, "all four region materials are hit: {seen:?}");
    let blended = s.material_params(&MaterialSample::Blend([(0, 0.5), (1, 0.25), (2, 0.25)]));
    let m = |i: usize| s.materials[i].params;
    let want = 0.5 * m(0).eta + 0.25 * m(1).eta + 0.25 * m(2).eta;
    assert!((blended.eta - want).abs() < 1e-12);
}

/// End to end: render the sphere scene's board from two of its own camera poses (intrinsics
/// scaled down 4×) with the sphere occluding, detect the tags with the real detector, and check
/// every detected corner against the world corner projected through `world_from_camera`.
#[test]
fn scene_poses_and_board_poses_agree_with_detections() {
    use crate::tag_checks::detect::detect_tag36h11;
    let s = Scene::load(&sim_dir().join("scenes/sphere.toml")).expect("sphere");
    let cam = &s.rig.camera;
    let scale = 4.0;
    let (w, h) = (
        (cam.resolution_px[0] / 4) as usize,
        (cam.resolution_px[1] / 4) as usize,
    );
    let (fx, fy) = (cam.intrinsics.fx / scale, cam.intrinsics.fy / scale);
    let (cx, cy) = (
        (cam.intrinsics.cx + 0.5) / scale - 0.5,
        (cam.intrinsics.cy + 0.5) / scale - 0.5,
    );
    for pose in [s.camera_poses[0], s.camera_poses[75]] {
        let eye = pose.world_from_camera * Point3::origin();
        let mut gray = vec![0u8; w * h];
        for v in 0..h {
            for u in 0..w {
                let mut acc = 0.0;
                for (sx, sy) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
                    let (x, y) = (u as f64 - 0.5 + sx, v as f64 - 0.5 + sy);
                    let dir =
                        pose.world_from_camera * Vector3::new((x - cx) / fx, (y - cy) / fy, 1.0);
                    acc += match s.intersect(&Ray::new(eye, dir), 0.0, f64::INFINITY) {
                        Some(SceneHit {
                            kind: SurfaceKind::Board { albedo, .. },
                            ..
                        }) => albedo as f64,
                        Some(_) => 0.3,
                        None => 0.1,
                    };
                }
                gray[v * w + u] = (acc / 4.0 * 255.0).round() as u8;
            }
        }
        let found = detect_tag36h11(&gray, w, h);
        assert!(found.len() >= 6, "only {} tags detected", found.len());
        let camera_from_world = pose.world_from_camera.inverse();
        for (id, corners) in found {
            let truth = s.boards[0]
                .tag_corners_world_m(id)
                .expect("detected id is on the board");
            for (k, got) in corners.iter().enumerate() {
                let q = camera_from_world * truth[k];
                let want = [fx * q.x / q.z + cx, fy * q.y / q.z + cy];
                let err = ((got[0] - want[0]).powi(2) + (got[1] - want[1]).powi(2)).sqrt();
                assert!(
                    err < 0.6,
                    "pose {} tag {id} corner {k}: {err:.3} px",
                    pose.index
                );
            }
        }
    }
}

/// OBJ `usemtl` names work as region keys, and barycentric blending yields weights summing to 1
/// that reproduce the vertex materials at the corners.
#[test]
fn obj_named_regions_and_barycentric_blend() {
    let dir = tempfile::tempdir().expect("tempdir");
    let obj = dir.path().join("two_tone.obj");
    std::fs::write(
        &obj,
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nusemtl left\nf 1 2 4\nusemtl right\nf 2 3 4\n",
    )
    .expect("write");
    let object = format!(
        "shape = \"mesh\"\nmesh = \"{}\"\nregions = {{ left = \"glass\", right = \"tin\" }}\nregion_blend = \"barycentric\"",
        obj.display()
    );
    let text = edit("shape = \"sphere\"\nradius_m = 0.04", &object)
        .replace("material = \"glass\"\n", "")
        .replace(
            "[[objects]]",
            "[materials.tin]\neta = 2.0\nsigma_s = 0.1\nsigma_ss = 0.2\nrho_s = 1.0\n\
             rho_ss = [0.1, 0.1, 0.1]\nrho_d = [0.1, 0.1, 0.1]\n\n[[objects]]",
        );
    let s = load(&text).unwrap_or_else(|e| panic!("{e}"));
    let (glass, tin) = (
        s.material_id("glass").expect("glass"),
        s.material_id("tin").expect("tin"),
    );
    let down = Vector3::new(0.0, 0.0, -1.0);
    // The object sits at z = 0.04 (pose from BASE); hit the left triangle near vertex 1.
    let ray = Ray::new(Point3::new(-0.9, -0.9, 1.0), down);
    let (hit, sample) = s.objects[0].intersect(&ray, 0.0, 10.0).expect("hit");
    assert!((hit.point.z - 0.04).abs() < 1e-12);
    let MaterialSample::Blend(items) = sample else {
        panic!("expected a blend, got {sample:?}")
    };
    assert!((items.iter().map(|(_, w)| w).sum::<f64>() - 1.0).abs() < 1e-12);
    assert!(
        items.iter().all(|(m, _)| *m == glass),
        "left triangle is all glass: {items:?}"
    );
    let ray = Ray::new(Point3::new(0.9, 0.9, 1.0), down);
    let (_, sample) = s.objects[0].intersect(&ray, 0.0, 10.0).expect("hit");
    assert_eq!(s.material_params(&sample).eta, s.materials[tin].params.eta);
    // A name that is not a region of the mesh is rejected at its key.
    let bad = text.replace("right = \"tin\"", "middle = \"tin\"");
    let e = load(&bad).expect_err("unknown region");
    assert_eq!(e.key(), "objects[0].regions.middle", "{e}");
}

/// Non-uniform scale turns the sphere into an ellipsoid with correct normals; a finite plane
/// object is hit inside its rectangle only.
#[test]
fn scaled_sphere_and_plane_objects() {
    let text = edit(
        "pose = { translation_m = [0.0, 0.0, 0.04] }\nmaterial = \"glass\"",
        "pose = { translation_m = [0.0, 0.0, 0.04], rotation_deg = [0.0, 0.0, 90.0] }\n\
         scale = [2.0, 1.0, 1.0]\nmaterial = \"glass\"\n\n[[objects]]\nname = \"shelf\"\n\
         shape = \"plane\"\nsize_m = [0.1, 0.1]\npose = { translation_m = [0.5, 0.0, 0.2] }\n\
         material = \"glass\"",
    );
    let s = load(&text).unwrap_or_else(|e| panic!("{e}"));
    // Rotated 90° about z, the long (2r = 0.08 m) axis lies along world y.
    let from_y = Ray::new(Point3::new(0.0, 1.0, 0.04), Vector3::new(0.0, -1.0, 0.0));
    let h = s.intersect(&from_y, 0.0, 10.0).expect("ellipsoid");
    assert!((h.hit.point.y - 0.08).abs() < 1e-12, "{}", h.hit.point);
    assert!((h.hit.normal_geometric.y - 1.0).abs() < 1e-12);
    // On the ellipsoid x²/r² + y²/(2r)² = 1 at 45° in the xy plane the normal tilts towards x.
    let r = 0.04;
    let (px, py) = (r / 2f64.sqrt(), 2.0 * r / 2f64.sqrt());
    let ray = Ray::new(
        Point3::new(px + 1.0, py, 0.04),
        Vector3::new(-1.0, 0.0, 0.0),
    );
    let h = s.intersect(&ray, 0.0, 10.0).expect("ellipsoid side");
    let n = h.hit.normal_geometric;
    let want = Vector3::new(px / (r * r), py / (4.0 * r * r), 0.0).normalize();
    assert!((n.into_inner() - want).norm() < 1e-9, "{n:?} vs {want}");
    let down = Vector3::new(0.0, 0.0, -1.0);
    let h = s
        .intersect(&Ray::new(Point3::new(0.52, 0.03, 1.0), down), 0.0, 10.0)
        .expect("plane");
    assert!(
        matches!(h.kind, SurfaceKind::Object { index: 1, .. })
            && (h.hit.point.z - 0.2).abs() < 1e-12
    );
    assert!(
        s.intersect(&Ray::new(Point3::new(0.56, 0.0, 1.0), down), 0.0, 10.0)
            .is_none()
    );
}
