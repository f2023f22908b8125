//! The host end of the trigger link: version handshake, commands, the pulse event stream, clock sync.
//!
//! Contract:
//! - A [`TriggerLink`] owns one byte stream to the trigger board (a serial port — USB CDC-ACM on the
//!   rig, a pseudo-terminal in tests — or a unix socket to an emulator) and one reader thread that
//!   decodes every frame the board sends. Bad frames are counted per kind in [`LinkStats`] and
//!   skipped; one never ends the link.
//! - [`TriggerLink::connect`] performs the `Hello` handshake and refuses a board that speaks another
//!   protocol version, naming both versions.
//! - Commands are request/response with a timeout; a refusal comes back as
//!   [`LinkError::Rejected`] with the board's typed reason. A command whose frame or reply was
//!   lost on a noisy link is sent again up to [`LinkConfig::retries`] times when repeating it is
//!   harmless: `Configure`, `Arm`, `Stop` and `StatusRequest` are idempotent on the board, and a
//!   repeated `Start` that finds the capture already running (`Busy`) or already finished
//!   (`NotArmed`) means the first one took. `FireOne` is never repeated (it would fire twice).
//! - Pulse events, faults, edges and unsolicited status arrive on [`TriggerLink::events`], each
//!   stamped with the host time its frame was decoded ([`HostTimeUs`](time::HostTimeUs)).
//! - When the stream ends or fails, the reader sends one [`LinkEvent::Disconnected`] and stops;
//!   every later command fails with [`LinkError::Disconnected`]. Nothing received before is lost.
//!
//! Here: the link's settings and [`TriggerLink`] (open, handshake, commands, clock sync); the
//! reader thread, its events and counters are in `reader`, the errors in `error`, the clock
//! model in [`clock`].

pub mod clock;
mod error;
mod reader;
/// Host and device time types (they are part of the session contract).
pub use ellipso_session::time;

use std::io::{Read, Write};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use crossbeam_channel::{Receiver, RecvTimeoutError};
use ellipso_protocol::{
    BoardInfo, BoardMessage, CaptureConfig, CommandKind, HostMessage, MAX_FRAME_LEN,
    PROTOCOL_VERSION, RejectReason, Status, encode,
};

pub use error::{LinkError, describe_reject};
pub use reader::{LinkEvent, LinkStats};

use clock::{ClockModel, ClockModelConfig, ClockSample};
use reader::{Reply, reader_loop};
use time::{DeviceTimeUs, HostClock};

pub use ellipso_session::link_counters::LinkCounters;

/// How many times the requested pings [`TriggerLink::sync_clock`] may send again while the clock
/// fit has too few usable samples (round trips too long on a loaded host are rejected).
pub const SYNC_EXTRA_PING_FACTOR: usize = 4;

/// Settings of a link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkConfig {
    /// How long a command waits for its reply.
    pub reply_timeout: Duration,
    /// Clock-model settings.
    pub clock: ClockModelConfig,
    /// Extra attempts of an idempotent command after a timeout.
    pub retries: u32,
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            reply_timeout: Duration::from_millis(1_000),
            clock: ClockModelConfig::default(),
            retries: 3,
        }
    }
}

/// An open, handshaken link to a trigger board.
pub struct TriggerLink {
    writer: Mutex<Box<dyn Write + Send>>,
    replies: Receiver<Reply>,
    events: Receiver<LinkEvent>,
    stats: Arc<LinkStats>,
    connected: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    reader: Option<JoinHandle<()>>,
    clock: HostClock,
    clock_model: Mutex<ClockModel>,
    next_nonce: AtomicU64,
    info: BoardInfo,
    config: LinkConfig,
}

impl std::fmt::Debug for TriggerLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TriggerLink")
            .field("board", &self.info.board_name)
            .finish_non_exhaustive()
    }
}

impl TriggerLink {
    /// Opens `path` — a serial device or pty (e.g. `/dev/ttyACM0`, `/dev/pts/5`), or
    /// `unix:PATH` for an emulator's socket — and performs the handshake.
    pub fn open(path: &str, clock: HostClock, config: LinkConfig) -> Result<Self, LinkError> {
        let open_err = |reason: String| LinkError::Open {
            path: path.to_string(),
            reason,
        };
        if let Some(sock) = path.strip_prefix("unix:") {
            let stream = std::os::unix::net::UnixStream::connect(Path::new(sock))
                .map_err(|e| open_err(e.to_string()))?;
            stream
                .set_read_timeout(Some(Duration::from_millis(50)))
                .map_err(|e| open_err(e.to_string()))?;
            let reader = stream.try_clone().map_err(|e| open_err(e.to_string()))?;
            return Self::connect(Box::new(reader), Box::new(stream), clock, config);
        }
        let port = serialport::new(path, 115_200)
            .timeout(Duration::from_millis(50))
            .open_native()
            .map_err(|e| open_err(e.to_string()))?;
        // drop what the board sent while nobody was reading (a previous capture's pulses)
        serialport::SerialPort::clear(&port, serialport::ClearBuffer::Input)
            .map_err(|e| open_err(e.to_string()))?;
        let reader = port
            .try_clone_native()
            .map_err(|e| open_err(e.to_string()))?;
        Self::connect(Box::new(reader), Box::new(port), clock, config)
    }

    /// Starts the reader on an already-open byte stream and performs the handshake.
    ///
    /// `reader` should return `ErrorKind::TimedOut`/`WouldBlock` periodically (a read timeout) so
    /// the reader thread can notice when the link is dropped.
    pub fn connect(
        reader: Box<dyn Read + Send>,
        writer: Box<dyn Write + Send>,
        clock: HostClock,
        config: LinkConfig,
    ) -> Result<Self, LinkError> {
        let (reply_tx, replies) = crossbeam_channel::unbounded();
        let (event_tx, events) = crossbeam_channel::unbounded();
        let stats = Arc::new(LinkStats::default());
        let connected = Arc::new(AtomicBool::new(true));
        let stop = Arc::new(AtomicBool::new(false));
        let handle = {
            let (stats, connected, stop) = (stats.clone(), connected.clone(), stop.clone());
            std::thread::Builder::new()
                .name("trigger-link-rx".into())
                .spawn(move || {
                    reader_loop(reader, clock, reply_tx, event_tx, &stats, &connected, &stop)
                })
                .map_err(|e| LinkError::Open {
                    path: "reader thread".into(),
                    reason: e.to_string(),
                })?
        };
        let placeholder = BoardInfo {
            protocol_version: 0,
            firmware_version: ellipso_protocol::FirmwareVersion {
                major: 0,
                minor: 0,
                patch: 0,
            },
            board_name: heapless::String::new(),
            timer_clock_hz: 0,
            limits: ellipso_protocol::BoardLimits {
                min_exposure_us: 0,
                max_exposure_us: 0,
                max_flash_on_us: 0,
                max_flash_duty_permille: 0,
                readout_us: 0,
                min_frame_period_us: 0,
                max_frame_period_us: 0,
                max_pulse_count: 0,
            },
        };
        let mut link = Self {
            writer: Mutex::new(writer),
            replies,
            events,
            stats,
            connected,
            stop,
            reader: Some(handle),
            clock,
            clock_model: Mutex::new(ClockModel::new(config.clock)),
            next_nonce: AtomicU64::new(1),
            info: placeholder,
            config,
        };
        // A leading delimiter flushes any partial frame the board holds from before we connected.
        link.write_raw(&[0])?;
        let hello = HostMessage::Hello {
            protocol_version: PROTOCOL_VERSION,
        };
        let is_reply = |m: &BoardMessage| matches!(m, BoardMessage::HelloReply(_));
        let mut reply = link.request(&hello, is_reply);
        for _ in 0..link.config.retries {
            if !matches!(reply, Err(LinkError::Timeout { .. })) {
                break;
            }
            reply = link.request(&hello, is_reply);
        }
        let (BoardMessage::HelloReply(info), _) = reply? else {
            unreachable!("request only returns matching replies")
        };
        if info.protocol_version != PROTOCOL_VERSION {
            return Err(LinkError::VersionMismatch {
                board: info.protocol_version,
                host: PROTOCOL_VERSION,
                board_name: info.board_name.to_string(),
            });
        }
        link.info = info;
        Ok(link)
    }

    /// What the board said about itself at the handshake.
    pub fn board(&self) -> &BoardInfo {
        &self.info
    }

    /// The host clock this link stamps with.
    pub fn host_clock(&self) -> HostClock {
        self.clock
    }

    /// Events: pulses, faults, edges, unsolicited status, disconnect.
    pub fn events(&self) -> &Receiver<LinkEvent> {
        &self.events
    }

    /// Link counters now.
    pub fn counters(&self) -> LinkCounters {
        self.stats.snapshot()
    }

    /// False once the reader saw the stream end.
    pub fn is_connected(&self) -> bool {
        self.connected.load(Ordering::Acquire)
    }

    /// Sends a capture configuration; `Err(Rejected)` carries the board's reason.
    pub fn configure(&self, config: CaptureConfig) -> Result<(), LinkError> {
        self.command(&HostMessage::Configure(config))
    }

    /// Arms the board.
    pub fn arm(&self) -> Result<(), LinkError> {
        self.command(&HostMessage::Arm)
    }

    /// Starts the capture.
    pub fn start(&self) -> Result<(), LinkError> {
        self.command(&HostMessage::Start)
    }

    /// Stops the capture (the flash is off when this returns `Ok`).
    pub fn stop(&self) -> Result<(), LinkError> {
        self.command(&HostMessage::Stop)
    }

    /// Asks the board to reboot into its USB DFU bootloader (`ellipso board flash`); after the
    /// `Ack` the board resets and this link ends. A board whose firmware predates the command
    /// answers with a bad-frame fault instead, so this times out.
    pub fn enter_bootloader(&self) -> Result<(), LinkError> {
        self.command(&HostMessage::EnterBootloader)
    }

    /// Fires one pulse (host-command trigger source).
    pub fn fire_one(&self) -> Result<(), LinkError> {
        self.command(&HostMessage::FireOne)
    }

    /// Asks for the board's status.
    pub fn status(&self) -> Result<Status, LinkError> {
        let is_status = |m: &BoardMessage| matches!(m, BoardMessage::Status(_));
        let mut reply = self.request(&HostMessage::StatusRequest, is_status);
        for _ in 0..self.config.retries {
            if !matches!(reply, Err(LinkError::Timeout { .. })) {
                break;
            }
            reply = self.request(&HostMessage::StatusRequest, is_status);
        }
        match reply? {
            (BoardMessage::Status(s), _) => Ok(s),
            _ => unreachable!("request only returns matching replies"),
        }
    }

    /// One bracketed ping: returns the sample (also added to the clock model if accepted).
    pub fn ping(&self) -> Result<ClockSample, LinkError> {
        let nonce = (self.next_nonce.fetch_add(1, Ordering::Relaxed) & 0xffff_ffff) as u32;
        let t_send = self.clock.now();
        let (m, t_recv) = self.request(
            &HostMessage::Ping { nonce },
            |m| matches!(m, BoardMessage::Pong { nonce: n, .. } if *n == nonce),
        )?;
        let BoardMessage::Pong { t_device_us, .. } = m else {
            unreachable!("request only returns matching replies")
        };
        let sample = ClockSample {
            t_send,
            t_device: DeviceTimeUs(t_device_us),
            t_recv,
        };
        if let Err(e) = self.lock_clock().add(sample) {
            tracing::debug!("clock sample rejected: {e}");
        }
        Ok(sample)
    }

    /// Sends `n` pings and returns the clock fit. A ping lost on a noisy link, or one whose round
    /// trip was too long to use (a host busy with other work), is skipped, not fatal: while the
    /// fit has too few accepted samples, up to [`SYNC_EXTRA_PING_FACTOR`]` × n` more pings are
    /// sent. `None` only when even those did not settle it.
    pub fn sync_clock(&self, n: usize) -> Result<Option<clock::ClockFit>, LinkError> {
        let budget = n.saturating_mul(1 + SYNC_EXTRA_PING_FACTOR);
        for sent in 0..budget {
            if sent >= n
                && let Some(fit) = self.lock_clock().fit()
            {
                return Ok(Some(fit));
            }
            match self.ping() {
                Ok(_) | Err(LinkError::Timeout { .. }) => {}
                Err(e) => return Err(e),
            }
        }
        Ok(self.lock_clock().fit())
    }

    /// The current clock fit, if settled.
    pub fn clock_fit(&self) -> Option<clock::ClockFit> {
        self.lock_clock().fit()
    }

    fn lock_clock(&self) -> std::sync::MutexGuard<'_, ClockModel> {
        // a panic while holding this lock cannot leave the model inconsistent: take it anyway
        self.clock_model.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn command(&self, msg: &HostMessage) -> Result<(), LinkError> {
        let kind = msg.kind();
        let attempts = if kind == CommandKind::FireOne {
            1
        } else {
            self.config.retries + 1
        };
        for attempt in 0..attempts {
            let result = self.request(msg, |m| {
                matches!(m, BoardMessage::Ack(k) | BoardMessage::Rejected { command: k, .. } if *k == kind)
            });
            match result {
                Ok((BoardMessage::Rejected { command, reason }, _)) => {
                    let first_start_took = attempt > 0
                        && kind == CommandKind::Start
                        && matches!(reason, RejectReason::Busy | RejectReason::NotArmed);
                    if first_start_took {
                        return Ok(());
                    }
                    return Err(LinkError::Rejected { command, reason });
                }
                Ok(_) => return Ok(()),
                Err(LinkError::Timeout { .. }) if attempt + 1 < attempts => {
                    tracing::debug!(
                        "{kind:?} timed out (attempt {}), sending again",
                        attempt + 1
                    );
                }
                Err(e) => return Err(e),
            }
        }
        Err(LinkError::Timeout {
            command: kind,
            timeout_ms: self.config.reply_timeout.as_millis() as u64,
        })
    }

    /// Sends `msg` and waits for the first reply `accept` matches; other replies are stale
    /// answers to earlier, timed-out requests and are dropped.
    fn request(
        &self,
        msg: &HostMessage,
        accept: impl Fn(&BoardMessage) -> bool,
    ) -> Result<Reply, LinkError> {
        let mut writer = self.writer.lock().unwrap_or_else(|p| p.into_inner());
        while self.replies.try_recv().is_ok() {}
        let mut frame = [0u8; MAX_FRAME_LEN];
        let n = encode(msg, &mut frame).map_err(|e| LinkError::Io(std::io::Error::other(e)))?;
        self.write_locked(&mut writer, &frame[..n])?;
        let deadline = std::time::Instant::now() + self.config.reply_timeout;
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match self.replies.recv_timeout(left) {
                Ok(r) if accept(&r.0) => return Ok(r),
                Ok(other) => tracing::debug!("dropping stale reply {other:?}"),
                Err(RecvTimeoutError::Timeout) => {
                    return Err(LinkError::Timeout {
                        command: msg.kind(),
                        timeout_ms: self.config.reply_timeout.as_millis() as u64,
                    });
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(LinkError::Disconnected("the reader stopped".into()));
                }
            }
        }
    }

    fn write_raw(&self, bytes: &[u8]) -> Result<(), LinkError> {
        let mut writer = self.writer.lock().unwrap_or_else(|p| p.into_inner());
        self.write_locked(&mut writer, bytes)
    }

    fn write_locked(
        &self,
        writer: &mut Box<dyn Write + Send>,
        bytes: &[u8],
    ) -> Result<(), LinkError> {
        if !self.is_connected() {
            return Err(LinkError::Disconnected(
                "the board's stream has ended".into(),
            ));
        }
        writer.write_all(bytes)?;
        writer.flush()?;
        self.stats
            .bytes_tx
            .fetch_add(bytes.len() as u64, Ordering::Relaxed);
        Ok(())
    }
}

impl Drop for TriggerLink {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(h) = self.reader.take() {
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests;
