//! Thermistor conversion: ADC count → temperature, by table and integer
//! interpolation (no float, no logarithm on the board).
//!
//! The tables are generated at build time (`build.rs`) from the β equation
//! every 4 ADC counts; between rows the temperature is interpolated
//! linearly. Counts outside the table (below the first row or above the last)
//! mean a shorted or open sensor and are reported as such.

use super::Celsius;

include!(concat!(env!("OUT_DIR"), "/thermistor_tables.rs"));

/// A table of (ADC count ascending, hundredths of °C descending), in flash.
pub type Table<const N: usize> = &'static crate::progmem::Flash<[(u16, i32); N]>;

/// Why an ADC reading is not a temperature.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SensorFault {
    /// Reading near zero: the thermistor or its wiring is shorted.
    Shorted,
    /// Reading near full scale: the thermistor is disconnected.
    Open,
}

/// Convert a 10-bit ADC reading with `table`.
pub fn celsius_from_adc<const N: usize>(table: Table<N>, adc: u16) -> Result<Celsius, SensorFault> {
    let row = |index: usize| table.get(index).unwrap_or((0, 0));
    let (first, last) = (row(0), row(N - 1));
    if adc < first.0 {
        return Err(SensorFault::Shorted);
    }
    if adc > last.0 {
        return Err(SensorFault::Open);
    }
    // Rows are evenly spaced, so the interval is found by division.
    let spacing = row(1).0 - first.0;
    let index = usize::from((adc - first.0) / spacing).min(N - 2);
    let (adc0, t0) = row(index);
    let (adc1, t1) = row(index + 1);
    let offset = i32::from(adc - adc0);
    let span = i32::from(adc1 - adc0);
    Ok(Celsius(t0 + (t1 - t0) * offset / span))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(actual: Celsius, expected_centi: i32, tolerance_centi: i32) -> bool {
        (actual.0 - expected_centi).abs() <= tolerance_centi
    }

    /// SPEC §4 vectors (4.8 kΩ). Linear interpolation between 4-count rows
    /// is within 0.6 °C of the β equation over 25–300 °C.
    #[test]
    fn spec_section_4_vectors_hold_to_the_tables_error() {
        for (adc, centi) in [(976, 2507), (606, 10000), (203, 17491), (118, 21006), (79, 23777), (36, 29926)] {
            let t = celsius_from_adc(&NTC100K_B3950_4K8, adc).unwrap();
            assert!(close(t, centi, 60), "ADC {adc}: {t:?} vs {centi}");
        }
    }

    #[test]
    fn the_ends_of_the_scale_are_sensor_faults() {
        assert_eq!(celsius_from_adc(&NTC100K_B3950_4K7, 0), Err(SensorFault::Shorted));
        assert_eq!(celsius_from_adc(&NTC100K_B3950_4K7, 1023), Err(SensorFault::Open));
    }

    #[test]
    fn room_temperature_on_a_stock_ramps() {
        // 100 k at 25 °C on 4.7 k: ADC = 1023·100/104.7 ≈ 977.
        let t = celsius_from_adc(&NTC100K_B3950_4K7, 977).unwrap();
        assert!(close(t, 2500, 60), "{t:?}");
    }
}
