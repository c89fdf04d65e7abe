//! Thermistors by the names users know them (Marlin's type numbers too),
//! and the firmware's ADC → temperature tables generated from their
//! resistance curves: nothing is typed in.
//!
//! A thermistor is a resistance curve R(T): either the β equation
//! (R = R25·e^(β(1/T − 1/T25))) or a Steinhart–Hart fit through three
//! points of the maker's R/T table. In a divider with a pull-up `Rs` to the
//! ADC reference and a 10-bit ADC, count = 1023·R/(R + Rs).
//!
//! # Tables
//! Rows are placed where they are needed: from the hot end of the table,
//! each row goes as far out as linear interpolation allows while the
//! interpolated temperature — computed with exactly the firmware's integer
//! arithmetic (`thermal::thermistor::interpolate`), at every 1/16 count,
//! from the rounded stored values — stays within [`ERROR_IN_RANGE_C`] of
//! the curve between 0 and 300 °C and within [`ERROR_OUTSIDE_C`] elsewhere
//! in the table. Every table then gets exactly [`ROWS`] rows (the longest
//! segments are halved until it has), so that the firmware's tables share
//! one type. The achieved worst error is returned beside the rows.

/// Rows of every generated table (`thermal::thermistor::ROWS`).
pub const ROWS: usize = 64;
/// Hottest temperature in a table: below its ADC count the sensor is
/// reported shorted.
pub const HOTTEST_C: f64 = 420.0;
/// Coldest temperature in a table: above its ADC count the sensor is
/// reported open.
pub const COLDEST_C: f64 = -30.0;
/// Added to hundredths of °C to store them as `u16`.
pub const STORED_OFFSET: i64 = 5_000;
/// Interpolation error bound between 0 and 300 °C.
pub const ERROR_IN_RANGE_C: f64 = 0.1;
/// Interpolation error bound outside 0–300 °C (still inside the table).
pub const ERROR_OUTSIDE_C: f64 = 1.0;

/// A resistance curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Curve {
    /// R25 (Ω) and β (K).
    Beta { r25: f64, beta: f64 },
    /// Steinhart–Hart 1/T = a + b·ln R + c·(ln R)³ through three (°C, Ω)
    /// points of a maker's table.
    SteinhartHart { points: [(f64, f64); 3] },
}

/// A thermistor the firmware knows by name.
#[derive(Clone, Copy, Debug)]
pub struct Kind {
    /// The name a machine file uses.
    pub name: &'static str,
    /// Marlin's `TEMP_SENSOR_n` number for the same part, also accepted.
    pub marlin_type: u8,
    pub description: &'static str,
    pub curve: Curve,
    /// The hottest temperature the part is rated for (°C): a heater's
    /// `max_temp` may not be above it.
    pub rated_max_c: f64,
}

/// The catalogue. Curves are the makers' published figures:
/// - EPCOS B57560G104F (Marlin type 1): its R/T table at 25, 150 and
///   250 °C (100 kΩ, 1 641.9 Ω, 226.15 Ω), Steinhart–Hart through them.
/// - ATC Semitec 104GT-2 (type 5): R25 100 kΩ, β25/85 4 267 K.
/// - Generic 100 k NTC, β 3950 (type 11): R25 100 kΩ, β 3 950 K.
/// - Hisens 100 k (type 13): R25 100 kΩ, β 3 950 K as its datasheet
///   states; the same curve as type 11, its own generated table.
pub const CATALOGUE: [Kind; 4] = [
    Kind {
        name: "epcos-100k",
        marlin_type: 1,
        description: "EPCOS 100 kΩ B57560G104F",
        curve: Curve::SteinhartHart { points: [(25.0, 100_000.0), (150.0, 1_641.9), (250.0, 226.15)] },
        rated_max_c: 300.0,
    },
    Kind {
        name: "semitec-104gt2",
        marlin_type: 5,
        description: "ATC Semitec 104GT-2 100 kΩ (E3D, J-Head)",
        curve: Curve::Beta { r25: 100_000.0, beta: 4_267.0 },
        rated_max_c: 300.0,
    },
    Kind {
        name: "ntc-100k-3950",
        marlin_type: 11,
        description: "100 kΩ NTC, β 3950 (the common glass bead)",
        curve: Curve::Beta { r25: 100_000.0, beta: 3_950.0 },
        rated_max_c: 300.0,
    },
    Kind {
        name: "hisens-100k-3950",
        marlin_type: 13,
        description: "Hisens 100 kΩ, β 3950",
        curve: Curve::Beta { r25: 100_000.0, beta: 3_950.0 },
        rated_max_c: 300.0,
    },
];

/// A thermistor by its name or Marlin type number (`"epcos-100k"`,
/// `"1"`, `"marlin-1"`).
pub fn find(name: &str) -> Option<&'static Kind> {
    let name = name.trim().to_ascii_lowercase();
    let number = name.strip_prefix("marlin-").unwrap_or(&name).parse::<u8>().ok();
    CATALOGUE.iter().find(|kind| kind.name == name || Some(kind.marlin_type) == number)
}

/// The names a machine file may use, for error messages.
pub fn known_names() -> String {
    CATALOGUE.iter().map(|k| format!("\"{}\" (Marlin {})", k.name, k.marlin_type)).collect::<Vec<_>>().join(", ")
}

impl Curve {
    /// Resistance (Ω) at `celsius`.
    pub fn resistance(&self, celsius: f64) -> f64 {
        let kelvin = celsius + 273.15;
        match *self {
            Curve::Beta { r25, beta } => r25 * (beta * (1.0 / kelvin - 1.0 / 298.15)).exp(),
            Curve::SteinhartHart { .. } => {
                // The inverse of a monotonic curve, by bisection on ln R.
                let (mut low, mut high) = (1e-3f64.ln(), 1e12f64.ln());
                for _ in 0..200 {
                    let middle = 0.5 * (low + high);
                    // Hotter means less resistance.
                    if self.celsius(middle.exp()) > celsius {
                        low = middle;
                    } else {
                        high = middle;
                    }
                }
                (0.5 * (low + high)).exp()
            }
        }
    }

    /// Temperature (°C) at `ohms`.
    pub fn celsius(&self, ohms: f64) -> f64 {
        match *self {
            Curve::Beta { r25, beta } => 1.0 / (1.0 / 298.15 + (ohms / r25).ln() / beta) - 273.15,
            Curve::SteinhartHart { points } => {
                let [a, b, c] = steinhart_hart(points);
                let ln = ohms.ln();
                1.0 / (a + b * ln + c * ln * ln * ln) - 273.15
            }
        }
    }
}

/// Coefficients (a, b, c) through three (°C, Ω) points.
fn steinhart_hart(points: [(f64, f64); 3]) -> [f64; 3] {
    let l: Vec<f64> = points.iter().map(|p| p.1.ln()).collect();
    let y: Vec<f64> = points.iter().map(|p| 1.0 / (p.0 + 273.15)).collect();
    let g2 = (y[1] - y[0]) / (l[1] - l[0]);
    let g3 = (y[2] - y[0]) / (l[2] - l[0]);
    let c = (g3 - g2) / (l[2] - l[1]) / (l[0] + l[1] + l[2]);
    let b = g2 - c * (l[0] * l[0] + l[0] * l[1] + l[1] * l[1]);
    let a = y[0] - (b + l[0] * l[0] * c) * l[0];
    [a, b, c]
}

/// A thermistor in its divider.
#[derive(Clone, Copy, Debug)]
pub struct Divider {
    pub curve: Curve,
    pub pullup_ohms: f64,
}

/// A generated table and its achieved accuracy.
#[derive(Clone, Debug)]
pub struct Table {
    /// (ADC count ascending, hundredths of °C descending).
    pub rows: Vec<(u32, i64)>,
    /// Worst interpolation error from 0 to 300 °C, °C.
    pub worst_in_range_c: f64,
    /// Worst elsewhere in the table, °C.
    pub worst_outside_c: f64,
}

impl Divider {
    /// Temperature at a (fractional) ADC count.
    pub fn celsius(&self, adc: f64) -> f64 {
        self.curve.celsius(self.pullup_ohms / (1023.0 / adc - 1.0))
    }

    /// The (fractional) ADC count at a temperature.
    pub fn adc_count(&self, celsius: f64) -> f64 {
        let r = self.curve.resistance(celsius);
        1023.0 * r / (r + self.pullup_ohms)
    }

    fn stored(&self, adc: u32) -> i64 {
        (self.celsius(f64::from(adc)) * 100.0).round() as i64
    }

    /// Largest errors of the segment between two rows (inside, outside
    /// 0–300 °C); `None` if it breaks its bound somewhere.
    fn segment_errors(&self, adc0: u32, adc1: u32) -> Option<(f64, f64)> {
        let (row0, row1) = ((adc0, self.stored(adc0)), (adc1, self.stored(adc1)));
        let (mut inside, mut outside) = (0.0f64, 0.0f64);
        for x16 in i64::from(adc0) * 16..=i64::from(adc1) * 16 {
            let exact = self.celsius(x16 as f64 / 16.0);
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

    /// The table: see the module comment.
    pub fn table(&self) -> Result<Table, String> {
        let first = self.adc_count(HOTTEST_C).ceil() as u32;
        let last = self.adc_count(COLDEST_C).floor() as u32;
        if first < 1 || last > 1022 || first >= last {
            return Err(format!(
                "with a {} Ω pull-up the readings from {COLDEST_C} to {HOTTEST_C} °C do not fit the ADC (counts {first}..{last})",
                self.pullup_ohms
            ));
        }
        let mut rows = vec![first];
        let mut start = first;
        while start < last {
            let mut end = start + 1;
            if self.segment_errors(start, end).is_none() {
                return Err("a one-count segment breaks the error bound".into());
            }
            while end < last && self.segment_errors(start, end + 1).is_some() {
                end += 1;
            }
            rows.push(end);
            start = end;
        }
        if rows.len() > ROWS {
            return Err(format!("the table needs {} rows, more than the firmware's {ROWS}", rows.len()));
        }
        // Pad to ROWS: halve the widest segment (by count) until full.
        while rows.len() < ROWS {
            let (widest, _) = rows.windows(2).enumerate().max_by_key(|(_, w)| w[1] - w[0]).expect("two rows at least");
            let (a, b) = (rows[widest], rows[widest + 1]);
            if b - a < 2 {
                return Err("the table cannot be padded to its row count".into());
            }
            rows.insert(widest + 1, a + (b - a) / 2);
        }
        let (mut worst_in_range_c, mut worst_outside_c) = (0.0f64, 0.0f64);
        for pair in rows.windows(2) {
            let (inside, outside) = self.segment_errors(pair[0], pair[1]).ok_or("a padded segment breaks the bound")?;
            worst_in_range_c = worst_in_range_c.max(inside);
            worst_outside_c = worst_outside_c.max(outside);
        }
        let rows = rows.into_iter().map(|adc| (adc, self.stored(adc))).collect::<Vec<_>>();
        for &(_, centi) in &rows {
            if !(0..=i64::from(u16::MAX)).contains(&(centi + STORED_OFFSET)) {
                return Err(format!("{centi}/100 °C does not fit the table's u16 storage"));
            }
        }
        Ok(Table { rows, worst_in_range_c, worst_outside_c })
    }
}

/// Exactly the firmware's interpolation: hundredths of °C at `x16`
/// sixteenths of a count between rows, rounding half away from zero.
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

/// Rust source for a table: a `static` in flash named `name` and its
/// achieved error, for `firmware::thermal::thermistor`'s types. `path` is
/// how the generated code reaches the firmware crate (`crate` or
/// `firmware`).
pub fn table_source(name: &str, description: &str, divider: &Divider, table: &Table, path: &str) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let hot = table.rows.first().map(|r| r.0).unwrap_or(0);
    let cold = table.rows.last().map(|r| r.0).unwrap_or(0);
    writeln!(
        out,
        "/// {description} on a {} Ω pull-up, 10-bit ADC: (ADC count, °C/100 + {STORED_OFFSET}),\n\
         /// {ROWS} rows from ADC {hot} ({HOTTEST_C} °C) to {cold} ({COLDEST_C} °C); linear interpolation\n\
         /// is within {:.2} °C of the curve from 0 to 300 °C and {:.2} °C elsewhere.",
        divider.pullup_ohms, table.worst_in_range_c, table.worst_outside_c
    )
    .unwrap();
    writeln!(out, "#[cfg_attr(target_arch = \"avr\", link_section = \".progmem.data\")]").unwrap();
    writeln!(out, "pub static {name}: {path}::thermal::thermistor::ThermistorTable<{ROWS}> = {path}::thermal::thermistor::ThermistorTable::new([").unwrap();
    for &(adc, centi) in &table.rows {
        writeln!(out, "    ({adc}, {}),", centi + STORED_OFFSET).unwrap();
    }
    writeln!(out, "]);").unwrap();
    writeln!(out, "/// Worst interpolation error of [`{name}`] from 0 to 300 °C, hundredths of °C.").unwrap();
    writeln!(out, "pub const {name}_ERROR_CENTI: i32 = {};", (table.worst_in_range_c * 100.0).ceil() as i64).unwrap();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marlin_numbers_and_names_find_the_same_thermistor() {
        assert_eq!(find("1").unwrap().name, "epcos-100k");
        assert_eq!(find("marlin-5").unwrap().name, "semitec-104gt2");
        assert_eq!(find("NTC-100K-3950").unwrap().marlin_type, 11);
        assert_eq!(find("hisens-100k-3950").unwrap().marlin_type, 13);
        assert!(find("pt100").is_none());
    }

    #[test]
    fn steinhart_hart_passes_through_its_three_points() {
        let curve = find("epcos-100k").unwrap().curve;
        for (celsius, ohms) in [(25.0, 100_000.0), (150.0, 1_641.9), (250.0, 226.15)] {
            assert!((curve.celsius(ohms) - celsius).abs() < 1e-6, "{celsius}");
            assert!((curve.resistance(celsius) / ohms - 1.0).abs() < 1e-6, "{ohms}");
        }
    }

    #[test]
    fn the_beta_curve_is_100k_at_25_c() {
        let curve = find("semitec-104gt2").unwrap().curve;
        assert!((curve.resistance(25.0) - 100_000.0).abs() < 1e-6);
        // β 4267 K: R(100 °C) = 100 k·e^(4267·(1/373.15 − 1/298.15)).
        assert!((curve.resistance(100.0) - 5_630.0).abs() < 10.0, "{}", curve.resistance(100.0));
    }

    #[test]
    fn every_catalogue_table_has_rows_and_meets_its_bound() {
        for kind in CATALOGUE {
            for pullup_ohms in [4_700.0, 4_800.0] {
                let table = Divider { curve: kind.curve, pullup_ohms }.table().unwrap();
                assert_eq!(table.rows.len(), ROWS);
                assert!(table.worst_in_range_c <= ERROR_IN_RANGE_C, "{}", kind.name);
                assert!(table.rows.windows(2).all(|w| w[0].0 < w[1].0 && w[0].1 > w[1].1), "{}", kind.name);
            }
        }
    }

    #[test]
    fn a_pullup_that_cannot_read_the_range_is_refused() {
        let curve = find("11").unwrap().curve;
        assert!(Divider { curve, pullup_ohms: 50.0 }.table().is_err());
    }
}
