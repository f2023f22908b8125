//! The shipped scenes, boards and assets, embedded in every binary that links the simulator.
//!
//! Contract: [`shipped_scene`] returns a path `Scene::load` can read. In a source checkout that
//! is the file under `sim/scenes/` (so an edit there is what runs); when the checkout is gone
//! (an installed binary) the embedded copies are written once to
//! `$TMPDIR/ellipso-shipped-<version>/` with the same layout (`scenes/`, `boards/`, `assets/`),
//! so the scenes' relative `mesh` and `file` references still resolve. A file already there
//! with other contents is rewritten; a directory that cannot be written leaves the returned path
//! absent, and loading it names that path.

use std::path::{Path, PathBuf};

/// Every shipped file, by its path under `sim/`.
const FILES: &[(&str, &[u8])] = &[
    (
        "scenes/calibration.toml",
        include_bytes!("../../scenes/calibration.toml"),
    ),
    ("scenes/demo.toml", include_bytes!("../../scenes/demo.toml")),
    (
        "scenes/multi_material.toml",
        include_bytes!("../../scenes/multi_material.toml"),
    ),
    (
        "scenes/multi_material_bracket.toml",
        include_bytes!("../../scenes/multi_material_bracket.toml"),
    ),
    (
        "scenes/s0_only.toml",
        include_bytes!("../../scenes/s0_only.toml"),
    ),
    (
        "scenes/sphere.toml",
        include_bytes!("../../scenes/sphere.toml"),
    ),
    (
        "boards/base_a4.toml",
        include_bytes!("../../boards/base_a4.toml"),
    ),
    (
        "boards/calib_grid.toml",
        include_bytes!("../../boards/calib_grid.toml"),
    ),
    (
        "boards/side_a5.toml",
        include_bytes!("../../boards/side_a5.toml"),
    ),
    (
        "assets/bumpy_blob.ply",
        include_bytes!("../../assets/bumpy_blob.ply"),
    ),
];

/// The names of the shipped scenes (`demo.toml`, …).
pub fn shipped_scene_names() -> impl Iterator<Item = &'static str> {
    FILES.iter().filter_map(|(p, _)| p.strip_prefix("scenes/"))
}

/// The path of shipped scene `name` (module doc): the source tree's file when it exists, else
/// the embedded copy written out.
pub fn shipped_scene(name: &str) -> PathBuf {
    let in_tree = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name);
    if in_tree.is_file() {
        return in_tree;
    }
    let root = std::env::temp_dir().join(format!("ellipso-shipped-{}", env!("CARGO_PKG_VERSION")));
    // Best effort: a failed write leaves the path absent and `Scene::load` names it.
    let _ = materialise(&root);
    root.join("scenes").join(name)
}

/// Writes every embedded file under `root`, leaving files with the right contents alone.
pub fn materialise(root: &Path) -> std::io::Result<()> {
    for (rel, bytes) in FILES {
        let path = root.join(rel);
        if std::fs::read(&path).is_ok_and(|have| have == *bytes) {
            continue;
        }
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        // Write to a unique name and rename, so a concurrent reader never sees half a file.
        let tmp = path.with_extension(format!("tmp{}", std::process::id()));
        std::fs::write(&tmp, bytes)?;
        std::fs::rename(&tmp, &path)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// Every scene in `sim/scenes/` is embedded, and the embedded copies load to the same scene
    /// as the source tree's files (same objects, boards and poses).
    #[test]
    fn embedded_scenes_load_like_the_source_tree() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".toml"))
            .collect();
        on_disk.sort();
        let mut embedded: Vec<String> = shipped_scene_names().map(str::to_string).collect();
        embedded.sort();
        assert_eq!(on_disk, embedded, "a scene in sim/scenes/ is not embedded");
        let tmp = tempfile::tempdir().unwrap();
        materialise(tmp.path()).unwrap();
        materialise(tmp.path()).unwrap(); // idempotent
        for name in embedded {
            let ours = Scene::load(&tmp.path().join("scenes").join(&name)).unwrap();
            let tree = Scene::load(&dir.join(&name)).unwrap();
            assert_eq!(ours.objects.len(), tree.objects.len(), "{name}");
            assert_eq!(ours.boards.len(), tree.boards.len(), "{name}");
            assert_eq!(ours.camera_poses.len(), tree.camera_poses.len(), "{name}");
            for (a, b) in ours.camera_poses.iter().zip(&tree.camera_poses) {
                assert_eq!(a.world_from_camera, b.world_from_camera, "{name}");
            }
        }
    }
}
