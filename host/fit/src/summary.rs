//! `fit-summary.json`: what a session fit did, beside its files (`ellipso fit`, `fit-merge`, the
//! demo's `fit/`; docs/fit-outputs.md, "`fit-summary.json`").
//!
//! Contract: [`FitSummary`] is the file's one schema, a rustdoc per key. The fields are
//! declared in alphabetical order and the file is written through a `serde_json::Value`, whose
//! map sorts keys: every object in the file, nested ones too, lists its keys alphabetically
//! (as the `serde_json::json!` object it replaces did), so the bytes do not depend on the
//! declaration order of the nested reports. Paths in it are relative to the file's own folder
//! where they name an existing file ([`FitSummary::make_paths_relative`],
//! `ellipso_report::paths`).

use std::path::Path;

use ellipso_report::paths::{paths_relative_to, relative_path};
use ellipso_run_error::{Context, RunError};

use crate::augment::{ClusterModel, PartitionSummary};
use crate::complete::Completion;
use crate::data::GateCounts;
use crate::export::ExportReport;
use crate::holdout::HoldoutReport;
use crate::observe::{ObserveReport, SkippedFrame};
use crate::pipeline::{PoolingSummary, StageTimes};
use crate::shape::combine::NormalCombination;
use crate::shape::surface::SurfaceIteration;

/// The contents of `fit-summary.json` (module doc). Fields in alphabetical order, as the file
/// lists them.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FitSummary {
    /// The clusters of step B with their two-lobe models and pooled η; `null` when step B did
    /// not run (`--joint-only`).
    pub clusters: Option<Vec<ClusterModel>>,
    /// What the fit covers of the surface the views see (decided from the poses and the mesh,
    /// not from the gates), overall and per material: observed vertices, how many the fit
    /// identified from their own samples, how many took their material's values
    /// (`FromMaterial`), how many stay withheld (`crate::complete::Completion`); `null` when
    /// step B did not run (no materials).
    pub coverage: Option<Completion>,
    /// The pictures and maps written: `files` (every file, in writing order), `rerender_rmse`
    /// (the comparison picture's relative RMSE) and `comparison_frame` (`{frame_id,
    /// held_out}`: the frame `rerender-vs-captured.png` shows) and `holes` (per picture view,
    /// the observed surface it shows and how many of those pixels are grey).
    pub export: ExportReport,
    /// Number of posed frames the fit used (the held-out ones excluded).
    pub frames_fitted: usize,
    /// Frame ids of the held-out frames (no step of the fit saw them; scored in `held_out`).
    pub frames_held_out: Vec<u64>,
    /// Number of poses the fit was given: the tracked ones, or with `--poses` the tracked and
    /// gained ones less the dropped ones.
    pub frames_posed: usize,
    /// Every posed frame that gave no samples, with its reason (also in `observe`).
    pub frames_skipped: Vec<SkippedFrame>,
    /// Number of frames that gave samples in the last extraction.
    pub frames_used: usize,
    /// Sample gate counts of the last extraction per reason, summed over vertices.
    pub gates: GateCounts,
    /// The re-render errors on the held-out frames, per frame and overall; `null` when none
    /// were held out or none gave samples.
    pub held_out: Option<HoldoutReport>,
    /// With `--poses`, `--mesh-frame colmap` or `--mesh-model`: the COLMAP alignment
    /// (`import.poses`, `import.mesh`; `ellipso_pipeline::fit_import::ImportSummary`, whose crate
    /// comes after this one); absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub import: Option<serde_json::Value>,
    /// Per material (step B's clusters): the pooled η, the median and spread of the η the
    /// vertices report from their own samples, and how many report it (`crate::materials`);
    /// empty when step B did not run.
    pub materials: Vec<crate::materials::MaterialEta>,
    /// How the reported normals were combined with the refined surface's
    /// (`shape::combine`); `null` when no surface step was applied.
    pub normal_combination: Option<NormalCombination>,
    /// The last extraction's whole report (frames posed, used, skipped with reasons).
    pub observe: ObserveReport,
    /// Number of vertices observed by at least one fitted frame (a kept sample).
    pub observed_vertices: usize,
    /// How step B partitioned the vertices into materials: k, sizes, the silhouette of every
    /// k tried, `joined_from` when clusters that were not separated were joined; `null` when
    /// step B did not run.
    pub partition: Option<PartitionSummary>,
    /// The process's peak resident memory, bytes (`null` where the system does not say).
    pub peak_rss_bytes: Option<u64>,
    /// The standard error of η before and after pooling; `null` when step B did not run.
    pub pooling: Option<PoolingSummary>,
    /// The session folder.
    pub session: String,
    /// What reading the session found (`intact`, or what was cut short or skipped).
    pub session_report: String,
    /// Why the surface update stopped (the last step that says), `null` when it ran every
    /// outer iteration.
    pub surface_stopped: Option<String>,
    /// One entry per surface update step (sizes, convergence, refusals; docs/fit-shape.md).
    pub surface_update: Vec<SurfaceIteration>,
    /// Stage timings, seconds (a merged fit's observation and step A times are the shards'
    /// summed CPU-seconds).
    pub times_s: StageTimes,
    /// Number of fitted vertices.
    pub vertices: usize,
    /// Frame id of the pictures' view.
    pub view_frame_id: u64,
    /// Wall time of the whole run, seconds (reading, poses, fit and pictures).
    pub wall_s: f64,
}

impl FitSummary {
    /// Rewrites the paths in the summary (the session folder, the files written, the import's
    /// model folders and mesh) relative to `base`, the summary's folder, where they name an
    /// existing file or directory (`ellipso_report::paths`).
    ///
    /// The session and the files are known to be paths, so they are rewritten whatever they
    /// look like (a bare `s1` is a folder too); `export.files` must name the files where they
    /// are now (the staging folder `base`, before the output is committed), not where they
    /// will be published.
    pub fn make_paths_relative(&mut self, base: &Path) {
        if let Some(r) = relative_path(Path::new(&self.session), base) {
            self.session = r.display().to_string();
        }
        for f in &mut self.export.files {
            if let Some(r) = relative_path(f, base) {
                *f = r;
            }
        }
        if let Some(import) = &mut self.import {
            paths_relative_to(import, base);
        }
    }

    /// The file's bytes: pretty-printed JSON, keys sorted (module doc).
    pub fn to_json(&self) -> Result<Vec<u8>, serde_json::Error> {
        serde_json::to_vec_pretty(&serde_json::to_value(self)?)
    }

    /// Writes the summary to `path` whole (`shown`: the path as the error names it).
    pub fn write(&self, path: &Path, shown: &Path) -> Result<(), RunError> {
        ellipso_report::atomic_file::write(path, self.to_json()?)
            .with_context(|| format!("writing {}", shown.display()))
    }
}
