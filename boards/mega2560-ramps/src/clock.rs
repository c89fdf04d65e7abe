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
    // Mode 4, CTC on OCR3A: WGM33:32 = 01 (in TCCR3B), WGM31:30 = 00.
    timer.tccr3a.write(|w| w.wgm3().bits(0b00));
    timer.tccr3b.write(|w| w.wgm3().bits(0b01).cs3().prescale_64());
    timer.timsk3.write(|w| w.ocie3a().set_bit());
}

/// Microseconds since boot (wraps after 71 minutes), to 4 µs: the count
/// plus Timer3's progress into the millisecond (prescaler 64). Called with
/// interrupts off; a compare match not yet taken reads up to 1 ms early.
#[cfg(feature = "encoders")]
pub fn micros(cs: avr_device::interrupt::CriticalSection<'_>) -> u32 {
    // SAFETY: reading TCNT3 (the 16-bit read goes through TEMP, and
    // interrupts are off).
    let ticks = unsafe { Peripherals::steal() }.TC3.tcnt3.read().bits();
    MILLIS.borrow(cs).get().wrapping_mul(1000).wrapping_add(u32::from(ticks) * 4)
}

/// Hold the tick interrupt off (`true`) or let it in again (who masks the
/// tick, and why: see `interrupts.rs`).
#[cfg(feature = "encoders")]
pub fn mask_tick(dp: &Peripherals, masked: bool) {
    // OCIE3A is the only interrupt of Timer3 in use.
    dp.TC3.timsk3.write(|w| w.ocie3a().bit(!masked));
}

/// Mask the tick from an interrupt handler; returns the mask to put back
/// with [`release_tick`] (the main loop may have masked it already).
#[cfg(feature = "encoders")]
#[inline(always)]
pub fn hold_tick() -> u8 {
    // SAFETY: Timer3's interrupt mask only (OCIE3A is its one interrupt).
    let timer = unsafe { &*avr_device::atmega2560::TC3::ptr() };
    let mask = timer.timsk3.read().bits();
    timer.timsk3.write(|w| unsafe { w.bits(0) });
    mask
}

#[cfg(feature = "encoders")]
#[inline(always)]
pub fn release_tick(mask: u8) {
    // SAFETY: as in `hold_tick`.
    let timer = unsafe { &*avr_device::atmega2560::TC3::ptr() };
    timer.timsk3.write(|w| unsafe { w.bits(mask) });
}

/// Milliseconds since boot (wraps after 49 days).
pub fn millis() -> u32 {
    avr_device::interrupt::free(|cs| MILLIS.borrow(cs).get())
}

/// TIMER3_COMPA, `sei` first (priority, nesting, cost: see `interrupts.rs`).
/// With the blocking ABI its prologue and the ADC start held a step back
/// by up to ~80 cycles, more than the bench's 10 % lateness allowance at
/// 30 000 steps/s (53 cycles).
#[no_mangle]
pub unsafe extern "avr-non-blocking-interrupt" fn __vector_32() {
    // SAFETY: only the ADC's control register is written (see adc.rs).
    crate::adc::start_conversion(&unsafe { Peripherals::steal() });
    // The count changes with interrupts off because the main loop reads
    // it so (four bytes); the step interrupt never reads it.
    let _now = avr_device::interrupt::free(|cs| {
        let millis = MILLIS.borrow(cs);
        let now = millis.get().wrapping_add(1);
        millis.set(now);
        #[cfg(feature = "machine-powder-bed")]
        crate::bed::on_tick(&unsafe { Peripherals::steal() }, cs, now);
        #[cfg(any(feature = "bed-ssr", feature = "machine-extrusion-line"))]
        crate::ssr::on_tick(&unsafe { Peripherals::steal() }, cs, now);
        now
    });
    // The encoder loops, with interrupts on (the I²C reads take ≈ 120 µs).
    #[cfg(feature = "encoders")]
    crate::encoders::on_tick(&unsafe { Peripherals::steal() }, _now);
}
