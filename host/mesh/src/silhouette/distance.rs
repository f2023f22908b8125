//! A view's signed distance to its board region ([`super`]'s contract): the exact Euclidean
//! distance transform of Felzenszwalb & Huttenlocher ("Distance Transforms of Sampled
//! Functions", Theory of Computing 8, 2012) over a crop of the silhouette, the measured edge
//! offsets added at the boundary pixels, and the per-pixel disagree and print masks the carving
//! counts.

use super::Silhouette;

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
pub(super) fn edt_2d(feature: &[bool], w: usize, h: usize) -> Vec<f32> {
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
