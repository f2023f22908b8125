//! `ellipso._native`: the extension module behind the `ellipso` Python package (python/ellipso).
//! Every function calls the crate code the `ellipso` binary runs; the Python layer adds the
//! types, the broadcasting and the docs.
//!
//! - [`polar`]: `ellipso polar`'s processing of a raw mosaic array;
//! - [`session`]: a recorded session, read-only;
//! - [`model`]: the pBRDF's Mueller matrices, the coaxial block, the Fresnel terms;
//! - [`run`]: `ellipso mesh` and `ellipso fit` with progress and Ctrl-C;
//! - [`errors`]: the CLI's messages as Python exceptions.

use pyo3::prelude::*;

mod errors;
mod model;
mod polar;
mod run;
mod session;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("EllipsoError", m.py().get_type::<errors::EllipsoError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<session::Session>()?;
    m.add_function(wrap_pyfunction!(polar::polar, m)?)?;
    m.add_function(wrap_pyfunction!(polar::_bench_polar_rust, m)?)?;
    m.add_function(wrap_pyfunction!(model::mueller, m)?)?;
    m.add_function(wrap_pyfunction!(model::coaxial, m)?)?;
    m.add_function(wrap_pyfunction!(model::fresnel, m)?)?;
    m.add_function(wrap_pyfunction!(run::mesh, m)?)?;
    m.add_function(wrap_pyfunction!(run::fit, m)?)?;
    m.add_function(wrap_pyfunction!(run::fit_flag_names, m)?)?;
    Ok(())
}
