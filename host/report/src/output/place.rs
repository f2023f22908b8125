//! Where an output may go: the path made absolute and canonical, and the checks every output
//! shares — never equal to, inside or around one of the command's inputs, never around the
//! current directory, never inside a recorded session except the session's own derived
//! directory of that command (`ellipso_session::paths::DERIVED`).
//!
//! Contract: [`resolve`] canonicalises the longest existing prefix of a path (so symbolic links
//! and `..` are followed as the kernel would) and appends the rest lexically; two spellings of
//! one place compare equal. Inputs that do not exist are compared as spelled, resolved the same
//! way.

use std::path::{Component, Path, PathBuf};

use super::OutputError;

/// `path` made absolute: the longest existing prefix canonical, the rest lexical.
pub fn resolve(path: &Path) -> Result<PathBuf, OutputError> {
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .map_err(|source| OutputError::io(path, source))?
            .join(path)
    };
    let mut out = PathBuf::new();
    let mut existing = true;
    for c in absolute.components() {
        match c {
            Component::Prefix(_) | Component::RootDir => out.push(c.as_os_str()),
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            Component::Normal(name) => {
                out.push(name);
                // once one component is missing, every later one is too
                if existing {
                    match out.canonicalize() {
                        Ok(canonical) => out = canonical,
                        Err(_) => existing = false,
                    }
                }
            }
        }
    }
    Ok(out)
}

/// How an output relates to an input.
fn relation(out: &Path, input: &Path) -> Option<&'static str> {
    if out == input {
        Some("is")
    } else if out.starts_with(input) {
        Some("is inside")
    } else if input.starts_with(out) {
        Some("contains")
    } else {
        None
    }
}

/// Checks that `out` (resolved) may be written by `command` reading `inputs` (see the module
/// doc); `derived` is the session subdirectory the command owns, if it has one.
pub fn check(
    out: &Path,
    command: &str,
    inputs: &[&Path],
    derived: Option<&str>,
) -> Result<(), OutputError> {
    // a session's own derived directory of this command: inside its session by design
    let mut allowed_session = None;
    if let Some(session) = ellipso_session::paths::enclosing_session(out) {
        let within = out.strip_prefix(&session).ok().and_then(|rest| {
            let first = rest.components().next()?;
            ellipso_session::paths::DERIVED
                .iter()
                .find(|(dir, owner)| {
                    first.as_os_str() == *dir && Some(*dir) == derived && *owner == command
                })
                .map(|_| ())
        });
        if within.is_none() {
            return Err(OutputError::InsideSession {
                out: out.to_path_buf(),
                session,
            });
        }
        allowed_session = Some(session);
    }
    for input in inputs {
        let input = resolve(input)?;
        if allowed_session.as_deref() == Some(input.as_path()) && out != input {
            continue;
        }
        if let Some(relation) = relation(out, &input) {
            return Err(OutputError::OverlapsInput {
                out: out.to_path_buf(),
                relation,
                input,
            });
        }
    }
    if let Ok(cwd) = std::env::current_dir().and_then(|d| d.canonicalize()) {
        if cwd.starts_with(out) {
            return Err(OutputError::OverlapsInput {
                out: out.to_path_buf(),
                relation: "contains",
                input: cwd,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spellings_of_one_place_resolve_alike() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().canonicalize().unwrap();
        std::fs::create_dir(root.join("a")).unwrap();
        std::os::unix::fs::symlink(root.join("a"), root.join("link")).unwrap();
        assert_eq!(resolve(&root.join("a/./b/../c")).unwrap(), root.join("a/c"));
        assert_eq!(resolve(&root.join("link/x")).unwrap(), root.join("a/x"));
        assert_eq!(resolve(&root.join("missing/../a")).unwrap(), root.join("a"));
    }

    #[test]
    fn outputs_never_overlap_inputs() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().canonicalize().unwrap();
        let input = root.join("in");
        std::fs::create_dir(&input).unwrap();
        for (out, relation) in [
            (input.clone(), "is"),
            (input.join("frames"), "is inside"),
            (root.clone(), "contains"),
        ] {
            match check(&out, "fit", &[&input], None) {
                Err(OutputError::OverlapsInput { relation: r, .. }) => assert_eq!(r, relation),
                other => panic!("{}: {other:?}", out.display()),
            }
        }
        check(&root.join("out"), "fit", &[&input], None).unwrap();
    }

    #[test]
    fn a_session_is_written_only_in_the_commands_derived_directory() {
        let dir = tempfile::tempdir().unwrap();
        let session = dir.path().canonicalize().unwrap().join("s");
        std::fs::create_dir_all(session.join("frames")).unwrap();
        std::fs::write(session.join("manifest.json"), b"{}").unwrap();
        let inputs: [&Path; 1] = [&session];
        let calib = session.join("calibration").join("camera.toml");
        check(&calib, "calibrate", &inputs, Some("calibration")).unwrap();
        // without the input too: a session is protected whoever writes
        assert!(matches!(
            check(
                &session.join("frames/00000001.png"),
                "model-plot",
                &[],
                None
            ),
            Err(OutputError::InsideSession { .. })
        ));
        assert!(matches!(
            check(&session.join("replay"), "fit", &inputs, None),
            Err(OutputError::InsideSession { .. })
        ));
        // the derived directory of another command is not this one's
        assert!(matches!(
            check(
                &session.join("replay"),
                "calibrate",
                &inputs,
                Some("calibration")
            ),
            Err(OutputError::InsideSession { .. })
        ));
    }
}
