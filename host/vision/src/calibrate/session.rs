//! `ellipso calibrate SESSION` ([`run`]): camera intrinsics and Brown–Conrady distortion from the board
//! frames of a recorded session (Zhang's closed form, then Levenberg–Marquardt over all frames).
//!
//! Tags are detected on every complete frame; each frame contributes the corners of the board
//! it sees best (Zhang needs one plane per view). Prints the reprojection RMS and the parameter
//! standard errors, and writes the rig file's `[camera]` section (`--out`, default
//! `SESSION/calibration/camera.toml`) with each value's 1σ error in a comment.
//!
//! With `--sphere R,X,Y,Z` (a glossy sphere of radius R m centred at (X, Y, Z) m in the world
//! frame of the session's boards — the base board's frame when it sits at the world origin) it
//! also finds the flash's specular highlight on the sphere in every calibrated frame
//! ([`crate::calibrate::highlight`]), with that frame's calibrated pose, estimates the flash
//! position in the camera frame ([`crate::calibrate::flash`]) and writes the `[flash]` section
//! below the camera section. Frames whose highlight is rejected are listed with the reason.
//! When the flash cannot be estimated (too few highlights, or rays that do not cross — an
//! orbit aimed at the sphere) the camera section is still written, and the command fails with
//! why and the photos to take for the flash ([`flash_not_measured`]).

use std::path::PathBuf;

use ellipso_model::camera::CAMERA_PARAM_NAMES;
use ellipso_run_error::{Context, RunError, Say};
use ellipso_run_error::{ensure, say};
use rayon::prelude::*;

use crate::calibrate::flash::{HighlightObservation, estimate_flash_position};
use crate::calibrate::highlight::{HighlightConfig, Sphere, find_highlight};
use crate::calibrate::views::board_view;
use crate::calibrate::{CalibConfig, calibrate};
use crate::pose::DetectorConfig;
use crate::track::{DetectImage, FamilyDetectors};
use ellipso_polar::frame::RawFrame;
use ellipso_session::reader;

/// What `ellipso calibrate` runs (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct Args {
    /// Session directory (frames of AprilTag boards).
    pub session: PathBuf,
    /// Where to write the `[camera]` section.
    pub out: Option<PathBuf>,
    /// Detection image.
    pub image: DetectImage,
    /// Also estimate k3 (needs corners out to the image corners).
    pub free_k3: bool,
    /// Estimate the flash position from highlights on a glossy sphere: RADIUS,X,Y,Z in metres,
    /// the centre in the world frame of the session's boards.
    pub sphere: Option<Sphere>,
}

/// What the frames gave, in words: unreadable frames by reason, frames without a board's tag,
/// frames with too few corners.
fn frame_causes(
    detected: &[Result<(crate::calibrate::views::View, Option<usize>), String>],
) -> String {
    let mut unreadable: std::collections::BTreeMap<&str, usize> = Default::default();
    let (mut no_tags, mut few, mut good) = (0, 0, 0);
    for d in detected {
        match d {
            // the reason up to its first detail (file paths differ per frame)
            Err(e) => {
                *unreadable
                    .entry(e.split(": ").last().unwrap_or(e))
                    .or_insert(0) += 1
            }
            Ok((v, _)) if v.is_empty() => no_tags += 1,
            Ok((v, _)) if v.len() < 8 => few += 1,
            Ok(_) => good += 1,
        }
    }
    let mut parts = Vec::new();
    if !unreadable.is_empty() {
        let n: usize = unreadable.values().sum();
        let why: Vec<String> = unreadable
            .iter()
            .take(3)
            .map(|(k, n)| format!("{n} × {k}"))
            .collect();
        parts.push(format!("{n} unreadable: {}", why.join("; ")));
    }
    if no_tags > 0 {
        parts.push(format!("{no_tags} without a tag of the session's boards"));
    }
    if few > 0 {
        parts.push(format!("{few} with fewer than 2 tags of one board"));
    }
    parts.push(format!("{good} usable"));
    parts.join(", ")
}

/// The error of a `--sphere` run whose camera calibration succeeded and whose flash part did
/// not: why, that the camera section is written, and the photos that would measure the flash.
/// The flash is triangulated from the rays the highlights reflect towards it (fixed in the
/// camera frame); photos that all see the sphere at one place in the image and one distance —
/// an orbit aimed at its centre — give one ray again and again.
pub fn flash_not_measured(why: &str) -> String {
    format!(
        "the flash position was not measured ({why}); the [camera] section is written. To \
         measure the flash, capture a session of the glossy sphere on the board with the sphere \
         at different places in the image — near each corner, the middle of each edge and the \
         centre — at two distances (about 0.3 m and 0.5 m): 10 photos or more, each showing the \
         sphere's highlight and at least 2 tags of the board (not an orbit aimed at the sphere: \
         its highlights reflect one ray); then run `ellipso calibrate SESSION --sphere R,X,Y,Z` \
         on that session"
    )
}

/// Runs `ellipso calibrate`: claims the output, detects, calibrates, writes the rig sections;
/// every line of the report goes to `say`.
pub fn run(args: &Args, say: &dyn Say) -> Result<(), RunError> {
    // claimed first: the session's own `calibration/` by default, never elsewhere inside it
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.session.join("calibration").join("camera.toml"));
    let out = ellipso_report::output::OutputFile::claim(
        &out,
        "calibrate",
        ellipso_report::output::FileFormat::TOML,
        &[&args.session],
        Some("calibration"),
    )?;
    let session = reader::open(&args.session)?;
    // calibration needs the boards only: the camera model is what it estimates
    let boards = crate::process::boards_of(&session)?;
    let layout = session.manifest.sensor.layout;
    let s = &session.manifest.sensor;
    let frames: Vec<_> = session.frames.iter().filter(|f| f.complete).collect();
    ensure!(
        !frames.is_empty(),
        "{}: no complete frame to calibrate from ({} frames on disk, {} flagged incomplete)",
        args.session.display(),
        session.frames.len(),
        session.frames.iter().filter(|f| !f.complete).count()
    );
    say!(
        say,
        "detecting tags on {} frames ({:?} image)…",
        frames.len(),
        args.image
    );
    // per frame: its view, or why it has none (kept, so a failed calibration can say why)
    let detected: Vec<Result<(crate::calibrate::views::View, Option<usize>), String>> = frames
        .par_iter()
        .map_init(
            || FamilyDetectors::new(&boards, DetectorConfig::default()),
            |detectors, entry| {
                let detectors = detectors.as_mut().map_err(|e| e.to_string())?;
                let (w, h, px) = session.load_frame(entry).map_err(|e| e.to_string())?;
                let raw = RawFrame::new(w, h, s.bit_depth, layout, px)
                    .map_err(|e| format!("{}: {e}", entry.path.display()))?;
                board_view(detectors, &raw, &boards, args.image).map_err(|e| e.to_string())
            },
        )
        .collect();
    let views: Vec<_> = detected
        .iter()
        .map(|d| d.as_ref().map(|(v, _)| v.clone()).unwrap_or_default())
        .collect();
    let usable = views.iter().filter(|v| v.len() >= 8).count();
    let causes = frame_causes(&detected);
    say!(say, "{usable} frames with ≥ 2 tags of one board ({causes})");
    let config = CalibConfig {
        fix_k3: !args.free_k3,
        ..CalibConfig::default()
    };
    let cal = calibrate(&views, (s.width, s.height), &config)
        .with_context(|| format!("{} frames: {causes}", frames.len()))?;
    let detected: Vec<_> = detected
        .into_iter()
        .map(|d| d.unwrap_or_default())
        .collect();
    say!(
        say,
        "reprojection RMS {:.4} px over {} views ({} rejected)",
        cal.rms_px,
        cal.views.len(),
        cal.rejected.len()
    );
    let params = cal.camera.params();
    for (k, name) in CAMERA_PARAM_NAMES.iter().enumerate() {
        if cal.estimated[k] {
            say!(
                say,
                "  {name:<3} = {:>14.6} ± {:.6}",
                params[k],
                cal.std_errors[k]
            );
        } else {
            say!(say, "  {name:<3} = {:>14.6}   (fixed)", params[k]);
        }
    }
    for r in &cal.rejected {
        say!(say, "  view {} rejected: {}", r.index, r.reason);
    }
    say!(
        say,
        "views: board tilt spread {:.2}°, out of one plane {:.3}° (common direction {:.3?})",
        cal.spread.tilt_spread_deg,
        cal.spread.out_of_plane_deg,
        cal.spread.common_direction_camera.as_slice()
    );
    let mut text = cal.to_toml_camera_section();
    if let Some(sphere) = args.sphere {
        let flash: Result<String, String> = 'flash: {
            // per calibrated view: its frame, board and pose → the highlight
            let observations: Vec<HighlightObservation> = cal
                .views
                .par_iter()
                .filter_map(|v| {
                    let board = &boards[detected[v.index].1?];
                    let entry = frames[v.index];
                    let found = session
                        .load_frame(entry)
                        .map_err(|e| e.to_string())
                        .and_then(|(w, h, px)| {
                            RawFrame::new(w, h, s.bit_depth, layout, px).map_err(|e| e.to_string())
                        })
                        .and_then(|raw| {
                            let camera_from_world =
                                v.camera_from_board * board.world_from_board().inverse();
                            find_highlight(
                                &raw,
                                &cal.camera,
                                &camera_from_world,
                                &sphere,
                                &HighlightConfig::default(),
                            )
                            .map_err(|e| e.to_string())
                        });
                    match found {
                        Ok(h) => Some(HighlightObservation {
                            camera_from_board: v.camera_from_board,
                            sphere_centre_board_m: board.world_from_board().inverse()
                                * sphere.centre_m,
                            sphere_radius_m: sphere.radius_m,
                            highlight_px: h.pixel,
                        }),
                        Err(why) => {
                            say!(say, "  frame {}: no highlight: {why}", entry.frame_id);
                            None
                        }
                    }
                })
                .collect();
            let flash = match estimate_flash_position(&cal.camera, &observations) {
                Ok(flash) => flash,
                Err(e) => break 'flash Err(e.to_string()),
            };
            let p = flash.flash_camera_m.coords * 1e3;
            let sd = flash.std_m.map(|v| v * 1e3);
            say!(
                say,
                "flash at ({:.2} ± {:.2}, {:.2} ± {:.2}, {:.2} ± {:.2}) mm in the camera frame from {} highlights, ray-angle RMS {:.3} mrad",
                p.x,
                sd[0],
                p.y,
                sd[1],
                p.z,
                sd[2],
                observations.len(),
                flash.rms_angle_rad * 1e3
            );
            Ok(flash.to_toml_flash_section())
        };
        match flash {
            Ok(section) => {
                text.push('\n');
                text.push_str(&section);
            }
            Err(why) => {
                // what was determined is kept: the camera section is written, then the flash
                // part's failure is the command's error, with the photos that would measure it
                out.write(text)?;
                say!(say, "[camera] written to {}", out.shown().display());
                return Err(RunError::msg(flash_not_measured(&why)));
            }
        }
    }
    out.write(text)?;
    say!(say, "rig sections written to {}", out.shown().display());
    Ok(())
}
