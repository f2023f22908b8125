//! The virtual trigger board: the real [`ellipso_firmware::Board`] core on a thread, in the
//! simulated device time of a [`LinearClock`], talking over any byte transport.
//!
//! Contract:
//! - [`VirtualBoard::spawn`] takes a reader and a writer (the device end of a pty, a unix socket,
//!   an in-memory [`duplex`](super::duplex)). The reader must return `TimedOut`/`WouldBlock`
//!   periodically (a read timeout) so the board can stop.
//! - The board behaves as a port with a hardware compare timer (firmware port guide, steps 4–6):
//!   every deadline is polled **with the deadline's own device time**, so edge times are exact
//!   and never reported late because the host OS woke the thread late; received bytes are fed
//!   with the device time they arrived, after every deadline due before them.
//! - Every camera-trigger and flash level change goes out on the trigger wire (if given) as a
//!   [`TriggerEdge`] (the flash's edges stand for its light, which the simulated camera meters)
//!   and is recorded in the truth.
//! - Outgoing frames are queued for a writer thread (like a UART ring buffer): a full queue drops
//!   whole frames, which the core counts in `tx_overflows`; a host that stops reading never
//!   stalls the sequencer.
//! - Link faults ([`LinkFaults`]): bits of each frame are flipped at the BER after it was
//!   recorded in the [`BoardTruth`]; a permanent [`Disconnect`] closes both ends when the pulse
//!   event numbered `at_pulse` is due and ends the thread; a blackout drops every byte both ways
//!   for its duration.
//! - The thread ends when the owner calls [`VirtualBoard::shutdown`] (or drops it), when the
//!   host's end reports end-of-stream or an I/O error, or at a permanent disconnect.
//!   [`BoardTruth::end_reason`] says which.

use std::io::{ErrorKind, Read, Write};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use ellipso_firmware::{Board, BoardConfig};
use ellipso_protocol::{FaultCounters, PulseEvent};

use super::RigError;
use super::clock::LinearClock;
use super::link_fault::{BitErrorInjector, Disconnect, LinkFaults};
use super::seeds::FaultStream;
use super::wire::TriggerEdge;

mod ports;

use ports::{LinkState, LinkTx, WireOutputs};

/// Longest the board thread sleeps without checking its stop flag.
const IDLE_WAKE: Duration = Duration::from_millis(20);
/// How long shutdown waits for a transport thread stuck in a blocking call before leaving it.
const THREAD_GRACE: Duration = Duration::from_secs(1);

/// Settings of a [`VirtualBoard`].
#[derive(Debug, Clone, Copy)]
pub struct VirtualBoardConfig {
    /// What the firmware core is told about the board (name, limits, timing).
    pub board: BoardConfig,
    /// The host instant at which the device clock reads `clock_offset_us`.
    pub epoch: Instant,
    /// Device clock reading at `epoch`, µs.
    pub clock_offset_us: u64,
    /// Device clock rate error against the host, ppm.
    pub clock_drift_ppm: f64,
    /// Bit errors and disconnects.
    pub link: LinkFaults,
    /// Seed of the link-fault streams (the scene seed).
    pub seed: u64,
    /// Frames the transmit queue holds before it drops.
    pub tx_queue_frames: usize,
}

impl VirtualBoardConfig {
    /// Defaults: the LED-rig limits, a device clock 25 ppm fast that has been up ≈ 11.6 days
    /// (offset 10¹² µs) so a host clock model has a real offset and slope to fit, a clean link,
    /// a 64-frame transmit queue.
    pub fn new(seed: u64) -> Self {
        Self {
            board: BoardConfig::new("ellipso-virtual", 1_000_000),
            epoch: Instant::now(),
            clock_offset_us: 1_000_000_000_000,
            clock_drift_ppm: 25.0,
            link: LinkFaults::default(),
            seed,
            tx_queue_frames: 64,
        }
    }

    /// Defaults plus the scene's seed and link faults: `link_corruption.bit_error_rate` on the
    /// board → host direction, `link_disconnect` (`at_frame` → `at_pulse`, `duration_ms` → blackout).
    pub fn from_scene(scene: &crate::scene::Scene) -> Self {
        let mut c = Self::new(scene.seed);
        if let Some(corruption) = scene.effects.link_corruption {
            c.link.ber_to_host = corruption.bit_error_rate;
        }
        if let Some(d) = scene.effects.link_disconnect {
            c.link.disconnect = Some(Disconnect {
                at_pulse: u64::from(d.at_frame),
                blackout: d
                    .duration_ms
                    .map(|ms| Duration::from_secs_f64(ms.max(0.0) * 1e-3)),
            });
        }
        c
    }

    /// The device clock these settings describe.
    pub fn device_clock(&self) -> Result<LinearClock, RigError> {
        LinearClock::new(self.epoch, self.clock_offset_us, self.clock_drift_ppm)
    }
}

/// What the board really did, for scoring what the host received.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BoardTruth {
    /// Every pulse event the core emitted, in order, before any link fault touched it.
    pub pulses: Vec<PulseEvent>,
    /// Every camera-trigger level change, in order.
    pub trigger_edges: Vec<TriggerEdge>,
    /// Every flash level change, in order.
    pub flash_edges: Vec<TriggerEdge>,
    /// Frames handed to the link (corrupted or not).
    pub frames_sent: u64,
    /// Of those, frames with at least one flipped bit.
    pub frames_corrupted: u64,
    /// Pulse sequence numbers whose frame was corrupted on the way out.
    pub corrupted_pulse_seqs: Vec<u64>,
    /// Frames never handed to the link: transmit queue full, link down.
    pub frames_lost: u64,
    /// Frames the writer gave up on because the host end did not drain (a write timed out);
    /// part of such a frame may have gone out, which the host's decoder drops as a bad frame.
    pub frames_stalled: u64,
    /// Bits flipped board → host.
    pub bits_flipped_to_host: u64,
    /// Bits flipped host → board.
    pub bits_flipped_to_board: u64,
    /// Bytes received from the host (including those lost in a blackout).
    pub bytes_from_host: u64,
    /// The first pulse not delivered, once a disconnect happened.
    pub disconnected_at_pulse: Option<u64>,
    /// The core's fault counters, updated after every step.
    pub board_faults: FaultCounters,
    /// Why the board thread ended, once it has.
    pub end_reason: Option<String>,
}

/// A running virtual board; see the [module docs](self).
pub struct VirtualBoard {
    thread: Option<JoinHandle<()>>,
    stop: Arc<AtomicBool>,
    truth: Arc<Mutex<BoardTruth>>,
    clock: LinearClock,
}

impl std::fmt::Debug for VirtualBoard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VirtualBoard")
            .field("clock", &self.clock)
            .finish_non_exhaustive()
    }
}

fn lock(truth: &Mutex<BoardTruth>) -> MutexGuard<'_, BoardTruth> {
    // Plain data: a panicking holder cannot leave it inconsistent.
    truth.lock().unwrap_or_else(|p| p.into_inner())
}

enum RxEvent {
    Bytes(Vec<u8>, Instant),
    Closed(String),
}

enum TxItem {
    Frame(Vec<u8>),
    Close,
}

impl VirtualBoard {
    /// Starts the board on `reader`/`writer`; trigger edges go to `wire` when given.
    pub fn spawn(
        config: VirtualBoardConfig,
        reader: Box<dyn Read + Send>,
        writer: Box<dyn Write + Send>,
        wire: Option<Sender<TriggerEdge>>,
    ) -> Result<Self, RigError> {
        config.link.check()?;
        if config.tx_queue_frames == 0 {
            return Err(RigError::Parameter {
                name: "tx_queue_frames",
                value: 0.0,
                expected: "at least 1",
            });
        }
        let clock = config.device_clock()?;
        let board = Board::new(config.board).map_err(RigError::Board)?;
        let to_host = BitErrorInjector::new(
            config.link.ber_to_host,
            config.seed,
            FaultStream::LinkBitErrorsToHost,
        )?;
        let to_board = BitErrorInjector::new(
            config.link.ber_to_board,
            config.seed,
            FaultStream::LinkBitErrorsToBoard,
        )?;
        let stop = Arc::new(AtomicBool::new(false));
        let truth = Arc::new(Mutex::new(BoardTruth::default()));
        let spawn_err = |e: std::io::Error| RigError::Io {
            what: "virtual board thread".into(),
            source: e,
        };
        let thread = {
            let (stop, truth) = (stop.clone(), truth.clone());
            let run = BoardRun {
                board,
                clock,
                to_host,
                to_board,
                disconnect: config.link.disconnect,
                tx_queue_frames: config.tx_queue_frames,
            };
            std::thread::Builder::new()
                .name("virtual-board".into())
                .spawn(move || {
                    let reason = run.run(reader, writer, wire, &truth, &stop);
                    lock(&truth).end_reason = Some(reason);
                })
                .map_err(spawn_err)?
        };
        Ok(Self {
            thread: Some(thread),
            stop,
            truth,
            clock,
        })
    }

    /// The board's device clock (ground truth of the drift and offset the host should fit).
    pub fn device_clock(&self) -> LinearClock {
        self.clock
    }

    /// A snapshot of what the board did so far.
    pub fn truth(&self) -> BoardTruth {
        lock(&self.truth).clone()
    }

    /// Whether the board thread has ended (disconnect, host gone, shutdown).
    pub fn is_finished(&self) -> bool {
        self.thread.as_ref().is_none_or(JoinHandle::is_finished)
    }

    /// Waits up to `timeout` for the thread to end by itself; true if it has.
    pub fn wait_finished(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        while !self.is_finished() {
            if Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        true
    }

    /// Stops the board (outputs low, transport closed), joins it and returns the final truth.
    pub fn shutdown(mut self) -> BoardTruth {
        self.stop_and_join();
        self.truth()
    }

    fn stop_and_join(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for VirtualBoard {
    fn drop(&mut self) {
        self.stop_and_join();
    }
}

/// The board thread's state.
struct BoardRun {
    board: Board,
    clock: LinearClock,
    to_host: BitErrorInjector,
    to_board: BitErrorInjector,
    disconnect: Option<Disconnect>,
    tx_queue_frames: usize,
}

impl BoardRun {
    fn run(
        mut self,
        reader: Box<dyn Read + Send>,
        writer: Box<dyn Write + Send>,
        wire: Option<Sender<TriggerEdge>>,
        truth: &Mutex<BoardTruth>,
        stop: &AtomicBool,
    ) -> String {
        let rx_stop = Arc::new(AtomicBool::new(false));
        let (rx_tx, rx) = crossbeam_channel::unbounded();
        let (rx_done_tx, rx_done) = crossbeam_channel::bounded::<()>(0);
        let rx_thread = {
            let rx_stop = rx_stop.clone();
            std::thread::Builder::new()
                .name("virtual-board-rx".into())
                .spawn(move || {
                    let _done = rx_done_tx;
                    rx_loop(reader, &rx_tx, &rx_stop);
                })
        };
        let (frames_tx, frames_rx) = crossbeam_channel::bounded(self.tx_queue_frames);
        let (tx_done_tx, tx_done) = crossbeam_channel::bounded::<()>(0);
        let tx_error = Arc::new(Mutex::new(None::<String>));
        let stalled = Arc::new(AtomicU64::new(0));
        let tx_thread = {
            let (tx_error, stalled) = (tx_error.clone(), stalled.clone());
            std::thread::Builder::new()
                .name("virtual-board-tx".into())
                .spawn(move || {
                    let _done = tx_done_tx;
                    if let Err(e) = tx_loop(writer, &frames_rx, &stalled) {
                        *tx_error.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
                    }
                })
        };
        let reason = match (rx_thread, tx_thread) {
            (Ok(_), Ok(_)) => self.serve(&rx, &frames_tx, wire.as_ref(), &tx_error, truth, stop),
            (Err(e), _) | (_, Err(e)) => format!("cannot start a transport thread: {e}"),
        };
        // Close the transport: the writer once the queued frames are out, the reader at its next
        // timeout. A thread stuck in a blocking call (a peer that never reads) is left behind
        // after a grace period rather than hanging the owner.
        let _ = frames_tx.send_timeout(TxItem::Close, THREAD_GRACE);
        drop(frames_tx);
        rx_stop.store(true, Ordering::Release);
        let _ = tx_done.recv_timeout(THREAD_GRACE);
        let _ = rx_done.recv_timeout(THREAD_GRACE);
        lock(truth).frames_stalled = stalled.load(Ordering::Relaxed);
        reason
    }

    fn serve(
        &mut self,
        rx: &Receiver<RxEvent>,
        frames: &Sender<TxItem>,
        wire: Option<&Sender<TriggerEdge>>,
        tx_error: &Mutex<Option<String>>,
        truth: &Mutex<BoardTruth>,
        stop: &AtomicBool,
    ) -> String {
        let mut link = LinkState::default();
        let mut outputs = WireOutputs {
            wire,
            camera_high: false,
            flash_high: false,
            truth,
        };
        let mut last_us = self.clock.now_us();
        self.board.reset_outputs(last_us, &mut outputs);
        loop {
            if stop.load(Ordering::Acquire) {
                // A board losing power mid-capture: both outputs go low.
                self.board
                    .reset_outputs(last_us.max(self.clock.now_us()), &mut outputs);
                return "stopped by its owner".into();
            }
            if link.closed {
                return "link disconnected by the scene's fault".into();
            }
            if let Some(e) = tx_error.lock().unwrap_or_else(|p| p.into_inner()).clone() {
                return format!("writing to the host failed: {e}");
            }
            let now_us = self.clock.now_us();
            if let Some(d) = self.board.next_deadline()
                && d <= now_us
            {
                last_us = self.poll_at(d.max(last_us), frames, &mut outputs, &mut link, truth);
                continue;
            }
            let idle = Instant::now() + IDLE_WAKE;
            let wake = self
                .board
                .next_deadline()
                .map_or(idle, |d| self.clock.instant_at_us(d).min(idle));
            match rx.recv_deadline(wake) {
                Ok(RxEvent::Bytes(mut bytes, t_arrival)) => {
                    let t_arrival_us = self.clock.at_us(t_arrival).max(last_us);
                    while let Some(d) = self.board.next_deadline()
                        && d <= t_arrival_us
                    {
                        last_us =
                            self.poll_at(d.max(last_us), frames, &mut outputs, &mut link, truth);
                    }
                    lock(truth).bytes_from_host += bytes.len() as u64;
                    if link.is_down(Instant::now()) {
                        continue;
                    }
                    let flipped = self.to_board.corrupt(&mut bytes);
                    lock(truth).bits_flipped_to_board += u64::from(flipped);
                    let mut sink = LinkTx {
                        frames,
                        to_host: &mut self.to_host,
                        disconnect: &mut self.disconnect,
                        link: &mut link,
                        truth,
                    };
                    for b in bytes {
                        self.board
                            .feed_rx_byte(b, t_arrival_us, &mut outputs, &mut sink);
                    }
                    last_us = t_arrival_us;
                    lock(truth).board_faults = self.board.faults();
                }
                Ok(RxEvent::Closed(reason)) => return format!("host end closed: {reason}"),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return "receive thread ended".into(),
            }
        }
    }

    /// Polls the core at device time `t_us`; returns `t_us`.
    fn poll_at(
        &mut self,
        t_us: u64,
        frames: &Sender<TxItem>,
        outputs: &mut WireOutputs<'_>,
        link: &mut LinkState,
        truth: &Mutex<BoardTruth>,
    ) -> u64 {
        let mut sink = LinkTx {
            frames,
            to_host: &mut self.to_host,
            disconnect: &mut self.disconnect,
            link,
            truth,
        };
        self.board.poll(t_us, outputs, &mut sink);
        lock(truth).board_faults = self.board.faults();
        t_us
    }
}

fn rx_loop(mut reader: Box<dyn Read + Send>, events: &Sender<RxEvent>, stop: &AtomicBool) {
    let mut buf = [0u8; 512];
    while !stop.load(Ordering::Acquire) {
        match reader.read(&mut buf) {
            Ok(0) => {
                let _ = events.send(RxEvent::Closed("end of stream".into()));
                return;
            }
            Ok(n) => {
                if events
                    .send(RxEvent::Bytes(buf[..n].to_vec(), Instant::now()))
                    .is_err()
                {
                    return;
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                ) => {}
            Err(e) => {
                let _ = events.send(RxEvent::Closed(e.to_string()));
                return;
            }
        }
    }
}

fn tx_loop(
    mut writer: Box<dyn Write + Send>,
    frames: &Receiver<TxItem>,
    stalled: &AtomicU64,
) -> Result<(), String> {
    for item in frames {
        match item {
            TxItem::Frame(f) => match writer.write_all(&f).and_then(|()| writer.flush()) {
                Ok(()) => {}
                // A host end that does not drain (nobody reading a pty): drop the frame, go on.
                Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock) => {
                    stalled.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => return Err(e.to_string()),
            },
            TxItem::Close => return Ok(()),
        }
    }
    Ok(())
}
