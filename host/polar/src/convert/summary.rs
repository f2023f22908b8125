//! `summary.json` of `ellipso polar`: how to read every output file, and per-band statistics
//! over valid pixels only (masked fractions per reason, means, axial mean AoLP, RMS residual).

use serde_json::json;

use super::{Args, FileEntry, load};
use crate::{MaskReason, MaskSummary, PolarConfig, PolarImage, StokesBand};

pub(super) fn band_statistics(
    band: &StokesBand,
    range_s: f32,
    range_alpha: f32,
) -> serde_json::Value {
    let masks = band.mask.data();
    let summary = MaskSummary::of(masks);
    let valid = |plane: &[f32]| -> Vec<f64> {
        plane
            .iter()
            .zip(masks)
            .filter(|(_, m)| m.is_valid())
            .map(|(v, _)| f64::from(*v))
            .collect()
    };
    let mean = |v: &[f64]| {
        if v.is_empty() {
            None
        } else {
            Some(v.iter().sum::<f64>() / v.len() as f64)
        }
    };
    let residual = valid(band.residual.data());
    let rms_residual = mean(&residual.iter().map(|r| r * r).collect::<Vec<_>>()).map(f64::sqrt);
    // AoLP is axial: average the doubled angle as a unit vector, then halve.
    let aolp = valid(band.aolp_rad.data());
    let (c, s) = aolp.iter().fold((0.0, 0.0), |(c, s), a| {
        (c + (2.0 * a).cos(), s + (2.0 * a).sin())
    });
    let n = aolp.len().max(1) as f64;
    let resultant = (c / n).hypot(s / n);
    let mean_aolp_deg = (!aolp.is_empty() && resultant > 1e-9)
        .then(|| (0.5 * s.atan2(c)).to_degrees().rem_euclid(180.0));
    let masked: serde_json::Map<String, serde_json::Value> = MaskReason::ALL
        .iter()
        .map(|r| (r.name().to_string(), json!(summary.fraction(*r))))
        .collect();
    json!({
        "colour": band.colour,
        "pixels": summary.pixels,
        "valid_fraction": summary.valid_fraction(),
        "masked_fraction": masked,
        "mean_s0_valid": mean(&valid(band.s0.data())),
        "mean_dolp_valid": mean(&valid(band.dolp.data())),
        "mean_aolp_deg_valid": mean_aolp_deg,
        "aolp_resultant_length": resultant,
        "rms_residual_valid": rms_residual,
        "display_range_i_s": range_s,
        "display_range_i_alpha": range_alpha,
    })
}

pub(super) fn summary_json(
    args: &Args,
    loaded: &load::Loaded,
    config: &PolarConfig,
    image: &PolarImage,
    bands: Vec<serde_json::Value>,
    files: &[FileEntry],
) -> serde_json::Value {
    let frame = &loaded.frame;
    json!({
        "tool": "ellipso polar",
        "input": args.frame.file_name().map(|n| n.to_string_lossy().into_owned()),
        "layout": image.layout,
        "demosaic": { "method": image.method.name(), "description": image.method.description() },
        "raw": {
            "width": frame.width(),
            "height": frame.height(),
            "container": loaded.container,
            "container_bits": loaded.container_bits,
            "layout_source": loaded.layout_source,
            "bit_depth": frame.bit_depth(),
            "bit_depth_source": loaded.bit_depth_source,
            "max_dn": frame.max_dn(),
            "warnings": loaded.warnings,
        },
        "levels": {
            "dark_level_dn": image.levels.dark_dn(),
            "saturation_dn": image.levels.saturation_dn(),
            "full_scale_dn": frame.full_scale_dn(),
            "normalisation": "I = (DN - dark_level_dn) / (full_scale_dn - dark_level_dn)",
        },
        "thresholds": { "dark_intensity": config.dark_intensity, "max_residual": config.max_residual },
        "analyser_calibration": config.calibration.map_or(json!("ideal"), |c| json!(c)),
        "output": {
            "width": image.width(),
            "height": image.height(),
            "note": "PNG rows below `height` are the key (colour bar, AoLP x DoLP key, mask swatches)",
        },
        "conventions": {
            "rows": "y grows downward, x to image-right, sensor not flipped",
            "analyser_angle": "from image-right toward image-up, looking back along propagation",
            "aolp": "counter-clockwise from image-right, [0, 180) degrees",
            "stokes": "s0 = (I0+I45+I90+I135)/2, s1 = I0-I90, s2 = I45-I135 (Hagen et al. 2019)",
            "channels": "I^d = 2*I90, I^s = I0-I90 (= s1), I^alpha = I135-I45 (= -s2)",
        },
        "bands": bands,
        "files": files.iter().map(|(f, w)| json!({ "file": f, "content": w })).collect::<Vec<_>>(),
    })
}
