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

/// A rectangle of pixels `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    /// First column.
    pub x0: isize,
    /// First row.
    pub y0: isize,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

/// The signed distance of a crop of a silhouette (see the module contract).
#[derive(Clone, Debug)]
pub struct SignedDistance {
    /// The crop it covers.
    pub crop: Crop,
    /// Pixels, row-major over the crop.
    pub values: Vec<f32>,
    /// Per pixel of the crop: it disagrees with the learned board.
    pub disagree: Vec<bool>,
    /// Per pixel of the crop: an ambiguous print pixel ([`crate::print`]).
    pub print: Vec<bool>,
}

/// Large finite stand-in for "no feature pixel" (keeps the parabola arithmetic finite).
const FAR: f32 = 1e12;

/// Squared 1-D distance transform of `f` into `d` (Felzenszwalb & Huttenlocher, Alg. 1).
fn edt_1d(f: &[f32], d: &mut [f32], v: &mut [usize], z: &mut [f32]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let mut k = 0usize;
    v[0] = 0;
    z[0] = f32::NEG_INFINITY;
    z[1] = f32::INFINITY;
    for q in 1..n {
        let fq = f[q] + (q * q) as f32;
        loop {
            let p = v[k];
            // q > p, so the denominator is ≥ 2
            let s = (fq - (f[p] + (p * p) as f32)) / (2.0 * (q - p) as f32);
            if s <= z[k] && k > 0 {
                k -= 1;
                continue;
            }
            if s <= z[k] {
                // k == 0 and the new parabola wins everywhere
                v[0] = q;
                z[0] = f32::NEG_INFINITY;
                z[1] = f32::INFINITY;
            } else {
                k += 1;
                v[k] = q;
                z[k] = s;
                z[k + 1] = f32::INFINITY;
            }
            break;
        }
    }
    let mut k = 0usize;
    for (q, out) in d.iter_mut().enumerate() {
        while z[k + 1] < q as f32 {
            k += 1;
        }
        let p = v[k];
        let dq = q as f32 - p as f32;
        *out = dq * dq + f[p];
    }
}

/// Squared Euclidean distance from every pixel to the nearest pixel where `feature` is true.
fn edt_2d(feature: &[bool], w: usize, h: usize) -> Vec<f32> {
    let mut g: Vec<f32> = feature.iter().map(|&b| if b { 0.0 } else { FAR }).collect();
    let n = w.max(h);
    let (mut f, mut d, mut v, mut z) = (
        vec![0f32; n],
        vec![0f32; n],
        vec![0usize; n],
        vec![0f32; n + 1],
    );
    for x in 0..w {
        for y in 0..h {
            f[y] = g[y * w + x];
        }
        edt_1d(&f[..h], &mut d[..h], &mut v, &mut z);
        for y in 0..h {
            g[y * w + x] = d[y].min(FAR);
        }
    }
    for y in 0..h {
        f[..w].copy_from_slice(&g[y * w..(y + 1) * w]);
        edt_1d(&f[..w], &mut d[..w], &mut v, &mut z);
        for x in 0..w {
            g[y * w + x] = d[x].min(FAR);
        }
    }
    g
}

impl SignedDistance {
    /// The signed distance over `crop` of `s`, its zero crossing moved into the not-board side
    /// by the measured edge offsets, elsewhere by `edge_inset_px` (module contract).
    pub fn new(s: &Silhouette, crop: Crop, edge_inset_px: f32) -> Self {
        let (w, h) = (crop.width, crop.height);
        let board: Vec<bool> = (0..w * h)
            .map(|k| s.is_board(crop.x0 + (k % w) as isize, crop.y0 + (k / w) as isize))
            .collect();
        let not_board: Vec<bool> = board.iter().map(|b| !b).collect();
        let to_not_board = edt_2d(&not_board, w, h);
        let to_board = edt_2d(&board, w, h);
        // the fixed inset, or the measured offset at the boundary pixels inside the crop
        let mut offset = vec![edge_inset_px; w * h];
        for &(k, d) in &s.edge.0 {
            let (x, y) = (
                (k as usize % s.width) as isize - crop.x0,
                (k as usize / s.width) as isize - crop.y0,
            );
            if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h {
                offset[y as usize * w + x as usize] = d;
            }
        }
        let values = (0..w * h)
            .map(|k| {
                offset[k]
                    + if board[k] {
                        to_not_board[k].sqrt() - 0.5
                    } else {
                        -(to_board[k].sqrt() - 0.5)
                    }
            })
            .collect();
        let disagree = (0..w * h)
            .map(|k| s.disagrees(crop.x0 + (k % w) as isize, crop.y0 + (k / w) as isize))
            .collect();
        let print = (0..w * h)
            .map(|k| s.is_print(crop.x0 + (k % w) as isize, crop.y0 + (k / w) as isize))
            .collect();
        Self {
            crop,
            values,
            disagree,
            print,
        }
    }

    /// Whether the pixel nearest superpixel coordinate `(x, y)` is an ambiguous print pixel.
    pub fn print_at(&self, x: f64, y: f64) -> bool {
        self.nearest(x, y).is_some_and(|k| self.print[k])
    }

    /// The crop index of the pixel nearest superpixel coordinate `(x, y)`.
    fn nearest(&self, x: f64, y: f64) -> Option<usize> {
        let (u, v) = (
            (x - self.crop.x0 as f64).round(),
            (y - self.crop.y0 as f64).round(),
        );
        (u >= 0.0 && v >= 0.0 && (u as usize) < self.crop.width && (v as usize) < self.crop.height)
            .then(|| v as usize * self.crop.width + u as usize)
    }

    /// Whether the pixel nearest superpixel coordinate `(x, y)` disagrees with the board.
    pub fn disagrees_at(&self, x: f64, y: f64) -> bool {
        self.nearest(x, y).is_some_and(|k| self.disagree[k])
    }

    /// Bilinear value at superpixel coordinate `(x, y)`, `None` outside the crop.
    pub fn sample(&self, x: f64, y: f64) -> Option<f32> {
        let (u, v) = (x - self.crop.x0 as f64, y - self.crop.y0 as f64);
        let (w, h) = (self.crop.width, self.crop.height);
        if !(u >= 0.0 && v >= 0.0 && u <= (w - 1) as f64 && v <= (h - 1) as f64) || w < 2 || h < 2 {
            return None;
        }
        let (i, j) = ((u as usize).min(w - 2), (v as usize).min(h - 2));
        let (fx, fy) = ((u - i as f64) as f32, (v - j as f64) as f32);
        let at = |a: usize, b: usize| self.values[b * w + a];
        Some(
            (1.0 - fy) * ((1.0 - fx) * at(i, j) + fx * at(i + 1, j))
                + fy * ((1.0 - fx) * at(i, j + 1) + fx * at(i + 1, j + 1)),
        )
    }
}

#[cfg(test)]
mod tests {
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
