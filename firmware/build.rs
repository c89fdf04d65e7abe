//! Generates the thermistor tables (ADC count → temperature) from the β
//! equation, so no table is hand-typed. See `src/thermal/thermistor.rs`.

use std::fmt::Write as _;

/// One NTC thermistor in a divider: pull-up `series_ohms` to the ADC's
/// reference, the thermistor to ground.
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

/// ADC counts between table rows.
const STEP: u32 = 4;

fn celsius(d: &Divider, adc: f64) -> f64 {
    // R = Rs / (1023/ADC − 1); 1/T = 1/T25 + ln(R/R25)/β.
    let resistance = d.series_ohms / (1023.0 / adc - 1.0);
    let inverse_kelvin = 1.0 / 298.15 + (resistance / d.r25_ohms).ln() / d.beta;
    1.0 / inverse_kelvin - 273.15
}

fn main() {
    let mut out = String::new();
    for d in DIVIDERS {
        // Rows from ADC 16 to 1008: the ends (0 and 1023) are shorted/open
        // sensors and are handled as faults, not temperatures.
        let rows: Vec<(u32, i64)> =
            (1..1023 / STEP).map(|i| i * STEP).map(|adc| (adc, (celsius(d, adc as f64) * 100.0).round() as i64)).collect();
        writeln!(out, "/// β-equation table for {}: (ADC count, hundredths of °C).", d.name).unwrap();
        writeln!(out, "#[cfg_attr(target_arch = \"avr\", link_section = \".progmem.data\")]").unwrap();
        writeln!(out, "pub static {}: crate::progmem::Flash<[(u16, i32); {}]> = crate::progmem::Flash::new([", d.name, rows.len()).unwrap();
        for (adc, centi) in rows {
            writeln!(out, "    ({adc}, {centi}),").unwrap();
        }
        writeln!(out, "]);").unwrap();
    }
    let path = std::path::Path::new(&std::env::var("OUT_DIR").unwrap()).join("thermistor_tables.rs");
    std::fs::write(path, out).unwrap();
    println!("cargo:rerun-if-changed=build.rs");
}
