//! Display ranges for the fit's pictures (the colour maps, frames and colour bars are
//! `ellipso_report`'s; the sRGB encoder is the model's [`ellipso_model::colour::srgb_u8`],
//! re-exported here as [`srgb`]).
//!
//! Contract: [`robust_range`] always returns a finite range with lo < hi; [`srgb`] takes any
//! f64 (NaN included) and returns a valid 8-bit value.

/// Robust display range of `values`: the 1st and 99th percentiles of the finite ones (a
/// degenerate range is widened to ±5 % or ±0.5).
pub fn robust_range(values: &[Option<f64>]) -> (f64, f64) {
    let mut v: Vec<f64> = values
        .iter()
        .flatten()
        .copied()
        .filter(|x| x.is_finite())
        .collect();
    if v.is_empty() {
        return (0.0, 1.0);
    }
    let lo = ellipso_report::percentile(&mut v, 0.01);
    let hi = ellipso_report::percentile(&mut v, 0.99);
    if hi - lo > 1e-9 * hi.abs().max(1.0) {
        (lo, hi)
    } else {
        let pad = (0.05 * lo.abs()).max(if lo == 0.0 { 0.5 } else { 0.0 });
        (lo - pad, hi + pad)
    }
}

/// The display ranges every map of a fit shares (the PNG maps and `ellipso view`): per
/// parameter ([`super::ply::PARAMS`] order) and per standard error, the 1st–99th percentile
/// ([`robust_range`]) over the vertices whose value the identifiability rule reports (η: only
/// where η is identifiable; standard errors: the finite ones).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct MapRanges {
    /// Range of each parameter.
    pub params: [(f64, f64); 10],
    /// Range of each standard error.
    pub std_error: [(f64, f64); 10],
}

impl MapRanges {
    /// The ranges over `vertices`: (parameters, reported standard errors, the rule).
    pub fn of(vertices: &[([f64; 10], [f64; 10], crate::data::Identifiable)]) -> Self {
        let column = |k: usize, std: bool| -> (f64, f64) {
            let values: Vec<Option<f64>> = vertices
                .iter()
                .filter(|(_, _, i)| i.vertex && (k != 0 || i.eta))
                .map(|(p, s, _)| Some(if std { s[k] } else { p[k] }))
                .collect();
            robust_range(&values)
        };
        Self {
            params: std::array::from_fn(|k| column(k, false)),
            std_error: std::array::from_fn(|k| column(k, true)),
        }
    }

    /// The ranges of a fit's vertices.
    pub fn of_fits(fits: &[crate::data::VertexFit]) -> Self {
        let rows: Vec<_> = fits
            .iter()
            .map(|f| {
                (
                    super::ply::params_of(f),
                    f.reported_std_error(),
                    f.identifiable(),
                )
            })
            .collect();
        Self::of(&rows)
    }
}

/// sRGB encoding of a linear value (IEC 61966-2-1): the model's one encoder.
pub use ellipso_model::colour::srgb_u8 as srgb;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_range_survives_degenerate_input() {
        assert_eq!(robust_range(&[]), (0.0, 1.0));
        let (lo, hi) = robust_range(&[Some(1.5), Some(1.5), None]);
        assert!(lo < 1.5 && hi > 1.5);
    }
}
