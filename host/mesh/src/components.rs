//! Connected parts of a carved grid: the object is one solid part standing inside the box;
//! anything else is a fault to report or a speck to drop.
//!
//! Contract:
//! - Occupied nodes (field < 0) are grouped 6-connected ([`label`]), largest first; each
//!   [`Part`] knows its size, bounding nodes, centroid and which faces of the box it touches.
//! - [`keep_only`] sets every other occupied node to outside, and fills cavities (outside nodes
//!   not 6-connected to the box's faces) so the surface is one closed shell.

use nalgebra::Point3;

use super::carve::Grid;

/// Faces of the box, in the order `-x, +x, -y, +y, -z, +z`.
pub const FACES: [&str; 6] = ["-x", "+x", "-y", "+y", "bottom", "top"];

/// One connected occupied part.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Part {
    /// Label (index in the list).
    pub label: u32,
    /// Nodes.
    pub nodes: usize,
    /// Lowest node `(i, j, k)`.
    pub min: [usize; 3],
    /// Highest node.
    pub max: [usize; 3],
    /// Centroid, volume frame, metres.
    pub centroid_m: [f64; 3],
    /// Touches face `FACES[f]` of the box.
    pub touches: [bool; 6],
}

impl Part {
    /// Volume, m³ (nodes × spacing³).
    pub fn volume_m3(&self, grid: &Grid) -> f64 {
        self.nodes as f64 * grid.spacing_m.powi(3)
    }
}

fn neighbours(grid: &Grid, n: usize) -> impl Iterator<Item = usize> + '_ {
    let [i, j, k] = grid.ijk(n);
    let [nx, ny, nz] = grid.n;
    [
        (i > 0).then(|| n - 1),
        (i + 1 < nx).then(|| n + 1),
        (j > 0).then(|| n - nx),
        (j + 1 < ny).then(|| n + nx),
        (k > 0).then(|| n - nx * ny),
        (k + 1 < nz).then(|| n + nx * ny),
    ]
    .into_iter()
    .flatten()
}

/// Labels the 6-connected components of `member`; returns per node its label (`u32::MAX` for
/// non-members) and the parts, largest first (labels renumbered in that order).
pub fn label(grid: &Grid, member: &[bool]) -> (Vec<u32>, Vec<Part>) {
    let mut labels = vec![u32::MAX; member.len()];
    let mut parts = Vec::new();
    let mut stack = Vec::new();
    for start in 0..member.len() {
        if !member[start] || labels[start] != u32::MAX {
            continue;
        }
        let label = parts.len() as u32;
        let mut part = Part {
            label,
            nodes: 0,
            min: [usize::MAX; 3],
            max: [0; 3],
            centroid_m: [0.0; 3],
            touches: [false; 6],
        };
        let mut sum = [0.0; 3];
        labels[start] = label;
        stack.push(start);
        while let Some(n) = stack.pop() {
            part.nodes += 1;
            let ijk = grid.ijk(n);
            let p = grid.point(ijk);
            for a in 0..3 {
                part.min[a] = part.min[a].min(ijk[a]);
                part.max[a] = part.max[a].max(ijk[a]);
                sum[a] += p[a];
                part.touches[2 * a] |= ijk[a] == 0;
                part.touches[2 * a + 1] |= ijk[a] + 1 == grid.n[a];
            }
            for m in neighbours(grid, n) {
                if member[m] && labels[m] == u32::MAX {
                    labels[m] = label;
                    stack.push(m);
                }
            }
        }
        part.centroid_m = sum.map(|s| s / part.nodes as f64);
        parts.push(part);
    }
    // largest first; ties by first node (label order)
    let mut order: Vec<usize> = (0..parts.len()).collect();
    order.sort_by_key(|&p| std::cmp::Reverse(parts[p].nodes));
    let mut renumber = vec![0u32; parts.len()];
    for (new, &old) in order.iter().enumerate() {
        renumber[old] = new as u32;
    }
    for l in labels.iter_mut().filter(|l| **l != u32::MAX) {
        *l = renumber[*l as usize];
    }
    let parts = order
        .into_iter()
        .enumerate()
        .map(|(new, old)| Part {
            label: new as u32,
            ..parts[old].clone()
        })
        .collect();
    (labels, parts)
}

/// Keeps only part `keep` of `labels` occupied in `field` (others set to `+outside`), and fills
/// its cavities with `-inside`. Returns (nodes cleared, nodes filled).
pub fn keep_only(
    grid: &Grid,
    field: &mut [f32],
    labels: &[u32],
    keep: u32,
    outside: f32,
    inside: f32,
) -> (usize, usize) {
    let mut cleared = 0;
    for (v, &l) in field.iter_mut().zip(labels) {
        if *v < 0.0 && l != keep {
            *v = outside;
            cleared += 1;
        }
    }
    // outside nodes connected to a face of the box (not the bottom: the board closes it)
    let empty: Vec<bool> = field.iter().map(|v| *v >= 0.0).collect();
    let (empty_labels, empty_parts) = label(grid, &empty);
    let open: Vec<bool> = empty_parts
        .iter()
        .map(|p| p.touches.iter().enumerate().any(|(f, t)| *t && f != 4))
        .collect();
    let mut filled = 0;
    for (v, &l) in field.iter_mut().zip(&empty_labels) {
        if l != u32::MAX && !open[l as usize] {
            *v = inside;
            filled += 1;
        }
    }
    (cleared, filled)
}

/// The part's centroid as a point.
pub fn centroid(part: &Part) -> Point3<f64> {
    Point3::from(part.centroid_m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_blobs_are_two_parts_and_a_cavity_is_filled() {
        let grid = Grid::covering(Point3::origin(), Point3::new(0.011, 0.011, 0.011), 0.001);
        let n = grid.len();
        let mut field = vec![1.0f32; n];
        // a 5³ shell with a hollow centre, and a single node elsewhere
        for k in 1..6 {
            for j in 1..6 {
                for i in 1..6 {
                    if (i, j, k) != (3, 3, 3) {
                        field[grid.index(i, j, k)] = -1.0;
                    }
                }
            }
        }
        field[grid.index(9, 9, 9)] = -1.0;
        let occupied: Vec<bool> = field.iter().map(|v| *v < 0.0).collect();
        let (labels, parts) = label(&grid, &occupied);
        assert_eq!(parts.len(), 2);
        assert_eq!(parts[0].nodes, 124);
        assert_eq!(parts[1].nodes, 1);
        assert!(!parts[0].touches.iter().any(|t| *t));
        let (cleared, filled) = keep_only(&grid, &mut field, &labels, 0, 1.0, -1.0);
        assert_eq!((cleared, filled), (1, 1));
        assert!(field[grid.index(3, 3, 3)] < 0.0);
        assert!(field[grid.index(9, 9, 9)] > 0.0);
    }
}
