//! `ellipso polar FRAME.png --out DIR`: one raw mosaic frame to s0, DoLP, AoLP and I^d/I^s/I^α images.
//!
//! Reads a raw IMX250MZR/MYR mosaic (grey PNG, TIFF — 8/16/32-bit or float — or `.npy`, as
//! the camera delivered it; [`load`] settles its bit depth and layout), runs
//! [`crate::process`] and writes into DIR, per band (suffix `_r/_g/_b` for colour):
//!
//! | file | content | encoding |
//! |---|---|---|
//! | `s0.png` | total intensity | RGB: s0/2 (mean analyser intensity, fraction of full scale) in grey, linear from 0 to its 99.5th percentile, colour bar below saying so |
//! | `dolp.png` | DoLP | RGB, viridis over [0, 1] (`ellipso_report::colour::dolp_colour`), colour bar below the image |
//! | `aolp.png` | AoLP and DoLP | RGB, HSV composite: hue = AoLP (once round the wheel over [0, π), 0 and π meet), saturation = DoLP, value 1 (`ellipso_report::colour::aolp_colour`: every AoLP picture's convention); AoLP × DoLP key below |
//! | `i_d.png` | I^d = 2·I90 | RGB: I^d/2 in grey as `s0.png`, colour bar below |
//! | `i_s.png`, `i_alpha.png` | I^s, I^α (signed) | RGB diverging map, symmetric range, legend |
//! | `mask.png`, `mask_bits.png` | validity | RGB by reason with legend; raw reason bits (8-bit) |
//! | `stokes.exr` | every band's S0, S1, S2, DoLP, AoLP, I^d, I^s, I^α, residual, mask | OpenEXR f32 channels named as Mitsuba's (`S0.R` …; [`stokes_exr`]) |
//! | `summary.json` | everything needed to read the above, plus statistics | JSON |
//!
//! Keys (colour bars, the AoLP × DoLP key, mask swatches) sit under the image rows (`summary.json` gives the image height), so the
//! top `height` rows are pixel-aligned with the demosaiced output. Masked pixels are the
//! pictures' no-data grey in every false-colour image (DoLP and AoLP included). Errors name the file and what is wrong, in one line.

pub mod load;
mod pictures;
mod render;
pub mod stokes_exr;
mod summary;

use std::path::{Path, PathBuf};

use ellipso_run_error::{Context, RunError, Say};

/// The conversion's result.
type Result<T> = std::result::Result<T, RunError>;
use ellipso_model::mosaic::SensorLayout;

use crate::{
    AnalyserCalibration, DemosaicMethod, PolarConfig, process, process_with_sensor,
    sensor_calibration,
};
use pictures::{write_band, write_s0_rgb};

/// What `ellipso polar` converts, and how (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct Args {
    /// Raw mosaic frame exactly as the camera delivered it: grey PNG (8/16-bit), TIFF
    /// (8/16/32-bit unsigned, 32/64-bit float) or NumPy `.npy` (u1/u2/u4/f4/f8, 2-D).
    pub frame: PathBuf,
    /// Directory to write the images and summary.json into (created if missing).
    pub out: PathBuf,
    /// Sensor mosaic layout [default: the session manifest's for a frame inside a session,
    /// else detected from the pixels; refused when unclear].
    pub layout: Option<SensorLayout>,
    /// Bits per sample the camera delivered [default: 8 for 8-bit containers, 12 for 16-bit
    /// ones, 16 for floats].
    pub bit_depth: Option<u8>,
    /// Demosaic method: superpixel (half resolution, no interpolation; for measuring) or
    /// bilinear (full resolution; for viewing).
    pub demosaic: DemosaicMethod,
    /// Black level subtracted from every raw sample, in DN (0..=65535).
    pub dark_level: f32,
    /// Raw samples at or above this DN are saturated [default: full scale of the bit depth].
    pub saturation: Option<u16>,
    /// Pixels whose mean analyser intensity (s0/2, normalised to full scale) is below this are
    /// masked dark.
    pub dark_intensity: f32,
    /// Mask pixels whose |I0 + I90 − I45 − I135| (normalised) exceeds this, in [0, 2] (off by
    /// default).
    pub max_residual: Option<f32>,
    /// Also write every plane at full f32 precision as NumPy `.npy` files (s0, s1, s2, dolp,
    /// aolp_rad, residual, i_d; mask as u8 bits).
    pub npy: bool,
    /// Analyser calibration: a sensor calibration file of `ellipso calibrate sensor` (every
    /// pixel's dark level and analysis vector; superpixel demosaic), or a global per-analyser
    /// JSON (`angle_deg`, `extinction_ratio`, `gain`, four values each in 0°, 45°, 90°, 135°
    /// order); default: ideal analysers.
    pub calibration: Option<PathBuf>,
}

/// Parses `--bit-depth` (the binary's value parser): one of the depths an IMX250 camera delivers.
pub fn parse_bit_depth(text: &str) -> std::result::Result<u8, String> {
    text.parse::<u8>()
        .ok()
        .filter(|b| load::BIT_DEPTHS.contains(b))
        .ok_or_else(|| format!("`{text}` is not one of 8, 10, 12, 16"))
}

/// What `ellipso polar` wrote.
pub struct Written {
    /// One line: input, size, depth, layout, method and output size.
    pub headline: String,
    /// Every file (name inside `--out`) with what it holds.
    pub files: Vec<FileEntry>,
    /// `summary.json`'s object.
    pub summary: serde_json::Value,
}

/// Runs `ellipso polar`: claims `args.out` (docs/reliability.md), writes every output into it
/// and swaps it in whole; warnings go to `say`, the caller prints what was written.
pub fn run(args: &Args, say: &dyn Say) -> Result<Written> {
    // the output directory is claimed first and written whole (docs/reliability.md)
    let mut inputs: Vec<&Path> = vec![&args.frame];
    inputs.extend(args.calibration.as_deref());
    let claimed = ellipso_report::output::OutputDir::claim(&args.out, "polar", &inputs)?;
    let args = Args {
        out: claimed.path().to_path_buf(),
        ..args.clone()
    };
    let written = write(&args, say)?;
    claimed.commit()?;
    Ok(written)
}

/// Processes the frame and writes every output into `args.out` without printing them (the
/// demo lists the folder once, `run` claims the folder first).
pub fn write(args: &Args, say: &dyn Say) -> Result<Written> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let name = args.frame.display().to_string();
    let loaded = load::load_frame(&args.frame, args.layout, args.bit_depth)
        .map_err(|msg| RunError::msg(format!("{name}: {msg}")))?;
    for w in &loaded.warnings {
        say.err(format_args!("warning: {name}: {w}"));
    }
    // one flag, two kinds of file: a per-pixel sensor calibration (its magic) or the global
    // per-analyser JSON
    let sensor = match &args.calibration {
        Some(path) if sensor_calibration::file::is_sensor_calibration(path) => Some(
            sensor_calibration::file::read(path, None).map_err(|e| RunError::msg(e.to_string()))?,
        ),
        _ => None,
    };
    let calibration = match &args.calibration {
        Some(path) if sensor.is_none() => Some(read_calibration(path)?),
        _ => None,
    };
    let config = PolarConfig {
        demosaic: args.demosaic,
        dark_level_dn: args.dark_level,
        saturation_dn: args.saturation,
        dark_intensity: args.dark_intensity,
        max_residual: args.max_residual,
        calibration,
    };
    let (image, config) = match &sensor {
        Some(cal) => {
            if args.dark_level != 0.0 {
                say.err(format_args!(
                    "warning: --dark-level {} ignored: sensor calibration {} brings the black level {:.2} DN and every pixel's dark level",
                    args.dark_level,
                    cal.id(),
                    cal.header.figures.black_level_dn
                ));
            }
            let config = sensor_calibration::apply::calibrated_config(
                &PolarConfig {
                    dark_level_dn: 0.0,
                    ..config
                },
                cal,
            )
            .map_err(|e| RunError::msg(format!("{name}: {e}")))?;
            let image = process_with_sensor(&loaded.frame, &config, cal)
                .map_err(|e| RunError::msg(format!("{name}: {e}")))?;
            (image, config)
        }
        None => (
            process(&loaded.frame, &config).map_err(|e| RunError::msg(format!("{name}: {e}")))?,
            config,
        ),
    };

    let mut files = Vec::new();
    let mut band_stats = Vec::new();
    for band in &image.bands {
        let suffix = band
            .colour
            .map_or(String::new(), |c| format!("_{}", c.letter()));
        let stats = write_band(args, band, &suffix, &mut files)?;
        band_stats.push(stats);
    }
    if image.layout == SensorLayout::ColourPolar {
        write_s0_rgb(&args.out, &image, &mut files)?;
    }
    files.push((
        stokes_exr::write(&args.out, &image)?,
        "OpenEXR: S0, S1, S2, DoLP, AoLP, I_d, I_s, I_alpha, residual, mask per band (f32; mask u32)"
            .into(),
    ));
    let summary = summary::summary_json(args, &loaded, &config, &image, band_stats, &files);
    let summary_path = args.out.join("summary.json");
    let text = serde_json::to_string_pretty(&summary).context("encoding summary.json")?;
    ellipso_report::atomic_file::write(&summary_path, text + "\n")
        .with_context(|| format!("cannot write {}", summary_path.display()))?;
    files.push((
        "summary.json".into(),
        "layout, method, levels, statistics, encodings".into(),
    ));
    let headline = format!(
        "{name}: {}×{} {}-bit {:?} ({}; layout from {}), demosaic {} → {}×{} × {} band(s)",
        loaded.frame.width(),
        loaded.frame.height(),
        loaded.frame.bit_depth(),
        image.layout,
        loaded.container,
        loaded.layout_source,
        image.method.name(),
        image.width(),
        image.height(),
        image.bands.len()
    );
    Ok(Written {
        headline,
        files,
        summary,
    })
}

/// Reads and checks an analyser calibration file; errors name the file.
fn read_calibration(path: &Path) -> Result<AnalyserCalibration> {
    let name = path.display();
    let text = ellipso_model::file_io::read_bounded_text(path, ellipso_model::file_io::caps::SCENE)
        .map_err(|e| RunError::msg(format!("{name}: cannot read: {e}")))?;
    let calibration: AnalyserCalibration = serde_json::from_str(&text)
        .map_err(|e| RunError::msg(format!("{name}: not an analyser calibration: {e}")))?;
    calibration
        .stokes_matrix()
        .map_err(|e| RunError::msg(format!("{name}: {e}")))?;
    Ok(calibration)
}

/// One written file: name inside DIR and what it holds.
pub type FileEntry = (String, String);

#[cfg(test)]
mod tests;
