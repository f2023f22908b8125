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
//! position in the camera frame and its polariser angle ([`crate::calibrate::flash_session`])
//! and writes the `[flash]` section below the camera section. Frames whose highlight is
//! rejected are listed with the reason. When the flash cannot be estimated (too few
//! highlights, rays that do not cross — an orbit aimed at the sphere —, highlights saturated
//! throughout or unpolarised) the camera section is still written, and the command fails with
//! why and the photos to take for the flash ([`flash_not_measured`]).
//!
//! `ellipso calibrate flash SESSION --sphere R,X,Y,Z --out RIG.toml` ([`Args::flash_only`])
//! does the same but writes only the `[flash]` table, into the rig file `RIG.toml`: its other
//! tables and comments are kept ([`crate::calibrate::flash_session::replace_flash_section`]),
//! and nothing is written when the flash is not measured.

use std::path::PathBuf;

use ellipso_model::camera::{CAMERA_PARAM_NAMES, CameraModel};
use ellipso_run_error::{Context, RunError, Say};
use ellipso_run_error::{ensure, say};
use rayon::prelude::*;

use crate::calibrate::flash_session::{
    FlashMeasurement, ViewHighlight, measure_flash, replace_flash_section, view_highlight,
};
use crate::calibrate::highlight::Sphere;
use crate::calibrate::views::{View, board_view};
use crate::calibrate::{CalibConfig, calibrate};
use crate::pose::DetectorConfig;
use crate::track::{DetectImage, FamilyDetectors, TrackedBoard};
use ellipso_polar::frame::RawFrame;
use ellipso_report::output::OutputFile;
use ellipso_session::reader::{self, FrameEntry, Session};

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
    /// Estimate the flash position and polariser angle from highlights on a glossy sphere:
    /// RADIUS,X,Y,Z in metres, the centre in the world frame of the session's boards.
    pub sphere: Option<Sphere>,
    /// `ellipso calibrate flash`: only the flash, its `[flash]` table put into the rig file
    /// `out` (its other tables kept; created when missing); the camera calibrated from the
    /// session gives the views' poses and is not written. Needs `sphere`.
    pub flash_only: bool,
}

/// What a run determined.
#[derive(Debug, Clone)]
pub struct SessionCalibration {
    /// The calibrated camera.
    pub camera: ellipso_model::camera::CameraModel,
    /// The flash, when a sphere was given and it was measured.
    pub flash: Option<FlashMeasurement>,
}

/// What the frames gave, in words: unreadable frames by reason, frames without a board's tag,
/// frames with too few corners.
fn frame_causes(detected: &[Result<(View, Option<usize>), String>]) -> String {
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
/// not: why, that the camera section is written (not for `calibrate flash`, `flash_only`: it
/// writes nothing then), and the photos that would measure the flash.
/// The flash is triangulated from the rays the highlights reflect towards it (fixed in the
/// camera frame); photos that all see the sphere at one place in the image and one distance —
/// an orbit aimed at its centre — give one ray again and again.
pub fn flash_not_measured(why: &str, flash_only: bool) -> String {
    let kept = if flash_only {
        "nothing is written"
    } else {
        "the [camera] section is written"
    };
    format!(
        "the flash (position and polariser angle) was not measured ({why}); {kept}. To \
         measure the flash, capture a session of the glossy sphere on the board with the sphere \
         at different places in the image — near each corner, the middle of each edge and the \
         centre — at two distances (about 0.3 m and 0.5 m): 10 photos or more, each showing the \
         sphere's highlight (with an unsaturated edge) and at least 2 tags of the board (not an \
         orbit aimed at the sphere: its highlights reflect one ray); then run `ellipso calibrate \
         flash SESSION --sphere R,X,Y,Z --out RIG.toml` (or `ellipso calibrate SESSION --sphere \
         R,X,Y,Z`) on that session"
    )
}

/// The session's complete frames with what detection made of each (stage 2 of [`run`]).
struct Detected<'a> {
    /// The complete frames, in session order.
    frames: Vec<&'a FrameEntry>,
    /// Per frame its view (empty when it has none).
    views: Vec<View>,
    /// Per frame the index of the board its view is of, if any.
    board_of_view: Vec<Option<usize>>,
    /// What the frames gave, in words ([`frame_causes`]).
    causes: String,
}

/// The camera the views are posed with, the posed views (index, camera_from_board) and the
/// `[camera]` section to write (none when the rig file's camera was used).
type PosedViews = (
    CameraModel,
    Vec<(usize, ellipso_model::camera::Pose)>,
    Option<String>,
);

/// Runs `ellipso calibrate`: claims the output, detects, calibrates, writes the rig sections;
/// every line of the report goes to `say`.
pub fn run(args: &Args, say: &dyn Say) -> Result<SessionCalibration, RunError> {
    ensure!(
        !args.flash_only || args.sphere.is_some(),
        "calibrate flash: give the sphere, --sphere R,X,Y,Z (radius and centre in metres, in the \
         world frame of the session's boards)"
    );
    let (out, rig_camera) = claim_output(args)?;
    let session = reader::open(&args.session)?;
    // calibration needs the boards only: the camera model is what it estimates
    let boards = crate::process::boards_of(&session)?;
    let detected = detect_views(args, &session, &boards, say)?;
    let size = (
        session.manifest.sensor.width,
        session.manifest.sensor.height,
    );
    let (camera, posed, camera_text) =
        camera_and_poses(rig_camera, &detected, size, args, &out, say)?;
    let camera_text = camera_text.unwrap_or_default();
    let Some(sphere) = args.sphere else {
        out.write(camera_text)?;
        say!(say, "rig sections written to {}", out.shown().display());
        return Ok(SessionCalibration {
            camera,
            flash: None,
        });
    };
    let highlights = sphere_highlights(&session, &detected, &boards, &camera, &posed, &sphere, say);
    let flash = match measure_flash(&camera, &highlights) {
        Ok(flash) => flash,
        Err(e) => {
            let why = e.to_string();
            if args.flash_only {
                return Err(RunError::msg(flash_not_measured(&why, true)));
            }
            // what was determined is kept: the camera section is written, then the flash
            // part's failure is the command's error, with the photos that would measure it
            out.write(camera_text)?;
            say!(say, "[camera] written to {}", out.shown().display());
            return Err(RunError::msg(flash_not_measured(&why, false)));
        }
    };
    say_flash(&flash, highlights.len(), say);
    write_flash(args, &out, &camera_text, &flash, say)?;
    Ok(SessionCalibration {
        camera,
        flash: Some(flash),
    })
}

/// Stage 1 of [`run`]: the output file claimed (the session's own `calibration/` by default,
/// never elsewhere inside it) and, for `calibrate flash`, the `[camera]` of the rig file it
/// names, if it has one.
fn claim_output(args: &Args) -> Result<(OutputFile, Option<CameraModel>), RunError> {
    let default_name = if args.flash_only {
        "flash.toml"
    } else {
        "camera.toml"
    };
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.session.join("calibration").join(default_name));
    let out = OutputFile::claim(
        &out,
        "calibrate",
        ellipso_report::output::FileFormat::TOML,
        &[&args.session],
        Some("calibration"),
    )?;
    // `calibrate flash` into a rig file that has a [camera]: the views are posed with it
    let rig_camera = if args.flash_only {
        rig_camera(out.path())
            .map_err(|e| RunError::msg(format!("{}: {e}", out.shown().display())))?
    } else {
        None
    };
    Ok((out, rig_camera))
}

/// Stage 2 of [`run`]: tags detected on every complete frame (in parallel), each frame's view
/// or why it has none; says how many frames are usable and what the others gave.
fn detect_views<'a>(
    args: &Args,
    session: &'a Session,
    boards: &[TrackedBoard],
    say: &dyn Say,
) -> Result<Detected<'a>, RunError> {
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
    let detected: Vec<Result<(View, Option<usize>), String>> = frames
        .par_iter()
        .map_init(
            || FamilyDetectors::new(boards, DetectorConfig::default()),
            |detectors, entry| {
                let detectors = detectors.as_mut().map_err(|e| e.to_string())?;
                let (w, h, px) = session.load_frame(entry).map_err(|e| e.to_string())?;
                let raw = RawFrame::new(w, h, s.bit_depth, layout, px)
                    .map_err(|e| format!("{}: {e}", entry.path.display()))?;
                board_view(detectors, &raw, boards, args.image).map_err(|e| e.to_string())
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
    let board_of_view: Vec<_> = detected
        .iter()
        .map(|d| d.as_ref().map(|(_, b)| *b).unwrap_or_default())
        .collect();
    Ok(Detected {
        frames,
        views,
        board_of_view,
        causes,
    })
}

/// Stage 3 of [`run`]: the views posed with the rig file's camera when there is one (it must
/// be of the session's frame size, `size`), else the camera calibrated from them.
fn camera_and_poses(
    rig_camera: Option<CameraModel>,
    detected: &Detected<'_>,
    size: (u32, u32),
    args: &Args,
    out: &OutputFile,
    say: &dyn Say,
) -> Result<PosedViews, RunError> {
    let (width, height) = size;
    Ok(match rig_camera {
        Some(camera) => {
            ensure!(
                (camera.width, camera.height) == (width, height),
                "{}: its [camera] is {}×{}, the session's frames {}×{}: not this camera's rig file",
                out.shown().display(),
                camera.width,
                camera.height,
                width,
                height
            );
            let posed = pose_views(&camera, &detected.views, say);
            say!(
                say,
                "{} views posed with the [camera] of {}",
                posed.len(),
                out.shown().display()
            );
            (camera, posed, None)
        }
        None => {
            let cal = calibrate_views(&detected.views, args, (width, height), say).with_context(
                || format!("{} frames: {}", detected.frames.len(), detected.causes),
            )?;
            let posed = cal
                .views
                .iter()
                .map(|v| (v.index, v.camera_from_board))
                .collect();
            (cal.camera, posed, Some(cal.to_toml_camera_section()))
        }
    })
}

/// Stage 4 of [`run`]: per posed view, its frame, board and pose → the highlight on `sphere`
/// and its polarisation; frames without one are said with why and left out.
fn sphere_highlights(
    session: &Session,
    detected: &Detected<'_>,
    boards: &[TrackedBoard],
    camera: &CameraModel,
    posed: &[(usize, ellipso_model::camera::Pose)],
    sphere: &Sphere,
    say: &dyn Say,
) -> Vec<ViewHighlight> {
    let layout = session.manifest.sensor.layout;
    let s = &session.manifest.sensor;
    posed
        .par_iter()
        .filter_map(|(index, camera_from_board)| {
            let board = &boards[detected.board_of_view[*index]?];
            let entry = detected.frames[*index];
            let found = session
                .load_frame(entry)
                .map_err(|e| e.to_string())
                .and_then(|(w, h, px)| {
                    RawFrame::new(w, h, s.bit_depth, layout, px).map_err(|e| e.to_string())
                })
                .and_then(|raw| {
                    view_highlight(
                        &raw,
                        camera,
                        camera_from_board,
                        &board.world_from_board(),
                        sphere,
                    )
                });
            match found {
                Ok(h) => Some(h),
                Err(why) => {
                    say!(say, "  frame {}: no highlight: {why}", entry.frame_id);
                    None
                }
            }
        })
        .collect()
}

/// Says the measured flash: its position (mm, camera frame) from `highlights` highlights, and
/// its polariser angle.
fn say_flash(flash: &FlashMeasurement, highlights: usize, say: &dyn Say) {
    let p = flash.position.flash_camera_m.coords * 1e3;
    let sd = flash.position.std_m.map(|v| v * 1e3);
    say!(
        say,
        "flash at ({:.2} ± {:.2}, {:.2} ± {:.2}, {:.2} ± {:.2}) mm in the camera frame from {} highlights, ray-angle RMS {:.3} mrad",
        p.x,
        sd[0],
        p.y,
        sd[1],
        p.z,
        sd[2],
        highlights,
        flash.position.rms_angle_rad * 1e3
    );
    say!(
        say,
        "flash polariser at {:.3} ± {:.3}° from camera x towards y (largest per-view geometric correction {:.3}°, lowest highlight DoLP {:.2})",
        flash.polariser.polariser_deg,
        flash.polariser.std_deg,
        flash.polariser.max_correction_deg,
        flash.polariser.min_dolp
    );
}

/// Stage 5 of [`run`]: the `[flash]` section written — into the rig file `out` with its other
/// tables kept (`calibrate flash`), else below `camera_text`.
fn write_flash(
    args: &Args,
    out: &OutputFile,
    camera_text: &str,
    flash: &FlashMeasurement,
    say: &dyn Say,
) -> Result<(), RunError> {
    let section = flash.to_toml_flash_section();
    if args.flash_only {
        // the rig file's other tables are kept as they are
        let existing = match std::fs::read_to_string(out.path()) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
            Err(e) => return Err(RunError::msg(format!("{}: {e}", out.shown().display()))),
        };
        let text = replace_flash_section(&existing, &section)
            .map_err(|e| RunError::msg(format!("{}: {e}", out.shown().display())))?;
        out.write(text)?;
        say!(say, "[flash] written to {}", out.shown().display());
    } else {
        out.write(format!("{camera_text}\n{section}"))?;
        say!(say, "rig sections written to {}", out.shown().display());
    }
    Ok(())
}

/// Calibrates the camera from the views and says the result (parameters ± σ, rejected views,
/// the views' spread).
fn calibrate_views(
    views: &[View],
    args: &Args,
    size: (u32, u32),
    say: &dyn Say,
) -> Result<crate::calibrate::Calibration, crate::calibrate::CalibError> {
    let config = CalibConfig {
        fix_k3: !args.free_k3,
        ..CalibConfig::default()
    };
    let cal = calibrate(views, size, &config)?;
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
    Ok(cal)
}

/// The `[camera]` table of the rig file at `path`, if the file exists and has one.
fn rig_camera(path: &std::path::Path) -> Result<Option<CameraModel>, String> {
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e.to_string()),
    };
    let table: toml::Table = toml::from_str(&text).map_err(|e| format!("not TOML: {e}"))?;
    table
        .get("camera")
        .map(|c| {
            c.clone()
                .try_into::<CameraModel>()
                .map_err(|e| format!("[camera]: {e}"))
        })
        .transpose()
}

/// Each view with at least 2 tags (8 corners) posed with a known camera: (view index,
/// camera_from_board); a view whose pose is rejected (reprojection RMS over 1 px: a camera
/// that is not this one; an ambiguous flip) is said with why and left out.
fn pose_views(
    camera: &CameraModel,
    views: &[View],
    say: &dyn Say,
) -> Vec<(usize, ellipso_model::camera::Pose)> {
    use crate::pose::estimate::{Correspondence, PoseConfig, estimate_board_pose};
    // the views carry no tag ids (one board's corners): the tag count is not checked, the
    // corner count and every other acceptance test of the tracker are
    let config = PoseConfig {
        min_tags: 0,
        ..PoseConfig::default()
    };
    views
        .iter()
        .enumerate()
        .filter(|(_, v)| v.len() >= 8)
        .filter_map(|(index, v)| {
            // one board's corners, as `calibrate` poses its views (no tag ids: one tag)
            let corr: Vec<Correspondence> = v
                .iter()
                .enumerate()
                .map(|(k, (q, px))| Correspondence {
                    tag_id: 0,
                    corner: (k % 4) as u8,
                    point_board_m: *q,
                    pixel: [px.x, px.y],
                })
                .collect();
            match estimate_board_pose(camera, &corr, &config) {
                Ok(p) => Some((index, p.camera_from_board)),
                Err(e) => {
                    say!(say, "  view {index}: not posed: {e}");
                    None
                }
            }
        })
        .collect()
}
