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
mod render;
pub mod stokes_exr;
mod summary;

use std::path::{Path, PathBuf};

use ellipso_run_error::{Context, RunError, Say};

/// The conversion's result.
type Result<T> = std::result::Result<T, RunError>;
use ellipso_model::mosaic::SensorLayout;

use crate::{
    AnalyserCalibration, DemosaicMethod, MaskReason, PixelMask, PolarConfig, PolarImage,
    StokesBand, process, process_with_sensor, sensor_calibration,
};
use ellipso_report::{ColourMap, Key, Rgb};
use render::MASKED;

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

fn write_band(
    args: &Args,
    band: &StokesBand,
    suffix: &str,
    files: &mut Vec<FileEntry>,
) -> Result<serde_json::Value> {
    let (w, h) = (band.width(), band.height());
    let masks = band.mask.data();
    let out = &args.out;
    if args.npy {
        write_npy(out, band, suffix, files)?;
    }

    // s0 and I^d as pictures a screen shows: grey linear in the value from 0 to its 99.5th
    // percentile, the key saying so (the floats are in stokes.exr and the .npy planes)
    let s0_half: Vec<f32> = band.s0.data().iter().map(|v| v / 2.0).collect();
    intensity_picture(
        out,
        &format!("s0{suffix}.png"),
        (w, h),
        &s0_half,
        masks,
        "s0/2, mean analyser intensity",
        files,
    )?;
    let channels = band.observation_channels();
    let i_d_half: Vec<f32> = channels.i_d.data().iter().map(|v| v / 2.0).collect();
    intensity_picture(
        out,
        &format!("i_d{suffix}.png"),
        (w, h),
        &i_d_half,
        masks,
        "I^d/2 = I90, the cross-polarised (diffuse) intensity",
        files,
    )?;

    // DoLP and AoLP in the one convention of every picture; masked pixels grey
    let valid = |m: &PixelMask| m.is_valid();
    let dolp = render::picture(
        w,
        h,
        band.dolp
            .data()
            .iter()
            .zip(masks)
            .map(|(d, m)| ellipso_report::colour::dolp_colour(valid(m).then_some(f64::from(*d))))
            .collect(),
    );
    let dolp = render::with_key(
        dolp,
        Key::Bar {
            map: ColourMap::Viridis,
            lo: 0.0,
            hi: 1.0,
            label: "DoLP (grey: masked)".into(),
        },
    )?;
    save_png(
        out,
        &format!("dolp{suffix}.png"),
        Some(dolp),
        files,
        "DoLP, viridis over [0, 1], masked pixels grey, key below",
    )?;

    let aolp = band
        .aolp_rad
        .data()
        .iter()
        .zip(band.dolp.data().iter().zip(masks))
        .map(|(a, (d, m))| {
            let ok = valid(m);
            ellipso_report::colour::aolp_colour(
                ok.then_some(f64::from(*a)),
                ok.then_some(f64::from(*d)),
            )
        })
        .collect();
    let aolp = render::with_key(
        render::picture(w, h, aolp),
        Key::AolpDolp {
            dolp_as_value: false,
        },
    )?;
    save_png(
        out,
        &format!("aolp{suffix}.png"),
        Some(aolp),
        files,
        "AoLP as hue, DoLP as saturation (unpolarised is white, masked grey)",
    )?;

    let range_s = symmetric_range(channels.i_s.data(), masks);
    let range_alpha = symmetric_range(channels.i_alpha.data(), masks);
    for (stem, title, data, range) in [
        ("i_s", "I^s = I0 − I90", channels.i_s.data(), range_s),
        (
            "i_alpha",
            "I^α = I135 − I45",
            channels.i_alpha.data(),
            range_alpha,
        ),
    ] {
        let pixels = data
            .iter()
            .zip(masks)
            .map(|(v, m)| {
                if m.is_valid() {
                    render::diverging(v / range)
                } else {
                    MASKED
                }
            })
            .collect();
        let img = render::with_key(
            render::picture(w, h, pixels),
            Key::Bar {
                map: ColourMap::Diverging,
                lo: f64::from(-range),
                hi: f64::from(range),
                label: format!("{title} (normalised)"),
            },
        )?;
        let what = format!("{title}, diverging map ±{range:.4}");
        save_png(out, &format!("{stem}{suffix}.png"), Some(img), files, &what)?;
    }

    let mask_pixels = masks.iter().map(|m| mask_colour(*m)).collect();
    let swatches = std::iter::once(([0, 0, 0], "valid".to_string()))
        .chain(MASK_COLOURS.iter().map(|(r, c)| (*c, r.name().to_string())))
        .collect();
    let what = "mask by reason (first of saturated, no_samples, unphysical, inconsistent, dark)";
    let mask_img = render::with_key(render::picture(w, h, mask_pixels), Key::Swatches(swatches))?;
    save_png(
        out,
        &format!("mask{suffix}.png"),
        Some(mask_img),
        files,
        what,
    )?;
    let bits: Vec<u8> = masks.iter().map(|m| m.0).collect();
    save_png(
        out,
        &format!("mask_bits{suffix}.png"),
        image::GrayImage::from_raw(w as u32, h as u32, bits),
        files,
        "mask reason bits, 0 = valid",
    )?;

    Ok(summary::band_statistics(band, range_s, range_alpha))
}

/// Writes the f32 planes (and the mask bits) of `band` as `.npy` files.
fn write_npy(
    out: &Path,
    band: &StokesBand,
    suffix: &str,
    files: &mut Vec<FileEntry>,
) -> Result<()> {
    let (w, h) = (band.width(), band.height());
    for (stem, plane, what) in [
        ("s0", &band.s0, "s0, f32"),
        ("s1", &band.s1, "s1 = I^s, f32"),
        ("s2", &band.s2, "s2 = -I^alpha, f32"),
        ("dolp", &band.dolp, "DoLP, f32"),
        ("aolp_rad", &band.aolp_rad, "AoLP in radians [0, pi), f32"),
        ("residual", &band.residual, "I0 + I90 - I45 - I135, f32"),
        ("i_d", &band.i_d, "I^d, f32"),
    ] {
        let name = format!("{stem}{suffix}.npy");
        let path = out.join(&name);
        ellipso_report::npy::write(&path, &[h, w], plane.data())
            .with_context(|| format!("cannot write {}", path.display()))?;
        files.push((name, what.into()));
    }
    let name = format!("mask{suffix}.npy");
    let path = out.join(&name);
    let bits: Vec<u8> = band.mask.data().iter().map(|m| m.0).collect();
    ellipso_report::npy::write(&path, &[h, w], &bits)
        .with_context(|| format!("cannot write {}", path.display()))?;
    files.push((name, "mask reason bits, u8, 0 = valid".into()));
    Ok(())
}

/// Reasons in drawing priority, with their colours in `mask.png`.
const MASK_COLOURS: [(MaskReason, Rgb); 5] = [
    (MaskReason::Saturated, [255, 0, 0]),
    (MaskReason::NoSamples, [255, 0, 255]),
    (MaskReason::Unphysical, [255, 255, 0]),
    (MaskReason::Inconsistent, [0, 255, 255]),
    (MaskReason::Dark, [0, 0, 255]),
];

fn mask_colour(m: PixelMask) -> Rgb {
    MASK_COLOURS
        .iter()
        .find(|(r, _)| m.has(*r))
        .map_or([0, 0, 0], |(_, c)| *c)
}

/// Symmetric display range: the 99.5th percentile of |v| over valid pixels (robust to a few
/// outliers), at least 1e-6 so the map never divides by zero.
fn symmetric_range(values: &[f32], masks: &[PixelMask]) -> f32 {
    let mut abs: Vec<f32> = values
        .iter()
        .zip(masks)
        .filter(|(_, m)| m.is_valid())
        .map(|(v, _)| v.abs())
        .collect();
    if abs.is_empty() {
        return 1e-6;
    }
    let k = ((abs.len() - 1) as f64 * 0.995).round() as usize;
    let (_, nth, _) = abs.select_nth_unstable_by(k, f32::total_cmp);
    nth.max(1e-6)
}

/// An intensity plane (fractions of full scale) as a picture readable on its own: grey linear
/// in the value from 0 to its 99.5th percentile over the valid pixels (white at and above it),
/// with a colour bar whose label names the quantity, the transform and where the numbers are.
fn intensity_picture(
    out: &Path,
    name: &str,
    (w, h): (usize, usize),
    values: &[f32],
    masks: &[PixelMask],
    quantity: &str,
    files: &mut Vec<FileEntry>,
) -> Result<()> {
    let hi = symmetric_range(values, masks);
    let pixels = values
        .iter()
        .map(|v| ColourMap::Grey.at(f64::from(v / hi)))
        .collect();
    let picture = render::with_key(
        render::picture(w, h, pixels),
        Key::Bar {
            map: ColourMap::Grey,
            lo: 0.0,
            hi: f64::from(hi),
            label: format!(
                "{quantity}, fraction of full scale (grey linear, white ≥ 99.5th percentile; \
                 floats in stokes.exr)"
            ),
        },
    )?;
    save_png(
        out,
        name,
        Some(picture),
        files,
        &format!("{quantity}: grey linear from 0 to its 99.5th percentile, colour bar below"),
    )
}

fn write_s0_rgb(out: &Path, image: &PolarImage, files: &mut Vec<FileEntry>) -> Result<()> {
    let (w, h) = (image.width(), image.height());
    // one range for the three bands, so the picture keeps the colour balance
    let all: Vec<f32> = image
        .bands
        .iter()
        .flat_map(|b| b.s0.data().iter().map(|v| v / 2.0))
        .collect();
    let masks: Vec<PixelMask> = image
        .bands
        .iter()
        .flat_map(|b| b.mask.data().iter().copied())
        .collect();
    let hi = symmetric_range(&all, &masks);
    let pixels = (0..w * h)
        .map(|i| {
            let mut c = [0u8; 3];
            for (slot, band) in c.iter_mut().zip(&image.bands) {
                *slot = ColourMap::Grey.at(f64::from(band.s0.data()[i] / 2.0 / hi))[0];
            }
            c
        })
        .collect();
    let picture = render::with_key(
        render::picture(w, h, pixels),
        Key::Bar {
            map: ColourMap::Grey,
            lo: 0.0,
            hi: f64::from(hi),
            label: "s0/2 of R, G, B, fraction of full scale (each channel linear, white ≥ \
                    99.5th percentile; floats in stokes.exr)"
                .into(),
        },
    )?;
    save_png(
        out,
        "s0_rgb.png",
        Some(picture),
        files,
        "s0/2 of R, G, B: each channel linear from 0 to their 99.5th percentile, colour bar below",
    )
}

/// Writes `buf` (absent: the pixels did not fill a `w × h` image) as PNG `name` under `out`
/// and lists it in `files` with `what` — the one writer behind every picture of this command.
fn save_png<P>(
    out: &Path,
    name: &str,
    buf: Option<image::ImageBuffer<P, Vec<P::Subpixel>>>,
    files: &mut Vec<FileEntry>,
    what: &str,
) -> Result<()>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
{
    let path = out.join(name);
    let buf = buf.ok_or_else(|| RunError::msg(format!("internal: {name} buffer size")))?;
    ellipso_report::atomic_file::write_png(&path, &buf)
        .with_context(|| format!("cannot write {}", path.display()))?;
    files.push((name.into(), what.into()));
    Ok(())
}

#[cfg(test)]
mod tests;
