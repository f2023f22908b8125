//! The files `ellipso polar` writes for one band (its `.npy` planes when asked, the s0 and I^d
//! intensity pictures, DoLP, AoLP, I^s, I^α and the mask pictures) and the colour s0 picture of
//! a colour frame. Contract: every file is written into `out` and listed in `files`, with what
//! it holds, in the order written; the first failure ends the band with an error naming the file.

use std::path::Path;

use ellipso_report::{ColourMap, Key, Rgb};
use ellipso_run_error::{Context, RunError};

use super::render::{self, MASKED};
use super::{Args, FileEntry, Result, summary};
use crate::{MaskReason, ObservationChannels, PixelMask, PolarImage, StokesBand};

/// Writes every file of `band` (file names end in `suffix`: `_r`, `_g`, `_b` or nothing) and
/// returns its statistics for `summary.json`.
pub(super) fn write_band(
    args: &Args,
    band: &StokesBand,
    suffix: &str,
    files: &mut Vec<FileEntry>,
) -> Result<serde_json::Value> {
    let out = &args.out;
    if args.npy {
        write_npy(out, band, suffix, files)?;
    }
    let channels = band.observation_channels();
    intensity_pictures(out, band, &channels, suffix, files)?;
    polarisation_pictures(out, band, suffix, files)?;
    let (range_s, range_alpha) = signed_pictures(out, band, &channels, suffix, files)?;
    mask_pictures(out, band, suffix, files)?;
    Ok(summary::band_statistics(band, range_s, range_alpha))
}

/// s0 and I^d as pictures a screen shows: grey linear in the value from 0 to its 99.5th
/// percentile, the key saying so (the floats are in stokes.exr and the .npy planes).
fn intensity_pictures(
    out: &Path,
    band: &StokesBand,
    channels: &ObservationChannels,
    suffix: &str,
    files: &mut Vec<FileEntry>,
) -> Result<()> {
    let (w, h) = (band.width(), band.height());
    let masks = band.mask.data();
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
    let i_d_half: Vec<f32> = channels.i_d.data().iter().map(|v| v / 2.0).collect();
    intensity_picture(
        out,
        &format!("i_d{suffix}.png"),
        (w, h),
        &i_d_half,
        masks,
        "I^d/2 = I90, the cross-polarised (diffuse) intensity",
        files,
    )
}

/// DoLP and AoLP in the one convention of every picture; masked pixels grey.
fn polarisation_pictures(
    out: &Path,
    band: &StokesBand,
    suffix: &str,
    files: &mut Vec<FileEntry>,
) -> Result<()> {
    let (w, h) = (band.width(), band.height());
    let masks = band.mask.data();
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
    Ok(())
}

/// I^s and I^α in the diverging map over their symmetric ranges; returns the ranges
/// `(I^s, I^α)`.
fn signed_pictures(
    out: &Path,
    band: &StokesBand,
    channels: &ObservationChannels,
    suffix: &str,
    files: &mut Vec<FileEntry>,
) -> Result<(f32, f32)> {
    let (w, h) = (band.width(), band.height());
    let masks = band.mask.data();
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
    Ok((range_s, range_alpha))
}

/// The mask by reason (colours with swatches) and its raw reason bits.
fn mask_pictures(
    out: &Path,
    band: &StokesBand,
    suffix: &str,
    files: &mut Vec<FileEntry>,
) -> Result<()> {
    let (w, h) = (band.width(), band.height());
    let masks = band.mask.data();
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
    Ok(())
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
pub(super) fn symmetric_range(values: &[f32], masks: &[PixelMask]) -> f32 {
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

pub(super) fn write_s0_rgb(
    out: &Path,
    image: &PolarImage,
    files: &mut Vec<FileEntry>,
) -> Result<()> {
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
