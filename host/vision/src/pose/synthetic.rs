//! Test support: synthetic hand-held views of a tag board — known camera, random camera poses
//! around the board, projected tag corners with seeded Gaussian pixel noise. Shared by the pose
//! and calibration tests.

use ellipso_model::camera::{CameraModel, Distortion, Intrinsics, Pose};
use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::board::{BoardCorners, TagGridBoard};
use super::estimate::Correspondence;

/// The 5 MP polarisation camera of the rig with a mild lens distortion.
pub fn camera_5mp() -> CameraModel {
    CameraModel {
        width: 2448,
        height: 2048,
        intrinsics: Intrinsics {
            fx: 3502.0,
            fy: 3498.5,
            cx: 1230.4,
            cy: 1019.2,
        },
        distortion: Distortion {
            k1: -0.09,
            k2: 0.12,
            k3: 0.0,
            p1: 3e-4,
            p2: -2e-4,
        },
    }
}

/// A 6×4 board of `tag_size_m` tags at 1.5× pitch, ids from 0.
pub fn board(tag_size_m: f64) -> TagGridBoard {
    TagGridBoard {
        cols: 6,
        rows: 4,
        tag_size_m,
        pitch_m: 1.5 * tag_size_m,
        first_id: 0,
    }
}

/// A camera pose looking at `target_board` from `distance_m`, with the line of sight tilted
/// `tilt_rad` from the board normal toward azimuth `azimuth_rad`, rolled by `roll_rad`.
pub fn look_at(
    target_board: Vector3<f64>,
    distance_m: f64,
    tilt_rad: f64,
    azimuth_rad: f64,
    roll_rad: f64,
) -> Pose {
    let dir = Vector3::new(
        tilt_rad.sin() * azimuth_rad.cos(),
        tilt_rad.sin() * azimuth_rad.sin(),
        tilt_rad.cos(),
    );
    let centre = target_board + distance_m * dir;
    let z_c = -dir;
    // Any vector not parallel to z_c seeds the x axis; then roll about z_c.
    let seed = if z_c.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let x0 = (seed - z_c * z_c.dot(&seed)).normalize();
    let x_c = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(z_c), roll_rad) * x0;
    let y_c = z_c.cross(&x_c);
    let board_from_camera_rot = Matrix3::from_columns(&[x_c, y_c, z_c]);
    let board_from_camera = Pose::from_parts(
        Translation3::from(centre),
        UnitQuaternion::from_matrix(&board_from_camera_rot),
    );
    board_from_camera.inverse()
}

/// Projects every tag of `board` whose four corners land inside the image (10 px margin),
/// adding N(0, σ²) noise per coordinate.
pub fn observe(
    camera: &CameraModel,
    board: &TagGridBoard,
    camera_from_board: &Pose,
    sigma_px: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<Correspondence> {
    let noise = Normal::new(0.0, sigma_px.max(0.0)).expect("σ ≥ 0 is a valid normal");
    let margin = 10.0;
    let mut out = Vec::new();
    for id in board.tag_ids() {
        let Some(corners) = board.corners_board_m(id) else {
            continue;
        };
        let projected: Option<Vec<[f64; 2]>> = corners
            .iter()
            .map(|p| camera.project(&(camera_from_board * p)))
            .collect();
        let Some(projected) = projected else { continue };
        let inside = projected.iter().all(|q| {
            q[0] > margin
                && q[1] > margin
                && q[0] < f64::from(camera.width) - margin
                && q[1] < f64::from(camera.height) - margin
        });
        if !inside {
            continue;
        }
        for (k, (p, q)) in corners.iter().zip(projected).enumerate() {
            out.push(Correspondence {
                tag_id: id,
                corner: k as u8,
                point_board_m: *p,
                pixel: [q[0] + noise.sample(rng), q[1] + noise.sample(rng)],
            });
        }
    }
    out
}

/// A random hand-held pose: 0.3–0.7 m away, aimed within ±40 mm of the board centre, tilt
/// 0–60° (or 0–2° when `near_fronto`), any azimuth and roll.
pub fn random_pose(rng: &mut ChaCha8Rng, near_fronto: bool) -> Pose {
    let target = Vector3::new(
        rng.random_range(-0.04..0.04),
        rng.random_range(-0.04..0.04),
        0.0,
    );
    let tilt = if near_fronto {
        rng.random_range(0.0f64..2.0).to_radians()
    } else {
        rng.random_range(0.0f64..60.0).to_radians()
    };
    look_at(
        target,
        rng.random_range(0.3..0.7),
        tilt,
        rng.random_range(0.0..std::f64::consts::TAU),
        rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
    )
}

/// Rotation error (deg) and translation error (mm) of an estimate: the model's one
/// [`ellipso_model::geometry::pose_error`], as the tuple the tests destructure.
pub fn pose_error(estimate: &Pose, truth: &Pose) -> (f64, f64) {
    let e = ellipso_model::geometry::pose_error(estimate, truth);
    (e.rotation_deg, e.translation_mm)
}

pub use ellipso_model::stats::median;
