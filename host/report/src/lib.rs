//! `ellipso-report`: the files every stage writes — result files written whole or not at all
//! ([`atomic_file`]), `.npy` arrays ([`npy`]), multi-channel OpenEXR float images
//! ([`exr_image`]), and small dependency-light raster reports: an RGB8 [`canvas::Canvas`] and a
//! [`plot::LinePlot`] builder, written as PNG.
//!
//! Contract: pure Rust drawing (lines with clipping, rectangles, `font8x8` text); pictures are
//! PNG through the `image` crate, float results OpenEXR through the `exr` crate. Used by `ellipso model plot` and by later
//! reports (accuracy-vs-time, parameter maps).

pub mod atomic_file;
pub mod canvas;
pub mod exr_image;
pub mod npy;
pub mod plot;

pub use canvas::{Canvas, ClipRect, Rgb, Stroke};
pub use plot::{LegendPosition, LinePlot, Series};

/// Errors of report rendering and writing.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Nothing drawable: no series, or only non-finite points.
    #[error("nothing to plot: no series has a finite point")]
    NoData,
    /// An explicit axis range is empty, reversed or not finite.
    #[error("the {0} range must be finite with lo < hi")]
    BadRange(&'static str),
    /// The image is too small for axes and labels.
    #[error("the plot is too small for its labels; enlarge it or reduce the text scale")]
    TooSmall,
    /// The canvas has no pixels.
    #[error("the canvas is empty")]
    EmptyCanvas,
    /// Writing the PNG failed.
    #[error("cannot write {path}: {source}")]
    Write {
        /// Destination.
        path: String,
        /// Cause.
        source: image::ImageError,
    },
}

impl PartialEq for ReportError {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (Self::BadRange(a), Self::BadRange(b)) => a == b,
            (Self::Write { path: a, .. }, Self::Write { path: b, .. }) => a == b,
            _ => core::mem::discriminant(self) == core::mem::discriminant(other),
        }
    }
}

/// The `p`-quantile (0..=1, nearest rank) of `values`, sorting them in place; NaN when empty.
pub fn percentile(values: &mut [f64], p: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * p.clamp(0.0, 1.0)).round() as usize]
}
