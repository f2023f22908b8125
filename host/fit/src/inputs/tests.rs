use super::*;
use ellipso_model::camera::Intrinsics;
use ellipso_model::geometry::procedural::icosphere;
use nalgebra::{Translation3, UnitQuaternion};

fn camera() -> CameraModel {
    CameraModel::pinhole(
        612,
        512,
        Intrinsics {
            fx: 869.5,
            fy: 869.5,
            cx: 305.5,
            cy: 255.5,
        },
    )
}

/// A sphere of radius 40 mm at z = 40 mm, scaled by `scale` about its centre.
fn sphere(scale: f64) -> TriangleMesh {
    let (dirs, faces) = icosphere(2);
    let pos = dirs
        .iter()
        .map(|d| Point3::new(0.0, 0.0, 0.04) + d.into_inner() * 0.04 * scale)
        .collect();
    TriangleMesh::new(pos, None, None, faces).unwrap()
}

/// 12 cameras on a ring at 0.5 m, 40° up, looking at the sphere.
fn orbit() -> Vec<(u64, Isometry3<f64>)> {
    (0..12)
        .map(|k| {
            let a = f64::from(k) * std::f64::consts::TAU / 12.0;
            let eye = Point3::new(0.38 * a.cos(), 0.38 * a.sin(), 0.36);
            let view = Isometry3::look_at_rh(&eye, &Point3::new(0.0, 0.0, 0.04), &Vector3::z());
            (u64::from(k as u32), view.inverse())
        })
        .collect()
}

#[test]
fn real_inputs_pass() {
    check_camera(&camera()).unwrap();
    check_poses(&orbit()).unwrap();
    check_mesh(&sphere(1.0), &orbit(), &camera()).unwrap();
}

#[test]
fn impossible_cameras_are_refused_by_name() {
    for (k, value, needle) in [
        (0usize, 1e308, "fx = 1e308"),
        (1, -5.0, "fy"),
        (3, 1e6, "cy"),
        (4, 1e308, "k1 = 1e308"),
        (6, 3.0, "p1"),
    ] {
        let mut p = camera().params();
        p[k] = value;
        let e = check_camera(&camera().with_params(&p))
            .unwrap_err()
            .to_string();
        assert!(e.contains(needle) && e.contains("rig.camera"), "{e}");
    }
}

#[test]
fn impossible_poses_are_refused() {
    let mut far = orbit();
    far[3].1.translation = Translation3::new(1e308, 0.0, 0.0);
    let e = check_poses(&far).unwrap_err().to_string();
    assert!(
        e.contains("frame 3") && e.contains("m from the board"),
        "{e}"
    );
    let same: Vec<_> = (0..5).map(|k| (k, orbit()[0].1)).collect();
    let e = check_poses(&same).unwrap_err().to_string();
    assert!(e.contains("one and the same pose"), "{e}");
    let mut nan = orbit();
    nan[0].1.rotation =
        UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
    assert!(
        check_poses(&nan)
            .unwrap_err()
            .to_string()
            .contains("not finite")
    );
}

#[test]
fn impossible_meshes_are_refused_with_the_cause() {
    let (poses, cam) = (orbit(), camera());
    // collapsed to one point; scaled to nothing
    for scale in [0.0, 1e-40] {
        let e = check_mesh(&sphere(scale), &poses, &cam)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no area") || e.contains("px in the median view"),
            "{scale}: {e}"
        );
    }
    // flattened onto a line: no area
    let s = sphere(1.0);
    let line: Vec<Point3<f64>> = s
        .positions()
        .iter()
        .map(|p| Point3::new(p.x, 0.0, 0.0))
        .collect();
    let flat = TriangleMesh::new(line, None, None, s.triangles().to_vec()).unwrap();
    let e = check_mesh(&flat, &poses, &cam).unwrap_err().to_string();
    assert!(e.contains("have no area"), "{e}");
    // 1e6 m across
    let e = check_mesh(&sphere(1e7), &poses, &cam)
        .unwrap_err()
        .to_string();
    assert!(e.contains("wrong units"), "{e}");
}

#[test]
fn inward_winding_is_refused_closed_or_open() {
    let (poses, cam) = (orbit(), camera());
    let s = sphere(1.0);
    let flipped: Vec<[u32; 3]> = s.triangles().iter().map(|t| [t[0], t[2], t[1]]).collect();
    let closed = TriangleMesh::new(s.positions().to_vec(), None, None, flipped.clone()).unwrap();
    let e = check_mesh(&closed, &poses, &cam).unwrap_err().to_string();
    assert!(e.contains("wind clockwise"), "{e}");
    // the upper cap only: open, judged by the cameras
    let open: Vec<[u32; 3]> = flipped
        .iter()
        .copied()
        .filter(|t| t.iter().all(|&i| s.positions()[i as usize].z > 0.035))
        .collect();
    let open_mesh = TriangleMesh::new(s.positions().to_vec(), None, None, open).unwrap();
    let e = check_mesh(&open_mesh, &poses, &cam)
        .unwrap_err()
        .to_string();
    assert!(e.contains("wind clockwise"), "{e}");
}
