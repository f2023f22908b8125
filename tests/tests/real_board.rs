//! A real trigger board, where one is attached (issue 45): `ELLIPSO_BOARD` names its serial
//! port (for example `/dev/ttyACM0`). CI machines have none; there the test says it was not
//! run and passes. With a board:
//! - `ellipso devices --port $ELLIPSO_BOARD --json` must find a trigger board that answers, with
//!   its name, firmware version and the protocol version this ellipso speaks;
//! - with `ELLIPSO_BOARD_FIRMWARE` naming a firmware image as well, `ellipso board flash IMAGE
//!   --port $ELLIPSO_BOARD` reboots it into its DFU bootloader, downloads, verifies and reboots
//!   it, and the board must answer again afterwards (within `REBOOT_WAIT`) with the same
//!   protocol version.
//!
//! Run: `ELLIPSO_BOARD=/dev/ttyACM0 cargo test -p ellipso-tests --test real_board -- --nocapture`.

use std::process::Command;
use std::time::{Duration, Instant};

use ellipso_tests::ellipso_bin;

/// How long a flashed board may take to come back on its serial port (the bootloader's
/// manifestation and the USB re-enumeration take a few seconds).
const REBOOT_WAIT: Duration = Duration::from_secs(20);

/// `devices --port PORT --json`: the port's probe, or the reason it failed.
fn probe(port: &str) -> Result<serde_json::Value, String> {
    let o = Command::new(ellipso_bin())
        .args(["devices", "--port", port, "--json"])
        .output()
        .map_err(|e| e.to_string())?;
    if !o.status.success() {
        return Err(String::from_utf8_lossy(&o.stderr).into_owned());
    }
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).map_err(|e| e.to_string())?;
    let ports = v["serial_ports"].as_array().cloned().unwrap_or_default();
    ports
        .into_iter()
        .find(|p| p["port"] == port)
        .map(|p| p["trigger_board"].clone())
        .ok_or_else(|| format!("{port} is not in the report: {v}"))
}

fn answers(board: &serde_json::Value) -> bool {
    board["answers"] == true && board["firmware"].is_string()
}

#[test]
fn a_real_board_answers_and_takes_a_firmware_image() {
    let Ok(port) = std::env::var("ELLIPSO_BOARD") else {
        eprintln!("ELLIPSO_BOARD is not set: no real trigger board to test (not run)");
        return;
    };
    let board = probe(&port).unwrap_or_else(|e| panic!("devices --port {port}: {e}"));
    assert!(
        answers(&board),
        "no trigger board answers on {port} (or its protocol differs from this ellipso's): {board}"
    );
    eprintln!(
        "{port}: board '{}', firmware {}, protocol {}",
        board["board_name"], board["firmware"], board["protocol_version"]
    );
    let Ok(image) = std::env::var("ELLIPSO_BOARD_FIRMWARE") else {
        eprintln!("ELLIPSO_BOARD_FIRMWARE is not set: the board is not flashed");
        return;
    };
    let o = Command::new(ellipso_bin())
        .args(["board", "flash", &image, "--port", &port])
        .output()
        .expect("run ellipso board flash");
    assert!(
        o.status.success(),
        "board flash {image} on {port} failed:\n{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let started = Instant::now();
    let after = loop {
        match probe(&port) {
            Ok(b) if answers(&b) => break b,
            other if started.elapsed() > REBOOT_WAIT => {
                panic!(
                    "the flashed board did not answer on {port} within {REBOOT_WAIT:?}: {other:?}"
                )
            }
            _ => std::thread::sleep(Duration::from_millis(500)),
        }
    };
    assert_eq!(
        after["protocol_version"], board["protocol_version"],
        "the flashed board speaks another protocol: {after}"
    );
}
