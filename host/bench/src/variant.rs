//! Scene variants: a scene file with stages of its effect plan removed (or its seed or photo
//! count changed), written out as a scene file of its own.
//!
//! Contract:
//! - [`write_variant`] reads the scene's TOML, applies a [`SceneEdit`] and writes the result to
//!   the given path with every relative file reference (`objects[].mesh`, `boards[].file`)
//!   made absolute, so the written scene renders the same object from anywhere — and a session
//!   rendered from it names a scene whose radiometry and sensor are exactly the frames' (the fit
//!   reads them from the scene the manifest names: undoing an extinction the frames never had
//!   would bias it).
//! - The written file is loaded back and returned: an edit that makes the scene invalid is an
//!   error naming the scene, never a silently different scene.

use std::path::{Path, PathBuf};

use ellipso_sim::scene::Scene;

use crate::BenchError;

/// What a variant changes in its scene.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SceneEdit {
    /// `[effects]` entries removed (`shot_noise`, `read_noise`, `quantisation`, `saturation`,
    /// `polariser_extinction`, `vignetting`, …; an entry the scene lacks is ignored).
    pub remove_effects: Vec<String>,
    /// Photos along the same capture path (`None`: the scene's).
    pub photo_count: Option<usize>,
    /// Scene seed (capture path of seeded paths, sensor noise; `None`: the scene's).
    pub seed: Option<u64>,
    /// No pixel ever clips: the camera's ADC gets 16 bits and its full well grows by the same
    /// factor, so DN per electron, read noise and quantisation stay as they are while the
    /// full-well and ADC clips move ~16× above any signal (the truth of "saturation": the
    /// scene's `saturation` effect alone cannot be removed, a 12-bit frame cannot hold the
    /// unclipped values).
    pub unclipped: bool,
}

/// Writes `scene` edited by `edit` to `out` (module doc) and returns it loaded from there.
pub fn write_variant(scene: &Path, edit: &SceneEdit, out: &Path) -> Result<Scene, BenchError> {
    let text = std::fs::read_to_string(scene).map_err(|e| BenchError::io(scene, e))?;
    let mut table: toml::Table = toml::from_str(&text).map_err(|e| BenchError::Scene {
        path: scene.to_owned(),
        what: e.to_string(),
    })?;
    let base = scene.parent().unwrap_or_else(|| Path::new("."));
    let base = std::fs::canonicalize(base).map_err(|e| BenchError::io(base, e))?;
    absolutise(&mut table, "objects", "mesh", &base);
    absolutise(&mut table, "boards", "file", &base);
    if let Some(effects) = table.get_mut("effects").and_then(|e| e.as_table_mut()) {
        for name in &edit.remove_effects {
            effects.remove(name);
        }
    }
    if let Some(n) = edit.photo_count {
        let capture = table
            .get_mut("capture")
            .and_then(|c| c.as_table_mut())
            .ok_or_else(|| BenchError::Scene {
                path: scene.to_owned(),
                what: "no [capture] table to set the photo count in".into(),
            })?;
        capture.insert("photo_count".into(), toml::Value::Integer(n as i64));
    }
    if edit.unclipped {
        let camera = table
            .get_mut("rig")
            .and_then(|r| r.as_table_mut())
            .and_then(|r| r.get_mut("camera"))
            .and_then(|c| c.as_table_mut())
            .ok_or_else(|| BenchError::Scene {
                path: scene.to_owned(),
                what: "no [rig.camera] table to unclip".into(),
            })?;
        let int = |v: Option<&toml::Value>, default: i64| {
            v.and_then(|v| v.as_integer()).unwrap_or(default)
        };
        let float = |v: Option<&toml::Value>, default: f64| {
            v.and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
                .unwrap_or(default)
        };
        let bits = int(camera.get("bit_depth"), 12);
        // The simulator's default full well (`CameraSpec::full_well_e`).
        let full_well = float(camera.get("full_well_e"), 10_500.0);
        let factor = 65_535.0 / ((1i64 << bits.clamp(1, 16)) - 1) as f64;
        camera.insert("bit_depth".into(), toml::Value::Integer(16));
        camera.insert("full_well_e".into(), toml::Value::Float(full_well * factor));
    }
    if let Some(seed) = edit.seed {
        // TOML integers are i64; a seed above i64::MAX keeps its bits.
        table.insert("seed".into(), toml::Value::Integer(seed as i64));
    }
    let written = toml::to_string(&table).map_err(|e| BenchError::Scene {
        path: scene.to_owned(),
        what: e.to_string(),
    })?;
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).map_err(|e| BenchError::io(dir, e))?;
    }
    std::fs::write(out, written).map_err(|e| BenchError::io(out, e))?;
    Scene::load(out).map_err(|e| BenchError::Scene {
        path: out.to_owned(),
        what: e.to_string(),
    })
}

/// Makes `key` of every table in the array `array` absolute against `base`.
fn absolutise(table: &mut toml::Table, array: &str, key: &str, base: &Path) {
    let Some(items) = table.get_mut(array).and_then(|a| a.as_array_mut()) else {
        return;
    };
    for item in items.iter_mut().filter_map(|i| i.as_table_mut()) {
        if let Some(toml::Value::String(p)) = item.get_mut(key) {
            let path = PathBuf::from(&*p);
            if path.is_relative() {
                *p = base.join(path).display().to_string();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_sim::scene::shipped_scene;

    #[test]
    fn a_variant_renders_the_same_object_without_the_removed_stages() {
        let tmp = tempfile::tempdir().unwrap();
        let src = shipped_scene("demo.toml");
        let original = Scene::load(&src).unwrap();
        let edit = SceneEdit {
            remove_effects: vec!["polariser_extinction".into(), "shot_noise".into()],
            photo_count: Some(12),
            seed: Some(3),
            unclipped: true,
        };
        let v = write_variant(&src, &edit, &tmp.path().join("deep/v.toml")).unwrap();
        assert!(v.effects.polariser_extinction.is_none());
        assert!(v.effects.shot_noise.is_none());
        assert!(v.effects.read_noise.is_some());
        assert_eq!(v.camera_poses.len(), 12);
        assert_eq!(v.seed, 3);
        // Unclipped: the same DN per electron, 16× the room.
        let dn_per_e =
            |s: &Scene| f64::from((1u32 << s.rig.camera.bit_depth) - 1) / s.rig.camera.full_well_e;
        assert_eq!(v.rig.camera.bit_depth, 16);
        assert!((dn_per_e(&v) / dn_per_e(&original) - 1.0).abs() < 1e-12);
        assert_eq!(v.materials.len(), original.materials.len());
        assert_eq!(v.boards.len(), original.boards.len());
    }

    #[test]
    fn an_edit_that_breaks_the_scene_is_an_error() {
        let tmp = tempfile::tempdir().unwrap();
        let src = shipped_scene("demo.toml");
        let edit = SceneEdit {
            photo_count: Some(0),
            ..SceneEdit::default()
        };
        let e = write_variant(&src, &edit, &tmp.path().join("v.toml")).unwrap_err();
        assert!(e.to_string().contains("v.toml"), "{e}");
    }
}
