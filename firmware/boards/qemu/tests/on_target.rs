//! On-target tests: run inside QEMU `netduinoplus2` by `embedded-test-qemu-runner` (`cargo test`
//! in this crate), one fresh boot per test, or on an STM32F405 with `probe-rs run` (same source).
//!
//! They check what host tests of the core cannot: the port's clock, alarm arithmetic and pins on
//! the real target, and the core driving a whole capture against the emulated TIM2.
#![no_std]
#![no_main]

use stm32f4 as _; // links the PAC's interrupt vector table

#[cfg(test)]
#[embedded_test::tests]
mod tests {
    use ellipso_board_qemu::clock::{self, DEVICE_CLOCK_HZ, WideClock};
    use ellipso_board_qemu::{
        ALARM_EARLY_US, BOARD_NAME, GpioaPin, HEARTBEAT_US, Port, board_config,
    };
    use ellipso_firmware::RecordingOutputs;
    use ellipso_protocol::{
        BoardMessage, BoardState, Bracket, CaptureConfig, Decoder, HostMessage, MAX_FRAME_LEN,
        Output, PROTOCOL_VERSION, PulseCount, TriggerSource, encode,
    };
    use stm32f4::stm32f405 as pac;

    #[init]
    fn init() -> pac::Peripherals {
        let dp = pac::Peripherals::take().unwrap();
        dp.RCC.apb1enr().modify(|_, w| w.tim2en().set_bit());
        clock::start_tim2(&dp.TIM2);
        dp
    }

    #[test]
    fn board_config_is_accepted_and_describes_this_board() {
        let info = board_config().board_info().unwrap();
        assert_eq!(info.board_name.as_str(), BOARD_NAME);
        assert_eq!(info.timer_clock_hz, DEVICE_CLOCK_HZ);
        assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    }

    /// SysTick counts 10 ms of core cycles; TIM2 must advance 10 000 ± 1 % counts meanwhile, so
    /// the prescaler and both clock constants agree with the machine.
    #[test]
    fn tim2_counts_microseconds_against_the_core_clock(_dp: pac::Peripherals) {
        let mut cp = cortex_m::Peripherals::take().unwrap();
        let syst = &mut cp.SYST;
        syst.set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
        syst.set_reload(clock::CPU_HZ / 100 - 1);
        syst.clear_current();
        let _ = syst.has_wrapped(); // clear COUNTFLAG
        let a = clock::read_tim2();
        syst.enable_counter();
        while !syst.has_wrapped() {}
        let b = clock::read_tim2();
        syst.disable_counter();
        let counts = b.wrapping_sub(a);
        assert!(
            (9_900..=10_100).contains(&counts),
            "TIM2 counted {counts} in 10 ms"
        );
    }

    #[test]
    fn wide_clock_extends_across_wraps() {
        let mut c = WideClock::new();
        assert_eq!(c.extend(5), 5);
        assert_eq!(c.extend(u32::MAX), u64::from(u32::MAX));
        assert_eq!(c.extend(3), (1 << 32) + 3);
        assert_eq!(c.extend(3), (1 << 32) + 3); // same count: no wrap
        assert_eq!(c.extend(2), (2 << 32) + 2);
        let mut hw = WideClock::new();
        let t0 = hw.now_us();
        cortex_m::asm::delay(100_000);
        assert!(hw.now_us() > t0);
    }

    #[test]
    fn systick_reload_fires_early_by_the_margin_or_at_the_heartbeat() {
        let mhz = clock::CPU_HZ / 1_000_000;
        let early = ALARM_EARLY_US as u32;
        assert_eq!(
            clock::systick_reload(1_000, Some(1_250)),
            (250 - early) * mhz - 1
        );
        assert_eq!(clock::systick_reload(1_000, Some(900)), mhz - 1); // past: 1 µs
        assert_eq!(clock::systick_reload(1_000, Some(1_000)), mhz - 1);
        assert_eq!(clock::systick_reload(1_000, Some(1_015)), mhz - 1); // inside the margin
        let beat = (HEARTBEAT_US as u32) * mhz - 1;
        assert_eq!(clock::systick_reload(0, None), beat);
        assert_eq!(clock::systick_reload(0, Some(u64::MAX)), beat);
        assert!(beat < 1 << 24);
    }

    #[test]
    fn pins_write_set_and_reset_bits() {
        assert_eq!(GpioaPin::<0>::SET, 0x0000_0001);
        assert_eq!(GpioaPin::<0>::RESET, 0x0001_0000);
        assert_eq!(GpioaPin::<1>::SET, 0x0000_0002);
        assert_eq!(GpioaPin::<1>::RESET, 0x0002_0000);
    }

    /// The core runs a 3-pulse capture on TIM2 time, polled as a busy-idle board does: every
    /// edge at or after its plan, in order, every reply a decodable frame.
    #[test]
    fn a_counted_capture_runs_on_the_emulated_clock() {
        let mut clock = WideClock::new();
        let mut port = Port::new(RecordingOutputs::<32>::new());
        port.boot(clock.now_us());
        let config = CaptureConfig {
            exposure_us: 2_000,
            flash_delay_us: 300,
            flash_duration_us: 1_000,
            frame_period_us: 25_000,
            pulses: PulseCount::Count(3),
            trigger: TriggerSource::FreeRun,
            report_edges: true,
            bracket: Bracket::NONE,
        };
        let msgs = [
            HostMessage::Hello {
                protocol_version: PROTOCOL_VERSION,
            },
            HostMessage::Configure(config),
            HostMessage::Arm,
            HostMessage::Start,
        ];
        let mut wire = heapless::Vec::<u8, 2048>::new();
        let mut drain = |port: &mut Port<RecordingOutputs<32>>| {
            while let Some(b) = port.pop_tx_byte() {
                wire.push(b).unwrap();
            }
        };
        for msg in msgs {
            let mut frame = [0u8; MAX_FRAME_LEN];
            let n = encode(&msg, &mut frame).unwrap();
            for &b in &frame[..n] {
                port.on_rx_byte(b, clock.now_us());
            }
            drain(&mut port);
        }
        let t_start = clock.now_us();
        while let Some(deadline) = port.next_deadline() {
            assert!(clock.now_us() < t_start + 200_000, "capture did not finish");
            if clock.now_us() >= deadline {
                port.on_alarm(clock.now_us());
                drain(&mut port);
            }
        }
        assert_eq!(port.board().state(), BoardState::Configured);
        assert_eq!(port.board().sequencer().pulses_fired(), 3);

        let edges: heapless::Vec<_, 32> = port.outputs().edges().copied().collect();
        assert_eq!(edges.len(), 12);
        for pulse in edges.chunks(4) {
            let order: heapless::Vec<_, 4> = pulse.iter().map(|e| (e.output, e.high)).collect();
            assert_eq!(
                order.as_slice(),
                [
                    (Output::CameraTrigger, true),
                    (Output::Flash, true),
                    (Output::Flash, false),
                    (Output::CameraTrigger, false)
                ]
            );
            let t = |i: usize| pulse[i].t_device_us - pulse[0].t_device_us;
            assert!(t(1) >= 300 && t(2) - t(1) >= 1_000 && t(3) >= 2_000);
        }
        assert!(edges[4].t_device_us - edges[0].t_device_us >= 25_000);

        let mut dec = Decoder::<BoardMessage>::new();
        let (mut acks, mut pulses, mut edge_reports, mut status) = (0, 0, 0, 0);
        for m in dec.feed(&wire) {
            match m.unwrap() {
                BoardMessage::Ack(_) | BoardMessage::HelloReply(_) => acks += 1,
                BoardMessage::Pulse(_) => pulses += 1,
                BoardMessage::Edge(_) => edge_reports += 1,
                BoardMessage::Status(_) => status += 1,
                other => panic!("unexpected {other:?}"),
            }
        }
        // 4 replies; 3 pulses; 12 edges; boot announcement + completion status.
        assert_eq!((acks, pulses, edge_reports, status), (4, 3, 12, 2));
    }

    /// The spin that follows an early alarm returns on the deadline's own count.
    #[test]
    fn spin_until_lands_on_the_deadline() {
        let mut clock = WideClock::new();
        for _ in 0..20 {
            let d = clock.now_us() + ALARM_EARLY_US / 2;
            assert_eq!(clock::spin_until(&mut clock, Some(d)), d);
        }
        // A heartbeat (deadline far away) and a past deadline return at once.
        let far = clock.now_us() + 10_000;
        assert!(clock::spin_until(&mut clock, Some(far)) < far);
        let now = clock.now_us();
        assert!(clock::spin_until(&mut clock, Some(now.saturating_sub(5))) >= now);
    }

    /// A 1, 1/4, 1/16 bracket of a 5 ms flash on the emulated TIM2, polled as the port's alarm
    /// does (each edge on the first count at or after its deadline): every pulse's flash lasts
    /// its step's planned on-time within one timer tick (1 µs), and its `Pulse` report carries
    /// the step and that on-time.
    #[test]
    fn a_bracketed_capture_holds_each_pulse_width_within_one_tick() {
        const N: usize = 6;
        let mut clock = WideClock::new();
        let mut port = Port::new(RecordingOutputs::<32>::new());
        port.boot(clock.now_us());
        let config = CaptureConfig {
            exposure_us: 6_000,
            flash_delay_us: 100,
            flash_duration_us: 5_000,
            frame_period_us: 50_000,
            pulses: PulseCount::Count(N as u32),
            trigger: TriggerSource::FreeRun,
            report_edges: false,
            bracket: Bracket::from_q15(&[0x8000, 0x2000, 0x0800]).unwrap(),
        };
        let mut wire = heapless::Vec::<u8, 2048>::new();
        for msg in [
            HostMessage::Configure(config),
            HostMessage::Arm,
            HostMessage::Start,
        ] {
            let mut frame = [0u8; MAX_FRAME_LEN];
            let n = encode(&msg, &mut frame).unwrap();
            for &b in &frame[..n] {
                port.on_rx_byte(b, clock.now_us());
            }
        }
        let t_start = clock.now_us();
        while let Some(deadline) = port.next_deadline() {
            assert!(clock.now_us() < t_start + 400_000, "capture did not finish");
            let now = clock::spin_until(&mut clock, Some(deadline));
            if now >= deadline {
                port.on_alarm(now);
            }
        }
        while let Some(b) = port.pop_tx_byte() {
            wire.push(b).unwrap();
        }
        let plan = *port.board().plan().unwrap();
        let flashes: heapless::Vec<_, 16> = port
            .outputs()
            .edges()
            .filter(|e| e.output == Output::Flash)
            .copied()
            .collect();
        assert_eq!(flashes.len(), 2 * N);
        let mut dec = Decoder::<BoardMessage>::new();
        let mut k = 0;
        for m in dec.feed(&wire) {
            let BoardMessage::Pulse(p) = m.unwrap() else {
                continue;
            };
            let step = (k % 3) as u8;
            assert_eq!(p.bracket_step, step);
            let planned = i64::from(plan.step_on_time_us(step));
            let width = (flashes[2 * k + 1].t_device_us - flashes[2 * k].t_device_us) as i64;
            assert!(
                (width - planned).abs() <= 1,
                "pulse {k}: {width} µs for a planned {planned} µs"
            );
            assert_eq!(i64::from(p.flash_on_us), width);
            assert_eq!(p.flags, 0);
            k += 1;
        }
        assert_eq!(k, N);
        assert_eq!(
            [0, 1, 2].map(|s| plan.step_on_time_us(s)),
            [5_000, 1_250, 313]
        );
    }
}
