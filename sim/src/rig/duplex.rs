//! An in-memory byte duplex for tests: two ends, each a [`Read`] + [`Write`] pair, like the two
//! ends of a pty but without a kernel.
//!
//! Contract:
//! - Bytes written on one end are read, in order and unchanged, on the other.
//! - A read blocks until bytes arrive, the peer's writer is dropped (then `Ok(0)` once drained), or
//!   the read timeout passes (then `ErrorKind::TimedOut`, as a serial port with a timeout does).
//! - Writing after the peer's reader was dropped fails with `ErrorKind::BrokenPipe`.
//! - Writes never block (the pipe is unbounded; tests are short).

use std::collections::VecDeque;
use std::io::{self, ErrorKind, Read, Write};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

#[derive(Default)]
struct PipeState {
    bytes: VecDeque<u8>,
    writer_closed: bool,
    reader_closed: bool,
}

#[derive(Default)]
struct Pipe {
    state: Mutex<PipeState>,
    ready: Condvar,
}

impl Pipe {
    fn lock(&self) -> MutexGuard<'_, PipeState> {
        // The state stays consistent whatever a panicking holder did: take it anyway.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// The reading half of one end.
pub struct DuplexReader {
    pipe: Arc<Pipe>,
    timeout: Duration,
}

/// The writing half of one end.
pub struct DuplexWriter {
    pipe: Arc<Pipe>,
}

/// One end of a [`duplex`]: read what the other end wrote, write what it reads.
pub struct DuplexEnd {
    /// Reads the peer's bytes.
    pub reader: DuplexReader,
    /// Writes to the peer.
    pub writer: DuplexWriter,
}

/// Two connected ends whose reads time out after `read_timeout`.
pub fn duplex(read_timeout: Duration) -> (DuplexEnd, DuplexEnd) {
    let a_to_b = Arc::new(Pipe::default());
    let b_to_a = Arc::new(Pipe::default());
    let end = |rx: &Arc<Pipe>, tx: &Arc<Pipe>| DuplexEnd {
        reader: DuplexReader {
            pipe: rx.clone(),
            timeout: read_timeout,
        },
        writer: DuplexWriter { pipe: tx.clone() },
    };
    (end(&b_to_a, &a_to_b), end(&a_to_b, &b_to_a))
}

impl Read for DuplexReader {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if buf.is_empty() {
            return Ok(0);
        }
        let deadline = Instant::now() + self.timeout;
        let mut state = self.pipe.lock();
        loop {
            if !state.bytes.is_empty() {
                let n = buf.len().min(state.bytes.len());
                for (dst, src) in buf.iter_mut().zip(state.bytes.drain(..n)) {
                    *dst = src;
                }
                return Ok(n);
            }
            if state.writer_closed {
                return Ok(0);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(io::Error::new(ErrorKind::TimedOut, "duplex read timed out"));
            }
            state = self
                .pipe
                .ready
                .wait_timeout(state, left)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }
}

impl Drop for DuplexReader {
    fn drop(&mut self) {
        self.pipe.lock().reader_closed = true;
    }
}

impl Write for DuplexWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut state = self.pipe.lock();
        if state.reader_closed {
            return Err(io::Error::new(
                ErrorKind::BrokenPipe,
                "the duplex peer closed its reader",
            ));
        }
        state.bytes.extend(buf);
        drop(state);
        self.pipe.ready.notify_all();
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Drop for DuplexWriter {
    fn drop(&mut self) {
        self.pipe.lock().writer_closed = true;
        self.pipe.ready.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_cross_in_order_and_close_reads_as_eof() {
        let (a, b) = duplex(Duration::from_millis(5));
        let (mut a_r, mut a_w) = (a.reader, a.writer);
        let (mut b_r, b_w) = (b.reader, b.writer);
        a_w.write_all(b"hello").unwrap();
        let mut buf = [0u8; 8];
        assert_eq!(b_r.read(&mut buf).unwrap(), 5);
        assert_eq!(&buf[..5], b"hello");
        assert_eq!(b_r.read(&mut buf).unwrap_err().kind(), ErrorKind::TimedOut);
        drop(b_w);
        assert_eq!(a_r.read(&mut buf).unwrap(), 0);
        drop(b_r);
        assert_eq!(a_w.write(b"x").unwrap_err().kind(), ErrorKind::BrokenPipe);
    }
}
