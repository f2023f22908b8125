//! `ellipso-report`: the files every stage writes — result directories and files a command owns
//! and swaps in whole ([`output`]), result files written whole or not at all ([`atomic_file`]), paths
//! inside a summary relative to its folder ([`paths`]), `.npy` arrays ([`npy`]), multi-channel OpenEXR float images
//! ([`exr_image`]) — and its pictures: line plots ([`plot::LinePlot`]) and framed images with
//! colour bars and keys ([`figure::Figure`]), in the colour maps of [`colour`]; the docs' DoP plot
//! of `ellipso model plot` ([`dop_plot`]); printable AprilTag boards as PDF, SVG or PNG
//! ([`board_print`]).
//!
//! Contract: all drawing goes through `plotters` (pure-Rust bitmap backend) with the font
//! bundled in [`font`], so pictures look the same on every machine and need no system font;
//! pictures are PNG, written through `image` and [`atomic_file`]; float results are OpenEXR
//! through the `exr` crate.

pub mod atomic_file;
pub mod board_print;
pub mod colour;
pub mod dop_plot;
pub mod exr_image;
pub mod figure;
pub mod font;
pub mod memory;
pub mod npy;
pub mod output;
pub mod paths;
pub mod plot;

pub use colour::{ColourMap, Rgb};
pub use figure::{Figure, Key, Picture};
pub use plot::{LegendPosition, LinePlot, Series, Stroke};

/// Errors of report rendering and writing.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Nothing drawable: no series, or only non-finite points.
    #[error("nothing to plot: no series has a finite point")]
    NoData,
    /// An explicit axis range is empty, reversed or not finite.
    #[error("the {0} range must be finite with lo < hi")]
    BadRange(&'static str),
    /// The figure has no pixels (no image).
    #[error("the picture is empty")]
    EmptyCanvas,
    /// The images of one figure differ in size, or one's pixels do not fill it.
    #[error("the images of one figure must all have the same size and be complete")]
    ImageSize,
    /// The drawing library failed (too small an area for the axes, a text error).
    #[error("cannot draw the picture: {0}")]
    Draw(String),
    /// Writing the PNG failed.
    #[error("cannot write {path}: {source}")]
    Write {
        /// Destination.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
}

impl ReportError {
    fn draw(e: impl std::fmt::Display) -> Self {
        Self::Draw(e.to_string())
    }
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

/// Writes an RGB image as PNG, whole or not at all (a full disk leaves no half picture).
fn save_rgb(img: &image::RgbImage, path: &std::path::Path) -> Result<(), ReportError> {
    atomic_file::write_png(path, img).map_err(|source| ReportError::Write {
        path: path.display().to_string(),
        source,
    })
}

/// The `p`-quantile (0..=1, nearest rank) of `values`, sorting them in place; NaN when empty —
/// the model's one percentile ([`ellipso_model::stats`]), re-exported where result tables are
/// made.
pub use ellipso_model::stats::percentile;
