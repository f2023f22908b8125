//! Calibration tests on synthetic board views (5 MP camera, σ = 0.15 px corner noise) and flash
//! estimation on synthetic sphere highlights.

use super::flash::{FlashError, HighlightObservation, estimate_flash_position};
use super::zhang::intrinsics_from_homographies;
use super::*;
use crate::pose::homography::homography_dlt;
use crate::pose::synthetic::{board, camera_5mp, look_at, observe, random_pose};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

type View = Vec<(Point3<f64>, Point2<f64>)>;

/// The 9×7 calibration board of 50 mm tags at 70 mm pitch (large enough to reach the image
/// corners, where the distortion shows).
fn calibration_board() -> crate::pose::TagGridBoard {
    crate::pose::TagGridBoard {
        cols: 9,
        rows: 7,
        tag_size_m: 0.05,
        pitch_m: 0.07,
        first_id: 0,
    }
}

/// A view as `calibrate` takes it: each observed corner's board point and pixel.
fn as_view(obs: &[crate::pose::estimate::Correspondence]) -> View {
    obs.iter()
        .map(|c| (c.point_board_m, Point2::new(c.pixel[0], c.pixel[1])))
        .collect()
}

/// `n` views of a 9×7 calibration board of 50 mm tags at 70 mm pitch (large enough to reach the
/// image corners, where the distortion shows), each with ≥ 8 tags visible.
fn synthetic_views(seed: u64, n: usize, sigma_px: f64) -> (CameraModel, Vec<View>, Vec<Pose>) {
    let cam = camera_5mp();
    let b = calibration_board();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut views, mut poses) = (Vec::new(), Vec::new());
    while views.len() < n {
        let truth = random_pose(&mut rng, false);
        let obs = observe(&cam, &b, &truth, sigma_px, &mut rng);
        if obs.len() < 32 {
            continue;
        }
        views.push(as_view(&obs));
        poses.push(truth);
    }
    (cam, views, poses)
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn twenty_views_recover_the_camera() {
    let (truth, views, poses) = synthetic_views(11, 20, 0.15);
    let cal = calibrate(&views, (truth.width, truth.height), &CalibConfig::default()).unwrap();
    let (e, t) = (cal.camera.params(), truth.params());
    println!(
        "calibration: rms {:.4} px, iterations {}, rel err fx {:.2e} fy {:.2e} cx {:.2e} cy {:.2e} \
         k1 {:.2e} k2 {:.2e}; std fx {:.3} cx {:.3} k1 {:.2e}",
        cal.rms_px,
        cal.iterations,
        rel(e[0], t[0]),
        rel(e[1], t[1]),
        rel(e[2], t[2]),
        rel(e[3], t[3]),
        rel(e[4], t[4]),
        rel(e[5], t[5]),
        cal.std_errors[0],
        cal.std_errors[2],
        cal.std_errors[4]
    );
    for k in 0..4 {
        assert!(
            rel(e[k], t[k]) < 1e-3,
            "{} off by {:.2e}",
            CAMERA_PARAM_NAMES_FOR_TEST[k],
            rel(e[k], t[k])
        );
    }
    assert!(rel(e[4], t[4]) < 0.02, "k1 {} vs {}", e[4], t[4]);
    // Honest uncertainty: every estimated parameter within 4σ of the truth.
    for k in 0..CAMERA_PARAM_COUNT {
        if cal.estimated[k] {
            assert!(
                (e[k] - t[k]).abs() < 4.0 * cal.std_errors[k],
                "param {k}: {} ± {} vs {}",
                e[k],
                cal.std_errors[k],
                t[k]
            );
        } else {
            assert_eq!(cal.std_errors[k], 0.0);
        }
    }
    assert!(cal.rejected.is_empty());
    assert_eq!(cal.views.len(), 20);
    for (v, truth_pose) in cal.views.iter().zip(&poses) {
        assert!(
            v.camera_from_board
                .rotation
                .angle_to(&truth_pose.rotation)
                .to_degrees()
                < 0.05
        );
        assert!((0.1..0.35).contains(&v.rms_px));
    }
}

const CAMERA_PARAM_NAMES_FOR_TEST: [&str; 4] = ["fx", "fy", "cx", "cy"];

#[test]
fn closed_form_is_exact_without_noise_or_distortion() {
    let (mut cam, _, _) = synthetic_views(12, 1, 0.0);
    cam.distortion = Distortion::ZERO;
    let b = board(0.05);
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let mut hs = Vec::new();
    while hs.len() < 5 {
        let pose = random_pose(&mut rng, false);
        let obs = observe(&cam, &b, &pose, 0.0, &mut rng);
        if obs.len() < 16 {
            continue;
        }
        let xy: Vec<[f64; 2]> = obs
            .iter()
            .map(|c| [c.point_board_m.x, c.point_board_m.y])
            .collect();
        let px: Vec<[f64; 2]> = obs.iter().map(|c| c.pixel).collect();
        hs.push(homography_dlt(&xy, &px).unwrap());
    }
    let k = intrinsics_from_homographies(&hs, cam.width, cam.height).unwrap();
    let i = cam.intrinsics;
    for (a, b) in [(k.fx, i.fx), (k.fy, i.fy), (k.cx, i.cx), (k.cy, i.cy)] {
        assert!((a - b).abs() < 1e-5 * b, "{a} vs {b}");
    }
    assert!(matches!(
        intrinsics_from_homographies(&hs[..2], 10, 10),
        Err(ZhangError::TooFewViews(2))
    ));
}

#[test]
fn outlier_and_invalid_views_are_rejected_with_reasons() {
    let (truth, mut views, _) = synthetic_views(13, 14, 0.15);
    // View 3: a tag decoded at the wrong place (its corners shifted by 6 px).
    for (p, q) in views[3].iter_mut().take(4) {
        let _ = p;
        q.x += 6.0;
    }
    views[5][2].1.x = f64::NAN;
    views[7][0].0.z = 0.01;
    views[9].truncate(5);
    let cal = calibrate(&views, (truth.width, truth.height), &CalibConfig::default()).unwrap();
    let reasons: Vec<(usize, &ViewRejection)> =
        cal.rejected.iter().map(|r| (r.index, &r.reason)).collect();
    println!("rejected: {reasons:?}");
    assert!(matches!(reasons[0], (3, ViewRejection::Outlier { .. })));
    assert!(matches!(
        reasons[1],
        (5, ViewRejection::NotFinite { point: 2 })
    ));
    assert!(matches!(
        reasons[2],
        (7, ViewRejection::OffBoardPlane { point: 0, .. })
    ));
    assert!(matches!(
        reasons[3],
        (
            9,
            ViewRejection::TooFewPoints {
                found: 5,
                required: 8
            }
        )
    ));
    assert_eq!(cal.rejected.len(), 4);
    assert_eq!(cal.views.len(), 10);
    assert!(rel(cal.camera.intrinsics.fx, truth.intrinsics.fx) < 1e-3);

    // Too few usable views is an error that lists every reason.
    let err = calibrate(
        &views[5..10],
        (truth.width, truth.height),
        &CalibConfig::default(),
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, CalibError::TooFewViews { usable: 2, .. }),
        "{msg}"
    );
    assert!(
        msg.contains("view 0")
            && msg.contains("off the board plane")
            && msg.contains("too few points"),
        "{msg}"
    );
    assert!(matches!(
        calibrate(&views, (0, 10), &CalibConfig::default()),
        Err(CalibError::EmptyImage { .. })
    ));
}

#[test]
fn toml_camera_section_round_trips() {
    let (truth, views, _) = synthetic_views(14, 8, 0.15);
    let cal = calibrate(&views, (truth.width, truth.height), &CalibConfig::default()).unwrap();
    let text = cal.to_toml_camera_section();
    println!("{text}");
    #[derive(serde::Deserialize)]
    struct Rig {
        camera: CameraModel,
    }
    let rig: Rig = toml::from_str(&text).unwrap();
    assert_eq!(rig.camera, cal.camera);
    assert!(text.contains("k3 = 0.0  # fixed"));
    assert!(
        text.lines()
            .any(|l| l.starts_with("fx = ") && l.contains("# ± "))
    );
}

/// The highlight point on a mirror sphere: the surface point whose normal bisects the
/// directions to the camera (origin) and the flash. Fixed-point iteration, converging because
/// r ≪ distance.
fn highlight_point(centre: Vector3<f64>, radius: f64, flash: Vector3<f64>) -> Vector3<f64> {
    let mut n = -centre.normalize();
    for _ in 0..100 {
        let p = centre + radius * n;
        n = ((-p).normalize() + (flash - p).normalize()).normalize();
    }
    centre + radius * n
}

#[test]
fn flash_offset_from_sphere_highlights() {
    let cam = camera_5mp();
    let flash_truth = Vector3::new(0.030, 0.0, 0.0); // 30 mm right of the lens
    let sphere_centre_board_m = Point3::new(0.0, 0.0, 0.025);
    let sphere_radius_m = 0.025;
    let mut rng = ChaCha8Rng::seed_from_u64(15);
    let noise = Normal::new(0.0, 0.3).unwrap();
    let mut obs = Vec::new();
    while obs.len() < 40 {
        let target = Vector3::new(
            rng.random_range(-0.12..0.12),
            rng.random_range(-0.1..0.1),
            0.0,
        );
        let pose = look_at(
            target,
            rng.random_range(0.3..0.7),
            rng.random_range(0.1f64..1.0),
            rng.random_range(0.0..std::f64::consts::TAU),
            rng.random_range(-3.0..3.0),
        );
        let c = (pose * sphere_centre_board_m).coords;
        let p = highlight_point(c, sphere_radius_m, flash_truth);
        let Some(px) = cam.project(&Point3::from(p)) else {
            continue;
        };
        if !cam.contains_pixel(px) {
            continue;
        }
        obs.push(HighlightObservation {
            camera_from_board: pose,
            sphere_centre_board_m,
            sphere_radius_m,
            highlight_px: [
                px[0] + noise.sample(&mut rng),
                px[1] + noise.sample(&mut rng),
            ],
        });
    }
    let est = estimate_flash_position(&cam, &obs).unwrap();
    let err = est.flash_camera_m.coords - flash_truth;
    let mahalanobis2 = err.dot(&(est.covariance_m2.try_inverse().unwrap() * err));
    println!(
        "flash: estimate {:?} mm, error {:.3} mm, std {:?} mm, rms angle {:.2} mrad, d² {mahalanobis2:.2}",
        (est.flash_camera_m.coords * 1e3).as_slice(),
        err.norm() * 1e3,
        est.std_m.map(|s| s * 1e3),
        est.rms_angle_rad * 1e3
    );
    assert!(err.norm() < 3e-3, "flash error {} mm", err.norm() * 1e3);
    // χ²(3) 99.9 % quantile is 16.3: the reported covariance covers the error.
    assert!(mahalanobis2 < 16.3);

    // Noise-free highlights give the flash exactly.
    let exact: Vec<HighlightObservation> = obs
        .iter()
        .map(|o| {
            let c = (o.camera_from_board * sphere_centre_board_m).coords;
            let px = cam
                .project(&Point3::from(highlight_point(
                    c,
                    sphere_radius_m,
                    flash_truth,
                )))
                .unwrap();
            HighlightObservation {
                highlight_px: px,
                ..*o
            }
        })
        .collect();
    let est = estimate_flash_position(&cam, &exact).unwrap();
    assert!((est.flash_camera_m.coords - flash_truth).norm() < 1e-7);

    // Bad input is named.
    assert_eq!(
        estimate_flash_position(&cam, &obs[..1]).unwrap_err(),
        FlashError::TooFewViews(1)
    );
    let mut miss = obs[..3].to_vec();
    miss[1].highlight_px = [10.0, 10.0];
    assert!(matches!(
        estimate_flash_position(&cam, &miss),
        Err(FlashError::RayMissesSphere { view: 1, .. })
    ));
    let mut bad = obs[..3].to_vec();
    bad[2].sphere_radius_m = -1.0;
    assert!(matches!(
        estimate_flash_position(&cam, &bad),
        Err(FlashError::BadRadius { view: 2, .. })
    ));
}

#[test]
fn free_k3_and_tangential_are_recovered_with_honest_errors() {
    let (truth, views, _) = synthetic_views(16, 25, 0.15);
    let config = CalibConfig {
        fix_k3: false,
        ..CalibConfig::default()
    };
    let cal = calibrate(&views, (truth.width, truth.height), &config).unwrap();
    let (e, t) = (cal.camera.params(), truth.params());
    assert!(cal.estimated.iter().all(|f| *f));
    for k in 0..CAMERA_PARAM_COUNT {
        assert!(cal.std_errors[k] > 0.0);
        assert!(
            (e[k] - t[k]).abs() < 4.0 * cal.std_errors[k],
            "param {k}: {} ± {} vs {}",
            e[k],
            cal.std_errors[k],
            t[k]
        );
    }
    // A free k3 costs precision on k1 (they trade off), never accuracy beyond the stated σ.
    let fixed = calibrate(&views, (truth.width, truth.height), &CalibConfig::default()).unwrap();
    assert!(cal.std_errors[4] > fixed.std_errors[4]);
}

#[test]
fn parallel_views_are_degenerate() {
    // Every view fronto-parallel (pure translations): Zhang's constraints are degenerate.
    let cam = camera_5mp();
    let b = board(0.05);
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let views: Vec<View> = (0..6)
        .map(|k| {
            let pose = look_at(
                Vector3::new(0.01 * k as f64, 0.0, 0.0),
                0.4 + 0.05 * k as f64,
                0.0,
                0.0,
                0.0,
            );
            observe(&cam, &b, &pose, 0.0, &mut rng)
                .iter()
                .map(|c| (c.point_board_m, Point2::new(c.pixel[0], c.pixel[1])))
                .collect()
        })
        .collect();
    let err = calibrate(&views, (cam.width, cam.height), &CalibConfig::default()).unwrap_err();
    assert!(
        matches!(err, CalibError::ClosedForm(ZhangError::Degenerate(_))),
        "{err}"
    );
    assert!(err.to_string().contains("vary the board tilt"));
}

/// Every view seeing the sphere at the same place in the camera frame (an orbit aimed at its
/// centre) gives identical reflected rays: rejected as degenerate instead of a confident
/// nonsense estimate, noise or not.
#[test]
fn flash_from_one_repeated_ray_geometry_is_degenerate() {
    let cam = camera_5mp();
    let flash_truth = Vector3::new(0.0, -0.03, 0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(16);
    let noise = Normal::new(0.0, 0.3).unwrap();
    let obs: Vec<HighlightObservation> = (0..20)
        .map(|k| {
            // aimed at the sphere's centre from 0.5 m, only the azimuth changes
            let pose = look_at(Vector3::new(0.0, 0.0, 0.04), 0.5, 0.6, k as f64 * 0.3, 0.0);
            let centre = Point3::new(0.0, 0.0, 0.04);
            let c = (pose * centre).coords;
            let px = cam
                .project(&Point3::from(highlight_point(c, 0.04, flash_truth)))
                .unwrap();
            HighlightObservation {
                camera_from_board: pose,
                sphere_centre_board_m: centre,
                sphere_radius_m: 0.04,
                highlight_px: [
                    px[0] + noise.sample(&mut rng),
                    px[1] + noise.sample(&mut rng),
                ],
            }
        })
        .collect();
    assert_eq!(
        estimate_flash_position(&cam, &obs),
        Err(FlashError::Degenerate)
    );
}

/// Views of a level camera orbiting the board's centre on a rising spiral (elevation 25…65°,
/// two turns), σ = 0.3 px: every view tilts the board about the camera's horizontal axis.
fn level_orbit(n: usize, distance_m: f64) -> (CameraModel, Vec<View>) {
    let cam = camera_5mp();
    let b = board(0.05);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let centre = Vector3::new(0.1125, 0.0675, 0.0);
    let views = (0..n)
        .filter_map(|k| {
            let t = k as f64 / n as f64;
            let elevation = (25.0 + 40.0 * t).to_radians();
            let azimuth = 2.0 * std::f64::consts::TAU * t;
            let dir = Vector3::new(
                elevation.cos() * azimuth.cos(),
                elevation.cos() * azimuth.sin(),
                elevation.sin(),
            );
            // camera axes: z toward the board, x horizontal (level), y completing the frame
            let z_c = -dir;
            let x_c = Vector3::z().cross(&dir).normalize();
            let y_c = z_c.cross(&x_c);
            let board_from_camera = Pose::from_parts(
                nalgebra::Translation3::from(centre + distance_m * dir),
                nalgebra::UnitQuaternion::from_matrix(&nalgebra::Matrix3::from_columns(&[
                    x_c, y_c, z_c,
                ])),
            );
            let obs = observe(&cam, &b, &board_from_camera.inverse(), 0.3, &mut rng);
            (obs.len() >= 16).then(|| as_view(&obs))
        })
        .collect();
    (cam, views)
}

/// Issue 28, case 2: an orbit around an object at one camera roll does not determine the
/// camera; calibration says so, with how to take calibration photos, instead of returning a
/// camera far from the truth with small uncertainties.
#[test]
fn a_level_orbit_is_refused_with_how_to_take_calibration_photos() {
    let (cam, views) = level_orbit(40, 1.2);
    assert!(views.len() >= 30, "{} views", views.len());
    match calibrate(&views, (cam.width, cam.height), &CalibConfig::default()) {
        Err(CalibError::Undetermined(u)) => {
            println!("{u}");
            assert!(u.spread.out_of_plane_deg < 0.5, "{u}");
            let text = u.to_string();
            assert!(
                text.contains("horizontal axis") && text.contains("calibration photos"),
                "{text}"
            );
        }
        Ok(cal) => {
            // where the views happen to determine it, the answer must be right within its σ
            let (e, t) = (cal.camera.params(), cam.params());
            for k in 0..4 {
                assert!(
                    (e[k] - t[k]).abs() < 4.0 * cal.std_errors[k],
                    "param {k}: {} vs {} ± {}",
                    e[k],
                    t[k],
                    cal.std_errors[k]
                );
            }
            panic!(
                "expected a refusal; got fx {:.1} ± {:.1}, cy {:.1} ± {:.1}, out of plane {:.3}°",
                e[0], cal.std_errors[0], e[3], cal.std_errors[3], cal.spread.out_of_plane_deg
            );
        }
        Err(e) => panic!("{e}"),
    }
}

/// Issue 46: `n` views of the 9×7 board seen only obliquely (tilt 55–75°, any azimuth and
/// roll), σ = 0.3 px, by the 5 MP camera with no k2: the corners near the image's edge are few
/// and foreshortened, so k2 trades off against k1 and the focal length. A guard, not the
/// issue's reproduction: its grazing-only session (k2 0.235 ± 0.072 for a lens without k2) is
/// not reproduced by corner noise alone, nor by simulated grazing-only captures of the
/// calibration board (24 views at 18–32° elevation: k2 0.0035 ± 0.0037 at 2448×2048,
/// 0.029 ± 0.021 at 612×512).
fn grazing_views(seed: u64, n: usize) -> (CameraModel, Vec<View>) {
    let cam = CameraModel {
        distortion: Distortion {
            k2: 0.0,
            ..camera_5mp().distortion
        },
        ..camera_5mp()
    };
    let b = calibration_board();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut views = Vec::new();
    let mut tries = 0;
    while views.len() < n && tries < 10_000 {
        tries += 1;
        let target = Vector3::new(
            rng.random_range(-0.1..0.1),
            rng.random_range(-0.08..0.08),
            0.0,
        );
        let pose = look_at(
            target,
            rng.random_range(0.35..0.8),
            rng.random_range(55.0f64..75.0).to_radians(),
            rng.random_range(0.0..std::f64::consts::TAU),
            rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
        );
        let obs = observe(&cam, &b, &pose, 0.3, &mut rng);
        if obs.len() < 32 {
            continue;
        }
        views.push(as_view(&obs));
    }
    (cam, views)
}

#[test]
fn grazing_views_do_not_report_a_k2_they_cannot_pin() {
    for seed in [1u64, 2, 3, 4] {
        let (cam, views) = grazing_views(seed, 20);
        assert_eq!(views.len(), 20);
        match calibrate(&views, (cam.width, cam.height), &CalibConfig::default()) {
            Err(CalibError::Undetermined(u)) => println!("seed {seed}: refused: {u}"),
            Err(e) => panic!("seed {seed}: {e}"),
            Ok(cal) => {
                let k2 = cal.camera.distortion.k2;
                println!(
                    "seed {seed}: k2 {k2:.4} ± {:.4} (estimated {}), k1 {:.4} ± {:.4}",
                    cal.std_errors[5],
                    cal.estimated[5],
                    cal.camera.distortion.k1,
                    cal.std_errors[4]
                );
                if cal.estimated[5] {
                    // Reported as a measurement: the truth (0) within 3σ.
                    assert!(
                        k2.abs() <= 3.0 * cal.std_errors[5],
                        "seed {seed}: k2 {k2} ± {}",
                        cal.std_errors[5]
                    );
                } else {
                    assert_eq!((k2, cal.std_errors[5]), (0.0, 0.0), "seed {seed}: fixed k2");
                }
            }
        }
    }
}
