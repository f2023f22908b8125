//! The device clock (TIM2 `CNT` at 1 MHz, extended to 64 bits) and the SysTick alarm arithmetic.
//!
//! Contract: [`WideClock::extend`] must see every TIM2 wrap, i.e. be called at least once per
//! 2³² µs (71.6 min); the SysTick heartbeat ([`HEARTBEAT_US`]) guarantees a call every 50 ms.
//! All calls must happen inside one critical section (the board keeps the clock next to the
//! [`Port`](crate::Port) in a `critical_section::Mutex`).

use stm32f4::stm32f405 as pac;

/// Core (and SysTick, clock source "processor") frequency, Hz.
#[cfg(feature = "qemu")]
pub const CPU_HZ: u32 = 168_000_000;
/// Core (and SysTick, clock source "processor") frequency, Hz: the HSI after reset.
#[cfg(not(feature = "qemu"))]
pub const CPU_HZ: u32 = 16_000_000;

/// TIM2's input clock, Hz. QEMU models TIM2–5 at 1 GHz whatever RCC says.
#[cfg(feature = "qemu")]
pub const TIM_CLK_HZ: u32 = 1_000_000_000;
/// TIM2's input clock, Hz: APB1 at the 16 MHz HSI (prescaler 1, so the timer clock is APB1's).
#[cfg(not(feature = "qemu"))]
pub const TIM_CLK_HZ: u32 = 16_000_000;

/// The device clock's tick rate: 1 MHz, so one TIM2 count is one µs.
pub const DEVICE_CLOCK_HZ: u32 = 1_000_000;

/// TIM2 prescaler: `PSC = TIM_CLK_HZ / DEVICE_CLOCK_HZ − 1` (999 under QEMU, 15 at 16 MHz).
pub const TIM2_PSC: u32 = TIM_CLK_HZ / DEVICE_CLOCK_HZ - 1;

/// Longest SysTick interval, µs: the alarm fires at least this often.
pub const HEARTBEAT_US: u64 = 50_000;

/// SysTick is armed this long before a deadline, and the alarm spins on TIM2 for the rest
/// ([`spin_until`]): the SysTick ISR path alone costs 7–13 µs under `-icount shift=3`, so an
/// alarm armed *at* the deadline executes every edge that late. Arming early makes each edge land
/// on the first TIM2 count at or after its deadline, which keeps a flash's on-time (its off-edge
/// anchored to its actual on-edge) within one tick of the plan, as a compare output would.
pub const ALARM_EARLY_US: u64 = 20;

// SysTick's reload register has 24 bits: the heartbeat must fit at CPU_HZ.
const _: () = assert!(HEARTBEAT_US * (CPU_HZ as u64 / 1_000_000) <= 1 << 24);
const _: () = assert!(TIM_CLK_HZ % DEVICE_CLOCK_HZ == 0);

/// TIM2's 32-bit count extended to a monotonic 64-bit µs clock.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WideClock {
    high: u32,
    last: u32,
}

impl WideClock {
    /// A clock at 0 that has seen no count yet.
    pub const fn new() -> Self {
        Self { high: 0, last: 0 }
    }

    /// Extends a raw count: a count below the previous one means TIM2 wrapped once.
    pub fn extend(&mut self, count: u32) -> u64 {
        if count < self.last {
            self.high = self.high.wrapping_add(1);
        }
        self.last = count;
        (u64::from(self.high) << 32) | u64::from(count)
    }

    /// Reads TIM2 and extends it: the device time now, µs.
    pub fn now_us(&mut self) -> u64 {
        self.extend(read_tim2())
    }
}

/// Starts TIM2 as a free-running 32-bit up-counter at [`DEVICE_CLOCK_HZ`].
pub fn start_tim2(tim2: &pac::TIM2) {
    tim2.psc().write(|w| unsafe { w.bits(TIM2_PSC) });
    tim2.arr().write(|w| unsafe { w.bits(u32::MAX) });
    tim2.egr().write(|w| w.ug().set_bit()); // load PSC now
    tim2.cr1().write(|w| w.cen().set_bit());
}

/// TIM2's raw count.
pub fn read_tim2() -> u32 {
    // SAFETY: a read of a counter register has no side effect.
    unsafe { (*pac::TIM2::ptr()).cnt().read().bits() }
}

/// The SysTick reload value that fires once [`ALARM_EARLY_US`] before `deadline_us` (or after
/// [`HEARTBEAT_US`]): `cycles − 1` with
/// `cycles = clamp(deadline − ALARM_EARLY_US − now, 1, HEARTBEAT_US) · CPU_HZ / 1 MHz`.
/// A deadline already past, or closer than the early margin, fires after 1 µs.
pub fn systick_reload(now_us: u64, deadline_us: Option<u64>) -> u32 {
    let dt_us = deadline_us
        .map_or(HEARTBEAT_US, |d| {
            d.saturating_sub(ALARM_EARLY_US).saturating_sub(now_us)
        })
        .clamp(1, HEARTBEAT_US);
    // ≤ 2^24 by the assertion above, so the cast is exact.
    (dt_us * u64::from(CPU_HZ / 1_000_000)) as u32 - 1
}

/// Waits on `clock` until `deadline_us` when it is at most [`ALARM_EARLY_US`] away (the alarm
/// fired early on purpose); returns the time to poll the core with. A deadline further away (a
/// heartbeat) or already past returns at once.
pub fn spin_until(clock: &mut WideClock, deadline_us: Option<u64>) -> u64 {
    let mut now = clock.now_us();
    if let Some(d) = deadline_us.filter(|&d| d > now && d - now <= ALARM_EARLY_US) {
        while now < d {
            now = clock.now_us();
        }
    }
    now
}

/// Arms SysTick (clock source: processor, interrupt on) to fire [`ALARM_EARLY_US`] before
/// `deadline_us`.
pub fn arm_systick(syst: &mut cortex_m::peripheral::SYST, now_us: u64, deadline_us: Option<u64>) {
    syst.disable_counter();
    syst.set_reload(systick_reload(now_us, deadline_us));
    syst.clear_current();
    syst.enable_counter();
}
