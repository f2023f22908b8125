//! The trigger wire between the virtual board and simulated cameras — and the flash's light.
//!
//! A real camera's trigger input is an opto-isolated line: it sees a level change and when it
//! happened, nothing else. A [`TriggerEdge`] carries exactly that — the board's device time of
//! the edge, the new level and which board output changed — and deliberately **no pulse sequence
//! number**: a simulated camera must number its frames itself, as a GigE camera does, and the
//! host must pair them to pulses.
//!
//! The same wire also carries the flash output's edges ([`Output::Flash`]). They stand for the
//! flash's *light*, which a real camera sees through its lens, not through a cable: the simulated
//! camera integrates the flash's on-time inside its own exposure and renders the frame with that
//! energy (`flash_meter`), so a bracketed or cut-short pulse shows as a darker frame, as it would
//! on the rig. A camera ignores flash edges for triggering.
//!
//! In-process the wire is a [`crossbeam_channel`] of edges. Across processes it is a unix stream
//! socket carrying the same edges as fixed 16-byte records ([`EDGE_RECORD_LEN`]):
//!
//! | bytes | field |
//! |---|---|
//! | 0–1 | magic `b"TE"` |
//! | 2 | record version, `2` |
//! | 3 | level: `1` rising, `0` falling |
//! | 4 | output: `0` camera trigger, `1` flash (version 2) |
//! | 5–7 | reserved, zero |
//! | 8–15 | `t_device_us`, u64 little-endian |
//!
//! [`WireServer`] (the board's side) listens on a path and broadcasts every edge to each
//! connected reader (a reader whose `connect` returned before an edge was published gets that
//! edge); a reader that stops reading for 1 s is disconnected rather than stalling the board.
//! [`connect_wire`] (a camera's side) turns the socket back into a channel of edges.
//!
//! Neither side prints: what goes wrong on their background threads (a failed `accept`, a
//! malformed record) is kept as a [`RigError`] in a [`WireProblems`] list that the owner reads
//! ([`WireServer::problems`], [`connect_wire_reporting`]).

use std::io::{ErrorKind, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender};
use ellipso_protocol::Output;

use super::RigError;

/// One level change of a board output: the camera trigger line, or the flash's light.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TriggerEdge {
    /// When the board drove the edge, board device µs.
    pub t_device_us: u64,
    /// `true` for low → high (exposure start; flash lit).
    pub rising: bool,
    /// Which output changed.
    pub output: Output,
}

impl TriggerEdge {
    /// A camera-trigger edge.
    pub const fn trigger(t_device_us: u64, rising: bool) -> Self {
        Self {
            t_device_us,
            rising,
            output: Output::CameraTrigger,
        }
    }

    /// A flash edge (the light turning on or off).
    pub const fn flash(t_device_us: u64, on: bool) -> Self {
        Self {
            t_device_us,
            rising: on,
            output: Output::Flash,
        }
    }
}

/// Size of one edge record on the socket.
pub const EDGE_RECORD_LEN: usize = 16;
const MAGIC: [u8; 2] = *b"TE";
const RECORD_VERSION: u8 = 2;

impl TriggerEdge {
    /// The socket record of this edge.
    pub fn to_record(&self) -> [u8; EDGE_RECORD_LEN] {
        let mut r = [0u8; EDGE_RECORD_LEN];
        r[..2].copy_from_slice(&MAGIC);
        r[2] = RECORD_VERSION;
        r[3] = u8::from(self.rising);
        r[4] = match self.output {
            Output::CameraTrigger => 0,
            Output::Flash => 1,
        };
        r[8..].copy_from_slice(&self.t_device_us.to_le_bytes());
        r
    }

    /// Parses a socket record; refuses a wrong magic, version, level or output byte.
    pub fn from_record(r: &[u8; EDGE_RECORD_LEN]) -> Result<Self, RigError> {
        if r[..2] != MAGIC || r[2] != RECORD_VERSION || r[3] > 1 || r[4] > 1 || r[5..8] != [0; 3] {
            return Err(RigError::WireRecord { record: *r });
        }
        let mut t = [0u8; 8];
        t.copy_from_slice(&r[8..]);
        Ok(Self {
            t_device_us: u64::from_le_bytes(t),
            rising: r[3] == 1,
            output: if r[4] == 1 {
                Output::Flash
            } else {
                Output::CameraTrigger
            },
        })
    }
}

/// An in-process wire: the board's end and the camera's end.
pub fn wire() -> (Sender<TriggerEdge>, Receiver<TriggerEdge>) {
    crossbeam_channel::unbounded()
}

/// What went wrong on a wire's background thread, in order, for its owner to read.
#[derive(Clone, Debug, Default)]
pub struct WireProblems(Arc<Mutex<Vec<RigError>>>);

impl WireProblems {
    fn push(&self, e: RigError) {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).push(e);
    }

    /// The problems recorded since the last call (oldest first).
    pub fn take(&self) -> Vec<RigError> {
        std::mem::take(&mut *self.0.lock().unwrap_or_else(|p| p.into_inner()))
    }
}

/// Broadcasts edges from a channel to every reader connected to a unix socket.
pub struct WireServer {
    path: PathBuf,
    clients: Arc<Mutex<Vec<UnixStream>>>,
    problems: WireProblems,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl WireServer {
    /// Binds `path` (an existing socket file there is replaced) and forwards every edge from
    /// `edges` until the channel's senders are gone or [`WireServer::shutdown`] is called.
    pub fn bind(path: &Path, edges: Receiver<TriggerEdge>) -> Result<Self, RigError> {
        let io_err = |e: std::io::Error| RigError::Io {
            what: format!("trigger wire socket {}", path.display()),
            source: e,
        };
        if path.exists() {
            std::fs::remove_file(path).map_err(io_err)?;
        }
        let listener = UnixListener::bind(path).map_err(io_err)?;
        listener.set_nonblocking(true).map_err(io_err)?;
        let clients: Arc<Mutex<Vec<UnixStream>>> = Arc::default();
        let stop = Arc::new(AtomicBool::new(false));
        let problems = WireProblems::default();
        let forward = {
            let (clients, stop, problems) = (clients.clone(), stop.clone(), problems.clone());
            std::thread::Builder::new()
                .name("wire-forward".into())
                .spawn(move || forward_loop(&listener, &edges, &clients, &stop, &problems))
                .map_err(io_err)?
        };
        Ok(Self {
            path: path.to_path_buf(),
            clients,
            problems,
            stop,
            threads: vec![forward],
        })
    }

    /// The socket's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Failed `accept`s of readers since the last call (oldest first).
    pub fn problems(&self) -> Vec<RigError> {
        self.problems.take()
    }

    /// Readers connected now.
    pub fn client_count(&self) -> usize {
        lock_clients(&self.clients).len()
    }

    /// Stops forwarding, joins the threads and removes the socket file.
    pub fn shutdown(mut self) {
        self.stop_threads();
    }

    fn stop_threads(&mut self) {
        self.stop.store(true, Ordering::Release);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        let _ = std::fs::remove_file(&self.path);
    }
}

impl Drop for WireServer {
    fn drop(&mut self) {
        self.stop_threads();
    }
}

fn lock_clients(c: &Mutex<Vec<UnixStream>>) -> std::sync::MutexGuard<'_, Vec<UnixStream>> {
    c.lock().unwrap_or_else(|p| p.into_inner())
}

/// Registers every reader whose `connect` has completed (non-blocking).
fn accept_pending(
    listener: &UnixListener,
    clients: &Mutex<Vec<UnixStream>>,
    problems: &WireProblems,
) {
    loop {
        match listener.accept() {
            Ok((stream, _)) => {
                // A reader that does not drain 1 s of writes is dropped, never waited on.
                if stream
                    .set_write_timeout(Some(Duration::from_secs(1)))
                    .is_ok()
                {
                    lock_clients(clients).push(stream);
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => return,
            Err(e) => {
                problems.push(RigError::Io {
                    what: "trigger wire: accepting a reader".into(),
                    source: e,
                });
                return;
            }
        }
    }
}

/// Forwards edges; pending readers are accepted before each edge, so a reader whose `connect`
/// returned before an edge was published receives that edge.
fn forward_loop(
    listener: &UnixListener,
    edges: &Receiver<TriggerEdge>,
    clients: &Mutex<Vec<UnixStream>>,
    stop: &AtomicBool,
    problems: &WireProblems,
) {
    while !stop.load(Ordering::Acquire) {
        let edge = edges.recv_timeout(Duration::from_millis(20));
        accept_pending(listener, clients, problems);
        let edge = match edge {
            Ok(e) => e,
            Err(crossbeam_channel::RecvTimeoutError::Timeout) => continue,
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => return,
        };
        let record = edge.to_record();
        lock_clients(clients).retain_mut(|c| c.write_all(&record).is_ok());
    }
}

/// Connects to a [`WireServer`] at `path`; edges arrive on the returned channel until the server
/// goes away (then the channel disconnects). A malformed record ends the stream
/// ([`connect_wire_reporting`] also says why).
pub fn connect_wire(path: &Path) -> Result<Receiver<TriggerEdge>, RigError> {
    connect_wire_reporting(path).map(|(edges, _)| edges)
}

/// [`connect_wire`], with the list where a malformed record that ended the stream is kept
/// ([`RigError::WireRecord`]).
pub fn connect_wire_reporting(
    path: &Path,
) -> Result<(Receiver<TriggerEdge>, WireProblems), RigError> {
    let problems = WireProblems::default();
    let io_err = |e: std::io::Error| RigError::Io {
        what: format!("trigger wire socket {}", path.display()),
        source: e,
    };
    let mut stream = UnixStream::connect(path).map_err(io_err)?;
    let (tx, rx) = crossbeam_channel::unbounded();
    let reader_problems = problems.clone();
    std::thread::Builder::new()
        .name("wire-read".into())
        .spawn(move || {
            let mut record = [0u8; EDGE_RECORD_LEN];
            while stream.read_exact(&mut record).is_ok() {
                let edge = match TriggerEdge::from_record(&record) {
                    Ok(edge) => edge,
                    Err(e) => {
                        reader_problems.push(e);
                        return;
                    }
                };
                if tx.send(edge).is_err() {
                    return;
                }
            }
        })
        .map_err(io_err)?;
    Ok((rx, problems))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_garbage_is_refused() {
        let e = TriggerEdge::trigger(0x0102_0304_0506_0708, true);
        let r = e.to_record();
        assert_eq!(&r[8..], &0x0102_0304_0506_0708u64.to_le_bytes());
        assert_eq!(TriggerEdge::from_record(&r).unwrap(), e);
        let f = TriggerEdge::flash(77, false);
        assert_eq!(f.to_record()[3..5], [0, 1]);
        assert_eq!(TriggerEdge::from_record(&f.to_record()).unwrap(), f);
        for (byte, value) in [(3, 2), (0, b'X'), (2, 1), (4, 2), (6, 1)] {
            let mut bad = r;
            bad[byte] = value;
            assert!(
                TriggerEdge::from_record(&bad).is_err(),
                "byte {byte} = {value}"
            );
        }
    }

    #[test]
    fn a_malformed_record_ends_the_stream_and_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("wire.sock");
        let listener = UnixListener::bind(&path).unwrap();
        let (camera, problems) = connect_wire_reporting(&path).unwrap();
        let (mut board, _) = listener.accept().unwrap();
        board
            .write_all(&TriggerEdge::trigger(5, true).to_record())
            .unwrap();
        board.write_all(&[b'X'; EDGE_RECORD_LEN]).unwrap();
        let first = camera.recv_timeout(Duration::from_secs(5)).unwrap();
        assert_eq!(first, TriggerEdge::trigger(5, true));
        // the reader stops at the garbage: the channel disconnects and says why
        assert!(camera.recv_timeout(Duration::from_secs(5)).is_err());
        let got = problems.take();
        assert!(
            matches!(got.as_slice(), [RigError::WireRecord { .. }]),
            "{got:?}"
        );
        assert!(problems.take().is_empty());
    }

    #[test]
    fn edges_cross_the_socket_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("wire.sock");
        let (tx, rx) = wire();
        let server = WireServer::bind(&path, rx).unwrap();
        let camera = connect_wire(&path).unwrap();
        // No waiting: a reader connected before an edge is published receives it.
        let sent: Vec<_> = (0..10)
            .map(|i| {
                if i % 3 == 2 {
                    TriggerEdge::flash(1_000 + i * 7, i % 2 == 0)
                } else {
                    TriggerEdge::trigger(1_000 + i * 7, i % 2 == 0)
                }
            })
            .collect();
        for e in &sent {
            tx.send(*e).unwrap();
        }
        let got: Vec<_> = (0..10)
            .map(|_| camera.recv_timeout(Duration::from_secs(5)).unwrap())
            .collect();
        assert_eq!(got, sent);
        assert_eq!(server.client_count(), 1);
        server.shutdown();
        assert!(!path.exists());
    }
}
