//! The raw pixels a sampled value draws on, as the points the mixed-sample test casts its rays
//! through ([`Footprint`]).
//!
//! Contract:
//! - A footprint is the union of the blocks of raw pixels under the kernel's *significant* taps
//!   — those whose two-dimensional weight |w_x·w_y| reaches the lightest tap that counts
//!   (`sampler::min_tap_weight`) — over every band and analyser. It is summarised by its
//!   bounding octagon: the extremes of x, y, x + y and x − y over the blocks' corners
//!   ([`Octagon`]). A separable cubic kernel's significant taps form a cross: its four corner
//!   taps weigh at most (1/16)² ≈ 0.4 % each (Keys' a = −½ at its worst phase), below the
//!   1.4 % of a mid-scale pixel's shot noise, so the octagon cuts the square's corners, which
//!   are the farthest pixels from the point and the first to cross a silhouette. At most two
//!   corner taps lie beyond a straight edge that spares the arms (0.8 % together).
//! - [`Footprint::points`] are the octagon's distinct vertices, then the midpoints of its
//!   axis-aligned edges up to eight points in all: a rectangle gives its four corners and four
//!   edge midpoints ([`Footprint::of_rect`]), a cross its eight corners — never more rays than
//!   the rectangle's eight.

use super::rect::PixelRect;

/// At most this many probe points.
const MAX_POINTS: usize = 8;

/// The probe points of a footprint (module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    points: [[f64; 2]; MAX_POINTS],
    len: usize,
}

impl Footprint {
    /// The four corners and four edge midpoints of `rect`.
    pub fn of_rect(rect: &PixelRect) -> Footprint {
        Octagon::of_rect(rect).footprint()
    }

    /// [`Footprint::of_rect`] of the square of half-side `radius_px` about `pixel`.
    pub fn square(pixel: [f64; 2], radius_px: f64) -> Footprint {
        Footprint::of_rect(&PixelRect {
            min: pixel.map(|v| v - radius_px),
            max: pixel.map(|v| v + radius_px),
        })
    }

    /// The probe points, corners first (they reach farthest).
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points[..self.len]
    }

    /// The largest distance of a probe point from `pixel`, px (0 without one).
    pub fn reach_px(&self, pixel: [f64; 2]) -> f64 {
        self.points()
            .iter()
            .map(|p| (p[0] - pixel[0]).hypot(p[1] - pixel[1]))
            .fold(0.0, f64::max)
    }

    /// The bounding rectangle of the probe points (`None` without one).
    pub fn rect(&self) -> Option<PixelRect> {
        PixelRect::around(self.points().iter().copied())
    }

    fn push(&mut self, p: [f64; 2]) {
        if self.len < MAX_POINTS && !self.points().contains(&p) {
            self.points[self.len] = p;
            self.len += 1;
        }
    }
}

/// A bounding octagon: extremes of x, y, x + y and x − y (module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Octagon {
    x: [f64; 2],
    y: [f64; 2],
    sum: [f64; 2],
    diff: [f64; 2],
}

impl Default for Octagon {
    fn default() -> Self {
        let empty = [f64::INFINITY, f64::NEG_INFINITY];
        Octagon {
            x: empty,
            y: empty,
            sum: empty,
            diff: empty,
        }
    }
}

impl Octagon {
    /// The octagon of a rectangle (no corner cut).
    pub fn of_rect(rect: &PixelRect) -> Octagon {
        let mut o = Octagon::default();
        o.add_block([rect.min[0], rect.max[0]], [rect.min[1], rect.max[1]]);
        o
    }

    /// Grows the octagon to hold the block `x[0]..=x[1]` × `y[0]..=y[1]`.
    pub fn add_block(&mut self, x: [f64; 2], y: [f64; 2]) {
        let widen = |r: &mut [f64; 2], lo: f64, hi: f64| {
            r[0] = r[0].min(lo);
            r[1] = r[1].max(hi);
        };
        widen(&mut self.x, x[0], x[1]);
        widen(&mut self.y, y[0], y[1]);
        widen(&mut self.sum, x[0] + y[0], x[1] + y[1]);
        widen(&mut self.diff, x[0] - y[1], x[1] - y[0]);
    }

    /// Whether no block was added (an extreme is not finite).
    pub fn is_empty(&self) -> bool {
        [self.x, self.y, self.sum, self.diff]
            .iter()
            .flatten()
            .any(|v| !v.is_finite())
    }

    /// The probe points (module doc): the vertices where the diagonal edges meet the
    /// axis-aligned ones (clamped to the rectangle, so an uncut corner is the rectangle's), and
    /// the axis-aligned edges' midpoints.
    pub fn footprint(&self) -> Footprint {
        let ([x0, x1], [y0, y1]) = (self.x, self.y);
        let cx = |x: f64| x.clamp(x0, x1);
        let cy = |y: f64| y.clamp(y0, y1);
        let ([s0, s1], [d0, d1]) = (self.sum, self.diff);
        // Along each side, the ends its diagonal neighbours leave of it.
        let left = [cy(s0 - x0), cy(x0 - d0)];
        let right = [cy(x1 - d1), cy(s1 - x1)];
        let top = [cx(s0 - y0), cx(y0 + d1)];
        let bottom = [cx(y1 + d0), cx(s1 - y1)];
        let mut f = Footprint {
            points: [[0.0; 2]; MAX_POINTS],
            len: 0,
        };
        for p in [
            [x0, left[0]],
            [top[0], y0],
            [top[1], y0],
            [x1, right[0]],
            [x1, right[1]],
            [bottom[1], y1],
            [bottom[0], y1],
            [x0, left[1]],
            [x0, 0.5 * (left[0] + left[1])],
            [x1, 0.5 * (right[0] + right[1])],
            [0.5 * (top[0] + top[1]), y0],
            [0.5 * (bottom[0] + bottom[1]), y1],
        ] {
            // Vertices first; the midpoints only while there is room (module doc).
            f.push(p);
        }
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(min: [f64; 2], max: [f64; 2]) -> PixelRect {
        PixelRect { min, max }
    }

    #[test]
    fn a_rectangle_probes_its_corners_and_edge_midpoints() {
        let f = Footprint::of_rect(&rect([0.0, 0.0], [4.0, 2.0]));
        let mut got: Vec<[f64; 2]> = f.points().to_vec();
        got.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let mut want = vec![
            [0.0, 0.0],
            [4.0, 0.0],
            [0.0, 2.0],
            [4.0, 2.0],
            [2.0, 0.0],
            [2.0, 2.0],
            [0.0, 1.0],
            [4.0, 1.0],
        ];
        want.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_eq!(got, want);
        assert!((f.reach_px([2.0, 1.0]) - 5f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_cross_cuts_the_corners_and_keeps_its_arms() {
        // Arms of a plus sign: x −6…6 at y −2…2, and y −6…6 at x −2…2.
        let mut o = Octagon::default();
        o.add_block([-6.0, 6.0], [-2.0, 2.0]);
        o.add_block([-2.0, 2.0], [-6.0, 6.0]);
        let f = o.footprint();
        // Every arm end is probed …
        assert_eq!(f.points().len(), 8);
        for p in [
            [-6.0, -2.0],
            [-6.0, 2.0],
            [6.0, -2.0],
            [6.0, 2.0],
            [-2.0, -6.0],
            [2.0, -6.0],
            [-2.0, 6.0],
            [2.0, 6.0],
        ] {
            assert!(
                f.points().contains(&p),
                "{p:?} missing from {:?}",
                f.points()
            );
        }
        // … and nothing beyond the cross's hull: no point near the square's corners.
        for p in f.points() {
            assert!(p[0].abs() + p[1].abs() <= 8.0 + 1e-12, "{p:?}");
        }
        // Nearer than the square's corner (6√2).
        assert!(f.reach_px([0.0, 0.0]) < 6.5);
        assert!(f.points().len() <= MAX_POINTS);
        assert_eq!(f.rect(), Some(rect([-6.0, -6.0], [6.0, 6.0])));
    }

    #[test]
    fn an_empty_octagon_says_so() {
        assert!(Octagon::default().is_empty());
        assert!(!Octagon::of_rect(&rect([0.0; 2], [1.0; 2])).is_empty());
    }
}
