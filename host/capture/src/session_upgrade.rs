//! `ellipso session upgrade DIR` ([`upgrade`]): gives a session recorded before sessions carried
//! their whole rig record (radiometry, sensor noise, analyser extinction) that record, so it can
//! be fitted without its scene file.
//!
//! It lives here, beside the capture on the simulated rig ([`crate::sim`]), not in
//! `ellipso-session`, because a simulator session's record is made from its scene file: reading
//! one needs the simulator (which the session crate, read by the fit, must not depend on), and
//! the record is written by [`ellipso_sim::record::rig_record_of_scene`], the one `ellipso
//! capture --sim` writes.
//!
//! Contract:
//! - A simulator session: the scene file its manifest names is read (as recorded, else
//!   relative to the session's parent directory, else inside the session) and its record is
//!   written exactly as `ellipso capture --sim` writes it today (`rig_record_of_scene`), with the
//!   recorded camera model kept. The scene's flash must equal the recorded one: a scene edited
//!   after the capture is refused, since it would silently change the fit's units.
//! - A hardware or replayed session: its record is already complete (relative radiometry); the
//!   upgrade writes that explicitly.
//! - The old manifest is kept beside the new one (`manifest.json.pre-upgrade`, never
//!   overwritten); nothing else in the session changes. A session already upgraded is left
//!   alone.

use std::path::{Path, PathBuf};

use ellipso_run_error::ensure;
use ellipso_run_error::{Context, RunError};
use ellipso_session::manifest::{Manifest, SessionSource};
use ellipso_session::reader;
use ellipso_session::rig::RadiometryRecord;

/// Upgrades the session in `dir` (module doc): the backup's path, or `None` when the session
/// already carried its record.
pub fn upgrade(dir: &Path) -> Result<Option<PathBuf>, RunError> {
    let session = reader::open(dir)?;
    let manifest = upgraded(&session.manifest, dir)?;
    if manifest == session.manifest {
        return Ok(None);
    }
    Ok(Some(ellipso_session::writer::replace_manifest(
        dir, &manifest,
    )?))
}

/// `manifest` with its rig record completed.
fn upgraded(manifest: &Manifest, dir: &Path) -> Result<Manifest, RunError> {
    let mut out = manifest.clone();
    let rig = out
        .rig
        .as_mut()
        .context("the manifest records no rig (camera model): nothing to upgrade from")?;
    if rig.radiometry.is_some() {
        return Ok(out);
    }
    match &manifest.source {
        SessionSource::Simulator { scene, .. } => {
            let path = resolve_scene(dir, scene).with_context(|| {
                format!(
                    "the scene file of this simulator session, {scene}, is not found (as \
                     recorded, beside the session or inside it)"
                )
            })?;
            let loaded = ellipso_sim::scene::Scene::load(&path)?;
            ensure!(
                rig.flash.as_ref() == Some(&loaded.rig.flash),
                "{}: its flash differs from the flash recorded in the session: the scene was \
                 edited after the capture",
                path.display()
            );
            *rig = ellipso_sim::record::rig_record_of_scene(&loaded, rig.camera);
        }
        SessionSource::Hardware { .. } | SessionSource::Replay { .. } => {
            rig.radiometry = Some(RadiometryRecord::Relative);
        }
    }
    Ok(out)
}

/// The scene file a simulator session names: as recorded, else relative to the session
/// directory's parent, else inside the session directory.
fn resolve_scene(dir: &Path, recorded: &str) -> Option<PathBuf> {
    let p = Path::new(recorded);
    if p.is_file() {
        return Some(p.to_path_buf());
    }
    if p.is_relative() {
        let parent = dir.parent().map(|d| d.join(p));
        let inside = Some(dir.join(p));
        return [parent, inside].into_iter().flatten().find(|c| c.is_file());
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_session::manifest::SensorInfo;
    use ellipso_session::writer::SessionWriter;

    /// A session of the shipped sphere scene as `ellipso capture --sim` records it today
    /// (manifest only), and the same manifest in the form older captures wrote.
    fn sessions(root: &Path) -> (PathBuf, Manifest, String) {
        let path = ellipso_sim::scene::shipped_scene("sphere.toml");
        let scene = ellipso_sim::scene::Scene::load(&path).unwrap();
        let camera = scene.rig.camera.camera_model();
        let mut m = Manifest::new(
            SessionSource::Simulator {
                scene: path.display().to_string(),
                seed: scene.seed,
            },
            SensorInfo {
                layout: ellipso_model::mosaic::SensorLayout::MonoPolar,
                width: camera.width,
                height: camera.height,
                bit_depth: scene.rig.camera.bit_depth,
            },
            1,
        );
        m.rig = Some(ellipso_sim::record::rig_record_of_scene(&scene, camera));
        m.boards = ellipso_sim::record::boards_of_scene(&scene);
        let dir = root.join("s");
        drop(SessionWriter::create(&dir, m.clone()).unwrap());
        let mut old = serde_json::to_value(&m).unwrap();
        for key in ["radiometry", "noise", "analyser_extinction_ratio"] {
            old["rig"].as_object_mut().unwrap().remove(key);
        }
        old["calibration"] = serde_json::Value::Null;
        old["sensor"]["layout"] = "monopolar".into();
        let old = serde_json::to_string_pretty(&old).unwrap();
        std::fs::write(dir.join("manifest.json"), &old).unwrap();
        (dir, m, old)
    }

    #[test]
    fn an_old_simulator_session_is_refused_then_upgraded_to_what_capture_writes() {
        let tmp = tempfile::tempdir().unwrap();
        let (dir, today, old_text) = sessions(tmp.path());
        let log_before = std::fs::read(dir.join("events.jsonl")).ok();
        // before: it opens, and the fit's inputs say which command upgrades it
        let s = reader::open(&dir).unwrap();
        let e = s.manifest.fit_inputs(&s.dir).unwrap_err().to_string();
        assert!(e.contains("ellipso session upgrade"), "{e}");
        // the upgrade writes today's record and keeps the old manifest
        let backup = upgrade(&dir).unwrap().expect("upgraded");
        assert_eq!(std::fs::read_to_string(&backup).unwrap(), old_text);
        let s = reader::open(&dir).unwrap();
        assert_eq!(s.manifest, today);
        assert!(s.manifest.fit_inputs(&s.dir).is_ok());
        assert_eq!(std::fs::read(dir.join("events.jsonl")).ok(), log_before);
        // a second run changes nothing and keeps the first backup
        assert_eq!(upgrade(&dir).unwrap(), None);
        assert_eq!(std::fs::read_to_string(&backup).unwrap(), old_text);
    }

    #[test]
    fn a_scene_edited_after_the_capture_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let (dir, _, old_text) = sessions(tmp.path());
        let mut v: serde_json::Value = serde_json::from_str(&old_text).unwrap();
        v["rig"]["flash"]["radiant_intensity_w_per_sr"] = 0.75.into();
        std::fs::write(dir.join("manifest.json"), v.to_string()).unwrap();
        let e = upgrade(&dir).unwrap_err().to_string();
        assert!(e.contains("edited after the capture"), "{e}");
        assert!(!dir.join("manifest.json.pre-upgrade").exists());
    }
}
