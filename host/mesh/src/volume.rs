//! The carving volume: which board the object stands on, its plane, its footprint, and the box
//! above it that the voxel grid fills.
//!
//! Contract:
//! - The object stands on the board with the largest tag footprint (the base board; an upright
//!   side board has a smaller one in the shipped scenes). Its frame is the **volume frame**:
//!   the board plane is z = 0 and z grows toward the cameras (a board whose print faces its
//!   own −z is turned over, decided by the median camera height), so "above the board" is
//!   z > 0 whatever the board file's axes.
//! - The footprint is the bounding rectangle of the board's tag corners. The box is the
//!   footprint × `[0, H]` with `H` the footprint's shorter side, capped at half the height of
//!   the lowest cameras (10th percentile): a ray can only carve a voxel if it goes on down to
//!   the board near the footprint, so space as high as the cameras cannot be carved from them.
//!   The box is everything the carving ever looks at, so its size bounds the memory (see
//!   `docs/mesh.md`).
//! - Rays meet the plane only going down (toward −z in the volume frame); a ray parallel to
//!   the plane or going up never meets it.

use nalgebra::{Isometry3, Point3, Rotation3, UnitQuaternion, Vector3};

use ellipso_vision::track::TrackedBoard;

/// The board the object stands on and the box above it.
#[derive(Clone, Debug, PartialEq)]
pub struct Volume {
    /// Index of the board in the session's `boards`.
    pub board: usize,
    /// Its name, when recorded.
    pub board_name: Option<String>,
    /// Volume frame → world frame.
    pub world_from_volume: Isometry3<f64>,
    /// Lower corner of the box, volume frame, metres (z = 0: the board plane).
    pub min_m: Point3<f64>,
    /// Upper corner of the box, volume frame, metres.
    pub max_m: Point3<f64>,
}

/// Why no volume can be set up.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VolumeError {
    /// No board has a tag.
    #[error("no AprilTag board with tags is recorded in the session")]
    NoBoard,
    /// The cameras are not above the board.
    #[error(
        "board {board}: cameras {height_m:.3} m above its plane (median, or 10th percentile); \
         they must look down on the board from one side"
    )]
    CamerasNotAbove {
        /// Board index.
        board: usize,
        /// Camera height (median, or 10th percentile), metres.
        height_m: f64,
    },
}

/// The footprint area of a board's tag corners (board frame x–y), m².
fn footprint(board: &TrackedBoard) -> Option<([f64; 2], [f64; 2])> {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for corner in board.corners_board_m.values().flatten() {
        for a in 0..2 {
            lo[a] = lo[a].min(corner[a]);
            hi[a] = hi[a].max(corner[a]);
        }
    }
    (lo[0] < hi[0] && lo[1] < hi[1]).then_some((lo, hi))
}

impl Volume {
    /// The volume of the base board among `boards`, seen by cameras at `world_from_cameras`.
    pub fn new(
        boards: &[TrackedBoard],
        world_from_cameras: &[Isometry3<f64>],
    ) -> Result<Volume, VolumeError> {
        let (board, (lo, hi)) = boards
            .iter()
            .enumerate()
            .filter_map(|(i, b)| footprint(b).map(|f| (i, f)))
            .max_by(|(_, a), (_, b)| {
                let area = |f: &([f64; 2], [f64; 2])| (f.1[0] - f.0[0]) * (f.1[1] - f.0[1]);
                area(a).total_cmp(&area(b))
            })
            .ok_or(VolumeError::NoBoard)?;
        let world_from_board = boards[board].world_from_board();
        let mut heights: Vec<f64> = world_from_cameras
            .iter()
            .map(|c| (world_from_board.inverse() * c).translation.vector.z)
            .collect();
        let median = ellipso_report::percentile(&mut heights, 0.5);
        let low = ellipso_report::percentile(&mut heights, 0.1);
        // Turned over (x kept, y and z flipped) when the cameras are on the board's −z side.
        let (world_from_volume, lo, hi, median, low) = if median < 0.0 {
            let flip = Isometry3::from_parts(
                nalgebra::Translation3::identity(),
                UnitQuaternion::from_rotation_matrix(&Rotation3::from_axis_angle(
                    &Vector3::x_axis(),
                    std::f64::consts::PI,
                )),
            );
            (
                world_from_board * flip,
                [lo[0], -hi[1]],
                [hi[0], -lo[1]],
                -median,
                -ellipso_report::percentile(&mut heights, 0.9),
            )
        } else {
            (world_from_board, lo, hi, median, low)
        };
        if median.is_nan() || median <= 0.0 {
            return Err(VolumeError::CamerasNotAbove {
                board,
                height_m: median,
            });
        }
        let height = (hi[0] - lo[0]).min(hi[1] - lo[1]).min(0.5 * low.max(0.0));
        if height.is_nan() || height <= 0.0 {
            return Err(VolumeError::CamerasNotAbove {
                board,
                height_m: low,
            });
        }
        Ok(Volume {
            board,
            board_name: boards[board].name.clone(),
            world_from_volume,
            min_m: Point3::new(lo[0], lo[1], 0.0),
            max_m: Point3::new(hi[0], hi[1], height),
        })
    }

    /// The eight corners of the box, volume frame.
    pub fn corners(&self) -> [Point3<f64>; 8] {
        let (a, b) = (self.min_m, self.max_m);
        std::array::from_fn(|i| {
            Point3::new(
                if i & 1 == 0 { a.x } else { b.x },
                if i & 2 == 0 { a.y } else { b.y },
                if i & 4 == 0 { a.z } else { b.z },
            )
        })
    }
}

/// Where a ray from `origin` along `direction` (volume frame) meets the board plane z = 0, if
/// it goes down toward it (`direction.z < 0`) from above (`origin.z > 0`).
pub fn plane_hit(origin: &Point3<f64>, direction: &Vector3<f64>) -> Option<[f64; 2]> {
    // direction.z < 0 strictly, so the division is finite; origin above gives t > 0.
    if !(direction.z < 0.0 && origin.z > 0.0) {
        return None;
    }
    let t = -origin.z / direction.z;
    Some([origin.x + t * direction.x, origin.y + t * direction.y])
}
