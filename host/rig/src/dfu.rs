//! Firmware updates over USB: the STM32 DfuSe bootloader protocol (ST's AN3156 extension of USB
//! DFU 1.1), spoken through a [`DfuTransport`] — the USB device through `rusb` ([`usb`]), or
//! the device model the tests drive ([`model`]).
//!
//! - [`dfuse`]: the host side: status polling, erase, download, read-back verify, leave.
//! - [`layout`]: the bootloader's memory description (`@Internal Flash /0x08000000/04*016Kg,…`).
//! - [`model`]: a DfuSe device model with fault injection (tests, and `board flash --model`).
//! - [`usb`]: the `rusb` transport: finds the bootloader by its USB id and claims its interface.
//!
//! Safety contract ("never bricked"): the STM32's DFU bootloader lives in ROM, so nothing the
//! host sends can erase it. What could leave a board that does not boot is a half-written
//! application that the bootloader then starts. So the download writes the first transfer block
//! (the vector table) **last**: until every other block is written, the vector table is erased
//! and no partial image can run. The host asks the bootloader to leave (start the new
//! firmware) only after the whole image read back equal to the file; on any error it stops with
//! the board still in DFU mode, where the next `board flash` starts over.

pub mod dfuse;
pub mod layout;
pub mod model;
pub mod usb;

use std::time::Duration;

/// DFU class requests (USB DFU 1.1, table 3.2).
pub mod request {
    /// Leave the application for the bootloader (run-time mode).
    pub const DETACH: u8 = 0;
    /// Host → device block (DfuSe: block 0 carries commands, blocks ≥ 2 data).
    pub const DNLOAD: u8 = 1;
    /// Device → host block.
    pub const UPLOAD: u8 = 2;
    /// Status, poll timeout and state.
    pub const GETSTATUS: u8 = 3;
    /// Clears an error status (dfuERROR → dfuIDLE).
    pub const CLRSTATUS: u8 = 4;
    /// State alone.
    pub const GETSTATE: u8 = 5;
    /// Back to dfuIDLE.
    pub const ABORT: u8 = 6;
}

/// The STM32 system bootloader's USB id (vendor ST, product "STM32 BOOTLOADER").
pub const STM32_DFU_VID_PID: (u16, u16) = (0x0483, 0xdf11);

/// Where the trigger board's firmware is linked: the start of the STM32's internal flash.
pub const FLASH_BASE: u32 = 0x0800_0000;

/// DFU device states (USB DFU 1.1, §6.1.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)]
pub enum DfuState {
    AppIdle = 0,
    AppDetach = 1,
    DfuIdle = 2,
    DnloadSync = 3,
    DnBusy = 4,
    DnloadIdle = 5,
    ManifestSync = 6,
    Manifest = 7,
    ManifestWaitReset = 8,
    UploadIdle = 9,
    Error = 10,
}

impl DfuState {
    /// The state a status byte names.
    pub fn from_byte(b: u8) -> Option<Self> {
        use DfuState::*;
        [
            AppIdle,
            AppDetach,
            DfuIdle,
            DnloadSync,
            DnBusy,
            DnloadIdle,
            ManifestSync,
            Manifest,
            ManifestWaitReset,
            UploadIdle,
            Error,
        ]
        .get(b as usize)
        .copied()
    }
}

/// DFU status codes (USB DFU 1.1, §6.1.2), by number.
pub fn status_name(status: u8) -> &'static str {
    match status {
        0x00 => "OK",
        0x01 => "errTARGET (file not for this device)",
        0x02 => "errFILE (file failed a verification)",
        0x03 => "errWRITE (cannot write memory)",
        0x04 => "errERASE (memory erase failed)",
        0x05 => "errCHECK_ERASED (erase check failed)",
        0x06 => "errPROG (program memory failed)",
        0x07 => "errVERIFY (programmed memory failed verification)",
        0x08 => "errADDRESS (address out of range)",
        0x09 => "errNOTDONE (download ended early)",
        0x0a => "errFIRMWARE (firmware corrupt)",
        0x0b => "errVENDOR",
        0x0c => "errUSBR (unexpected USB reset)",
        0x0d => "errPOR (unexpected power-on reset)",
        0x0e => "errUNKNOWN",
        0x0f => "errSTALLEDPKT (unexpected request)",
        _ => "unknown status",
    }
}

/// The answer to GETSTATUS.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DfuStatus {
    /// Status code (0 = OK).
    pub status: u8,
    /// How long the host must wait before the next GETSTATUS, ms.
    pub poll_timeout_ms: u32,
    /// State the device enters.
    pub state: u8,
}

impl DfuStatus {
    /// Parses the 6-byte GETSTATUS payload.
    pub fn parse(b: &[u8]) -> Option<Self> {
        (b.len() >= 6).then(|| Self {
            status: b[0],
            poll_timeout_ms: u32::from_le_bytes([b[1], b[2], b[3], 0]),
            state: b[4],
        })
    }

    /// The 6-byte GETSTATUS payload.
    pub fn to_bytes(self) -> [u8; 6] {
        let t = self.poll_timeout_ms.to_le_bytes();
        [self.status, t[0], t[1], t[2], self.state, 0]
    }
}

/// What a transport reports about the device it talks to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceIdentity {
    /// USB vendor id.
    pub vid: u16,
    /// USB product id.
    pub pid: u16,
    /// The DFU interface's alternate-setting string (DfuSe memory layout).
    pub layout: String,
    /// Largest block the device takes per DNLOAD/UPLOAD (DFU functional descriptor), bytes.
    pub transfer_size: u16,
    /// Where the device was found (bus and address, or "model").
    pub location: String,
}

/// Why a USB control transfer failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TransportError {
    /// No answer within the transfer timeout.
    #[error("no answer within {0:?}")]
    Timeout(Duration),
    /// The device went away (unplugged, reset).
    #[error("the device disconnected")]
    Disconnected,
    /// The device stalled the request (it refuses it in its current state).
    #[error("the device stalled the request")]
    Stall,
    /// Anything else the USB stack reports.
    #[error("{0}")]
    Other(String),
}

/// A DFU interface's class requests: what [`dfuse::DfuSe`] needs from USB.
pub trait DfuTransport {
    /// The device's identity and memory layout.
    fn identity(&self) -> DeviceIdentity;
    /// A class request with data to the device (`bmRequestType` 0x21, to the DFU interface).
    fn control_out(&mut self, request: u8, value: u16, data: &[u8]) -> Result<(), TransportError>;
    /// A class request with data from the device (`bmRequestType` 0xA1); bytes read.
    fn control_in(
        &mut self,
        request: u8,
        value: u16,
        buf: &mut [u8],
    ) -> Result<usize, TransportError>;
    /// Waits `d` (the device's poll timeout); the model advances its clock instead of sleeping.
    fn wait(&mut self, d: Duration);
}
