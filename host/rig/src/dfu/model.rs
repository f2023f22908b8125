//! A model of the STM32 DfuSe bootloader behind the [`DfuTransport`] boundary: the DFU 1.1
//! state machine with DfuSe's set-address and erase commands, flash that only programs erased
//! bytes, erase times reported as poll timeouts on a virtual clock, and injected faults — a
//! board that stops answering, a USB disconnect half-way through a download, a write error, a
//! silently corrupted write. Tests drive [`super::dfuse::DfuSe`] against it, and so can
//! `ellipso board flash --model`.
//!
//! Contract: the model follows AN3156 where the host could tell the difference; after
//! [`DfuSeModel::power_cycle`] it starts the application only when the flash holds a vector
//! table (initial stack pointer not erased), and otherwise comes up in the bootloader — the
//! behaviour the host's vector-table-last order relies on (on the F4 with an erased vector
//! table, the BOOT0 button brings the bootloader up).

use std::time::Duration;

use super::layout::{self, MemoryLayout};
use super::{
    DeviceIdentity, DfuState, DfuStatus, DfuTransport, FLASH_BASE, STM32_DFU_VID_PID,
    TransportError, request,
};

/// The STM32F411's flash as its bootloader describes it.
pub const STM32F411_LAYOUT: &str = "@Internal Flash  /0x08000000/04*016Kg,01*064Kg,03*128Kg";

/// The STM32 bootloader's transfer size, bytes.
pub const TRANSFER_SIZE: u16 = 2048;

/// A fault to inject.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// Every request after this many times out (the board hangs).
    StopAnsweringAfter(usize),
    /// The USB connection drops after this many data blocks were written (cable pulled).
    DisconnectAfterBlocks(usize),
    /// The write of the data block with this index (0 = the first written) fails with errPROG.
    WriteErrorAtBlock(usize),
    /// The byte at this flash address is programmed with one bit flipped, unreported.
    CorruptByteAt(u32),
}

/// What runs on the modelled board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Running {
    /// The DFU bootloader (ROM).
    Bootloader,
    /// The application in flash.
    Application,
    /// Nothing answers on USB (disconnected or hung).
    Gone,
}

/// The modelled device.
#[derive(Debug, Clone)]
pub struct DfuSeModel {
    identity: DeviceIdentity,
    layout: MemoryLayout,
    flash: Vec<u8>,
    state: DfuState,
    status: u8,
    pointer: u32,
    pending: Option<Pending>,
    busy_until_ms: u64,
    clock_ms: u64,
    running: Running,
    requests: usize,
    blocks_written: usize,
    faults: Vec<Fault>,
}

#[derive(Debug, Clone)]
enum Pending {
    Command(Vec<u8>),
    Write { address: u32, data: Vec<u8> },
    Leave,
}

/// Errors of DfuSe (status codes).
const ERR_TARGET: u8 = 0x01;
const ERR_PROG: u8 = 0x06;
const ERR_ADDRESS: u8 = 0x08;
const ERR_STALLED: u8 = 0x0f;

impl DfuSeModel {
    /// An STM32F411 in its bootloader with blank flash.
    pub fn stm32f411() -> Self {
        Self::with_identity(DeviceIdentity {
            vid: STM32_DFU_VID_PID.0,
            pid: STM32_DFU_VID_PID.1,
            layout: STM32F411_LAYOUT.into(),
            transfer_size: TRANSFER_SIZE,
            location: "model".into(),
        })
    }

    /// A device with another identity (a wrong device, another layout); a layout that does not
    /// parse gives the model a 1 KiB read-only region the host will refuse.
    pub fn with_identity(identity: DeviceIdentity) -> Self {
        let layout = layout::parse(&identity.layout)
            .unwrap_or_else(|_| layout::parse("@Other /0x00000000/1*1Ka").expect("fallback"));
        let size = (layout.end() - u64::from(layout.start())) as usize;
        Self {
            identity,
            layout,
            flash: vec![0xff; size],
            state: DfuState::DfuIdle,
            status: 0,
            pointer: FLASH_BASE,
            pending: None,
            busy_until_ms: 0,
            clock_ms: 0,
            running: Running::Bootloader,
            requests: 0,
            blocks_written: 0,
            faults: Vec::new(),
        }
    }

    /// Adds a fault.
    pub fn inject(&mut self, fault: Fault) -> &mut Self {
        self.faults.push(fault);
        self
    }

    /// What runs now.
    pub fn running(&self) -> Running {
        self.running
    }

    /// The flash's bytes from [`FLASH_BASE`].
    pub fn flash(&self) -> &[u8] {
        &self.flash
    }

    /// Virtual time spent, ms.
    pub fn clock_ms(&self) -> u64 {
        self.clock_ms
    }

    /// Power off and on (faults cleared): the application starts when the flash holds a vector
    /// table, the bootloader otherwise.
    pub fn power_cycle(&mut self) {
        self.faults.clear();
        self.requests = 0;
        self.blocks_written = 0;
        self.state = DfuState::DfuIdle;
        self.status = 0;
        self.pending = None;
        let sp = u32::from_le_bytes([self.flash[0], self.flash[1], self.flash[2], self.flash[3]]);
        self.running = if sp == 0xffff_ffff {
            Running::Bootloader
        } else {
            Running::Application
        };
    }

    /// The bootloader again (BOOT0 held at reset, or the app's reboot-to-DFU command).
    pub fn enter_bootloader(&mut self) {
        self.power_cycle();
        self.running = Running::Bootloader;
    }

    fn check_link(&mut self) -> Result<(), TransportError> {
        self.requests += 1;
        if self.running != Running::Bootloader {
            return Err(TransportError::Disconnected);
        }
        let hung = self
            .faults
            .iter()
            .any(|f| matches!(f, Fault::StopAnsweringAfter(n) if self.requests > *n));
        if hung {
            return Err(TransportError::Timeout(Duration::from_secs(5)));
        }
        Ok(())
    }

    fn fail(&mut self, status: u8) {
        self.state = DfuState::Error;
        self.status = status;
    }

    fn offset(&self, address: u32, len: usize) -> Option<usize> {
        let start = address.checked_sub(self.layout.start())? as usize;
        (start + len <= self.flash.len()).then_some(start)
    }

    /// Runs what a DNLOAD queued; returns the busy time, ms.
    fn execute(&mut self, p: Pending) -> Result<u64, u8> {
        match p {
            Pending::Command(c) if c.len() == 5 && (c[0] == 0x21 || c[0] == 0x41) => {
                let address = u32::from_le_bytes([c[1], c[2], c[3], c[4]]);
                let Some(sector) = self
                    .layout
                    .sectors
                    .iter()
                    .find(|s| (s.start..s.start.saturating_add(s.size)).contains(&address))
                    .copied()
                else {
                    return Err(ERR_ADDRESS);
                };
                if c[0] == 0x21 {
                    self.pointer = address;
                    return Ok(1);
                }
                let o = (sector.start - self.layout.start()) as usize;
                self.flash[o..o + sector.size as usize].fill(0xff);
                // erase time: about 8 ms per KiB (a 128 KiB sector in about 1 s)
                Ok(u64::from(sector.size / 1024) * 8)
            }
            Pending::Command(_) => Err(ERR_TARGET),
            Pending::Write { address, data } => {
                let index = self.blocks_written;
                self.blocks_written += 1;
                if self.faults.contains(&Fault::WriteErrorAtBlock(index)) {
                    return Err(ERR_PROG);
                }
                let Some(o) = self.offset(address, data.len()) else {
                    return Err(ERR_ADDRESS);
                };
                for (k, &b) in data.iter().enumerate() {
                    let mut b = b;
                    if self
                        .faults
                        .contains(&Fault::CorruptByteAt(address + k as u32))
                    {
                        b ^= 0x10;
                    }
                    // flash programs 1 → 0 only: writing unerased bytes fails
                    if self.flash[o + k] != 0xff && self.flash[o + k] != b {
                        return Err(ERR_PROG);
                    }
                    self.flash[o + k] = b;
                }
                Ok(2)
            }
            Pending::Leave => Ok(0),
        }
    }
}

impl DfuTransport for DfuSeModel {
    fn identity(&self) -> DeviceIdentity {
        self.identity.clone()
    }

    fn control_out(&mut self, req: u8, value: u16, data: &[u8]) -> Result<(), TransportError> {
        self.check_link()?;
        match req {
            request::DNLOAD => {
                if !matches!(self.state, DfuState::DfuIdle | DfuState::DnloadIdle) {
                    self.fail(ERR_STALLED);
                    return Err(TransportError::Stall);
                }
                self.pending = Some(match (value, data.is_empty()) {
                    (_, true) => Pending::Leave,
                    (0, false) => Pending::Command(data.to_vec()),
                    (1, false) => {
                        self.fail(ERR_STALLED);
                        return Err(TransportError::Stall);
                    }
                    (n, false) => Pending::Write {
                        address: self.pointer
                            + u32::from(n - 2) * u32::from(self.identity.transfer_size),
                        data: data.to_vec(),
                    },
                });
                self.state = if data.is_empty() {
                    DfuState::ManifestSync
                } else {
                    DfuState::DnloadSync
                };
                Ok(())
            }
            request::CLRSTATUS => {
                self.state = DfuState::DfuIdle;
                self.status = 0;
                Ok(())
            }
            request::ABORT => {
                if self.state != DfuState::Error {
                    self.state = DfuState::DfuIdle;
                }
                Ok(())
            }
            _ => {
                self.fail(ERR_STALLED);
                Err(TransportError::Stall)
            }
        }
    }

    fn control_in(&mut self, req: u8, value: u16, buf: &mut [u8]) -> Result<usize, TransportError> {
        self.check_link()?;
        match req {
            request::GETSTATUS => {
                let mut poll_ms = 0u64;
                match self.state {
                    DfuState::DnloadSync => {
                        let p = self.pending.take();
                        match p.map(|p| self.execute(p)) {
                            Some(Ok(ms)) => {
                                self.busy_until_ms = self.clock_ms + ms;
                                self.state = DfuState::DnBusy;
                                poll_ms = ms;
                            }
                            Some(Err(status)) => self.fail(status),
                            None => self.state = DfuState::DnloadIdle,
                        }
                    }
                    DfuState::DnBusy => {
                        if self.clock_ms >= self.busy_until_ms {
                            self.state = DfuState::DnloadIdle;
                        } else {
                            poll_ms = self.busy_until_ms - self.clock_ms;
                        }
                    }
                    DfuState::ManifestSync => {
                        // the bootloader jumps to the application at the pointer
                        self.pending = None;
                        self.state = DfuState::Manifest;
                        let answer = DfuStatus {
                            status: 0,
                            poll_timeout_ms: 0,
                            state: DfuState::Manifest as u8,
                        }
                        .to_bytes();
                        self.power_cycle();
                        let n = buf.len().min(6);
                        buf[..n].copy_from_slice(&answer[..n]);
                        return Ok(n);
                    }
                    _ => {}
                }
                let answer = DfuStatus {
                    status: self.status,
                    poll_timeout_ms: poll_ms as u32,
                    state: self.state as u8,
                }
                .to_bytes();
                let n = buf.len().min(6);
                buf[..n].copy_from_slice(&answer[..n]);
                Ok(n)
            }
            request::GETSTATE => {
                if let Some(b) = buf.first_mut() {
                    *b = self.state as u8;
                }
                Ok(buf.len().min(1))
            }
            request::UPLOAD if value >= 2 => {
                if !matches!(self.state, DfuState::DfuIdle | DfuState::UploadIdle) {
                    self.fail(ERR_STALLED);
                    return Err(TransportError::Stall);
                }
                let address =
                    self.pointer + u32::from(value - 2) * u32::from(self.identity.transfer_size);
                let Some(o) = self.offset(address, buf.len()) else {
                    self.fail(ERR_ADDRESS);
                    return Err(TransportError::Stall);
                };
                buf.copy_from_slice(&self.flash[o..o + buf.len()]);
                self.state = DfuState::UploadIdle;
                Ok(buf.len())
            }
            _ => {
                self.fail(ERR_STALLED);
                Err(TransportError::Stall)
            }
        }
    }

    fn wait(&mut self, d: Duration) {
        self.clock_ms += d.as_millis() as u64;
        // a cable pulled half-way: the drop happens while the host waits on a written block
        let limit = self.faults.iter().find_map(|f| match f {
            Fault::DisconnectAfterBlocks(n) => Some(*n),
            _ => None,
        });
        if limit.is_some_and(|n| self.blocks_written >= n) {
            self.running = Running::Gone;
        }
    }
}

impl DfuTransport for &mut DfuSeModel {
    fn identity(&self) -> DeviceIdentity {
        (**self).identity()
    }
    fn control_out(&mut self, req: u8, value: u16, data: &[u8]) -> Result<(), TransportError> {
        (**self).control_out(req, value, data)
    }
    fn control_in(&mut self, req: u8, value: u16, buf: &mut [u8]) -> Result<usize, TransportError> {
        (**self).control_in(req, value, buf)
    }
    fn wait(&mut self, d: Duration) {
        (**self).wait(d)
    }
}

#[cfg(test)]
mod tests;
