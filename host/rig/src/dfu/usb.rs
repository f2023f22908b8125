//! The DFU transport over real USB through `rusb` (libusb, built from the crate's bundled
//! source): finds the STM32 bootloader by its USB id, reads its DFU interface (alternate
//! setting 0, the internal flash) and functional descriptor, claims the interface and sends
//! class requests with a [`TRANSFER_TIMEOUT`].

use std::time::Duration;

use rusb::{Direction, Recipient, RequestType, UsbContext as _};

use super::{DeviceIdentity, DfuTransport, STM32_DFU_VID_PID, TransportError};

/// Longest one control transfer may take. Derivation: the bootloader answers each request at
/// once (erase and program run between status polls, announced by `bwPollTimeout`); 5 s leaves
/// room for a slow hub and is still short enough that a hung board is reported promptly.
pub const TRANSFER_TIMEOUT: Duration = Duration::from_secs(5);

/// Why no USB DFU device could be opened.
#[derive(Debug, thiserror::Error)]
pub enum UsbError {
    /// libusb failed.
    #[error("USB: {0}")]
    Usb(#[from] rusb::Error),
    /// No matching device.
    #[error(
        "no STM32 DFU bootloader ({vid:04x}:{pid:04x}) on USB{0}: connect the trigger board and \
         put it in DFU mode (`ellipso board flash --port PORT` asks it to reboot into DFU; or hold \
         BOOT0 while pressing reset)",
        vid = STM32_DFU_VID_PID.0,
        pid = STM32_DFU_VID_PID.1
    )]
    NotFound(String),
    /// The device has no DFU interface.
    #[error("{0} has no DFU interface in DFU mode")]
    NoDfuInterface(String),
}

/// An STM32 bootloader opened over USB.
pub struct UsbDfu {
    handle: rusb::DeviceHandle<rusb::Context>,
    interface: u8,
    identity: DeviceIdentity,
}

impl std::fmt::Debug for UsbDfu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UsbDfu")
            .field("identity", &self.identity)
            .finish_non_exhaustive()
    }
}

/// USB devices in DFU mode (interface class 0xFE, subclass 1, protocol 2): `(vid, pid,
/// "bus B address A")`.
pub fn list_dfu_devices() -> Result<Vec<(u16, u16, String)>, UsbError> {
    let mut out = Vec::new();
    // an own context: libusb's global one panics where USB is absent (a container)
    for device in rusb::Context::new()?.devices()?.iter() {
        let Ok(desc) = device.device_descriptor() else {
            continue;
        };
        let Ok(config) = device
            .active_config_descriptor()
            .or_else(|_| device.config_descriptor(0))
        else {
            continue;
        };
        let dfu = config.interfaces().any(|i| {
            i.descriptors().any(|d| {
                (d.class_code(), d.sub_class_code(), d.protocol_code()) == (0xfe, 0x01, 0x02)
            })
        });
        if dfu {
            out.push((
                desc.vendor_id(),
                desc.product_id(),
                format!("bus {} address {}", device.bus_number(), device.address()),
            ));
        }
    }
    Ok(out)
}

impl UsbDfu {
    /// Opens the first STM32 bootloader on USB.
    pub fn open_stm32() -> Result<Self, UsbError> {
        let devices = rusb::Context::new()?.devices()?;
        let mut seen = 0;
        for device in devices.iter() {
            seen += 1;
            let Ok(desc) = device.device_descriptor() else {
                continue;
            };
            if (desc.vendor_id(), desc.product_id()) != STM32_DFU_VID_PID {
                continue;
            }
            let location = format!("bus {} address {}", device.bus_number(), device.address());
            let config = device.config_descriptor(0)?;
            let handle = device.open()?;
            for iface in config.interfaces() {
                for d in iface.descriptors() {
                    if (
                        d.class_code(),
                        d.sub_class_code(),
                        d.protocol_code(),
                        d.setting_number(),
                    ) != (0xfe, 0x01, 0x02, 0)
                    {
                        continue;
                    }
                    let layout = d
                        .description_string_index()
                        .map(|i| handle.read_string_descriptor_ascii(i))
                        .transpose()?
                        .unwrap_or_default();
                    // DFU functional descriptor: bLength 9, type 0x21, attributes,
                    // wDetachTimeOut, wTransferSize, bcdDFUVersion
                    let extra = d.extra();
                    let transfer_size = if extra.len() >= 7 && extra[1] == 0x21 {
                        u16::from_le_bytes([extra[5], extra[6]])
                    } else {
                        2048
                    };
                    let interface = d.interface_number();
                    // the kernel has no driver on a DFU interface; detach is best effort
                    let _ = handle.set_auto_detach_kernel_driver(true);
                    handle.claim_interface(interface)?;
                    handle.set_alternate_setting(interface, 0)?;
                    return Ok(Self {
                        handle,
                        interface,
                        identity: DeviceIdentity {
                            vid: desc.vendor_id(),
                            pid: desc.product_id(),
                            layout,
                            transfer_size,
                            location,
                        },
                    });
                }
            }
            return Err(UsbError::NoDfuInterface(location));
        }
        Err(UsbError::NotFound(format!(" (of {seen} USB devices)")))
    }

    /// Waits up to `timeout` for an STM32 bootloader to appear (after a reboot into DFU).
    pub fn wait_for_stm32(timeout: Duration) -> Result<Self, UsbError> {
        let start = std::time::Instant::now();
        loop {
            match Self::open_stm32() {
                Err(UsbError::NotFound(_)) if start.elapsed() < timeout => {
                    std::thread::sleep(Duration::from_millis(200));
                }
                other => return other,
            }
        }
    }
}

fn transport_error(e: rusb::Error) -> TransportError {
    match e {
        rusb::Error::Timeout => TransportError::Timeout(TRANSFER_TIMEOUT),
        rusb::Error::NoDevice => TransportError::Disconnected,
        rusb::Error::Pipe => TransportError::Stall,
        other => TransportError::Other(other.to_string()),
    }
}

impl DfuTransport for UsbDfu {
    fn identity(&self) -> DeviceIdentity {
        self.identity.clone()
    }

    fn control_out(&mut self, request: u8, value: u16, data: &[u8]) -> Result<(), TransportError> {
        let t = rusb::request_type(Direction::Out, RequestType::Class, Recipient::Interface);
        self.handle
            .write_control(
                t,
                request,
                value,
                u16::from(self.interface),
                data,
                TRANSFER_TIMEOUT,
            )
            .map(|_| ())
            .map_err(transport_error)
    }

    fn control_in(
        &mut self,
        request: u8,
        value: u16,
        buf: &mut [u8],
    ) -> Result<usize, TransportError> {
        let t = rusb::request_type(Direction::In, RequestType::Class, Recipient::Interface);
        self.handle
            .read_control(
                t,
                request,
                value,
                u16::from(self.interface),
                buf,
                TRANSFER_TIMEOUT,
            )
            .map_err(transport_error)
    }

    fn wait(&mut self, d: Duration) {
        std::thread::sleep(d);
    }
}
