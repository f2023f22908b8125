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
}
