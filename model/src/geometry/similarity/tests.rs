//! Tests of the similarity estimate: a known similarity recovered (exactly without noise, to the
//! noise with it), outliers of every kind tolerated and flagged, and each refusal.

use super::*;
use nalgebra::{Unit, Vector3};
use proptest::prelude::*;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// A camera at `eye` looking at `target` (OpenCV axes: x right, y down, z forward; world z up).
fn look_at(eye: Point3<f64>, target: Point3<f64>) -> Isometry3<f64> {
    let z = (target - eye).normalize();
    let x = z.cross(&Vector3::z()).normalize();
    let y = z.cross(&x);
    let r = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    Isometry3::from_parts(Translation3::from(eye.coords), UnitQuaternion::from(r))
}

/// `n` board-frame cameras on an orbit around the object (0.35 m, 25–60° elevation).
fn orbit(n: usize) -> Vec<Isometry3<f64>> {
    (0..n)
        .map(|k| {
            let az = k as f64 * std::f64::consts::TAU / n as f64;
            let el = (25.0 + 35.0 * ((k * 7) % n) as f64 / n as f64).to_radians();
            let eye = Point3::new(
                0.35 * el.cos() * az.cos(),
                0.35 * el.cos() * az.sin(),
                0.03 + 0.35 * el.sin(),
            );
            look_at(eye, Point3::new(0.0, 0.0, 0.03))
        })
        .collect()
}

/// A similarity far from the identity (COLMAP's arbitrary frame: scale ~ 12, turned, moved).
fn known() -> Similarity3<f64> {
    Similarity3::from_parts(
        Translation3::new(0.21, -0.05, 0.13),
        UnitQuaternion::from_axis_angle(&Unit::new_normalize(Vector3::new(0.3, -0.8, 0.5)), 2.1),
        1.0 / 12.5,
    )
}

/// Board poses and their source-frame copies under `known()`, with seeded noise on the board
/// side (σ per axis, mm; rotation σ, degrees).
fn pairs(n: usize, sigma_mm: f64, sigma_deg: f64, seed: u64) -> Vec<PosePair> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let source_from_target = known().inverse();
    let mut gauss = move || {
        // Box–Muller; u1 in (0, 1] keeps the log finite
        let u1: f64 = 1.0 - rng.random::<f64>();
        let u2: f64 = rng.random();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    orbit(n)
        .into_iter()
        .map(|target_from_camera| {
            let source_from_camera = apply_to_pose(&source_from_target, &target_from_camera);
            let dt = Vector3::new(gauss(), gauss(), gauss()) * sigma_mm * 1e-3;
            let dr = Vector3::new(gauss(), gauss(), gauss()) * sigma_deg.to_radians();
            let noisy = Isometry3::from_parts(
                Translation3::from(target_from_camera.translation.vector + dt),
                UnitQuaternion::from_scaled_axis(dr) * target_from_camera.rotation,
            );
            PosePair {
                source_from_camera,
                target_from_camera: noisy,
            }
        })
        .collect()
}

/// Distance between two similarities on the object's scale: the largest displacement of a
/// point within 0.2 m of the board origin (mm), and the rotation between them (degrees).
fn difference(a: &Similarity3<f64>, b: &Similarity3<f64>) -> (f64, f64) {
    let corners = [-1.0, 1.0];
    let mut worst: f64 = 0.0;
    // source points that map into the 0.2 m box around the board origin under `b`
    for x in corners {
        for y in corners {
            for z in corners {
                let board = Point3::new(x, y, z) * 0.2;
                let source = b.inverse_transform_point(&board);
                worst = worst.max((a.transform_point(&source) - board).norm() * 1e3);
            }
        }
    }
    (
        worst,
        a.isometry
            .rotation
            .angle_to(&b.isometry.rotation)
            .to_degrees(),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Noise-free points: Umeyama returns the similarity that made them, whatever its scale.
    #[test]
    fn umeyama_recovers_a_known_similarity(
        seed in 0u64..10_000,
        log_scale in -4.0f64..4.0,
        axis in prop::array::uniform3(-1.0f64..1.0),
        angle in 0.0f64..3.1,
        t in prop::array::uniform3(-5.0f64..5.0),
    ) {
        let axis = Vector3::from(axis);
        prop_assume!(axis.norm() > 1e-3);
        let sim = Similarity3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), angle),
            log_scale.exp(),
        );
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let source: Vec<Point3<f64>> = (0..6)
            .map(|_| Point3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)))
            .collect();
        prop_assume!(spans_plane(&source, 1e-3));
        let target: Vec<Point3<f64>> = source.iter().map(|p| sim.transform_point(p)).collect();
        let got = umeyama(&source, &target).expect("points span a plane");
        prop_assert!((got.scaling() / sim.scaling() - 1.0).abs() < 1e-9);
        prop_assert!(got.isometry.rotation.angle_to(&sim.isometry.rotation) < 1e-9);
        for p in &source {
            prop_assert!((got.transform_point(p) - sim.transform_point(p)).norm() < 1e-9 * (1.0 + sim.scaling()));
        }
    }
}

#[test]
fn umeyama_refuses_what_fixes_no_similarity() {
    let line: Vec<Point3<f64>> = (0..5)
        .map(|k| Point3::new(k as f64, 2.0 * k as f64, 0.0))
        .collect();
    assert!(umeyama(&line, &line).is_none(), "collinear");
    let one = vec![Point3::new(1.0, 2.0, 3.0); 4];
    assert!(umeyama(&one, &one).is_none(), "coincident");
    let few = [Point3::origin(), Point3::new(1.0, 0.0, 0.0)];
    assert!(umeyama(&few, &few).is_none(), "two points");
    // a mirror image is not a similarity: Umeyama's guard returns the nearest proper rotation
    let tri = [
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(1.0, 0.0, 0.0),
        Point3::new(0.0, 1.0, 0.0),
        Point3::new(0.0, 0.0, 1.0),
    ];
    let mirrored: Vec<Point3<f64>> = tri.iter().map(|p| Point3::new(-p.x, p.y, p.z)).collect();
    let got = umeyama(&tri, &mirrored).unwrap();
    assert!(
        got.isometry
            .rotation
            .to_rotation_matrix()
            .matrix()
            .determinant()
            > 0.0
    );
}

#[test]
fn poses_recover_a_known_similarity_to_the_noise() {
    let pairs = pairs(24, 0.1, 0.02, 1);
    let a = align_poses(&pairs, &AlignConfig::default()).unwrap();
    let (mm, deg) = difference(&a.target_from_source, &known());
    assert!(mm < 0.1 && deg < 0.02, "{mm} mm, {deg}°");
    assert_eq!(a.inliers, 24);
    // the residual is the noise's size: |Δc| of a 3-D Gaussian with σ = 0.1 mm has RMS 0.17 mm
    assert!(
        (0.1..0.25).contains(&a.rms_position_mm),
        "{}",
        a.rms_position_mm
    );
    assert!(a.rms_rotation_deg < 0.05, "{}", a.rms_rotation_deg);
    assert!(a.max_position_mm >= a.rms_position_mm);
    // noise-free: exact
    let exact = align_poses(&self::pairs(6, 0.0, 0.0, 2), &AlignConfig::default()).unwrap();
    let (mm, deg) = difference(&exact.target_from_source, &known());
    assert!(mm < 1e-9 && deg < 1e-9, "{mm} mm, {deg}°");
    assert!(exact.rms_position_mm < 1e-9);
}

#[test]
fn bad_frames_are_flagged_and_do_not_move_the_alignment() {
    let mut pairs = pairs(20, 0.1, 0.02, 3);
    // a tracking pose 30 mm off, one turned by 4° about its centre, one pose of another frame
    // (swapped names), and a model pose at the far side of the object
    pairs[2].target_from_camera.translation.vector += Vector3::new(0.03, 0.0, 0.0);
    pairs[7].target_from_camera.rotation =
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 4f64.to_radians())
            * pairs[7].target_from_camera.rotation;
    let swapped = pairs[11].target_from_camera;
    pairs[11].target_from_camera = pairs[12].target_from_camera;
    pairs[12].target_from_camera = swapped;
    let far = pairs[16].source_from_camera;
    pairs[16].source_from_camera =
        Isometry3::from_parts(Translation3::from(-far.translation.vector), far.rotation);
    let a = align_poses(&pairs, &AlignConfig::default()).unwrap();
    let outliers: Vec<usize> = (0..20).filter(|&i| !a.residuals[i].inlier).collect();
    assert_eq!(outliers, [2, 7, 11, 12, 16]);
    assert!((a.residuals[2].position_mm - 30.0).abs() < 1.0);
    assert!((a.residuals[7].rotation_deg - 4.0).abs() < 0.2);
    assert!(a.residuals[7].position_mm < 1.0, "only its rotation is off");
    let (mm, deg) = difference(&a.target_from_source, &known());
    assert!(mm < 0.15 && deg < 0.02, "{mm} mm, {deg}°");
    assert!(a.rms_position_mm < 0.25 && a.max_position_mm < 1.0);
}

#[test]
fn many_frames_with_a_fifth_bad_take_the_sampled_path_and_hold() {
    // C(40, 3) = 9880 > 2000 triples: seeded random hypotheses
    let mut pairs = pairs(40, 0.2, 0.03, 4);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for i in (0..40).step_by(5) {
        pairs[i].target_from_camera.translation.vector += Vector3::new(
            rng.random_range(-0.05..0.05),
            rng.random_range(-0.05..0.05),
            0.02,
        );
    }
    let a = align_poses(&pairs, &AlignConfig::default()).unwrap();
    assert_eq!(a.inliers, 32);
    let (mm, deg) = difference(&a.target_from_source, &known());
    assert!(mm < 0.3 && deg < 0.03, "{mm} mm, {deg}°");
    // the same input gives the same result
    assert_eq!(align_poses(&pairs, &AlignConfig::default()).unwrap(), a);
}

#[test]
fn each_refusal_names_its_cause() {
    let config = AlignConfig::default();
    let e = align_poses(&pairs(3, 0.0, 0.0, 6), &config).unwrap_err();
    assert_eq!(
        e,
        AlignError::TooFewFrames {
            frames: 3,
            needed: 4
        }
    );

    // a straight pass: centres on a line
    let line: Vec<PosePair> = (0..8)
        .map(|k| {
            let eye = Point3::new(-0.2 + 0.05 * k as f64, -0.3, 0.25);
            let target_from_camera = look_at(eye, Point3::new(0.0, 0.0, 0.03));
            PosePair {
                source_from_camera: apply_to_pose(&known().inverse(), &target_from_camera),
                target_from_camera,
            }
        })
        .collect();
    let e = align_poses(&line, &config).unwrap_err();
    assert!(
        matches!(
            e,
            AlignError::Degenerate {
                frame: "source",
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("line"), "{e}");

    // a tripod turning on the spot: every centre the same
    let spot: Vec<PosePair> = (0..6)
        .map(|k| {
            let target_from_camera = Isometry3::from_parts(
                Translation3::new(0.0, -0.3, 0.2),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.1 * k as f64),
            );
            PosePair {
                source_from_camera: target_from_camera,
                target_from_camera,
            }
        })
        .collect();
    let e = align_poses(&spot, &config).unwrap_err();
    assert!(e.to_string().contains("coincide"), "{e}");

    // two unrelated sets of poses
    let mut unrelated = pairs(12, 0.0, 0.0, 7);
    let others = orbit(12);
    for (k, p) in unrelated.iter_mut().enumerate() {
        p.target_from_camera = others[(k * 5 + 3) % 12];
    }
    let e = align_poses(&unrelated, &config).unwrap_err();
    assert!(
        matches!(e, AlignError::TooFewInliers { frames: 12, .. }),
        "{e}"
    );

    // the same cameras, but 2.5 mm of noise everywhere: inliers under a loose threshold, and
    // above the residual limit
    let loose = AlignConfig {
        inlier_mm: 30.0,
        ..config
    };
    let e = align_poses(&pairs(16, 2.5, 0.02, 8), &loose).unwrap_err();
    let AlignError::ResidualTooLarge {
        rms_mm, inliers, ..
    } = e
    else {
        panic!("{e}");
    };
    assert!(rms_mm > 2.0 && inliers == 16, "{rms_mm} {inliers}");
}

#[test]
fn rotations_carry_the_alignment_where_centres_are_noisy() {
    // noisy centres, precise rotations: the joint estimate's rotation beats centres alone
    let pairs = pairs(8, 1.0, 0.005, 9);
    let loose = AlignConfig {
        inlier_mm: 20.0,
        max_rms_mm: 5.0,
        ..AlignConfig::default()
    };
    let joint = align_poses(&pairs, &loose).unwrap();
    let centres = align_poses(
        &pairs,
        &AlignConfig {
            rotation_weight: 0.0,
            ..loose
        },
    )
    .unwrap();
    let (_, joint_deg) = difference(&joint.target_from_source, &known());
    let (_, centres_deg) = difference(&centres.target_from_source, &known());
    assert!(
        joint_deg < centres_deg,
        "joint {joint_deg}° vs centres {centres_deg}°"
    );
}
