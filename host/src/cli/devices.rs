//! `ellipso devices`: what the host can see and what answers — trigger boards (each USB serial
//! port, and every `--port`, asked `Hello` over the protocol with a short timeout: board name,
//! firmware and protocol version, board id = the USB serial number), boards waiting in their
//! DFU bootloader, V4L2 video devices, and, only when asked with `--gige`, GigE / USB3 Vision
//! cameras through aravis. One table, or `--json`.
//!
//! Contract: only USB serial ports (the trigger board is a USB CDC device) and the ports named
//! with `--port` are written to; other serial ports are listed, never probed. GigE discovery
//! broadcasts on every interface, so it is opt-in. A machine with nothing attached says so and
//! exits 0; a `--port` that does not exist is an error naming it.

use std::time::Duration;

use anyhow::bail;
use ellipso_rig::link::time::HostClock;
use ellipso_rig::link::{LinkConfig, LinkError, TriggerLink};
use serde_json::{Value, json};

/// How long a port may take to answer `Hello`. Derivation: the board answers within a few
/// milliseconds (one USB frame plus its handler); 300 ms is two orders of magnitude more and
/// keeps a scan of a few silent ports under a second or two.
pub const PROBE_TIMEOUT: Duration = Duration::from_millis(300);

/// Arguments of `ellipso devices`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Also discover GigE Vision cameras (broadcasts a discovery packet on every interface;
    /// needs a build with `--features aravis`).
    #[arg(long)]
    pub gige: bool,
    /// Also ask this port (a serial device or pty, e.g. the simulator's) whether a trigger board
    /// answers; may be given several times.
    #[arg(long = "port", value_name = "PATH")]
    pub ports: Vec<String>,
    /// Print JSON instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// Asks `path` for a trigger board's `Hello`; the JSON of what answered.
pub fn probe(path: &str) -> Value {
    let config = LinkConfig {
        reply_timeout: PROBE_TIMEOUT,
        retries: 0,
        ..LinkConfig::default()
    };
    match TriggerLink::open(path, HostClock::new(), config) {
        Ok(link) => {
            let b = link.board();
            let v = b.firmware_version;
            json!({
                "answers": true,
                "board_name": b.board_name.as_str(),
                "firmware": format!("{}.{}.{}", v.major, v.minor, v.patch),
                "protocol_version": b.protocol_version,
            })
        }
        Err(LinkError::VersionMismatch {
            board,
            host,
            board_name,
        }) => json!({
            "answers": true,
            "board_name": board_name,
            "protocol_version": board,
            "note": format!("protocol {board}, this ellipso speaks {host}: flash matching firmware"),
        }),
        Err(LinkError::Timeout { .. }) => {
            json!({"answers": false, "note": "no trigger board answered"})
        }
        Err(e) => json!({"answers": false, "note": e.to_string()}),
    }
}

/// Runs `ellipso devices`.
pub fn run(args: Args) -> anyhow::Result<()> {
    for p in &args.ports {
        if !p.starts_with("unix:") && !std::path::Path::new(p).exists() {
            bail!("--port {p}: no such device");
        }
    }
    let mut serial = Vec::new();
    match serialport::available_ports() {
        Ok(ports) => {
            for p in ports {
                let usb = match &p.port_type {
                    serialport::SerialPortType::UsbPort(u) => Some(json!({
                        "vid": format!("{:04x}", u.vid),
                        "pid": format!("{:04x}", u.pid),
                        "serial_number": u.serial_number,
                        "product": u.product,
                    })),
                    _ => None,
                };
                let board = if usb.is_some() || args.ports.contains(&p.port_name) {
                    probe(&p.port_name)
                } else {
                    json!({"answers": false, "note": "not probed (not a USB serial port)"})
                };
                serial.push(json!({"port": p.port_name, "usb": usb, "trigger_board": board}));
            }
        }
        Err(e) => tracing::warn!("cannot list serial ports: {e}"),
    }
    for p in &args.ports {
        if !serial.iter().any(|s| s["port"] == p.as_str()) {
            serial.push(json!({"port": p, "usb": null, "trigger_board": probe(p)}));
        }
    }
    let dfu: Vec<Value> = match ellipso_rig::dfu::usb::list_dfu_devices() {
        Ok(list) => list
            .into_iter()
            .map(|(vid, pid, at)| json!({"vid": format!("{vid:04x}"), "pid": format!("{pid:04x}"), "location": at}))
            .collect(),
        Err(e) => {
            tracing::warn!("cannot list USB devices: {e}");
            Vec::new()
        }
    };
    let mut videos: Vec<String> = std::fs::read_dir("/dev")
        .map(|d| {
            d.filter_map(Result::ok)
                .filter(|e| {
                    e.file_name()
                        .to_str()
                        .is_some_and(|n| n.starts_with("video"))
                })
                .map(|e| e.path().display().to_string())
                .collect()
        })
        .unwrap_or_default();
    videos.sort();
    let cameras = if args.gige { Some(gige()?) } else { None };
    let boards = serial
        .iter()
        .filter(|s| s["trigger_board"]["answers"] == true)
        .count();
    let nothing = boards == 0
        && dfu.is_empty()
        && videos.is_empty()
        && cameras.as_ref().is_none_or(|c| c.is_empty());
    let report = json!({
        "trigger_boards": boards,
        "serial_ports": serial,
        "dfu_bootloaders": dfu,
        "v4l2": videos,
        "cameras": cameras,
        "nothing_attached": nothing,
    });
    if args.json {
        crate::outln!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    print_table(&report, args.gige);
    Ok(())
}

fn print_table(r: &Value, gige: bool) {
    crate::outln!("{:<14} {:<28} {}", "KIND", "WHERE", "WHAT");
    let text = |v: &Value| v.as_str().unwrap_or("").to_string();
    for s in r["serial_ports"].as_array().into_iter().flatten() {
        let b = &s["trigger_board"];
        let usb = if s["usb"].is_null() {
            String::new()
        } else {
            format!(
                "USB {}:{} id {} ",
                text(&s["usb"]["vid"]),
                text(&s["usb"]["pid"]),
                s["usb"]["serial_number"].as_str().unwrap_or("-")
            )
        };
        let what = if b["answers"] == true {
            format!(
                "{usb}trigger board '{}', firmware {}, protocol {}{}",
                text(&b["board_name"]),
                b["firmware"].as_str().unwrap_or("?"),
                b["protocol_version"],
                b["note"]
                    .as_str()
                    .map(|n| format!(" ({n})"))
                    .unwrap_or_default()
            )
        } else {
            format!("{usb}{}", text(&b["note"]))
        };
        crate::outln!("{:<14} {:<28} {what}", "serial", text(&s["port"]));
    }
    for d in r["dfu_bootloaders"].as_array().into_iter().flatten() {
        crate::outln!(
            "{:<14} {:<28} USB {}:{} in DFU mode: `ellipso board flash FIRMWARE`",
            "dfu",
            text(&d["location"]),
            text(&d["vid"]),
            text(&d["pid"])
        );
    }
    for v in r["v4l2"].as_array().into_iter().flatten() {
        crate::outln!("{:<14} {:<28} video device", "v4l2", text(v));
    }
    match r["cameras"].as_array() {
        Some(cams) => {
            for c in cams {
                crate::outln!(
                    "{:<14} {:<28} {} {} (id {})",
                    "gige/u3v",
                    text(&c["address"]),
                    text(&c["vendor"]),
                    text(&c["model"]),
                    text(&c["id"])
                );
            }
        }
        None if !gige => crate::outln!(
            "{:<14} {:<28} not searched (discovery broadcasts on every interface; pass --gige)",
            "gige/u3v",
            "-"
        ),
        None => {}
    }
    if r["nothing_attached"] == true {
        crate::outln!(
            "nothing attached: no trigger board answered, no board in DFU mode, no camera found"
        );
    }
}

#[cfg(not(feature = "aravis"))]
fn gige() -> anyhow::Result<Vec<Value>> {
    anyhow::bail!(
        "--gige needs ellipso built with `--features aravis` (apt: pkg-config libaravis-dev)"
    )
}

#[cfg(feature = "aravis")]
fn gige() -> anyhow::Result<Vec<Value>> {
    Ok(ellipso_rig::camera::aravis::discover_gige_cameras()
        .into_iter()
        .map(|c| json!({"address": c.address, "vendor": c.vendor, "model": c.model, "id": c.id}))
        .collect())
}
