//! Generates the thermistor tables (ADC count → temperature) from the β
//! equation, so no table is hand-typed. See `src/thermal/thermistor.rs`.
//!
//! Rows are placed where they are needed, not every N counts: starting at
//! the hot end of the table, each row is pushed as far out as linear
//! interpolation allows while the interpolated temperature — computed with
//! exactly the firmware's integer arithmetic, at every 1/16 of a count (the
//! oversampled resolution) and from the rounded stored values — stays
//! within [`ERROR_IN_RANGE_C`] of the β equation between 0 and 300 °C, and
//! within [`ERROR_OUTSIDE_C`] from 300 to 420 °C and from −30 to 0 °C.
//! The achieved maximum errors are emitted beside each table and checked by
//! the firmware's unit tests.

use std::fmt::Write as _;

/// One NTC thermistor in a divider: pull-up `series_ohms` to the ADC's
/// reference, the thermistor to ground, a 10-bit ADC.
struct Divider {
    name: &'static str,
    r25_ohms: f64,
    beta: f64,
    series_ohms: f64,
}

const DIVIDERS: &[Divider] = &[
    // Stock RAMPS 1.4: 100 k NTC (β 3950), 4.7 kΩ pull-up.
    Divider { name: "NTC100K_B3950_4K7", r25_ohms: 100_000.0, beta: 3950.0, series_ohms: 4_700.0 },
    // SPEC §4 (extrusion line): the same NTC on a 4.8 kΩ resistor.
    Divider { name: "NTC100K_B3950_4K8", r25_ohms: 100_000.0, beta: 3950.0, series_ohms: 4_800.0 },
];

/// Hottest temperature in a table: below its ADC count the sensor is
/// reported shorted.
const HOTTEST_C: f64 = 420.0;
/// Coldest temperature in a table: above its ADC count the sensor is
/// reported open (a disconnected thermistor reads full scale, 1023).
const COLDEST_C: f64 = -30.0;
/// Added to a temperature (hundredths of °C) to store it as a `u16`.
const STORED_OFFSET: i64 = 5_000;
/// Interpolation error bound between 0 and 300 °C.
const ERROR_IN_RANGE_C: f64 = 0.1;
/// Interpolation error bound outside 0–300 °C (still inside the table).
const ERROR_OUTSIDE_C: f64 = 1.0;

/// β equation: R = Rs / (1023/ADC − 1); 1/T = 1/T25 + ln(R/R25)/β.
fn celsius(d: &Divider, adc: f64) -> f64 {
    let resistance = d.series_ohms / (1023.0 / adc - 1.0);
    let inverse_kelvin = 1.0 / 298.15 + (resistance / d.r25_ohms).ln() / d.beta;
    1.0 / inverse_kelvin - 273.15
}

/// The inverse: ADC count (fractional) of a temperature.
fn adc_count(d: &Divider, celsius: f64) -> f64 {
    let resistance = d.r25_ohms * (d.beta * (1.0 / (celsius + 273.15) - 1.0 / 298.15)).exp();
    1023.0 * resistance / (resistance + d.series_ohms)
}

fn stored(d: &Divider, adc: u32) -> i64 {
    (celsius(d, f64::from(adc)) * 100.0).round() as i64
}

/// Exactly `thermistor::interpolate`: hundredths of °C at `x16` sixteenths
/// of a count between rows, rounding half away from zero.
fn interpolate(x16: i64, (adc0, t0): (u32, i64), (adc1, t1): (u32, i64)) -> i64 {
    let numerator = (t1 - t0) * (x16 - i64::from(adc0) * 16);
    let denominator = i64::from(adc1 - adc0) * 16;
    let magnitude = (numerator.abs() + denominator / 2) / denominator;
    t0 + if numerator < 0 { -magnitude } else { magnitude }
}

fn allowed_error(celsius: f64) -> f64 {
    if (0.0..=300.0).contains(&celsius) {
        ERROR_IN_RANGE_C
    } else {
        ERROR_OUTSIDE_C
    }
}

/// Largest error (°C) of the segment between two rows, inside and outside
/// 0–300 °C; `None` if the segment breaks its bound somewhere.
fn segment_errors(d: &Divider, adc0: u32, adc1: u32) -> Option<(f64, f64)> {
    let (row0, row1) = ((adc0, stored(d, adc0)), (adc1, stored(d, adc1)));
    let (mut inside, mut outside) = (0.0f64, 0.0f64);
    for x16 in i64::from(adc0) * 16..=i64::from(adc1) * 16 {
        let exact = celsius(d, x16 as f64 / 16.0);
        let error = (interpolate(x16, row0, row1) as f64 / 100.0 - exact).abs();
        if error > allowed_error(exact) {
            return None;
        }
        if (0.0..=300.0).contains(&exact) {
            inside = inside.max(error);
        } else {
            outside = outside.max(error);
        }
    }
    Some((inside, outside))
}

fn main() {
    let mut out = String::new();
    let mut table_rows = None;
    for d in DIVIDERS {
        let first = adc_count(d, HOTTEST_C).ceil() as u32;
        let last = adc_count(d, COLDEST_C).floor() as u32;
        let mut rows = vec![first];
        let (mut worst_inside, mut worst_outside) = (0.0f64, 0.0f64);
        let mut start = first;
        while start < last {
            // The longest segment from `start` that keeps its bound (a
            // one-count segment always does: it is checked below).
            let mut end = start + 1;
            let mut errors = segment_errors(d, start, end).expect("a one-count segment breaks the bound: refine the table");
            while end < last {
                match segment_errors(d, start, end + 1) {
                    Some(e) => {
                        end += 1;
                        errors = e;
                    }
                    None => break,
                }
            }
            worst_inside = worst_inside.max(errors.0);
            worst_outside = worst_outside.max(errors.1);
            rows.push(end);
            start = end;
        }
        let inside_centi = (worst_inside * 100.0).ceil() as i64;
        let outside_centi = (worst_outside * 100.0).ceil() as i64;
        writeln!(
            out,
            "/// β-equation table for {name} (R25 {r25} Ω, β {beta}, pull-up {rs} Ω, 10-bit ADC):\n\
             /// (ADC count, hundredths of °C), {n} rows from ADC {first} ({hot} °C) to {last} ({cold} °C).\n\
             /// Linear interpolation is within {inside_centi}/100 °C of the β equation from 0 to 300 °C\n\
             /// and within {outside_centi}/100 °C elsewhere in the table.",
            name = d.name,
            r25 = d.r25_ohms,
            beta = d.beta,
            rs = d.series_ohms,
            n = rows.len(),
            hot = HOTTEST_C,
            cold = COLDEST_C,
        )
        .unwrap();
        // Each temperature is stored as a `u16`, hundredths of °C plus
        // `STORED_OFFSET` (4 bytes a row instead of 6).
        writeln!(out, "#[cfg_attr(target_arch = \"avr\", link_section = \".progmem.data\")]").unwrap();
        writeln!(out, "pub static {}: ThermistorTable<{}> = ThermistorTable::new([", d.name, rows.len()).unwrap();
        for adc in &rows {
            let raw = stored(d, *adc) + STORED_OFFSET;
            assert!((0..=i64::from(u16::MAX)).contains(&raw), "{}: {} °C/100 does not fit the u16 storage", d.name, stored(d, *adc));
            writeln!(out, "    ({adc}, {raw}),").unwrap();
        }
        writeln!(out, "]);").unwrap();
        match table_rows {
            None => table_rows = Some(rows.len()),
            Some(n) => assert_eq!(n, rows.len(), "every table must have the same number of rows (`thermistor::ROWS`)"),
        }
        writeln!(out, "/// Worst interpolation error of [`{}`] from 0 to 300 °C, hundredths of °C.", d.name).unwrap();
        writeln!(out, "pub const {}_ERROR_CENTI: i32 = {inside_centi};", d.name).unwrap();
    }
    writeln!(out, "/// Rows of every table.\npub const ROWS: usize = {};", table_rows.unwrap()).unwrap();
    writeln!(out, "/// What is added to hundredths of °C to store them as `u16`.\nconst STORED_OFFSET: i32 = {STORED_OFFSET};").unwrap();
    let path = std::path::Path::new(&std::env::var("OUT_DIR").unwrap()).join("thermistor_tables.rs");
    std::fs::write(path, out).unwrap();
    println!("cargo:rerun-if-changed=build.rs");
}
