//! ellipso trigger board on a WeAct **STM32F411CE "Black Pill"** (25 MHz HSE), embassy-stm32 +
//! embassy-usb. Compile-checked in CI; embassy-stm32 cannot boot in QEMU (no RCC model) and QEMU
//! has no USB device model, so the sync core's logic is tested on the host and on the QEMU board.
//!
//! # Board limits
//!
//! - **Link:** USB full-speed CDC-ACM (PA11/PA12), frames written in packets of ≤ 63 bytes so no
//!   zero-length packet is ever needed. The baud rate the host sets is ignored.
//! - **Clock:** TIM2 (32-bit) at 1 MHz from the 96 MHz APB1 timer clock: 1 µs edge resolution,
//!   64-bit extension kept alive by a 1 s heartbeat (TIM2 wraps every 71.6 min).
//! - **Edges:** by TIM2 output compare in hardware — camera trigger on CH3 (PA2), flash on CH4
//!   (PA3); see `edges.rs`. The flash's off-edge is always programmed in the timer before the
//!   firmware moves on, so a stalled CPU cannot hold the LED on past `max_flash_on_us`.
//!   A deadline under 3 µs away is executed in software and reported with its real time.
//! - **Grip button:** PA0 (the Black Pill's KEY button, or an external one to GND), pull-up,
//!   falling edge on EXTI0; bounces are filtered by the core (one frame period).
//! - **Status LED:** PC13, active low: slow blink idle, solid configured/armed, fast blink
//!   running, double blink after any fault counter moved.
//! - **Exposure-active input:** PA15 (TIM2 CH1) is wired for input capture (`docs/rig.md`) but not
//!   yet used by this firmware.
//! - **Limits:** the LED rig defaults of `ellipso_firmware::LED_RIG_LIMITS`.
//! - **Firmware update:** `EnterBootloader` (after its `Ack` has gone out) writes a magic word to
//!   RAM that survives a reset and resets; the next boot sees it before any clock or peripheral
//!   is set up and jumps to the STM32's ROM DFU bootloader (0x1FFF0000, AN2606), which
//!   `ellipso board flash` then talks to over USB.
//!
//! # Clock tree (`clock_config`)
//!
//! `SYSCLK = HSE / PLLM · PLLN / PLLP = 25 MHz / 25 · 192 / 2 = 96 MHz`;
//! `USB = HSE / PLLM · PLLN / PLLQ = 25 / 25 · 192 / 4 = 48 MHz` (required exactly);
//! `HCLK = 96 MHz` (AHB /1), `APB1 = 48 MHz` (/2, its limit is 50 MHz), `APB2 = 96 MHz` (/1);
//! APB1 timers run at `2 · APB1 = 96 MHz`, so TIM2's `PSC = 96 − 1` gives 1 MHz.
#![no_std]
#![no_main]

mod edges;

use core::cell::RefCell;

use critical_section::Mutex;
use ellipso_firmware::{Board, BoardConfig, FrameWriter, parse_version};
use ellipso_protocol::{BoardState, FirmwareVersion, MAX_FRAME_LEN};
use embassy_executor::Spawner;
use embassy_stm32::exti::{self, ExtiInput};
use embassy_stm32::gpio::{Level, Output, OutputType, Pull, Speed};
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::pac::interrupt;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::{Config, bind_interrupts, peripherals, usb};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Ticker, Timer};
use embassy_usb::Builder;
use embassy_usb::class::cdc_acm::{self, CdcAcmClass};
use panic_halt as _;
use static_cell::StaticCell;

use edges::{MIN_LEAD_US, TimerOutputs, next_edge};

bind_interrupts!(struct Irqs {
    OTG_FS => usb::InterruptHandler<peripherals::USB_OTG_FS>;
    EXTI0 => exti::InterruptHandler<embassy_stm32::interrupt::typelevel::EXTI0>;
});

/// The name sent in `HelloReply`.
const BOARD_NAME: &str = "blackpill-f411";
/// TIM2's input clock with [`clock_config`], Hz.
const TIM2_CLOCK_HZ: u32 = 96_000_000;
/// The device clock, Hz.
const DEVICE_CLOCK_HZ: u32 = 1_000_000;
/// Transmit queue, bytes: two worst-case pulse bursts (see the core's port guide).
const TX_QUEUE_BYTES: usize = 8 * MAX_FRAME_LEN;
/// Largest USB packet written: one less than the endpoint's 64, so a transfer always ends with a
/// short packet and never needs a zero-length one.
const USB_PACKET: usize = 63;

const FIRMWARE_VERSION: FirmwareVersion = match parse_version(env!("CARGO_PKG_VERSION")) {
    Some(v) => v,
    None => panic!("CARGO_PKG_VERSION is not MAJOR.MINOR.PATCH"),
};

type TxBytes = heapless::Deque<u8, TX_QUEUE_BYTES>;

/// The core, its outputs and queue, and the clock, shared by the TIM2 interrupt and the tasks.
struct Shared {
    board: Board,
    outputs: TimerOutputs,
    tx: FrameWriter<TxBytes>,
    clock_high: u32,
    clock_last: u32,
}

impl Shared {
    /// TIM2 extended to 64 bits, µs.
    fn now_us(&mut self) -> u64 {
        let count = edges::read_count();
        if count < self.clock_last {
            self.clock_high = self.clock_high.wrapping_add(1);
        }
        self.clock_last = count;
        (u64::from(self.clock_high) << 32) | u64::from(count)
    }

    /// A 32-bit compare value that has just matched, as a 64-bit time (it lies in the past).
    fn past_time_of(&mut self, compare: u32) -> u64 {
        let now = self.now_us();
        now - u64::from((now as u32).wrapping_sub(compare))
    }

    /// Hands the core's next edge to the timer, executing in software what is too close.
    fn schedule(&mut self) {
        loop {
            let Some(deadline) = self.board.next_deadline() else {
                self.outputs.disarm();
                return;
            };
            let now = self.now_us();
            if deadline > now + MIN_LEAD_US {
                let edge = next_edge(
                    self.board.sequencer(),
                    self.outputs.t_trigger_us(),
                    deadline,
                );
                self.outputs.arm(edge, deadline);
                return;
            }
            // Too close (or past) for the compare unit: run it now, at most MIN_LEAD_US early
            // waits, and let the core judge lateness.
            let mut now = now;
            while now < deadline {
                now = self.now_us();
            }
            self.board.poll(now, &mut self.outputs, &mut self.tx);
        }
    }
}

static SHARED: Mutex<RefCell<Option<Shared>>> = Mutex::new(RefCell::new(None));
/// Raised whenever bytes were queued for the host.
static TX_READY: Signal<CriticalSectionRawMutex, ()> = Signal::new();

fn with_shared<R>(f: impl FnOnce(&mut Shared) -> R) -> Option<R> {
    let r = critical_section::with(|cs| {
        let mut shared = SHARED.borrow_ref_mut(cs);
        let s = shared.as_mut()?;
        let r = f(s);
        s.schedule();
        Some(r)
    });
    TX_READY.signal(());
    r
}

/// TIM2 compare: a pin just moved in hardware; tell the core, at the compare time.
#[interrupt]
fn TIM2() {
    let tim = embassy_stm32::pac::TIM2;
    let sr = tim.sr().read();
    let dier = tim.dier().read();
    let fired = [edges::CAMERA_CH, edges::FLASH_CH].map(|ch| (ch, sr.ccif(ch) && dier.ccie(ch)));
    let mut clear = embassy_stm32::pac::timer::regs::SrGp16(u32::MAX);
    for (ch, _) in fired.iter().filter(|(_, f)| *f) {
        clear.set_ccif(*ch, false);
    }
    tim.sr().write_value(clear);
    with_shared(|s| {
        for (ch, _) in fired.into_iter().filter(|(_, f)| *f) {
            tim.dier().modify(|w| w.set_ccie(ch, false));
            let t = s.past_time_of(tim.ccr(ch).read());
            s.board.poll(t, &mut s.outputs, &mut s.tx);
        }
    });
}

fn clock_config() -> Config {
    use embassy_stm32::rcc::{
        AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPDiv, PllPreDiv, PllQDiv,
        PllSource, Sysclk, mux,
    };
    let mut config = Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(25_000_000),
        mode: HseMode::Oscillator,
    });
    config.rcc.pll_src = PllSource::HSE;
    config.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV25,
        mul: PllMul::MUL192,
        divp: Some(PllPDiv::DIV2), // 96 MHz SYSCLK
        divq: Some(PllQDiv::DIV4), // 48 MHz USB
        divr: None,
    });
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV2;
    config.rcc.apb2_pre = APBPrescaler::DIV1;
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.mux.clk48sel = mux::Clk48sel::PLL1_Q;
    config
}

/// Written before the reset that asks for the DFU bootloader ("DFU!" in ASCII).
const DFU_MAGIC: u32 = 0x2155_4644;

/// A RAM word cortex-m-rt neither zeroes nor initialises, so it survives a software reset.
#[unsafe(link_section = ".uninit.ELLIPSO_DFU")]
static mut DFU_REQUEST: core::mem::MaybeUninit<u32> = core::mem::MaybeUninit::uninit();

/// Resets into the ROM bootloader (see the module doc).
fn reboot_into_bootloader() -> ! {
    // SAFETY: a plain volatile write of a word this firmware owns; nothing else touches it.
    unsafe { core::ptr::write_volatile((&raw mut DFU_REQUEST).cast::<u32>(), DFU_MAGIC) };
    cortex_m::peripheral::SCB::sys_reset()
}

/// At boot, before any clock or peripheral set-up: jumps to the ROM bootloader when the last
/// reset asked for it.
fn enter_bootloader_if_requested() {
    let word = (&raw mut DFU_REQUEST).cast::<u32>();
    // SAFETY: volatile accesses to a word this firmware owns; an uninitialised value after a
    // power-on is just a number that is not the magic.
    let requested = unsafe { core::ptr::read_volatile(word) } == DFU_MAGIC;
    if !requested {
        return;
    }
    // SAFETY: as above; then, with the chip as reset left it, enable SYSCFG (RCC_APB2ENR bit
    // 14), map system memory at 0 (SYSCFG_MEMRMP = 0b01) and jump through the bootloader's
    // vector table (stack pointer, reset handler), as AN2606 describes for the STM32F4.
    unsafe {
        core::ptr::write_volatile(word, 0);
        let apb2enr = 0x4002_3844 as *mut u32;
        core::ptr::write_volatile(apb2enr, core::ptr::read_volatile(apb2enr) | (1 << 14));
        core::ptr::write_volatile(0x4001_3800 as *mut u32, 0b01);
        cortex_m::asm::bootload(0x1fff_0000 as *const u32)
    }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    enter_bootloader_if_requested();
    let p = embassy_stm32::init(clock_config());

    // TIM2 owns PA2/PA3 (AF1); the pins stay configured as long as these live (forever).
    let _camera_pin =
        PwmPin::<peripherals::TIM2, embassy_stm32::timer::Ch3>::new(p.PA2, OutputType::PushPull);
    let _flash_pin =
        PwmPin::<peripherals::TIM2, embassy_stm32::timer::Ch4>::new(p.PA3, OutputType::PushPull);
    let _tim2 = p.TIM2; // owned here: nothing else may use it
    embassy_stm32::rcc::enable_and_reset::<peripherals::TIM2>();
    edges::start_tim2(TIM2_CLOCK_HZ);

    let mut config = BoardConfig::new(BOARD_NAME, DEVICE_CLOCK_HZ);
    config.firmware_version = FIRMWARE_VERSION;
    let Ok(board) = Board::new(config) else {
        panic!("board config refused")
    };
    critical_section::with(|cs| {
        let mut s = Shared {
            board,
            outputs: TimerOutputs::new(),
            tx: FrameWriter::new(TxBytes::new()),
            clock_high: 0,
            clock_last: 0,
        };
        let now = s.now_us();
        s.board.reset_outputs(now, &mut s.outputs);
        SHARED.borrow_ref_mut(cs).replace(s);
    });
    embassy_stm32::interrupt::TIM2.unpend();
    // SAFETY: the handler only touches SHARED through a critical section.
    unsafe { embassy_stm32::interrupt::TIM2.enable() };

    // USB CDC-ACM.
    static EP_OUT: StaticCell<[u8; 256]> = StaticCell::new();
    static CONFIG_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static CONTROL: StaticCell<[u8; 64]> = StaticCell::new();
    static CDC_STATE: StaticCell<cdc_acm::State> = StaticCell::new();
    let mut usb_config = usb::Config::default();
    usb_config.vbus_detection = false; // the Black Pill does not route VBUS to PA9
    let driver = usb::Driver::new_fs(
        p.USB_OTG_FS,
        Irqs,
        p.PA12,
        p.PA11,
        EP_OUT.init([0; 256]),
        usb_config,
    );
    // pid.codes test VID/PID; replace with an allocated pair for a product.
    let mut device = embassy_usb::Config::new(0x1209, 0x0001);
    device.manufacturer = Some("ellipso");
    device.product = Some("ellipso trigger board");
    device.serial_number = Some(BOARD_NAME);
    device.max_power = 100;
    device.max_packet_size_0 = 64;
    let mut builder = Builder::new(
        driver,
        device,
        CONFIG_DESC.init([0; 256]),
        BOS_DESC.init([0; 256]),
        &mut [],
        CONTROL.init([0; 64]),
    );
    let class = CdcAcmClass::new(&mut builder, CDC_STATE.init(cdc_acm::State::new()), 64);
    let usb_device = builder.build();
    let (sender, receiver) = class.split();

    let button = ExtiInput::new(p.PA0, p.EXTI0, Pull::Up, Irqs);
    let led = Output::new(p.PC13, Level::High, Speed::Low); // high = off

    spawner.spawn(usb_task(usb_device).unwrap());
    spawner.spawn(rx_task(receiver).unwrap());
    spawner.spawn(tx_task(sender).unwrap());
    spawner.spawn(button_task(button).unwrap());
    spawner.spawn(led_task(led).unwrap());

    // Heartbeat: keeps the 64-bit clock extension ahead of TIM2's wrap.
    let mut ticker = Ticker::every(Duration::from_secs(1));
    loop {
        ticker.next().await;
        with_shared(|s| {
            s.now_us();
        });
    }
}

type UsbDriver = usb::Driver<'static, peripherals::USB_OTG_FS>;

#[embassy_executor::task]
async fn usb_task(mut device: embassy_usb::UsbDevice<'static, UsbDriver>) -> ! {
    device.run().await
}

/// Host → core: every received byte, stamped when its packet arrived.
#[embassy_executor::task]
async fn rx_task(mut rx: cdc_acm::Receiver<'static, UsbDriver>) -> ! {
    let mut packet = [0u8; 64];
    loop {
        rx.wait_connection().await;
        // A new session: drop any half frame from the previous one.
        with_shared(|s| s.board.reset_decoder());
        while let Ok(n) = rx.read_packet(&mut packet).await {
            with_shared(|s| {
                for &byte in &packet[..n] {
                    let now = s.now_us();
                    s.board.feed_rx_byte(byte, now, &mut s.outputs, &mut s.tx);
                }
            });
        }
    }
}

/// Core → host: drains the queue in packets of at most [`USB_PACKET`] bytes.
#[embassy_executor::task]
async fn tx_task(mut tx: cdc_acm::Sender<'static, UsbDriver>) -> ! {
    let mut packet = [0u8; USB_PACKET];
    loop {
        tx.wait_connection().await;
        loop {
            let n = critical_section::with(|cs| {
                let mut shared = SHARED.borrow_ref_mut(cs);
                let Some(s) = shared.as_mut() else { return 0 };
                let bytes = s.tx.bytes_mut();
                let mut n = 0;
                while n < USB_PACKET {
                    let Some(b) = bytes.pop_front() else { break };
                    packet[n] = b;
                    n += 1;
                }
                n
            });
            if n == 0 {
                let reboot = critical_section::with(|cs| {
                    SHARED
                        .borrow_ref_mut(cs)
                        .as_mut()
                        .is_some_and(|s| s.board.take_bootloader_request())
                });
                if reboot {
                    // the Ack has been handed to USB: give the host time to read it
                    Timer::after_millis(50).await;
                    reboot_into_bootloader();
                }
                TX_READY.wait().await;
                continue;
            }
            if tx.write_packet(&packet[..n]).await.is_err() {
                break; // host went away; wait for the next connection
            }
        }
    }
}

/// Grip button → core (press = falling edge; the core debounces).
#[embassy_executor::task]
async fn button_task(mut button: ExtiInput<'static, embassy_stm32::mode::Async>) -> ! {
    loop {
        button.wait_for_falling_edge().await;
        with_shared(|s| {
            let now = s.now_us();
            s.board.button_pressed(now);
        });
    }
}

/// Status LED (active low) from the board state and fault counters.
#[embassy_executor::task]
async fn led_task(mut led: Output<'static>) -> ! {
    let mut faults_seen = None;
    let mut phase = 0u32;
    loop {
        let (state, faults) = critical_section::with(|cs| {
            SHARED
                .borrow_ref(cs)
                .as_ref()
                .map(|s| (s.board.state(), s.board.faults()))
        })
        .unzip();
        let new_fault = faults.is_some() && faults_seen.is_some() && faults != faults_seen;
        faults_seen = faults;
        let on = if new_fault {
            // double blink
            for _ in 0..2 {
                led.set_low();
                Timer::after_millis(60).await;
                led.set_high();
                Timer::after_millis(120).await;
            }
            false
        } else {
            match state {
                Some(BoardState::Running) => phase % 2 == 0, // 5 Hz
                Some(BoardState::Configured | BoardState::Armed) => true,
                Some(BoardState::Idle) | None => phase % 10 == 0, // 1 Hz flash
            }
        };
        if on {
            led.set_low()
        } else {
            led.set_high()
        }
        phase = phase.wrapping_add(1);
        Timer::after_millis(100).await;
    }
}
