//! Thermistor sampling in the ADC interrupt.
//!
//! The 1 kHz tick (`clock.rs`) starts one conversion per millisecond; the
//! conversion-complete interrupt adds the result to its channel's
//! [`SampleAverager`] and points the multiplexer at the other thermistor
//! for the next one. So each thermistor is sampled 500 times a second and
//! the interrupt does an add, a compare and two register writes (see
//! `firmware::thermal`, "ADC interrupt"). A conversion takes 13 ADC clocks
//! at 125 kHz = 104 µs, well inside the millisecond.
//!
//! The main loop takes one averaged reading per channel every sample
//! period ([`take_readings`]). A channel that produced no average for
//! [`MISSING_PERIODS_LIMIT`] periods in a row (a dead ADC; QEMU's AVR
//! machine has none) is reported as a reading of 0, which the thermal core
//! judges a shorted sensor: a board whose thermistors cannot be read never
//! heats.

// Without heaters (the powder bed) the conversions run but nothing reads
// them: the main loop's reader is compiled for heated machines only.


use avr_device::atmega2560::Peripherals;
#[cfg(feature = "heaters")]
use firmware::thermal::Oversampled;
use firmware::thermal::SampleAverager;

use crate::pins;

/// Conversions per averaged reading: 16 at 500 per second per channel, one
/// average every 32 ms, so every 100 ms sample period has a fresh one.
const SAMPLES_PER_READING: u8 = 16;

#[cfg(feature = "heaters")]
/// Sample periods without a reading before the channel counts as dead.
pub const MISSING_PERIODS_LIMIT: u8 = 3;

/// The thermistors in conversion order: hot end, bed.
const CHANNELS: [u8; 2] = [if pins::HOTEND.is_some() { pins::HOTEND_ADC } else { pins::BARREL_ADC }, pins::BED_ADC];

/// What the interrupt fills and the main loop empties.
struct Sampling {
    averagers: [SampleAverager; 2],
    /// Index into [`CHANNELS`] of the conversion running.
    current: u8,
}

/// Written by the ADC interrupt; the main loop reads it with interrupts off
/// (`Readings::take`), so the two never overlap. A plain `static mut`, not a
/// `Mutex<Cell<_>>`: the interrupt re-enables interrupts at once (below) and
/// must not copy the whole state twice.
static mut SAMPLING: Sampling = Sampling {
    averagers: [SampleAverager::new(SAMPLES_PER_READING), SampleAverager::new(SAMPLES_PER_READING)],
    current: 0,
};

pub fn init(dp: &Peripherals) {
    select(dp, CHANNELS[0]);
    // No conversion started yet.
    dp.ADC.adcsra.write(|w| w.aden().set_bit().adie().set_bit().adps().prescaler_128());
}

/// Start a conversion (from the 1 kHz tick, interrupts off).
#[inline(always)]
pub fn start_conversion(dp: &Peripherals) {
    // Prescaler 128: 16 MHz / 128 = 125 kHz. ADIF is written 0, which
    // leaves a pending completion alone; writing ADSC while a conversion
    // runs has no effect.
    dp.ADC.adcsra.write(|w| w.aden().set_bit().adsc().set_bit().adie().set_bit().adps().prescaler_128());
}

/// Point the multiplexer at `channel` (0–15), AVcc reference.
fn select(dp: &Peripherals, channel: u8) {
    // MUX5 in ADCSRB for channels 8–15, MUX2..0 in ADMUX.
    dp.ADC.adcsrb.write(|w| w.mux5().bit(channel >= 8));
    dp.ADC.admux.write(|w| w.refs().avcc().mux().bits(channel & 0x07));
}

/// ADC conversion complete, `sei` first (priority, nesting, sharing, cost:
/// see `interrupts.rs`).
#[no_mangle]
pub unsafe extern "avr-non-blocking-interrupt" fn __vector_29() {
    // SAFETY: the ADC registers are only written here, in `init` (before
    // interrupts) and by `start_conversion` (the tick, 1 ms apart from the
    // conversion that raised this interrupt).
    let dp = unsafe { Peripherals::steal() };
    let value = dp.ADC.adc.read().bits();
    // SAFETY: see above: this handler cannot re-enter and the main loop
    // takes the sums with interrupts off.
    let sampling = unsafe { &mut *core::ptr::addr_of_mut!(SAMPLING) };
    // The multiplexer moves to the other thermistor long before the tick
    // starts the next conversion.
    let index = usize::from(sampling.current & 1);
    sampling.current = (sampling.current + 1) & 1;
    select(&dp, CHANNELS[usize::from(sampling.current)]);
    sampling.averagers[index].push(value);
}

#[cfg(feature = "heaters")]
/// Per-channel count of sample periods without a reading.
pub struct Readings {
    missing: [u8; 2],
}

#[cfg(feature = "heaters")]
impl Readings {
    pub const fn new() -> Self {
        Self { missing: [0; 2] }
    }

    /// The hot end's and the bed's averaged readings for this sample
    /// period: `None` when none is new yet, a reading of 0 (shorted) once
    /// a channel has had none for [`MISSING_PERIODS_LIMIT`] periods.
    pub fn take(&mut self) -> [Option<Oversampled>; 2] {
        // Interrupts off only to take each sum (one lock per channel: the
        // two in one lock held the step interrupt off for 74 cycles, a
        // fifth of a step interval at 47 000 steps/s); the divisions after.
        let take = |channel: usize| {
            avr_device::interrupt::free(|_| {
                // SAFETY: with interrupts off the ADC interrupt cannot run.
                let sampling = unsafe { &mut *core::ptr::addr_of_mut!(SAMPLING) };
                sampling.averagers[channel].take_sum()
            })
        };
        let sums = [take(0), take(1)];
        let fresh = sums.map(|sum| sum.map(firmware::thermal::CompletedSum::average));
        let mut readings = [None; 2];
        for (index, reading) in fresh.into_iter().enumerate() {
            readings[index] = match reading {
                Some(reading) => {
                    self.missing[index] = 0;
                    Some(reading)
                }
                None => {
                    self.missing[index] = self.missing[index].saturating_add(1);
                    (self.missing[index] >= MISSING_PERIODS_LIMIT).then(|| Oversampled::from_count(0))
                }
            };
        }
        readings
    }
}
