//! End-to-end: a board of library-rendered tag36h11 tags, ray-traced through a camera with lens
//! distortion into an 8-bit image, goes through detection → assembly → joint PnP, and the pose
//! must match the one it was rendered with. This checks the corner order, the board frame, the
//! 0.5 px convention and the distortion handling together.

use super::super::detect::tests::tag36h11_cells;
use super::super::synthetic::{look_at, pose_error};
use super::super::*;
use ellipso_model::camera::{CameraModel, Distortion, Intrinsics, Pose};
use nalgebra::Vector3;

/// Intensity of the board at a board-frame point: tags on white.
fn board_intensity(board: &TagGridBoard, cells: &[(usize, Vec<u8>)], x: f64, y: f64) -> f64 {
    let (dark, light) = (20.0, 230.0);
    let cell_m = board.tag_size_m / 8.0;
    let col = ((x / board.pitch_m) + f64::from(board.cols - 1) / 2.0).round();
    let row = (f64::from(board.rows - 1) / 2.0 - y / board.pitch_m).round();
    if col < 0.0 || row < 0.0 || col >= f64::from(board.cols) || row >= f64::from(board.rows) {
        return light;
    }
    let cx = (col - f64::from(board.cols - 1) / 2.0) * board.pitch_m;
    let cy = (f64::from(board.rows - 1) / 2.0 - row) * board.pitch_m;
    // Tag image cells: x right = board +x, y down = board −y; the image spans ±5 cells.
    let u = (x - cx) / cell_m + 5.0;
    let v = (cy - y) / cell_m + 5.0;
    let (n, img) = &cells[(row as usize) * board.cols as usize + col as usize];
    if u < 0.0 || v < 0.0 || u >= *n as f64 || v >= *n as f64 {
        return light;
    }
    if img[v as usize * n + u as usize] > 127 {
        light
    } else {
        dark
    }
}

fn render(cam: &CameraModel, camera_from_board: &Pose, board: &TagGridBoard) -> Vec<u8> {
    let cells: Vec<(usize, Vec<u8>)> = board
        .tag_ids()
        .map(|id| tag36h11_cells(id as i32))
        .collect();
    let board_from_camera = camera_from_board.inverse();
    let origin = board_from_camera.translation.vector;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let ss = 3;
    let mut img = vec![0u8; w * h];
    for j in 0..h {
        for i in 0..w {
            let mut acc = 0.0;
            for sy in 0..ss {
                for sx in 0..ss {
                    let u = i as f64 - 0.5 + (sx as f64 + 0.5) / ss as f64;
                    let v = j as f64 - 0.5 + (sy as f64 + 0.5) / ss as f64;
                    let ray = cam.unproject_to_ray([u, v]).unwrap();
                    let d = board_from_camera.rotation * ray.into_inner();
                    let s = -origin.z / d.z;
                    let p: Vector3<f64> = origin + d * s;
                    acc += board_intensity(board, &cells, p.x, p.y);
                }
            }
            img[j * w + i] = (acc / (ss * ss) as f64).round() as u8;
        }
    }
    img
}

#[test]
fn rendered_board_pose_round_trips_through_detection() {
    let cam = CameraModel {
        width: 800,
        height: 600,
        intrinsics: Intrinsics {
            fx: 1150.0,
            fy: 1148.0,
            cx: 401.3,
            cy: 297.6,
        },
        distortion: Distortion {
            k1: -0.12,
            k2: 0.1,
            k3: 0.0,
            p1: 5e-4,
            p2: -3e-4,
        },
    };
    let board = TagGridBoard {
        cols: 3,
        rows: 2,
        tag_size_m: 0.04,
        pitch_m: 0.06,
        first_id: 0,
    };
    let truth = look_at(Vector3::new(0.004, -0.003, 0.0), 0.36, 0.45, 0.7, 0.3);
    let img = render(&cam, &truth, &board);
    let mut det = TagDetector::new(DetectorConfig {
        decimation: 1.0,
        ..DetectorConfig::default()
    })
    .unwrap();
    let detections = det
        .detect(&img, cam.width as usize, cam.height as usize)
        .unwrap();
    let assembly = assemble_correspondences(&detections, &board);
    assert_eq!(detections.len(), 6, "{detections:?}");
    assert!(assembly.foreign_ids.is_empty() && assembly.duplicate_ids.is_empty());
    // Every detected corner lands within 0.3 px of the projected board corner.
    for c in &assembly.correspondences {
        let q = cam.project(&(truth * c.point_board_m)).unwrap();
        let err = (q[0] - c.pixel[0]).hypot(q[1] - c.pixel[1]);
        assert!(
            err < 0.3,
            "tag {} corner {}: {err:.3} px",
            c.tag_id,
            c.corner
        );
    }
    let pose =
        estimate_board_pose(&cam, &assembly.correspondences, &PoseConfig::default()).unwrap();
    let (rot_deg, trans_mm) = pose_error(&pose.camera_from_board, &truth);
    println!(
        "rendered: rms {:.3} px, rotation error {rot_deg:.4}°, translation error {trans_mm:.4} mm",
        pose.rms_px
    );
    assert!(pose.rms_px < 0.3);
    assert!(rot_deg < 0.1 && trans_mm < 0.3, "{rot_deg}° {trans_mm} mm");
}
