//! A full disk, for real: a 20 MB tmpfs mounted in a private mount namespace (so nothing leaks
//! if the test dies), filled to the last page, and the `ellipso` binary writing onto it:
//! - a capture whose frames cannot be written;
//! - a fit whose pose appends run out of space, then the same fit once space is back;
//! - a fit whose results cannot be written;
//! - `sim render` and `polar` writing their outputs.
//!
//! Each must fail with a clear error (or succeed), never panic or hang, leave no partial log line
//! and no empty or half-written result file, and change nothing already recorded.
//!
//! Needs root (mount). Without it the test prints why and passes; CI runs as root and sets
//! `ELLIPSO_REQUIRE_TMPFS=1` so a skip there is a failure.
//! `cargo test -p ellipso-tests --test full_disk -- --nocapture` prints the table row.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyFormat, write_ply};
use ellipso_model::geometry::procedural::icosphere;
use ellipso_session::reader;
use ellipso_tests::{ellipso_bin, shipped_scene};
use nalgebra::Point3;

const IN_MOUNT_NS: &str = "ELLIPSO_TEST_IN_MOUNT_NS";

/// Re-runs test `name` inside `unshare -m` (private mounts); true when this process is the
/// outer one (whose work is then done). Skips, with the reason printed, where it cannot.
fn reexec_in_mount_ns(name: &str) -> Option<bool> {
    if std::env::var_os(IN_MOUNT_NS).is_some() {
        return Some(false);
    }
    let require = std::env::var_os("ELLIPSO_REQUIRE_TMPFS").is_some();
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        assert!(
            !require,
            "ELLIPSO_REQUIRE_TMPFS is set but the test is not running as root"
        );
        println!("skipped: mounting a tmpfs needs root (CI runs as root)");
        return None;
    }
    let exe = std::env::current_exe().unwrap();
    let status = Command::new("unshare")
        .args(["-m", "--propagation", "private"])
        .arg(exe)
        .args([name, "--exact", "--nocapture", "--test-threads=1"])
        .env(IN_MOUNT_NS, "1")
        .status();
    match status {
        Ok(s) => {
            assert!(s.success(), "{name} failed inside its mount namespace: {s}");
            Some(true)
        }
        Err(e) => {
            assert!(!require, "cannot run unshare -m: {e}");
            println!("skipped: cannot run unshare -m ({e}); util-linux is needed");
            None
        }
    }
}

struct Disk {
    mount: PathBuf,
}

impl Disk {
    /// A fresh 20 MB tmpfs at `at`.
    fn mount(at: &Path) -> Self {
        std::fs::create_dir_all(at).unwrap();
        let s = Command::new("mount")
            .args(["-t", "tmpfs", "-o", "size=20m", "tmpfs"])
            .arg(at)
            .status()
            .unwrap();
        assert!(s.success(), "mount tmpfs failed");
        Self {
            mount: at.to_path_buf(),
        }
    }

    /// Fills the disk to the last byte (a ballast file grown until the write fails).
    fn fill(&self) {
        use std::io::Write;
        let mut f = std::fs::File::create(self.mount.join("ballast")).unwrap();
        let chunk = vec![0u8; 64 * 1024];
        while f.write_all(&chunk).is_ok() {}
        let one = [0u8; 1];
        while f.write_all(&one).is_ok() {}
    }

    /// Frees the ballast.
    fn free(&self) {
        let _ = std::fs::remove_file(self.mount.join("ballast"));
    }
}

impl Drop for Disk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.mount).status();
    }
}

fn ellipso() -> Command {
    Command::new(ellipso_bin())
}

fn capture(out: &Path, photos: &str) -> Output {
    ellipso()
        .args(["capture", "--interval-ms", "50", "--sim"])
        .arg(shipped_scene("sphere.toml"))
        .arg("--out")
        .arg(out)
        .args(["--photos", photos, "--resolution", "612x512"])
        .args(["--supersampling", "1"])
        .output()
        .unwrap()
}

fn sphere_mesh(dir: &Path) -> PathBuf {
    let (dirs, faces) = icosphere(1);
    let pos = dirs
        .iter()
        .map(|d| Point3::new(0.0, 0.0, 0.04) + d.into_inner() * 0.04)
        .collect();
    let m = TriangleMesh::new(pos, None, None, faces).unwrap();
    let p = dir.join("sphere.ply");
    std::fs::write(&p, write_ply(&m, PlyFormat::BinaryLittleEndian, false)).unwrap();
    p
}

fn fit(session: &Path, mesh: &Path, out: &Path) -> Output {
    ellipso()
        .arg("fit")
        .arg(session)
        .arg("--mesh")
        .arg(mesh)
        .args(["--outer", "1", "--out"])
        .arg(out)
        .output()
        .unwrap()
}

fn copy_dir(from: &Path, to: &Path) {
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

/// Every file under `dir`: (path, bytes).
fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.filter_map(Result::ok) {
            if e.path().is_dir() {
                stack.push(e.path());
            } else {
                out.push((e.path(), std::fs::read(e.path()).unwrap_or_default()));
            }
        }
    }
    out.sort();
    out
}

/// No empty result and no temporary `.partial` file under `dir`.
fn no_half_written_results(dir: &Path) -> Result<(), String> {
    for (p, bytes) in files(dir) {
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        if name.ends_with(".partial") {
            return Err(format!("temporary file left: {}", p.display()));
        }
        if bytes.is_empty() {
            return Err(format!("empty result: {}", p.display()));
        }
    }
    Ok(())
}

/// No temporary `.partial` file under `dir` (a failed write cleans up after itself).
fn no_partial_files(dir: &Path) -> Result<(), String> {
    match files(dir)
        .into_iter()
        .find(|(p, _)| p.to_string_lossy().ends_with(".partial"))
    {
        Some((p, _)) => Err(format!("temporary file left: {}", p.display())),
        None => Ok(()),
    }
}

/// Every line of the session's log is whole JSON (the last one ends with a newline).
fn log_whole(session: &Path) -> Result<(), String> {
    let log = std::fs::read(session.join("events.jsonl")).unwrap_or_default();
    if !log.is_empty() && log.last() != Some(&b'\n') {
        return Err("the log ends in a partial line".into());
    }
    for (i, line) in log.split(|&b| b == b'\n').enumerate() {
        if !line.is_empty() && serde_json::from_slice::<serde_json::Value>(line).is_err() {
            return Err(format!("log line {} is partial", i + 1));
        }
    }
    Ok(())
}

fn clear_error(o: &Output) -> Result<(), String> {
    let err = String::from_utf8_lossy(&o.stderr);
    println!(
        "  exit {:?}: {}",
        o.status.code(),
        err.lines().last().unwrap_or_default()
    );
    if err.contains("panicked") || o.status.code().is_none() {
        return Err(format!("died: {err}"));
    }
    if o.status.success() {
        return Ok(());
    }
    if !err.contains("No space left on device") {
        return Err(format!("unclear error: {err}"));
    }
    Ok(())
}

#[test]
fn a_full_disk_changes_nothing_recorded_and_leaves_nothing_half_written() {
    let Some(outer) =
        reexec_in_mount_ns("a_full_disk_changes_nothing_recorded_and_leaves_nothing_half_written")
    else {
        return;
    };
    if outer {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    // a session recorded on the ordinary disk, with its poses
    let recorded = tmp.path().join("recorded");
    let o = capture(&recorded, "8");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mesh = sphere_mesh(tmp.path());
    let disk = Disk::mount(&tmp.path().join("disk"));
    let mut results: Vec<(&str, Result<(), String>)> = Vec::new();

    // 1. capture onto a full disk
    let out = disk.mount.join("capture");
    disk.fill();
    let o = capture(&out, "6");
    results.push((
        "capture onto a full disk",
        clear_error(&o).and_then(|()| {
            if o.status.success() {
                return Err("a capture onto a full disk reported success".into());
            }
            if out.join("manifest.json").exists() {
                reader::open(&out).map_err(|e| format!("the session does not open: {e}"))?;
                log_whole(&out)?;
            }
            no_partial_files(&out)
        }),
    ));
    disk.free();
    // ... and one with room for its manifest and log but not its frames
    let out = disk.mount.join("capture-frames");
    std::fs::write(disk.mount.join("gap"), vec![0u8; 160 * 1024]).unwrap();
    disk.fill();
    std::fs::remove_file(disk.mount.join("gap")).unwrap();
    let o = capture(&out, "6");
    results.push((
        "capture whose frames fill the disk",
        clear_error(&o).and_then(|()| {
            if o.status.success() {
                return Err("a capture that lost its frames reported success".into());
            }
            let s = reader::open(&out).map_err(|e| format!("the session does not open: {e}"))?;
            for f in &s.frames {
                s.load_frame(f)
                    .map_err(|e| format!("a frame on disk does not load: {e}"))?;
            }
            log_whole(&out)?;
            no_partial_files(&out)
        }),
    ));
    disk.free();

    // 2. fit of a session on the full disk whose poses must be re-tracked and appended
    let session = disk.mount.join("session");
    copy_dir(&recorded, &session);
    let log = session.join("events.jsonl");
    let text = std::fs::read_to_string(&log).unwrap();
    let kept: Vec<&str> = text
        .lines()
        .filter(|l| !l.contains("\"type\":\"pose"))
        .collect();
    // blank lines (the reader skips them) so the log's last page has 100 bytes to spare: the
    // first pose line then fits only in part, as on a real disk filling mid-write
    let mut text = kept.join("\n") + "\n";
    let page = 4096;
    let mut target = text.len().div_ceil(page) * page - 100;
    if target < text.len() {
        target += page;
    }
    text.push_str(&"\n".repeat(target - text.len()));
    std::fs::write(&log, text).unwrap();
    let frames_before = files(&session.join("frames"));
    let log_before = std::fs::read(&log).unwrap();
    let manifest_before = std::fs::read(session.join("manifest.json")).unwrap();
    disk.fill();
    let o = fit(&session, &mesh, &tmp.path().join("fit-a"));
    let unchanged = |what: &str| -> Result<(), String> {
        if files(&session.join("frames")) != frames_before {
            return Err(format!("{what}: frames changed"));
        }
        if std::fs::read(session.join("manifest.json")).unwrap() != manifest_before {
            return Err(format!("{what}: manifest changed"));
        }
        if !std::fs::read(&log).unwrap().starts_with(&log_before) {
            return Err(format!("{what}: recorded log lines changed"));
        }
        log_whole(&session)
    };
    results.push((
        "fit appending poses onto a full disk",
        clear_error(&o).and_then(|()| unchanged("full")),
    ));
    disk.free();
    // with space again the same fit re-tracks what was missing and finishes
    let o = fit(&session, &mesh, &tmp.path().join("fit-b"));
    results.push((
        "the same fit with space again",
        if o.status.success() {
            unchanged("freed").and_then(|()| {
                let s = reader::open(&session).unwrap();
                let tracked = ellipso_vision::process::untracked_frames(&s);
                if tracked.is_empty() {
                    Ok(())
                } else {
                    Err(format!("frames never re-tracked: {tracked:?}"))
                }
            })
        } else {
            Err(String::from_utf8_lossy(&o.stderr).into_owned())
        },
    ));

    // 3. fit results onto a full disk
    let out = disk.mount.join("fit-results");
    std::fs::create_dir(&out).unwrap();
    disk.fill();
    let o = fit(&recorded, &mesh, &out);
    results.push((
        "fit results onto a full disk",
        clear_error(&o).and_then(|()| no_half_written_results(&out)),
    ));

    // 4. sim render and polar outputs onto a full disk
    let out = disk.mount.join("render");
    let o = ellipso()
        .args(["sim", "render"])
        .arg(shipped_scene("sphere.toml"))
        .arg("--out")
        .arg(&out)
        .args(["--frames", "2", "--width", "612", "--height", "512"])
        .args(["--supersampling", "1"])
        .output()
        .unwrap();
    results.push((
        "sim render onto a full disk",
        clear_error(&o).and_then(|()| no_half_written_results(&out)),
    ));
    let frame = files(&recorded.join("frames"))[0].0.clone();
    let out = disk.mount.join("polar");
    let o = ellipso()
        .arg("polar")
        .arg(&frame)
        .arg("--out")
        .arg(&out)
        .args(["--bit-depth", "12"])
        .output()
        .unwrap();
    results.push((
        "polar onto a full disk",
        clear_error(&o).and_then(|()| no_half_written_results(&out)),
    ));
    disk.free();

    let failed: Vec<_> = results.iter().filter(|r| r.1.is_err()).collect();
    println!(
        "| input | tried | clear error or success | panic / hang / data changed / half-written |"
    );
    println!("|---|---|---|---|");
    println!(
        "| full disk (20 MB tmpfs) | {} | {} | {} |",
        results.len(),
        results.len() - failed.len(),
        failed.len()
    );
    for (name, r) in &results {
        println!(
            "  {name}: {}",
            r.as_ref().err().map_or("ok", String::as_str)
        );
    }
    assert!(failed.is_empty(), "{failed:#?}");
}

/// `ellipso mesh SESSION --out OUT` (both paths as given).
fn mesh(session: &Path, out: &Path) -> Output {
    ellipso()
        .arg("mesh")
        .arg(session)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

#[test]
fn mesh_refuses_a_full_or_read_only_out_before_carving() {
    let name = "mesh_refuses_a_full_or_read_only_out_before_carving";
    let Some(outer) = reexec_in_mount_ns(name) else {
        return;
    };
    if outer {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let recorded = tmp.path().join("recorded");
    let o = capture(&recorded, "8");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let disk = Disk::mount(&tmp.path().join("disk"));
    // a full disk: refused at the claim, naming the room, before the carving (whose own error
    // on this one-sided 8-photo orbit, "meshing …", would otherwise come first)
    disk.fill();
    let out = disk.mount.join("mesh.ply");
    let o = mesh(&recorded, &out);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("bytes free"), "the room is named: {err}");
    assert!(
        !err.contains("meshing"),
        "refused before the carving: {err}"
    );
    assert!(!out.exists(), "nothing written: {err}");
    disk.free();
    // a read-only one: refused at the claim too
    let s = Command::new("mount")
        .args(["-o", "remount,ro"])
        .arg(&disk.mount)
        .status()
        .unwrap();
    assert!(s.success(), "remount read-only failed");
    let o = mesh(&recorded, &out);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "{err}");
    assert!(err.to_lowercase().contains("read-only"), "{err}");
    assert!(
        !err.contains("meshing"),
        "refused before the carving: {err}"
    );
}
