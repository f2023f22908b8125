//! The pBRDF of `ellipso-model` over arrays: the Mueller matrices of `ellipso model mueller`,
//! the coaxial 3×3 block and the Fresnel terms of `ellipso model fresnel`, one element at a
//! time through the same functions (`ellipso_model::optics::{inspect, coaxial}`).
//!
//! Contract: the Python layer broadcasts its arguments and passes flat C-contiguous `float64`
//! arrays of one length `n` (vectors as `(n, 3)`); each element is checked and evaluated as the
//! command line does for one, and the first bad element raises `ValueError` naming its index
//! and the command's message. The GIL is released over the loop.

use ellipso_model::optics::Vec3;
use ellipso_model::optics::coaxial::{CoaxialGeometry, terms};
use ellipso_model::optics::inspect::{
    MuellerInputs, fresnel as fresnel_one, mueller as mueller_one,
};
use ellipso_model::optics::pbrdf::PbrdfParams;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A flat array's values (contiguity checked).
fn flat<'a>(name: &str, a: &'a PyReadonlyArray1<'_, f64>) -> PyResult<&'a [f64]> {
    a.as_slice()
        .map_err(|_| PyValueError::new_err(format!("{name} is not C-contiguous")))
}

/// An `(n, 3)` array's rows.
fn rows3(name: &str, a: &PyReadonlyArray2<'_, f64>, n: usize) -> PyResult<Vec<[f64; 3]>> {
    let shape = a.shape();
    if shape != [n, 3] {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape ({n}, 3), got {shape:?}"
        )));
    }
    let s = a
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("{name} is not C-contiguous")))?;
    Ok(s.chunks_exact(3).map(|r| [r[0], r[1], r[2]]).collect())
}

/// The material parameters of every element.
struct Params<'a> {
    eta: &'a [f64],
    sigma_s: &'a [f64],
    sigma_ss: &'a [f64],
    rho_s: &'a [f64],
    rho_ss: Vec<[f64; 3]>,
    rho_d: Vec<[f64; 3]>,
}

impl<'a> Params<'a> {
    /// The six parameter arrays of `n = eta.len()` elements, their lengths checked
    /// ([`Params::len`]).
    fn read(
        eta: &'a PyReadonlyArray1<'_, f64>,
        sigma_s: &'a PyReadonlyArray1<'_, f64>,
        sigma_ss: &'a PyReadonlyArray1<'_, f64>,
        rho_s: &'a PyReadonlyArray1<'_, f64>,
        rho_ss: &PyReadonlyArray2<'_, f64>,
        rho_d: &PyReadonlyArray2<'_, f64>,
    ) -> PyResult<Self> {
        let n = eta.len();
        let p = Params {
            eta: flat("eta", eta)?,
            sigma_s: flat("sigma_s", sigma_s)?,
            sigma_ss: flat("sigma_ss", sigma_ss)?,
            rho_s: flat("rho_s", rho_s)?,
            rho_ss: rows3("rho_ss", rho_ss, n)?,
            rho_d: rows3("rho_d", rho_d, n)?,
        };
        p.len()?;
        Ok(p)
    }

    fn len(&self) -> PyResult<usize> {
        let n = self.eta.len();
        for (name, len) in [
            ("sigma_s", self.sigma_s.len()),
            ("sigma_ss", self.sigma_ss.len()),
            ("rho_s", self.rho_s.len()),
        ] {
            if len != n {
                return Err(PyValueError::new_err(format!(
                    "{name} has {len} values but eta has {n}"
                )));
            }
        }
        Ok(n)
    }

    fn at(&self, i: usize) -> PbrdfParams<f64> {
        PbrdfParams {
            eta: self.eta[i],
            sigma_s: self.sigma_s[i],
            sigma_ss: self.sigma_ss[i],
            rho_s: self.rho_s[i],
            rho_ss: self.rho_ss[i],
            rho_d: self.rho_d[i],
        }
    }
}

fn element_error(i: usize, e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("element {i}: {e}"))
}

/// 4×4 matrices pushed row-major.
fn push4(out: &mut Vec<f64>, m: &[[f64; 4]; 4]) {
    out.extend(m.iter().flatten());
}

/// `ellipso model mueller` for `n` geometries and materials.
#[pyfunction]
#[expect(
    clippy::too_many_arguments,
    reason = "the model's inputs, one array each"
)]
pub fn mueller<'py>(
    py: Python<'py>,
    eta: PyReadonlyArray1<'py, f64>,
    sigma_s: PyReadonlyArray1<'py, f64>,
    sigma_ss: PyReadonlyArray1<'py, f64>,
    rho_s: PyReadonlyArray1<'py, f64>,
    rho_ss: PyReadonlyArray2<'py, f64>,
    rho_d: PyReadonlyArray2<'py, f64>,
    normal: PyReadonlyArray2<'py, f64>,
    to_light: PyReadonlyArray2<'py, f64>,
    to_camera: PyReadonlyArray2<'py, f64>,
    light_up: PyReadonlyArray2<'py, f64>,
    camera_up: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let n = eta.len();
    let p = Params::read(&eta, &sigma_s, &sigma_ss, &rho_s, &rho_ss, &rho_d)?;
    let normal = rows3("normal", &normal, n)?;
    let to_light = rows3("to_light", &to_light, n)?;
    let to_camera = rows3("to_camera", &to_camera, n)?;
    let light_up = rows3("light_up", &light_up, n)?;
    let camera_up = rows3("camera_up", &camera_up, n)?;
    let (total, diffuse, specular, single, front) = py
        .detach(|| {
            let mut total = Vec::with_capacity(n * 48);
            let mut diffuse = Vec::with_capacity(n * 48);
            let mut specular = Vec::with_capacity(n * 16);
            let mut single = Vec::with_capacity(n * 48);
            let mut front = Vec::with_capacity(n);
            for i in 0..n {
                let t = mueller_one(&MuellerInputs {
                    params: p.at(i),
                    normal: normal[i],
                    to_light: to_light[i],
                    to_camera: to_camera[i],
                    light_up: Some(light_up[i]),
                    camera_up: Some(camera_up[i]),
                })
                .map_err(|e| (i, e.to_string()))?;
                t.total.iter().for_each(|m| push4(&mut total, m));
                t.diffuse.iter().for_each(|m| push4(&mut diffuse, m));
                push4(&mut specular, &t.specular);
                t.single_scattering
                    .iter()
                    .for_each(|m| push4(&mut single, m));
                front.push(t.front_facing);
            }
            Ok((total, diffuse, specular, single, front))
        })
        .map_err(|(i, e): (usize, String)| element_error(i, e))?;
    let d = PyDict::new(py);
    d.set_item(
        "total",
        PyArray1::from_vec(py, total).reshape([n, 3, 4, 4])?,
    )?;
    d.set_item(
        "diffuse",
        PyArray1::from_vec(py, diffuse).reshape([n, 3, 4, 4])?,
    )?;
    d.set_item(
        "specular",
        PyArray1::from_vec(py, specular).reshape([n, 4, 4])?,
    )?;
    d.set_item(
        "single_scattering",
        PyArray1::from_vec(py, single).reshape([n, 3, 4, 4])?,
    )?;
    d.set_item("front_facing", PyArray1::from_vec(py, front))?;
    Ok(d)
}

/// The coaxial 3×3 block per channel (talk form, docs/model.md §5) for `n` normals in the
/// camera frame (x right, y up, z toward the camera) and materials: `(n, 3, 3, 3)`.
#[pyfunction]
#[expect(
    clippy::too_many_arguments,
    reason = "the model's inputs, one array each"
)]
pub fn coaxial<'py>(
    py: Python<'py>,
    eta: PyReadonlyArray1<'py, f64>,
    sigma_s: PyReadonlyArray1<'py, f64>,
    sigma_ss: PyReadonlyArray1<'py, f64>,
    rho_s: PyReadonlyArray1<'py, f64>,
    rho_ss: PyReadonlyArray2<'py, f64>,
    rho_d: PyReadonlyArray2<'py, f64>,
    normal_camera: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, numpy::PyArray4<f64>>> {
    let n = eta.len();
    let p = Params::read(&eta, &sigma_s, &sigma_ss, &rho_s, &rho_ss, &rho_d)?;
    let normals = rows3("normal_camera", &normal_camera, n)?;
    let out = py
        .detach(|| {
            let mut out = Vec::with_capacity(n * 27);
            for (i, &nc) in normals.iter().enumerate() {
                let params = p.at(i);
                params.validate().map_err(|e| (i, e.to_string()))?;
                if !nc.iter().all(|v| v.is_finite()) || nc.iter().all(|v| *v == 0.0) {
                    return Err((
                        i,
                        format!("normal_camera must be a finite non-zero vector, got {nc:?}"),
                    ));
                }
                let g = CoaxialGeometry::from_normal_in_camera(Vec3::from_f64(nc));
                for channel in terms(&g, &params) {
                    out.extend(channel.linear3().iter().flatten());
                }
            }
            Ok(out)
        })
        .map_err(|(i, e): (usize, String)| element_error(i, e))?;
    PyArray1::from_vec(py, out).reshape([n, 3, 3, 3])
}

/// `ellipso model fresnel` for `n` indices and angles: `rs, rp, r_plus, r_minus, r_cross,
/// t_plus, t_minus`, each `(n,)`.
#[pyfunction]
pub fn fresnel<'py>(
    py: Python<'py>,
    eta: PyReadonlyArray1<'py, f64>,
    theta_deg: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let eta = flat("eta", &eta)?;
    let theta = flat("theta_deg", &theta_deg)?;
    if eta.len() != theta.len() {
        return Err(PyValueError::new_err(format!(
            "theta_deg has {} values but eta has {}",
            theta.len(),
            eta.len()
        )));
    }
    let columns = py
        .detach(|| {
            let mut c: [Vec<f64>; 7] = Default::default();
            for (i, (&e, &t)) in eta.iter().zip(theta).enumerate() {
                let f = fresnel_one(e, t).map_err(|err| (i, err.to_string()))?;
                for (col, v) in c.iter_mut().zip([
                    f.rs, f.rp, f.r_plus, f.r_minus, f.r_cross, f.t_plus, f.t_minus,
                ]) {
                    col.push(v);
                }
            }
            Ok(c)
        })
        .map_err(|(i, e): (usize, String)| element_error(i, e))?;
    let d = PyDict::new(py);
    let names = [
        "rs", "rp", "r_plus", "r_minus", "r_cross", "t_plus", "t_minus",
    ];
    for (name, col) in names.into_iter().zip(columns) {
        d.set_item(name, PyArray1::from_vec(py, col))?;
    }
    Ok(d)
}
