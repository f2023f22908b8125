//! Applying settings to an [`AravisCamera`]: region, packet size and frame rate on open; pixel
//! format, binning/decimation and trigger on `configure`.
//!
//! Contract: every setting that would break the 2×2 polariser mosaic is refused with a
//! [`CameraError::Setting`] naming it (odd region, binning or decimation ≠ 1 that the camera will
//! not reset, camera-processed polarisation formats); the pixel format is read back as a PFNC
//! code (never through `pixel_format_as_string`, which panics in glib on formats missing from
//! the GenICam enumeration); the trigger is set in GenICam order (selector, mode, source).

use aravis::prelude::*;

use super::{AravisCamera, format};
use crate::camera::CameraError;
use crate::camera::unpack::{RawEncoding, check_mosaic_factor, check_mosaic_region};

impl AravisCamera {
    /// Region, packet size and frame rate from the options; binning/decimation forced to 1×1.
    pub(super) fn apply_geometry(&mut self) -> Result<(), CameraError> {
        if let Some((x, y, w, h)) = self.options.region {
            check_mosaic_region(x, y, w, h).map_err(|r| self.setting_err("region", r))?;
            let to_i32 = |v: u32| i32::try_from(v).unwrap_or(i32::MAX);
            self.camera
                .set_region(to_i32(x), to_i32(y), to_i32(w), to_i32(h))
                .map_err(|e| self.setting_err("region", e))?;
        }
        let (x, y, w, h) = self
            .camera
            .region()
            .map_err(|e| self.setting_err("region", e))?;
        let as_u32 = |v: i32| u32::try_from(v).unwrap_or(u32::MAX);
        check_mosaic_region(as_u32(x), as_u32(y), as_u32(w), as_u32(h))
            .map_err(|r| self.setting_err("region", r))?;
        self.force_unit_factor("binning", "BinningHorizontal", "BinningVertical")?;
        self.force_unit_factor("decimation", "DecimationHorizontal", "DecimationVertical")?;
        if self.camera.is_gv_device() {
            if let Some(size) = self.options.packet_size_bytes {
                let size = i32::try_from(size).unwrap_or(i32::MAX);
                self.camera
                    .gv_set_packet_size(size)
                    .map_err(|e| self.setting_err("packet size", e))?;
            }
            let granted = self.camera.gv_get_packet_size().unwrap_or(0);
            tracing::info!(camera = %self.address, packet_size_bytes = granted, "GVSP packet size granted");
        }
        if let Some(fps) = self.options.frame_rate_hz {
            self.camera
                .set_frame_rate(fps)
                .map_err(|e| self.setting_err("frame rate", e))?;
        }
        Ok(())
    }

    /// Sets a binning/decimation pair to 1×1 where the camera has it; refuses if it stays ≠ 1.
    pub(super) fn force_unit_factor(
        &self,
        what: &'static str,
        horizontal: &str,
        vertical: &str,
    ) -> Result<(), CameraError> {
        for feature in [horizontal, vertical] {
            if self.has(feature) && self.camera.integer(feature).unwrap_or(1) != 1 {
                self.camera
                    .set_integer(feature, 1)
                    .map_err(|e| self.setting_err(what, e))?;
            }
        }
        let read = |f: &str| {
            if self.has(f) {
                self.camera.integer(f).unwrap_or(1)
            } else {
                1
            }
        };
        check_mosaic_factor(what, read(horizontal), read(vertical))
            .map_err(|r| self.setting_err(what, r))
    }

    /// The encoding of the camera's current pixel format, read as a PFNC code (never through
    /// `pixel_format_as_string`, which panics on formats missing from the GenICam enumeration).
    pub(super) fn current_encoding(&self) -> Result<RawEncoding, CameraError> {
        let code = self
            .camera
            .pixel_format()
            .map_err(|e| self.setting_err("pixel format", e))?
            .raw();
        format::encoding_of_pfnc(code).ok_or_else(|| {
            self.setting_err(
                "pixel format",
                format!("current pixel format {code:#010x} is not a raw mono/mosaic format"),
            )
        })
    }

    /// Chooses a raw-mosaic pixel format with `bit_depth` significant bits.
    pub(super) fn select_pixel_format(&mut self, bit_depth: u8) -> Result<(), CameraError> {
        if let Ok(enc) = self.current_encoding()
            && enc.bit_depth() == bit_depth
        {
            self.encoding = enc;
            return Ok(());
        }
        let offered: Vec<String> = self
            .camera
            .dup_available_pixel_formats_as_strings()
            .map(|v| v.iter().map(|s| s.to_string()).collect())
            .unwrap_or_default();
        let Some(name) = format::preferred_names(bit_depth)
            .iter()
            .find(|n| offered.iter().any(|o| o == *n))
        else {
            let refused: Vec<String> = offered
                .iter()
                .filter_map(|o| format::refused_name(o))
                .collect();
            return Err(self.setting_err(
                "pixel format",
                format!(
                    "no raw {bit_depth}-bit mono/mosaic format among {offered:?}{}",
                    if refused.is_empty() {
                        String::new()
                    } else {
                        format!(" ({})", refused.join("; "))
                    }
                ),
            ));
        };
        self.camera
            .set_pixel_format_from_string(name)
            .map_err(|e| self.setting_err("pixel format", e))?;
        self.encoding = self.current_encoding()?;
        Ok(())
    }

    /// Free-running, or exposure on the external trigger line `Line0`.
    pub(super) fn set_trigger(&self, external: bool) -> Result<(), CameraError> {
        let has_mode = self.has("TriggerMode");
        if self.has("TriggerSelector") {
            self.camera
                .set_string("TriggerSelector", "FrameStart")
                .map_err(|e| self.setting_err("trigger", e))?;
        }
        if !external {
            if has_mode {
                self.camera
                    .set_string("TriggerMode", "Off")
                    .map_err(|e| self.setting_err("trigger", e))?;
            }
            return Ok(());
        }
        if !has_mode || !self.has("TriggerSource") {
            return Err(self.setting_err(
                "external trigger",
                "the camera has no TriggerMode/TriggerSource features",
            ));
        }
        let sources: Vec<String> = self
            .camera
            .dup_available_enumerations_as_strings("TriggerSource")
            .map(|v| v.iter().map(|s| s.to_string()).collect())
            .unwrap_or_default();
        if !sources.iter().any(|s| s == "Line0") {
            return Err(self.setting_err(
                "external trigger",
                format!("TriggerSource has no Line0 (offered: {sources:?})"),
            ));
        }
        self.camera
            .set_string("TriggerMode", "On")
            .and_then(|()| self.camera.set_string("TriggerSource", "Line0"))
            .map_err(|e| self.setting_err("external trigger", e))
    }
}
