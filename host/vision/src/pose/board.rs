//! Board geometry as the pose estimator needs it, and correspondence assembly: detections of one
//! frame + a board → every corner of every tag of that board as a [`Correspondence`].
//!
//! [`BoardCorners`] is the minimal interface; the scene crate's board type implements it when it
//! is wired in. [`TagGridBoard`] is a regular grid used by tests, benchmarks and calibration
//! targets.
//!
//! Corner order contract: `corners_board_m(id)[k]` is the board point the detector reports as
//! corner k (see [`super::detect`]): for a tag printed upright, 0 = bottom-left, 1 = bottom-right,
//! 2 = top-right, 3 = top-left — counter-clockwise seen from the front of the board.

use std::collections::BTreeMap;

use nalgebra::Point3;

use super::detect::TagDetection;
use super::estimate::Correspondence;

/// A rigid board of tags with known corner positions.
pub trait BoardCorners {
    /// The four corners of tag `tag_id` in the board frame (m), in detector corner order; `None`
    /// when the tag is not on this board.
    fn corners_board_m(&self, tag_id: u32) -> Option<[Point3<f64>; 4]>;
}

/// A regular grid of square tags on the plane z = 0.
///
/// Board frame: origin at the grid centre, x to the right and y up on the printed board (tag
/// images upright), z out of the board toward the viewer (right-handed). Tag ids run row by row
/// from the top-left tag: `id = first_id + row·cols + col`, row 0 at the top (largest y).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TagGridBoard {
    /// Tags per row.
    pub cols: u32,
    /// Rows of tags.
    pub rows: u32,
    /// Edge length of a tag's black border square, m (the corners AprilTag reports).
    pub tag_size_m: f64,
    /// Centre-to-centre distance of neighbouring tags, m.
    pub pitch_m: f64,
    /// Id of the top-left tag.
    pub first_id: u32,
}

impl TagGridBoard {
    /// Centre of tag (row, col) in the board frame.
    fn tag_centre(&self, row: u32, col: u32) -> [f64; 2] {
        let x = (f64::from(col) - f64::from(self.cols - 1) / 2.0) * self.pitch_m;
        let y = (f64::from(self.rows - 1) / 2.0 - f64::from(row)) * self.pitch_m;
        [x, y]
    }

    /// Ids of all tags on the board.
    pub fn tag_ids(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.rows * self.cols).map(move |k| self.first_id + k)
    }
}

impl BoardCorners for TagGridBoard {
    fn corners_board_m(&self, tag_id: u32) -> Option<[Point3<f64>; 4]> {
        let k = tag_id.checked_sub(self.first_id)?;
        if k >= self.rows * self.cols {
            return None;
        }
        let [cx, cy] = self.tag_centre(k / self.cols, k % self.cols);
        let h = self.tag_size_m / 2.0;
        Some([
            Point3::new(cx - h, cy - h, 0.0),
            Point3::new(cx + h, cy - h, 0.0),
            Point3::new(cx + h, cy + h, 0.0),
            Point3::new(cx - h, cy + h, 0.0),
        ])
    }
}

/// Correspondences of one board in one frame, plus what was left out and why.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Assembly {
    /// Four per usable detection, in detection order.
    pub correspondences: Vec<Correspondence>,
    /// Detected ids that are not on this board (other boards, or false positives).
    pub foreign_ids: Vec<u32>,
    /// Ids detected more than once in the frame: all their detections are dropped, because at
    /// most one can be the board's tag and we cannot tell which.
    pub duplicate_ids: Vec<u32>,
}

/// Gathers all corners of all detected tags of `board`.
pub fn assemble_correspondences(detections: &[TagDetection], board: &dyn BoardCorners) -> Assembly {
    let mut count: BTreeMap<u32, usize> = BTreeMap::new();
    for d in detections {
        *count.entry(d.id).or_default() += 1;
    }
    let mut out = Assembly {
        duplicate_ids: count
            .iter()
            .filter(|(_, n)| **n > 1)
            .map(|(id, _)| *id)
            .collect(),
        ..Assembly::default()
    };
    for d in detections {
        if count[&d.id] > 1 {
            continue;
        }
        let Some(corners) = board.corners_board_m(d.id) else {
            out.foreign_ids.push(d.id);
            continue;
        };
        for (k, (point_board_m, pixel)) in corners.iter().zip(d.corners_px).enumerate() {
            out.correspondences.push(Correspondence {
                tag_id: d.id,
                corner: k as u8,
                point_board_m: *point_board_m,
                pixel,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::detect::TagFamily;

    fn detection(id: u32) -> TagDetection {
        TagDetection {
            family: TagFamily::Tag36h11,
            id,
            hamming: 0,
            decision_margin: 100.0,
            corners_px: [[0.0, 10.0], [10.0, 10.0], [10.0, 0.0], [0.0, 0.0]],
            centre_px: [5.0, 5.0],
        }
    }

    #[test]
    fn grid_layout_and_corner_order() {
        let b = TagGridBoard {
            cols: 3,
            rows: 2,
            tag_size_m: 0.04,
            pitch_m: 0.05,
            first_id: 10,
        };
        let top_left = b.corners_board_m(10).unwrap();
        // Corner 0 bottom-left, counter-clockwise seen from +z.
        assert!((top_left[0].x - (-0.07)).abs() < 1e-12 && (top_left[0].y - 0.005).abs() < 1e-12);
        let e1 = top_left[1] - top_left[0];
        let e2 = top_left[2] - top_left[1];
        assert!(e1.cross(&e2).z > 0.0);
        assert!(b.corners_board_m(9).is_none() && b.corners_board_m(16).is_none());
        assert_eq!(b.tag_ids().count(), 6);
    }

    #[test]
    fn assembly_drops_foreign_and_duplicate_tags() {
        let b = TagGridBoard {
            cols: 2,
            rows: 2,
            tag_size_m: 0.04,
            pitch_m: 0.05,
            first_id: 0,
        };
        let dets = [
            detection(0),
            detection(3),
            detection(7),
            detection(2),
            detection(2),
        ];
        let a = assemble_correspondences(&dets, &b);
        assert_eq!(a.correspondences.len(), 8);
        assert_eq!(a.foreign_ids, vec![7]);
        assert_eq!(a.duplicate_ids, vec![2]);
        assert_eq!(a.correspondences[5].tag_id, 3);
        assert_eq!(a.correspondences[5].corner, 1);
        assert_eq!(
            a.correspondences[5].point_board_m,
            b.corners_board_m(3).unwrap()[1]
        );
    }
}
