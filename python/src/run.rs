//! `ellipso.mesh(…)` and `ellipso.fit(…)`: the bodies of `ellipso mesh` and `ellipso fit`
//! (`ellipso_pipeline::mesh::mesh_command`, `ellipso_pipeline::fit_run::run`) run from Python
//! with a progress callback, stoppable with Ctrl-C.
//!
//! Contract:
//! - The work runs on a thread of its own with the GIL released; the calling thread waits for
//!   its messages, passes each progress line to `progress(kind, text)` (kind `begin`, `stage`,
//!   `end`, `line`) and checks for Python signals between them (every 50 ms at most).
//! - Ctrl-C (or an exception raised by `progress`) asks the work to stop; it stops at its next
//!   progress point (a stage of the carving or the fit: seconds, not minutes, at the sizes
//!   the fit runs) by unwinding, which drops the claimed output's staging folder
//!   (`ellipso_report::output`): nothing half-written is left, an earlier output at `out` is
//!   unchanged, and the call raises the `KeyboardInterrupt` (or the callback's exception) once
//!   the work has stopped. Lines appended to the session's log (poses tracked on the way) are
//!   whole lines, as with the CLI.
//! - Errors raise with the CLI's messages ([`crate::errors`]).

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, unbounded};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use ellipso_fit::session::SessionFitConfig;
use ellipso_pipeline::fit_run::{FitDone, FitRequest};
use ellipso_pipeline::steps::Steps;
use ellipso_run_error::{RunError, Say};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{EllipsoError, run_error};
use crate::session::to_python;

/// The payload of the unwind that stops the work.
struct Cancelled;

/// How often the waiting thread looks for signals.
const POLL: Duration = Duration::from_millis(50);

/// A progress line from the work.
enum Message {
    Progress(&'static str, String),
}

/// The work's [`Steps`] and [`Say`]: forwards every line, and stops the work when asked.
#[derive(Clone)]
struct Forward {
    tx: Sender<Message>,
    cancel: Arc<AtomicBool>,
}

impl Forward {
    fn send(&self, kind: &'static str, text: String) {
        if self.cancel.load(Ordering::Acquire) {
            std::panic::panic_any(Cancelled);
        }
        let _ = self.tx.send(Message::Progress(kind, text));
    }
}

impl Steps for Forward {
    fn begin(&mut self, label: &str) {
        self.send("begin", label.to_string());
    }
    fn stage(&mut self, name: &str) {
        self.send("stage", name.to_string());
    }
    fn end(&mut self, summary: &str) {
        self.send("end", summary.to_string());
    }
}

impl Say for Forward {
    fn out(&self, line: std::fmt::Arguments<'_>) {
        self.send("line", line.to_string());
    }
    fn err(&self, line: std::fmt::Arguments<'_>) {
        self.send("line", line.to_string());
    }
}

/// Keeps the stop's unwind out of the panic hook's report (once per process).
fn quiet_cancel_hook() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !info.payload().is::<Cancelled>() {
                previous(info);
            }
        }));
    });
}

/// Runs `work` on its own thread (module contract) and returns what it returned.
fn drive<T: Send + 'static>(
    py: Python<'_>,
    progress: Option<&Bound<'_, PyAny>>,
    work: impl FnOnce(&mut Forward) -> Result<T, RunError> + Send + 'static,
) -> PyResult<T> {
    quiet_cancel_hook();
    let (tx, rx): (Sender<Message>, Receiver<Message>) = unbounded();
    let cancel = Arc::new(AtomicBool::new(false));
    let mut forward = Forward {
        tx,
        cancel: cancel.clone(),
    };
    let handle = std::thread::Builder::new()
        .name("ellipso-run".into())
        .spawn(move || catch_unwind(AssertUnwindSafe(move || work(&mut forward))))
        .map_err(|e| EllipsoError::new_err(format!("cannot start the work's thread: {e}")))?;
    let mut stop: Option<PyErr> = None;
    loop {
        match py.detach(|| rx.recv_timeout(POLL)) {
            Ok(Message::Progress(kind, text)) => {
                if let (Some(cb), None) = (progress, &stop)
                    && let Err(e) = cb.call1((kind, text))
                {
                    cancel.store(true, Ordering::Release);
                    stop = Some(e);
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            // the work is over: every sender is dropped
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if stop.is_none()
            && let Err(e) = py.check_signals()
        {
            cancel.store(true, Ordering::Release);
            stop = Some(e);
        }
    }
    let joined = py.detach(|| handle.join());
    if let Some(e) = stop {
        // stopped (or finished just before the stop was seen: its output then stands)
        return Err(e);
    }
    match joined {
        Ok(Ok(Ok(value))) => Ok(value),
        Ok(Ok(Err(e))) => Err(run_error(e)),
        Ok(Err(panic)) | Err(panic) => {
            let text = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            Err(EllipsoError::new_err(format!("internal error: {text}")))
        }
    }
}

/// `ellipso mesh SESSION --out OUT --vertices N`: returns `{mesh_file, report_file, report,
/// wall_s}`.
#[pyfunction]
#[pyo3(signature = (session, out, *, vertices=2500, progress=None))]
pub fn mesh<'py>(
    py: Python<'py>,
    session: PathBuf,
    out: PathBuf,
    vertices: usize,
    progress: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    check_vertices(vertices)?;
    let done = drive(py, progress.as_ref(), move |fw| {
        let mut config = ellipso_mesh::MeshConfig::default();
        config.remesh.target_vertices = vertices;
        let say = fw.clone();
        ellipso_pipeline::mesh::mesh_command(&session, &out, &config, fw, &say)
    })?;
    let d = PyDict::new(py);
    d.set_item("mesh_file", &done.mesh_file)?;
    d.set_item("report_file", &done.report_file)?;
    d.set_item("report", to_python(py, &done.report)?)?;
    d.set_item("wall_s", done.wall_s)?;
    Ok(d)
}

fn check_vertices(vertices: usize) -> PyResult<()> {
    if !(100..=2_000_000).contains(&vertices) {
        return Err(PyValueError::new_err(format!(
            "vertices {vertices} is outside 100..=2000000"
        )));
    }
    Ok(())
}

/// The fit's settings from the keywords, checked as `ellipso fit` checks its flags.
fn fit_config(
    outer: Option<usize>,
    holdout: f64,
    joint_only: bool,
    normal_prior_deg: f64,
    grazing_cutoff_deg: f64,
) -> PyResult<SessionFitConfig> {
    let bad = |text: String| Err(PyValueError::new_err(text));
    if let Some(o) = outer
        && !(1..=20).contains(&o)
    {
        return bad(format!("outer {o} is outside 1..=20"));
    }
    if !(normal_prior_deg.is_finite() && (0.0..=90.0).contains(&normal_prior_deg)) {
        return bad(format!(
            "normal_prior_deg {normal_prior_deg}: must be in [0, 90]"
        ));
    }
    if !(grazing_cutoff_deg.is_finite() && (10.0..=89.0).contains(&grazing_cutoff_deg)) {
        return bad(format!(
            "grazing_cutoff_deg {grazing_cutoff_deg}: must be in [10, 89]"
        ));
    }
    let mut config = SessionFitConfig {
        outer_iterations: outer.unwrap_or(SessionFitConfig::default().outer_iterations),
        holdout_fraction: holdout,
        ..SessionFitConfig::default()
    };
    if joint_only {
        config.fit = ellipso_fit::pipeline::FitConfig::joint_only();
    }
    config.fit.solver.normal_prior_deg = normal_prior_deg;
    config.observe.gate.grazing_cutoff_deg = grazing_cutoff_deg;
    Ok(config)
}

/// What a whole fit returns to Python.
struct Fitted {
    out: PathBuf,
    files: Vec<PathBuf>,
    summary: ellipso_fit::summary::FitSummary,
}

/// `ellipso fit SESSION --out OUT …`: returns `{out, files, summary}` (each vertex's material
/// is `fit.ply`'s `material` column).
#[pyfunction]
#[pyo3(signature = (session, out, *, mesh=None, vertices=2500, outer=None, holdout=0.1, joint_only=false, normal_prior_deg=10.0, grazing_cutoff_deg=ellipso_fit::gate::GateConfig::default().grazing_cutoff_deg, view=None, no_hull=false, progress=None))]
#[expect(
    clippy::too_many_arguments,
    reason = "the flags of `ellipso fit`, one keyword each"
)]
pub fn fit<'py>(
    py: Python<'py>,
    session: PathBuf,
    out: PathBuf,
    mesh: Option<PathBuf>,
    vertices: usize,
    outer: Option<usize>,
    holdout: f64,
    joint_only: bool,
    normal_prior_deg: f64,
    grazing_cutoff_deg: f64,
    view: Option<u64>,
    no_hull: bool,
    progress: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    check_vertices(vertices)?;
    let config = fit_config(
        outer,
        holdout,
        joint_only,
        normal_prior_deg,
        grazing_cutoff_deg,
    )?;
    let fitted = drive(py, progress.as_ref(), move |fw| {
        let request = FitRequest {
            session: &session,
            mesh: mesh.as_deref(),
            out: &out,
            view,
            vertices,
            no_hull,
            config,
            shard: None,
            import: Default::default(),
            sensor_calibration: None,
        };
        let say = fw.clone();
        match ellipso_pipeline::fit_run::run(request, fw, &say)? {
            FitDone::Whole { out, run } => Ok(Fitted {
                out,
                files: run.files,
                summary: run.summary,
            }),
            FitDone::Shard(_) => Err(RunError::msg("a shard was run where a whole fit was asked")),
        }
    })?;
    let d = PyDict::new(py);
    d.set_item("out", &fitted.out)?;
    d.set_item("files", &fitted.files)?;
    d.set_item("summary", to_python(py, &fitted.summary)?)?;
    Ok(d)
}

/// The fit's flag names in bit order (`fit.ply`'s `flags`: bit k = entry k).
#[pyfunction]
pub fn fit_flag_names() -> Vec<String> {
    ellipso_fit::data::FitFlag::ALL
        .iter()
        .map(|f| format!("{f:?}"))
        .collect()
}
