//! The tag code of `ellipso_model::tags` against the AprilTag C library (a dev-dependency of
//! this crate only, so the shared core needs no C library): the embedded code tables and the
//! rendered cells against the library's own, and a rendered board detected by the real
//! detector. [`detect`] runs that detector for the scene and renderer tests too.

pub(crate) mod detect;

use ellipso_model::geometry::Ray;
use ellipso_model::tags::{Board, TagFamily};
use ellipso_model::test_support::grid_spec;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// The embedded tables against the C library's `apriltag_family_t`, field by field.
#[test]
fn tables_match_the_c_library() {
    use apriltag_sys as sys;
    for family in TagFamily::ALL {
        let ours = family.code_table();
        // SAFETY: the `*_create` functions return a heap-allocated, fully initialised family
        // (null on allocation failure, asserted); we read `nbits` entries of bit_x/bit_y and
        // `ncodes` codes (the lengths the C code allocated) and free it once with the
        // matching `*_destroy`, its only owner.
        unsafe {
            let (fam, destroy): (*mut sys::apriltag_family_t, unsafe extern "C" fn(_)) =
                match family {
                    TagFamily::Tag36h11 => (sys::tag36h11_create(), sys::tag36h11_destroy),
                    TagFamily::Tag25h9 => (sys::tag25h9_create(), sys::tag25h9_destroy),
                    TagFamily::Tag16h5 => (sys::tag16h5_create(), sys::tag16h5_destroy),
                };
            assert!(!fam.is_null());
            let f = &*fam;
            assert_eq!(
                ours.codes,
                std::slice::from_raw_parts(f.codes, f.ncodes as usize)
            );
            assert_eq!(
                ours.bit_x,
                std::slice::from_raw_parts(f.bit_x, f.nbits as usize)
            );
            assert_eq!(
                ours.bit_y,
                std::slice::from_raw_parts(f.bit_y, f.nbits as usize)
            );
            assert_eq!(ours.nbits, f.nbits);
            assert_eq!(ours.width_at_border, f.width_at_border as u32);
            assert_eq!(ours.total_width, f.total_width as u32);
            assert_eq!(ours.reversed_border, f.reversed_border);
            destroy(fam);
        }
    }
}

/// Our renderer against the C library's `apriltag_to_image`, cell for cell.
#[test]
fn cells_match_apriltag_to_image() {
    use apriltag_sys as sys;
    for family in TagFamily::ALL {
        let table = family.code_table();
        let n = table.len() as u32;
        for id in [0, 1, 7, n / 2, n - 1] {
            let ours = table.cells(id).expect("valid id");
            // SAFETY: create/destroy pairs as in `from_c`; `apriltag_to_image` returns an
            // owned image of total_width² with `stride` bytes per row, freed below.
            let theirs = unsafe {
                let (fam, destroy): (*mut sys::apriltag_family_t, unsafe extern "C" fn(_)) =
                    match family {
                        TagFamily::Tag36h11 => (sys::tag36h11_create(), sys::tag36h11_destroy),
                        TagFamily::Tag25h9 => (sys::tag25h9_create(), sys::tag25h9_destroy),
                        TagFamily::Tag16h5 => (sys::tag16h5_create(), sys::tag16h5_destroy),
                    };
                let im = sys::apriltag_to_image(fam, id as i32);
                let img = &*im;
                assert_eq!(img.width as usize, ours.width);
                let mut cells = Vec::new();
                for row in 0..img.height as usize {
                    for col in 0..img.width as usize {
                        cells.push(*img.buf.add(row * img.stride as usize + col) == 255);
                    }
                }
                sys::image_u8_destroy(im);
                destroy(fam);
                cells
            };
            assert_eq!(ours.white, theirs, "{} id {id}", family.name());
        }
    }
}

/// Pinhole projection of a board-frame point (OpenCV convention, pixel centres at integers).
fn project(camera_from_board: &Isometry3<f64>, f: f64, c: (f64, f64), p: &Point3<f64>) -> [f64; 2] {
    let q = camera_from_board * p;
    [f * q.x / q.z + c.0, f * q.y / q.z + c.1]
}

/// Renders `board` with a pinhole camera 0.35 m in front of the sheet centre, tilted, 3×3
/// supersampled; returns the image and the camera pose and intrinsics used.
fn render_tilted(board: &Board) -> (Vec<u8>, usize, usize, f64, (f64, f64), Isometry3<f64>) {
    let (w, h, f) = (480usize, 400usize, 700.0);
    let c = (w as f64 / 2.0 - 0.5, h as f64 / 2.0 - 0.5);
    // Camera 0.35 m in front of the board centre, tilted 20° about x and 10° about y.
    let centre = Point3::new(
        board.sheet_size_m[0] / 2.0,
        board.sheet_size_m[1] / 2.0,
        0.0,
    );
    let rot = UnitQuaternion::from_euler_angles(0.35, -0.17, 0.1);
    let board_from_camera = Isometry3::from_parts(Translation3::from(centre.coords), rot)
        * Translation3::new(0.0, 0.0, -0.35);
    let mut gray = vec![0u8; w * h];
    let ss = 3;
    for v in 0..h {
        for u in 0..w {
            let mut acc = 0.0;
            for sy in 0..ss {
                for sx in 0..ss {
                    let x = u as f64 - 0.5 + (sx as f64 + 0.5) / ss as f64;
                    let y = v as f64 - 0.5 + (sy as f64 + 0.5) / ss as f64;
                    let dir_cam = Vector3::new((x - c.0) / f, (y - c.1) / f, 1.0);
                    let ray = Ray::new(
                        board_from_camera * Point3::origin(),
                        board_from_camera * dir_cam,
                    );
                    acc += board
                        .intersect(&ray, 0.0, 10.0)
                        .map_or(0.3, |hit| hit.albedo as f64);
                }
            }
            gray[v * w + u] = (acc / (ss * ss) as f64 * 255.0).round() as u8;
        }
    }
    (gray, w, h, f, c, board_from_camera.inverse())
}

/// Renders a tilted 2×2 board per family and detects it with the real detector: right ids,
/// corners within 0.5 px of the projected board corners.
#[test]
fn rendered_boards_are_detected_with_correct_ids_and_corners() {
    for family in TagFamily::ALL {
        let mut spec = grid_spec(2, 2, 0.04, 0.05);
        spec.family = family;
        let board = Board::from_spec(&spec).expect("valid");
        let (gray, w, h, f, c, camera_from_board) = render_tilted(&board);
        let mut found: Vec<u32> = Vec::new();
        for (id, corners) in detect::detect(family, &gray, w, h) {
            found.push(id);
            let truth = board
                .tag_corners_board_m(id)
                .expect("detected id is on the board");
            for (k, got) in corners.iter().enumerate() {
                let want = project(&camera_from_board, f, c, &truth[k]);
                let err = ((got[0] - want[0]).powi(2) + (got[1] - want[1]).powi(2)).sqrt();
                assert!(
                    err < 0.5,
                    "{family:?} tag {id} corner {k}: {got:?} vs {want:?} ({err:.3} px)"
                );
            }
        }
        found.sort_unstable();
        assert_eq!(found, vec![3, 4, 5, 6], "{family:?}");
    }
}
