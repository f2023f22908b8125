//! `ellipso rig …`: the rig file a physical capture reads.
//!
//! - `rig init --out rig.toml`: a commented rig file for the named (or found) trigger board and
//!   camera; `[camera]` is left out until `ellipso calibrate` writes it.
//! - `rig check RIG.toml`: loads the file (every error names the key), loads its boards, asks
//!   the trigger board `Hello` and offers it the capture's timing, and says what to fix.
//!   `--fire [N]` also fires N test flashes through the capture ([`fire`]) and reports what
//!   they show ([`flash_check`]); without it the check says that no flash was fired.
//!
//! The fields, their units and ranges are documented in docs/rig-file.md.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context as _, bail};
use ellipso_capture::rig_file::RigFile;
use ellipso_rig::link::time::HostClock;
use ellipso_rig::link::{LinkConfig, LinkError, TriggerLink, describe_reject};

mod fire;
mod flash_check;

/// Subcommands of `ellipso rig`.
#[derive(Debug, clap::Subcommand)]
pub enum Args {
    /// Write a commented rig file to start from.
    Init(InitArgs),
    /// Check a rig file and the trigger board it names.
    Check(CheckArgs),
}

/// Camera families `rig init` knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Family {
    /// Sony IMX250MZR (monochrome polarisation) on GigE Vision, through aravis.
    Imx250mzrGige,
    /// Sony IMX250MYR (colour polarisation) on GigE Vision, through aravis.
    Imx250myrGige,
    /// A UVC polarisation camera through V4L2.
    V4l2,
}

/// Arguments of `ellipso rig init`.
#[derive(Debug, clap::Args)]
pub struct InitArgs {
    /// Where to write the rig file (refused if it exists, unless --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Camera family.
    #[arg(long, value_enum, default_value_t = Family::Imx250mzrGige)]
    pub camera: Family,
    /// The camera's address: its numeric IP (GigE) or /dev/videoN (V4L2).
    #[arg(long)]
    pub address: Option<String>,
    /// The trigger board's serial port; default: the first USB serial port where a trigger
    /// board answers, else /dev/ttyACM0.
    #[arg(long)]
    pub trigger: Option<String>,
    /// Board files of the capture (e.g. one `ellipso board new` wrote), relative paths taken
    /// from the current directory.
    #[arg(long = "board")]
    pub boards: Vec<PathBuf>,
    /// Overwrite an existing file.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `ellipso rig check`.
#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    /// Rig file.
    pub rig: PathBuf,
    /// Also fire N test flashes (1 to 50; 5 with a bare `--fire`) through the capture, into a
    /// temporary session removed afterwards, and report per flash its frame, where the flash
    /// fell in the exposure, the black level and saturation, then what to fix.
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "5",
          value_parser = fire::flashes)]
    pub fire: Option<u32>,
    /// With --fire: the simulated camera of this scene stands in for the rig file's camera, on
    /// the trigger wire of `ellipso sim serve --wire` (the rig file's port is its pty).
    #[arg(long, value_name = "SCENE", requires_all = ["wire", "fire"])]
    pub sim_camera: Option<PathBuf>,
    /// Trigger-wire socket of `ellipso sim serve --wire` (with --sim-camera).
    #[arg(long, value_name = "SOCKET", requires = "sim_camera")]
    pub wire: Option<PathBuf>,
    /// Render the stand-in camera at WIDTHxHEIGHT (with --sim-camera; even sides).
    #[arg(long, requires = "sim_camera", value_parser = super::limits::resolution)]
    pub resolution: Option<[u32; 2]>,
}

/// Runs `ellipso rig …`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args {
        Args::Init(a) => init(a),
        Args::Check(a) => check(a),
    }
}

/// The first USB serial port where a trigger board answers.
fn find_trigger() -> Option<String> {
    let ports = serialport::available_ports().ok()?;
    ports
        .into_iter()
        .filter(|p| matches!(p.port_type, serialport::SerialPortType::UsbPort(_)))
        .find(|p| super::devices::probe(&p.port_name)["answers"] == true)
        .map(|p| p.port_name)
}

/// The rig file text for `args` (board paths as written, relative to the rig file's folder).
pub fn template(family: Family, address: &str, trigger: &str, boards: &[String]) -> String {
    let (backend, layout, what) = match family {
        Family::Imx250mzrGige => ("aravis", "monopolar", "Sony IMX250MZR on GigE Vision"),
        Family::Imx250myrGige => ("aravis", "colourpolar", "Sony IMX250MYR on GigE Vision"),
        Family::V4l2 => ("v4l", "monopolar", "a UVC polarisation camera (V4L2)"),
    };
    let mut t = format!(
        r#"# ellipso rig file ({what}). Every field: docs/rig-file.md.
# Check it with `ellipso rig check THIS.toml`; capture with `ellipso capture --rig THIS.toml`.

[trigger]
# The trigger board: serial device (/dev/ttyACM0), pty, or unix:PATH. `ellipso devices` lists
# the ports where a board answers.
port = "{trigger}"

[sensor]
backend = "{backend}"          # aravis (GigE / USB3 Vision) | v4l (UVC)
# aravis: the camera's numeric IP address (never a name: names would need discovery);
# v4l: /dev/videoN
address = "{address}"
layout = "{layout}"            # monopolar (IMX250MZR) | colourpolar (IMX250MYR)
bit_depth = 12                 # 8 | 10 | 12 | 16 significant bits per sample
exposure_us = 8000             # µs, > 0; the flash fires inside it
gain_db = 0.0                  # dB, ≥ 0

[capture]
photos = 150                   # ≥ 1
interval_ms = 500.0            # ms between photos (free run), or the least between presses
trigger = "free_run"           # free_run | grip_button
flash_delay_us = 100           # µs from exposure start to flash on
flash_duration_us = 2000       # µs; delay + duration ≤ exposure_us

# [camera] is written by `ellipso calibrate SESSION --out camera.toml`: paste it here. Until
# then a capture records a provisional camera model (enough to calibrate from).
# [camera]
# width = 2448
# height = 2048
# fx = 3500.0 ...

# [flash] is written by `ellipso calibrate SESSION --sphere R,X,Y,Z`: the flash position in
# the camera frame (x right, y down, z forward), metres. The fit needs it.
# [flash]
# offset_m = [0.0, -0.03, 0.0]
"#
    );
    if boards.is_empty() {
        t.push_str(
            "\n# The AprilTag boards of the capture (print them with `ellipso board print`):\n\
             # [[boards]]\n# file = \"board.toml\"          # relative to this rig file\n\
             # translation_m = [0.0, 0.0, 0.0]\n# rotation_deg = [0.0, 0.0, 0.0]\n",
        );
    }
    for b in boards {
        t.push_str(&format!(
            "\n[[boards]]\nfile = \"{b}\"  # relative to this rig file\n\
             translation_m = [0.0, 0.0, 0.0]  # world from board, m\n\
             rotation_deg = [0.0, 0.0, 0.0]   # world from board, XYZ Euler angles, degrees\n"
        ));
    }
    t
}

/// `path` relative to the folder `base` (both absolute): `..` up to their common part.
fn relative(path: &std::path::Path, base: &std::path::Path) -> PathBuf {
    let (p, b): (Vec<_>, Vec<_>) = (path.components().collect(), base.components().collect());
    let common = p.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut out = PathBuf::new();
    for _ in common..b.len() {
        out.push("..");
    }
    for c in &p[common..] {
        out.push(c);
    }
    out
}

fn init(args: InitArgs) -> anyhow::Result<()> {
    if args.out.exists() && !args.force {
        bail!(
            "--out {}: the file exists (pass --force to overwrite it)",
            args.out.display()
        );
    }
    let address = args.address.clone().unwrap_or_else(|| match args.camera {
        Family::V4l2 => "/dev/video0".into(),
        _ => "192.168.10.2".into(),
    });
    let trigger = match &args.trigger {
        Some(t) => t.clone(),
        None => find_trigger().unwrap_or_else(|| {
            crate::errln!("no trigger board answered on a USB serial port: writing /dev/ttyACM0");
            "/dev/ttyACM0".into()
        }),
    };
    let folder = args
        .out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let folder_abs = std::path::absolute(folder)?;
    let mut boards = Vec::new();
    for b in &args.boards {
        ellipso_sim::scene::load_board_file(b)
            .with_context(|| format!("--board {}", b.display()))?;
        let rel = relative(&std::path::absolute(b)?, &folder_abs);
        boards.push(rel.display().to_string());
    }
    let text = template(args.camera, &address, &trigger, &boards);
    ellipso_report::atomic_file::write(&args.out, &text)
        .with_context(|| format!("writing {}", args.out.display()))?;
    // what was written must load: a template that does not is a bug, said at once
    if let Err(e) = RigFile::load(&args.out) {
        let _ = std::fs::remove_file(&args.out);
        bail!("the written rig file does not load back: {e}");
    }
    crate::outln!(
        "wrote {} (trigger {trigger}, camera {address}); next: `ellipso rig check {}`",
        args.out.display(),
        args.out.display()
    );
    Ok(())
}

fn check(args: CheckArgs) -> anyhow::Result<()> {
    let rig = RigFile::load(&args.rig)?;
    let mut todo = check_file(&args, &rig)?;
    let timing_ok = check_board(&args, &rig, &mut todo)?;
    let fire_fixes = fire_test_flashes(&args, &rig, timing_ok)?;
    verdict(&args, &todo, &fire_fixes)
}

/// The loaded rig file said: its boards (with their tag count) and camera. Returns the to-do
/// for what it lacks (boards, camera, flash).
fn check_file(args: &CheckArgs, rig: &RigFile) -> anyhow::Result<Vec<String>> {
    let boards = ellipso_capture::hardware::rig_of_file(rig, None)
        .map_err(|e| anyhow::anyhow!("{e}"))?
        .boards;
    crate::outln!("rig file {}: loads", args.rig.display());
    crate::outln!(
        "  boards: {} ({} tags)",
        boards.len(),
        boards
            .iter()
            .map(|b| b.corners_board_m.len())
            .sum::<usize>()
    );
    let mut todo: Vec<String> = Vec::new();
    if boards.is_empty() {
        todo.push("add the [[boards]] of the capture (poses need them)".into());
    }
    match &rig.camera {
        Some(c) => crate::outln!(
            "  camera: {}×{}, fx {:.1} px",
            c.width,
            c.height,
            c.intrinsics.fx
        ),
        None => todo.push(
            "calibrate the camera (`ellipso calibrate SESSION --out camera.toml`) and paste its \
             [camera]"
                .into(),
        ),
    }
    if rig.flash.is_none() {
        todo.push(
            "measure the flash (`ellipso calibrate SESSION --sphere R,X,Y,Z`) and paste its \
             [flash]: the fit needs it"
                .into(),
        );
    }
    Ok(todo)
}

/// The trigger board on `trigger.port`: it must answer `Hello` (said), then is offered the
/// capture's timing; a refusal goes to `todo`. Returns whether the board accepts the timing.
/// The port is closed again on return.
fn check_board(args: &CheckArgs, rig: &RigFile, todo: &mut Vec<String>) -> anyhow::Result<bool> {
    let port = &rig.trigger.port;
    if !port.starts_with("unix:") && !std::path::Path::new(port).exists() {
        bail!(
            "{}: `trigger.port` {port}: no such device (`ellipso devices` lists the ports where a \
             board answers)",
            args.rig.display()
        );
    }
    let config = LinkConfig {
        reply_timeout: Duration::from_millis(500),
        retries: 1,
        ..LinkConfig::default()
    };
    let link = match TriggerLink::open(port, HostClock::new(), config) {
        Ok(l) => l,
        Err(e @ LinkError::Timeout { .. }) => bail!(
            "{}: `trigger.port` {port}: no trigger board answers ({e}); is it the right port, and \
             is the ellipso firmware flashed (`ellipso board flash`)?",
            args.rig.display()
        ),
        Err(e) => bail!("{}: `trigger.port` {port}: {e}", args.rig.display()),
    };
    let b = link.board();
    let v = b.firmware_version;
    crate::outln!(
        "  trigger board on {port}: '{}', firmware {}.{}.{}, protocol {}",
        b.board_name,
        v.major,
        v.minor,
        v.patch,
        b.protocol_version
    );
    let mut timing_ok = false;
    match link.configure(rig.board_config()) {
        Ok(()) => {
            timing_ok = true;
            crate::outln!(
                "  the board accepts the capture timing: exposure {} µs, flash {} µs after its start \
             for {} µs, one photo per {} ms",
                rig.sensor.exposure_us,
                rig.capture.flash_delay_us,
                rig.capture.flash_duration_us,
                rig.capture.interval_ms
            )
        }
        Err(LinkError::Rejected { reason, .. }) => todo.push(format!(
            "the board refuses the capture timing: {} (fix [capture] / sensor.exposure_us)",
            describe_reject(&reason)
        )),
        Err(e) => bail!(
            "{}: configuring the board on {port}: {e}",
            args.rig.display()
        ),
    }
    drop(link); // the capture of --fire opens the port again
    Ok(timing_ok)
}

/// `--fire N`: N test flashes fired through the capture ([`fire`]) and what they show said;
/// returns what to fix. Without it (or when the board refuses the timing) it says that no flash
/// was fired.
fn fire_test_flashes(
    args: &CheckArgs,
    rig: &RigFile,
    timing_ok: bool,
) -> anyhow::Result<Vec<String>> {
    let camera = format!(
        "{} at {}",
        match rig.sensor.backend {
            ellipso_capture::rig_file::Backend::Aravis => "aravis",
            ellipso_capture::rig_file::Backend::V4l => "v4l",
        },
        rig.sensor.address
    );
    let mut fire_fixes = Vec::new();
    match args.fire {
        None => crate::outln!(
            "  flashes: none fired, camera {camera} not opened (`--fire` fires 5 test flashes \
             and checks pairing, flash timing, black level and saturation)"
        ),
        Some(_) if !timing_ok => {
            crate::outln!("  flashes: none fired: the board refuses the capture timing (below)")
        }
        Some(n) => {
            let stand_in = match (&args.sim_camera, &args.wire) {
                (Some(scene), Some(wire)) => Some(fire::SimStandIn {
                    scene: scene.clone(),
                    wire: wire.clone(),
                    resolution: args.resolution,
                }),
                _ => None,
            };
            let who = match &stand_in {
                Some(s) => format!("the simulated camera of {}", s.scene.display()),
                None => format!("camera {camera}"),
            };
            crate::outln!("  firing {n} test flashes (free run) with {who}");
            let check = fire::fire(rig, n, stand_in.as_ref()).context("firing test flashes")?;
            crate::outln!("  flashes: {} of {n} paired with a frame", check.paired());
            for line in check.lines() {
                crate::outln!("    {line}");
            }
            let (fixes, notes) = check.fixes();
            for n in notes {
                crate::outln!("  note: {n}");
            }
            fire_fixes = fixes;
        }
    }
    Ok(fire_fixes)
}

/// The check's end: what the test flashes found to fix (an error) with the rest of the to-do,
/// else ready to capture or the to-do before a fit.
fn verdict(args: &CheckArgs, todo: &[String], fire_fixes: &[String]) -> anyhow::Result<()> {
    if !fire_fixes.is_empty() {
        crate::outln!("fix before capturing:");
        for f in fire_fixes {
            crate::outln!("  - {f}");
        }
        for t in todo {
            crate::outln!("  - {t}");
        }
        bail!(
            "{}: the test flashes found {} problem(s), listed above",
            args.rig.display(),
            fire_fixes.len()
        );
    }
    if todo.is_empty() {
        crate::outln!(
            "ready to capture: `ellipso capture --rig {}`",
            args.rig.display()
        );
    } else {
        crate::outln!("to do before a fit:");
        for t in todo {
            crate::outln!("  - {t}");
        }
    }
    Ok(())
}
