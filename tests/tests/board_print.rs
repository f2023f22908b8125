//! A printed board tracks like the built-in one: `ellipso board print` rasterises the shipped
//! base board (PNG at 300 dpi, the same drawing the PDF and SVG carry), the PNG becomes the
//! simulated board's texture (`Board::with_texture`, what the renderer reads for every ray that
//! hits the sheet), and the same camera views of both boards are rendered, detected and posed
//! with the tracker's detector and joint PnP. Printed and built-in poses must agree within
//! 0.05° and 0.2 mm (median over the views); both are also compared with the truth.
//!
//! The PDF itself is not rasterised here (no PDF rasteriser among our dependencies); it is
//! written from the same drawing list as the PNG, which `ellipso-report`'s unit tests check at
//! cell level against the board's own cells.

use std::path::{Path, PathBuf};
use std::process::Command;

use ellipso_model::camera::{CameraModel, Distortion, Intrinsics};
use ellipso_model::geometry::Ray;
use ellipso_model::tags::{Board, SheetTexture};
use ellipso_tests::ellipso_bin;
use ellipso_vision::pose::board::{BoardCorners, assemble_correspondences};
use ellipso_vision::pose::detect::{DetectorConfig, TagDetector};
use ellipso_vision::pose::estimate::{PoseConfig, estimate_board_pose};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

struct Corners<'a>(&'a Board);

impl BoardCorners for Corners<'_> {
    fn corners_board_m(&self, tag_id: u32) -> Option<[Point3<f64>; 4]> {
        self.0.tag_corners_board_m(tag_id)
    }
}

fn shipped_board(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../sim/boards")
        .join(name)
}

fn ellipso(args: &[&str]) -> std::process::Output {
    Command::new(ellipso_bin())
        .args(args)
        .output()
        .expect("run ellipso")
}

fn camera() -> CameraModel {
    CameraModel {
        width: 1280,
        height: 1024,
        intrinsics: Intrinsics {
            fx: 1500.0,
            fy: 1500.0,
            cx: 639.5,
            cy: 511.5,
        },
        distortion: Distortion::default(),
    }
}

/// `camera_from_board` for a camera `distance_m` from the board point `target`, its line of
/// sight tilted `tilt_deg` from the board's front normal towards azimuth `azimuth_deg`.
fn view(
    board: &Board,
    target: Point3<f64>,
    distance_m: f64,
    tilt_deg: f64,
    azimuth_deg: f64,
) -> Isometry3<f64> {
    let n = board.front_normal_board().into_inner();
    let (t, a) = (tilt_deg.to_radians(), azimuth_deg.to_radians());
    // an in-plane basis of the board
    let u = Vector3::x();
    let v = n.cross(&u);
    let dir = n * t.cos() + (u * a.cos() + v * a.sin()) * t.sin();
    let eye = target + dir * distance_m;
    let z = -dir; // camera looks at the target
    let x = v.cross(&z).normalize();
    let y = z.cross(&x);
    let board_from_camera = Isometry3::from_parts(
        Translation3::from(eye.coords),
        // exact: `from_matrix` iterates from the identity and stalls on a 180° turn
        UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(
            nalgebra::Matrix3::from_columns(&[x, y, z]),
        )),
    );
    board_from_camera.inverse()
}

/// Renders the board as the simulator's board does (its albedo at every ray hit), 3 × 3
/// samples per pixel, gray = albedo on a background of 0.3.
fn render(board: &Board, cam: &CameraModel, camera_from_board: &Isometry3<f64>) -> Vec<u8> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let k = &cam.intrinsics;
    let board_from_camera = camera_from_board.inverse();
    let origin = board_from_camera * Point3::origin();
    let ss = 3;
    let rows: Vec<Vec<u8>> = std::thread::scope(|s| {
        let chunks: Vec<_> = (0..2)
            .map(|part| {
                s.spawn(move || {
                    (0..h)
                        .filter(|v| v % 2 == part)
                        .map(|v| {
                            (0..w)
                                .map(|u| {
                                    let mut acc = 0.0;
                                    for sy in 0..ss {
                                        for sx in 0..ss {
                                            let x = u as f64 - 0.5 + (sx as f64 + 0.5) / ss as f64;
                                            let y = v as f64 - 0.5 + (sy as f64 + 0.5) / ss as f64;
                                            let d = Vector3::new(
                                                (x - k.cx) / k.fx,
                                                (y - k.cy) / k.fy,
                                                1.0,
                                            );
                                            let ray = Ray::new(origin, board_from_camera * d);
                                            acc += board
                                                .intersect(&ray, 0.0, 10.0)
                                                .map_or(0.3, |hit| f64::from(hit.albedo));
                                        }
                                    }
                                    (acc / (ss * ss) as f64 * 255.0).round() as u8
                                })
                                .collect::<Vec<u8>>()
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        let parts: Vec<Vec<Vec<u8>>> = chunks
            .into_iter()
            .map(|c| c.join().expect("render thread"))
            .collect();
        (0..h).map(|v| parts[v % 2][v / 2].clone()).collect()
    });
    rows.concat()
}

/// Rotation angle between two poses, degrees, and distance between their board origins, mm.
fn difference(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let rot = (a.rotation.inverse() * b.rotation).angle().to_degrees();
    let trans = (a.translation.vector - b.translation.vector).norm() * 1e3;
    (rot, trans)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn track(board: &Board, gray: &[u8], cam: &CameraModel) -> Isometry3<f64> {
    // the shipped base board is tag36h11, the detector's default family
    assert_eq!(board.family.name(), "tag36h11");
    let mut detector = TagDetector::new(DetectorConfig::default()).expect("detector");
    let detections = detector
        .detect(gray, cam.width as usize, cam.height as usize)
        .expect("detect");
    if detections.is_empty() {
        let _ = image::save_buffer(
            std::env::temp_dir().join("ellipso-board-print-view.png"),
            gray,
            cam.width,
            cam.height,
            image::ExtendedColorType::L8,
        );
    }
    let assembly = assemble_correspondences(&detections, &Corners(board));
    estimate_board_pose(cam, &assembly.correspondences, &PoseConfig::default())
        .expect("pose")
        .camera_from_board
}

fn print_png(board_file: &Path, out: &Path) {
    let o = ellipso(&[
        "board",
        "print",
        board_file.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
        "--dpi",
        "300",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn printed_board_tracks_like_the_built_in_board() {
    let dir = tempfile::tempdir().expect("tempdir");
    let board_file = shipped_board("base_a4.toml");
    let png = dir.path().join("base_a4.png");
    print_png(&board_file, &png);
    let built_in = ellipso_sim::scene::load_board_file(&board_file).expect("board");
    let img = image::open(&png).expect("printed PNG").to_luma8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    // 297 × 210 mm at 300 dpi
    assert_eq!((w, h), (3508, 2480));
    let texture = SheetTexture::new(w, h, img.into_raw(), built_in.sheet_size_m).expect("texture");
    let printed = built_in.clone().with_texture(texture);
    let cam = camera();
    let centre = Point3::origin(); // base_a4's origin is the sheet centre
    let views: Vec<Isometry3<f64>> = [
        (0.40, 0.0, 0.0),
        (0.38, 20.0, 0.0),
        (0.40, 25.0, 90.0),
        (0.42, 30.0, 200.0),
        (0.36, 35.0, 300.0),
        (0.45, 15.0, 135.0),
        (0.40, 40.0, 45.0),
    ]
    .iter()
    .map(|&(d, tilt, az)| view(&built_in, centre, d, tilt, az))
    .collect();
    let (mut rot, mut trans, mut rot_truth, mut trans_truth) = (vec![], vec![], vec![], vec![]);
    for truth in &views {
        let a = track(&built_in, &render(&built_in, &cam, truth), &cam);
        let b = track(&printed, &render(&printed, &cam, truth), &cam);
        let (r, t) = difference(&a, &b);
        rot.push(r);
        trans.push(t);
        let (r, t) = difference(&b, truth);
        rot_truth.push(r);
        trans_truth.push(t);
    }
    let (rot, trans) = (median(rot), median(trans));
    eprintln!(
        "printed vs built-in board, median over {} views: {rot:.4}° / {trans:.4} mm; printed vs \
         truth: {:.4}° / {:.4} mm",
        views.len(),
        median(rot_truth),
        median(trans_truth)
    );
    assert!(rot < 0.05 && trans < 0.2, "{rot}° / {trans} mm");
}

#[test]
fn board_new_prints_and_a_board_too_big_for_its_paper_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let toml = dir.path().join("a4.toml");
    let o = ellipso(&[
        "board",
        "new",
        "--paper",
        "a4",
        "--landscape",
        "--tag-mm",
        "25",
        "--out",
        toml.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let board = ellipso_sim::scene::load_board_file(&toml).expect("board new writes a valid board");
    assert!(board.tags.len() >= 20, "{}", board.tags.len());
    for ext in ["pdf", "svg", "png"] {
        let out = dir.path().join(format!("a4.{ext}"));
        let o = ellipso(&[
            "board",
            "print",
            toml.to_str().expect("utf-8"),
            "--out",
            out.to_str().expect("utf-8"),
            "--dpi",
            "100",
        ]);
        assert!(
            o.status.success(),
            "{ext}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(std::fs::metadata(&out).expect("written").len() > 1000);
    }
    // a tag bigger than the paper
    let o = ellipso(&[
        "board",
        "new",
        "--paper",
        "a5",
        "--tag-mm",
        "200",
        "--out",
        dir.path().join("big.toml").to_str().expect("utf-8"),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--tag-mm 200") && err.contains("does not fit its paper"),
        "{err}"
    );
    assert!(!dir.path().join("big.toml").exists());
    // the shipped calibration grid fills its A4 sheet: no room for the label and scale bar
    let o = ellipso(&[
        "board",
        "print",
        shipped_board("calib_grid.toml").to_str().expect("utf-8"),
        "--out",
        dir.path().join("grid.pdf").to_str().expect("utf-8"),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("calib_grid.toml") && err.contains("does not fit its paper"),
        "{err}"
    );
    assert!(!dir.path().join("grid.pdf").exists());
}
