//! Per-output-pixel validity mask: a bit set of reasons why a pixel must not be trusted.
//!
//! Contract: a pixel is valid exactly when its mask is empty ([`PixelMask::VALID`]). Masked pixels
//! still carry finite numbers in every output plane (for display), but fits and statistics must
//! skip them. Reasons are independent bits, so a pixel can be, say, both saturated and
//! inconsistent; [`MaskSummary`] counts each reason separately.

use serde::Serialize;

/// Why an output pixel is invalid. Each reason is one bit of [`PixelMask`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskReason {
    /// A raw analyser sample that feeds this pixel reached the saturation level.
    Saturated,
    /// Mean analyser intensity s0/2 below the dark threshold: DoLP and AoLP are noise.
    Dark,
    /// Interpolation found no raw sample of some analyser in reach (tiny frames only).
    NoSamples,
    /// Measured √(s1²+s2²) exceeds s0 (DoLP > 1): no physical light gives these four values.
    Unphysical,
    /// |I0 + I90 − I45 − I135| above the configured limit (misregistration, wrong phase, clipping).
    Inconsistent,
}

impl MaskReason {
    /// All reasons in bit order.
    pub const ALL: [MaskReason; 5] = [
        MaskReason::Saturated,
        MaskReason::Dark,
        MaskReason::NoSamples,
        MaskReason::Unphysical,
        MaskReason::Inconsistent,
    ];

    /// The bit of this reason in [`PixelMask`].
    pub const fn bit(self) -> u8 {
        match self {
            MaskReason::Saturated => 1,
            MaskReason::Dark => 2,
            MaskReason::NoSamples => 4,
            MaskReason::Unphysical => 8,
            MaskReason::Inconsistent => 16,
        }
    }

    /// snake_case name, as used in `summary.json`.
    pub fn name(self) -> &'static str {
        match self {
            MaskReason::Saturated => "saturated",
            MaskReason::Dark => "dark",
            MaskReason::NoSamples => "no_samples",
            MaskReason::Unphysical => "unphysical",
            MaskReason::Inconsistent => "inconsistent",
        }
    }
}

/// Bit set of [`MaskReason`]s for one output pixel; empty means valid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[repr(transparent)]
pub struct PixelMask(pub u8);

impl PixelMask {
    /// No reason: the pixel is valid.
    pub const VALID: PixelMask = PixelMask(0);

    /// A mask holding exactly `reason`.
    pub const fn only(reason: MaskReason) -> PixelMask {
        PixelMask(reason.bit())
    }

    /// True when no reason is set.
    pub const fn is_valid(self) -> bool {
        self.0 == 0
    }

    /// True when `reason` is set.
    pub const fn has(self, reason: MaskReason) -> bool {
        self.0 & reason.bit() != 0
    }

    /// This mask with `reason` added.
    #[must_use]
    pub const fn with(self, reason: MaskReason) -> PixelMask {
        PixelMask(self.0 | reason.bit())
    }

    /// The reasons set, in bit order.
    pub fn reasons(self) -> impl Iterator<Item = MaskReason> {
        MaskReason::ALL.into_iter().filter(move |r| self.has(*r))
    }
}

/// Counts of masked pixels per reason over one plane.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MaskSummary {
    /// Number of pixels summarised.
    pub pixels: usize,
    /// Number of valid pixels.
    pub valid: usize,
    /// Pixels carrying each reason (a pixel may count under several), in [`MaskReason::ALL`] order.
    pub per_reason: Vec<(MaskReason, usize)>,
}

impl MaskSummary {
    /// Counts `masks`.
    pub fn of(masks: &[PixelMask]) -> MaskSummary {
        let mut per_bit = [0usize; 8];
        let mut valid = 0usize;
        for m in masks {
            valid += usize::from(m.is_valid());
            for (bit, count) in per_bit.iter_mut().enumerate() {
                *count += usize::from(m.0 & (1 << bit) != 0);
            }
        }
        let per_reason = MaskReason::ALL
            .iter()
            .map(|r| (*r, per_bit[r.bit().trailing_zeros() as usize]))
            .collect();
        MaskSummary {
            pixels: masks.len(),
            valid,
            per_reason,
        }
    }

    /// Fraction (0..=1) of pixels carrying `reason`; 0 for an empty plane.
    pub fn fraction(&self, reason: MaskReason) -> f64 {
        let count = self
            .per_reason
            .iter()
            .find(|(r, _)| *r == reason)
            .map_or(0, |(_, c)| *c);
        fraction(count, self.pixels)
    }

    /// Fraction (0..=1) of valid pixels; 0 for an empty plane.
    pub fn valid_fraction(&self) -> f64 {
        fraction(self.valid, self.pixels)
    }
}

/// `count / total`, with 0 for an empty total (no division by zero).
fn fraction(count: usize, total: usize) -> f64 {
    if total == 0 {
        0.0
    } else {
        count as f64 / total as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_are_distinct_bits() {
        let mut all = 0u8;
        for r in MaskReason::ALL {
            assert_eq!(r.bit().count_ones(), 1);
            assert_eq!(all & r.bit(), 0, "{r:?} reuses a bit");
            all |= r.bit();
        }
    }

    #[test]
    fn mask_set_operations() {
        let m = PixelMask::VALID
            .with(MaskReason::Saturated)
            .with(MaskReason::Inconsistent);
        assert!(!m.is_valid());
        assert!(m.has(MaskReason::Saturated) && m.has(MaskReason::Inconsistent));
        assert!(!m.has(MaskReason::Dark));
        let reasons: Vec<_> = m.reasons().collect();
        assert_eq!(reasons, [MaskReason::Saturated, MaskReason::Inconsistent]);
        assert!(PixelMask::VALID.is_valid());
        assert_eq!(PixelMask::only(MaskReason::Dark).0, MaskReason::Dark.bit());
    }

    #[test]
    fn summary_counts_each_reason() {
        let masks = [
            PixelMask::VALID,
            PixelMask::only(MaskReason::Dark),
            PixelMask::only(MaskReason::Dark).with(MaskReason::Saturated),
            PixelMask::VALID,
        ];
        let s = MaskSummary::of(&masks);
        assert_eq!(s.pixels, 4);
        assert_eq!(s.valid, 2);
        assert_eq!(s.fraction(MaskReason::Dark), 0.5);
        assert_eq!(s.fraction(MaskReason::Saturated), 0.25);
        assert_eq!(s.fraction(MaskReason::NoSamples), 0.0);
        assert_eq!(s.valid_fraction(), 0.5);
        assert_eq!(MaskSummary::of(&[]).valid_fraction(), 0.0);
    }
}
