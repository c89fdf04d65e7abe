//! Thermistor conversion: ADC count → temperature, by table and integer
//! interpolation (no float, no logarithm on the board).
//!
//! # Tables
//! Generated at build time (`build.rs`) from the β equation
//! (R = Rs / (1023/ADC − 1); 1/T = 1/T25 + ln(R/R25)/β). Rows are not
//! evenly spaced: the generator places each row as far from the previous
//! one as linear interpolation allows while staying within **0.1 °C of the
//! β equation from 0 to 300 °C** (1 °C from 300 to 420 °C and from −30 to
//! 0 °C), checked at every 1/16 count with the firmware's own integer
//! arithmetic. That takes 54 rows (216 bytes of flash) per table instead of
//! 254 rows every 4 counts. The achieved error is exported as
//! `<TABLE>_ERROR_CENTI` and tested.
//!
//! # Open and shorted sensors
//! A table spans 420 °C (its first row, ADC 12 on 4.7 kΩ) to −30 °C (its
//! last row, ADC 1020). A reading **below the first row** is a shorted
//! thermistor (≲ 50 Ω); a reading **above the last row** (1021–1023, the
//! pull-up alone) is an open one. One such reading is only suspicious: the
//! [`HeaterGuard`](super::guard::HeaterGuard) latches the fault after a few
//! consecutive ones (well within 1 s).
//!
//! # Oversampling
//! The ADC interrupt feeds a [`SampleAverager`]; the main loop takes the
//! average as an [`Oversampled`] reading in 1/16 counts, which the table
//! interpolates to sub-count resolution (at 300 °C one count is 1.6 °C, so
//! averaging noisy conversions matters).

use super::Celsius;
use crate::progmem::Flash;

include!(concat!(env!("OUT_DIR"), "/thermistor_tables.rs"));

/// A table of (ADC count ascending, hundredths of °C descending), in flash;
/// each temperature is kept as a `u16` (plus `STORED_OFFSET`): 4 bytes a row.
pub struct ThermistorTable<const N: usize>(Flash<[(u16, u16); N]>);

impl<const N: usize> ThermistorTable<N> {
    pub const fn new(rows: [(u16, u16); N]) -> Self {
        Self(Flash::new(rows))
    }

    /// Number of rows.
    pub const fn len(&self) -> usize {
        N
    }

    pub const fn is_empty(&self) -> bool {
        N == 0
    }

    /// Row `index`: (ADC count, hundredths of °C); `None` past the end.
    pub fn get(&self, index: usize) -> Option<(u16, i32)> {
        let (adc, stored) = self.0.get(index)?;
        Some((adc, celsius_of(stored)))
    }
}

/// A stored temperature in hundredths of °C.
fn celsius_of(stored: u16) -> i32 {
    i32::from(stored) - STORED_OFFSET
}

/// A table in flash, as the conversions take it.
pub type Table<const N: usize> = &'static ThermistorTable<N>;

/// Why an ADC reading is not a temperature.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SensorFault {
    /// Reading near zero: the thermistor or its wiring is shorted.
    Shorted,
    /// Reading near full scale: the thermistor is disconnected.
    Open,
}

/// An ADC reading in sixteenths of a 10-bit count (0..=16368): the average
/// of several conversions keeps its fraction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Oversampled(pub u16);

impl Oversampled {
    /// One plain conversion (0..=1023; larger values are clamped).
    pub const fn from_count(adc: u16) -> Self {
        Self(if adc > 1023 { 1023 * 16 } else { adc * 16 })
    }
}

/// A thermistor circuit the firmware has a table for: a reference to the
/// table in flash, which configurations can hold (and that can live in
/// flash itself: the address is that of the table in program memory, and
/// [`Flash`] reads it from there). Only the tables a configuration names
/// are linked.
#[derive(Clone, Copy)]
pub struct Thermistor(Table<ROWS>);

#[allow(non_upper_case_globals)]
impl Thermistor {
    /// 100 k NTC, β 3950, 4.7 kΩ pull-up (stock RAMPS 1.4).
    pub const Ntc100kB3950Pullup4k7: Thermistor = Thermistor(&NTC100K_B3950_4K7);
    /// 100 k NTC, β 3950, 4.8 kΩ pull-up (SPEC §4's extrusion line).
    pub const Ntc100kB3950Pullup4k8: Thermistor = Thermistor(&NTC100K_B3950_4K8);

    /// A thermistor with its own table (a machine file's, generated).
    pub const fn new(table: Table<ROWS>) -> Self {
        Self(table)
    }

    /// Temperature of an (oversampled) reading.
    pub fn celsius(self, reading: Oversampled) -> Result<Celsius, SensorFault> {
        celsius_from_oversampled(self.0, reading)
    }
}

impl PartialEq for Thermistor {
    fn eq(&self, other: &Self) -> bool {
        core::ptr::eq(self.0, other.0)
    }
}

impl Eq for Thermistor {}

impl core::fmt::Debug for Thermistor {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(if *self == Self::Ntc100kB3950Pullup4k7 {
            "Ntc100kB3950Pullup4k7"
        } else if *self == Self::Ntc100kB3950Pullup4k8 {
            "Ntc100kB3950Pullup4k8"
        } else {
            "Thermistor"
        })
    }
}

/// Convert a 10-bit ADC reading with `table`.
pub fn celsius_from_adc<const N: usize>(table: Table<N>, adc: u16) -> Result<Celsius, SensorFault> {
    celsius_from_oversampled(table, Oversampled::from_count(adc))
}

/// Convert a reading in 1/16 counts with `table` (binary search for the
/// row pair, then linear interpolation rounded half away from zero).
pub fn celsius_from_oversampled<const N: usize>(table: Table<N>, reading: Oversampled) -> Result<Celsius, SensorFault> {
    let row = |index: usize| row(table, index);
    let x16 = reading.0;
    if N < 2 || x16 < row(0).0 {
        return Err(SensorFault::Shorted);
    }
    if x16 > row(N - 1).0 {
        return Err(SensorFault::Open);
    }
    // Invariant: row(low) ≤ x16 ≤ row(high).
    let (mut low, mut high) = (0, N - 1);
    while high - low > 1 {
        let middle = (low + high) / 2;
        if row(middle).0 <= x16 {
            low = middle;
        } else {
            high = middle;
        }
    }
    Ok(Celsius(celsius_of(interpolate(x16, row(low), row(high)))))
}

/// One stored row out of flash with its ADC count in sixteenths (counts
/// are at most 1023: × 16 fits a u16); one copy of the copying loop, not
/// one per use.
#[inline(never)]
fn row<const N: usize>(table: Table<N>, index: usize) -> (u16, u16) {
    let (adc, stored) = table.0.get(index).unwrap_or((0, 0));
    (adc.wrapping_mul(16), stored)
}

/// The stored temperature at `x16` (with `row0 ≤ x16 ≤ row1`, ADC counts
/// in sixteenths) between two rows: `t0 + (t1 − t0)·(x16 − x0)/(x1 − x0)`,
/// the quotient rounded half away from zero. `build.rs` evaluates the
/// table's error with the same arithmetic. The product stays below 2³²:
/// |t1 − t0| < 2¹⁶ and the offset < 2¹⁴.
fn interpolate(x16: u16, (x0, t0): (u16, u16), (x1, t1): (u16, u16)) -> u16 {
    let offset = x16.wrapping_sub(x0);
    let span = x1.wrapping_sub(x0);
    if span == 0 || x1 < x0 {
        return t0;
    }
    let falling = t1 < t0;
    let difference = if falling { t0 - t1 } else { t1 - t0 };
    // ≤ difference, as offset ≤ span.
    let magnitude = ((u32::from(difference) * u32::from(offset) + u32::from(span / 2)) / u32::from(span)) as u16;
    if falling {
        t0.wrapping_sub(magnitude)
    } else {
        t0.wrapping_add(magnitude)
    }
}

/// Averages `samples` conversions into one [`Oversampled`] reading.
///
/// [`push`](Self::push) is what the ADC interrupt calls: an add, a compare
/// and a copy, no division. [`take`](Self::take) runs in the main loop
/// (inside a critical section on the board) and divides. At most 64
/// samples, so the sum fits 16 bits. 7 bytes on the AVR.
#[derive(Clone, Copy, Debug)]
pub struct SampleAverager {
    sum: u16,
    count: u8,
    samples: u8,
    /// A completed sum the main loop has not taken yet.
    ready: Option<u16>,
}

impl SampleAverager {
    /// Most samples per average.
    pub const MAX_SAMPLES: u8 = 64;

    /// Average `samples` conversions (clamped to 1..=64).
    pub const fn new(samples: u8) -> Self {
        let samples = if samples == 0 {
            1
        } else if samples > Self::MAX_SAMPLES {
            Self::MAX_SAMPLES
        } else {
            samples
        };
        Self { sum: 0, count: 0, samples, ready: None }
    }

    /// Add one 10-bit conversion (clamped to 1023). Returns `true` when it
    /// completed an average (which replaces one not yet taken).
    pub fn push(&mut self, adc: u16) -> bool {
        self.sum += if adc > 1023 { 1023 } else { adc };
        self.count += 1;
        if self.count < self.samples {
            return false;
        }
        self.ready = Some(self.sum);
        self.sum = 0;
        self.count = 0;
        true
    }

    /// The latest completed average, once.
    pub fn take(&mut self) -> Option<Oversampled> {
        self.take_sum().map(CompletedSum::average)
    }

    /// The latest completed sum, once, without the division: what a board
    /// takes inside its critical section (a 32-bit division there would
    /// hold the step interrupt off for tens of microseconds); the average
    /// is worked out afterwards with [`CompletedSum::average`].
    pub fn take_sum(&mut self) -> Option<CompletedSum> {
        Some(CompletedSum { sum: self.ready.take()?, samples: self.samples })
    }
}

/// A completed sum of conversions, not yet divided.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CompletedSum {
    sum: u16,
    samples: u8,
}

impl CompletedSum {
    /// The average, as 16 × a 10-bit conversion.
    pub fn average(self) -> Oversampled {
        let samples = u32::from(self.samples);
        Oversampled(((u32::from(self.sum) * 16 + samples / 2) / samples) as u16)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(table: Table<ROWS>, adc: u16) -> i32 {
        celsius_from_adc(table, adc).unwrap().0
    }

    #[test]
    fn tables_have_their_rows_and_state_their_error_within_a_tenth_of_a_degree() {
        assert_eq!(NTC100K_B3950_4K7.len(), ROWS);
        assert_eq!(NTC100K_B3950_4K8.len(), ROWS);
        const { assert!(NTC100K_B3950_4K7_ERROR_CENTI <= 10) };
        const { assert!(NTC100K_B3950_4K8_ERROR_CENTI <= 10) };
    }

    /// SPEC §4 vectors (4.8 kΩ; the SPEC's values are the β equation
    /// rounded to 0.01 °C), each within the table's stated error.
    #[test]
    fn spec_section_4_vectors_hold_to_the_tables_error() {
        let tolerance = NTC100K_B3950_4K8_ERROR_CENTI + 1;
        for (adc, centi) in [(976, 2507), (606, 10000), (203, 17491), (118, 21006), (79, 23777), (36, 29926)] {
            let t = at(&NTC100K_B3950_4K8, adc);
            assert!((t - centi).abs() <= tolerance, "ADC {adc}: {t} vs {centi}");
        }
    }

    #[test]
    fn exact_rows_read_back_their_stored_value() {
        let (adc, centi) = NTC100K_B3950_4K7.get(10).unwrap();
        assert_eq!(at(&NTC100K_B3950_4K7, adc), centi);
        assert_eq!(at(&NTC100K_B3950_4K7, 12), 41297); // first row: 420 °C side
        assert_eq!(at(&NTC100K_B3950_4K7, 1020), -2658); // last row: −26.58 °C
    }

    #[test]
    fn room_temperature_on_a_stock_ramps() {
        // 100 k at 25 °C on 4.7 k: ADC = 1023·100/104.7 = 977.08.
        let t = at(&NTC100K_B3950_4K7, 977);
        assert!((t - 2500).abs() <= 10, "{t}");
    }

    #[test]
    fn temperature_falls_as_the_count_rises_at_every_sixteenth() {
        let mut previous = i32::MAX;
        for x16 in 12 * 16..=1020 * 16 {
            let t = celsius_from_oversampled(&NTC100K_B3950_4K7, Oversampled(x16)).unwrap().0;
            assert!(t <= previous, "{x16}: {t} after {previous}");
            previous = t;
        }
    }

    #[test]
    fn an_oversampled_reading_resolves_between_counts() {
        // 118 → 210.06 °C and 119 → ~209.7 °C; half-way reads half-way.
        let whole = at(&NTC100K_B3950_4K8, 118);
        let next = at(&NTC100K_B3950_4K8, 119);
        let half = celsius_from_oversampled(&NTC100K_B3950_4K8, Oversampled(118 * 16 + 8)).unwrap().0;
        assert!(next < half && half < whole, "{next} < {half} < {whole}");
    }

    /// The previous conversion (i32 rows, signed arithmetic), as the reference.
    fn reference(table: Table<ROWS>, x16: u16) -> Result<Celsius, SensorFault> {
        let rows: std::vec::Vec<(u16, i32)> = (0..table.len()).map(|i| table.get(i).unwrap()).collect();
        let x16 = i32::from(x16);
        let sixteenths = |(adc, _): (u16, i32)| i32::from(adc) * 16;
        if x16 < sixteenths(rows[0]) {
            return Err(SensorFault::Shorted);
        }
        if x16 > sixteenths(rows[rows.len() - 1]) {
            return Err(SensorFault::Open);
        }
        let (mut low, mut high) = (0, rows.len() - 1);
        while high - low > 1 {
            let middle = (low + high) / 2;
            if sixteenths(rows[middle]) <= x16 {
                low = middle;
            } else {
                high = middle;
            }
        }
        let ((adc0, t0), (adc1, t1)) = (rows[low], rows[high]);
        let numerator = (t1 - t0) * (x16 - i32::from(adc0) * 16);
        let denominator = (i32::from(adc1) - i32::from(adc0)) * 16;
        let magnitude = (numerator.abs() + denominator / 2) / denominator;
        Ok(Celsius(t0 + if numerator < 0 { -magnitude } else { magnitude }))
    }

    #[test]
    fn conversion_matches_the_signed_reference_at_every_sixteenth() {
        for table in [&NTC100K_B3950_4K7, &NTC100K_B3950_4K8] {
            for x16 in 0..=1023 * 16 {
                assert_eq!(celsius_from_oversampled(table, Oversampled(x16)), reference(table, x16), "{x16}");
            }
        }
    }

    #[test]
    fn open_and_shorted_thresholds_are_the_table_ends() {
        let table = &NTC100K_B3950_4K7;
        assert_eq!(celsius_from_adc(table, 0), Err(SensorFault::Shorted));
        assert_eq!(celsius_from_adc(table, 11), Err(SensorFault::Shorted));
        assert!(celsius_from_adc(table, 12).is_ok());
        assert!(celsius_from_adc(table, 1020).is_ok());
        assert_eq!(celsius_from_adc(table, 1021), Err(SensorFault::Open));
        assert_eq!(celsius_from_adc(table, 1023), Err(SensorFault::Open));
        assert_eq!(celsius_from_oversampled(table, Oversampled(1020 * 16 + 1)), Err(SensorFault::Open));
        assert_eq!(celsius_from_oversampled(table, Oversampled(12 * 16 - 1)), Err(SensorFault::Shorted));
    }

    #[test]
    fn thermistor_names_select_their_tables() {
        let reading = Oversampled::from_count(606);
        assert_eq!(Thermistor::Ntc100kB3950Pullup4k8.celsius(reading), celsius_from_adc(&NTC100K_B3950_4K8, 606));
        assert_eq!(Thermistor::Ntc100kB3950Pullup4k7.celsius(reading), celsius_from_adc(&NTC100K_B3950_4K7, 606));
    }

    #[test]
    fn averager_of_ten_yields_the_mean_in_sixteenths_once() {
        let mut averager = SampleAverager::new(10);
        for adc in [118, 118, 119, 118, 119, 118, 118, 119, 118, 118] {
            assert_eq!(averager.take(), None);
            averager.push(adc);
        }
        // Sum 1183 → 118.3 counts → 1892.8 sixteenths → 1893.
        assert_eq!(averager.take(), Some(Oversampled(1893)));
        assert_eq!(averager.take(), None);
    }

    #[test]
    fn averager_reports_completion_and_keeps_only_the_latest_average() {
        let mut averager = SampleAverager::new(2);
        assert!(!averager.push(100));
        assert!(averager.push(102));
        assert!(!averager.push(1023));
        assert!(averager.push(5000)); // clamped to 1023
        assert_eq!(averager.take(), Some(Oversampled(1023 * 16)));
    }

    #[test]
    fn averager_of_64_full_scale_samples_does_not_overflow() {
        let mut averager = SampleAverager::new(200); // clamped to 64
        for _ in 0..63 {
            assert!(!averager.push(1023));
        }
        assert!(averager.push(1023));
        assert_eq!(averager.take(), Some(Oversampled(16368)));
    }
}
