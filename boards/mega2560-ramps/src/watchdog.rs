//! The hardware watchdog: resets a firmware that stops running its main loop.
//!
//! After any reset the ATmega2560 keeps the watchdog running if it caused the
//! reset, so WDRF is cleared and the timeout set again first thing.

use avr_device::atmega2560::Peripherals;

/// WDP2..0 = 111: 256 k cycles of the 128 kHz watchdog oscillator = 2 s.
const TIMEOUT_BITS: u8 = 0b0000_0111;

/// WDTCSR's data-space address on the ATmega2560.
const WDTCSR: u16 = 0x60;

/// The timed write: WDCE | WDE, then `value` within four cycles. Two `sts`
/// in assembly, so the compiler can never schedule anything between them
/// (if it did, the change would be ignored, and after a watchdog reset the
/// 16 ms default timeout would stay in force).
fn timed_write(value: u8) {
    // SAFETY: the documented change sequence on WDTCSR; interrupts are off
    // (callers run it inside a critical section or with them disabled).
    unsafe {
        core::arch::asm!(
            "sts {addr}, {unlock}",
            "sts {addr}, {value}",
            addr = const WDTCSR,
            unlock = in(reg) (1u8 << 4) | (1 << 3),
            value = in(reg) value,
            options(nostack),
        );
    }
}

pub fn start(dp: &Peripherals) {
    avr_device::interrupt::free(|_| {
        // Clearing WDRF is required before WDE can be changed.
        dp.CPU.mcusr.modify(|_, w| w.wdrf().clear_bit());
        avr_device::asm::wdr();
        // WDE (bit 3) with the 2 s prescaler.
        timed_write((1 << 3) | TIMEOUT_BITS);
        // Restart the count under the new timeout. Harmless on silicon;
        // needed on simavr, which re-arms its watchdog timer on `wdr` but
        // not on a prescaler change while WDE stays on: after a watchdog
        // reset (16 ms default) the board otherwise reset again 16 ms into
        // every boot, a boot loop whenever booting took longer than that.
        avr_device::asm::wdr();
    });
}

pub fn stop(dp: &Peripherals) {
    avr_device::asm::wdr();
    // Clearing WDRF, as in `start`.
    dp.CPU.mcusr.modify(|_, w| w.wdrf().clear_bit());
    timed_write(0);
}

/// Reset the watchdog's count; called once per main-loop pass.
pub fn feed() {
    avr_device::asm::wdr();
}
