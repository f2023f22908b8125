//! ellipso trigger board on QEMU `netduinoplus2` — see the crate docs (`src/lib.rs`) for the
//! board's limits. USART1 RX interrupt → core; SysTick alarm → core; main loop → USART1 TX.
//!
//! Run it: `cargo run --release` (the runner line in `docs/rig.md`), or from the host's
//! end-to-end test `tests/tests/qemu_link.rs`.
#![no_std]
#![no_main]

use core::cell::RefCell;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::{entry, exception};
use critical_section::Mutex;
use ellipso_board_qemu::clock::{self, WideClock};
use ellipso_board_qemu::{GpioaPin, Port, pins, usart};
use ellipso_firmware::PinOutputs;
use pac::interrupt;
use panic_halt as _;
use stm32f4::stm32f405 as pac;

type QemuOutputs = PinOutputs<GpioaPin<0>, GpioaPin<1>>;

/// Everything the ISRs and the main loop share, under one critical section.
struct Shared {
    port: Port<QemuOutputs>,
    clock: WideClock,
}

static SHARED: Mutex<RefCell<Option<Shared>>> = Mutex::new(RefCell::new(None));

/// Runs `f` on the shared state, then re-arms SysTick for the core's next deadline.
fn with_port(f: impl FnOnce(&mut Port<QemuOutputs>, &mut WideClock)) {
    critical_section::with(|cs| {
        let mut shared = SHARED.borrow_ref_mut(cs);
        let Some(s) = shared.as_mut() else {
            return; // an interrupt before boot finished: nothing to do yet
        };
        f(&mut s.port, &mut s.clock);
        let now_us = s.clock.now_us();
        // SAFETY: SysTick is only touched here and at boot, always inside this critical section.
        let mut syst = unsafe { cortex_m::Peripherals::steal() }.SYST;
        clock::arm_systick(&mut syst, now_us, s.port.next_deadline());
    });
}

#[exception]
fn SysTick() {
    with_port(|port, clock| {
        // Armed ALARM_EARLY_US ahead: wait out the last µs so the edge lands on its deadline.
        let now = clock::spin_until(clock, port.next_deadline());
        port.on_alarm(now);
    });
}

#[interrupt]
fn USART1() {
    // SAFETY: USART1 DR/SR are read only here; TX writes DR only, which does not touch RXNE.
    let usart = unsafe { &*pac::USART1::ptr() };
    with_port(|port, clock| {
        while let Some(byte) = usart::try_read(usart) {
            port.on_rx_byte(byte, clock.now_us());
        }
    });
}

#[entry]
fn main() -> ! {
    let (Some(dp), Some(mut cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
        unreachable!("entry runs once")
    };

    // Clock enables are needed on silicon and ignored by QEMU. Never wait on RCC/FLASH/PWR ready
    // bits here: QEMU 7.2 reads them as 0 forever.
    dp.RCC.apb1enr().modify(|_, w| w.tim2en().set_bit());
    pins::configure_outputs(&dp.RCC, &dp.GPIOA);
    clock::start_tim2(&dp.TIM2);

    let mut clock = WideClock::new();
    let mut port = Port::new(PinOutputs::new(GpioaPin::<0>::new(), GpioaPin::<1>::new()));
    port.boot(clock.now_us());
    critical_section::with(|cs| SHARED.borrow_ref_mut(cs).replace(Shared { port, clock }));

    // The receiver is enabled last: every byte from now on finds a booted core.
    usart::init(&dp.RCC, &dp.GPIOA, &dp.USART1);
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.enable_interrupt();
    with_port(|_, _| {}); // arms SysTick
    // SAFETY: the handler only touches SHARED through a critical section.
    unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1) };

    let usart = &*dp.USART1;
    loop {
        let byte = critical_section::with(|cs| {
            let byte = SHARED
                .borrow_ref_mut(cs)
                .as_mut()
                .and_then(|s| s.port.pop_tx_byte());
            if byte.is_none() && !cfg!(feature = "qemu") {
                // Wakes on a pending interrupt even inside the critical section. Under QEMU 7.2
                // with -icount, WFI wakes 0.5-4 ms late, so the QEMU build busy-idles.
                cortex_m::asm::wfi();
            }
            byte
        });
        if let Some(byte) = byte {
            usart::write_blocking(usart, byte);
        }
    }
}
