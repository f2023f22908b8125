//! ellipso trigger board for QEMU `netduinoplus2` (STM32F405, Cortex-M4F): the hardware glue
//! around the `ellipso-firmware` sync core, as a library so the on-target tests exercise the very
//! code the firmware binary (`src/main.rs`) runs.
//!
//! # Board limits
//!
//! - **Link:** USART1 (PA9 TX / PA10 RX, 115 200 8N1), QEMU's first `-serial`. RX is interrupt
//!   driven (one byte per `RXNE`); TX is drained from a [`TxBytes`] queue by polling `TXE`
//!   (QEMU raises no TXE interrupt).
//! - **Clock:** TIM2 `CNT` at 1 MHz, extended to 64 bits by [`WideClock`]. Resolution 1 µs.
//! - **Alarm:** SysTick, one-shot, re-armed after every event for [`ALARM_EARLY_US`] before the
//!   core's next deadline (the ISR then spins on TIM2 to the deadline itself) and at least every
//!   [`HEARTBEAT_US`] so the 32→64-bit extension never misses a TIM2 wrap (71.6 min).
//! - **Outputs:** PA0 camera trigger, PA1 flash, written through `GPIOA.BSRR` by [`GpioaPin`].
//!   QEMU does not emulate GPIO (writes are only logged with `-d unimp`), so the host asks for
//!   `report_edges` to see every transition as an `Edge` message. Edges are placed by the SysTick
//!   ISR, armed early and spinning to each deadline on TIM2, so an edge lands on the first TIM2
//!   count at or after its deadline (without the spin the ISR path, 7–13 µs under
//!   `-icount shift=3`, would make every edge that late and every flash that much longer); the
//!   core reports the executed times and flags anything later than its 50 µs tolerance. A
//!   bracketed flash's on-time is thus within one tick (1 µs) of its plan.
//! - **No grip button, no hardware flash cut-off:** QEMU models neither EXTI-wired GPIO nor timer
//!   outputs. The real board (`firmware/boards/blackpill`) has both.
//! - **Clocks** (feature `qemu`, default): QEMU's TIM2–5 model clock is 1 GHz (`PSC = 999`), the
//!   core and SysTick run at 168 MHz. Without `qemu` the STM32F405's reset clocks are assumed:
//!   HSI 16 MHz for the core, SysTick, APB1 timers and USART1 (no PLL is configured).

#![no_std]

pub mod clock;
pub mod pins;
pub mod port;
pub mod usart;

pub use clock::{ALARM_EARLY_US, CPU_HZ, HEARTBEAT_US, TIM_CLK_HZ, WideClock, systick_reload};
pub use pins::GpioaPin;
pub use port::{BOARD_NAME, Port, TX_QUEUE_BYTES, TxBytes, board_config};
