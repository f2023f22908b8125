//! The host side of STM32 DfuSe: image checks, erase, download (vector table last), read-back
//! verify, and leave (start the new firmware), over any [`DfuTransport`].
//!
//! Contract: [`DfuSe::flash`] either returns with the whole image written, read back equal and
//! the bootloader asked to start it, or returns a [`DfuError`] having sent no leave request —
//! the board is still in its DFU bootloader (see the safety contract in [`super`]). Every
//! status poll honours the device's `bwPollTimeout`; one operation may keep the device busy for
//! at most [`MAX_BUSY`].

use std::time::Duration;

use super::layout::{self, MemoryLayout};
use super::{
    DeviceIdentity, DfuState, DfuStatus, DfuTransport, FLASH_BASE, STM32_DFU_VID_PID,
    TransportError, request, status_name,
};

/// Longest one operation may keep the device busy. Derivation: the slowest operation is the
/// erase of a 128 KiB sector, 1–2 s typical and 4 s at most on the STM32F4 (datasheet, flash
/// erase time at ×8 parallelism); 2.5 × that worst case.
pub const MAX_BUSY: Duration = Duration::from_secs(10);

/// Most GETSTATUS polls for one operation: a device answering busy with a poll timeout of 0
/// would otherwise be polled forever.
const MAX_POLLS: u32 = 10_000;

/// SRAM of the STM32F4 family: an image's initial stack pointer must lie in it.
const SRAM: std::ops::RangeInclusive<u32> = 0x2000_0000..=0x2005_0000;

/// DfuSe commands (AN3156 §6): the first byte of a block-0 download.
const CMD_SET_ADDRESS: u8 = 0x21;
const CMD_ERASE: u8 = 0x41;

/// Why a flash did not complete.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DfuError {
    /// The USB device is not an STM32 DFU bootloader with internal flash at 0x08000000.
    #[error("{found} is not the trigger board's STM32 DFU bootloader: {why}")]
    WrongDevice {
        /// The device, as found.
        found: String,
        /// What does not match.
        why: String,
    },
    /// The file is not a firmware image for this board.
    #[error("not a firmware image for the trigger board: {0}")]
    Image(String),
    /// The layout string does not parse.
    #[error(transparent)]
    Layout(#[from] layout::LayoutError),
    /// A USB transfer failed (timeout, disconnect, stall).
    #[error("the board stopped answering while {during}: {source}")]
    NotAnswering {
        /// What was being done.
        during: String,
        /// The transport's error.
        source: TransportError,
    },
    /// The device reported an error status.
    #[error("the bootloader reported {} while {during}", status_name(*status))]
    Device {
        /// What was being done.
        during: String,
        /// DFU status code.
        status: u8,
    },
    /// The device stayed busy too long.
    #[error("the bootloader stayed busy for more than {} s while {during}", MAX_BUSY.as_secs())]
    Busy {
        /// What was being done.
        during: String,
    },
    /// The device went into a state the protocol does not allow here.
    #[error("the bootloader went into state {state} while {during}")]
    UnexpectedState {
        /// What was being done.
        during: String,
        /// The state byte.
        state: u8,
    },
    /// The image read back differs from the file.
    #[error(
        "verify failed: byte at 0x{address:08x} reads 0x{found:02x}, the file has 0x{expected:02x}"
    )]
    Verify {
        /// First differing address.
        address: u32,
        /// The file's byte.
        expected: u8,
        /// The board's byte.
        found: u8,
    },
}

/// Phases [`DfuSe::flash`] reports progress in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Erasing sectors.
    Erase,
    /// Writing blocks.
    Write,
    /// Reading back.
    Verify,
}

/// What a completed flash did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FlashReport {
    /// Bytes written and verified.
    pub bytes: usize,
    /// Sectors erased.
    pub sectors_erased: usize,
    /// Transfer blocks written.
    pub blocks: usize,
}

/// A DfuSe session with one device.
pub struct DfuSe<T: DfuTransport> {
    transport: T,
    identity: DeviceIdentity,
    layout: MemoryLayout,
}

impl<T: DfuTransport> DfuSe<T> {
    /// Opens a session: checks the device is an STM32 bootloader whose interface is the
    /// internal flash at [`FLASH_BASE`].
    pub fn new(transport: T) -> Result<Self, DfuError> {
        let identity = transport.identity();
        let found = format!(
            "USB device {:04x}:{:04x} at {}",
            identity.vid, identity.pid, identity.location
        );
        if (identity.vid, identity.pid) != STM32_DFU_VID_PID {
            return Err(DfuError::WrongDevice {
                found,
                why: format!(
                    "expected {:04x}:{:04x} (STM32 BOOTLOADER)",
                    STM32_DFU_VID_PID.0, STM32_DFU_VID_PID.1
                ),
            });
        }
        let layout = layout::parse(&identity.layout)?;
        if !layout.name.eq_ignore_ascii_case("Internal Flash") || layout.start() != FLASH_BASE {
            return Err(DfuError::WrongDevice {
                found,
                why: format!(
                    "its DFU interface is '{}', not the internal flash at 0x{FLASH_BASE:08x}",
                    identity.layout
                ),
            });
        }
        if identity.transfer_size == 0 {
            return Err(DfuError::WrongDevice {
                found,
                why: "it announces a transfer size of 0 bytes".into(),
            });
        }
        Ok(Self {
            transport,
            identity,
            layout,
        })
    }

    /// The device's identity.
    pub fn identity(&self) -> &DeviceIdentity {
        &self.identity
    }

    /// The transport (tests inspect the model through it).
    pub fn into_transport(self) -> T {
        self.transport
    }

    /// Checks that `image` is a firmware image for this device: fits the flash, and its vector
    /// table's initial stack pointer lies in SRAM and its reset vector (a Thumb address) inside
    /// the image.
    pub fn check_image(&self, image: &[u8]) -> Result<(), DfuError> {
        if image.len() < 8 {
            return Err(DfuError::Image(format!(
                "{} bytes, shorter than a vector table",
                image.len()
            )));
        }
        let capacity = self.layout.end() - u64::from(FLASH_BASE);
        if image.len() as u64 > capacity {
            return Err(DfuError::Image(format!(
                "{} bytes do not fit the board's {capacity} bytes of flash",
                image.len()
            )));
        }
        let word =
            |k: usize| u32::from_le_bytes([image[k], image[k + 1], image[k + 2], image[k + 3]]);
        let (sp, reset) = (word(0), word(4));
        if !SRAM.contains(&sp) {
            return Err(DfuError::Image(format!(
                "its initial stack pointer 0x{sp:08x} is not in SRAM (0x{:08x}..0x{:08x}): not a \
                 raw binary linked for 0x{FLASH_BASE:08x} (an ELF or hex file, or corrupt?)",
                SRAM.start(),
                SRAM.end()
            )));
        }
        let end = FLASH_BASE as u64 + image.len() as u64;
        if reset & 1 == 0 || !(u64::from(FLASH_BASE)..end).contains(&u64::from(reset & !1)) {
            return Err(DfuError::Image(format!(
                "its reset vector 0x{reset:08x} does not point into the image \
                 (0x{FLASH_BASE:08x}..0x{end:08x}) as a Thumb address"
            )));
        }
        Ok(())
    }

    fn status(&mut self, during: &str) -> Result<DfuStatus, DfuError> {
        let mut buf = [0u8; 6];
        let n = self
            .transport
            .control_in(request::GETSTATUS, 0, &mut buf)
            .map_err(|source| DfuError::NotAnswering {
                during: during.into(),
                source,
            })?;
        DfuStatus::parse(&buf[..n]).ok_or_else(|| DfuError::NotAnswering {
            during: during.into(),
            source: TransportError::Other(format!("GETSTATUS answered {n} bytes, not 6")),
        })
    }

    fn out(&mut self, req: u8, value: u16, data: &[u8], during: &str) -> Result<(), DfuError> {
        self.transport
            .control_out(req, value, data)
            .map_err(|source| DfuError::NotAnswering {
                during: during.into(),
                source,
            })
    }

    /// Polls GETSTATUS until the device reaches `want`, honouring its poll timeouts.
    fn poll_until(&mut self, want: DfuState, during: &str) -> Result<(), DfuError> {
        let mut busy = Duration::ZERO;
        for _ in 0..MAX_POLLS {
            let st = self.status(during)?;
            if st.status != 0 {
                // back to dfuIDLE so the next attempt starts clean; the error is what counts
                let _ = self.transport.control_out(request::CLRSTATUS, 0, &[]);
                return Err(DfuError::Device {
                    during: during.into(),
                    status: st.status,
                });
            }
            match DfuState::from_byte(st.state) {
                Some(s) if s == want => return Ok(()),
                Some(DfuState::DnBusy | DfuState::DnloadSync | DfuState::ManifestSync) => {
                    let d = Duration::from_millis(u64::from(st.poll_timeout_ms));
                    busy += d;
                    if busy > MAX_BUSY {
                        return Err(DfuError::Busy {
                            during: during.into(),
                        });
                    }
                    self.transport.wait(d);
                }
                _ => {
                    return Err(DfuError::UnexpectedState {
                        during: during.into(),
                        state: st.state,
                    });
                }
            }
        }
        Err(DfuError::Busy {
            during: during.into(),
        })
    }

    /// Brings the device to dfuIDLE from wherever a previous session left it.
    fn back_to_idle(&mut self) -> Result<(), DfuError> {
        let during = "asking the bootloader's state";
        let st = self.status(during)?;
        if st.state == DfuState::Error as u8 {
            self.out(request::CLRSTATUS, 0, &[], during)?;
        } else if st.state != DfuState::DfuIdle as u8 {
            self.out(request::ABORT, 0, &[], during)?;
        }
        let st = self.status(during)?;
        if st.state != DfuState::DfuIdle as u8 {
            return Err(DfuError::UnexpectedState {
                during: during.into(),
                state: st.state,
            });
        }
        Ok(())
    }

    fn command(&mut self, cmd: u8, address: u32, during: &str) -> Result<(), DfuError> {
        let mut data = [0u8; 5];
        data[0] = cmd;
        data[1..].copy_from_slice(&address.to_le_bytes());
        self.out(request::DNLOAD, 0, &data, during)?;
        self.poll_until(DfuState::DnloadIdle, during)
    }

    /// Erases, writes (vector table last), verifies and, when all that succeeded, starts
    /// `image`. `progress(phase, done, total)` is called as the work goes.
    pub fn flash(
        &mut self,
        image: &[u8],
        progress: &mut dyn FnMut(Phase, usize, usize),
    ) -> Result<FlashReport, DfuError> {
        self.check_image(image)?;
        self.back_to_idle()?;
        let sectors = self.layout.sectors_for(FLASH_BASE, image.len() as u32);
        if let Some(s) = sectors.iter().find(|s| !s.writable) {
            return Err(DfuError::WrongDevice {
                found: self.identity.location.clone(),
                why: format!("its flash sector at 0x{:08x} is not writable", s.start),
            });
        }
        for (k, s) in sectors.iter().enumerate() {
            progress(Phase::Erase, k, sectors.len());
            self.command(
                CMD_ERASE,
                s.start,
                &format!("erasing the sector at 0x{:08x}", s.start),
            )?;
        }
        progress(Phase::Erase, sectors.len(), sectors.len());
        let size = usize::from(self.identity.transfer_size);
        let blocks: Vec<&[u8]> = image.chunks(size).collect();
        // the vector table (block 0) last: until then no partial image can boot
        let order: Vec<usize> = (1..blocks.len()).chain([0]).collect();
        for (done, &k) in order.iter().enumerate() {
            progress(Phase::Write, done, blocks.len());
            let address = FLASH_BASE + (k * size) as u32;
            let during = format!("writing block {k} at 0x{address:08x}");
            self.command(CMD_SET_ADDRESS, address, &during)?;
            // block number 2 addresses the pointer itself (AN3156 §6.2)
            self.out(request::DNLOAD, 2, blocks[k], &during)?;
            self.poll_until(DfuState::DnloadIdle, &during)?;
        }
        progress(Phase::Write, blocks.len(), blocks.len());
        self.verify(image, size, progress)?;
        // leave: pointer at the image, a zero-length download, then the manifestation
        let during = "starting the new firmware";
        self.command(CMD_SET_ADDRESS, FLASH_BASE, during)?;
        self.out(request::DNLOAD, 2, &[], during)?;
        // the device resets while manifesting: a failed status here is the reset, not an error
        let _ = self.status(during);
        Ok(FlashReport {
            bytes: image.len(),
            sectors_erased: sectors.len(),
            blocks: blocks.len(),
        })
    }

    fn verify(
        &mut self,
        image: &[u8],
        size: usize,
        progress: &mut dyn FnMut(Phase, usize, usize),
    ) -> Result<(), DfuError> {
        let during = "reading the image back";
        self.command(CMD_SET_ADDRESS, FLASH_BASE, during)?;
        self.out(request::ABORT, 0, &[], during)?;
        let blocks = image.len().div_ceil(size);
        let mut buf = vec![0u8; size];
        for k in 0..blocks {
            progress(Phase::Verify, k, blocks);
            let want = &image[k * size..((k + 1) * size).min(image.len())];
            let n = self
                .transport
                .control_in(request::UPLOAD, (k + 2) as u16, &mut buf[..want.len()])
                .map_err(|source| DfuError::NotAnswering {
                    during: during.into(),
                    source,
                })?;
            if let Some(i) = (0..want.len()).find(|&i| i >= n || buf[i] != want[i]) {
                return Err(DfuError::Verify {
                    address: FLASH_BASE + (k * size + i) as u32,
                    expected: want[i],
                    found: if i < n { buf[i] } else { 0xff },
                });
            }
        }
        progress(Phase::Verify, blocks, blocks);
        self.out(request::ABORT, 0, &[], during)
    }
}
