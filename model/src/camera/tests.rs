//! Tests of the camera model: round trips, Jacobians vs central differences, serde contract.

use super::*;
use proptest::prelude::*;

fn camera_5mp() -> CameraModel {
    CameraModel {
        width: 2448,
        height: 2048,
        intrinsics: Intrinsics {
            fx: 3500.0,
            fy: 3495.0,
            cx: 1221.3,
            cy: 1027.8,
        },
        distortion: Distortion {
            k1: -0.12,
            k2: 0.08,
            k3: -0.02,
            p1: 4e-4,
            p2: -3e-4,
        },
    }
}

#[test]
fn projects_principal_ray_to_principal_point() {
    let cam = camera_5mp();
    let p = cam.project(&Point3::new(0.0, 0.0, 0.5)).unwrap();
    assert!((p[0] - 1221.3).abs() < 1e-12 && (p[1] - 1027.8).abs() < 1e-12);
}

#[test]
fn points_behind_or_at_the_camera_do_not_project() {
    let cam = camera_5mp();
    assert!(cam.project(&Point3::new(0.1, 0.0, -0.5)).is_none());
    assert!(cam.project(&Point3::new(0.1, 0.0, 0.0)).is_none());
    assert!(cam.project(&Point3::new(f64::NAN, 0.0, 1.0)).is_none());
    assert!(
        cam.project_with_jacobians(&Point3::new(0.1, 0.0, -1.0))
            .is_none()
    );
}

#[test]
fn x_right_y_down_convention() {
    let cam = camera_5mp();
    let right = cam.project(&Point3::new(0.05, 0.0, 1.0)).unwrap();
    let down = cam.project(&Point3::new(0.0, 0.05, 1.0)).unwrap();
    assert!(right[0] > cam.intrinsics.cx && down[1] > cam.intrinsics.cy);
}

#[test]
fn undistort_fails_loudly_where_the_polynomial_folds() {
    // Strong barrel distortion: x_d(x) = x(1 − 0.5 x²) has a maximum 0.544 at x = 0.816;
    // a distorted radius beyond it has no preimage.
    let d = Distortion {
        k1: -0.5,
        ..Distortion::ZERO
    };
    assert!(matches!(
        d.undistort([0.7, 0.0]),
        Err(CameraError::UndistortNoConvergence { .. })
    ));
    assert!(d.undistort([0.5, 0.0]).is_ok());
    assert!(d.undistort([f64::NAN, 0.0]).is_err());
}

#[test]
fn toml_round_trip_and_validation() {
    let cam = camera_5mp();
    let text = toml::to_string(&cam).unwrap();
    let back: CameraModel = toml::from_str(&text).unwrap();
    assert_eq!(back, cam);

    let minimal = "width = 640\nheight = 480\nfx = 500.0\nfy = 500.0\ncx = 319.5\ncy = 239.5\n";
    let m: CameraModel = toml::from_str(minimal).unwrap();
    assert_eq!(m.distortion, Distortion::ZERO);

    let unknown = format!("{minimal}k4 = 0.1\n");
    let err = toml::from_str::<CameraModel>(&unknown)
        .unwrap_err()
        .to_string();
    assert!(err.contains("k4"), "{err}");

    let negative = minimal.replace("fx = 500.0", "fx = -500.0");
    let err = toml::from_str::<CameraModel>(&negative)
        .unwrap_err()
        .to_string();
    assert!(err.contains("fx"), "{err}");

    let nan = minimal.replace("cy = 239.5", "cy = nan");
    let err = toml::from_str::<CameraModel>(&nan).unwrap_err().to_string();
    assert!(err.contains("cy"), "{err}");

    let empty = minimal.replace("width = 640", "width = 0");
    assert!(toml::from_str::<CameraModel>(&empty).is_err());
}

#[test]
fn params_round_trip() {
    let cam = camera_5mp();
    assert_eq!(cam.with_params(&cam.params()), cam);
}

fn central_difference_point(cam: &CameraModel, p: &Point3<f64>) -> Matrix2x3Num {
    let h = 1e-7;
    let mut j = Matrix2x3Num::zeros();
    for k in 0..3 {
        let (mut a, mut b) = (*p, *p);
        a[k] += h;
        b[k] -= h;
        let (pa, pb) = (cam.project(&a).unwrap(), cam.project(&b).unwrap());
        j[(0, k)] = (pa[0] - pb[0]) / (2.0 * h);
        j[(1, k)] = (pa[1] - pb[1]) / (2.0 * h);
    }
    j
}

type Matrix2x3Num = nalgebra::Matrix2x3<f64>;

proptest! {
    #[test]
    fn undistort_inverts_distort(x in -0.45f64..0.45, y in -0.4f64..0.4) {
        let cam = camera_5mp();
        let d = cam.distortion.distort([x, y]);
        let back = cam.distortion.undistort(d).unwrap();
        prop_assert!((back[0] - x).abs() < 1e-11 && (back[1] - y).abs() < 1e-11);
    }

    #[test]
    fn ray_through_projection_contains_the_point(
        x in -0.3f64..0.3, y in -0.25f64..0.25, z in 0.2f64..3.0,
    ) {
        let cam = camera_5mp();
        let p = Point3::new(x * z, y * z, z);
        let pixel = cam.project(&p).unwrap();
        let ray = cam.unproject_to_ray(pixel).unwrap();
        let dir = p.coords.normalize();
        prop_assert!((ray.into_inner() - dir).norm() < 1e-11);
        prop_assert!(ray.z > 0.0);
    }

    #[test]
    fn point_jacobian_matches_central_differences(
        x in -0.4f64..0.4, y in -0.35f64..0.35, z in 0.2f64..2.0,
    ) {
        let cam = camera_5mp();
        let p = Point3::new(x * z, y * z, z);
        let analytic = cam.project_with_jacobians(&p).unwrap();
        let numeric = central_difference_point(&cam, &p);
        let scale = analytic.d_pixel_d_point.abs().max();
        prop_assert!((analytic.d_pixel_d_point - numeric).abs().max() < 1e-5 * scale.max(1.0));
        prop_assert_eq!(analytic.pixel, cam.project(&p).unwrap());
    }

    #[test]
    fn param_jacobian_matches_central_differences(
        x in -0.4f64..0.4, y in -0.35f64..0.35, z in 0.2f64..2.0,
    ) {
        let cam = camera_5mp();
        let p = Point3::new(x * z, y * z, z);
        let analytic = cam.project_with_jacobians(&p).unwrap().d_pixel_d_params;
        let base = cam.params();
        for k in 0..CAMERA_PARAM_COUNT {
            // u, v are linear in each parameter: central differences are exact up to round-off,
            // so a large step minimises the round-off.
            let h = 1e-3 * base[k].abs().max(1.0);
            let (mut a, mut b) = (base, base);
            a[k] += h;
            b[k] -= h;
            let pa = cam.with_params(&a).project(&p).unwrap();
            let pb = cam.with_params(&b).project(&p).unwrap();
            for row in 0..2 {
                let numeric = (pa[row] - pb[row]) / (2.0 * h);
                let tol = 1e-6 * numeric.abs().max(analytic[(row, k)].abs()).max(1.0);
                prop_assert!(
                    (analytic[(row, k)] - numeric).abs() < tol,
                    "param {} row {}: analytic {} numeric {}",
                    CAMERA_PARAM_NAMES[k], row, analytic[(row, k)], numeric
                );
            }
        }
    }
}
