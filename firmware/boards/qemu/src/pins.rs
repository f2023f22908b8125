//! GPIOA output pins written through `BSRR` (one atomic store per edge, no read-modify-write),
//! as embedded-hal 1.0 [`OutputPin`]s for the core's `PinOutputs`.
//!
//! On QEMU the store is dropped but logged by `-d unimp` as
//! `GPIOA: unimplemented device write (size 4, offset 0x018, value …)`: bit `n` sets pin `n`,
//! bit `16 + n` resets it, which the end-to-end test reads back.

use core::convert::Infallible;

use embedded_hal::digital::{ErrorType, OutputPin};
use stm32f4::stm32f405 as pac;

/// Pin `N` of GPIOA, push-pull output (configure it with [`configure_outputs`]).
#[derive(Debug)]
pub struct GpioaPin<const N: u8>(());

impl<const N: u8> GpioaPin<N> {
    /// The `BSRR` value that sets the pin.
    pub const SET: u32 = 1 << N;
    /// The `BSRR` value that resets the pin.
    pub const RESET: u32 = 1 << (N + 16);

    /// Takes the pin. Only one value per pin may exist; [`crate::port`] makes the only two.
    pub const fn new() -> Self {
        const { assert!(N < 16) };
        Self(())
    }

    fn write(value: u32) {
        // SAFETY: BSRR is write-only and atomic per bit: a store touches only the named pin.
        unsafe {
            (*pac::GPIOA::ptr()).bsrr().write(|w| w.bits(value));
        }
    }
}

impl<const N: u8> Default for GpioaPin<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: u8> ErrorType for GpioaPin<N> {
    type Error = Infallible;
}

impl<const N: u8> OutputPin for GpioaPin<N> {
    fn set_low(&mut self) -> Result<(), Infallible> {
        Self::write(Self::RESET);
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Infallible> {
        Self::write(Self::SET);
        Ok(())
    }
}

/// Enables GPIOA's clock and makes PA0 (camera trigger) and PA1 (flash) push-pull outputs, low.
pub fn configure_outputs(rcc: &pac::RCC, gpioa: &pac::GPIOA) {
    rcc.ahb1enr().modify(|_, w| w.gpioaen().set_bit());
    gpioa
        .bsrr()
        .write(|w| unsafe { w.bits(GpioaPin::<0>::RESET | GpioaPin::<1>::RESET) });
    // MODER: 2 bits per pin, 01 = general-purpose output.
    gpioa
        .moder()
        .modify(|r, w| unsafe { w.bits((r.bits() & !0xF) | 0b0101) });
}
