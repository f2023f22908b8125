//! One view's evidence: which of its pixels show the board as learned (they see past any
//! object), and the signed distance to the boundary of that set.
//!
//! Contract:
//! - A pixel is *board* when its ray meets a learned texel and agrees with it
//!   (`appearance::Agreement`); where its own texel is unknown, when it agrees with one of the
//!   learned texels around it. A pixel that disagrees, whose texel and neighbours are unknown,
//!   that is saturated or whose ray misses the board plane is *not board*. Only board pixels
//!   carve.
//! - Pixels that disagree are kept as a second mask: a voxel is solid only where views see
//!   something other than the board through it, not merely no board (`carve`). Those that
//!   disagree with a printed texel only as a mixture of its ink and paper would are a third
//!   mask instead, *print* ([`crate::print`]): evidence of neither.
//! - Board islands are made not-board (4-connected): those smaller than `min_island_px`, and
//!   those *enclosed* (not reaching the image border) with less than `max_enclosed_fraction` of
//!   the view's board pixels. Pixels of an object that happen to match the board behind them
//!   (a white object in front of white paper, where its shading and distance happen to equal
//!   the paper's) form patches inside the object's silhouette, ringed by its dark rim; the board
//!   around an object is one large region reaching the image border. The price: board seen
//!   through a small hole in the object (a mug's handle) does not carve.
//! - [`SignedDistance`]: Euclidean distance transform (Felzenszwalb & Huttenlocher, "Distance
//!   Transforms of Sampled Functions", Theory of Computing 8, 2012), exact, in pixels:
//!   `d − ½` to the nearest not-board pixel for board pixels (> 0), `−(d − ½)` to the nearest
//!   board pixel for the others, so the zero crossing lies on the pixel boundary; plus, at the
//!   boundary pixels whose cover was measured, the edge's offset inside them ([`crate::edge`]),
//!   elsewhere the configured edge inset, either moving the crossing into the not-board pixels
//!   (`MeshConfig::edge_inset_px`). Pixels
//!   outside the image or the crop count as not board; values within `margin` px of a crop
//!   edge that the crop cuts are therefore only lower bounds, which is why crops carry a margin.

use super::appearance::{Agreement, Board, TexelGrid, TexelSample, Verdict, pixel_sample};
use super::edge::{EdgeOffsets, EdgePixel, edge_offsets};
use super::frames::{FeatureImage, RayTable, View};

mod distance;
pub use distance::{Crop, SignedDistance};

/// A view's board pixels as a bit mask, with counts.
#[derive(Clone, Debug)]
pub struct Silhouette {
    /// Frame id.
    pub frame_id: u64,
    /// Superpixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    bits: Vec<u64>,
    /// Pixels that disagree with the learned board (they show something else: the object).
    disagree: Vec<u64>,
    /// Board pixels.
    pub board_px: usize,
    /// Pixels that disagree with a learned texel.
    pub disagree_px: usize,
    /// Pixels that disagree with a printed texel as a mixture of its ink and paper could
    /// ([`crate::print`]): neither board nor evidence of an object.
    print: Vec<u64>,
    /// Such pixels.
    pub print_px: usize,
    /// Board islands removed, pixels.
    pub removed_island_px: usize,
    /// Where the edge lies inside the boundary pixels whose cover could be measured
    /// ([`crate::edge`]).
    pub edge: EdgeOffsets,
}

impl Silhouette {
    /// Whether pixel `(x, y)` shows the board (false outside the image).
    pub fn is_board(&self, x: isize, y: isize) -> bool {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            return false;
        }
        let k = y as usize * self.width + x as usize;
        self.bits[k / 64] >> (k % 64) & 1 == 1
    }

    /// Whether pixel `(x, y)` disagrees with the learned board (false outside the image).
    pub fn disagrees(&self, x: isize, y: isize) -> bool {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            return false;
        }
        let k = y as usize * self.width + x as usize;
        self.disagree[k / 64] >> (k % 64) & 1 == 1
    }

    /// Whether pixel `(x, y)` is an ambiguous print pixel ([`crate::print`]; false outside).
    pub fn is_print(&self, x: isize, y: isize) -> bool {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            return false;
        }
        let k = y as usize * self.width + x as usize;
        self.print[k / 64] >> (k % 64) & 1 == 1
    }

    fn set(&mut self, k: usize, on: bool) {
        if on {
            self.bits[k / 64] |= 1 << (k % 64);
        } else {
            self.bits[k / 64] &= !(1 << (k % 64));
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        (self.bits.len() + self.disagree.len() + self.print.len()) * 8 + self.edge.bytes()
    }
}

/// The verdict of a pixel on an unknown texel from its learned neighbours: the board when one
/// shows it, else dark when one is [`Verdict::Dark`], else something else when one is learned
/// (`None`: none is).
fn neighbour_verdict<'a>(
    learned: impl Iterator<Item = &'a TexelSample>,
    verdict: impl Fn(&TexelSample) -> Verdict,
) -> Option<Verdict> {
    let mut out = None;
    for texel in learned {
        match verdict(texel) {
            Verdict::Board => return Some(Verdict::Board),
            Verdict::Dark => out = Some(Verdict::Dark),
            Verdict::Other => out = out.or(Some(Verdict::Other)),
        }
    }
    out
}

/// Dark-surround pixels ([`Verdict::Dark`]) within this many pixels (Chebyshev) of a dim
/// pixel of the object do not show the board: the object's limb may still be darkening
/// there. Measured on the glass sphere (ρd 0.02) in front of the void beyond the board: its
/// top limb is indistinguishable from the void up to 2.2 superpixels inside its true edge.
pub const DARK_LIMB_MARGIN_PX: usize = 3;

/// `mask` grown by `r` pixels (a square of side 2r + 1), separably.
fn dilate(mask: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    let grow = |get: &dyn Fn(usize) -> bool, n: usize, out: &mut dyn FnMut(usize, bool)| {
        // running count of set pixels in the window [i − r, i + r]
        let mut count = (0..r.min(n)).filter(|&j| get(j)).count();
        for i in 0..n {
            if i + r < n && get(i + r) {
                count += 1;
            }
            out(i, count > 0);
            if i >= r && get(i - r) {
                count -= 1;
            }
        }
    };
    let mut rows = vec![false; w * h];
    for y in 0..h {
        let line = &mask[y * w..(y + 1) * w];
        grow(&|x| line[x], w, &mut |x, v| rows[y * w + x] = v);
    }
    let mut out = vec![false; w * h];
    for x in 0..w {
        grow(&|y| rows[y * w + x], h, &mut |y, v| out[y * w + x] = v);
    }
    out
}

/// Classifies every pixel of a view (see the module contract).
#[expect(
    clippy::too_many_arguments,
    reason = "the view, its rays and image, and the three thresholds of one classification"
)]
pub fn classify(
    board: &Board,
    rule: &Agreement,
    rays: &RayTable,
    view: &View,
    image: &FeatureImage,
    floor_dn: f64,
    min_island_px: usize,
    max_enclosed_fraction: f64,
) -> Silhouette {
    // The caller checks that the image and the ray table have the same size.
    let (w, h) = (image.width, image.height);
    let mut s = Silhouette {
        frame_id: view.frame_id,
        width: w,
        height: h,
        bits: vec![0; (w * h).div_ceil(64)],
        disagree: vec![0; (w * h).div_ceil(64)],
        board_px: 0,
        disagree_px: 0,
        print: vec![0; (w * h).div_ceil(64)],
        print_px: 0,
        removed_island_px: 0,
        edge: EdgeOffsets::default(),
    };
    let mut dim_px = Vec::new();
    let mut dark = Vec::new();
    for k in 0..w * h {
        let Some((texel, sample)) = pixel_sample(&board.grid, rays, view, image, k, floor_dn)
        else {
            continue;
        };
        let verdict = match &board.texels[texel] {
            Some(learned) => Some(rule.verdict(&sample, learned)),
            // an unknown texel: its learned neighbours speak for it (texels far from the
            // cameras are hit by fewer pixels than texels)
            None => neighbour_verdict(
                neighbours(&board.grid, texel).filter_map(|n| board.texels[n].as_ref()),
                |learned| rule.verdict(&sample, learned),
            ),
        };
        match verdict {
            Some(Verdict::Board) => {
                s.set(k, true);
                s.board_px += 1;
            }
            Some(Verdict::Other) => {
                if board.print.ambiguous(rule, texel, &sample) {
                    s.print[k / 64] |= 1 << (k % 64);
                    s.print_px += 1;
                } else {
                    s.disagree[k / 64] |= 1 << (k % 64);
                    s.disagree_px += 1;
                }
                // either way a dim ramp may be an object's limb darkening into the print
                if rule.dim(&sample) {
                    dim_px.push(k);
                }
            }
            Some(Verdict::Dark) => dark.push(k),
            None => {}
        }
    }
    // A dark-surround pixel shows the board unless a dim object pixel is near: there the
    // object's limb may still be darkening into it (`DARK_LIMB_MARGIN_PX`).
    let mut dim = vec![false; w * h];
    for k in dim_px {
        dim[k] = true;
    }
    // A ramp is two dim object pixels side by side: the mixed pixel on a bright object's edge
    // is dim alone.
    let ramp: Vec<bool> = (0..w * h)
        .map(|k| {
            let (x, y) = (k % w, k / w);
            dim[k]
                && ((x > 0 && dim[k - 1])
                    || (x + 1 < w && dim[k + 1])
                    || (y > 0 && dim[k - w])
                    || (y + 1 < h && dim[k + w]))
        })
        .collect();
    let near_dim = dilate(&ramp, w, h, DARK_LIMB_MARGIN_PX);
    for k in dark {
        if !near_dim[k] {
            s.set(k, true);
            s.board_px += 1;
        }
    }
    remove_islands(&mut s, min_island_px, max_enclosed_fraction);
    s.edge = edge_offsets(
        rule,
        w,
        h,
        |x, y| s.is_board(x, y),
        |x, y| s.disagrees(x, y),
        |k| {
            let (texel, sample) = pixel_sample(&board.grid, rays, view, image, k, floor_dn)?;
            Some(EdgePixel {
                sample,
                board: board.texels[texel],
            })
        },
    );
    s
}

/// The 8 neighbours of a texel inside the grid.
fn neighbours(grid: &TexelGrid, texel: usize) -> impl Iterator<Item = usize> + '_ {
    let (i, j) = ((texel % grid.nx) as isize, (texel / grid.nx) as isize);
    (-1..=1)
        .flat_map(move |dj| (-1..=1).map(move |di| (i + di, j + dj)))
        .filter(move |&(x, y)| {
            (x, y) != (i, j) && x >= 0 && y >= 0 && x < grid.nx as isize && y < grid.ny as isize
        })
        .map(move |(x, y)| y as usize * grid.nx + x as usize)
}

/// Makes board islands not-board (4-connected components): those smaller than `min_px`, and
/// those that do not reach the image border and hold less than `max_enclosed_fraction` of the
/// view's board pixels.
fn remove_islands(s: &mut Silhouette, min_px: usize, max_enclosed_fraction: f64) {
    let (w, h) = (s.width, s.height);
    let enclosed_limit = (max_enclosed_fraction * s.board_px as f64) as usize;
    let mut visited = vec![false; w * h];
    let mut stack = Vec::new();
    let mut component = Vec::new();
    for start in 0..w * h {
        if visited[start] || !s.is_board((start % w) as isize, (start / w) as isize) {
            continue;
        }
        component.clear();
        stack.push(start);
        visited[start] = true;
        let mut border = false;
        while let Some(k) = stack.pop() {
            component.push(k);
            let (x, y) = ((k % w) as isize, (k / w) as isize);
            border |= x == 0 || y == 0 || x as usize + 1 == w || y as usize + 1 == h;
            for (dx, dy) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                let (nx, ny) = (x + dx, y + dy);
                if s.is_board(nx, ny) {
                    let n = ny as usize * w + nx as usize;
                    if !visited[n] {
                        visited[n] = true;
                        stack.push(n);
                    }
                }
            }
        }
        if component.len() < min_px || (!border && component.len() < enclosed_limit) {
            for &k in &component {
                s.set(k, false);
            }
            s.board_px -= component.len();
            s.removed_island_px += component.len();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::distance::edt_2d;
    use super::*;

    #[test]
    fn dilation_matches_brute_force() {
        let (w, h) = (17, 11);
        let mask: Vec<bool> = (0..w * h).map(|k| (k * 7919) % 23 == 0).collect();
        for r in 0..4 {
            let d = dilate(&mask, w, h, r);
            for (k, &got) in d.iter().enumerate() {
                let (x, y) = ((k % w) as isize, (k / w) as isize);
                let want = (0..w * h).any(|j| {
                    let (a, b) = ((j % w) as isize, (j / w) as isize);
                    mask[j] && (a - x).abs() <= r as isize && (b - y).abs() <= r as isize
                });
                assert_eq!(got, want, "r {r}, pixel ({x}, {y})");
            }
        }
    }

    #[test]
    fn a_texel_a_black_pixel_matches_is_dark_and_decides_nothing_alone() {
        let rule = Agreement::new(&crate::appearance::AppearanceConfig::default(), 1, 4095.0);
        let sample = |v: f32| TexelSample {
            value: [v, 0.0, 0.0],
            p: 0.0,
            floor: 8.0,
            s0_dn: v,
        };
        // paper: a matching pixel shows the board, a dark one does not
        assert_eq!(
            rule.verdict(&sample(1650.0), &sample(1640.0)),
            Verdict::Board
        );
        assert_eq!(rule.verdict(&sample(16.0), &sample(1640.0)), Verdict::Other);
        // ink (80): a black pixel is told from it
        assert_eq!(rule.verdict(&sample(78.0), &sample(80.0)), Verdict::Board);
        // the void beyond the sheet (≈ 1): a glass limb at 6 agrees, and so would black
        assert_eq!(rule.verdict(&sample(6.0), &sample(1.0)), Verdict::Dark);
        assert_eq!(rule.verdict(&sample(30.0), &sample(1.0)), Verdict::Other);
        // dim: below 4 × floor / (1 − 0.12) ≈ 36
        assert!(rule.dim(&sample(16.0)) && !rule.dim(&sample(60.0)));
        // neighbours: one showing the board decides, else one dark, else other
        let v = |pixel: f32, vals: &[f32]| {
            let learned: Vec<TexelSample> = vals.iter().map(|&v| sample(v)).collect();
            neighbour_verdict(learned.iter(), |l| rule.verdict(&sample(pixel), l))
        };
        assert_eq!(v(6.0, &[1.0, 6.5]), Some(Verdict::Dark));
        assert_eq!(v(80.0, &[1.0, 80.0]), Some(Verdict::Board));
        assert_eq!(v(6.0, &[1.0, 900.0]), Some(Verdict::Dark));
        assert_eq!(v(6.0, &[900.0]), Some(Verdict::Other));
        assert_eq!(v(6.0, &[]), None);
    }

    #[test]
    fn distance_transform_matches_brute_force() {
        let (w, h) = (13, 9);
        let feature: Vec<bool> = (0..w * h).map(|k| (k * 7919) % 11 == 0).collect();
        let d = edt_2d(&feature, w, h);
        for (k, &dk) in d.iter().enumerate() {
            let (x, y) = ((k % w) as f32, (k / w) as f32);
            let brute = (0..w * h)
                .filter(|&j| feature[j])
                .map(|j| {
                    let (a, b) = ((j % w) as f32, (j / w) as f32);
                    (a - x).powi(2) + (b - y).powi(2)
                })
                .fold(f32::INFINITY, f32::min);
            assert!((dk - brute).abs() < 1e-3, "pixel {k}: {} vs {brute}", d[k]);
        }
    }

    #[test]
    fn signed_distance_crosses_zero_on_the_boundary_and_small_islands_go() {
        // board everywhere except a 10×10 object; one 2-pixel board island inside it
        let (w, h) = (40, 30);
        let mut s = Silhouette {
            frame_id: 0,
            width: w,
            height: h,
            bits: vec![0; (w * h).div_ceil(64)],
            disagree: vec![0; (w * h).div_ceil(64)],
            board_px: 0,
            disagree_px: 0,
            print: vec![0; (w * h).div_ceil(64)],
            print_px: 0,
            removed_island_px: 0,
            edge: EdgeOffsets::default(),
        };
        for y in 0..h {
            for x in 0..w {
                let object = (10..20).contains(&x) && (10..20).contains(&y);
                let island = y == 15 && (14..16).contains(&x);
                if !object || island {
                    s.set(y * w + x, true);
                    s.board_px += 1;
                }
            }
        }
        remove_islands(&mut s, 4, 0.0);
        assert_eq!(s.removed_island_px, 2);
        assert!(!s.is_board(14, 15));
        let crop = Crop {
            x0: 0,
            y0: 0,
            width: w,
            height: h,
        };
        let d = SignedDistance::new(&s, crop, 0.0);
        // boundary between x = 9 (board) and x = 10 (object): zero at x = 9.5
        let at = |x: f64| d.sample(x, 15.0).unwrap();
        assert!(at(9.5).abs() < 1e-6, "{}", at(9.5));
        assert!((at(7.0) - 2.5).abs() < 1e-6);
        assert!((at(12.0) + 2.5).abs() < 1e-6);
        assert!(d.sample(-1.0, 3.0).is_none());
    }
}
