//! `ellipso._native.Session`: a recorded session opened read-only through
//! `ellipso_session::reader::open` (what every command reads), its parts as Python values.
//!
//! Contract: opening reads the manifest and the log once (a missing folder or manifest is
//! `FileNotFoundError`, a bad manifest `ValueError`, both with the CLI's message); nothing is
//! ever written. Frames are decoded on request with the GIL released, as recorded: `uint16`,
//! `(height, width)`, right-aligned DN (a corrupt or wrongly sized frame is `ValueError` naming
//! the file). Poses are the session's one fold of its log (`Session::poses`), camera → world
//! (board frame, metres; OpenCV camera axes). The manifest, the rig record and the events are
//! their JSON forms, as written in the session (`docs/session-format.md`).

use ellipso_session::reader::{FrameEntry, Session as Recorded};
use nalgebra::Isometry3;
use numpy::{PyArray1, PyArray3, PyArrayMethods};
use pyo3::exceptions::PyKeyError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::errors::{EllipsoError, session_error};

/// A JSON-serialisable value as the Python object `json.loads` makes of it.
pub fn to_python<'py>(
    py: Python<'py>,
    value: &impl serde::Serialize,
) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value).map_err(|e| EllipsoError::new_err(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// A recorded session (module contract).
#[pyclass(frozen, module = "ellipso._native")]
pub struct Session {
    session: Recorded,
}

impl Session {
    fn entry(&self, frame_id: u64) -> PyResult<&FrameEntry> {
        self.session
            .frames
            .iter()
            .find(|f| f.frame_id == frame_id)
            .ok_or_else(|| {
                let ids = &self.session.frames;
                PyKeyError::new_err(format!(
                    "{}: no frame {frame_id} ({} frames, ids {}…{})",
                    self.session.dir.display(),
                    ids.len(),
                    ids.first().map_or(0, |f| f.frame_id),
                    ids.last().map_or(0, |f| f.frame_id)
                ))
            })
    }
}

/// Poses as `(ids, world_from_camera)`: a `uint64` vector and an `(n, 4, 4)` array.
type PoseArrays<'py> = (Bound<'py, PyArray1<u64>>, Bound<'py, PyArray3<f64>>);

fn pose_arrays<'py>(py: Python<'py>, poses: &[(u64, Isometry3<f64>)]) -> PyResult<PoseArrays<'py>> {
    let ids: Vec<u64> = poses.iter().map(|p| p.0).collect();
    let mut m = Vec::with_capacity(poses.len() * 16);
    for (_, pose) in poses {
        let h = pose.to_homogeneous();
        for r in 0..4 {
            for c in 0..4 {
                m.push(h[(r, c)]);
            }
        }
    }
    Ok((
        PyArray1::from_vec(py, ids),
        PyArray1::from_vec(py, m).reshape([poses.len(), 4, 4])?,
    ))
}

#[pymethods]
impl Session {
    /// Opens the session in `path` (read-only).
    #[new]
    fn new(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Self> {
        let session = py
            .detach(|| ellipso_session::reader::open(&path))
            .map_err(session_error)?;
        Ok(Session { session })
    }

    /// The session folder.
    #[getter]
    fn path(&self) -> std::path::PathBuf {
        self.session.dir.clone()
    }

    /// `'mono'` (IMX250MZR) or `'colour'` (IMX250MYR).
    #[getter]
    fn layout(&self) -> &'static str {
        crate::polar::layout_name(self.session.manifest.sensor.layout)
    }

    /// Frame width, px.
    #[getter]
    fn width(&self) -> u32 {
        self.session.manifest.sensor.width
    }

    /// Frame height, px.
    #[getter]
    fn height(&self) -> u32 {
        self.session.manifest.sensor.height
    }

    /// Significant bits per sample in the 16-bit container.
    #[getter]
    fn bit_depth(&self) -> u8 {
        self.session.manifest.sensor.bit_depth
    }

    /// Frame ids on disk, ascending.
    #[getter]
    fn frame_ids<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        PyArray1::from_vec(py, self.session.frames.iter().map(|f| f.frame_id).collect())
    }

    /// What reading found wrong (`'intact'` when nothing).
    #[getter]
    fn read_report(&self) -> String {
        self.session.report.summary()
    }

    /// The manifest as written (a dict).
    #[getter]
    fn manifest<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.session.manifest)
    }

    /// Every readable event of the log, in order (dicts with a `type` key).
    #[getter]
    fn events<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.session.events)
    }

    /// Per frame: `frame_id`, `complete`, `pulse_seq`, `bracket_step`, `flash_on_us`,
    /// `flash_energy_rel`, `file` (dicts, by frame id).
    #[getter]
    fn frame_records<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let list = PyList::empty(py);
        for f in &self.session.frames {
            let d = PyDict::new(py);
            d.set_item("frame_id", f.frame_id)?;
            d.set_item("complete", f.complete)?;
            d.set_item("pulse_seq", f.pulse_seq)?;
            d.set_item("bracket_step", f.bracket_step)?;
            d.set_item("flash_on_us", f.flash_on_us)?;
            d.set_item("flash_energy_rel", f.flash_energy_rel)?;
            d.set_item("file", f.path.clone())?;
            list.append(d)?;
        }
        Ok(list)
    }

    /// The raw mosaic of frame `frame_id` as recorded: `uint16`, `(height, width)`.
    fn frame<'py>(
        &self,
        py: Python<'py>,
        frame_id: u64,
    ) -> PyResult<Bound<'py, numpy::PyArray2<u16>>> {
        let entry = self.entry(frame_id)?;
        let (w, h, pixels) = py
            .detach(|| self.session.load_frame(entry))
            .map_err(session_error)?;
        PyArray1::from_vec(py, pixels).reshape([h as usize, w as usize])
    }

    /// Tracked poses: `(frame_ids, world_from_camera)`, camera → world 4×4 (board frame,
    /// metres; camera axes x right, y down, z forward).
    fn tracked_poses<'py>(&self, py: Python<'py>) -> PyResult<PoseArrays<'py>> {
        pose_arrays(py, &self.session.poses().tracked())
    }

    /// Borrowed poses of short-pulse frames (same form as `tracked_poses`).
    fn interpolated_poses<'py>(&self, py: Python<'py>) -> PyResult<PoseArrays<'py>> {
        pose_arrays(py, &self.session.poses().interpolated())
    }

    /// Frames tracking refused: `{frame_id: reason}`.
    fn rejected_poses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (id, reason) in self.session.poses().rejected() {
            d.set_item(id, reason)?;
        }
        Ok(d)
    }

    /// The rig record (`manifest.rig`) as written, or `None`.
    #[getter]
    fn rig<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.session
            .manifest
            .rig
            .as_ref()
            .map(|r| to_python(py, r))
            .transpose()
    }

    /// The camera model of the rig record: `width, height, fx, fy, cx, cy, k1, k2, k3, p1, p2`
    /// (px; OpenCV's Brown–Conrady coefficients), or `None` without a rig record.
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(rig) = &self.session.manifest.rig else {
            return Ok(None);
        };
        let c = &rig.camera;
        let d = PyDict::new(py);
        d.set_item("width", c.width)?;
        d.set_item("height", c.height)?;
        let k = &c.intrinsics;
        for (name, v) in [("fx", k.fx), ("fy", k.fy), ("cx", k.cx), ("cy", k.cy)] {
            d.set_item(name, v)?;
        }
        let t = &c.distortion;
        for (name, v) in [
            ("k1", t.k1),
            ("k2", t.k2),
            ("k3", t.k3),
            ("p1", t.p1),
            ("p2", t.p2),
        ] {
            d.set_item(name, v)?;
        }
        Ok(Some(d))
    }

    fn __repr__(&self) -> String {
        let s = &self.session;
        format!(
            "ellipso.Session({:?}: {} frames, {}×{} {}, {}-bit)",
            s.dir.display().to_string(),
            s.frames.len(),
            s.manifest.sensor.width,
            s.manifest.sensor.height,
            self.layout(),
            s.manifest.sensor.bit_depth
        )
    }
}
