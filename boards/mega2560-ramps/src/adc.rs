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


/// Non-blocking sampling of the thermistors for the main loop: each call
/// collects a finished conversion into its channel's averager and starts
/// the next channel's, so no pass waits the 104 µs of a conversion.
pub struct Sampler {
    /// Index into the channel list of the conversion running, if any.
    running: Option<usize>,
    /// Calls since that conversion started (QEMU has no ADC: give up).
    polls: u16,
}

impl Sampler {
    pub const fn new() -> Self {
        Self { running: None, polls: 0 }
    }

    /// One step; `averagers[i]` collects `channels[i]`. A conversion that
    /// never finishes (no ADC) counts as a reading of 0, which the thermal
    /// core reports as a shorted sensor: a board without working
    /// thermistors never heats.
    pub fn poll(&mut self, dp: &Peripherals, channels: &[u8], averagers: &mut [firmware::thermal::SampleAverager]) {
        let adc = &dp.ADC;
        if let Some(index) = self.running {
            let done = adc.adcsra.read().bits() & (1 << 6) == 0;
            self.polls = self.polls.saturating_add(1);
            if !done && self.polls < MAX_POLLS {
                return;
            }
            let value = if done { adc.adc.read().bits() } else { 0 };
            averagers[index].push(value);
            self.running = Some((index + 1) % channels.len());
        } else {
            self.running = Some(0);
        }
        let index = self.running.unwrap_or(0);
        let channel = channels[index];
        // SAFETY: valid channel selections, AVcc reference, ADEN | ADSC |
        // prescaler 128.
        adc.adcsrb.write(|w| unsafe { w.bits(if channel >= 8 { 1 << 3 } else { 0 }) });
        adc.admux.write(|w| unsafe { w.bits((1 << 6) | (channel & 0x07)) });
        adc.adcsra.write(|w| unsafe { w.bits(0b1100_0111) });
        self.polls = 0;
    }
}
