//! Benchmark: µs per joint board PnP solve (`estimate_board_pose`: undistortion, IPPE, two LM
//! refinements with distortion, covariance) for 4–16 visible tags on a 5 MP camera, plus one
//! full calibration from 20 views.
//!
//! Run: `cargo bench -p ellipso-vision --bench pose`. Prints a table; no assertions.

use std::hint::black_box;
use std::time::Instant;

use ellipso_model::camera::{CameraModel, Distortion, Intrinsics, Pose};
use ellipso_vision::calibrate::{CalibConfig, calibrate};
use ellipso_vision::pose::{
    BoardCorners, Correspondence, PoseConfig, TagGridBoard, estimate_board_pose,
};
use nalgebra::{Point2, Translation3, UnitQuaternion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

fn camera() -> CameraModel {
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

/// A tilted view of the whole board from 0.5 m; all tags visible.
fn frame(board: &TagGridBoard, rng: &mut ChaCha8Rng) -> Vec<Correspondence> {
    let cam = camera();
    let pose = Pose::from_parts(
        Translation3::new(
            rng.random_range(-0.02..0.02),
            rng.random_range(-0.02..0.02),
            0.5,
        ),
        UnitQuaternion::from_euler_angles(
            std::f64::consts::PI + rng.random_range(-0.5..0.5),
            rng.random_range(-0.5..0.5),
            rng.random_range(-3.0..3.0),
        ),
    );
    let noise = Normal::new(0.0, 0.15).expect("valid σ");
    let mut out = Vec::new();
    for id in board.tag_ids() {
        let corners = board.corners_board_m(id).expect("id on board");
        for (k, p) in corners.iter().enumerate() {
            let q = cam.project(&(pose * p)).expect("board in front");
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

fn main() {
    let cam = camera();
    let config = PoseConfig::default();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    println!("joint board PnP, 5 MP camera with distortion, σ = 0.15 px");
    println!("| tags | corners | µs per solve | LM iterations (mean) |");
    println!("|---:|---:|---:|---:|");
    for (cols, rows) in [(2u32, 2u32), (4, 2), (4, 3), (4, 4)] {
        let board = TagGridBoard {
            cols,
            rows,
            tag_size_m: 0.04,
            pitch_m: 0.06,
            first_id: 0,
        };
        let frames: Vec<_> = (0..200).map(|_| frame(&board, &mut rng)).collect();
        // Warm-up.
        for f in frames.iter().take(20) {
            black_box(estimate_board_pose(&cam, f, &config).ok());
        }
        let reps = 5;
        let start = Instant::now();
        let mut iterations = 0usize;
        let mut solved = 0usize;
        for _ in 0..reps {
            for f in &frames {
                if let Ok(p) = estimate_board_pose(&cam, black_box(f), &config) {
                    iterations += p.iterations;
                    solved += 1;
                }
            }
        }
        let us = start.elapsed().as_secs_f64() * 1e6 / (reps * frames.len()) as f64;
        println!(
            "| {} | {} | {:.1} | {:.1} |",
            cols * rows,
            frames[0].len(),
            us,
            iterations as f64 / solved.max(1) as f64
        );
    }

    // One calibration: 20 views of a 9×7 board.
    let board = TagGridBoard {
        cols: 9,
        rows: 7,
        tag_size_m: 0.05,
        pitch_m: 0.07,
        first_id: 0,
    };
    let views: Vec<Vec<(nalgebra::Point3<f64>, Point2<f64>)>> = (0..20)
        .map(|_| {
            let mut f = frame(&board, &mut rng);
            f.retain(|c| cam.contains_pixel(c.pixel));
            f.iter()
                .map(|c| (c.point_board_m, Point2::new(c.pixel[0], c.pixel[1])))
                .collect()
        })
        .collect();
    let start = Instant::now();
    let reps = 5;
    let mut rms = 0.0;
    for _ in 0..reps {
        rms = calibrate(
            black_box(&views),
            (cam.width, cam.height),
            &CalibConfig::default(),
        )
        .map(|c| c.rms_px)
        .unwrap_or(f64::NAN);
    }
    let points: usize = views.iter().map(Vec::len).sum();
    println!(
        "\ncalibration, 20 views / {points} points: {:.2} ms per run (RMS {rms:.3} px)",
        start.elapsed().as_secs_f64() * 1e3 / reps as f64
    );
}
