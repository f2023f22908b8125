//! The step's safety nets: a step that would turn triangles over is cut back corner by corner
//! ([`BACKTRACK_FRACTIONS`], [`unfolded_step`]) until none does, and how far a step takes a
//! vertex further outside the hull ([`left_hull_by`]). Pure geometry on position lists; the
//! caller decides what to apply and what to refuse.

use nalgebra::Point3;

use super::super::hull::HullField;
use super::super::integrate::project_inside;

/// The fractions of its solved move a vertex may be cut back to, in turn, where the whole
/// step would turn one of its triangles over. Only the corners of the triangles that fold are
/// cut back (and then the corners of any triangle the cut folds): a sliver next to a
/// silhouette can fold under a step that moves the rest of the surface as it should. Refusing
/// the whole step had ended the update after one step on the demo at 9 389 vertices (observed
/// surface 0.25 mm); shortening the whole step for one sliver applied half of every step there
/// (0.131 mm). The last fraction is 0: the corner stays exactly where it was (not even
/// projected onto the hull), so a triangle with every corner there is the last good mesh's and
/// cannot fold. Refusing the step when ⅛ still folded ended the update before its first step
/// on a 60-photo capture of the demo, where the projection onto the hull folded two slivers of
/// the unobserved underside (observed surface 0.521 mm, normals 1.80°).
pub const BACKTRACK_FRACTIONS: [f64; 4] = [0.5, 0.25, 0.125, 0.0];

/// The step `before → after` with the move of the corners of folding triangles cut back
/// ([`BACKTRACK_FRACTIONS`]) until no triangle turns over, projected inside the hull (except
/// the corners that do not move): the smallest fraction applied, the vertices cut back, the
/// positions and the vertices projected. Ends: each round raises a corner's level, and a
/// triangle with every corner at the last level is the one `before` had.
pub(super) fn unfolded_step(
    triangles: &[[u32; 3]],
    before: &[Point3<f64>],
    after: &[Point3<f64>],
    hull: Option<&HullField>,
) -> Unfolded {
    let fractions = |level: u8| match level {
        0 => 1.0,
        l => BACKTRACK_FRACTIONS[usize::from(l) - 1],
    };
    let last = BACKTRACK_FRACTIONS.len() as u8;
    let mut level = vec![0u8; before.len()];
    loop {
        let mut positions: Vec<Point3<f64>> = before
            .iter()
            .zip(after)
            .zip(&level)
            .map(|((b, a), &l)| b + (a - b) * fractions(l))
            .collect();
        // Between two surfaces inside a hull that is not convex lies a surface that may leave
        // it: projected back as the solve's own result is.
        let projected = hull.map_or(0, |h| project_inside(h, &mut positions));
        for ((p, b), &l) in positions.iter_mut().zip(before).zip(&level) {
            if l == last {
                *p = *b;
            }
        }
        let folded: Vec<&[u32; 3]> = triangles
            .iter()
            .filter(|t| turns_over(before, &positions, t))
            .collect();
        if folded.is_empty() {
            let shortened = level.iter().filter(|&&l| l > 0).count();
            let deepest = level.iter().copied().max().unwrap_or(0);
            return Unfolded {
                fraction: fractions(deepest),
                shortened,
                positions,
                projected,
            };
        }
        for t in folded {
            for &v in t {
                let l = &mut level[v as usize];
                // A folded triangle has a corner below the last level (module doc).
                *l = (*l + 1).min(last);
            }
        }
    }
}

/// How far a step `before → after` takes a vertex further outside the hull than it was (or
/// than the hull's surface, for one that was inside), metres; ≤ 0 when none goes out. A vertex
/// of the input mesh that lies outside (a mesh from elsewhere, the carved mesh's own
/// extraction error, a corner held in place by [`unfolded_step`]) is not a step leaving it.
pub(super) fn left_hull_by(hull: &HullField, before: &[Point3<f64>], after: &[Point3<f64>]) -> f64 {
    before
        .iter()
        .zip(after)
        .map(|(b, a)| hull.value_world(a).0 - hull.value_world(b).0.max(0.0))
        .filter(|d| !d.is_nan())
        .fold(f64::NEG_INFINITY, f64::max)
}

/// What [`unfolded_step`] applied.
pub(super) struct Unfolded {
    /// The smallest fraction of a vertex's move applied.
    pub fraction: f64,
    /// Vertices whose move was cut back.
    pub shortened: usize,
    pub positions: Vec<Point3<f64>>,
    pub projected: usize,
}

/// Whether triangle `t` reverses its orientation between `before` and `after`.
fn turns_over(before: &[Point3<f64>], after: &[Point3<f64>], t: &[u32; 3]) -> bool {
    let normal = |p: &[Point3<f64>]| {
        let [a, b, c] = t.map(|i| p[i as usize]);
        (b - a).cross(&(c - a))
    };
    normal(before).dot(&normal(after)) < 0.0
}

/// Triangles whose orientation reverses between `before` and `after`.
pub(super) fn turned_over(
    triangles: &[[u32; 3]],
    before: &[Point3<f64>],
    after: &[Point3<f64>],
) -> usize {
    triangles
        .iter()
        .filter(|t| turns_over(before, after, t))
        .count()
}
