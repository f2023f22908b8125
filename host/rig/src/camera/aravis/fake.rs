//! aravis' GigE Vision fake camera served in-process on `127.0.0.1`, with scene content from a
//! Rust closure: the camera for loopback tests, demos and benchmarks of the aravis backend.
//!
//! Contract:
//! - [`FakeGigeCamera::serve_on_loopback`] starts libaravis' `GvFakeCamera` (real GVCP + GVSP
//!   sockets) bound to the loopback address only, sets its pixel format and region by raw register
//!   writes (so PFNC formats outside its GenICam list, such as `Mono12` and `Mono12Packed`, work),
//!   and installs the fill closure. Open it with
//!   [`AravisCamera::open`](super::AravisCamera::open)`("127.0.0.1", …)`. Run it inside a private
//!   network namespace in tests (see `docs/cameras.md`).
//! - The fill closure runs on the fake camera's streaming thread once per frame and gets the
//!   frame's GVSP block id, size, pixel format, exposure and the payload bytes to write. A panic in
//!   it is caught (the frame is sent as it stands) so it never unwinds into C.
//! - [`FakeGigeCamera::set_lost_ratio`] drops that fraction of GVSP packets at random (glib's
//!   global RNG: not reproducible run to run). The fake camera never resends.
//! - Dropping the value uninstalls the closure before stopping the server, then frees it.

use std::ffi::c_void;
use std::panic::AssertUnwindSafe;

use aravis::glib::translate::ToGlibPtr;
use aravis::{FakeCamera, GvFakeCamera};

use crate::camera::CameraError;

/// Register addresses of aravis' fake camera (`arvfakecamera.h`).
mod reg {
    pub const WIDTH: u32 = 0x100;
    pub const HEIGHT: u32 = 0x104;
    pub const SENSOR_HEIGHT: u32 = 0x118;
    pub const SENSOR_WIDTH: u32 = 0x11c;
    pub const PIXEL_FORMAT: u32 = 0x128;
    pub const OFFSET_X: u32 = 0x130;
    pub const OFFSET_Y: u32 = 0x134;
}

/// One frame to fill.
pub struct FillRequest<'a> {
    /// GVSP block id the frame will carry (1..=65535, wrapping).
    pub block_id: u64,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// PFNC pixel-format code.
    pub pixel_format: u32,
    /// Exposure register value, µs.
    pub exposure_us: u32,
    /// The payload: `width × height × bits_per_pixel / 8` bytes.
    pub data: &'a mut [u8],
}

/// A fill closure.
pub type FillFn = dyn Fn(FillRequest<'_>) + Send + Sync + 'static;

/// Setup of the fake camera.
#[derive(Debug, Clone, PartialEq)]
pub struct FakeGigeOptions {
    /// Serial number it reports.
    pub serial: String,
    /// Sensor size, px.
    pub sensor_width: u32,
    /// Sensor height, px.
    pub sensor_height: u32,
    /// Initial region width, px.
    pub width: u32,
    /// Initial region height, px.
    pub height: u32,
    /// PFNC pixel-format code written to its `PixelFormat` register.
    pub pixel_format: u32,
}

impl Default for FakeGigeOptions {
    fn default() -> Self {
        Self {
            serial: "ELLIPSO-FAKE".to_owned(),
            sensor_width: 2448,
            sensor_height: 2048,
            width: 2448,
            height: 2048,
            pixel_format: super::format::PFNC_MONO12,
        }
    }
}

/// aravis' fake GigE camera, serving on `127.0.0.1` in this process.
pub struct FakeGigeCamera {
    // field order is drop order: the server stops before the closure is freed
    server: GvFakeCamera,
    camera: FakeCamera,
    fill: Option<Box<Box<FillFn>>>,
}

/// The fill callback aravis' fake camera calls for each frame; it forwards to the installed
/// [`FillFn`].
///
/// # Safety
///
/// Only aravis calls it, as the fill pattern `serve_on_loopback` installs with `user` pointing
/// at that camera's `Box<FillFn>`.
// SAFETY: `unsafe` because the caller must pass a live `ArvBuffer` and the `user` pointer
// installed with it. That holds: the only caller is the fake camera's fill hook, installed in
// `serve_on_loopback` with `user` = the boxed closure that `FakeGigeCamera::fill` keeps alive,
// and uninstalled in `Drop` before that box is freed; aravis passes the frame's own buffer.
unsafe extern "C" fn fill_trampoline(
    buffer: *mut aravis_sys::ArvBuffer,
    user: *mut c_void,
    exposure_us: u32,
    _gain: u32,
    pixel_format: aravis_sys::ArvPixelFormat,
) {
    if buffer.is_null() || user.is_null() {
        return;
    }
    // SAFETY: `user` is the `Box<Box<FillFn>>` installed by `serve_on_loopback`, alive until the
    // closure is uninstalled in `Drop` (the fake camera holds its fill mutex while calling us).
    // `buffer` is the frame being filled; its data holds the payload sized from the format's
    // bits per pixel (`arv_buffer_get_data` reports size 0 inside the callback, so it is computed).
    unsafe {
        let fill = &*(user as *const Box<FillFn>);
        let width = u32::try_from(aravis_sys::arv_buffer_get_image_width(buffer)).unwrap_or(0);
        let height = u32::try_from(aravis_sys::arv_buffer_get_image_height(buffer)).unwrap_or(0);
        let mut reported = 0usize;
        let data = aravis_sys::arv_buffer_get_data(buffer, &mut reported);
        if data.is_null() {
            return;
        }
        let bits = ((pixel_format >> 16) & 0xff) as usize;
        let len = (width as usize * height as usize * bits).div_ceil(8);
        let data = std::slice::from_raw_parts_mut(data, len);
        let block_id = aravis_sys::arv_buffer_get_frame_id(buffer);
        let request = FillRequest {
            block_id,
            width,
            height,
            pixel_format,
            exposure_us,
            data,
        };
        // never unwind into C
        let _ = std::panic::catch_unwind(AssertUnwindSafe(|| fill(request)));
    }
}

fn serve_err(reason: impl std::fmt::Display) -> CameraError {
    CameraError::Open {
        device: "fake GigE camera on 127.0.0.1".to_owned(),
        reason: reason.to_string(),
    }
}

impl FakeGigeCamera {
    /// Starts the fake camera on `127.0.0.1` with `options`, filling frames with `fill` (or
    /// aravis' built-in pattern, which knows only its GenICam formats, when `None`).
    pub fn serve_on_loopback(
        options: &FakeGigeOptions,
        fill: Option<Box<FillFn>>,
    ) -> Result<Self, CameraError> {
        let server = GvFakeCamera::new(Some("127.0.0.1"), Some(&options.serial));
        if !server.is_running() {
            return Err(serve_err(
                "GvFakeCamera did not start (is UDP port 3956 on 127.0.0.1 taken, or lo down?)",
            ));
        }
        let camera = server
            .fake_camera()
            .ok_or_else(|| serve_err("GvFakeCamera has no FakeCamera"))?;
        for (address, value) in [
            (reg::SENSOR_WIDTH, options.sensor_width),
            (reg::SENSOR_HEIGHT, options.sensor_height),
            (reg::OFFSET_X, 0),
            (reg::OFFSET_Y, 0),
            (reg::WIDTH, options.width),
            (reg::HEIGHT, options.height),
            (reg::PIXEL_FORMAT, options.pixel_format),
        ] {
            if !camera.write_register(address, value) {
                return Err(serve_err(format!(
                    "register {address:#x} refused value {value:#x}"
                )));
            }
        }
        let mut fake = Self {
            server,
            camera,
            fill: None,
        };
        if let Some(f) = fill {
            let boxed: Box<Box<FillFn>> = Box::new(f);
            let user = &*boxed as *const Box<FillFn> as *mut c_void;
            let raw: *mut aravis_sys::ArvFakeCamera = fake.camera.to_glib_none().0;
            // SAFETY: `raw` is the live fake camera; `user` points into `boxed`, which `fake` owns
            // and frees only after `Drop` has uninstalled the callback.
            unsafe {
                aravis_sys::arv_fake_camera_set_fill_pattern(raw, Some(fill_trampoline), user);
            }
            fake.fill = Some(boxed);
        }
        Ok(fake)
    }

    /// Drops `ratio` (0..=1) of the GVSP packets at random.
    pub fn set_lost_ratio(&self, ratio: f64) {
        self.server.set_gvsp_lost_ratio(ratio.clamp(0.0, 1.0));
    }

    /// Reads a register of the fake camera.
    pub fn read_register(&self, address: u32) -> Option<u32> {
        self.camera.read_register(address)
    }
}

impl Drop for FakeGigeCamera {
    fn drop(&mut self) {
        if self.fill.is_some() {
            let raw: *mut aravis_sys::ArvFakeCamera = self.camera.to_glib_none().0;
            // SAFETY: restores the built-in pattern under the fake camera's fill mutex, so no
            // call into our closure is in flight or can start once this returns.
            unsafe {
                aravis_sys::arv_fake_camera_set_fill_pattern(raw, None, std::ptr::null_mut())
            };
        }
    }
}
