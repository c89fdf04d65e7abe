//! ADC3 single conversions for the thermistors (PF3–PF6 are ADC3 inputs).
//!
//! 12-bit results; the core's thermistor tables are for a 10-bit ADC with
//! the pull-up on the reference voltage, so [`read_10bit`] drops two bits
//! (the ratio is what matters: 3.3 V pull-up and reference here, 5 V on
//! RAMPS). ADC clock 84 MHz / 4 = 21 MHz; 480-cycle sampling (≈ 23 µs per
//! conversion) gives the 4.7 kΩ divider time to charge the sample
//! capacitor. Called from the main loop every 100 ms, so polled.

use stm32f4::stm32f407 as pac;

/// RCC_APB2ENR: ADC3EN.
const ADC3EN: u32 = 1 << 10;
// ADC_CR2 bits.
const ADON: u32 = 1 << 0;
const SWSTART: u32 = 1 << 30;
// ADC_SR: EOC.
const EOC: u32 = 1 << 1;
/// ADC_CCR (common to the three ADCs): ADCPRE = 01, PCLK2 / 4.
const ADCPRE_DIV4: u32 = 0b01 << 16;
/// SMPx = 111: 480 cycles.
const SAMPLE_480: u32 = 0b111;
/// Bounded wait for a conversion (≈ 4 000 core cycles; each poll is a few).
const MAX_POLLS: u32 = 20_000;

pub fn init(rcc: &pac::RCC, common: &pac::ADC_COMMON, adc: &pac::ADC3) {
    // SAFETY (all `bits` here): documented field values.
    rcc.apb2enr().modify(|r, w| unsafe { w.bits(r.bits() | ADC3EN) });
    cortex_m::asm::dsb();
    common.ccr().write(|w| unsafe { w.bits(ADCPRE_DIV4) });
    // 480-cycle sampling on every channel (0–9 in SMPR2, 10–18 in SMPR1).
    let all = |count: u32| (0..count).fold(0, |bits, ch| bits | (SAMPLE_480 << (3 * ch)));
    adc.smpr2().write(|w| unsafe { w.bits(all(10)) });
    adc.smpr1().write(|w| unsafe { w.bits(all(9)) });
    adc.cr1().write(|w| unsafe { w.bits(0) });
    adc.sqr1().write(|w| unsafe { w.bits(0) }); // one conversion per sequence
    adc.cr2().write(|w| unsafe { w.bits(ADON) });
}

/// One conversion of `channel`, 12 bits.
pub fn read(adc: &pac::ADC3, channel: u8) -> u16 {
    // SAFETY: a channel number 0–18 in SQ1; documented CR2 bits.
    adc.sqr3().write(|w| unsafe { w.bits(u32::from(channel & 0x1F)) });
    adc.cr2().write(|w| unsafe { w.bits(ADON | SWSTART) });
    for _ in 0..MAX_POLLS {
        if adc.sr().read().bits() & EOC != 0 {
            break;
        }
    }
    (adc.dr().read().bits() & 0x0FFF) as u16
}

/// One conversion scaled to the core's 10-bit tables.
pub fn read_10bit(adc: &pac::ADC3, channel: u8) -> u16 {
    read(adc, channel) >> 2
}

/// Conversions averaged into one reading.
pub const SAMPLES_PER_READING: u32 = 16;

/// One thermal reading of `channel`: 16 conversions of 12 bits summed and
/// scaled to the core's 16 × 10-bit [`Oversampled`] (the two extra bits of
/// this ADC add resolution). 16 × 23 µs: polled from the main loop every
/// 100 ms, well under a millisecond.
pub fn oversampled(adc: &pac::ADC3, channel: u8) -> firmware::thermal::Oversampled {
    let sum: u32 = (0..SAMPLES_PER_READING).map(|_| u32::from(read(adc, channel))).sum();
    firmware::thermal::Oversampled((sum >> 2).min(16 * 1023) as u16)
}
