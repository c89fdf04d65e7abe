//! The virtual heaters: a first-order plant with dead time per heater,
//! heated by the duty measured on the heater's pin, and the RAMPS thermistor
//! divider that turns its temperature into ADC counts.

use std::collections::VecDeque;

/// First-order thermal plant with dead time:
/// `τ·dT/dt = T_ambient + gain·u(t − θ) − T`, `u` the heater duty 0..1.
#[derive(Clone, Debug)]
pub struct ThermalPlant {
    pub ambient_c: f64,
    /// Steady-state rise above ambient at 100 % duty, °C.
    pub gain_c: f64,
    /// Time constant τ, seconds.
    pub tau_s: f64,
    /// Dead time θ, seconds.
    pub dead_time_s: f64,
    pub temperature_c: f64,
    delay: VecDeque<f64>,
}

impl ThermalPlant {
    pub fn new(ambient_c: f64, gain_c: f64, tau_s: f64, dead_time_s: f64) -> Self {
        Self {
            ambient_c,
            gain_c,
            tau_s,
            dead_time_s,
            temperature_c: ambient_c,
            delay: VecDeque::new(),
        }
    }

    /// A generic 12 V 40 W hot end (≈ 3.7 °C/s from cold at full power).
    pub fn hotend() -> Self {
        Self::new(25.0, 450.0, 120.0, 1.5)
    }

    /// A generic 12 V MK2-class heated bed (≈ 0.27 °C/s from cold).
    pub fn bed() -> Self {
        Self::new(25.0, 120.0, 450.0, 5.0)
    }

    /// SPEC §2's delta bed: a Ø320 nichrome disc under glass on mains
    /// through a triac stage, ≈ 0.07 °C/s from cold at full power: 150 °C
    /// above ambient at 100 % (1.5 °C per %), τ 2143 s, θ 10 s — hal-sim's
    /// `PlantModel::BED_SLOW`. Full power takes it 25 → 100 °C in
    /// 10 + 2143·ln 2 ≈ 1495 s; holding 100 °C takes 75/150 = 50 %.
    pub fn slow_bed() -> Self {
        Self::new(25.0, 150.0, 2143.0, 10.0)
    }

    /// The same plant, already at `celsius` (preheated, no power in the
    /// dead time's pipeline yet).
    pub fn at(mut self, celsius: f64) -> Self {
        self.temperature_c = celsius;
        self
    }

    /// SPEC §4's barrel heater as published: 4.3 °C per % (430 °C at
    /// 100 %), τ 549 s, θ 28 s.
    pub fn extrusion_barrel() -> Self {
        Self::new(24.0, 430.0, 549.0, 28.0)
    }

    /// A sensor with no heater on it (T1 on ADC15 of a single-extruder RAMPS).
    pub fn unheated() -> Self {
        Self::new(25.0, 0.0, 1.0, 0.0)
    }

    /// Advance by `dt_s` with duty `duty` (0..1) applied now.
    pub fn step(&mut self, duty: f64, dt_s: f64) {
        let slots = (self.dead_time_s / dt_s).round() as usize;
        self.delay.push_back(duty.clamp(0.0, 1.0));
        let applied = if self.delay.len() > slots {
            self.delay.pop_front().unwrap_or(0.0)
        } else {
            0.0
        };
        let target = self.ambient_c + self.gain_c * applied;
        // Exact solution over the step (u held constant): stable for any dt.
        self.temperature_c = target + (self.temperature_c - target) * (-dt_s / self.tau_s).exp();
    }
}

/// A thermistor to ground with a pull-up to the ADC reference (RAMPS: 4.7 kΩ
/// to 5 V), read by the 10-bit ADC.
#[derive(Clone, Copy, Debug)]
pub struct Thermistor {
    pub r25_ohm: f64,
    pub beta: f64,
    pub pullup_ohm: f64,
}

impl Thermistor {
    /// The stock RAMPS sensor: 100 kΩ NTC, β 3950, 4.7 kΩ pull-up.
    pub const NTC100K_B3950_4K7: Self = Self {
        r25_ohm: 100_000.0,
        beta: 3950.0,
        pullup_ohm: 4_700.0,
    };

    pub fn resistance(&self, celsius: f64) -> f64 {
        self.r25_ohm * (self.beta * (1.0 / (celsius + 273.15) - 1.0 / 298.15)).exp()
    }

    /// ADC counts, with the convention the firmware's table and SPEC §4 use:
    /// `ADC = 1023·R/(R + R_pullup)`, rounded (25 °C → 977).
    pub fn adc_counts(&self, celsius: f64) -> u16 {
        let r = self.resistance(celsius);
        (1023.0 * r / (r + self.pullup_ohm))
            .round()
            .clamp(0.0, 1023.0) as u16
    }

    /// The inverse, for reports: the temperature a reading stands for.
    pub fn celsius(&self, counts: u16) -> Option<f64> {
        if counts == 0 || counts >= 1023 {
            return None;
        }
        let r = self.pullup_ohm / (1023.0 / f64::from(counts) - 1.0);
        Some(1.0 / ((r / self.r25_ohm).ln() / self.beta + 1.0 / 298.15) - 273.15)
    }
}

/// What the ADC channel of a sensor reads.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SensorInput {
    /// The plant's temperature through the thermistor divider.
    Plant,
    /// A fixed count (open sensor = 1023, shorted = 0).
    Fixed(u16),
}

impl SensorInput {
    pub const OPEN: Self = Self::Fixed(1023);
    pub const SHORTED: Self = Self::Fixed(0);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn room_temperature_reads_977_counts() {
        let t = Thermistor::NTC100K_B3950_4K7;
        assert_eq!(t.adc_counts(25.0), 977);
        assert!((t.celsius(977).unwrap() - 25.0).abs() < 0.2);
    }

    #[test]
    fn the_plant_settles_at_ambient_plus_gain_times_duty() {
        let mut p = ThermalPlant::new(20.0, 100.0, 10.0, 0.5);
        for _ in 0..200_000 {
            p.step(0.5, 0.001);
        }
        assert!((p.temperature_c - 70.0).abs() < 0.01);
    }

    #[test]
    fn the_slow_bed_heats_at_about_0_07_degrees_per_second_and_takes_1495_s_to_100() {
        let mut p = ThermalPlant::slow_bed();
        for _ in 0..110_000 {
            p.step(1.0, 0.001);
        }
        // The first 10 s are dead time.
        assert!(((p.temperature_c - 25.0) / 100.0 - 0.07).abs() < 0.002, "{}", p.temperature_c);
        let mut p = ThermalPlant::slow_bed();
        let mut t = 0.0_f64;
        while p.temperature_c < 100.0 {
            p.step(1.0, 0.01);
            t += 0.01;
        }
        assert!((t - 1495.4).abs() < 0.5, "{t}");
    }

    #[test]
    fn dead_time_delays_the_response() {
        let mut p = ThermalPlant::new(20.0, 100.0, 10.0, 0.5);
        for _ in 0..499 {
            p.step(1.0, 0.001);
        }
        assert_eq!(p.temperature_c, 20.0);
        p.step(1.0, 0.001);
        p.step(1.0, 0.001);
        assert!(p.temperature_c > 20.0);
    }
}
