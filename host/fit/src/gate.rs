//! Sample gating (docs/model.md §11 "Sample gating", §12): which (vertex, view) observations
//! the fit may use, one rule set shared by observation extraction from real frames and by the
//! synthetic sample generator, so both gate identically.
//!
//! Contract:
//! - [`GateConfig::check_sample`] judges one sample from its raw analyser intensities in DN
//!   (`[I0, I45, I90, I135]` per colour channel, after demosaicing) and its view angle. It returns
//!   the first failing reason in this order: non-finite, grazing, saturated, dark.
//!   - *saturated*: any analyser intensity ≥ `saturation_fraction · full_scale_dn` (I0 carries the
//!     specular and clips first; a clipped analyser corrupts I^s and the DoP).
//!   - *dark*: the cross-polarised diffuse intensity I^d = 2·I90, summed over colour channels and
//!     divided by `full_scale_dn · channels`, below `dark_fraction` (the paper's 0.001 on
//!     normalised intensity).
//!   - *grazing*: the view direction more than `grazing_cutoff_deg` from the current normal.
//! - [`GateConfig::reject_colour_outliers`] removes samples whose chromaticity (unit-length RGB
//!   of I^d) lies farther than `colour_outlier_distance` from the vertex's robust mean
//!   chromaticity (3 re-centring iterations), counting them; monochrome samples are never
//!   outliers. It keeps every sample when fewer than `min_colour_survivors` would survive
//!   (the test is then uninformative, and dropping most of a vertex is worse).

use super::data::{GateCounts, Sample};

/// Thresholds of the sample gates.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GateConfig {
    /// Samples viewed more than this far from the normal are dropped, degrees (docs/model.md
    /// §12, grazing: start near 80–85°).
    pub grazing_cutoff_deg: f64,
    /// A sample is saturated when any analyser intensity reaches this fraction of full scale.
    pub saturation_fraction: f64,
    /// A sample is dark when mean I^d / full scale is below this (paper: 0.001).
    pub dark_fraction: f64,
    /// Colour-outlier radius on unit chromaticity (paper: 0.2, i.e. squared distance 0.04).
    pub colour_outlier_distance: f64,
    /// The colour test is applied only if at least this many samples survive it (paper: 8).
    pub min_colour_survivors: usize,
    /// Minimum kept samples for a vertex to be fitted (paper: 12 joint step, 8 final step).
    pub min_views: usize,
}

impl Default for GateConfig {
    fn default() -> Self {
        Self {
            grazing_cutoff_deg: 80.0,
            saturation_fraction: 0.98,
            dark_fraction: 0.001,
            colour_outlier_distance: 0.2,
            min_colour_survivors: 8,
            min_views: 12,
        }
    }
}

/// Why one sample was gated out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleGate {
    /// A non-finite analyser value.
    NonFinite,
    /// Viewed beyond the grazing cut-off.
    Grazing,
    /// An analyser at or above the saturation level.
    Saturated,
    /// Too little diffuse signal.
    Dark,
}

impl SampleGate {
    /// Counts this rejection in `counts`.
    pub fn count(self, counts: &mut GateCounts) {
        match self {
            SampleGate::NonFinite => counts.non_finite += 1,
            SampleGate::Grazing => counts.grazing += 1,
            SampleGate::Saturated => counts.saturated += 1,
            SampleGate::Dark => counts.dark += 1,
        }
    }
}

impl GateConfig {
    /// Judges one sample. `analysers_dn[c]` = `[I0, I45, I90, I135]` of colour channel `c`
    /// (`channels` = 1 for a monochrome sensor: only entry 0 is read), `cos_view` = cosine of the
    /// angle between the view direction and the current normal.
    pub fn check_sample(
        &self,
        analysers_dn: &[[f32; 4]; 3],
        channels: usize,
        full_scale_dn: f64,
        cos_view: f64,
    ) -> Result<(), SampleGate> {
        let channels = channels.clamp(1, 3);
        let used = &analysers_dn[..channels];
        if used.iter().flatten().any(|v| !v.is_finite()) || !cos_view.is_finite() {
            return Err(SampleGate::NonFinite);
        }
        if cos_view < self.grazing_cutoff_deg.to_radians().cos() {
            return Err(SampleGate::Grazing);
        }
        let saturation_dn = self.saturation_fraction * full_scale_dn;
        if used
            .iter()
            .flatten()
            .any(|&v| f64::from(v) >= saturation_dn)
        {
            return Err(SampleGate::Saturated);
        }
        let diffuse: f64 = used.iter().map(|a| 2.0 * f64::from(a[2])).sum();
        // full_scale_dn > 0 for any real sensor; max(1) keeps the ratio finite regardless.
        if diffuse / (full_scale_dn.max(1.0) * channels as f64) < self.dark_fraction {
            return Err(SampleGate::Dark);
        }
        Ok(())
    }

    /// Drops colour outliers from `samples` (see the module doc), counting them in `counts`.
    /// `colour` = false (monochrome) keeps everything.
    pub fn reject_colour_outliers(
        &self,
        samples: &mut Vec<Sample>,
        colour: bool,
        counts: &mut GateCounts,
    ) {
        if !colour || samples.is_empty() {
            return;
        }
        let chroma: Vec<Option<[f64; 3]>> = samples.iter().map(chromaticity).collect();
        let mut centre = mean_of(chroma.iter().flatten());
        let r2 = self.colour_outlier_distance * self.colour_outlier_distance;
        let inside = |c: &Option<[f64; 3]>, centre: &[f64; 3]| {
            c.is_some_and(|c| (0..3).map(|k| (c[k] - centre[k]).powi(2)).sum::<f64>() <= r2)
        };
        // Robust re-centring: the mean of the samples inside the radius, three times.
        for _ in 0..3 {
            let kept: Vec<[f64; 3]> = chroma
                .iter()
                .filter(|c| inside(c, &centre))
                .flatten()
                .copied()
                .collect();
            if kept.is_empty() {
                break;
            }
            centre = mean_of(kept.iter());
        }
        let survivors = chroma.iter().filter(|c| inside(c, &centre)).count();
        if survivors < self.min_colour_survivors || survivors == samples.len() {
            return;
        }
        let mut k = 0;
        samples.retain(|_| {
            let keep = inside(&chroma[k], &centre);
            k += 1;
            keep
        });
        let dropped = (chroma.len() - samples.len()) as u64;
        counts.colour_outlier += dropped;
        counts.kept = counts.kept.saturating_sub(dropped);
    }
}

/// Unit-length RGB of a sample's I^d, or `None` when it has no positive diffuse signal.
fn chromaticity(s: &Sample) -> Option<[f64; 3]> {
    let rgb = [0, 1, 2].map(|c| f64::from(s.channels[c][0]).max(0.0));
    let norm = rgb.iter().map(|v| v * v).sum::<f64>().sqrt();
    // Below 1e-12 model units there is no colour to speak of.
    (norm > 1e-12).then(|| rgb.map(|v| v / norm))
}

fn mean_of<'a>(items: impl Iterator<Item = &'a [f64; 3]>) -> [f64; 3] {
    let mut sum = [0.0; 3];
    let mut n = 0usize;
    for c in items {
        for k in 0..3 {
            sum[k] += c[k];
        }
        n += 1;
    }
    // An empty set has no mean; the grey axis is as good a centre as any.
    if n == 0 {
        return [1.0 / 3f64.sqrt(); 3];
    }
    sum.map(|v| v / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(rgb: [f32; 3]) -> Sample {
        Sample {
            view: 0,
            channels: [0, 1, 2].map(|c| [rgb[c], 0.0, 0.0, rgb[c]]),
            normaliser: 1.0,
        }
    }

    #[test]
    fn each_gate_fires_for_its_own_reason() {
        let g = GateConfig::default();
        let fs = 4095.0;
        let ok = [[400.0, 380.0, 360.0, 380.0]; 3];
        assert_eq!(g.check_sample(&ok, 3, fs, 0.9), Ok(()));
        let mut nan = ok;
        nan[1][2] = f32::NAN;
        assert_eq!(g.check_sample(&nan, 3, fs, 0.9), Err(SampleGate::NonFinite));
        // A NaN in an unused colour channel of a mono sensor does not matter.
        assert_eq!(g.check_sample(&nan, 1, fs, 0.9), Ok(()));
        assert_eq!(
            g.check_sample(&ok, 3, fs, 85f64.to_radians().cos()),
            Err(SampleGate::Grazing)
        );
        let mut hot = ok;
        hot[0][0] = 4090.0;
        assert_eq!(g.check_sample(&hot, 3, fs, 0.9), Err(SampleGate::Saturated));
        let dark = [[2.0, 1.0, 1.0, 1.0]; 3];
        assert_eq!(g.check_sample(&dark, 3, fs, 0.9), Err(SampleGate::Dark));
        let mut counts = GateCounts::default();
        for r in [
            SampleGate::NonFinite,
            SampleGate::Grazing,
            SampleGate::Saturated,
            SampleGate::Dark,
        ] {
            r.count(&mut counts);
        }
        assert_eq!(
            (
                counts.non_finite,
                counts.grazing,
                counts.saturated,
                counts.dark
            ),
            (1, 1, 1, 1)
        );
    }

    #[test]
    fn colour_outliers_are_dropped_and_counted() {
        let g = GateConfig::default();
        let mut samples: Vec<Sample> = (0..20)
            .map(|k| sample([0.6 + 0.001 * k as f32, 0.3, 0.1]))
            .collect();
        // Two white (highlight-dominated) samples.
        samples.push(sample([1.0, 1.0, 1.0]));
        samples.push(sample([0.9, 0.9, 0.95]));
        let mut counts = GateCounts {
            kept: 22,
            ..Default::default()
        };
        g.reject_colour_outliers(&mut samples, true, &mut counts);
        assert_eq!(samples.len(), 20);
        assert_eq!(counts.colour_outlier, 2);
        assert_eq!(counts.kept, 20);
        // Monochrome: untouched.
        let mut mono = vec![sample([1.0, 1.0, 1.0]), sample([0.1, 0.1, 0.1])];
        g.reject_colour_outliers(&mut mono, false, &mut counts);
        assert_eq!(mono.len(), 2);
    }

    #[test]
    fn too_few_survivors_keeps_everything() {
        let g = GateConfig::default();
        let mut samples: Vec<Sample> = (0..5).map(|_| sample([0.6, 0.3, 0.1])).collect();
        samples.extend((0..5).map(|_| sample([0.1, 0.3, 0.9])));
        let mut counts = GateCounts::default();
        g.reject_colour_outliers(&mut samples, true, &mut counts);
        assert_eq!(samples.len(), 10);
        assert_eq!(counts.colour_outlier, 0);
    }
}
