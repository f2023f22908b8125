//! The board's printed area: where the tags' ink and the paper alternate below a texel, so no
//! one value describes what a pixel sees there.
//!
//! Why: a tag's cells (3.75 mm for a 30 mm tag36h11) are about as large as a texel at the
//! coarser resolutions, and each view's pixel footprint covers a different share of ink and
//! paper (its size, slant and phase on the board differ from view to view). Such a texel is
//! either never learned (its samples do not agree) or learned from one footprint, and then
//! every other view's pixel "disagrees" with it. Counted as evidence of an object, that left a
//! low, solid slab over the tags: at 612×512 a 4–6 cm³ part over one tag of the sheet's short
//! side stopped `ellipso mesh` on hand-held captures (`HullDisconnected`).
//!
//! Contract:
//! - A texel is *printed* when it lies within one texel of a tag's square (its outer black
//!   border, from the session's board record): the texel itself and the pixel footprints
//!   reaching into it (at most a texel: texels are 1.5 footprints wide) can mix ink and paper.
//! - The *paper* value is the per-band median of the learned texels inside the tags' footprint
//!   that are not printed (the sheet between the tags and under the object's surround).
//! - A pixel that disagrees with its printed texel is *ambiguous* when it is what some mixture
//!   of ink and paper could give: every band at most the paper's value within the agreement
//!   tolerance (ink is darker than paper in every band). Its polarisation contrast is not
//!   tested: the four analyser phases of a superpixel sample points a pixel apart, so across an
//!   ink/paper edge the measured contrast takes any value (the mosaic's false polarisation at
//!   edges, seen as disagreeing pixels ringing every tag). An ambiguous pixel is neither board
//!   nor evidence of an object: it carves nothing, and the view does not count towards the
//!   share of views that must see an object through a node (`carve::field`). A pixel brighter
//!   than the paper stays evidence of an object, printed texel or not; so does every pixel
//!   off the print.

pub use super::appearance::PrintedArea;
use super::appearance::{Agreement, TexelGrid, TexelSample};

/// Signed distance of `p` inside the convex quad `quad` (negative outside), metres.
fn inside_distance(quad: &[[f64; 2]; 4], p: [f64; 2]) -> f64 {
    // orientation of the quad: the sign of its area
    let area: f64 = (0..4)
        .map(|i| {
            let (a, b) = (quad[i], quad[(i + 1) % 4]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum();
    let sign = if area >= 0.0 { 1.0 } else { -1.0 };
    (0..4)
        .map(|i| {
            let (a, b) = (quad[i], quad[(i + 1) % 4]);
            let e = [b[0] - a[0], b[1] - a[1]];
            let len = e[0].hypot(e[1]).max(1e-12);
            // left of the edge for a counter-clockwise quad
            sign * (e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0])) / len
        })
        .fold(f64::INFINITY, f64::min)
}

impl PrintedArea {
    /// The printed texels of `grid` for the tag squares `tags` (board plane, the grid's
    /// frame), and the paper's value from the learned `texels` inside the footprint `[lo, hi]`.
    pub fn new(
        grid: &TexelGrid,
        tags: &[[[f64; 2]; 4]],
        texels: &[Option<TexelSample>],
        [lo, hi]: [[f64; 2]; 2],
    ) -> Self {
        // the texel's half diagonal plus one texel of footprint reach
        let reach = grid.texel_m * (1.0 + std::f64::consts::FRAC_1_SQRT_2);
        let printed: Vec<bool> = (0..grid.len())
            .map(|t| {
                let centre = grid.centre(t);
                tags.iter().any(|q| inside_distance(q, centre) >= -reach)
            })
            .collect();
        let mut bands: [Vec<f32>; 3] = Default::default();
        for (t, texel) in texels.iter().enumerate() {
            let c = grid.centre(t);
            let in_footprint = c[0] >= lo[0] && c[0] <= hi[0] && c[1] >= lo[1] && c[1] <= hi[1];
            if let (Some(s), false, true) = (texel, printed[t], in_footprint) {
                for (band, &v) in bands.iter_mut().zip(&s.value) {
                    band.push(v);
                }
            }
        }
        let paper = (!bands[0].is_empty()).then(|| {
            bands.map(|mut v| {
                v.sort_by(f32::total_cmp);
                v[v.len() / 2]
            })
        });
        Self { printed, paper }
    }

    /// Whether `sample`, which disagrees with texel `texel`, is what ink and paper could give
    /// there (see the module contract).
    pub fn ambiguous(&self, rule: &Agreement, texel: usize, sample: &TexelSample) -> bool {
        let (Some(true), Some(paper)) = (self.printed.get(texel), self.paper.as_ref()) else {
            return false;
        };
        let tol = rule.tolerance_rel();
        // no brighter than the paper in any band
        sample.value[..rule.bands()]
            .iter()
            .zip(paper)
            .all(|(&v, &w)| v <= w * (1.0 + tol) + sample.floor)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::appearance::AppearanceConfig;

    fn sample(v: f32, p: f32) -> TexelSample {
        TexelSample {
            value: [v; 3],
            p,
            floor: 1.0,
            s0_dn: v * 30.0,
        }
    }

    #[test]
    fn a_texel_near_a_tag_is_printed_and_a_mixture_is_ambiguous() {
        let grid = TexelGrid::covering([-0.05, -0.05], [0.05, 0.05], 0.002, 1_000_000);
        let tag = [[0.01, 0.01], [0.04, 0.01], [0.04, 0.04], [0.01, 0.04]];
        let paper = sample(100.0, 0.0);
        let texels = vec![Some(paper); grid.len()];
        let area = PrintedArea::new(&grid, &[tag], &texels, [[-0.05; 2], [0.05; 2]]);
        let on_tag = grid.index([0.02, 0.02]).unwrap();
        let beside = grid.index([0.0115, 0.02]).unwrap();
        let off = grid.index([-0.02, -0.02]).unwrap();
        assert!(area.printed[on_tag] && area.printed[beside] && !area.printed[off]);
        assert_eq!(area.paper.unwrap()[0], 100.0);
        let rule = Agreement::new(&AppearanceConfig::default(), 3, 4095.0);
        // half ink, half paper: ambiguous on the tag, evidence off it
        assert!(area.ambiguous(&rule, on_tag, &sample(52.0, 0.0)));
        assert!(!area.ambiguous(&rule, off, &sample(52.0, 0.0)));
        // brighter than the paper: an object; polarisation proves nothing at ink edges
        assert!(!area.ambiguous(&rule, on_tag, &sample(130.0, 0.0)));
        assert!(area.ambiguous(&rule, on_tag, &sample(90.0, 0.4)));
    }

    #[test]
    fn quad_distance_is_signed_either_winding() {
        let ccw = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let cw = [[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]];
        for q in [ccw, cw] {
            assert!((inside_distance(&q, [0.5, 0.5]) - 0.5).abs() < 1e-12);
            assert!((inside_distance(&q, [1.5, 0.5]) + 0.5).abs() < 1e-12);
        }
    }
}
