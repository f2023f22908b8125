//! Tag corners refined on the raw mosaic: tags are found on the superpixel image (one value
//! per 2×2 analyser tile, or 4×4 on a colour sensor), whose corners are quantised to that
//! tile; here each side of a tag's black square is fitted on the raw pixels themselves and the
//! corners are the intersections of the fitted sides.
//!
//! Contract of [`refine_corners`]:
//! - **Model of one side.** Near a straight edge between the black square and the white paper,
//!   a raw pixel of mosaic phase p (its position in the tile: colour filter × analyser) reads
//!   v = B_p + (W_p − B_p)·S((d − δ − α·s)/w): d and s its distance across and along the
//!   detected side (from the side's middle), S the logistic step, w the blur, and B_p, W_p the
//!   phase's black and white levels. The levels are per phase because every phase sees the
//!   same ink and paper through its own colour filter and analyser (unknown gains, the
//!   flash's residual polarisation, any black level); they enter linearly, so they are solved
//!   exactly for each trial (δ, α, w) — variable projection (Golub & Pereyra 1973) — and the
//!   Levenberg–Marquardt loop of the crate ([`crate::lm`]) runs over the three geometric
//!   parameters only.
//! - **Which pixels.** Those whose centre lies within `reach` of the detected side across it
//!   and at least `reach` from both its ends along it (the neighbouring sides and their corner
//!   stay out). `reach` is the square's border cell (side length / cells across the black
//!   square: 8 for tag36h11, 7 for tag25h9, 6 for tag16h5) less the detection's possible error
//!   (half a tile's diagonal, [`DETECTION_ERROR_TILES`]) and the step's tail ([`TAIL_PX`]): inside
//!   the side the window reads only the black border cell, outside it only the white margin
//!   every AprilTag layout keeps, never the data bits, wherever within that error the true
//!   side lies. The reach must in turn exceed that error by a pixel, or the true side may lie
//!   outside the window: smaller tags (a border cell under about 1.4 tiles + 2 px, e.g. 52 px
//!   across for tag36h11 on a colour sensor) keep their detected corners.
//! - **The corners.** Each fitted side is a line; a corner is where its two sides meet. A side
//!   whose fit fails (too few pixels of some phase, a contrast within the noise, no
//!   convergence, a shift beyond the window) leaves the tag's detected corners as they were: a
//!   refinement either improves all four corners consistently or does nothing. A refined corner
//!   farther than one tile from the detected one is taken as a failed fit too (the detection
//!   is within half a tile).

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

use super::TagFamily;
use crate::lm::{Schedule, Step, minimise};

/// Cells across a tag family's black square (data bits plus the one-cell black border on
/// both sides) for the classic families, whose detected corners are that square's; `None` for
/// the standard, circle and custom layouts (their outermost ring is data or white: no plain
/// black-to-white side), which keep their detected corners.
pub fn cells_across(family: TagFamily) -> Option<f64> {
    match family {
        TagFamily::Tag36h11 => Some(8.0),
        TagFamily::Tag25h9 => Some(7.0),
        TagFamily::Tag16h5 => Some(6.0),
        _ => None,
    }
}

/// How far a detected corner may be from the true one, in tiles: half the tile's diagonal
/// (the superpixel image quantises each coordinate to a tile, and the library's own edge fit
/// places the corner inside the superpixel it falls in).
const DETECTION_ERROR_TILES: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// The logistic step's tail kept off the data bits, px: at half a pixel beyond the fitted
/// edge a one-pixel blur is 38 % of the way, so the window's last pixel still reads the
/// border cell, not a data bit beside it.
const TAIL_PX: f64 = 0.5;

/// A raw image to refine on: row-major values and the mosaic tile size.
#[derive(Clone, Copy)]
pub struct RawImage<'a> {
    /// Pixel values (DN), row-major.
    pub data: &'a [u16],
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Mosaic tile size (2: analysers; 4: analysers × Bayer).
    pub tile: usize,
}

/// One side's pixels: across and along coordinates, value, phase.
struct SidePixels {
    d: Vec<f64>,
    s: Vec<f64>,
    v: Vec<f64>,
    phase: Vec<usize>,
    phases: usize,
}

/// The fitted line of a side: a point on it and its unit direction.
#[derive(Clone, Copy, Debug)]
struct Line {
    point: Vector2<f64>,
    direction: Vector2<f64>,
}

/// The side model's residuals at one line and blur, the levels solved ([`SidePixels::residuals`]).
struct Projected {
    /// Per pixel: value − model.
    residuals: Vec<f64>,
    /// Per pixel: the step's argument x.
    arguments: Vec<f64>,
    /// Per pixel: the step S(x) (kept for the Jacobian, which would take it again).
    shape: Vec<f64>,
    /// Per phase: (a, b) = (B, W − B).
    levels: Vec<[f64; 2]>,
}

/// Logistic step, `1 / (1 + e^−x)`. Far out on either side the exponential overflows to ∞ or
/// underflows to 0, which libm reaches on a slow path that sets `errno` (a fifth of a
/// calibration's time on sharp edges, whose far pixels have |x| in the thousands); the step is
/// then exactly 0 or 1, returned here without the call — the same bits.
fn step(x: f64) -> f64 {
    let t = -x;
    if t > 710.0 {
        // e^t overflows above ln(f64::MAX) = 709.78: 1 / (1 + ∞) = 0
        0.0
    } else if t < -746.0 {
        // e^t underflows below ln(smallest subnormal / 2) = −745.13: 1 / (1 + 0) = 1
        1.0
    } else {
        1.0 / (1.0 + t.exp())
    }
}

impl SidePixels {
    /// The residuals of the side model at (δ, α, ln w) with the per-phase levels solved
    /// (module doc), and each pixel's argument x of the step and its phase's coefficients
    /// (a = B, b = W − B); `None` where a phase's levels cannot be solved.
    fn residuals(&self, p: &Vector3<f64>) -> Option<Projected> {
        let w = p[2].exp();
        let x: Vec<f64> = (0..self.v.len())
            .map(|i| (self.d[i] - p[0] - p[1] * self.s[i]) / w)
            .collect();
        let shape: Vec<f64> = x.iter().map(|&x| step(x)).collect();
        // Per phase: v ≈ B + (W − B)·S, i.e. v ≈ a + b·S (normal equations, 2×2).
        let mut sums = vec![[0.0f64; 5]; self.phases];
        for i in 0..self.v.len() {
            let t = &mut sums[self.phase[i]];
            let (s, y) = (shape[i], self.v[i]);
            t[0] += 1.0;
            t[1] += s;
            t[2] += s * s;
            t[3] += y;
            t[4] += s * y;
        }
        let mut coef = vec![[0.0f64; 2]; self.phases];
        for (k, t) in sums.iter().enumerate() {
            if t[0] == 0.0 {
                continue;
            }
            let m = Matrix2::new(t[0], t[1], t[1], t[2]);
            let ab = m.lu().solve(&Vector2::new(t[3], t[4]))?;
            coef[k] = [ab[0], ab[1]];
        }
        let r = (0..self.v.len())
            .map(|i| {
                let [a, b] = coef[self.phase[i]];
                self.v[i] - a - b * shape[i]
            })
            .collect();
        Some(Projected {
            residuals: r,
            arguments: x,
            shape,
            levels: coef,
        })
    }

    /// The Jacobian row of pixel `i` with the levels held (Kaufman 1975's simplification of
    /// variable projection: the levels' own change with the step is left out of the
    /// derivative, not of the residual, which costs iterations, never accuracy).
    fn jacobian_row(&self, i: usize, x: f64, s: f64, coef: &[[f64; 2]], w: f64) -> Vector3<f64> {
        // s = S(x), as `residuals` took it
        let b = coef[self.phase[i]][1];
        // r = v − a − b·S(x), x = (d − δ − α·s)/w: ∂r/∂θ = −b·S'(x)·∂x/∂θ.
        let ds = -b * s * (1.0 - s);
        Vector3::new(-ds / w, -ds * self.s[i] / w, -ds * x)
    }

    /// The per-phase contrast W − B at the fitted parameters (for the contrast test).
    fn min_contrast(&self, p: &Vector3<f64>) -> f64 {
        let w = p[2].exp();
        let mut bright = vec![(0.0, 0.0); self.phases];
        let mut dark = vec![(0.0, 0.0); self.phases];
        for i in 0..self.v.len() {
            let x = (self.d[i] - p[0] - p[1] * self.s[i]) / w;
            let side = if x > 2.0 {
                &mut bright
            } else if x < -2.0 {
                &mut dark
            } else {
                continue;
            };
            side[self.phase[i]].0 += self.v[i];
            side[self.phase[i]].1 += 1.0;
        }
        (0..self.phases)
            .filter(|&k| bright[k].1 > 0.0 && dark[k].1 > 0.0)
            .map(|k| bright[k].0 / bright[k].1 - dark[k].0 / dark[k].1)
            .fold(f64::INFINITY, f64::min)
    }
}

/// Fits one side from `a` to `b` (raw px) with the black square on its left-hand normal's
/// negative side or positive side (whichever the data say); `None` where it fails (module doc).
fn fit_side(img: &RawImage<'_>, a: [f64; 2], b: [f64; 2], reach: f64) -> Option<Line> {
    let (a, b) = (Vector2::from(a), Vector2::from(b));
    let length = (b - a).norm();
    let along = (b - a) / length;
    let across = Vector2::new(-along.y, along.x);
    if length <= 2.0 * reach + 2.0 {
        return None;
    }
    let mid = 0.5 * (a + b);
    let half = 0.5 * length - reach;
    // Bounding box of the window.
    let corners = [
        mid + along * half + across * reach,
        mid + along * half - across * reach,
        mid - along * half + across * reach,
        mid - along * half - across * reach,
    ];
    let lo = |k: usize| corners.iter().map(|c| c[k]).fold(f64::INFINITY, f64::min);
    let hi = |k: usize| {
        corners
            .iter()
            .map(|c| c[k])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let (x0, x1) = (lo(0).floor().max(0.0) as usize, hi(0).ceil() as usize);
    let (y0, y1) = (lo(1).floor().max(0.0) as usize, hi(1).ceil() as usize);
    if x1 >= img.width || y1 >= img.height {
        return None;
    }
    let t = img.tile;
    let mut px = SidePixels {
        d: Vec::new(),
        s: Vec::new(),
        v: Vec::new(),
        phase: Vec::new(),
        phases: t * t,
    };
    for y in y0..=y1 {
        for x in x0..=x1 {
            let r = Vector2::new(x as f64, y as f64) - mid;
            let (d, s) = (r.dot(&across), r.dot(&along));
            if d.abs() <= reach && s.abs() <= half {
                px.d.push(d);
                px.s.push(s / half);
                px.v.push(f64::from(img.data[y * img.width + x]));
                px.phase.push((y % t) * t + x % t);
            }
        }
    }
    // Every phase needs pixels on both sides: at least 4 of each phase.
    let mut counts = vec![0usize; t * t];
    px.phase.iter().for_each(|&k| counts[k] += 1);
    if counts.iter().any(|&c| c < 4) {
        return None;
    }
    // Orientation: the darker side of the window gets negative d.
    let (mut neg, mut pos) = ((0.0, 0usize), (0.0, 0usize));
    for (d, v) in px.d.iter().zip(&px.v) {
        if *d < 0.0 {
            neg = (neg.0 + v, neg.1 + 1);
        } else {
            pos = (pos.0 + v, pos.1 + 1);
        }
    }
    let flip = neg.1 > 0 && pos.1 > 0 && neg.0 / neg.1 as f64 > pos.0 / pos.1 as f64;
    if flip {
        px.d.iter_mut().for_each(|d| *d = -*d);
        px.s.iter_mut().for_each(|s| *s = -*s);
    }
    // A state carries its own residuals, so the next step's Jacobian does not take them again.
    let cost = |p: &(Vector3<f64>, f64, Projected)| p.1;
    let eval = |p: Vector3<f64>| -> Option<(Vector3<f64>, f64, Projected)> {
        if !(p[0].abs() < reach && p[1].abs() < reach && p[2].is_finite()) {
            return None;
        }
        let projected = px.residuals(&p)?;
        let cost = projected.residuals.iter().map(|e| e * e).sum();
        Some((p, cost, projected))
    };
    // Start on the detected side, blur one pixel.
    let start = eval(Vector3::new(0.0, 0.0, 0.0))?;
    // A step under a thousandth of a pixel (or of ln w) moves no corner by anything the pose
    // can see (the corners' noise is ~0.01 px, the test's measure).
    let schedule = Schedule {
        initial_damping: 1e-3,
        relative_cost_tolerance: 1e-8,
        step_tolerance: 1e-3,
    };
    let (fitted, _) = minimise(start, cost, &schedule, 60, |state, lambda| {
        let (p, _, projected) = state;
        let Projected {
            residuals: r,
            arguments: x,
            shape,
            levels: coef,
        } = projected;
        let w = p[2].exp();
        let mut jtj = Matrix3::zeros();
        let mut jtr = Vector3::zeros();
        for (i, (ri, xi)) in r.iter().zip(x).enumerate() {
            let row = px.jacobian_row(i, *xi, shape[i], coef, w);
            jtj += row * row.transpose();
            jtr += row * *ri;
        }
        let damped = jtj + Matrix3::from_diagonal(&jtj.diagonal()) * lambda;
        let Some(chol) = damped.cholesky() else {
            return Step::Singular;
        };
        let delta = -chol.solve(&jtr);
        Step::Tried {
            trial: eval(p + delta),
            step_norm: delta.norm(),
        }
    });
    let p = fitted.0;
    // The contrast must stand out of the residual noise: every phase's W − B above 5 times
    // the residuals' standard deviation (a step within the noise locates nothing).
    let n = px.v.len() as f64;
    let sd = (fitted.1 / (n - 3.0 - 2.0 * (t * t) as f64).max(1.0)).sqrt();
    let contrast = px.min_contrast(&p);
    if contrast.is_nan() || contrast <= 5.0 * sd || p[0].abs() >= reach - 1.0 {
        return None;
    }
    let sign = if flip { -1.0 } else { 1.0 };
    // d = δ + α·s/half (in the flipped frame, both d and s change sign).
    let point = mid + across * (sign * p[0]);
    let direction = (along * half + across * (p[1])).normalize();
    Some(Line { point, direction })
}

/// Where two lines meet (`None` when nearly parallel).
fn intersect(l: &Line, m: &Line) -> Option<[f64; 2]> {
    let a = Matrix2::from_columns(&[l.direction, -m.direction]);
    let det = a.determinant();
    if det.abs() < 1e-6 {
        return None;
    }
    let t = a.lu().solve(&(m.point - l.point))?;
    let p = l.point + l.direction * t[0];
    Some([p.x, p.y])
}

/// The corners of one tag's black square refined on the raw image (module doc); `corners` are
/// the detected ones in raw pixels (integer-centre convention, the library's order around the
/// square). `None` keeps the detected corners.
pub fn refine_corners(
    img: &RawImage<'_>,
    corners: &[[f64; 2]; 4],
    family: TagFamily,
) -> Option<[[f64; 2]; 4]> {
    let side = |k: usize| {
        let (a, b) = (corners[k], corners[(k + 1) % 4]);
        (a[0] - b[0]).hypot(a[1] - b[1])
    };
    let shortest = (0..4).map(side).fold(f64::INFINITY, f64::min);
    let tile = img.tile as f64;
    let error_px = DETECTION_ERROR_TILES * tile;
    let reach = shortest / cells_across(family)? - error_px - TAIL_PX;
    if reach < error_px + 1.0 {
        return None;
    }
    let lines: Vec<Line> = (0..4)
        .map(|k| fit_side(img, corners[k], corners[(k + 1) % 4], reach))
        .collect::<Option<_>>()?;
    let mut out = [[0.0; 2]; 4];
    for k in 0..4 {
        // Corner k joins side k − 1 (into it) and side k (out of it).
        let c = intersect(&lines[(k + 3) % 4], &lines[k])?;
        if (c[0] - corners[k][0]).hypot(c[1] - corners[k][1]) > tile {
            return None;
        }
        out[k] = c;
    }
    Some(out)
}

#[cfg(test)]
mod tests;
