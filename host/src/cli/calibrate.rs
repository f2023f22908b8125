//! `ellipso calibrate SESSION`: camera intrinsics and Brown–Conrady distortion from the board
//! frames of a recorded session (Zhang's closed form, then Levenberg–Marquardt over all frames).
//!
//! Tags are detected on every complete frame; each frame contributes the corners of the board
//! it sees best (Zhang needs one plane per view). Prints the reprojection RMS and the parameter
//! standard errors, and writes the rig file's `[camera]` section (`--out`, default
//! `SESSION/calibration/camera.toml`) with each value's 1σ error in a comment.

use std::path::PathBuf;

use anyhow::Context;
use ellipso_sim::camera::CAMERA_PARAM_NAMES;
use rayon::prelude::*;

use crate::calibrate::{CalibConfig, calibrate};
use crate::polar::frame::RawFrame;
use crate::calibrate::views::board_view;
use crate::pose::{DetectorConfig, TagDetector};
use crate::process::layout_of;
use crate::session::reader;
use crate::track::DetectImage;

/// Arguments of `ellipso calibrate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Session directory (frames of AprilTag boards).
    pub session: PathBuf,
    /// Where to write the `[camera]` section.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Detection image.
    #[arg(long, value_enum, default_value_t = DetectImage::S0)]
    pub image: DetectImage,
    /// Also estimate k3 (needs corners out to the image corners).
    #[arg(long)]
    pub free_k3: bool,
}

/// Runs `ellipso calibrate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let session = reader::open(&args.session)?;
    // calibration needs the boards only: the camera model is what it estimates
    let boards = crate::process::boards_of(&session)?;
    let layout = layout_of(&session.manifest)?;
    let s = &session.manifest.sensor;
    let frames: Vec<_> = session.frames.iter().filter(|f| f.complete).collect();
    println!(
        "detecting tags on {} frames ({:?} image)…",
        frames.len(),
        args.image
    );
    let views: Vec<crate::calibrate::views::View> = frames
        .par_iter()
        .map_init(
            || TagDetector::new(DetectorConfig::default()),
            |detector, entry| {
                let Ok(detector) = detector else {
                    return Vec::new();
                };
                let Ok((w, h, px)) = session.load_frame(entry) else {
                    return Vec::new();
                };
                let Ok(raw) = RawFrame::new(w, h, s.bit_depth, layout, px) else {
                    return Vec::new();
                };
                board_view(detector, &raw, &boards, args.image)
                    .map(|(view, _)| view)
                    .unwrap_or_default()
            },
        )
        .collect();
    let usable = views.iter().filter(|v| v.len() >= 8).count();
    println!("{usable} frames with ≥ 2 tags of one board");
    let config = CalibConfig {
        fix_k3: !args.free_k3,
        ..CalibConfig::default()
    };
    let cal = calibrate(&views, (s.width, s.height), &config)?;
    println!(
        "reprojection RMS {:.4} px over {} views ({} rejected)",
        cal.rms_px,
        cal.views.len(),
        cal.rejected.len()
    );
    let params = cal.camera.params();
    for (k, name) in CAMERA_PARAM_NAMES.iter().enumerate() {
        if cal.estimated[k] {
            println!(
                "  {name:<3} = {:>14.6} ± {:.6}",
                params[k], cal.std_errors[k]
            );
        } else {
            println!("  {name:<3} = {:>14.6}   (fixed)", params[k]);
        }
    }
    for r in &cal.rejected {
        println!("  view {} rejected: {}", r.index, r.reason);
    }
    let out = args
        .out
        .unwrap_or_else(|| args.session.join("calibration").join("camera.toml"));
    if let Some(parent) = out.parent() {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    std::fs::write(&out, cal.to_toml_camera_section())
        .with_context(|| format!("writing {}", out.display()))?;
    println!("camera section written to {}", out.display());
    Ok(())
}
