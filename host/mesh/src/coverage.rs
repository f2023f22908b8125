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
//!
//! The same shortage from above: views all around but all steep (a top-down capture) bound the
//! hull's height only through their lowest elevation `e`. Each view's silhouette of a round
//! object of radius `r` is a cylinder tilted `e` from the board; a point on the vertical
//! through the object's centre at height `z` above it lies inside the cylinder of every azimuth
//! while `z·cos e ≤ r`, so the hull runs up to `r / cos e` above the centre instead of `r`.
//! Above [`STEEP_ELEVATION_DEG`] (60°: `1/cos e > 2`) it rises more than the object's own
//! height over its top — the phantom that reaches the box's top face or stands apart — and the
//! capture's steepness, not the object, is blamed.

use nalgebra::Point3;

/// Lowest view elevation (degrees above the board, seen from the point) above which the views
/// cannot bound the hull's height: it rises to `1 / cos e > 2` radii above a round object's
/// centre (module doc).
pub const STEEP_ELEVATION_DEG: f64 = 60.0;

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
    /// The lowest elevation of a view above the board plane through the point, degrees (seen
    /// from the point); `None` without views.
    pub lowest_elevation_deg: Option<f64>,
}

impl Coverage {
    /// Whether the views leave the point's far side unseen (module contract).
    pub fn one_sided(&self, votes: usize) -> bool {
        self.views < votes || self.largest_gap_deg > 180.0 || self.steep_only()
    }

    /// Whether every view looks from above [`STEEP_ELEVATION_DEG`] (module doc).
    pub fn steep_only(&self) -> bool {
        self.lowest_elevation_deg
            .is_some_and(|e| e > STEEP_ELEVATION_DEG)
    }

    /// Views all around the point (no gap over half a turn), but all steep: the steepness,
    /// not a missing side, is what the capture lacks.
    fn steep_all_around(&self) -> bool {
        self.steep_only() && self.largest_gap_deg <= 180.0
    }

    /// What the capture lacks, as advice: views from lower down when every view is steep (and
    /// they surround the point), else views from its other side.
    pub fn advice(&self) -> &'static str {
        if self.steep_all_around() {
            "the space above and beside it was only ever seen from above, so it could not be \
             carved. Take photos from lower down as well (20–45° above the board) and mesh again"
        } else {
            "the space behind it was never seen from its other side, so it could not be carved. \
             Take photos from all around the object (no gap of more than half a turn) and mesh \
             again"
        }
    }

    /// `"only 2 frames see it"` or `"the 16 frames that see it all look from azimuths 145° to
    /// 217°, leaving 288° with no view"`.
    pub fn describe(&self, votes: usize) -> String {
        match (self.from_to_deg, self.lowest_elevation_deg) {
            (Some(_), Some(e)) if self.views >= votes && self.steep_all_around() => {
                format!(
                    "the {} frames that see it all look from above (the lowest {e:.0}° above the \
                     board: views all steeper than {STEEP_ELEVATION_DEG:.0}° let the hull rise \
                     over twice the object's height)",
                    self.views
                )
            }
            (Some([a, b]), _) if self.views >= votes => format!(
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
    let centres: Vec<Point3<f64>> = centres.into_iter().collect();
    let mut az: Vec<f64> = centres
        .iter()
        .map(|c| {
            (c.y - point.y)
                .atan2(c.x - point.x)
                .to_degrees()
                .rem_euclid(360.0)
        })
        .collect();
    // atan2 of the height over the horizontal distance: a view straight above is 90°
    let elevations: Vec<f64> = centres
        .iter()
        .map(|c| {
            (c.z - point.z)
                .atan2((c.x - point.x).hypot(c.y - point.y))
                .to_degrees()
        })
        .collect();
    az.sort_by(f64::total_cmp);
    let lowest_elevation_deg = elevations.into_iter().reduce(f64::min);
    let views = az.len();
    if views == 0 {
        return Coverage {
            views,
            largest_gap_deg: 360.0,
            from_to_deg: None,
            lowest_elevation_deg,
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
        lowest_elevation_deg,
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
        assert!(arc.advice().contains("all around the object"));
        let two = coverage(p, ring([0.0, 180.0]));
        assert!(two.one_sided(3));
        assert!(two.describe(3).starts_with("only 2 frames see it"));
        assert!(coverage(p, []).one_sided(3));
    }

    #[test]
    fn views_all_around_but_all_steep_are_blamed_and_an_orbit_from_low_down_is_not() {
        let p = Point3::new(0.0, 0.0, 0.04);
        let at = |az: f64, el: f64| {
            let (a, e) = (az.to_radians(), el.to_radians());
            Point3::new(
                0.5 * e.cos() * a.cos(),
                0.5 * e.cos() * a.sin(),
                0.04 + 0.5 * e.sin(),
            )
        };
        // a top-down orbit: 40 views all around at 78–88°
        let steep = coverage(
            p,
            (0..40).map(|i| at(9.0 * f64::from(i), 78.0 + f64::from(i % 11))),
        );
        assert!(steep.largest_gap_deg < 180.0, "{steep:?}");
        assert!((steep.lowest_elevation_deg.unwrap() - 78.0).abs() < 1e-9);
        assert!(steep.steep_only() && steep.one_sided(3));
        let text = steep.describe(3);
        assert!(
            text.contains("all look from above (the lowest 78°"),
            "{text}"
        );
        // the demo's orbit: 20–70°, and one steep view among low ones
        let orbit = coverage(
            p,
            (0..40).map(|i| at(18.0 * f64::from(i), 20.0 + 1.25 * f64::from(i))),
        );
        assert!(!orbit.steep_only() && !orbit.one_sided(3), "{orbit:?}");
        let mixed = coverage(p, [at(0.0, 85.0), at(120.0, 30.0), at(240.0, 85.0)]);
        assert!(!mixed.steep_only());
    }
}
