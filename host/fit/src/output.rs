//! A finished session fit's files, as `ellipso fit`, `ellipso fit-merge` and the demo write
//! them: the pictures and maps ([`crate::export`]) from one view and `fit-summary.json`
//! ([`crate::summary::FitSummary`]).
//!
//! Contract: [`export_fit`] writes into a folder the caller owns (an output's staging folder)
//! and records every path as it will be once the caller commits that folder
//! ([`OutputTo::publish`]). Its lines (skipped frames, the held-out score, the picture's frame)
//! go to the caller's [`Say`]; each skipped frame is also a `tracing` warning. It never prints.

use std::path::{Path, PathBuf};
use std::time::Instant;

use ellipso_run_error::{Context, RunError, Say};
use ellipso_session::reader::Session;
use nalgebra::Isometry3;

use crate::session::SessionFit;
use crate::summary::FitSummary;

/// Where a fit's outputs go: the (staging) folder written now, and where a path under it will
/// be once the output is committed (the paths recorded and shown).
pub struct OutputTo<'a> {
    /// The folder written now.
    pub dir: &'a Path,
    /// A path under `dir` as it will be once the output is committed.
    pub publish: &'a dyn Fn(&Path) -> PathBuf,
}

/// What a session fit wrote.
pub struct FitRun {
    /// The fit.
    pub fit: SessionFit,
    /// Every file written, as published.
    pub files: Vec<PathBuf>,
    /// Wall time, seconds.
    pub wall_s: f64,
    /// What `fit-summary.json` holds (its paths relative to its folder).
    pub summary: FitSummary,
}

/// Writes a finished fit's outputs into `to.dir`: pictures from frame `view` (default: the
/// first fitted frame), `fit-summary.json` with `import` where poses or a mesh were imported;
/// `poses` are the poses the fit was given, `started` is when the whole run began.
#[expect(
    clippy::too_many_arguments,
    reason = "the fit, its poses, its output and what the run adds are independent values"
)]
pub fn export_fit(
    session: &Session,
    poses: &[(u64, Isometry3<f64>)],
    fit: SessionFit,
    to: OutputTo<'_>,
    view: Option<u64>,
    started: Instant,
    import: Option<serde_json::Value>,
    say: &dyn Say,
) -> Result<FitRun, RunError> {
    let (out, publish) = (to.dir, to.publish);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    // every posed frame that gave nothing is said, with its reason, and counted in the summary
    for s in &fit.observe.skipped {
        tracing::warn!("frame {} skipped: {}", s.frame_id, s.reason);
    }
    if !fit.observe.skipped.is_empty() {
        say.err(format_args!(
            "warning: {} of {} posed frames skipped (reasons above and in fit-summary.json)",
            fit.observe.skipped.len(),
            fit.observe.frames_posed
        ));
    }
    let (frame_id, world_from_camera) = match view {
        Some(id) => *poses
            .iter()
            .find(|p| p.0 == id)
            .with_context(|| format!("frame {id} has no pose"))?,
        None => fit.poses_fitted.first().copied().unwrap_or(poses[0]),
    };
    // The comparison picture shows the held-out frame with the most samples (one the fit never
    // saw); without held-out frames, the view of the maps.
    let comparison = fit
        .holdout
        .as_ref()
        .and_then(|h| h.per_frame.iter().max_by_key(|f| f.samples))
        .and_then(|f| f.frame_id)
        .and_then(|id| fit.poses_held_out.iter().find(|p| p.0 == id))
        .map(|p| (p.0, p.1, true))
        .unwrap_or((frame_id, world_from_camera, false));
    if let Some(h) = &fit.holdout {
        say.err(format_args!(
            "held-out views: {} frames, {} samples: s0 relative RMSE {:.3} (PSNR {:.1} dB), I^s {:.3}, I^alpha {:.3}",
            h.per_frame.len(),
            h.overall.samples,
            h.overall.s0.relative_rmse,
            h.overall.s0.psnr_db,
            h.overall.specular.relative_rmse,
            h.overall.alpha.relative_rmse
        ));
    }
    let rig = (session.manifest.rig.as_ref())
        .context("the session's manifest has no usable rig section")?;
    let flash = crate::observe::flash_of(session)?;
    say.err(format_args!("pictures from frame {frame_id}…"));
    let captured_s0 =
        match crate::export::captured_s0(session, comparison.0, comparison.1, comparison.2) {
            Ok(c) => Some(crate::export::CapturedS0 {
                held_out_samples_rmse: fit.holdout.as_ref().map(|h| h.overall.s0.relative_rmse),
                ..c
            }),
            Err(e) => {
                say.err(format_args!(
                    "note: no comparison picture: frame {}: {e}",
                    comparison.0
                ));
                None
            }
        };
    let report = crate::export::export_all(
        out,
        &fit.mesh,
        &fit.outcome.fits,
        // each vertex's material as the summary's `materials` count it
        fit.completion.as_ref().map(|c| c.labels.as_slice()),
        &rig.camera,
        &world_from_camera,
        &flash,
        &crate::export::ExportConfig::default(),
        captured_s0.as_ref(),
    )?;
    let wall_s = started.elapsed().as_secs_f64();
    // printed paths are where the files will be, not the staging directory; the summary's are
    // made relative to its folder from where they are now (below)
    let mut files: Vec<PathBuf> = report.files.iter().map(|f| publish(f)).collect();
    let mut summary = FitSummary {
        clusters: fit
            .outcome
            .augmentation
            .as_ref()
            .map(|a| a.clusters.clone()),
        coverage: fit.completion.clone(),
        export: report,
        frames_fitted: fit.poses_fitted.len(),
        frames_held_out: fit.poses_held_out.iter().map(|p| p.0).collect(),
        frames_posed: poses.len(),
        frames_skipped: fit.observe.skipped.clone(),
        frames_used: fit.observe.frames_used,
        gates: fit.gates.clone(),
        held_out: fit.holdout.clone(),
        import,
        materials: crate::materials::material_eta(&fit.outcome.fits, fit.completion.as_ref()),
        normal_combination: fit.normal_combination.clone(),
        partition: fit
            .outcome
            .augmentation
            .as_ref()
            .map(|a| a.partition.clone()),
        observe: fit.observe.clone(),
        observed_vertices: fit.observed.iter().filter(|o| **o).count(),
        peak_rss_bytes: ellipso_report::memory::peak_rss_bytes(),
        pooling: fit.outcome.pooling,
        session: session.dir.display().to_string(),
        session_report: session.report.summary(),
        surface_stopped: fit.surface.iter().rev().find_map(|s| s.stopped.clone()),
        surface_update: fit.surface.clone(),
        times_s: fit.outcome.times.clone(),
        vertices: fit.outcome.fits.len(),
        view_frame_id: frame_id,
        wall_s,
    };
    // every path in the summary is relative to its own folder
    summary.make_paths_relative(out);
    let path = out.join("fit-summary.json");
    summary.write(&path, &publish(&path))?;
    files.push(publish(&path));
    Ok(FitRun {
        fit,
        files,
        wall_s,
        summary,
    })
}
