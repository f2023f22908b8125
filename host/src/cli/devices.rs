//! `ellipso devices`: what the host can see — serial ports (trigger boards), V4L2 video devices,
//! and, only when asked with `--gige`, GigE Vision cameras.
//!
//! GigE discovery broadcasts on every network interface, so it is opt-in and never a default;
//! serial and V4L2 listing only read the local device tree.

/// Arguments of `ellipso devices`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Also discover GigE Vision cameras (broadcasts a discovery packet on every interface;
    /// needs a build with `--features aravis`).
    #[arg(long)]
    pub gige: bool,
}

/// Runs `ellipso devices`.
pub fn run(args: Args) -> anyhow::Result<()> {
    crate::outln!("serial ports (trigger boards):");
    match serialport::available_ports() {
        Ok(ports) if ports.is_empty() => {
            crate::outln!("  none found (pseudo-terminals are not listed; open them by path)")
        }
        Ok(ports) => {
            for p in ports {
                let kind = match p.port_type {
                    serialport::SerialPortType::UsbPort(u) => format!(
                        "USB {:04x}:{:04x} {}",
                        u.vid,
                        u.pid,
                        u.product.unwrap_or_default()
                    ),
                    serialport::SerialPortType::PciPort => "PCI".into(),
                    serialport::SerialPortType::BluetoothPort => "Bluetooth".into(),
                    serialport::SerialPortType::Unknown => "unknown".into(),
                };
                crate::outln!("  {}  {kind}", p.port_name);
            }
        }
        Err(e) => crate::outln!("  cannot list serial ports: {e}"),
    }
    crate::outln!("video devices (V4L2):");
    let mut videos: Vec<_> = std::fs::read_dir("/dev")
        .map(|d| {
            d.filter_map(Result::ok)
                .map(|e| e.path())
                .filter(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with("video"))
                })
                .collect()
        })
        .unwrap_or_default();
    videos.sort();
    if videos.is_empty() {
        crate::outln!("  none found");
    }
    for v in videos {
        crate::outln!("  {}", v.display());
    }
    if args.gige {
        gige()?;
    } else {
        crate::outln!(
            "GigE Vision cameras: not searched (discovery broadcasts on every interface; pass --gige)"
        );
    }
    Ok(())
}

#[cfg(not(feature = "aravis"))]
fn gige() -> anyhow::Result<()> {
    anyhow::bail!(
        "--gige needs ellipso built with `--features aravis` (apt: pkg-config libaravis-dev)"
    )
}

#[cfg(feature = "aravis")]
fn gige() -> anyhow::Result<()> {
    crate::outln!("GigE Vision / USB3 Vision cameras (discovery broadcast sent):");
    let cameras = ellipso_rig::camera::aravis::discover_gige_cameras();
    if cameras.is_empty() {
        crate::outln!("  none answered");
    }
    for c in cameras {
        crate::outln!(
            "  {}  {} {}  (id {}; open it by this address)",
            c.address,
            c.vendor,
            c.model,
            c.id
        );
    }
    Ok(())
}
