//! Errors from the crates as Python exceptions, with the command line's messages.
//!
//! Contract: every error reaching Python carries the text `ellipso` prints after `error:` for
//! the same failure (the error and its causes joined by `: `, as `anyhow`'s `{:#}` writes
//! them). The class says what kind of failure it is: bad arguments are `TypeError` /
//! `ValueError`, a missing file `FileNotFoundError`, everything else [`EllipsoError`] (a
//! `RuntimeError`), so `except ValueError` catches what the caller can fix by changing the call.

use pyo3::PyErr;
use pyo3::exceptions::{PyFileNotFoundError, PyRuntimeError, PyValueError};

pyo3::create_exception!(
    _native,
    EllipsoError,
    PyRuntimeError,
    "A failure inside ellipso (reading, meshing, fitting, writing); the message is the command line's."
);

/// An error and its causes on one line, `a: b: c` (the CLI's `error: {:#}`), without repeats:
/// a cause whose text the error already ends with is not written twice.
pub fn chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let more = c.to_string();
        if !text.ends_with(&more) {
            text.push_str(": ");
            text.push_str(&more);
        }
        cause = c.source();
    }
    text
}

/// A pipeline error ([`ellipso_run_error::RunError`]) as a Python exception.
pub fn run_error(e: ellipso_run_error::RunError) -> PyErr {
    let boxed = e.into_boxed();
    let text = chain(boxed.as_ref());
    if is_not_found(boxed.as_ref()) {
        PyFileNotFoundError::new_err(text)
    } else {
        EllipsoError::new_err(text)
    }
}

/// A session error as a Python exception (a missing file is `FileNotFoundError`, a bad frame
/// or manifest `ValueError`).
pub fn session_error(e: ellipso_session::SessionError) -> PyErr {
    use ellipso_session::SessionError as E;
    let text = chain(&e);
    match &e {
        E::Io { error, .. } if error.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(text)
        }
        E::Io { .. } => EllipsoError::new_err(text),
        _ => PyValueError::new_err(text),
    }
}

/// Whether a missing file is what failed (the error, or any error it wraps).
fn is_not_found(e: &(dyn std::error::Error + 'static)) -> bool {
    // a `RunError` passed on by `?` is transparent: its `source` skips the error it wraps
    if let Some(ellipso_run_error::RunErrorKind::Other(inner)) =
        e.downcast_ref::<ellipso_run_error::RunErrorKind>()
    {
        return is_not_found(inner.as_ref());
    }
    if let Some(io) = e.downcast_ref::<std::io::Error>()
        && io.kind() == std::io::ErrorKind::NotFound
    {
        return true;
    }
    if let Some(ellipso_session::SessionError::Io { error, .. }) =
        e.downcast_ref::<ellipso_session::SessionError>()
        && error.kind() == std::io::ErrorKind::NotFound
    {
        return true;
    }
    e.source().is_some_and(is_not_found)
}
