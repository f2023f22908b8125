//! `ellipso board flash FIRMWARE`: updates the trigger board's firmware over USB.
//!
//! With `--port`, the running board is first asked over the protocol to reboot into its DFU
//! bootloader ([`ellipso_rig::link::TriggerLink::enter_bootloader`]); without it, the board must
//! already be in DFU mode (BOOT0 held at reset). The image is then erased, written (vector table
//! last), read back and, only when it reads back equal, started — see
//! [`ellipso_rig::dfu`] for what keeps a failed update from leaving a board that cannot be
//! flashed again. `--model` runs the same download against the DfuSe device model instead of
//! USB (what the test suite and the simulated-rig walkthrough use).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context as _, bail};
use ellipso_rig::dfu::dfuse::{DfuSe, Phase};
use ellipso_rig::dfu::{DfuTransport, model::DfuSeModel, usb::UsbDfu};
use ellipso_rig::link::time::HostClock;
use ellipso_rig::link::{LinkConfig, TriggerLink};

/// Largest firmware file read (the STM32F411's flash is 512 KiB; twice that is surely wrong).
const MAX_IMAGE_BYTES: u64 = 1 << 20;

/// How long the bootloader may take to show up on USB after the reboot command. Derivation:
/// the reset takes milliseconds; USB enumeration of a full-speed device takes up to about 1 s
/// with a hub; 10 s covers a slow host's device scan several times over.
const ENUMERATION_TIMEOUT: Duration = Duration::from_secs(10);

/// Arguments of `ellipso board flash`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Firmware image: a raw binary linked for 0x08000000 (`cargo objcopy --release -- -O
    /// binary ellipso-board.bin` in firmware/boards/blackpill).
    pub firmware: PathBuf,
    /// Serial port of the running board: ask it to reboot into DFU first. Without it the board
    /// must already be in DFU mode.
    #[arg(long)]
    pub port: Option<String>,
    /// Flash the DfuSe device model instead of a USB device (tests, the simulated rig).
    #[arg(long)]
    pub model: bool,
}

/// Runs `ellipso board flash`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let size = std::fs::metadata(&args.firmware)
        .with_context(|| format!("firmware {}", args.firmware.display()))?
        .len();
    if size > MAX_IMAGE_BYTES {
        bail!(
            "firmware {}: {size} bytes, more than any trigger board's flash",
            args.firmware.display()
        );
    }
    let image = std::fs::read(&args.firmware)
        .with_context(|| format!("firmware {}", args.firmware.display()))?;
    if image.starts_with(b"\x7fELF") {
        bail!(
            "firmware {}: an ELF file, not a raw binary: convert it with `cargo objcopy --release \
             -- -O binary ellipso-board.bin` (or arm-none-eabi-objcopy -O binary)",
            args.firmware.display()
        );
    }
    if let Some(port) = &args.port {
        let config = LinkConfig {
            reply_timeout: Duration::from_millis(500),
            retries: 1,
            ..LinkConfig::default()
        };
        let link = TriggerLink::open(port, HostClock::new(), config)
            .with_context(|| format!("trigger board on {port}"))?;
        link.enter_bootloader().with_context(|| {
            format!(
                "asking the board on {port} ({} firmware {}.{}.{}) to reboot into DFU (firmware \
                 older than this command: hold BOOT0 while pressing reset, then run `ellipso \
                 board flash` without --port)",
                link.board().board_name,
                link.board().firmware_version.major,
                link.board().firmware_version.minor,
                link.board().firmware_version.patch
            )
        })?;
        crate::errln!("{port}: the board is rebooting into its DFU bootloader");
    }
    if args.model {
        let mut model = DfuSeModel::stm32f411();
        flash(&mut model, &image, &args)?;
        return Ok(());
    }
    let usb = if args.port.is_some() {
        UsbDfu::wait_for_stm32(ENUMERATION_TIMEOUT)
    } else {
        UsbDfu::open_stm32()
    }?;
    flash(usb, &image, &args)
}

fn flash<T: DfuTransport>(transport: T, image: &[u8], args: &Args) -> anyhow::Result<()> {
    let mut dfu = DfuSe::new(transport)?;
    let location = dfu.identity().location.clone();
    let mut last = None;
    let report = dfu
        .flash(image, &mut |phase, done, total| {
            if done == total && last != Some(phase) {
                last = Some(phase);
                let what = match phase {
                    Phase::Erase => "erased",
                    Phase::Write => "written",
                    Phase::Verify => "verified",
                };
                crate::errln!("  {what}: {total}");
            }
        })
        .map_err(|e| {
            anyhow::anyhow!(
                "{e}; the board is still in its DFU bootloader (nothing was started): run `ellipso \
                 board flash {}` again",
                args.firmware.display()
            )
        })?;
    crate::outln!(
        "flashed {} ({} bytes, {} sectors erased, {} blocks written and read back) to the board at \
         {location}; it is starting the new firmware",
        args.firmware.display(),
        report.bytes,
        report.sectors_erased,
        report.blocks
    );
    Ok(())
}
