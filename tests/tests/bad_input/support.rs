//! Shared pieces of the bad-input table: what a case expects, the case itself, and the inputs
//! cases damage (a captured session, the sphere scene, a mesh).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyFormat, write_ply};
use ellipso_model::geometry::procedural::icosphere;
use ellipso_tests::{ellipso_bin, shipped_scene};
use nalgebra::Point3;

/// What a case must do.
#[derive(Clone, Copy, Debug)]
pub enum Expect {
    /// Exit non-zero, stderr containing this.
    Refuse(&'static str),
    /// Exit 0, stdout or stderr containing this.
    Warn(&'static str),
    /// Exit non-zero, stderr containing this exactly once (a cause said once, not twice).
    RefuseOnce(&'static str),
}

/// Prepares a case's input in its own directory; returns the command and what it must not change.
pub type Setup = Box<dyn Fn(&Path) -> (Command, Vec<PathBuf>) + Send + Sync>;

/// One tried input.
pub struct Case {
    pub category: &'static str,
    pub name: String,
    pub expect: Expect,
    /// Prepares the input in its own directory and returns the command and what it must not
    /// change.
    pub setup: Setup,
}

pub fn case(
    category: &'static str,
    name: impl Into<String>,
    expect: Expect,
    setup: impl Fn(&Path) -> (Command, Vec<PathBuf>) + Send + Sync + 'static,
) -> Case {
    Case {
        category,
        name: name.into(),
        expect,
        setup: Box::new(setup),
    }
}

pub fn ellipso(args: &[&str]) -> Command {
    let mut c = Command::new(ellipso_bin());
    c.args(args);
    c
}

pub fn s(p: &Path) -> String {
    p.display().to_string()
}

/// The sphere scene with its board path absolute (so copies work from anywhere).
pub fn sphere_text() -> String {
    let board = shipped_scene("../boards/base_a4.toml")
        .canonicalize()
        .unwrap();
    std::fs::read_to_string(shipped_scene("sphere.toml"))
        .unwrap()
        .replace(
            "file = \"../boards/base_a4.toml\"",
            &format!("file = \"{}\"", board.display()),
        )
}

/// One captured session for every session, frame and mesh case (copied per case).
pub fn fixture() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| capture_sphere(8))
}

/// The probe's orbit: 40 frames of the sphere scene at 612×512, tracked (calibration, carving
/// and the tag cases; copied per case).
pub fn fixture40() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| capture_sphere(40))
}

fn capture_sphere(photos: u32) -> PathBuf {
    let root = tempfile::tempdir().unwrap().keep();
    let out = root.join("session");
    let o = ellipso(&["capture", "--interval-ms", "50", "--sim"])
        .arg(shipped_scene("sphere.toml").canonicalize().unwrap())
        .arg("--out")
        .arg(&out)
        .args(["--photos", &photos.to_string()])
        .args(["--resolution", "612x512", "--supersampling", "1"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dst = to.join(e.file_name());
        if e.path().is_dir() {
            copy_dir(&e.path(), &dst);
        } else {
            std::fs::copy(e.path(), dst).unwrap();
        }
    }
}

/// A copy of the fixture session in `dir`, damaged by `damage`.
pub fn damaged(dir: &Path, damage: impl Fn(&Path)) -> PathBuf {
    let s = dir.join("session");
    copy_dir(fixture(), &s);
    damage(&s);
    s
}

/// Edits the session's manifest as JSON.
pub fn edit_manifest(session: &Path, edit: impl Fn(&mut serde_json::Value)) {
    let p = session.join("manifest.json");
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
    edit(&mut v);
    std::fs::write(&p, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
}

/// Rewrites every line of the session's log through `edit` (lines it returns `None` for go).
pub fn edit_log(session: &Path, edit: impl Fn(serde_json::Value) -> Option<serde_json::Value>) {
    let p = session.join("events.jsonl");
    let text = std::fs::read_to_string(&p).unwrap();
    let lines: Vec<String> = text
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok().and_then(&edit))
        .map(|v| v.to_string())
        .collect();
    std::fs::write(&p, lines.join("\n") + "\n").unwrap();
}

/// Makes a FIFO at `path` (replacing what is there).
pub fn fifo(path: &Path) {
    let _ = std::fs::remove_file(path);
    let c = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
    // SAFETY: a NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
}

/// The sphere object (r = 40 mm at z = 40 mm, moved by `offset`) as a mesh file.
pub fn mesh(dir: &Path, offset: f64) -> PathBuf {
    let (dirs, faces) = icosphere(1);
    let pos = dirs
        .iter()
        .map(|d| Point3::new(offset, 0.0, 0.04) + d.into_inner() * 0.04)
        .collect();
    let m = TriangleMesh::new(pos, None, None, faces).unwrap();
    let p = dir.join("mesh.ply");
    std::fs::write(&p, write_ply(&m, PlyFormat::BinaryLittleEndian, false)).unwrap();
    p
}

/// `ellipso fit SESSION --mesh MESH --outer 1 --out DIR/fit`.
pub fn fit(dir: &Path, session: &Path, mesh: &Path) -> Command {
    let mut c = ellipso(&["fit"]);
    c.arg(session)
        .arg("--mesh")
        .arg(mesh)
        .args(["--outer", "1", "--out"])
        .arg(dir.join("fit"));
    c
}

pub fn edit_file(p: &Path, from: &str, to: &str) {
    let t = std::fs::read_to_string(p).unwrap();
    // sessions of older builds name the layout `monopolar`
    let from = if from == "\"mono_polar\"" && !t.contains(from) {
        "\"monopolar\""
    } else {
        from
    };
    assert!(t.contains(from), "{from} not in {}", p.display());
    std::fs::write(p, t.replacen(from, to, 1)).unwrap();
}
