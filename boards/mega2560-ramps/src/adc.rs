//! Thermistor sampling on the ADC (AVcc reference, 125 kHz ADC clock).
//!
//! A conversion takes 13 ADC clocks = 104 µs. The wait is bounded, so a
//! missing or broken ADC (QEMU's AVR machine has none) yields a reading of
//! zero, which the core reports as a shorted sensor, instead of a hang.

use avr_device::atmega2560::Peripherals;

/// Longest wait for one conversion, in polls (a conversion needs ≈ 300).
const MAX_POLLS: u16 = 2_000;

pub fn init(dp: &Peripherals) {
    // SAFETY: ADEN and prescaler 128 (ADPS2..0 = 111).
    dp.ADC.adcsra.write(|w| unsafe { w.bits(0b1000_0111) });
}

/// One 10-bit conversion of `channel` (0–15); 0 if it never completes.
pub fn read(dp: &Peripherals, channel: u8) -> u16 {
    let adc = &dp.ADC;
    // MUX5 lives in ADCSRB bit 3; MUX4..0 and REFS0 (AVcc) in ADMUX.
    // SAFETY: valid channel selections and reference.
    adc.adcsrb.write(|w| unsafe { w.bits(if channel >= 8 { 1 << 3 } else { 0 }) });
    adc.admux.write(|w| unsafe { w.bits((1 << 6) | (channel & 0x07)) });
    // SAFETY: ADEN | ADSC | prescaler 128.
    adc.adcsra.write(|w| unsafe { w.bits(0b1100_0111) });
    for _ in 0..MAX_POLLS {
        if adc.adcsra.read().bits() & (1 << 6) == 0 {
            return adc.adc.read().bits();
        }
    }
    0
}
