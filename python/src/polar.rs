//! `ellipso.polar(mosaic, …)`: a raw mosaic (numpy `uint8`/`uint16`, 2-D, C-contiguous) to
//! Stokes planes through `ellipso_polar::process`, the code `ellipso polar` runs.
//!
//! Contract:
//! - The same defaults and checks as `ellipso polar`: bit depth 8 for `uint8`, 12 for `uint16`
//!   unless given; the layout detected from the pixels when not given ([`ellipso_polar::layout`],
//!   refused when unclear); every value above the bit depth refused with the frame's message.
//! - Bad input raises, never crashes: not an array or a dtype other than `uint8`/`uint16` →
//!   `TypeError`; not 2-D, not C-contiguous, a size that is not whole mosaic tiles, values
//!   above the bit depth, bad levels → `ValueError`.
//! - Memory: a `uint16` mosaic is read in numpy's own buffer (a `RawFrameView` over it: checked
//!   and processed in place, no copy; the array is C-contiguous, or refused); a `uint8` one is
//!   widened to `u16` once (the frame's sample type). Every output plane is the vector the crate
//!   filled, handed to numpy without a copy. The GIL is released while the frame is checked and
//!   processed (as numpy's own ufuncs do: another thread writing the array meanwhile races, as
//!   it would with them).

use ellipso_model::mosaic::SensorLayout;
use ellipso_polar::layout::{Detection, detect};
use ellipso_polar::{DemosaicMethod, PolarConfig, PolarImage, RawFrame, RawFrameView, process};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// The layout names of `ellipso polar --layout`.
pub fn layout_of(name: &str) -> PyResult<SensorLayout> {
    match name {
        "mono" => Ok(SensorLayout::MonoPolar),
        "colour" | "color" => Ok(SensorLayout::ColourPolar),
        other => Err(PyValueError::new_err(format!(
            "layout '{other}': expected 'mono' (IMX250MZR) or 'colour' (IMX250MYR)"
        ))),
    }
}

/// The name `layout_of` reads.
pub fn layout_name(layout: SensorLayout) -> &'static str {
    match layout {
        SensorLayout::MonoPolar => "mono",
        SensorLayout::ColourPolar => "colour",
    }
}

fn demosaic_of(name: &str) -> PyResult<DemosaicMethod> {
    match name {
        "superpixel" => Ok(DemosaicMethod::Superpixel),
        "bilinear" => Ok(DemosaicMethod::Bilinear),
        other => Err(PyValueError::new_err(format!(
            "demosaic '{other}': expected 'superpixel' or 'bilinear'"
        ))),
    }
}

/// A mosaic array's samples borrowed from numpy, with its container depth.
pub enum Samples<'py> {
    /// `uint8`.
    U8(PyReadonlyArray2<'py, u8>),
    /// `uint16`.
    U16(PyReadonlyArray2<'py, u16>),
}

impl Samples<'_> {
    /// Bits of the container (8 or 16).
    pub fn container_bits(&self) -> u8 {
        match self {
            Samples::U8(_) => 8,
            Samples::U16(_) => 16,
        }
    }

    /// The samples in place (contiguity was checked by [`samples`]).
    pub fn slice(&self) -> Slice<'_> {
        match self {
            Samples::U8(a) => Slice::U8(a.as_slice().unwrap_or_default()),
            Samples::U16(a) => Slice::U16(a.as_slice().unwrap_or_default()),
        }
    }
}

/// A mosaic's samples in numpy's buffer, shareable with the work done without the GIL.
#[derive(Clone, Copy)]
pub enum Slice<'a> {
    /// `uint8`.
    U8(&'a [u8]),
    /// `uint16`.
    U16(&'a [u16]),
}

/// Checks `mosaic` is a 2-D C-contiguous `uint8`/`uint16` array (module contract).
pub fn samples<'py>(mosaic: &Bound<'py, PyAny>) -> PyResult<(Samples<'py>, usize, usize)> {
    let array = mosaic.cast::<PyUntypedArray>().map_err(|_| {
        let kind = mosaic
            .get_type()
            .name()
            .map_or_else(|_| "?".to_string(), |n| n.to_string());
        PyTypeError::new_err(format!(
            "mosaic must be a numpy array of uint8 or uint16 raw samples, got {kind}"
        ))
    })?;
    if array.ndim() != 2 {
        return Err(PyValueError::new_err(format!(
            "mosaic must be 2-D (height, width) raw samples, got shape {:?}",
            array.shape()
        )));
    }
    let (h, w) = (array.shape()[0], array.shape()[1]);
    let dtype = array.dtype().to_string();
    let samples = if let Ok(a) = mosaic.extract::<PyReadonlyArray2<'py, u16>>() {
        Samples::U16(a)
    } else if let Ok(a) = mosaic.extract::<PyReadonlyArray2<'py, u8>>() {
        Samples::U8(a)
    } else {
        return Err(PyTypeError::new_err(format!(
            "mosaic has dtype {dtype}: expected uint8 or uint16 (raw DN exactly as the camera \
             delivered them, native byte order)"
        )));
    };
    if !array.is_c_contiguous() {
        return Err(PyValueError::new_err(format!(
            "mosaic ({h}×{w} {dtype}) is not C-contiguous (a slice, a transpose or a flipped \
             view of an image?): the mosaic's 2×2 pattern would be read wrongly; pass \
             numpy.ascontiguousarray(mosaic) if that is what you mean"
        )));
    }
    Ok((samples, w, h))
}

/// The layout given, or detected from the pixels as `ellipso polar` does without `--layout`.
fn settle_layout(
    given: Option<SensorLayout>,
    w: usize,
    h: usize,
    data: &[u16],
) -> Result<SensorLayout, String> {
    if let Some(layout) = given {
        return Ok(layout);
    }
    let e = detect(w, h, data);
    let numbers = format!(
        "colour contrast {:.3}, green-green {:.3} over {} tiles",
        e.rg, e.gg, e.tiles
    );
    match e.detection {
        Detection::Mono => Ok(SensorLayout::MonoPolar),
        Detection::Colour => Ok(SensorLayout::ColourPolar),
        Detection::Unsure => Err(format!(
            "cannot tell a mono (IMX250MZR) from a colour (IMX250MYR) mosaic ({numbers}); pass \
             layout='mono' or layout='colour'"
        )),
    }
}

/// The processing settings of one call (the flags of `ellipso polar`).
pub struct Request {
    /// `None`: detected.
    pub layout: Option<SensorLayout>,
    /// `None`: the container's default.
    pub bit_depth: Option<u8>,
    /// Everything else.
    pub config: PolarConfig,
}

thread_local! {
    /// The widened samples of this thread's last `uint8` mosaic, kept for the next call: its
    /// pages are already mapped, so the widening writes into memory, not page faults (at
    /// 2448×2048 the faults of a fresh 10 MB vector cost several times the work). `uint16`
    /// mosaics are never copied.
    static WIDENED: std::cell::RefCell<Vec<u16>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Validates and processes (no GIL needed): a `uint16` mosaic in numpy's own buffer (a
/// [`RawFrameView`]: checked and read in place, no copy), a `uint8` one widened to `u16` first
/// (the frame's sample type).
pub fn run(
    samples: Slice<'_>,
    w: usize,
    h: usize,
    request: &Request,
) -> Result<(PolarImage, u8), String> {
    match samples {
        // the IMX250's ADC depth (Mono12/Polarized12), as `ellipso polar` assumes
        Slice::U16(s) => process_samples(s, w, h, 12, request),
        Slice::U8(s) => {
            let mut data = WIDENED.with(|v| std::mem::take(&mut *v.borrow_mut()));
            data.clear();
            data.extend(s.iter().map(|&v| u16::from(v)));
            let result = process_samples(&data, w, h, 8, request);
            WIDENED.with(|v| *v.borrow_mut() = data);
            result
        }
    }
}

/// [`run`] over `u16` samples; `default_bits`: the container's bit depth when none was given.
fn process_samples(
    data: &[u16],
    w: usize,
    h: usize,
    default_bits: u8,
    request: &Request,
) -> Result<(PolarImage, u8), String> {
    let layout = settle_layout(request.layout, w, h, data)?;
    let bit_depth = request.bit_depth.unwrap_or(default_bits);
    let too_big = |n: usize| format!("mosaic side {n} exceeds 4294967295");
    let frame = RawFrameView::new(
        u32::try_from(w).map_err(|_| too_big(w))?,
        u32::try_from(h).map_err(|_| too_big(h))?,
        bit_depth,
        layout,
        data,
    )
    .map_err(|e| format!("mosaic: {e}"))?;
    let image = process(&frame, &request.config).map_err(|e| format!("mosaic: {e}"))?;
    Ok((image, bit_depth))
}

/// `ellipso.polar`'s native body: the bands as dicts of arrays (module contract).
#[pyfunction]
#[pyo3(signature = (mosaic, *, layout=None, bit_depth=None, demosaic="superpixel", dark_level=0.0, saturation=None, dark_intensity=ellipso_polar::DEFAULT_DARK_INTENSITY, max_residual=None))]
#[expect(
    clippy::too_many_arguments,
    reason = "the flags of `ellipso polar`, one keyword each"
)]
pub fn polar<'py>(
    py: Python<'py>,
    mosaic: &Bound<'py, PyAny>,
    layout: Option<&str>,
    bit_depth: Option<u8>,
    demosaic: &str,
    dark_level: f32,
    saturation: Option<u16>,
    dark_intensity: f32,
    max_residual: Option<f32>,
) -> PyResult<Bound<'py, PyDict>> {
    let (samples, w, h) = samples(mosaic)?;
    if let Some(b) = bit_depth
        && !(1..=16).contains(&b)
    {
        return Err(PyValueError::new_err(format!(
            "bit_depth {b} is not supported (1..=16 bits per sample)"
        )));
    }
    let request = Request {
        layout: layout.map(layout_of).transpose()?,
        bit_depth,
        config: PolarConfig {
            demosaic: demosaic_of(demosaic)?,
            dark_level_dn: dark_level,
            saturation_dn: saturation,
            dark_intensity,
            max_residual,
            calibration: None,
        },
    };
    let slice = samples.slice();
    let (image, bit_depth) = py
        .detach(|| run(slice, w, h, &request))
        .map_err(PyValueError::new_err)?;
    image_dict(py, image, bit_depth)
}

/// The processed image as `{layout, demosaic, bit_depth, levels…, bands: [{colour, s0, …}]}`,
/// every plane a numpy array that owns the crate's vector.
fn image_dict(py: Python<'_>, image: PolarImage, bit_depth: u8) -> PyResult<Bound<'_, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("layout", layout_name(image.layout))?;
    out.set_item("demosaic", image.method.name())?;
    out.set_item("bit_depth", bit_depth)?;
    out.set_item("dark_level_dn", image.levels.dark_dn())?;
    out.set_item("saturation_dn", image.levels.saturation_dn())?;
    let bands = PyList::empty(py);
    for band in image.bands {
        let (w, h) = (band.width(), band.height());
        let d = PyDict::new(py);
        d.set_item("colour", band.colour.map(|c| c.letter().to_string()))?;
        let plane = |v: Vec<f32>| PyArray1::from_vec(py, v).reshape([h, w]);
        d.set_item("s0", plane(band.s0.into_vec())?)?;
        d.set_item("s1", plane(band.s1.into_vec())?)?;
        d.set_item("s2", plane(band.s2.into_vec())?)?;
        d.set_item("dolp", plane(band.dolp.into_vec())?)?;
        d.set_item("aolp", plane(band.aolp_rad.into_vec())?)?;
        d.set_item("residual", plane(band.residual.into_vec())?)?;
        d.set_item("i_d", plane(band.i_d.into_vec())?)?;
        let mask: Vec<u8> = band.mask.into_vec().into_iter().map(|m| m.0).collect();
        d.set_item("mask", PyArray1::from_vec(py, mask).reshape([h, w])?)?;
        bands.append(d)?;
    }
    out.set_item("bands", bands)?;
    Ok(out)
}

/// This thread's CPU time, seconds (`CLOCK_THREAD_CPUTIME_ID`: what the thread itself ran,
/// whatever else the machine runs; the bench's clock on a shared machine).
pub fn thread_cpu_s() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a valid, writable timespec; the clock id is a constant the OS defines.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    if rc != 0 {
        return f64::NAN;
    }
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

/// Per call of the same work from Rust, `repeats` times one way, then `repeats` times the
/// other, for the bench report (the GIL released throughout): `(cpu_s, wall_s)` of `borrowed`
/// — a [`RawFrameView`] over the caller's buffer (checked in place, processed; what
/// `ellipso.polar` does with a `uint16` array) — then of `owned`, from a vector the caller
/// already owns (checked, processed; no copy). CPU time is this thread's.
#[pyfunction]
#[pyo3(signature = (mosaic, repeats, *, layout, demosaic="superpixel"))]
pub fn _bench_polar_rust(
    py: Python<'_>,
    mosaic: &Bound<'_, PyAny>,
    repeats: usize,
    layout: &str,
    demosaic: &str,
) -> PyResult<BenchTimes> {
    let (samples, w, h) = samples(mosaic)?;
    let layout = layout_of(layout)?;
    let config = PolarConfig {
        demosaic: demosaic_of(demosaic)?,
        ..PolarConfig::default()
    };
    let bits = if samples.container_bits() == 8 { 8 } else { 12 };
    let slice = samples.slice();
    py.detach(|| {
        let owned: Vec<u16> = match slice {
            Slice::U16(s) => s.to_vec(),
            Slice::U8(s) => s.iter().map(|&v| u16::from(v)).collect(),
        };
        // a u8 mosaic has no u16 buffer to borrow: its widened copy stands in for it
        let borrowed: &[u16] = match slice {
            Slice::U16(s) => s,
            Slice::U8(_) => &owned,
        };
        let mut times = BenchTimes::default();
        for _ in 0..repeats {
            let (c, t) = (thread_cpu_s(), std::time::Instant::now());
            let frame = RawFrameView::new(w as u32, h as u32, bits, layout, borrowed)
                .map_err(|e| e.to_string())?;
            let image = process(&frame, &config).map_err(|e| e.to_string())?;
            times
                .0
                .push((thread_cpu_s() - c, t.elapsed().as_secs_f64()));
            drop(std::hint::black_box(image));
        }
        let mut data = owned.clone();
        for _ in 0..repeats {
            let (c, t) = (thread_cpu_s(), std::time::Instant::now());
            let frame = RawFrame::new(w as u32, h as u32, bits, layout, std::mem::take(&mut data))
                .map_err(|e| e.to_string())?;
            let image = process(&frame, &config).map_err(|e| e.to_string())?;
            times
                .1
                .push((thread_cpu_s() - c, t.elapsed().as_secs_f64()));
            data = frame.into_data();
            drop(std::hint::black_box(image));
        }
        Ok::<_, String>(times)
    })
    .map_err(PyValueError::new_err)
}

/// `(borrowed, owned)`: `(cpu_s, wall_s)` per call.
pub type BenchTimes = (Vec<(f64, f64)>, Vec<(f64, f64)>);
