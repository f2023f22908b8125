//! Order statistics of samples: the one median and percentile every crate reports with.
//!
//! Contract:
//! - [`percentile`] sorts `values` in place (IEEE total order, so NaNs sort to the ends instead
//!   of panicking) and returns the element at index `round((n − 1)·p)`, `p` clamped to [0, 1]
//!   — the nearest-rank percentile on the sorted samples, no interpolation, so the result is
//!   always one of the samples. An empty slice gives NaN.
//! - [`median`] is `percentile(values, 0.5)`: for even `n` the upper of the two middle samples
//!   (index `n/2`; `round` takes halves away from zero), for odd `n` the middle one. Every
//!   median the fit, vision and bench report is this one, so their numbers agree.
//! - [`robust_sigma`] is 1.4826·MAD, the median absolute deviation about [`median`] scaled to
//!   estimate σ of a normal sample (Hampel 1974); a few gross outliers cannot inflate it, as
//!   they would the standard deviation. NaN when empty.
//! - [`median_standard_error`] is the large-sample standard error of that median,
//!   1.2533·[`robust_sigma`]/√n: exact for normal samples (Kendall & Stuart, *The Advanced
//!   Theory of Statistics*, §10.10: var(median) → πσ²/2n). NaN for fewer than two samples.
//!
//! Not a crate dependency: the few lines here fix the convention (upper median, nearest rank,
//! NaN when empty) that recorded results already use; `statrs` and friends interpolate.

/// The nearest-rank `p`-percentile of `values` (sorts them in place; NaN when empty).
pub fn percentile(values: &mut [f64], p: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * p.clamp(0.0, 1.0)).round() as usize]
}

/// The median of `values` — the upper middle sample for an even count (sorts them in place;
/// NaN when empty).
pub fn median(values: &mut [f64]) -> f64 {
    percentile(values, 0.5)
}

/// 1.4826·MAD of `values` about their [`median`] (module doc; reorders them; NaN when empty).
pub fn robust_sigma(values: &mut [f64]) -> f64 {
    let centre = median(values);
    let mut deviations: Vec<f64> = values.iter().map(|v| (v - centre).abs()).collect();
    1.4826 * median(&mut deviations)
}

/// The standard error of [`median`] of `values` (module doc; reorders them; NaN below two).
pub fn median_standard_error(values: &mut [f64]) -> f64 {
    let n = values.len();
    if n < 2 {
        return f64::NAN;
    }
    1.2533 * robust_sigma(values) / (n as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_is_the_upper_middle_sample() {
        for n in 1..40usize {
            let mut v: Vec<f64> = (0..n).rev().map(|i| i as f64).collect();
            assert_eq!(median(&mut v), (n / 2) as f64, "n = {n}");
            assert!(v.windows(2).all(|w| w[0] <= w[1]), "sorted in place");
        }
        assert!(median(&mut []).is_nan());
    }

    #[test]
    fn percentiles_are_nearest_rank_and_clamped() {
        let mut v = vec![5.0, 1.0, 4.0, 2.0, 3.0];
        assert_eq!(percentile(&mut v, 0.0), 1.0);
        assert_eq!(percentile(&mut v, 1.0), 5.0);
        assert_eq!(percentile(&mut v, 0.9), 5.0);
        assert_eq!(percentile(&mut v, 0.2), 2.0);
        assert_eq!(percentile(&mut v, 7.0), 5.0);
        assert_eq!(percentile(&mut v, -1.0), 1.0);
        let mut with_nan = vec![f64::NAN, 1.0, 2.0];
        assert_eq!(percentile(&mut with_nan, 0.0), 1.0);
    }

    #[test]
    fn the_median_standard_error_follows_the_spread_and_the_count() {
        // Median 10, absolute deviations {3, 2, 1, 0, 1, 2, 3}: MAD = 2.
        let seven = [7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0];
        let se = median_standard_error(&mut seven.clone());
        assert!(
            (se - 1.2533 * 1.4826 * 2.0 / 7f64.sqrt()).abs() < 1e-12,
            "{se}"
        );
        // Twice the spread, twice the error; four times the samples, half of it.
        let wide: Vec<f64> = seven.iter().map(|v| 10.0 + 2.0 * (v - 10.0)).collect();
        assert!((median_standard_error(&mut wide.clone()) / se - 2.0).abs() < 1e-12);
        let many: Vec<f64> = seven.iter().copied().cycle().take(28).collect();
        assert!((median_standard_error(&mut many.clone()) / se - 0.5).abs() < 1e-12);
        // One sample thrown far away leaves MAD where it was (the standard deviation would not).
        let mut outlier = many.clone();
        outlier[0] = 1e9;
        assert!((median_standard_error(&mut outlier) / se - 0.5).abs() < 1e-12);
        assert!(robust_sigma(&mut []).is_nan());
        assert!((robust_sigma(&mut seven.clone()) - 1.4826 * 2.0).abs() < 1e-12);
        assert!(median_standard_error(&mut [1.0]).is_nan());
        assert!(median_standard_error(&mut []).is_nan());
    }
}
