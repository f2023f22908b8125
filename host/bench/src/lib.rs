//! ellipso's end-to-end benchmarks against the simulator's truth.
//!
//! The fit-only benches (`ellipso bench accuracy`) simulate each observation with the very
//! optics the fit inverts; what a user gets goes through the whole chain — rendered frames, the
//! mosaic and its demosaic, tracked poses, the carved mesh, the fit. This crate measures that
//! chain and what each of its stages costs, by replacing one stage at a time with its truth
//! ([`chain`], `ellipso bench chain`, docs/error-budget.md).
//!
//! | module | what it does |
//! |---|---|
//! | [`truth`] | a scene's object with its true parameters per vertex, and the views of its capture path |
//! | [`accuracy`] | observation-level simulated captures with known truth, and a fit's errors against it (`ellipso bench accuracy`) |
//! | [`variant`] | scene files with effects removed (or seed, photo count changed) |
//! | [`capture`] | a scene rendered straight into a session; true poses of a recorded session |
//! | [`ideal`] | a session's frames as an ideal polarisation sensor sees them (no mosaic) |
//! | [`truth_map`] | the truth at the vertices of any mesh (closest point of the true surface) |
//! | [`coverage`] | what a fit covers of the surface its views see (decided from the true geometry), per material, with its accuracy and σ calibration (`ellipso bench score`) |
//! | [`score`] | per-material and per-vertex errors, held-out re-render beside the truth's own, residuals at the truth |
//! | [`surface`] | a carved and a refined mesh against the truth, observed and unobserved surface apart; η beside the true mesh's |
//! | [`chain`] | the error budget: the full chain and one stage replaced at a time |
//! | [`report`] | the budget as docs/error-budget.md, its JSON and a plot |
//! | [`budget`] | `ellipso bench chain`: the budget's runs on a scene and its report files |
//! | [`accuracy_time`] | `ellipso bench accuracy`: fit error against seconds on simulated captures, and its report |
//! | [`pose`] | `ellipso bench pose`: pose accuracy and speed per detection image; the rendered frames of the other benches |
//! | [`calibration`] | `ellipso bench calibration`: the camera calibration against the renderer's camera |
//! | [`sim_render`] | `ellipso sim render`: a scene's capture as raw frames, `truth.json` and per-pixel truth |
//! | [`view_cost`] | `ellipso bench view`: what the live view costs a simulated capture |
//! | [`rig_capture`] | a scene captured on the simulated rig (pty link, pairing), recorded by the caller |
//! | [`demo`] | `ellipso demo`: capture, tracking, carving and fit, scored against the truth; pictures and `summary.json` |
//! | [`generalize`] | `ellipso bench generalize`: the whole chain on procedurally generated scenes (held-out seeds ≥ 1000), `docs/generalize.md` |
//! | [`generalize_report`] | its figures over a set of scenes and its Markdown report |
//! | [`mesh_bench`] | `ellipso bench mesh`: the built-in mesh (and with `--fit` the refined one) against the truth, its cost, `docs/mesh-bench.md` |
//! | [`table`] | the head of a report's Markdown table (column names and alignment rule) from one list |
#![forbid(unsafe_code)]

pub mod accuracy;
pub mod accuracy_time;
pub mod budget;
pub mod calibration;
pub mod capture;
pub mod chain;
pub mod coverage;
pub mod demo;
pub mod generalize;
pub mod generalize_report;
pub mod ideal;
pub mod mesh_bench;
pub mod pose;
pub mod report;
pub mod rig_capture;
pub mod score;
pub mod sensor_calibration;
pub mod sim_render;
pub mod surface;
pub mod table;
pub mod truth;
pub mod truth_map;
pub mod variant;
pub mod view_cost;

use std::path::{Path, PathBuf};

/// Why a bench run failed.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// File I/O.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// A scene file could not be read, edited or loaded.
    #[error("scene {}: {what}", path.display())]
    Scene {
        /// The scene file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// Rendering failed.
    #[error("render: {0}")]
    Render(String),
    /// Writing or reading a session failed.
    #[error("session: {0}")]
    Session(String),
    /// A stage of the chain (tracking, meshing, fitting) failed.
    #[error("{stage}: {what}")]
    Stage {
        /// The stage.
        stage: &'static str,
        /// What went wrong.
        what: String,
    },
}

impl BenchError {
    fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_owned(),
            source,
        }
    }

    fn stage(stage: &'static str, e: impl std::fmt::Display) -> Self {
        Self::Stage {
            stage,
            what: e.to_string(),
        }
    }
}
