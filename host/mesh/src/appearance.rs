//! The board's appearance, learned from the capture itself: per texel of the board plane, the
//! value that the views which see it agree on — and the test of one pixel against it.
//!
//! Why learned and not printed: the pattern file says where black and white are, but not what
//! the camera makes of them (blur at cell edges, paper and ink reflectance, the table beyond the
//! sheet, a glossy print). Learning each texel from the views makes the test as tight as the
//! capture allows and works on any planar surround.
//!
//! Contract:
//! - **Units.** A pixel's s0 per colour band (DN) is divided by the view's board scale
//!   (`View::board_scale`: the session's normaliser N — flash distance, angular profile,
//!   exposure, gain, vignetting — times the cosine of the flash's incidence on the board), so a
//!   Lambertian board gives the same value in every view. The polarisation contrast `p` is
//!   compared as is.
//! - **Learning.** Each texel keeps a reservoir of at most `reservoir` samples, one per view at
//!   most, replaced by a seeded hash of (texel, view) once full: deterministic and independent
//!   of the thread count. Views through the object show the object, not the board, and do not
//!   agree with each other; the texel's value is the mean of the largest group of mutually
//!   agreeing samples (the mode, not the mean or median, so a texel hidden from more than half
//!   of its views is still learned right), when that group has at least `min_support` samples
//!   and a third of those kept. Other texels are unknown and never carve.
//! - **Agreement** of two samples: every band within `tolerance_rel` of the larger value plus
//!   a noise floor of `tolerance_dn` DN (converted to each view's units), and, where both are
//!   brighter than `min_polarised_dn`, `p` within `tolerance_polarisation`. A pixel is
//!   *board-consistent* when it agrees with its texel's learned value; where a black pixel
//!   would agree with it too ([`Verdict::Dark`]: the surround beyond a sheet on a dark table)
//!   the texel cannot tell an object's limb — which darkens to black under the near-coaxial
//!   flash — from itself, and the silhouette decides how far such pixels count
//!   (`silhouette::classify`).
//! - **Memory** is bounded by `max_texels × reservoir × 24 B`; the texel size grows when the
//!   region would need more texels.

use super::frames::{FeatureImage, RayTable, View};
use super::volume::plane_hit;

/// Settings of the appearance model.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AppearanceConfig {
    /// Samples kept per texel.
    pub reservoir: usize,
    /// Largest number of texels (bounds memory).
    pub max_texels: usize,
    /// Smallest texel side, metres.
    pub min_texel_m: f64,
    /// Relative tolerance of agreement.
    pub tolerance_rel: f64,
    /// Noise floor of agreement, DN of a 12-bit frame (scaled to the session's bit depth).
    pub tolerance_dn: f64,
    /// Tolerance of the polarisation contrast.
    pub tolerance_polarisation: f64,
    /// Below this s0 (DN of a 12-bit frame, all bands) the polarisation contrast is not tested.
    pub min_polarised_dn: f64,
    /// Fewest agreeing samples for a texel to be learned.
    pub min_support: usize,
}

impl Default for AppearanceConfig {
    fn default() -> Self {
        Self {
            reservoir: 10,
            max_texels: 200_000,
            min_texel_m: 5e-4,
            tolerance_rel: 0.12,
            tolerance_dn: 8.0,
            tolerance_polarisation: 0.08,
            min_polarised_dn: 200.0,
            min_support: 3,
        }
    }
}

/// A regular grid of square texels on the board plane (volume frame).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct TexelGrid {
    /// Lower corner `(x, y)`, metres.
    pub origin_m: [f64; 2],
    /// Texel side, metres.
    pub texel_m: f64,
    /// Texels along x.
    pub nx: usize,
    /// Texels along y.
    pub ny: usize,
}

impl TexelGrid {
    /// A grid over `[lo, hi]` with texels of at least `min_texel_m` and at most `max_texels`.
    pub fn covering(lo: [f64; 2], hi: [f64; 2], min_texel_m: f64, max_texels: usize) -> Self {
        let (w, h) = ((hi[0] - lo[0]).max(1e-6), (hi[1] - lo[1]).max(1e-6));
        let texel_m = min_texel_m.max((w * h / max_texels.max(1) as f64).sqrt());
        // ceil may exceed the budget by a row and a column; the texel grows until it fits.
        let mut t = texel_m;
        loop {
            let (nx, ny) = ((w / t).ceil() as usize, (h / t).ceil() as usize);
            if nx * ny <= max_texels.max(1) {
                return TexelGrid {
                    origin_m: lo,
                    texel_m: t,
                    nx,
                    ny,
                };
            }
            t *= 1.01;
        }
    }

    /// The texel holding board point `(x, y)`.
    pub fn index(&self, xy: [f64; 2]) -> Option<usize> {
        let u = (xy[0] - self.origin_m[0]) / self.texel_m;
        let v = (xy[1] - self.origin_m[1]) / self.texel_m;
        (u >= 0.0 && v >= 0.0 && u < self.nx as f64 && v < self.ny as f64)
            .then(|| v as usize * self.nx + u as usize)
    }

    /// The centre of texel `t`, metres.
    pub fn centre(&self, t: usize) -> [f64; 2] {
        let (i, j) = (t % self.nx.max(1), t / self.nx.max(1));
        [
            self.origin_m[0] + (i as f64 + 0.5) * self.texel_m,
            self.origin_m[1] + (j as f64 + 0.5) * self.texel_m,
        ]
    }

    /// Number of texels.
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    /// True for a grid without texels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// One observation of a texel: appearance per band, `p`, its noise floor (appearance units)
/// and its total s0 (DN).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TexelSample {
    /// s0 per band over the board scale.
    pub value: [f32; 3],
    /// Polarisation contrast.
    pub p: f32,
    /// Noise floor in the units of `value`.
    pub floor: f32,
    /// s0 summed over bands, DN.
    pub s0_dn: f32,
}

/// What a pixel says of the board point its ray meets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// It agrees with the learned texel, and a black pixel would not.
    Board,
    /// It disagrees: something else is in front of the board.
    Other,
    /// It agrees, but so would a black pixel: the texel is too dark to tell an object's limb
    /// (which darkens to black under the near-coaxial flash) from itself.
    Dark,
}

/// A disagreeing pixel is *dim* below this many times the darkest value a black pixel cannot
/// be told from ([`Agreement::dim`]).
pub const DIM_FACTOR: f32 = 4.0;

/// The agreement rule of the module contract, fixed for one session.
#[derive(Clone, Copy, Debug)]
pub struct Agreement {
    bands: usize,
    tolerance_rel: f32,
    tolerance_p: f32,
    min_polarised_dn: f32,
}

impl Agreement {
    /// The rule for `bands` colour bands; DN thresholds scaled from 12 bits to `full_scale_dn`.
    pub fn new(config: &AppearanceConfig, bands: usize, full_scale_dn: f64) -> Self {
        Self {
            bands: bands.clamp(1, 3),
            tolerance_rel: config.tolerance_rel as f32,
            tolerance_p: config.tolerance_polarisation as f32,
            min_polarised_dn: (config.min_polarised_dn * full_scale_dn / 4095.0) as f32,
        }
    }

    /// Colour bands compared.
    pub fn bands(&self) -> usize {
        self.bands
    }

    /// Relative tolerance of agreement.
    pub fn tolerance_rel(&self) -> f32 {
        self.tolerance_rel
    }

    /// What `sample` says of its texel's `learned` value (see [`Verdict`]).
    pub fn verdict(&self, sample: &TexelSample, learned: &TexelSample) -> Verdict {
        if !self.agree(sample, learned) {
            return Verdict::Other;
        }
        let black = TexelSample {
            value: [0.0; 3],
            s0_dn: 0.0,
            ..*sample
        };
        if self.agree(&black, learned) {
            Verdict::Dark
        } else {
            Verdict::Board
        }
    }

    /// Whether `sample` is dim: every band below [`DIM_FACTOR`] times the darkest value a
    /// black pixel cannot be told from (`floor / (1 − tolerance_rel)`) — a limb that is still
    /// darkening there.
    pub fn dim(&self, sample: &TexelSample) -> bool {
        let limit = DIM_FACTOR * sample.floor / (1.0 - self.tolerance_rel).max(1e-3);
        sample.value[..self.bands].iter().all(|&v| v < limit)
    }

    /// Whether two samples agree.
    pub fn agree(&self, a: &TexelSample, b: &TexelSample) -> bool {
        let floor = a.floor.max(b.floor);
        for k in 0..self.bands {
            let (x, y) = (a.value[k], b.value[k]);
            if (x - y).abs() > self.tolerance_rel * x.max(y).max(0.0) + floor {
                return false;
            }
        }
        a.s0_dn.min(b.s0_dn) < self.min_polarised_dn || (a.p - b.p).abs() <= self.tolerance_p
    }
}

/// The sample a pixel of `view` gives of the board point its ray meets, with its texel.
pub fn pixel_sample(
    grid: &TexelGrid,
    rays: &RayTable,
    view: &View,
    image: &FeatureImage,
    k: usize,
    floor_dn: f64,
) -> Option<(usize, TexelSample)> {
    if image.saturated[k] {
        return None;
    }
    let xy = rays.rays[k];
    if !xy[0].is_finite() {
        return None;
    }
    let hit = plane_hit(&view.centre, &view.ray(xy))?;
    let texel = grid.index(hit)?;
    let scale = view.board_scale(hit[0], hit[1])?;
    let f = image.features[k];
    let mut value = [0f32; 3];
    for (v, dn) in value.iter_mut().zip(f).take(image.bands) {
        *v = (f64::from(dn) / scale) as f32;
    }
    let s0_dn = f[..image.bands].iter().sum();
    Some((
        texel,
        TexelSample {
            value,
            p: f[3],
            floor: (floor_dn / scale) as f32,
            s0_dn,
        },
    ))
}

/// Texel reservoirs while the views stream past.
pub struct Reservoirs {
    grid: TexelGrid,
    per_texel: usize,
    seen: Vec<u32>,
    last_view: Vec<u32>,
    slots: Vec<TexelSample>,
}

/// SplitMix64 finaliser: a seeded, order-free hash of (texel, view).
fn mix(texel: usize, view: u32) -> u64 {
    let mut z = (texel as u64) ^ (u64::from(view) << 40) ^ 0x9e37_79b9_7f4a_7c15;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Reservoirs {
    /// Empty reservoirs of `per_texel` samples over `grid`.
    pub fn new(grid: TexelGrid, per_texel: usize) -> Self {
        let per_texel = per_texel.max(1);
        Self {
            grid,
            per_texel,
            seen: vec![0; grid.len()],
            last_view: vec![u32::MAX; grid.len()],
            slots: vec![TexelSample::default(); grid.len() * per_texel],
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.slots.len() * std::mem::size_of::<TexelSample>() + self.seen.len() * 8
    }

    /// Adds view `view`'s samples (one per texel: the first pixel of the view on it counts).
    pub fn add(&mut self, view: u32, samples: &[(usize, TexelSample)]) {
        for &(texel, sample) in samples {
            if self.last_view[texel] == view {
                continue;
            }
            self.last_view[texel] = view;
            let n = self.seen[texel] as usize;
            let slot = if n < self.per_texel {
                Some(n)
            } else {
                let j = (mix(texel, view) % (n as u64 + 1)) as usize;
                (j < self.per_texel).then_some(j)
            };
            if let Some(j) = slot {
                self.slots[texel * self.per_texel + j] = sample;
            }
            self.seen[texel] = self.seen[texel].saturating_add(1);
        }
    }

    /// The learned board (see the module contract).
    pub fn learn(self, rule: &Agreement, min_support: usize) -> Board {
        let r = self.per_texel;
        let texels: Vec<Option<TexelSample>> = self
            .seen
            .iter()
            .enumerate()
            .map(|(t, &seen)| {
                let kept = &self.slots[t * r..t * r + (seen as usize).min(r)];
                mode(kept, rule, min_support)
            })
            .collect();
        let learned = texels.iter().filter(|t| t.is_some()).count();
        Board {
            grid: self.grid,
            texels,
            learned,
            print: Default::default(),
        }
    }
}

/// The mean of the largest group of samples that agree with one of them, if big enough.
fn mode(kept: &[TexelSample], rule: &Agreement, min_support: usize) -> Option<TexelSample> {
    let mut best: Option<(usize, usize)> = None;
    for (i, a) in kept.iter().enumerate() {
        let support = kept.iter().filter(|b| rule.agree(a, b)).count();
        if best.is_none_or(|(_, s)| support > s) {
            best = Some((i, support));
        }
    }
    let (i, support) = best?;
    if support < min_support.max(1) || 3 * support < kept.len() {
        return None;
    }
    let group: Vec<&TexelSample> = kept.iter().filter(|b| rule.agree(&kept[i], b)).collect();
    let n = group.len() as f32;
    let mut mean = TexelSample::default();
    for s in &group {
        for k in 0..3 {
            mean.value[k] += s.value[k] / n;
        }
        mean.p += s.p / n;
        mean.s0_dn += s.s0_dn / n;
    }
    // The reference carries no noise floor of its own: each pixel brings its view's.
    mean.floor = 0.0;
    Some(mean)
}

/// The learned board appearance.
pub struct Board {
    /// The texel grid.
    pub grid: TexelGrid,
    /// Per texel its value, or `None` when unknown.
    pub texels: Vec<Option<TexelSample>>,
    /// Number of learned texels.
    pub learned: usize,
    /// Where tags are printed, and the paper's value ([`crate::print`]); empty when not known.
    pub print: PrintedArea,
}

impl Board {
    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.texels.len() * std::mem::size_of::<Option<TexelSample>>()
    }
}

/// Where the board is printed, and the paper's value: computed and read by [`crate::print`]
/// (its contract), held here by the [`Board`] it belongs to.
#[derive(Clone, Debug, Default)]
pub struct PrintedArea {
    /// Per texel: within one texel of a tag's square.
    pub printed: Vec<bool>,
    /// The paper's learned value per band (`None` when no unprinted texel was learned).
    pub paper: Option<[f32; 3]>,
}
