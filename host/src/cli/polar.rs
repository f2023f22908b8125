//! `ellipso polar FRAME --out DIR`: one raw mosaic frame to s0, DoLP, AoLP and I^d/I^s/I^α
//! images. The flags become [`ellipso_polar::convert::Args`]; [`ellipso_polar::convert::run`]
//! reads, processes and writes the folder (its module doc lists the files); this prints what
//! was written, or `summary.json`'s object with `--json`.

use std::path::PathBuf;

use ellipso_model::mosaic::SensorLayout;
use ellipso_polar::DemosaicMethod;
use ellipso_polar::convert;

use super::{limits, out};

/// Sensor layout names on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LayoutArg {
    /// IMX250MZR: monochrome polarisation mosaic (2×2: 90 45 / 135 0).
    Mono,
    /// IMX250MYR: 2×2 polariser blocks under a Bayer RGGB colour pattern (4×4 tile).
    Colour,
}

impl From<LayoutArg> for SensorLayout {
    fn from(arg: LayoutArg) -> SensorLayout {
        match arg {
            LayoutArg::Mono => SensorLayout::MonoPolar,
            LayoutArg::Colour => SensorLayout::ColourPolar,
        }
    }
}

/// Arguments of `ellipso polar`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Raw mosaic frame exactly as the camera delivered it: grey PNG (8/16-bit), TIFF
    /// (8/16/32-bit unsigned, 32/64-bit float) or NumPy `.npy` (u1/u2/u4/f4/f8, 2-D).
    pub frame: PathBuf,
    /// Directory to write the images and summary.json into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Sensor mosaic layout [default: the session manifest's for a frame inside a session,
    /// else detected from the pixels; refused when unclear].
    #[arg(long, value_enum)]
    pub layout: Option<LayoutArg>,
    /// Bits per sample the camera delivered [default: 8 for 8-bit containers, 12 for 16-bit
    /// ones, 16 for floats].
    #[arg(long, value_parser = convert::parse_bit_depth)]
    pub bit_depth: Option<u8>,
    /// Demosaic method: superpixel (half resolution, no interpolation; for measuring) or
    /// bilinear (full resolution; for viewing).
    #[arg(long, value_enum, default_value = "superpixel")]
    pub demosaic: DemosaicMethod,
    /// Black level subtracted from every raw sample, in DN (0..=65535).
    #[arg(long, default_value_t = 0.0, value_parser = limits::dn_level)]
    pub dark_level: f32,
    /// Raw samples at or above this DN are saturated [default: full scale of the bit depth].
    #[arg(long)]
    pub saturation: Option<u16>,
    /// Pixels whose mean analyser intensity (s0/2, normalised to full scale) is below this are
    /// masked dark.
    #[arg(long, default_value_t = ellipso_polar::DEFAULT_DARK_INTENSITY, value_parser = limits::unit_f32)]
    pub dark_intensity: f32,
    /// Mask pixels whose |I0 + I90 − I45 − I135| (normalised) exceeds this, in [0, 2] (off by
    /// default).
    #[arg(long, value_parser = |s: &str| limits::real_in(s, 0.0_f32, 2.0))]
    pub max_residual: Option<f32>,
    /// Also write every plane at full f32 precision as NumPy `.npy` files (s0, s1, s2, dolp,
    /// aolp_rad, residual, i_d; mask as u8 bits).
    #[arg(long)]
    pub npy: bool,
    /// Analyser calibration: a sensor calibration file (`ellipso calibrate sensor`; per pixel,
    /// superpixel demosaic) or a per-analyser JSON (`angle_deg`, `extinction_ratio`, `gain`, four values each in
    /// 0°, 45°, 90°, 135° order); default: ideal analysers.
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Print `summary.json`'s object (with the files written) on one line instead of the text
    /// report.
    #[arg(long)]
    pub json: bool,
}

/// Runs `ellipso polar`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let options = convert::Args {
        frame: args.frame,
        out: args.out,
        layout: args.layout.map(SensorLayout::from),
        bit_depth: args.bit_depth,
        demosaic: args.demosaic,
        dark_level: args.dark_level,
        saturation: args.saturation,
        dark_intensity: args.dark_intensity,
        max_residual: args.max_residual,
        npy: args.npy,
        calibration: args.calibration,
    };
    let written = convert::run(&options, &out::Printed).map_err(out::failed)?;
    let shown_out = &options.out;
    if args.json {
        crate::outln!(
            "{}",
            serde_json::json!({ "out": shown_out.display().to_string(), "summary": written.summary })
        );
        return Ok(());
    }
    crate::outln!("{}", written.headline);
    for (file, what) in &written.files {
        crate::outln!("  wrote {}  ({what})", shown_out.join(file).display());
    }
    Ok(())
}
