//! Where a view's silhouette edge lies inside its boundary pixels, from what those pixels see.
//!
//! A pixel on the silhouette's edge sees a mix of the object and the board behind it. With
//! the board's learned value `T` at the pixel (its texel) and the object's value `O` next to
//! it (the not-board pixel one step further into the object), the pixel's value is
//! `v = (1 − c)·T + c·O` for the fraction `c` of it the object covers (light adds linearly
//! over a pixel: the superpixel features are sums of raw DN). The least-squares `c` over the
//! colour bands is `Σ(v − T)(O − T) / Σ(O − T)²`.
//!
//! Contract:
//! - For each pair of 4-neighbours `b` (board) and `o` (not board, disagreeing with its texel)
//!   whose next pixel `o₂ = o + (o − b)` also disagrees, the edge lies `δ = (1 − c_o) − c_b`
//!   pixels from the `b|o` boundary into `o` (`c_o`: the object's cover of `o`, `c_b` of `b`,
//!   each clamped to [0, 1]). A straight edge crossing `o` gives `c_b = 0`, `δ = 1 − c_o`; one
//!   crossing `b` gives `c_o = 1`, `δ = −c_b`; a blurred edge spreads its cover over both.
//! - `O` is taken one pixel inside the object, but a limb darkens towards its edge (the
//!   surface turns away from the near-coaxial flash), so the object's part of `o` is darker
//!   than `O`. Against a board brighter than the object that changes `T − O` little and the
//!   cover holds; against a board darker than the object (the void beyond the board behind a
//!   low view's top limb, black ink behind a white object) it is the whole contrast, the cover
//!   comes out too small and the edge too deep. There `δ` =
//!   [`DARK_BOARD_OFFSET_PX`]: the pixel boundary, the loose side of the unknown edge (the
//!   hull keeps the tighter views). Measured on the demo session against the true silhouettes
//!   (15 views, 2186 pairs): median error of δ 0.00 … −0.06 px where the board is brighter,
//!   +0.35 … +0.54 px (too deep) where it is darker.
//! - A pair is used only where the object stands out from the board: `|O − T|` at least
//!   [`MIN_CONTRAST`] times the agreement threshold at `T` (tolerance × the brighter band +
//!   the noise floor) at both `b` and `o`, and both texels learned. Elsewhere (a dark rim in
//!   front of black ink, an unknown texel) the pixel keeps the configured
//!   `MeshConfig::edge_inset_px`.
//! - Each boundary pixel gets the mean `δ` of its pairs ([`EdgeOffsets`]); the signed
//!   distance adds it in place of the fixed inset (`silhouette::SignedDistance`), so the
//!   zero crossing between `b` and `o` lies at the measured edge. `δ` only moves the
//!   crossing within a pixel of the boundary: the signs of pixels further away never change.
//!
//! Why: a visual hull keeps, at each point, the tightest of the views that graze it (the k-th
//! vote), so it follows the tail of the silhouettes' edge errors, not their mean. With whole
//! pixels and one fixed inset, each edge is off by up to half a pixel either way, and the
//! low views' top limbs against the dark void were carved tight: the demo's hull lay 0.12 mm
//! inside the object where its normal is 0.6–0.9 up (docs/mesh.md "Edge: where inside its boundary pixels").

use super::appearance::{Agreement, TexelSample};

/// Contrast between object and board, in agreement thresholds, below which a pair's cover is
/// not measured.
pub const MIN_CONTRAST: f32 = 2.0;

/// The edge offset where the board behind is darker than the object: the pixel boundary.
pub const DARK_BOARD_OFFSET_PX: f32 = 0.0;

/// The boundary pixels' edge offsets of one view: `(pixel index, δ)` sorted by index.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EdgeOffsets(pub Vec<(u32, f32)>);

impl EdgeOffsets {
    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.0.len() * 8
    }
}

/// What the edge measurement needs of one pixel: its sample and its texel's learned value.
#[derive(Clone, Copy, Debug)]
pub struct EdgePixel {
    /// The pixel's sample (board units).
    pub sample: TexelSample,
    /// The learned board value where its ray meets the board, if known.
    pub board: Option<TexelSample>,
}

/// The object's cover of a pixel of value `v` over board `t` next to object `o`, or `None`
/// where the object does not stand out from the board (module contract).
fn cover(rule: &Agreement, v: &TexelSample, t: &TexelSample, o: &TexelSample) -> Option<f32> {
    let (mut num, mut den, mut bright) = (0f32, 0f32, 0f32);
    for k in 0..rule.bands() {
        let d = o.value[k] - t.value[k];
        num += (v.value[k] - t.value[k]) * d;
        den += d * d;
        bright = bright.max(t.value[k]).max(o.value[k]);
    }
    let threshold = rule.tolerance_rel() * bright + t.floor.max(v.floor);
    // den ≥ (2·threshold)² > 0 past this test, so the division is safe
    (den.sqrt() >= MIN_CONTRAST * threshold && den > 0.0).then(|| (num / den).clamp(0.0, 1.0))
}

/// The edge offsets of a `width × height` view (module contract): `is_board` and `disagrees`
/// are the view's final masks, `pixel(k)` the sample of pixel `k` (`None`: no sample).
pub fn edge_offsets(
    rule: &Agreement,
    width: usize,
    height: usize,
    is_board: impl Fn(isize, isize) -> bool,
    disagrees: impl Fn(isize, isize) -> bool,
    pixel: impl Fn(usize) -> Option<EdgePixel>,
) -> EdgeOffsets {
    let mut pairs: Vec<(u32, f32)> = Vec::new();
    let index = |x: isize, y: isize| y as usize * width + x as usize;
    for y in 0..height as isize {
        for x in 0..width as isize {
            if !is_board(x, y) {
                continue;
            }
            for (dx, dy) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                let (ox, oy, o2x, o2y) = (x + dx, y + dy, x + 2 * dx, y + 2 * dy);
                // a pixel that disagrees is never board (the masks are exclusive)
                if !disagrees(ox, oy) || !disagrees(o2x, o2y) {
                    continue;
                }
                let (Some(b), Some(o), Some(o2)) = (
                    pixel(index(x, y)),
                    pixel(index(ox, oy)),
                    pixel(index(o2x, o2y)),
                ) else {
                    continue;
                };
                let (Some(tb), Some(to)) = (b.board, o.board) else {
                    continue;
                };
                let (Some(cb), Some(co)) = (
                    cover(rule, &b.sample, &tb, &o2.sample),
                    cover(rule, &o.sample, &to, &o2.sample),
                ) else {
                    continue;
                };
                // the board behind darker than the object: the rim's own darkening decides
                // the mix (module contract), so the edge goes on the pixel boundary
                let brightness = |t: &TexelSample| t.value[..rule.bands()].iter().sum::<f32>();
                let delta = if brightness(&tb).min(brightness(&to)) > brightness(&o2.sample) {
                    (1.0 - co) - cb
                } else {
                    DARK_BOARD_OFFSET_PX
                };
                pairs.push((index(x, y) as u32, delta));
                pairs.push((index(ox, oy) as u32, delta));
            }
        }
    }
    // each boundary pixel: the mean δ of its pairs
    pairs.sort_unstable_by_key(|&(k, _)| k);
    EdgeOffsets(
        pairs
            .chunk_by(|a, b| a.0 == b.0)
            .map(|g| (g[0].0, g.iter().map(|p| p.1).sum::<f32>() / g.len() as f32))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::appearance::AppearanceConfig;

    /// The offset of pixel `k`, if it was measured.
    fn get(offsets: &EdgeOffsets, k: usize) -> Option<f32> {
        offsets
            .0
            .iter()
            .find(|&&(i, _)| i as usize == k)
            .map(|p| p.1)
    }

    fn sample(v: f32) -> TexelSample {
        TexelSample {
            value: [v, v, v],
            p: 0.0,
            floor: 0.002,
            s0_dn: 3000.0 * v,
        }
    }

    /// A view of a vertical edge at `x = edge` (pixels left of it board of value `t`, right
    /// of it object of value `o`), classified with the agreement rule: in front of a brighter
    /// board the measured offsets put the edge back where it is, wherever it crosses the
    /// pixel; in front of a darker one the edge stays on the pixel boundary.
    #[test]
    fn a_straight_edge_is_found_within_its_pixel() {
        let rule = Agreement::new(&AppearanceConfig::default(), 3, 4095.0);
        let (w, h) = (12usize, 3usize);
        for (t, o) in [(0.8f32, 0.05f32), (0.3, 0.9)] {
            for edge in [5.0f32, 5.2, 5.5, 5.8, 5.95] {
                // pixel x covers [x − ½, x + ½]; the object covers x > edge
                let cov = |x: isize| ((x as f32 + 0.5) - edge).clamp(0.0, 1.0);
                let value = |x: isize| (1.0 - cov(x)) * t + cov(x) * o;
                let agrees = |x: isize| rule.agree(&sample(value(x)), &sample(t));
                let offsets = edge_offsets(
                    &rule,
                    w,
                    h,
                    |x, y| y >= 0 && (y as usize) < h && x >= 0 && agrees(x),
                    |x, y| y >= 0 && (y as usize) < h && (x as usize) < w && !agrees(x),
                    |k| {
                        let x = (k % w) as isize;
                        Some(EdgePixel {
                            sample: sample(value(x)),
                            board: Some(sample(t)),
                        })
                    },
                );
                // the last board pixel and the first one that is not
                let b = (0..w as isize).take_while(|&x| agrees(x)).last().unwrap();
                let found = b as f32 + 0.5 + get(&offsets, w + b as usize).unwrap();
                let expected = if t > o { edge } else { b as f32 + 0.5 };
                assert!(
                    (found - expected).abs() < 1e-4,
                    "t {t} o {o} edge {edge}: found {found}, expected {expected}"
                );
                assert_eq!(
                    get(&offsets, w + b as usize),
                    get(&offsets, w + b as usize + 1)
                );
            }
        }
    }

    #[test]
    fn no_contrast_no_offset() {
        let rule = Agreement::new(&AppearanceConfig::default(), 3, 4095.0);
        // a dark object in front of dark ink: it differs (p, say) but not by enough to measure
        let (t, o) = (sample(0.05), sample(0.045));
        assert_eq!(cover(&rule, &sample(0.047), &t, &o), None);
        assert_eq!(
            cover(&rule, &sample(0.4), &sample(0.8), &sample(0.0)),
            Some(0.5)
        );
    }
}
