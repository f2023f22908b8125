//! USART1, the host link: 115 200 8N1 on PA9 (TX) / PA10 (RX), RX interrupt on, TX polled.
//!
//! QEMU delivers one host byte per `RXNE` and holds the next until `DR` is read, so nothing
//! overruns; it drops bytes that arrive before `UE`/`RE` are set, which is why the firmware
//! announces its boot and the host sends only after that announcement. Its `TXE` always reads 1
//! and never interrupts, so transmission polls `TXE`.

use stm32f4::stm32f405 as pac;

/// `BRR` for 115 200 baud at the USART1 clock (APB2): `BRR = f_apb2 / baud` (oversampling 16,
/// mantissa and fraction packed as one integer). QEMU ignores it.
#[cfg(feature = "qemu")]
pub const BRR: u16 = (84_000_000u32 / 115_200) as u16;
/// `BRR` for 115 200 baud at the 16 MHz HSI (APB2 undivided after reset).
#[cfg(not(feature = "qemu"))]
pub const BRR: u16 = (16_000_000u32 / 115_200) as u16;

/// Clocks USART1 and PA9/PA10 (alternate function 7), sets 115 200 8N1, enables TX, RX and the
/// RX interrupt (the NVIC line is unmasked by the caller).
pub fn init(rcc: &pac::RCC, gpioa: &pac::GPIOA, usart: &pac::USART1) {
    rcc.ahb1enr().modify(|_, w| w.gpioaen().set_bit());
    rcc.apb2enr().modify(|_, w| w.usart1en().set_bit());
    // PA9, PA10: MODER 10 (alternate), AFRH AF7.
    gpioa
        .moder()
        .modify(|r, w| unsafe { w.bits((r.bits() & !(0xF << 18)) | (0b1010 << 18)) });
    gpioa
        .afrh()
        .modify(|r, w| unsafe { w.bits((r.bits() & !0xFF0) | 0x770) });
    usart.brr().write(|w| unsafe { w.bits(BRR) });
    usart.cr1().write(|w| {
        w.ue().set_bit();
        w.te().set_bit();
        w.re().set_bit();
        w.rxneie().set_bit()
    });
}

/// The next received byte, if one is waiting (reading `DR` clears `RXNE`).
pub fn try_read(usart: &pac::usart1::RegisterBlock) -> Option<u8> {
    if usart.sr().read().rxne().bit_is_set() {
        Some(usart.dr().read().dr().bits() as u8)
    } else {
        None
    }
}

/// Sends one byte, waiting for `TXE` (immediate under QEMU).
pub fn write_blocking(usart: &pac::usart1::RegisterBlock, byte: u8) {
    while usart.sr().read().txe().bit_is_clear() {}
    usart
        .dr()
        .write(|w| unsafe { w.dr().bits(u16::from(byte)) });
}
