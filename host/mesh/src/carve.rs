//! Carving with votes: a voxel grid over the volume, and per node the robust signed distance
//! to the visual hull, built one view at a time.
//!
//! Contract:
//! - Each view gives every node it sees (projects inside the image) a signed distance in
//!   metres: its silhouette's signed pixel distance (`silhouette::SignedDistance`) at the
//!   node's projection, times depth over the focal length in superpixels, truncated to
//!   `±truncation_m`. Positive: the node's pixel shows the board, so the ray through the node
//!   passes no object — the view votes to carve it.
//! - A node's field value is the **k-th largest** of its views' values (`votes` = k): a node is
//!   carved only when at least k views see the board through it, so up to k − 1 wrong pixels
//!   at one place punch no hole, while the zero crossing stays where the k-th best view's
//!   silhouette puts it (the hull moves outward by the angle between the k best tangent views,
//!   a few hundredths of a millimetre with 100+ views; docs/mesh.md). With k = 1 this is the
//!   classic visual hull's distance bound.
//! - Nodes seen by fewer than k views cannot be carved by votes; they are reported and counted
//!   as outside (carved), so a poorly covered corner of the box never becomes an object. So
//!   are nodes that are not carved but that fewer than k views, or fewer than half of the views
//!   that see them, see *something other than the board* through (pixels that disagree with a
//!   learned texel): where views show unknown board (beyond the learned region, blurred tag
//!   edges), there is no evidence of an object either. Views that see only the print of a tag
//!   through a node (`crate::print`: ink and paper mixed below a pixel) do not count towards
//!   that half. This rule runs on the coarse grid only.
//! - Views stream past: only the k largest values per node are kept (`k × 4` bytes per node),
//!   updated in parallel over nodes in view order, so results do not depend on the thread count.

use ellipso_model::camera::CameraModel;
use nalgebra::Point3;
use rayon::prelude::*;

use super::frames::{RayTable, View};
use super::silhouette::{Crop, SignedDistance, Silhouette};

/// A regular grid of nodes in the volume frame.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Grid {
    /// Position of node (0, 0, 0), metres.
    pub origin_m: [f64; 3],
    /// Node spacing, metres.
    pub spacing_m: f64,
    /// Nodes along x, y, z.
    pub n: [usize; 3],
}

impl Grid {
    /// A grid covering `[lo, hi]` with spacing `spacing_m` (at least 2 nodes per axis).
    pub fn covering(lo: Point3<f64>, hi: Point3<f64>, spacing_m: f64) -> Self {
        let n = std::array::from_fn(|a| (((hi[a] - lo[a]) / spacing_m).ceil() as usize + 1).max(2));
        Grid {
            origin_m: [lo.x, lo.y, lo.z],
            spacing_m,
            n,
        }
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.n[0] * self.n[1] * self.n[2]
    }

    /// The grid as the fit's hull constraint describes it (same layout).
    pub fn geometry(&self) -> ellipso_fit::shape::hull::GridGeometry {
        ellipso_fit::shape::hull::GridGeometry {
            origin_m: self.origin_m,
            spacing_m: self.spacing_m,
            n: self.n,
        }
    }

    /// True for a grid without nodes.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Linear index of node `(i, j, k)`.
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        (k * self.n[1] + j) * self.n[0] + i
    }

    /// `(i, j, k)` of a linear index.
    pub fn ijk(&self, index: usize) -> [usize; 3] {
        let i = index % self.n[0];
        let j = (index / self.n[0]) % self.n[1];
        [i, j, index / (self.n[0] * self.n[1])]
    }

    /// Position of node `(i, j, k)`.
    pub fn point(&self, ijk: [usize; 3]) -> Point3<f64> {
        Point3::new(
            self.origin_m[0] + ijk[0] as f64 * self.spacing_m,
            self.origin_m[1] + ijk[1] as f64 * self.spacing_m,
            self.origin_m[2] + ijk[2] as f64 * self.spacing_m,
        )
    }

    /// The upper corner.
    pub fn max_point(&self) -> Point3<f64> {
        self.point([self.n[0] - 1, self.n[1] - 1, self.n[2] - 1])
    }
}

/// The k largest values seen per node.
pub struct TopK {
    k: usize,
    values: Vec<f32>,
    seen: Vec<u16>,
    solid: Vec<u16>,
    /// Views in which the node projects onto an ambiguous print pixel ([`crate::print`]).
    print: Vec<u16>,
}

impl TopK {
    /// Empty for `nodes` nodes.
    pub fn new(nodes: usize, k: usize) -> Self {
        let k = k.max(1);
        Self {
            k,
            values: vec![f32::NEG_INFINITY; nodes * k],
            seen: vec![0; nodes],
            solid: vec![0; nodes],
            print: vec![0; nodes],
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.values.len() * 4 + self.seen.len() * 6
    }

    /// Views in which a node projects onto a pixel that disagrees with the board.
    pub fn solid(&self, node: usize) -> usize {
        self.solid[node] as usize
    }

    /// The k-th largest value of a node, `None` when fewer than k views saw it.
    pub fn kth(&self, node: usize) -> Option<f32> {
        (self.seen[node] as usize >= self.k).then(|| self.values[node * self.k + self.k - 1])
    }

    /// Views that saw a node.
    pub fn seen(&self, node: usize) -> usize {
        self.seen[node] as usize
    }

    /// Whether a node that is not carved has evidence of an object: at least k views, and
    /// at least half of the views that could judge it (those that saw it, less those that saw
    /// only the print of a tag through it), see something other than the board through it.
    pub fn has_evidence(&self, node: usize) -> bool {
        let judging = self.seen[node].saturating_sub(self.print[node]) as usize;
        self.solid(node) >= self.k.max(judging / 2)
    }
}

fn push(top: &mut [f32], seen: &mut u16, v: f32) {
    *seen = seen.saturating_add(1);
    let k = top.len();
    if v <= top[k - 1] {
        return;
    }
    let mut i = k - 1;
    while i > 0 && top[i - 1] < v {
        top[i] = top[i - 1];
        i -= 1;
    }
    top[i] = v;
}

/// One view ready to vote: its geometry and the signed distance over the part of its image the
/// grid projects to.
pub struct Voter {
    /// The view.
    pub view: View,
    /// Signed distance over the crop.
    pub distance: SignedDistance,
}

/// The crop of a view's image that holds the projection of the box `[lo, hi]`, widened by
/// `margin_px`; `None` when the box is not in front of the camera.
pub fn crop_of(
    camera: &CameraModel,
    rays: &RayTable,
    view: &View,
    lo: Point3<f64>,
    hi: Point3<f64>,
    margin_px: f64,
) -> Option<Crop> {
    let mut min = [f64::INFINITY; 2];
    let mut max = [f64::NEG_INFINITY; 2];
    // corners and edge midpoints: distortion bends the box's edges
    for ix in 0..3 {
        for iy in 0..3 {
            for iz in 0..3 {
                let f = |a: f64, b: f64, t: usize| a + (b - a) * t as f64 / 2.0;
                let p = Point3::new(f(lo.x, hi.x, ix), f(lo.y, hi.y, iy), f(lo.z, hi.z, iz));
                let c = view.camera_from_volume * p;
                let Some(raw) = camera.project(&c) else {
                    continue;
                };
                let [u, v] = rays.to_superpixel(raw);
                min = [min[0].min(u), min[1].min(v)];
                max = [max[0].max(u), max[1].max(v)];
            }
        }
    }
    if !min[0].is_finite() {
        return None;
    }
    let x0 = ((min[0] - margin_px).floor() as isize).max(-1);
    let y0 = ((min[1] - margin_px).floor() as isize).max(-1);
    let x1 = ((max[0] + margin_px).ceil() as isize).min(rays.width as isize + 1);
    let y1 = ((max[1] + margin_px).ceil() as isize).min(rays.height as isize + 1);
    (x1 - x0 >= 2 && y1 - y0 >= 2).then(|| Crop {
        x0,
        y0,
        width: (x1 - x0) as usize,
        height: (y1 - y0) as usize,
    })
}

/// A view's voter over the box `[lo, hi]` with a margin for `truncation_m`.
pub fn voter(
    camera: &CameraModel,
    rays: &RayTable,
    view: View,
    silhouette: &Silhouette,
    [lo, hi]: [Point3<f64>; 2],
    truncation_m: f64,
    edge_inset_px: f64,
) -> Option<Voter> {
    let f_sp = camera.intrinsics.fx.max(camera.intrinsics.fy) / rays.tile as f64;
    // the nearest the box gets to the camera bounds the truncation in pixels
    let near = (view.centre - nalgebra::center(&lo, &hi)).norm().max(1e-3);
    let margin = (truncation_m * f_sp / near).clamp(4.0, 256.0) + 2.0;
    let crop = crop_of(camera, rays, &view, lo, hi, margin)?;
    Some(Voter {
        distance: SignedDistance::new(silhouette, crop, edge_inset_px as f32),
        view,
    })
}

/// Adds the votes of `voters` (in order) for the nodes `active` (all nodes when `None`).
pub fn vote(
    grid: &Grid,
    camera: &CameraModel,
    rays: &RayTable,
    voters: &[Voter],
    active: Option<&[bool]>,
    truncation_m: f64,
    top: &mut TopK,
) {
    let k = top.k;
    let f_sp = camera.intrinsics.fx.max(camera.intrinsics.fy) / rays.tile as f64;
    let tau = truncation_m as f32;
    let chunk = 4096;
    top.values
        .par_chunks_mut(chunk * k)
        .zip(top.seen.par_chunks_mut(chunk))
        .zip(top.solid.par_chunks_mut(chunk))
        .zip(top.print.par_chunks_mut(chunk))
        .enumerate()
        .for_each(|(c, (((values, seen), solid), print))| {
            for (o, ((seen, solid), print)) in seen
                .iter_mut()
                .zip(solid.iter_mut())
                .zip(print.iter_mut())
                .enumerate()
            {
                let node = c * chunk + o;
                if active.is_some_and(|a| !a[node]) {
                    continue;
                }
                let p = grid.point(grid.ijk(node));
                for voter in voters {
                    let pc = voter.view.camera_from_volume * p;
                    let Some(raw) = camera.project(&pc) else {
                        continue;
                    };
                    if !camera.contains_pixel(raw) {
                        continue;
                    }
                    let [u, v] = rays.to_superpixel(raw);
                    let Some(s) = voter.distance.sample(u, v) else {
                        continue;
                    };
                    if voter.distance.disagrees_at(u, v) {
                        *solid = solid.saturating_add(1);
                    } else if voter.distance.print_at(u, v) {
                        *print = print.saturating_add(1);
                    }
                    let metres = (f64::from(s) * pc.z / f_sp) as f32;
                    push(
                        &mut values[o * k..(o + 1) * k],
                        seen,
                        metres.clamp(-tau, tau),
                    );
                }
            }
        });
}

/// The field of a carving: per node the k-th largest vote; `+truncation` where fewer than k
/// views saw it, or where it is not carved but fewer than k views — and fewer than half of
/// those that saw it — saw something other than the board through it (no evidence of an
/// object: the region beyond the learned board, residue at tag edges); and how many such nodes
/// there were.
pub fn field(top: &TopK, truncation_m: f64) -> (Vec<f32>, usize) {
    let mut unseen = 0;
    let values = (0..top.seen.len())
        .map(|n| match top.kth(n) {
            Some(v) if v >= 0.0 || top.has_evidence(n) => v,
            _ => {
                unseen += 1;
                truncation_m as f32
            }
        })
        .collect();
    (values, unseen)
}

/// Per node: not carved, yet without evidence of an object (the nodes [`field`] sets to
/// `+truncation` although no k views saw the board through them): space no view could judge.
pub fn unjudged(top: &TopK) -> Vec<bool> {
    (0..top.seen.len())
        .map(|n| match top.kth(n) {
            Some(v) => v < 0.0 && !top.has_evidence(n),
            None => true,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn top_k_keeps_the_k_largest_in_order() {
        let mut top = [f32::NEG_INFINITY; 3];
        let mut seen = 0;
        for v in [0.5, -1.0, 2.0, 0.7, 0.1, 3.0] {
            push(&mut top, &mut seen, v);
        }
        assert_eq!(top, [3.0, 2.0, 0.7]);
        assert_eq!(seen, 6);
    }

    #[test]
    fn grid_indices_round_trip() {
        let g = Grid::covering(
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.1, 0.05, 0.02),
            0.01,
        );
        assert_eq!(g.n, [11, 6, 3]);
        for n in [0, 17, g.len() - 1] {
            assert_eq!(g.index(g.ijk(n)[0], g.ijk(n)[1], g.ijk(n)[2]), n);
        }
        assert!((g.max_point() - Point3::new(0.1, 0.05, 0.02)).norm() < 1e-12);
    }
}
