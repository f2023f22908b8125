//! Paths inside a summary file, relative to that file's own folder: the summaries' rule, so a
//! result folder can be moved or read from anywhere (`fit-summary.json`, the demo's
//! `summary.json`).
//!
//! Contract: a string is taken for a path when it contains a path separator or has an
//! extension, and names an existing file or directory (written relative to the working
//! directory, or absolute); it is then rewritten relative to the summary's folder (`..` where
//! needed). Any other string, and a path that does not exist (yet), is left alone.

use std::path::{MAIN_SEPARATOR, Path, PathBuf};

/// `text` rewritten relative to `base` when it names an existing file or directory (module
/// contract), else `None`.
pub fn relative_if_path(text: &str, base: &Path) -> Option<String> {
    let p = Path::new(text);
    let looks_like_path = text.contains(MAIN_SEPARATOR) || p.extension().is_some();
    if looks_like_path && p.exists() {
        relative_path(p, base).map(|r| r.display().to_string())
    } else {
        None
    }
}

/// Every string in `value` that names an existing file or directory rewritten relative to
/// `base` ([`relative_if_path`]); other strings are left alone.
pub fn paths_relative_to(value: &mut serde_json::Value, base: &Path) {
    match value {
        serde_json::Value::String(s) => {
            if let Some(r) = relative_if_path(s, base) {
                *s = r;
            }
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(|v| paths_relative_to(v, base)),
        serde_json::Value::Object(o) => o.values_mut().for_each(|v| paths_relative_to(v, base)),
        _ => {}
    }
}

/// `path` relative to the directory `base` (both resolved; `..` where needed), or `None` when
/// either cannot be resolved.
pub fn relative_path(path: &Path, base: &Path) -> Option<PathBuf> {
    let path = path.canonicalize().ok()?;
    let base = base.canonicalize().ok()?;
    let common = path
        .components()
        .zip(base.components())
        .take_while(|(a, b)| a == b)
        .count();
    let mut out = PathBuf::new();
    for _ in base.components().skip(common) {
        out.push("..");
    }
    for c in path.components().skip(common) {
        out.push(c);
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_paths_become_relative_to_the_summary_folder() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("demo").join("fit");
        std::fs::create_dir_all(&out).unwrap();
        let session = tmp.path().join("demo").join("session");
        std::fs::create_dir_all(&session).unwrap();
        std::fs::write(out.join("fit.ply"), b"x").unwrap();
        let mut v = serde_json::json!({
            "session": session.display().to_string(),
            "files": [out.join("fit.ply").display().to_string()],
            "note": "intact",
            "later": out.join("not-yet.json").display().to_string(),
        });
        paths_relative_to(&mut v, &out);
        assert_eq!(v["session"], "../session");
        assert_eq!(v["files"][0], "fit.ply");
        assert_eq!(v["note"], "intact");
        assert_eq!(v["later"], out.join("not-yet.json").display().to_string());
    }
}
