//! The hardware watchdog: resets a firmware that stops running its main loop.
//!
//! After any reset the ATmega2560 keeps the watchdog running if it caused the
//! reset, so WDRF is cleared and the timeout set again first thing.

use avr_device::atmega2560::Peripherals;

/// WDP2..0 = 111: 256 k cycles of the 128 kHz watchdog oscillator = 2 s.
const TIMEOUT_BITS: u8 = 0b0000_0111;

pub fn start(dp: &Peripherals) {
    avr_device::interrupt::free(|_| {
        // SAFETY: clearing WDRF (bit 3) is required before WDE can be changed.
        dp.CPU.mcusr.modify(|r, w| unsafe { w.bits(r.bits() & !(1 << 3)) });
        avr_device::asm::wdr();
        // Timed sequence: WDCE | WDE, then the new value within 4 cycles.
        // SAFETY: documented sequence; WDE (bit 3) with the 2 s prescaler.
        dp.WDT.wdtcsr.write(|w| unsafe { w.bits((1 << 4) | (1 << 3)) });
        dp.WDT.wdtcsr.write(|w| unsafe { w.bits((1 << 3) | TIMEOUT_BITS) });
    });
}

pub fn stop(dp: &Peripherals) {
    // SAFETY: the same timed sequence, ending with WDE clear.
    avr_device::asm::wdr();
    dp.CPU.mcusr.modify(|r, w| unsafe { w.bits(r.bits() & !(1 << 3)) });
    dp.WDT.wdtcsr.write(|w| unsafe { w.bits((1 << 4) | (1 << 3)) });
    dp.WDT.wdtcsr.write(|w| unsafe { w.bits(0) });
}

/// Reset the watchdog's count; called once per main-loop pass.
pub fn feed() {
    avr_device::asm::wdr();
}
