//! Board tests: corner layout, albedo against the code table, validation, ray hits. (Detection
//! of a rendered board by the real AprilTag detector, and the code tables against the C
//! library, are checked in `ellipso-sim`'s `tag_checks`, where the C library is a dev-dependency.)

use super::*;
use crate::geometry::Ray;
use crate::test_support::grid_spec;
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};

#[test]
fn grid_corners_follow_apriltag_order_and_spacing() {
    let b = Board::from_spec(&grid_spec(3, 2, 0.04, 0.05)).expect("valid");
    assert_eq!(
        b.tags.iter().map(|t| t.id).collect::<Vec<_>>(),
        vec![3, 4, 5, 6, 7, 8]
    );
    let c0 = b.tag_corners_board_m(3).expect("tag 3");
    // First centre: margin + quiet (0.005) + half tag = 0.035.
    let (cx, cy, h) = (0.035, 0.035, 0.02);
    let expect = [
        (cx - h, cy + h),
        (cx + h, cy + h),
        (cx + h, cy - h),
        (cx - h, cy - h),
    ];
    for (c, (x, y)) in c0.iter().zip(expect) {
        assert!(
            (c.x - x).abs() < 1e-12 && (c.y - y).abs() < 1e-12 && c.z == 0.0,
            "{c}"
        );
    }
    // Right neighbour is one spacing along +x, the tag below one spacing along +y.
    let right = b.tag_corners_board_m(4).expect("tag 4");
    let below = b.tag_corners_board_m(6).expect("tag 6");
    for k in 0..4 {
        assert!((right[k] - c0[k] - Vector3::new(0.05, 0.0, 0.0)).norm() < 1e-12);
        assert!((below[k] - c0[k] - Vector3::new(0.0, 0.05, 0.0)).norm() < 1e-12);
    }
    // Default sheet: last tag's outer quiet edge plus margin.
    assert!((b.sheet_size_m[0] - (0.035 + 0.1 + 0.025 + 0.01)).abs() < 1e-12);
    // y-up axes with a centred origin: y flips, the printed face points to +z.
    let mut spec = grid_spec(3, 2, 0.04, 0.05);
    spec.axes = BoardAxes::XRightYUp;
    spec.origin = BoardOrigin::SheetCentre;
    let up = Board::from_spec(&spec).expect("valid");
    let c = up.tag_corners_board_m(3).expect("tag 3");
    let (w, hgt) = (up.sheet_size_m[0], up.sheet_size_m[1]);
    assert!((c[0].x - (cx - h - 0.5 * w)).abs() < 1e-12);
    assert!((c[0].y - -(cy + h - 0.5 * hgt)).abs() < 1e-12);
    assert!((up.front_normal_board().z - 1.0).abs() < 1e-12);
    assert!((b.front_normal_board().z + 1.0).abs() < 1e-12);
}

/// Samples every cell centre of a (possibly rotated) tag and compares with the code table.
#[test]
fn albedo_reproduces_the_code_cells_including_rotation() {
    let table = TagFamily::Tag36h11.code_table();
    for rotation_deg in [0.0, 90.0, 30.0] {
        let mut spec = grid_spec(1, 1, 0.08, 0.2);
        spec.grid = None;
        spec.tags = vec![TagPlacementSpec {
            id: 42,
            centre_m: [0.1, 0.1],
            rotation_deg,
        }];
        let b = Board::from_spec(&spec).expect("valid");
        let cells = table.cells(42).expect("id");
        let cell = 0.08 / 8.0;
        let (s, c) = rotation_deg.to_radians().sin_cos();
        for row in 0..10 {
            for col in 0..10 {
                let local = ((col as f64 - 4.5) * cell, (row as f64 - 4.5) * cell);
                // Tag frame to sheet: rotate clockwise-seen-from-front (x toward y), then shift.
                let p = Point2::new(
                    0.1 + c * local.0 - s * local.1,
                    0.1 + s * local.0 + c * local.1,
                );
                let want = if cells.is_white(col, row) { 0.85 } else { 0.04 };
                assert_eq!(
                    b.albedo_at(&p),
                    want,
                    "rot {rotation_deg} cell ({col},{row})"
                );
            }
        }
        // Well outside the tag: white sheet; off the sheet: white.
        assert_eq!(b.albedo_at(&Point2::new(0.01, 0.19)), 0.85);
        assert_eq!(b.albedo_at(&Point2::new(-1.0, 0.1)), 0.85);
    }
}

#[test]
fn validation_names_the_offending_key() {
    let check = |spec: BoardSpec, key: &str, needle: &str| {
        let e = Board::from_spec(&spec).expect_err("must fail");
        assert_eq!(e.key, key, "{e}");
        assert!(e.message.contains(needle), "{e}");
    };
    check(grid_spec(2, 2, 0.04, 0.044), "grid.spacing_m", "quiet zone");
    check(grid_spec(2, 2, -0.04, 0.05), "tag_size_m", "positive");
    let mut s = grid_spec(2, 2, 0.04, 0.05);
    s.grid.as_mut().expect("grid").first_id = 585;
    check(s, "grid.first_id", "not in tag36h11");
    let mut s = grid_spec(2, 1, 0.04, 0.05);
    s.grid.as_mut().expect("grid").ids = Some(vec![1, 2, 3]);
    check(s, "grid.ids", "3 ids for a 2×1 grid");
    let mut s = grid_spec(2, 1, 0.04, 0.05);
    s.tags = vec![TagPlacementSpec {
        id: 3,
        centre_m: [0.3, 0.3],
        rotation_deg: 0.0,
    }];
    check(s, "tags[0].id", "appears twice");
    let mut s = grid_spec(1, 1, 0.04, 0.05);
    s.tags = vec![TagPlacementSpec {
        id: 9,
        centre_m: [0.06, 0.04],
        rotation_deg: 45.0,
    }];
    check(s, "tags[0].id", "overlaps");
    let mut s = grid_spec(2, 2, 0.04, 0.05);
    s.sheet_size_m = Some([0.1, 0.3]);
    check(s, "grid.first_id", "outside");
    let mut s = grid_spec(1, 1, 0.04, 0.05);
    s.family = TagFamily::Tag16h5;
    s.grid.as_mut().expect("grid").first_id = 30;
    check(s, "grid.first_id", "ids 0..29");
    check(
        grid_spec(100_000, 100_000, 0.04, 0.05),
        "grid.cols",
        "exceed the 587 codes",
    );
    let mut s = grid_spec(2, 1, 0.04, 0.05);
    s.grid.as_mut().expect("grid").first_id = u32::MAX;
    check(s, "grid.first_id", "not in tag36h11");
    let mut s = grid_spec(1, 1, 0.04, 0.05);
    s.black_albedo = 0.9;
    check(s, "black_albedo", "darker");
}

#[test]
fn posed_board_ray_hits_front_back_and_misses_off_sheet() {
    let b = Board::from_spec(&grid_spec(2, 2, 0.04, 0.05)).expect("valid");
    let placed = PlacedBoard {
        board: b,
        world_from_board: Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.3),
            UnitQuaternion::from_euler_angles(0.2, -0.4, 1.0),
        ),
    };
    let target_board = Point3::new(0.035, 0.035, 0.0); // centre of tag 3
    let target = placed.world_from_board * target_board;
    let n = placed.front_normal_world();
    let from_front = Ray::new(target + n.into_inner() * 0.5, -n.into_inner());
    let h = placed.intersect(&from_front, 0.0, 10.0).expect("front hit");
    assert!(h.front && (h.t - 0.5).abs() < 1e-12);
    assert!((h.point_board_m - Point2::new(0.035, 0.035)).norm() < 1e-12);
    let from_back = Ray::new(target - n.into_inner() * 0.5, n.into_inner());
    let h = placed.intersect(&from_back, 0.0, 10.0).expect("back hit");
    assert!(!h.front && h.albedo == 0.85);
    let off = placed.world_from_board * Point3::new(-0.01, 0.02, 0.0);
    assert!(
        placed
            .intersect(&Ray::new(off + n.into_inner(), -n.into_inner()), 0.0, 10.0)
            .is_none()
    );
    let c = placed.tag_corners_world_m(3).expect("tag 3");
    let cb = placed.board.tag_corners_board_m(3).expect("tag 3");
    assert!((c[2] - placed.world_from_board * cb[2]).norm() < 1e-15);
}
