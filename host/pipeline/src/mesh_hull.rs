//! The visual hull `ellipso mesh` carved, saved beside its mesh so that `ellipso fit --mesh` on
//! the same session reuses it instead of carving the session again (docs/mesh.md, "The hull
//! beside the mesh").
//!
//! Files: `<stem>-hull.json` ([`HullSidecar`]: what the hull is and where it came from) and
//! `<stem>-hull.npy` (the field's values, `f4`, shape `[nz, ny, nx]`, metres, > 0 outside).
//!
//! Contract: sameness is proved, never assumed. The sidecar records the session's identity
//! ([`SessionIdentity`]: its manifest's start time, software and sensor), a CRC-64 of the poses
//! the carving used (frame ids and matrices, in order), of the mesh file's bytes as written and
//! of the values. [`reusable_hull`] returns the hull only when the mesh file's sidecar exists
//! and every one of them matches the fit's session, the poses the fit would carve from, the
//! mesh file's bytes now and the values file; otherwise `Err(reason)` says which did not (the
//! caller carves as before). A CRC guards against accident (a mesh edited or re-exported, another
//! session, re-tracked poses), not against forgery; nothing a fit reads is trusted further.

use std::path::{Path, PathBuf};

use ellipso_fit::shape::hull::{GridGeometry, HullField};
use ellipso_report::output::{FileFormat, OutputFile};
use ellipso_run_error::RunError;
use ellipso_session::reader::Session;
use nalgebra::Isometry3;

/// The sidecar's format tag (a later layout changes it; an unknown tag is not reused).
pub const FORMAT: &str = "ellipso-hull/1";

/// `.npy` arrays, as the hull's values are written.
pub const NPY: FileFormat = FileFormat {
    name: "NumPy .npy",
    extensions: &["npy"],
    magic: b"\x93NUMPY",
};

/// What identifies a session: the manifest's start time (microseconds since the Unix epoch),
/// the software that recorded it and its sensor.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SessionIdentity {
    /// `manifest.host_epoch_unix_us`.
    pub host_epoch_unix_us: u64,
    /// `manifest.software`.
    pub software: String,
    /// Sensor width × height, pixels.
    pub sensor_px: [u32; 2],
}

impl SessionIdentity {
    /// The identity of `session`.
    pub fn of(session: &Session) -> Self {
        let m = &session.manifest;
        Self {
            host_epoch_unix_us: m.host_epoch_unix_us,
            software: m.software.clone(),
            sensor_px: [m.sensor.width, m.sensor.height],
        }
    }
}

/// `<stem>-hull.json` (module doc).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HullSidecar {
    /// [`FORMAT`].
    pub format: String,
    /// The session the hull was carved from.
    pub session: SessionIdentity,
    /// Number of poses the carving used.
    pub poses: usize,
    /// CRC-64 of those poses (hex; [`poses_crc64`]).
    pub poses_crc64: String,
    /// CRC-64 of the mesh file's bytes as written (hex).
    pub mesh_crc64: String,
    /// The values file, beside this one.
    pub values_file: String,
    /// CRC-64 of the values file's bytes (hex).
    pub values_crc64: String,
    /// Volume frame → board frame: rotation as a unit quaternion `[w, x, y, z]`.
    pub rotation_wxyz: [f64; 4],
    /// Volume frame → board frame: translation, metres.
    pub translation_m: [f64; 3],
    /// The grid, volume frame.
    pub grid: GridGeometry,
    /// φ beyond the grid, metres.
    pub outside_m: f64,
    /// The votes the field was carved with.
    pub votes: usize,
}

/// The sidecar's paths beside a mesh file: `<stem>-hull.json`, `<stem>-hull.npy`.
pub fn sidecar_paths(mesh: &Path) -> (PathBuf, PathBuf) {
    let stem = mesh.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh");
    (
        mesh.with_file_name(format!("{stem}-hull.json")),
        mesh.with_file_name(format!("{stem}-hull.npy")),
    )
}

/// CRC-64/XZ of `bytes` (the session's [`ellipso_session::provenance::crc64`]), as 16 hex digits.
fn crc64(bytes: &[u8]) -> String {
    format!("{:016x}", ellipso_session::provenance::crc64(bytes))
}

/// CRC-64 of poses: each frame id (u64 LE) and its 4×4 matrix (row-major f64 LE), in order.
pub fn poses_crc64(poses: &[(u64, Isometry3<f64>)]) -> String {
    let mut bytes = Vec::with_capacity(poses.len() * 136);
    for (id, pose) in poses {
        bytes.extend(id.to_le_bytes());
        let m = pose.to_homogeneous();
        for r in 0..4 {
            for c in 0..4 {
                bytes.extend(m[(r, c)].to_le_bytes());
            }
        }
    }
    crc64(&bytes)
}

fn values_npy(hull: &HullField) -> Vec<u8> {
    let [nx, ny, nz] = hull.grid.n;
    ellipso_report::npy::encode(&[nz, ny, nx], &hull.values)
}

/// The two sidecar files claimed beside a mesh (before the work: an existing file of another
/// kind is refused, as the mesh's own claim does).
pub struct HullFiles {
    json: OutputFile,
    npy: OutputFile,
}

impl HullFiles {
    /// Claims `<stem>-hull.json` and `<stem>-hull.npy` beside `mesh` for `ellipso mesh`.
    pub fn claim(mesh: &Path, session_dir: &Path) -> Result<Self, RunError> {
        let (json, npy) = sidecar_paths(mesh);
        Ok(Self {
            json: OutputFile::claim(&json, "mesh", FileFormat::JSON, &[session_dir], None)?,
            npy: OutputFile::claim(&npy, "mesh", NPY, &[session_dir], None)?,
        })
    }

    /// The JSON file as shown.
    pub fn shown(&self) -> &Path {
        self.json.shown()
    }

    /// Writes the hull carved from the session of `session` with `poses`, for the mesh file of `mesh_bytes`.
    pub fn write(
        &self,
        session: &SessionIdentity,
        poses: &[(u64, Isometry3<f64>)],
        mesh_bytes: &[u8],
        hull: &HullField,
    ) -> Result<(), RunError> {
        let values = values_npy(hull);
        let q = hull.world_from_volume.rotation.quaternion();
        let t = hull.world_from_volume.translation.vector;
        let sidecar = HullSidecar {
            format: FORMAT.into(),
            session: session.clone(),
            poses: poses.len(),
            poses_crc64: poses_crc64(poses),
            mesh_crc64: crc64(mesh_bytes),
            values_file: self
                .npy
                .path()
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            values_crc64: crc64(&values),
            rotation_wxyz: [q.w, q.i, q.j, q.k],
            translation_m: [t.x, t.y, t.z],
            grid: hull.grid,
            outside_m: hull.outside_m,
            votes: hull.votes,
        };
        self.npy.write(&values)?;
        self.json.write(serde_json::to_vec_pretty(&sidecar)?)?;
        Ok(())
    }
}

/// The hull saved beside `mesh` when it is this session's, carved from `poses`, for exactly
/// this mesh file (module contract); `Ok(None)` where the mesh has no sidecar (a scanner's or
/// another tool's mesh), `Err` saying what differs where it has one that does not match.
pub fn reusable_hull(
    mesh: &Path,
    session: &SessionIdentity,
    poses: &[(u64, Isometry3<f64>)],
) -> Result<Option<HullField>, String> {
    let (json_path, _) = sidecar_paths(mesh);
    if !json_path.exists() {
        return Ok(None);
    }
    let text = std::fs::read(&json_path).map_err(|e| format!("{}: {e}", json_path.display()))?;
    let sidecar: HullSidecar = serde_json::from_slice(&text)
        .map_err(|e| format!("{}: not a hull sidecar: {e}", json_path.display()))?;
    let differs = |what: &str| format!("{} was made for {what}", json_path.display());
    if sidecar.format != FORMAT {
        return Err(differs(&format!("format {}", sidecar.format)));
    }
    if sidecar.session != *session {
        return Err(differs("another session"));
    }
    if sidecar.poses != poses.len() || sidecar.poses_crc64 != poses_crc64(poses) {
        return Err(differs(
            "other poses (the session was tracked again, or poses imported)",
        ));
    }
    let mesh_bytes = std::fs::read(mesh).map_err(|e| format!("{}: {e}", mesh.display()))?;
    if sidecar.mesh_crc64 != crc64(&mesh_bytes) {
        return Err(differs("another mesh file (this one was changed since)"));
    }
    let values_path = json_path.with_file_name(&sidecar.values_file);
    let values =
        std::fs::read(&values_path).map_err(|e| format!("{}: {e}", values_path.display()))?;
    if sidecar.values_crc64 != crc64(&values) {
        return Err(format!(
            "{}: changed since it was written",
            values_path.display()
        ));
    }
    let array = ellipso_report::npy::decode(&values)
        .map_err(|e| format!("{}: {e}", values_path.display()))?;
    let [nx, ny, nz] = sidecar.grid.n;
    if array.shape != [nz, ny, nx] {
        return Err(format!(
            "{}: shape {:?}, the sidecar's grid is {:?}",
            values_path.display(),
            array.shape,
            [nz, ny, nx]
        ));
    }
    let [w, i, j, k] = sidecar.rotation_wxyz;
    let [x, y, z] = sidecar.translation_m;
    // the quaternion as written: already unit, so the hull is the carved one to the bit
    let world_from_volume = Isometry3::from_parts(
        nalgebra::Translation3::new(x, y, z),
        nalgebra::UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(w, i, j, k)),
    );
    HullField::new(
        world_from_volume,
        sidecar.grid,
        array.data.iter().map(|&v| v as f32).collect(),
        sidecar.outside_m,
        sidecar.votes,
    )
    .map(Some)
    .map_err(|e| format!("{}: {e}", values_path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn hull() -> HullField {
        let grid = GridGeometry {
            origin_m: [-0.01, -0.02, 0.0],
            spacing_m: 0.001,
            n: [5, 4, 3],
        };
        let values: Vec<f32> = (0..grid.len()).map(|v| v as f32 * 1e-4 - 2e-3).collect();
        let pose = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.003),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3),
        );
        HullField::new(pose, grid, values, 0.05, 3).unwrap()
    }

    fn identity() -> SessionIdentity {
        SessionIdentity {
            host_epoch_unix_us: 1_700_000_000_000_000,
            software: "ellipso 0.1.0".into(),
            sensor_px: [612, 512],
        }
    }

    #[test]
    fn the_hull_comes_back_only_for_the_same_session_poses_and_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let session_dir = dir.path().join("session");
        std::fs::create_dir(&session_dir).unwrap();
        let mesh = dir.path().join("mesh.ply");
        let mesh_bytes = b"ply\nformat binary_little_endian 1.0\n".to_vec();
        std::fs::write(&mesh, &mesh_bytes).unwrap();
        let poses = vec![(3u64, Isometry3::translation(0.0, 0.0, 0.5))];
        let files = HullFiles::claim(&mesh, &session_dir).unwrap();
        files
            .write(&identity(), &poses, &mesh_bytes, &hull())
            .unwrap();

        let back = reusable_hull(&mesh, &identity(), &poses).unwrap().unwrap();
        let h = hull();
        assert_eq!(back.values, h.values);
        assert_eq!(back.grid, h.grid);
        assert_eq!(back.world_from_volume, h.world_from_volume);
        assert_eq!((back.outside_m, back.votes), (h.outside_m, h.votes));

        // another session, other poses, a changed mesh: each refused, saying which
        let other = SessionIdentity {
            host_epoch_unix_us: 1,
            ..identity()
        };
        assert!(
            reusable_hull(&mesh, &other, &poses)
                .unwrap_err()
                .contains("another session")
        );
        let moved = vec![(3u64, Isometry3::translation(0.0, 0.0, 0.6))];
        assert!(
            reusable_hull(&mesh, &identity(), &moved)
                .unwrap_err()
                .contains("other poses")
        );
        std::fs::write(&mesh, b"ply\nchanged").unwrap();
        assert!(
            reusable_hull(&mesh, &identity(), &poses)
                .unwrap_err()
                .contains("mesh file")
        );
        // no sidecar at all: nothing to reuse, nothing wrong
        let bare = dir.path().join("other.ply");
        std::fs::write(&bare, &mesh_bytes).unwrap();
        assert!(reusable_hull(&bare, &identity(), &poses).unwrap().is_none());
    }
}
