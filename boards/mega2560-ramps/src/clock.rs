//! A 1 kHz system tick on Timer3 (a 16-bit timer: QEMU's AVR machine models
//! only those, and its Timer5 interrupt jumps to the reset vector, seen with
//! QEMU 10.0).
//! It wakes the main loop from sleep and counts milliseconds.

use avr_device::atmega2560::Peripherals;
use core::cell::Cell;
use avr_device::interrupt::Mutex;

static MILLIS: Mutex<Cell<u32>> = Mutex::new(Cell::new(0));

/// CTC mode, prescaler 64: 16 MHz / 64 / 250 = 1 kHz.
pub fn init(dp: &Peripherals) {
    let timer = &dp.TC3;
    timer.ocr3a.write(|w| w.bits(249));
    // SAFETY: WGM32 (CTC on OCR3A) and CS31|CS30 (prescaler 64).
    timer.tccr3a.write(|w| unsafe { w.bits(0) });
    timer.tccr3b.write(|w| unsafe { w.bits((1 << 3) | 0b011) });
    // SAFETY: OCIE3A only.
    timer.timsk3.write(|w| unsafe { w.bits(1 << 1) });
}

/// Milliseconds since boot (wraps after 49 days).
pub fn millis() -> u32 {
    avr_device::interrupt::free(|cs| MILLIS.borrow(cs).get())
}

#[avr_device::interrupt(atmega2560)]
fn TIMER3_COMPA() {
    // SAFETY: only the ADC's control register is written (see adc.rs).
    crate::adc::start_conversion(&unsafe { Peripherals::steal() });
    // The step interrupt may come in from here on; the count below is
    // still changed with interrupts off (the main loop reads it so), and
    // this handler cannot re-enter: the next compare match is 1 ms away.
    // SAFETY: see above.
    unsafe { avr_device::interrupt::enable() };
    avr_device::interrupt::free(|cs| {
        let millis = MILLIS.borrow(cs);
        let now = millis.get().wrapping_add(1);
        millis.set(now);
        #[cfg(feature = "machine-powder-bed")]
        crate::bed::on_tick(&unsafe { Peripherals::steal() }, cs, now);
        #[cfg(any(feature = "bed-ssr", feature = "machine-extrusion-line"))]
        crate::ssr::on_tick(&unsafe { Peripherals::steal() }, cs, now);
    });
}
