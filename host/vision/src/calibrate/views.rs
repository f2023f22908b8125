//! Calibration views from raw board frames: detect tags on a frame's detection image and keep
//! the corners of the one board with the most corners (Zhang needs one plane per view), as
//! `(point_board_m, pixel)` pairs ready for [`super::calibrate`].
//!
//! Contract: pixels are raw-image pixels in the integer-centre convention (the detector's 0.5 px
//! shift and the superpixel→raw mapping of [`crate::track::detect_frame`] applied); board points
//! come from the board's corner table (z = 0 for a flat board). A frame where nothing is detected
//! yields an empty view (calibration sets it aside with a reason) — never an error, because one
//! unreadable frame must not stop a calibration.

use nalgebra::{Point2, Point3};

use crate::pose::{BoardCorners, assemble_correspondences};
use crate::track::{DetectImage, FamilyDetectors, TrackRejection, TrackedBoard};
use ellipso_polar::frame::RawFrame;

/// One calibration view: board point (m) ↔ observed pixel.
pub type View = Vec<(Point3<f64>, Point2<f64>)>;

/// The view of one frame: the corners of the board with the most detected corners, and that
/// board's index (`None` when no tag of any board was seen).
pub fn board_view(
    detectors: &mut FamilyDetectors,
    frame: &RawFrame,
    boards: &[TrackedBoard],
    image: DetectImage,
) -> Result<(View, Option<usize>), TrackRejection> {
    let detections = detectors.detect(frame, image)?;
    let best = boards
        .iter()
        .enumerate()
        .map(|(i, b)| {
            (
                i,
                assemble_correspondences(
                    &detectors.of_board(&detections, i),
                    b as &dyn BoardCorners,
                )
                .correspondences,
            )
        })
        .filter(|(_, c)| !c.is_empty())
        .max_by_key(|(_, c)| c.len());
    Ok(match best {
        None => (Vec::new(), None),
        Some((i, corr)) => (
            corr.into_iter()
                .map(|c| (c.point_board_m, Point2::new(c.pixel[0], c.pixel[1])))
                .collect(),
            Some(i),
        ),
    })
}
