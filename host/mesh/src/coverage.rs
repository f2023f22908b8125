//! How well the views cover a region of the carving volume, so that a hull reaching a face of
//! the box, or falling apart, is blamed on what is actually missing: views of that region from
//! its other side, not the object's placement.
//!
//! Contract: [`coverage`] takes the camera centres of the views that see a point (the centre of
//! a carved part: a point at the box's edge is out of the nearest views' images whatever the
//! capture) and measures
//! their azimuths about the board normal (volume z) around that point; [`Coverage::one_sided`]
//! holds when they leave a gap of more than half a turn, or when fewer than `votes` views see it.
//!
//! Why half a turn: a point is carved only where `votes` views see the board through it. Each
//! view's silhouette cone holds the space behind the object along its lines of sight; views
//! whose azimuths span θ < 180° intersect those cones in a wedge that runs on behind the object
//! (for an object of width w, about w / (2·tan(θ/2)) deep, unbounded as θ → 0: a 72° arc of 16
//! photos leaves ≈ 0.7·w), so the hull there is the capture's shadow and reaches the box's
//! faces, or leaves a separate phantom part, with the object placed correctly and alone. Once
//! views surround the point (no gap over 180°) some view looks at the far side of every such
//! wedge and carves it; what still reaches a face is then really there. Fewer views than
//! `votes` seeing a point cannot carve it at all: the same shortage, counted.

use nalgebra::Point3;

/// The views seeing one point of the volume.
#[derive(Clone, Debug, PartialEq)]
pub struct Coverage {
    /// How many views see the point.
    pub views: usize,
    /// The largest azimuth gap between them about the board normal, degrees (360 for one view
    /// or none).
    pub largest_gap_deg: f64,
    /// The azimuth range they cover, degrees, `[from, to]` going counter-clockwise (the
    /// complement of the largest gap); `None` without views.
    pub from_to_deg: Option<[f64; 2]>,
}

impl Coverage {
    /// Whether the views leave the point's far side unseen (module contract).
    pub fn one_sided(&self, votes: usize) -> bool {
        self.views < votes || self.largest_gap_deg > 180.0
    }

    /// `"only 2 frames see it"` or `"the 16 frames that see it all look from azimuths 145° to
    /// 217°, leaving 288° with no view"`.
    pub fn describe(&self, votes: usize) -> String {
        match self.from_to_deg {
            Some([a, b]) if self.views >= votes => format!(
                "the {} frames that see it all look from one side (azimuths {a:.0}° to {b:.0}° \
                 about the board normal, {:.0}° with no view)",
                self.views, self.largest_gap_deg
            ),
            _ => format!(
                "only {} frames see it (carving needs {votes} that see the board through a \
                 point)",
                self.views
            ),
        }
    }
}

/// The coverage of `point` by views whose camera centres are `centres` (volume frame, metres).
pub fn coverage(point: Point3<f64>, centres: impl IntoIterator<Item = Point3<f64>>) -> Coverage {
    let mut az: Vec<f64> = centres
        .into_iter()
        .map(|c| {
            (c.y - point.y)
                .atan2(c.x - point.x)
                .to_degrees()
                .rem_euclid(360.0)
        })
        .collect();
    az.sort_by(f64::total_cmp);
    let views = az.len();
    if views == 0 {
        return Coverage {
            views,
            largest_gap_deg: 360.0,
            from_to_deg: None,
        };
    }
    // the gap after each azimuth, to the next one counter-clockwise
    let (gap, after) = (0..views)
        .map(|i| {
            let next = if i + 1 < views {
                az[i + 1]
            } else {
                az[0] + 360.0
            };
            (next - az[i], i)
        })
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .expect("at least one view");
    let gap = if views == 1 { 360.0 } else { gap };
    Coverage {
        views,
        largest_gap_deg: gap,
        from_to_deg: Some([az[(after + 1) % views], az[after]]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring(azimuths_deg: impl IntoIterator<Item = f64>) -> Vec<Point3<f64>> {
        azimuths_deg
            .into_iter()
            .map(|a| {
                let r = a.to_radians();
                Point3::new(0.45 * r.cos(), 0.45 * r.sin(), 0.26)
            })
            .collect()
    }

    #[test]
    fn an_arc_of_photos_is_one_sided_and_a_ring_is_not() {
        let p = Point3::new(0.0, 0.0, 0.03);
        // the simulator's 16-photo capture: an arc of 72° (145° … 217°)
        let arc = coverage(p, ring((0..16).map(|i| 145.0 + 4.8 * f64::from(i))));
        assert_eq!(arc.views, 16);
        assert!((arc.largest_gap_deg - 288.0).abs() < 1e-9, "{arc:?}");
        assert!(arc.one_sided(3));
        let text = arc.describe(3);
        assert!(text.contains("azimuths 145° to 217°"), "{text}");
        // 16 photos all around: 22.5° apart
        let around = coverage(p, ring((0..16).map(|i| 22.5 * f64::from(i))));
        assert!((around.largest_gap_deg - 22.5).abs() < 1e-9);
        assert!(!around.one_sided(3));
        // three views 120° apart surround the point; two views do not reach the votes
        assert!(!coverage(p, ring([0.0, 120.0, 240.0])).one_sided(3));
        let two = coverage(p, ring([0.0, 180.0]));
        assert!(two.one_sided(3));
        assert!(two.describe(3).starts_with("only 2 frames see it"));
        assert!(coverage(p, []).one_sided(3));
    }
}
