//! A rectangle of raw pixel positions: a frame crop's region and a footprint's bounds.

/// A rectangle of raw pixel positions, `min` to `max` inclusive (`x` right, `y` down).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelRect {
    /// Smallest x and y, px.
    pub min: [f64; 2],
    /// Largest x and y, px.
    pub max: [f64; 2],
}

impl PixelRect {
    /// The smallest rectangle holding every point of `points` (`None` without one).
    pub fn around(points: impl IntoIterator<Item = [f64; 2]>) -> Option<PixelRect> {
        let mut rect: Option<PixelRect> = None;
        for p in points {
            let r = rect.get_or_insert(PixelRect { min: p, max: p });
            r.min = [r.min[0].min(p[0]), r.min[1].min(p[1])];
            r.max = [r.max[0].max(p[0]), r.max[1].max(p[1])];
        }
        rect
    }

    /// This rectangle grown by `margin_px` on every side.
    pub fn grown(&self, margin_px: f64) -> PixelRect {
        PixelRect {
            min: self.min.map(|v| v - margin_px),
            max: self.max.map(|v| v + margin_px),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_rect_around_points() {
        assert_eq!(PixelRect::around(std::iter::empty()), None);
        let r = PixelRect::around([[3.0, 1.0], [-1.0, 5.0], [2.0, 2.0]]).unwrap();
        assert_eq!(r.min, [-1.0, 1.0]);
        assert_eq!(r.max, [3.0, 5.0]);
        assert_eq!(r.grown(1.0).min, [-2.0, 0.0]);
    }
}
