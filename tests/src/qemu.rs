//! The emulated trigger board: `qemu-system-arm -M netduinoplus2` running the
//! `firmware/boards/qemu` ELF, its UART on a unix socket or a pseudo-terminal, and a guard that
//! kills the emulator's process group on drop.
//!
//! Contract:
//! - [`firmware_or_skip`] finds QEMU and the firmware ELF. When either is missing it panics if
//!   `ELLIPSO_REQUIRE_QEMU=1` (CI), otherwise it prints a loud `skipped:` line (straight to stderr,
//!   past libtest's capture) and returns `None`, so a fresh checkout's `cargo test --workspace`
//!   passes without an ARM toolchain.
//! - [`QemuBoard::spawn`] starts QEMU in its own process group with deterministic guest time
//!   (`-icount shift=3,align=off,sleep=off`) and GPIO writes logged (`-d unimp`).
//! - [`QemuBoard::open_link`] returns the host's real [`TriggerLink`] on that UART. It sends
//!   nothing before the firmware's receiver is on: on the socket it waits for the boot
//!   announcement (QEMU drops bytes that reach USART1 before the firmware enables it); on a pty
//!   it holds the pty open from the moment QEMU names it and waits for the announcement there.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::os::unix::net::UnixStream;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use ellipso_protocol::{BoardMessage, BoardState, Decoder};
use ellipso_rig::link::{LinkConfig, TriggerLink};
use ellipso_session::time::HostClock;

/// The emulator binary.
pub const QEMU_BIN: &str = "qemu-system-arm";
/// Env var naming the firmware ELF (default: [`default_firmware_path`]).
pub const ENV_FIRMWARE: &str = "ELLIPSO_QEMU_FW";
/// Env var that turns a missing emulator or ELF into a test failure (`1` in CI).
pub const ENV_REQUIRE: &str = "ELLIPSO_REQUIRE_QEMU";
/// The command that builds the firmware, for messages.
pub const BUILD_HINT: &str = "(cd firmware/boards/qemu && cargo build --release --locked); \
     needs `rustup target add thumbv7em-none-eabihf` and `apt-get install qemu-system-arm`";

/// Where `cargo build --release` in `firmware/boards/qemu` puts the firmware.
pub fn default_firmware_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../firmware/boards/qemu/target/thumbv7em-none-eabihf/release/ellipso-board-qemu")
}

/// Why the emulated board cannot run here, or `Ok(elf)`.
pub fn locate_firmware() -> Result<PathBuf, String> {
    let elf = std::env::var_os(ENV_FIRMWARE).map_or_else(default_firmware_path, PathBuf::from);
    match Command::new(QEMU_BIN).arg("--version").output() {
        Ok(out) if out.status.success() => {}
        Ok(out) => return Err(format!("`{QEMU_BIN} --version` failed: {}", out.status)),
        Err(e) => return Err(format!("`{QEMU_BIN}` not runnable: {e}")),
    }
    if !elf.is_file() {
        return Err(format!("firmware ELF not found at {}", elf.display()));
    }
    Ok(elf)
}

/// The firmware ELF, or `None` after printing why the test is skipped; panics instead when
/// `ELLIPSO_REQUIRE_QEMU=1`.
pub fn firmware_or_skip(test: &str) -> Option<PathBuf> {
    match locate_firmware() {
        Ok(elf) => Some(elf),
        Err(why) if std::env::var(ENV_REQUIRE).as_deref() == Ok("1") => {
            panic!(
                "{test}: {why}; {ENV_REQUIRE}=1 requires the emulated board. Build it: {BUILD_HINT}"
            )
        }
        Err(why) => {
            // Straight to the process's stderr: libtest captures only the print macros.
            let _ = writeln!(
                io::stderr(),
                "\n*** {test} skipped: {why}. Build the firmware with {BUILD_HINT} ***\n"
            );
            None
        }
    }
}

/// How the firmware's UART reaches the host.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Serial {
    /// `-chardev socket,server=on,wait=on`: the guest starts when the host connects.
    UnixSocket,
    /// `-serial pty`: QEMU prints the `/dev/pts/N` it made.
    Pty,
}

/// A running emulated board; dropping it kills QEMU's process group.
pub struct QemuBoard {
    child: Child,
    dir: tempfile::TempDir,
    serial: Serial,
    pty_path: Option<String>,
    pty_probe: Option<File>,
}

fn other(msg: String) -> io::Error {
    io::Error::other(msg)
}

impl QemuBoard {
    /// Starts QEMU on `elf` with its UART on `serial`.
    pub fn spawn(elf: &Path, serial: Serial) -> io::Result<Self> {
        // sun_path holds 108 bytes: keep the socket under a short temp dir.
        let dir = tempfile::Builder::new()
            .prefix("eq")
            .tempdir_in(short_temp_root())?;
        let mut cmd = Command::new(QEMU_BIN);
        cmd.args(["-M", "netduinoplus2", "-nographic", "-monitor", "none"])
            .args(["-icount", "shift=3,align=off,sleep=off"])
            .args(["-d", "unimp", "-D"])
            .arg(dir.path().join("unimp.log"))
            .arg("-kernel")
            .arg(elf);
        match serial {
            Serial::UnixSocket => {
                let sock = dir.path().join("s");
                cmd.arg("-chardev")
                    .arg(format!(
                        "socket,id=s0,path={},server=on,wait=on",
                        sock.display()
                    ))
                    .args(["-serial", "chardev:s0"]);
            }
            Serial::Pty => {
                cmd.args(["-serial", "pty"]);
            }
        }
        let stderr = File::create(dir.path().join("stderr.log"))?;
        let mut child = cmd
            .process_group(0)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(stderr)
            .spawn()?;
        let stdout = child.stdout.take().expect("stdout is piped");
        let mut board = Self {
            child,
            dir,
            serial,
            pty_path: None,
            pty_probe: None,
        };
        if serial == Serial::Pty {
            // QEMU 7.2 prints `char device redirected to /dev/pts/N (label serial0)` on stdout.
            let mut lines = BufReader::new(stdout);
            let mut line = String::new();
            lines.read_line(&mut line)?;
            let path = line
                .split_whitespace()
                .find(|w| w.starts_with("/dev/pts/"))
                .ok_or_else(|| {
                    other(format!(
                        "no pty in QEMU's output {line:?}; {}",
                        board.stderr_tail()
                    ))
                })?;
            board.pty_path = Some(path.to_string());
            // Open it at once so the guest's boot announcement is heard (QEMU drops output
            // while nothing holds the pty open).
            board.pty_probe = Some(
                std::fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .custom_flags(libc::O_NOCTTY | libc::O_NONBLOCK)
                    .open(path)?,
            );
            // Keep draining stdout so QEMU never blocks on a full pipe.
            std::thread::spawn(move || io::copy(&mut lines, &mut io::sink()));
        } else {
            std::thread::spawn(move || io::copy(&mut BufReader::new(stdout), &mut io::sink()));
        }
        Ok(board)
    }

    /// The pty QEMU made (pty mode only).
    pub fn pty_path(&self) -> Option<&str> {
        self.pty_path.as_deref()
    }

    /// The host's trigger link to the firmware, handshaken.
    pub fn open_link(&mut self, config: LinkConfig) -> io::Result<TriggerLink> {
        match self.serial {
            Serial::UnixSocket => self.open_socket_link(config, &[]),
            Serial::Pty => self.open_pty_link(config),
        }
    }

    /// Like [`QemuBoard::open_link`] on a socket, but first writes `preamble` raw (e.g. line
    /// noise) once the firmware's receiver is on, before the link's handshake.
    pub fn open_link_after_raw_bytes(
        &mut self,
        config: LinkConfig,
        preamble: &[u8],
    ) -> io::Result<TriggerLink> {
        if self.serial != Serial::UnixSocket {
            return Err(other("raw preambles need the unix-socket UART".into()));
        }
        self.open_socket_link(config, preamble)
    }

    fn open_socket_link(&mut self, config: LinkConfig, preamble: &[u8]) -> io::Result<TriggerLink> {
        let sock = self.dir.path().join("s");
        let deadline = Instant::now() + Duration::from_secs(10);
        let mut stream = loop {
            match UnixStream::connect(&sock) {
                Ok(s) => break s,
                Err(e) => {
                    if let Some(status) = self.child.try_wait()? {
                        return Err(other(format!(
                            "QEMU exited ({status}); {}",
                            self.stderr_tail()
                        )));
                    }
                    if Instant::now() > deadline {
                        return Err(other(format!("cannot connect to {}: {e}", sock.display())));
                    }
                    std::thread::sleep(Duration::from_millis(5));
                }
            }
        };
        // The boot announcement: the firmware's receiver is on once it arrives.
        stream.set_read_timeout(Some(Duration::from_secs(10)))?;
        let announcement = read_one_frame(&mut stream)
            .map_err(|e| other(format!("no boot announcement: {e}; {}", self.stderr_tail())))?;
        check_announcement(&announcement)?;
        stream.write_all(preamble)?;
        // What TriggerLink::open does for `unix:` paths, on the already connected stream.
        stream.set_read_timeout(Some(Duration::from_millis(50)))?;
        let reader = stream.try_clone()?;
        TriggerLink::connect(Box::new(reader), Box::new(stream), HostClock::new(), config).map_err(
            |e| {
                other(format!(
                    "handshake over the socket failed: {e}; {}",
                    self.stderr_tail()
                ))
            },
        )
    }

    fn open_pty_link(&mut self, config: LinkConfig) -> io::Result<TriggerLink> {
        let path = self
            .pty_path
            .clone()
            .ok_or_else(|| other("no pty".into()))?;
        let Some(probe) = self.pty_probe.as_mut() else {
            return Err(other("pty probe not open".into()));
        };
        // QEMU prints the pty's name before the guest runs. The probe opened it right then, so
        // it normally hears the boot announcement; if the guest booted before that (a loaded
        // machine), its receiver is already on and sending is safe anyway.
        let heard = read_announcement(probe, Duration::from_secs(2))?;
        if let Some(msg) = &heard {
            check_announcement(msg)?;
        }
        // The probe stays open, so QEMU keeps seeing a connected pty.
        TriggerLink::open(&path, HostClock::new(), config).map_err(|e| {
            other(format!(
                "handshake over {path} failed: {e}; {}",
                self.stderr_tail()
            ))
        })
    }

    /// Every value the firmware stored to `GPIOA.BSRR`, in order, from QEMU's `-d unimp` log.
    pub fn gpioa_bsrr_writes(&self) -> io::Result<Vec<u32>> {
        let log = std::fs::read_to_string(self.dir.path().join("unimp.log"))?;
        Ok(parse_bsrr_writes(&log, "GPIOA"))
    }

    /// The last lines QEMU wrote to stderr, for error messages.
    pub fn stderr_tail(&self) -> String {
        let text = std::fs::read_to_string(self.dir.path().join("stderr.log")).unwrap_or_default();
        let tail: Vec<&str> = text.lines().rev().take(5).collect();
        format!(
            "QEMU stderr: {:?}",
            tail.into_iter().rev().collect::<Vec<_>>()
        )
    }
}

impl Drop for QemuBoard {
    fn drop(&mut self) {
        // QEMU leads its own group (process_group(0)): kill the whole group, then reap.
        if let Ok(pid) = i32::try_from(self.child.id()) {
            // SAFETY: kill(2) with a negative pid signals that process group; no memory involved.
            unsafe {
                libc::kill(-pid, libc::SIGKILL);
            }
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `/tmp` when `TMPDIR` would make the socket path too long for `sun_path`.
fn short_temp_root() -> PathBuf {
    let tmp = std::env::temp_dir();
    if tmp.as_os_str().len() <= 60 {
        tmp
    } else {
        PathBuf::from("/tmp")
    }
}

/// The boot announcement is an unsolicited `Status`: state `Idle`, no pulses.
fn check_announcement(msg: &BoardMessage) -> io::Result<()> {
    match msg {
        BoardMessage::Status(s) if s.state == BoardState::Idle && s.pulses_fired == 0 => Ok(()),
        other_msg => Err(other(format!("unexpected boot announcement {other_msg:?}"))),
    }
}

/// Reads a non-blocking pty byte by byte until one frame decodes or `timeout` passes
/// (`Ok(None)`).
fn read_announcement(pty: &mut File, timeout: Duration) -> io::Result<Option<BoardMessage>> {
    let mut decoder = Decoder::<BoardMessage>::new();
    let mut byte = [0u8; 1];
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        match pty.read(&mut byte) {
            Ok(1) => {
                if let Some(result) = decoder.push(byte[0]) {
                    return result
                        .map(Some)
                        .map_err(|e| other(format!("bad boot frame: {e}")));
                }
            }
            Ok(_) => std::thread::sleep(Duration::from_millis(1)),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(1));
            }
            Err(e) => return Err(e),
        }
    }
    Ok(None)
}

/// Reads bytes one at a time up to the first frame delimiter and decodes that frame (so no byte
/// after it is consumed).
fn read_one_frame(stream: &mut UnixStream) -> io::Result<BoardMessage> {
    let mut decoder = Decoder::<BoardMessage>::new();
    let mut byte = [0u8; 1];
    loop {
        stream.read_exact(&mut byte)?;
        if let Some(result) = decoder.push(byte[0]) {
            return result.map_err(|e| other(format!("bad frame: {e}")));
        }
    }
}

/// Parses `<DEV>: unimplemented device write (size 4, offset 0x018, value 0x…)` lines.
pub fn parse_bsrr_writes(log: &str, device: &str) -> Vec<u32> {
    let prefix = format!("{device}: unimplemented device write (size 4, offset 0x018, value ");
    log.lines()
        .filter_map(|l| l.strip_prefix(prefix.as_str()))
        .filter_map(|rest| rest.strip_suffix(')'))
        .filter_map(|v| u32::from_str_radix(v.trim_start_matches("0x"), 16).ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bsrr_writes_are_parsed_from_the_unimp_log_in_order() {
        let log = "RCC: unimplemented device write (size 4, offset 0x030, value 0x00000001)\n\
                   GPIOA: unimplemented device write (size 4, offset 0x018, value 0x00030000)\n\
                   GPIOA: unimplemented device write (size 4, offset 0x000, value 0x00000005)\n\
                   GPIOA: unimplemented device write (size 4, offset 0x018, value 0x00000001)\n\
                   GPIOB: unimplemented device write (size 4, offset 0x018, value 0x00000002)\n";
        assert_eq!(parse_bsrr_writes(log, "GPIOA"), [0x3_0000, 0x1]);
    }

    #[test]
    fn the_default_firmware_path_is_under_the_qemu_board_crate() {
        let p = default_firmware_path();
        assert!(p.ends_with(
            "firmware/boards/qemu/target/thumbv7em-none-eabihf/release/ellipso-board-qemu"
        ));
    }
}
