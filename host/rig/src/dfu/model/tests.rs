//! `DfuSe` against the device model: a good image, and each failure leaving the board in its
//! bootloader.

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::dfu::dfuse::{DfuError, DfuSe, Phase};

/// A firmware-like image: a vector table (stack in SRAM, reset handler inside the image) and
/// seeded random bytes.
fn image(len: usize) -> Vec<u8> {
    let mut v = vec![0u8; len];
    ChaCha8Rng::seed_from_u64(45).fill_bytes(&mut v);
    v[0..4].copy_from_slice(&0x2002_0000u32.to_le_bytes());
    v[4..8].copy_from_slice(&0x0800_0199u32.to_le_bytes());
    v
}

fn flash(model: &mut DfuSeModel, img: &[u8]) -> Result<(), DfuError> {
    let mut dfu = DfuSe::new(model)?;
    dfu.flash(img, &mut |_, _, _| {}).map(|_| ())
}

#[test]
fn a_good_image_is_written_verified_and_started() {
    let mut m = DfuSeModel::stm32f411();
    // 70 KiB spans the four 16 KiB sectors and the 64 KiB one
    let img = image(70 * 1024 + 123);
    let mut phases = Vec::new();
    let report = {
        let mut dfu = DfuSe::new(&mut m).expect("an STM32 bootloader");
        dfu.flash(&img, &mut |p, done, total| {
            if done == total {
                phases.push(p)
            }
        })
        .expect("flashes")
    };
    assert_eq!(phases, [Phase::Erase, Phase::Write, Phase::Verify]);
    assert_eq!(report.sectors_erased, 5);
    assert_eq!(report.blocks, 36);
    assert_eq!(&m.flash()[..img.len()], &img[..]);
    assert_eq!(m.running(), Running::Application);
    // erases were waited for as the device asked: 4 × 16 KiB + 64 KiB at 8 ms/KiB
    assert!(m.clock_ms() >= 8 * 128, "{}", m.clock_ms());
}

#[test]
fn a_corrupt_image_is_refused_before_anything_is_erased() {
    let mut m = DfuSeModel::stm32f411();
    flash(&mut m, &image(4096)).expect("first image");
    m.enter_bootloader();
    let before = m.flash().to_vec();
    for (bad, why) in [
        (vec![0u8; 4], "shorter than a vector table"),
        (
            {
                let mut v = image(4096);
                v[3] = 0x7f;
                v
            },
            "stack pointer",
        ),
        (
            {
                let mut v = image(4096);
                v[4..8].copy_from_slice(&0x0900_0001u32.to_le_bytes());
                v
            },
            "reset vector",
        ),
        (image(600 * 1024), "do not fit"),
    ] {
        let e = flash(&mut m, &bad).expect_err("refused");
        assert!(
            matches!(e, DfuError::Image(_)) && e.to_string().contains(why),
            "{e}"
        );
        assert_eq!(m.flash(), &before[..], "nothing erased");
        assert_eq!(m.running(), Running::Bootloader);
    }
}

#[test]
fn a_wrong_device_is_refused() {
    let mut other = DfuSeModel::with_identity(DeviceIdentity {
        vid: 0x1d50,
        pid: 0x6017,
        layout: STM32F411_LAYOUT.into(),
        transfer_size: 1024,
        location: "bus 1 address 7".into(),
    });
    let e = flash(&mut other, &image(4096)).expect_err("not ST's bootloader");
    assert!(
        e.to_string().contains("1d50:6017 at bus 1 address 7"),
        "{e}"
    );
    let mut option_bytes = DfuSeModel::with_identity(DeviceIdentity {
        layout: "@Option Bytes  /0x1FFFC000/01*016 e".into(),
        ..DfuSeModel::stm32f411().identity()
    });
    let e = flash(&mut option_bytes, &image(4096)).expect_err("not the flash");
    assert!(e.to_string().contains("Option Bytes"), "{e}");
}

/// Every failure of the download itself leaves a board that comes back in its bootloader and
/// takes the next flash.
fn recovers(m: &mut DfuSeModel, img: &[u8]) {
    assert_ne!(
        m.running(),
        Running::Application,
        "never started a partial image"
    );
    m.power_cycle();
    assert_eq!(
        m.running(),
        Running::Bootloader,
        "vector table still erased: the board comes up in DFU"
    );
    flash(m, img).expect("the next flash succeeds");
    assert_eq!(m.running(), Running::Application);
}

#[test]
fn an_interrupted_download_leaves_the_board_in_dfu() {
    let img = image(100 * 1024);
    let mut m = DfuSeModel::stm32f411();
    m.inject(Fault::DisconnectAfterBlocks(20));
    let e = flash(&mut m, &img).expect_err("cable pulled");
    assert!(
        matches!(&e, DfuError::NotAnswering { source: TransportError::Disconnected, during } if during.contains("block")),
        "{e}"
    );
    assert_eq!(m.running(), Running::Gone);
    assert_eq!(&m.flash()[..4], &[0xff; 4], "vector table not written yet");
    recovers(&mut m, &img);
}

#[test]
fn a_board_that_stops_answering_is_a_clear_error() {
    let img = image(40 * 1024);
    let mut m = DfuSeModel::stm32f411();
    m.inject(Fault::StopAnsweringAfter(30));
    let e = flash(&mut m, &img).expect_err("hangs");
    assert!(
        matches!(
            &e,
            DfuError::NotAnswering {
                source: TransportError::Timeout(_),
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("stopped answering"), "{e}");
    recovers(&mut m, &img);
}

#[test]
fn write_errors_and_bad_read_back_stop_before_the_leave() {
    let img = image(40 * 1024);
    let mut m = DfuSeModel::stm32f411();
    m.inject(Fault::WriteErrorAtBlock(3));
    let e = flash(&mut m, &img).expect_err("errPROG");
    assert!(matches!(e, DfuError::Device { status: 0x06, .. }), "{e}");
    assert!(e.to_string().contains("errPROG"), "{e}");
    recovers(&mut m, &img);

    let mut m = DfuSeModel::stm32f411();
    m.inject(Fault::CorruptByteAt(FLASH_BASE + 5000));
    let e = flash(&mut m, &img).expect_err("verify");
    assert!(
        matches!(e, DfuError::Verify { address, .. } if address == FLASH_BASE + 5000),
        "{e}"
    );
    // the vector table was written (last), so this board would boot a bad image: it was not
    // started, and the next flash rewrites it
    assert_eq!(m.running(), Running::Bootloader);
    m.enter_bootloader(); // the cause gone (a fresh attempt), still in DFU
    flash(&mut m, &img).expect("reflash");
    assert_eq!(&m.flash()[..img.len()], &img[..]);
}

#[test]
fn the_state_machine_refuses_out_of_order_requests_and_the_host_recovers() {
    let mut m = DfuSeModel::stm32f411();
    let mut status = [0u8; 6];
    // UPLOAD while a download is pending: stalled, dfuERROR
    m.control_out(crate::dfu::request::DNLOAD, 0, &[0x21, 0, 0, 0, 8])
        .expect("set address");
    assert_eq!(
        m.control_in(crate::dfu::request::UPLOAD, 2, &mut [0u8; 16]),
        Err(TransportError::Stall)
    );
    m.control_in(crate::dfu::request::GETSTATUS, 0, &mut status)
        .expect("status");
    assert_eq!(status[4], DfuState::Error as u8);
    assert_eq!(status[0], 0x0f);
    // a block-1 download is not DfuSe
    let mut m2 = DfuSeModel::stm32f411();
    assert_eq!(
        m2.control_out(crate::dfu::request::DNLOAD, 1, &[1]),
        Err(TransportError::Stall)
    );
    // an address outside the flash
    let mut m3 = DfuSeModel::stm32f411();
    m3.control_out(crate::dfu::request::DNLOAD, 0, &[0x21, 0, 0, 0, 0x09])
        .expect("queued");
    m3.control_in(crate::dfu::request::GETSTATUS, 0, &mut status)
        .expect("status");
    assert_eq!((status[0], status[4]), (0x08, DfuState::Error as u8));
    // the host starts from dfuERROR without help
    let img = image(8192);
    flash(&mut m, &img).expect("from dfuERROR");
    assert_eq!(m.running(), Running::Application);
}
