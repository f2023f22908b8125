//! `ellipso export colmap` whole: the output claimed, the session's poses taken (tracked first
//! where the log has none) and the COLMAP model written ([`ellipso_colmap::export`]).

use std::path::{Path, PathBuf};

use ellipso_colmap::export::{ColmapOptions, ColmapReport};

/// `ellipso export colmap SESSION --out DIR`: claims `out` (new, empty, or an earlier `export
/// colmap`'s; written beside and swapped in whole), opens the session, takes its poses
/// ([`crate::poses::poses_of`], lines to `say`), writes the model
/// ([`ellipso_colmap::export::export_colmap`]) and commits it. Returns the
/// report and the published folder.
pub fn export_session(
    session_dir: &Path,
    out: &Path,
    options: ColmapOptions,
    say: &dyn ellipso_run_error::Say,
) -> Result<(ColmapReport, PathBuf), ellipso_run_error::RunError> {
    use ellipso_run_error::Context;
    let out = ellipso_report::output::OutputDir::claim(out, "export-colmap", &[session_dir])?;
    let session = ellipso_session::reader::open(session_dir)?;
    let poses = crate::poses::poses_of(&session, say)?;
    let report = ellipso_colmap::export::export_colmap(&session, &poses, out.path(), options)
        .with_context(|| format!("exporting {} for COLMAP", session_dir.display()))?;
    let published = out.commit()?;
    Ok((report, published))
}
