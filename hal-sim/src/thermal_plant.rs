//! Heaters in simulation: first-order plants with dead time, read back
//! through the same thermistor divider the firmware's tables describe, and
//! a rig that runs the firmware's own [`HeaterChannel`] on virtual time.
//!
//! # Plants ([`PlantModel`])
//! `G(s) = K·e^(−θs)/(τs + 1)` in °C per % of heater power above ambient,
//! discretised exactly for a zero-order hold (`y += (K·u − y)·(1 − e^(−Δt/τ))`)
//! every [`PLANT_STEP_MS`], the power delayed by θ in a queue:
//! - [`PlantModel::BARREL_PUBLISHED`]: SPEC §4 as published, 4.3·e^(−28s)/(549s+1)
//!   from 24 °C (a 50 % step goes 24 → 239 °C);
//! - [`PlantModel::BARREL_STEP_FIT`]: the thesis' own step data, θ 36 s, τ 477 s;
//! - [`PlantModel::HOTEND_40W`]: a 12 V 40 W cartridge in an aluminium block
//!   (ours): K 4 °C/% (full power would settle at 425 °C), τ 120 s,
//!   θ 3 s — 25 → 200 °C in ≈70 s at full power, ≈46 % duty at 210 °C;
//! - [`PlantModel::BED_SLOW`]: SPEC §2's 320 mm mains bed, ≈0.07 °C/s at
//!   full power: K 1.5 °C/%, τ 2143 s, θ 10 s (25 → 100 °C in ≈20 min).
//!
//! # Sensor ([`SimulatedSensor`])
//! The plant's temperature → thermistor resistance (β 3950, 100 k) → the
//! 10-bit count of the pull-up divider (`1023·R/(R + Rs)`), plus Gaussian
//! noise (σ 0.5 count, ours) and rounding; open reads 1023, shorted 0.
//! So the firmware's tables, averaging and fault thresholds are all
//! exercised.
//!
//! # Rig ([`ThermalRig`])
//! Virtual milliseconds. Every sample period it makes `conversions` ADC
//! conversions into a [`SampleAverager`] and hands the average to
//! [`HeaterChannel::on_sample`] (or `on_tuning_sample` during `M303`); every
//! millisecond it applies the output — the duty as a fraction for hardware
//! PWM, the [`SlowPwm`] pin level for an SSR — and the plant integrates the
//! mean power of each step.

use crate::axis_plant::Rng;
use firmware::progmem::Flash;
use firmware::thermal::autotune::{Autotune, TuneConfig, TuneError, TuneResult};
use firmware::thermal::{Celsius, HeaterChannel, HeaterConfig, OutputMode, SampleAverager, SlowPwm, ThermalFault, TuneProgress};
use std::collections::VecDeque;

/// The plant integrates in steps of this many milliseconds.
pub const PLANT_STEP_MS: u64 = 10;

/// A first-order heater with dead time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantModel {
    /// K: °C above ambient per % of power, at steady state.
    pub gain_c_per_percent: f64,
    /// τ, seconds.
    pub time_constant_s: f64,
    /// θ, seconds.
    pub dead_time_s: f64,
    pub ambient_c: f64,
}

impl PlantModel {
    pub const BARREL_PUBLISHED: PlantModel = PlantModel { gain_c_per_percent: 4.3, time_constant_s: 549.0, dead_time_s: 28.0, ambient_c: 24.0 };
    pub const BARREL_STEP_FIT: PlantModel = PlantModel { gain_c_per_percent: 4.3, time_constant_s: 477.0, dead_time_s: 36.0, ambient_c: 24.0 };
    pub const HOTEND_40W: PlantModel = PlantModel { gain_c_per_percent: 4.0, time_constant_s: 120.0, dead_time_s: 3.0, ambient_c: 25.0 };
    pub const BED_SLOW: PlantModel = PlantModel { gain_c_per_percent: 1.5, time_constant_s: 2143.0, dead_time_s: 10.0, ambient_c: 25.0 };
    /// Issue 22 finding 7's bed: 200 W, 0.55 °C/W to the air (full power
    /// settles at 25 + 110 = 135 °C, so K = 1.1 °C per %), τ 600 s, 10 s
    /// of dead time (the heat crossing the plate to the thermistor). At
    /// full power 25 → 60 °C takes 10 + 600·ln(110/75) ≈ 240 s; holding
    /// 60 °C takes 35/110 = 32 % (81 counts).
    pub const BED_200W: PlantModel = PlantModel { gain_c_per_percent: 1.1, time_constant_s: 600.0, dead_time_s: 10.0, ambient_c: 25.0 };
}

/// A heater plant on virtual time.
#[derive(Clone, Debug)]
pub struct HeaterPlant {
    model: PlantModel,
    /// Temperature above ambient, °C.
    rise_c: f64,
    /// Power (fraction 0..=1) on its way through the dead time.
    pipeline: VecDeque<f64>,
    /// `1 − e^(−Δt/τ)`.
    alpha: f64,
    /// `false`: the heater's wire is cut (power has no effect).
    connected: bool,
    /// `Some(p)`: the switch is stuck and the heater gets `p` whatever
    /// the firmware commands (a shorted MOSFET is `Some(1.0)`).
    stuck: Option<f64>,
    /// Extra cooling (the part fan at full, air from a long travel), as
    /// the fraction of the heater's power it takes away at steady state.
    extra_cooling: f64,
}

impl HeaterPlant {
    /// At ambient temperature.
    pub fn new(model: PlantModel) -> Self {
        let steps = (model.dead_time_s * 1000.0 / PLANT_STEP_MS as f64).round() as usize;
        let alpha = 1.0 - (-(PLANT_STEP_MS as f64 / 1000.0) / model.time_constant_s).exp();
        Self { model, rise_c: 0.0, pipeline: VecDeque::from(vec![0.0; steps]), alpha, connected: true, stuck: None, extra_cooling: 0.0 }
    }

    /// At `celsius` (in equilibrium: the pipeline holds no power).
    pub fn at(model: PlantModel, celsius: f64) -> Self {
        Self { rise_c: celsius - model.ambient_c, ..Self::new(model) }
    }

    pub fn model(&self) -> &PlantModel {
        &self.model
    }

    pub fn temperature_c(&self) -> f64 {
        self.model.ambient_c + self.rise_c
    }

    /// One [`PLANT_STEP_MS`] step with the mean power over it (0..=1).
    pub fn step(&mut self, power: f64) {
        let commanded = self.stuck.unwrap_or(power.clamp(0.0, 1.0));
        let applied = if self.connected { commanded } else { 0.0 };
        self.pipeline.push_back(applied);
        let delayed = self.pipeline.pop_front().unwrap_or(applied);
        let steady = self.model.gain_c_per_percent * 100.0 * delayed * (1.0 - self.extra_cooling);
        self.rise_c += (steady - self.rise_c) * self.alpha;
    }

    /// Cool the heater harder: `fraction` of its power is lost to the air
    /// (0: still air). A disturbance the controller must ride out.
    pub fn set_extra_cooling(&mut self, fraction: f64) {
        self.extra_cooling = fraction.clamp(0.0, 0.9);
    }

    /// Cut the heater's wire (the firmware's output no longer heats).
    pub fn disconnect_heater(&mut self) {
        self.connected = false;
    }

    /// The heater's switch fails at a fixed power (`1.0`: shorted MOSFET).
    pub fn stick_output(&mut self, power: f64) {
        self.stuck = Some(power);
    }
}

/// The thermistor and its pull-up, as the board wires them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThermistorCircuit {
    pub r25_ohms: f64,
    pub beta: f64,
    pub series_ohms: f64,
}

impl ThermistorCircuit {
    /// 100 k β 3950 on a stock RAMPS (4.7 kΩ).
    pub const RAMPS: ThermistorCircuit = ThermistorCircuit { r25_ohms: 100_000.0, beta: 3950.0, series_ohms: 4_700.0 };
    /// SPEC §4's 4.8 kΩ.
    pub const SPEC_4K8: ThermistorCircuit = ThermistorCircuit { r25_ohms: 100_000.0, beta: 3950.0, series_ohms: 4_800.0 };

    /// The exact (fractional) ADC count at `celsius`.
    pub fn adc(&self, celsius: f64) -> f64 {
        let resistance = self.r25_ohms * (self.beta * (1.0 / (celsius + 273.15) - 1.0 / 298.15)).exp();
        1023.0 * resistance / (resistance + self.series_ohms)
    }

    /// The β equation the other way (the SPEC's R = Rs/(1023/ADC − 1)).
    pub fn celsius(&self, adc: f64) -> f64 {
        let resistance = self.series_ohms / (1023.0 / adc - 1.0);
        1.0 / (1.0 / 298.15 + (resistance / self.r25_ohms).ln() / self.beta) - 273.15
    }
}

/// What the thermistor's wiring does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SensorWiring {
    Good,
    /// Disconnected: the pull-up alone, full scale.
    Open,
    /// Shorted to ground: zero.
    Shorted,
}

/// The thermistor, its wiring and the ADC.
#[derive(Clone, Debug)]
pub struct SimulatedSensor {
    pub circuit: ThermistorCircuit,
    /// ADC noise, σ in counts.
    pub noise_counts: f64,
    pub wiring: SensorWiring,
    rng: Rng,
}

impl SimulatedSensor {
    pub fn new(circuit: ThermistorCircuit, noise_counts: f64, seed: u64) -> Self {
        Self { circuit, noise_counts, wiring: SensorWiring::Good, rng: Rng::new(seed) }
    }

    /// One 10-bit conversion at `celsius`.
    pub fn convert(&mut self, celsius: f64) -> u16 {
        match self.wiring {
            SensorWiring::Open => 1023,
            SensorWiring::Shorted => 0,
            SensorWiring::Good => {
                let noisy = self.circuit.adc(celsius) + self.noise_counts * self.rng.gaussian();
                noisy.round().clamp(0.0, 1023.0) as u16
            }
        }
    }
}

/// One sample period as the rig saw it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleRecord {
    pub time_s: f64,
    /// The plant's true temperature.
    pub plant_c: f64,
    /// What the firmware measured.
    pub measured: Celsius,
    pub duty: u8,
}

/// A heater channel of the firmware on a plant.
pub struct ThermalRig {
    pub channel: HeaterChannel,
    pub plant: HeaterPlant,
    pub sensor: SimulatedSensor,
    averager: SampleAverager,
    conversions: u8,
    slow: SlowPwm,
    config: HeaterConfig,
    now_ms: u64,
    power_sum: f64,
    power_count: u32,
    /// Every sample, in order.
    pub trace: Vec<SampleRecord>,
    /// The first fault the channel reported, with its time.
    pub fault: Option<(f64, ThermalFault)>,
}

/// A configuration in "flash" for the simulation (leaked: it must be
/// `'static`, as on the board).
pub fn flash_config(config: HeaterConfig) -> &'static Flash<HeaterConfig> {
    Box::leak(Box::new(Flash::new(config)))
}

impl ThermalRig {
    /// `conversions` ADC conversions are averaged per sample.
    pub fn new(channel: HeaterChannel, plant: HeaterPlant, sensor: SimulatedSensor, conversions: u8) -> Self {
        let config = channel.config();
        Self {
            channel,
            plant,
            sensor,
            averager: SampleAverager::new(conversions),
            conversions,
            slow: SlowPwm::new(),
            config,
            now_ms: 0,
            power_sum: 0.0,
            power_count: 0,
            trace: Vec::new(),
            fault: None,
        }
    }

    pub fn time_s(&self) -> f64 {
        self.now_ms as f64 / 1000.0
    }

    fn read(&mut self) -> firmware::thermal::Oversampled {
        let celsius = self.plant.temperature_c();
        for _ in 0..self.conversions {
            let count = self.sensor.convert(celsius);
            self.averager.push(count);
        }
        self.averager.take().expect("a full average after `conversions` pushes")
    }

    fn record(&mut self) {
        self.trace.push(SampleRecord {
            time_s: self.time_s(),
            plant_c: self.plant.temperature_c(),
            measured: self.channel.measured(),
            duty: self.channel.duty(),
        });
    }

    /// One millisecond of output and plant.
    fn tick(&mut self) {
        let duty = self.channel.duty();
        let power = match self.config.output {
            OutputMode::HardwarePwm => f64::from(duty) / 255.0,
            OutputMode::TimeProportioning(timing) => {
                if self.slow.level(&timing, self.now_ms as u32, duty) {
                    1.0
                } else {
                    0.0
                }
            }
        };
        self.power_sum += power;
        self.power_count += 1;
        self.now_ms += 1;
        if self.now_ms.is_multiple_of(PLANT_STEP_MS) {
            self.plant.step(self.power_sum / f64::from(self.power_count));
            self.power_sum = 0.0;
            self.power_count = 0;
        }
    }

    fn is_sample_time(&self) -> bool {
        self.now_ms.is_multiple_of(u64::from(self.config.sample_period_ms.max(1)))
    }

    /// Run the normal loop for `seconds` of virtual time.
    pub fn run(&mut self, seconds: f64) {
        let end = self.now_ms + (seconds * 1000.0).round() as u64;
        while self.now_ms < end {
            if self.is_sample_time() {
                let reading = self.read();
                if let Some(fault) = self.channel.on_sample(reading) {
                    self.fault.get_or_insert((self.time_s(), fault));
                }
                self.record();
            }
            self.tick();
        }
    }

    /// Run `M303` to its end (at most `max_seconds`).
    pub fn tune(&mut self, config: TuneConfig, max_seconds: f64) -> Result<TuneResult, TuneOutcome> {
        let mut tune = Autotune::new(config);
        self.channel.start_tuning(&tune).map_err(TuneOutcome::Fault)?;
        let end = self.now_ms + (max_seconds * 1000.0).round() as u64;
        while self.now_ms < end {
            if self.is_sample_time() {
                let reading = self.read();
                let progress = self.channel.on_tuning_sample(reading, &mut tune);
                self.record();
                match progress {
                    TuneProgress::Running | TuneProgress::Cycle => {}
                    TuneProgress::Done(result) => return Ok(result),
                    TuneProgress::Failed(error) => return Err(TuneOutcome::Failed(error)),
                    TuneProgress::Fault(fault) => return Err(TuneOutcome::Fault(fault)),
                }
            }
            self.tick();
        }
        Err(TuneOutcome::StillRunning)
    }

    /// The trace from `from_s` on.
    pub fn since(&self, from_s: f64) -> impl Iterator<Item = &SampleRecord> {
        self.trace.iter().filter(move |r| r.time_s >= from_s)
    }
}

/// Why [`ThermalRig::tune`] returned no gains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TuneOutcome {
    Failed(TuneError),
    Fault(ThermalFault),
    StillRunning,
}

/// Figures of a step response toward `target_c` (plant temperature).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepFigures {
    /// From the start to 90 % of the way.
    pub rise_s: f64,
    /// Highest temperature above the target (0 if never above).
    pub overshoot_c: f64,
    /// When it entered ±`band` for good.
    pub settle_s: f64,
    /// Peak-to-peak / 2 over the last `tail_s` of the trace.
    pub ripple_c: f64,
}

/// Figures of `trace` (started at `trace[0]`) toward `target_c`.
pub fn step_figures(trace: &[SampleRecord], target_c: f64, band_c: f64, tail_s: f64) -> StepFigures {
    let start = trace.first().map_or(0.0, |r| r.plant_c);
    let t0 = trace.first().map_or(0.0, |r| r.time_s);
    let ninety = start + 0.9 * (target_c - start);
    let rise_s = trace.iter().find(|r| r.plant_c >= ninety).map_or(f64::INFINITY, |r| r.time_s - t0);
    let overshoot_c = trace.iter().map(|r| r.plant_c - target_c).fold(0.0, f64::max);
    let settle_s = match trace.iter().rposition(|r| (r.plant_c - target_c).abs() > band_c) {
        Some(i) if i + 1 < trace.len() => trace[i + 1].time_s - t0,
        Some(_) => f64::INFINITY,
        None => 0.0,
    };
    let end = trace.last().map_or(0.0, |r| r.time_s);
    let tail = trace.iter().filter(|r| r.time_s >= end - tail_s).map(|r| r.plant_c);
    let (low, high) = tail.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| (lo.min(t), hi.max(t)));
    StepFigures { rise_s, overshoot_c, settle_s, ripple_c: (high - low) / 2.0 }
}

/// Figures for `cargo benchmark` (issue 6's keys), from simulation with
/// auto-tuned gains: `M303 S210 C8` on each plant, then a step from
/// ambient to 210 °C (hot end: 600 s, barrel: 2400 s). The barrel is SPEC
/// §4's (published plant, 4.8 kΩ, SSR, T = 1 s) with Marlin's PID
/// (functional range 10 °C) in place of the thesis PI. Seen: hot end rise
/// 68 s, overshoot 1.3 °C, settled (±1 °C) at 94 s, ripple 0.06 °C; barrel
/// settled at 587 s with 2.6 °C overshoot (the thesis PI: 1041 s, none).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThermalBenchmark {
    pub hotend: StepFigures,
    pub barrel: StepFigures,
    /// The gains `M303` found.
    pub hotend_gains: firmware::thermal::Gains,
    pub barrel_gains: firmware::thermal::Gains,
}

impl ThermalBenchmark {
    /// `(key, value)` pairs: `hotend_rise_s`, `hotend_overshoot_c`,
    /// `hotend_settle_s`, `hotend_ripple_c`, `barrel_settle_s`,
    /// `barrel_overshoot_c`.
    pub fn keys(&self) -> [(&'static str, f64); 6] {
        [
            ("hotend_rise_s", self.hotend.rise_s),
            ("hotend_overshoot_c", self.hotend.overshoot_c),
            ("hotend_settle_s", self.hotend.settle_s),
            ("hotend_ripple_c", self.hotend.ripple_c),
            ("barrel_settle_s", self.barrel.settle_s),
            ("barrel_overshoot_c", self.barrel.overshoot_c),
        ]
    }
}

/// Tune on `plant`, then step to 210 °C with the result.
fn tuned_step(config: &'static Flash<HeaterConfig>, model: PlantModel, circuit: ThermistorCircuit, conversions: u8, seconds: f64) -> (StepFigures, firmware::thermal::Gains) {
    let rig = |gains| ThermalRig::new(HeaterChannel::new(config, gains), HeaterPlant::new(model), SimulatedSensor::new(circuit, 0.5, 7), conversions);
    let mut tuning = rig(firmware::thermal::Gains::MARLIN_HOTEND);
    let tune = TuneConfig { cycles: 8, timeout_s: 3000, ..TuneConfig::new(Celsius(21_000), config.load().sample_period_ms) };
    let gains = tuning.tune(tune, 20_000.0).map(|r| r.gains).unwrap_or(firmware::thermal::Gains::MARLIN_HOTEND);
    let mut run = rig(gains);
    run.channel.set_target(Celsius(21_000)).unwrap();
    run.run(seconds);
    (step_figures(&run.trace, 210.0, 1.0, 120.0), gains)
}

/// The benchmark run (≈0.1 s of real time).
pub fn thermal_benchmark() -> ThermalBenchmark {
    use firmware::thermal::channel::{BARREL, HOTEND_0};
    let (hotend, hotend_gains) = tuned_step(&HOTEND_0, PlantModel::HOTEND_40W, ThermistorCircuit::RAMPS, 16, 600.0);
    let (barrel, barrel_gains) = tuned_step(flash_config(HeaterConfig { control: firmware::thermal::Control::PID, ..BARREL.load() }), PlantModel::BARREL_PUBLISHED, ThermistorCircuit::SPEC_4K8, 10, 2400.0);
    ThermalBenchmark { hotend, barrel, hotend_gains, barrel_gains }
}

#[cfg(test)]
mod tests {
    use super::*;
    use firmware::thermal::channel::{BARREL, BED, HOTEND_0};
    use firmware::thermal::{GuardConfig, Gains};

    fn hotend_rig(gains: Gains) -> ThermalRig {
        ThermalRig::new(
            HeaterChannel::new(&HOTEND_0, gains),
            HeaterPlant::new(PlantModel::HOTEND_40W),
            SimulatedSensor::new(ThermistorCircuit::RAMPS, 0.5, 7),
            16,
        )
    }

    #[test]
    fn benchmark_hot_end_meets_the_issue_goals() {
        let bench = thermal_benchmark();
        std::println!("{bench:?}");
        // Issue 6: overshoot ≤ 2 °C and ±0.5 °C steady ripple on the hot end.
        assert!(bench.hotend.overshoot_c <= 2.0, "{bench:?}");
        assert!(bench.hotend.ripple_c <= 0.5, "{bench:?}");
        assert!(bench.hotend.settle_s.is_finite() && bench.barrel.settle_s.is_finite(), "{bench:?}");
    }

    #[test]
    fn the_published_barrel_plant_goes_24_to_239_on_a_50_percent_step() {
        let mut plant = HeaterPlant::new(PlantModel::BARREL_PUBLISHED);
        for _ in 0..(28.0 / 0.01) as usize {
            plant.step(0.5);
        }
        assert_eq!(plant.temperature_c(), 24.0); // dead time
        for _ in 0..(10.0 * 549.0 / 0.01) as usize {
            plant.step(0.5);
        }
        assert!((plant.temperature_c() - 239.0).abs() < 0.01, "{}", plant.temperature_c());
    }

    #[test]
    fn a_plant_reaches_63_percent_one_time_constant_after_its_dead_time() {
        let mut plant = HeaterPlant::new(PlantModel::BARREL_STEP_FIT);
        for _ in 0..((36.0 + 477.0) / 0.01) as usize {
            plant.step(1.0);
        }
        let expected = 24.0 + 430.0 * (1.0 - (-1.0f64).exp());
        assert!((plant.temperature_c() - expected).abs() < 0.05, "{} vs {expected}", plant.temperature_c());
    }

    #[test]
    fn the_slow_bed_heats_at_about_0_07_degrees_per_second() {
        let mut plant = HeaterPlant::new(PlantModel::BED_SLOW);
        for _ in 0..(110.0 / 0.01) as usize {
            plant.step(1.0);
        }
        let slope = (plant.temperature_c() - 25.0) / 100.0; // the first 10 s are dead time
        assert!((slope - 0.07).abs() < 0.002, "{slope}");
    }

    #[test]
    fn the_sensor_reads_the_spec_counts_through_the_divider() {
        let circuit = ThermistorCircuit::SPEC_4K8;
        for (adc, celsius) in [(976.0, 25.07), (606.0, 100.00), (203.0, 174.91), (118.0, 210.06), (79.0, 237.77), (36.0, 299.26)] {
            assert!((circuit.celsius(adc) - celsius).abs() < 0.005, "{adc}: {}", circuit.celsius(adc));
            assert!((circuit.adc(celsius) - adc).abs() < 0.05, "{celsius}: {}", circuit.adc(celsius));
        }
        let mut sensor = SimulatedSensor::new(circuit, 0.0, 1);
        assert_eq!(sensor.convert(210.06), 118);
        sensor.wiring = SensorWiring::Open;
        assert_eq!(sensor.convert(210.0), 1023);
        sensor.wiring = SensorWiring::Shorted;
        assert_eq!(sensor.convert(210.0), 0);
    }

    #[test]
    fn firmware_tables_read_the_simulated_sensor_within_a_tenth_of_a_degree_on_average() {
        // Noisy conversions, averaged 16 at a time and over 10 s, read the
        // plant within the table's 0.1 °C plus a little averaging error.
        for celsius in [25.0, 60.0, 150.0, 210.0, 250.0] {
            let mut rig = hotend_rig(Gains::MARLIN_HOTEND);
            rig.plant = HeaterPlant::at(PlantModel::HOTEND_40W, celsius);
            rig.run(10.0);
            let n = rig.trace.len() as f64;
            let error = rig.trace.iter().map(|r| f64::from(r.measured.0) / 100.0 - r.plant_c).sum::<f64>() / n;
            assert!(error.abs() < 0.12, "{celsius}: {error}");
        }
    }

    /// Auto-tune the hot end at 210 °C, as `M303 E0 S210 C8 U1` would.
    fn tuned_hotend() -> (ThermalRig, TuneResult) {
        let mut rig = hotend_rig(Gains::MARLIN_HOTEND);
        let result = rig.tune(TuneConfig { cycles: 8, ..TuneConfig::new(Celsius(21_000), 100) }, 1800.0).expect("the tune finishes");
        rig.channel.set_gains(result.gains);
        (rig, result)
    }

    #[test]
    fn autotune_on_the_hot_end_plant_converges_to_usable_gains() {
        let (_, result) = tuned_hotend();
        assert!(result.converged, "{result:?}");
        // θ 3 s, τ 120 s, K 4 °C/%: the relay oscillates a few degrees with
        // a period of some tens of seconds.
        assert!((50..=1000).contains(&result.oscillation.0), "{result:?}");
        assert!((5_000..=60_000).contains(&result.period_ms), "{result:?}");
        assert!(result.gains.kp > 0 && result.gains.ki > 0 && result.gains.kd > 0, "{result:?}");
    }

    #[test]
    fn tuned_pid_holds_210_on_the_hot_end_within_a_degree_without_overshooting_5() {
        let (_, result) = tuned_hotend();
        let mut rig = hotend_rig(result.gains);
        rig.channel.set_target(Celsius(21_000)).unwrap();
        rig.run(600.0);
        let figures = step_figures(&rig.trace, 210.0, 1.0, 120.0);
        assert!(figures.overshoot_c <= 5.0, "{figures:?} with {result:?}");
        assert!(figures.settle_s < 300.0, "{figures:?}");
        for r in rig.since(300.0) {
            assert!((r.plant_c - 210.0).abs() <= 1.0, "{r:?}");
        }
        assert_eq!(rig.fault, None);
    }

    /// Marlin's stock gains were tuned for another hot end: on this plant
    /// they limit-cycle (±3 °C, Kd 114 against 0.6 °C ADC steps), which is
    /// why `M303` exists — but nothing trips for an hour.
    #[test]
    fn marlin_stock_gains_keep_the_hot_end_within_4_degrees_for_an_hour() {
        let mut rig = hotend_rig(Gains::MARLIN_HOTEND);
        rig.channel.set_target(Celsius(21_000)).unwrap();
        rig.run(3600.0);
        assert_eq!(rig.fault, None);
        for r in rig.since(300.0) {
            assert!((r.plant_c - 210.0).abs() <= 4.0, "{r:?}");
        }
    }

    fn barrel_rig(model: PlantModel) -> ThermalRig {
        ThermalRig::new(
            HeaterChannel::new(&BARREL, Gains::THESIS_BARREL),
            HeaterPlant::new(model),
            SimulatedSensor::new(ThermistorCircuit::SPEC_4K8, 0.5, 11),
            10,
        )
    }

    /// SPEC §4: the thesis PI (Kp 2.4, Ki 0.008, T = 1 s, conditional
    /// integration) on the SSR's 200 ms windows settles with no overshoot,
    /// within ±1 °C after ≈1140–1180 s (at 238 °C, the top of the
    /// 210–238 °C range; at 210 °C it is ≈1040–1060 s).
    #[test]
    fn thesis_pi_on_the_barrel_settles_without_overshoot_in_about_1160_s() {
        for model in [PlantModel::BARREL_PUBLISHED, PlantModel::BARREL_STEP_FIT] {
            let mut rig = barrel_rig(model);
            rig.channel.set_target(Celsius(23_800)).unwrap();
            rig.run(1600.0);
            let figures = step_figures(&rig.trace, 238.0, 1.0, 200.0);
            assert!(figures.overshoot_c < 0.5, "{model:?}: {figures:?}");
            assert!((1100.0..=1200.0).contains(&figures.settle_s), "{model:?}: {figures:?}");
            assert_eq!(rig.fault, None);
        }
    }

    fn slow_bed_rig(control: firmware::thermal::Control, gains: Gains) -> ThermalRig {
        let config = HeaterConfig { control, guard: GuardConfig::SLOW_BED, ..BED.load() };
        ThermalRig::new(
            HeaterChannel::new(flash_config(config), gains),
            HeaterPlant::new(PlantModel::BED_SLOW),
            SimulatedSensor::new(ThermistorCircuit::RAMPS, 0.5, 3),
            16,
        )
    }

    fn assert_slow_bed_holds_100(rig: &mut ThermalRig) {
        rig.channel.set_target(Celsius(10_000)).unwrap();
        rig.run(2400.0);
        assert_eq!(rig.fault, None);
        let reached = rig.trace.iter().find(|r| r.plant_c >= 99.0).map(|r| r.time_s).unwrap();
        assert!((1000.0..=1500.0).contains(&reached), "{reached}");
        for r in rig.since(reached + 200.0) {
            assert!((r.plant_c - 100.0).abs() <= 2.5, "{r:?}");
        }
    }

    /// SPEC §2's bed with bang-bang (Marlin's 2 °C hysteresis) and its
    /// slow-bed protections: ≈20 min to 100 °C and no false alarm.
    #[test]
    fn the_slow_bed_on_bang_bang_reaches_100_in_about_20_minutes_without_tripping() {
        let mut rig = slow_bed_rig(firmware::thermal::Control::BANG_BANG, Gains::MARLIN_BED);
        assert_slow_bed_holds_100(&mut rig);
    }

    /// The same bed on PID with gains from `M303` (Marlin's stock bed gains
    /// reach ≈91 °C, P-only equilibrium, then crawl on the integral).
    #[test]
    fn the_slow_bed_on_auto_tuned_pid_reaches_100_without_tripping() {
        let mut tuning = slow_bed_rig(firmware::thermal::Control::PID, Gains::MARLIN_BED);
        let config = TuneConfig { timeout_s: 3000, ..TuneConfig::new(Celsius(10_000), 100) };
        let result = tuning.tune(config, 20_000.0).expect("the bed tunes");
        let mut rig = slow_bed_rig(firmware::thermal::Control::PID, result.gains);
        assert_slow_bed_holds_100(&mut rig);
    }

    /// Marlin's stock bed gains on SPEC §2's slow bed: full power to 90 °C,
    /// then P-only equilibrium near 91 °C and a slow climb on the tiny
    /// integral. That is a slow controller, not a failed heater: the watch
    /// judges only full-power periods (issue 22, finding 7; it used to
    /// latch `HeatingFailed` here).
    #[test]
    fn marlin_stock_bed_gains_crawl_on_the_slow_bed_without_a_false_heating_failure() {
        let mut rig = slow_bed_rig(firmware::thermal::Control::PID, Gains::MARLIN_BED);
        rig.channel.set_target(Celsius(10_000)).unwrap();
        rig.run(6000.0);
        assert_eq!(rig.fault, None);
        let reached = first_at(&rig, 99.0);
        std::println!("slow bed, stock gains: 99 °C after {reached:?} s");
        assert!(reached.is_some());
    }

    /// Issue 22 finding 7's bed with the RAMPS bed channel as it ships
    /// (PID, Marlin's bed protections) and `gains`.
    fn bed_200w_rig(gains: Gains) -> ThermalRig {
        ThermalRig::new(
            HeaterChannel::new(&BED, gains),
            HeaterPlant::new(PlantModel::BED_200W),
            SimulatedSensor::new(ThermistorCircuit::RAMPS, 0.5, 5),
            16,
        )
    }

    /// Seconds until the plant first reaches `celsius`.
    fn first_at(rig: &ThermalRig, celsius: f64) -> Option<f64> {
        rig.trace.iter().find(|r| r.plant_c >= celsius).map(|r| r.time_s)
    }

    /// The physical time: 25 → 60 °C at full power, ≈ 240 s.
    fn bed_200w_full_power_time_to_60() -> f64 {
        let mut plant = HeaterPlant::new(PlantModel::BED_200W);
        let mut ms = 0u64;
        while plant.temperature_c() < 60.0 {
            plant.step(1.0);
            ms += PLANT_STEP_MS;
        }
        ms as f64 / 1000.0
    }

    /// Issue 22 finding 7: `M304 P10 I0.023 D305.4` (the slicer's, Marlin's
    /// stock bed gains) on the 200 W bed. Full power to 50 °C, then the
    /// PID's duty falls to ≈ 0.38 and the rise to under 2 °C a minute:
    /// the watch called that a failed heater at ≈ 51 °C. A working bed
    /// under its own (slow) PID must get to the target.
    #[test]
    fn marlin_stock_bed_gains_bring_the_200w_bed_to_60_without_a_false_heating_failure() {
        let mut rig = bed_200w_rig(Gains::MARLIN_BED);
        rig.channel.set_target(Celsius(6_000)).unwrap();
        rig.run(3600.0);
        assert_eq!(rig.fault, None, "{:?}", rig.trace.last());
        let reached = first_at(&rig, 59.5).expect("reaches 59.5 °C");
        std::println!("stock gains: 59.5 °C after {reached:.0} s");
        for r in rig.since(reached + 600.0) {
            assert!((r.plant_c - 60.0).abs() <= 1.0, "{r:?}");
        }
    }

    /// The watch still catches a bed heater that does not heat at full
    /// power: 2 °C in 60 s (Marlin's `WATCH_BED_TEMP_*`).
    #[test]
    fn a_dead_bed_heater_at_full_power_is_still_a_heating_failure() {
        let mut rig = bed_200w_rig(Gains::MARLIN_BED);
        rig.plant.disconnect_heater();
        rig.channel.set_target(Celsius(6_000)).unwrap();
        rig.run(120.0);
        assert_off_after(&mut rig, ThermalFault::HeatingFailed, 61.0, 0.0);
    }

    /// A bed heater that dies half way (a broken wire at 40 °C, the PID
    /// still below its range and at full power) is caught too.
    #[test]
    fn a_bed_heater_lost_while_heating_is_a_heating_failure() {
        let mut rig = bed_200w_rig(Gains::MARLIN_BED);
        rig.channel.set_target(Celsius(6_000)).unwrap();
        rig.run(120.0);
        assert_eq!(rig.fault, None);
        rig.plant.disconnect_heater();
        rig.run(150.0);
        assert_off_after(&mut rig, ThermalFault::HeatingFailed, 140.0, 120.0);
    }

    /// A bed heater that dies while the stock PID backs off near the
    /// target (≈ 0.4 duty at 52 °C, where the watch no longer judges): the
    /// bed cools, the PID goes back to full power below its 10 °C range,
    /// and the next full 60 s period catches it.
    #[test]
    fn a_bed_heater_lost_while_the_pid_backs_off_is_still_caught() {
        let mut rig = bed_200w_rig(Gains::MARLIN_BED);
        rig.channel.set_target(Celsius(6_000)).unwrap();
        rig.run(1.0);
        while rig.plant.temperature_c() < 52.0 {
            rig.run(1.0);
        }
        let lost = rig.time_s();
        assert!(rig.trace.last().unwrap().duty < 150, "{:?}", rig.trace.last());
        rig.plant.disconnect_heater();
        rig.run(300.0);
        std::println!("lost at {lost:.0} s, caught after {:?}", rig.fault.map(|(at, _)| at - lost));
        assert_off_after(&mut rig, ThermalFault::HeatingFailed, 150.0, lost);
    }

    /// `M303 E-1 S60 C5` on the 200 W bed: gains that heat 25 → 60 °C in
    /// close to the physical time (within 1.5× full power's).
    #[test]
    fn autotuned_gains_heat_the_200w_bed_in_close_to_its_physical_time() {
        let mut tuning = bed_200w_rig(Gains::MARLIN_BED);
        let result = tuning.tune(TuneConfig { cycles: 5, ..TuneConfig::new(Celsius(6_000), 100) }, 20_000.0).expect("the bed tunes");
        let mut rig = bed_200w_rig(result.gains);
        rig.channel.set_target(Celsius(6_000)).unwrap();
        rig.run(1800.0);
        assert_eq!(rig.fault, None);
        let physical = bed_200w_full_power_time_to_60();
        let reached = first_at(&rig, 59.5).expect("reaches 59.5 °C");
        let peak = rig.trace.iter().map(|r| r.plant_c).fold(0.0, f64::max);
        std::println!("tuned {:?}: 59.5 °C after {reached:.0} s (full power to 60: {physical:.0} s), peak {peak:.2}", result.gains);
        assert!(reached <= 1.5 * physical, "{reached} s vs {physical} s");
        for r in rig.since(reached + 300.0) {
            assert!((r.plant_c - 60.0).abs() <= 1.0, "{r:?}");
        }
    }

    /// Hold 210 °C with Marlin's gains, then break something.
    fn holding_hotend() -> ThermalRig {
        let mut rig = hotend_rig(Gains::MARLIN_HOTEND);
        rig.channel.set_target(Celsius(21_000)).unwrap();
        rig.run(300.0);
        assert_eq!(rig.fault, None);
        rig
    }

    fn assert_off_after(rig: &mut ThermalRig, fault: ThermalFault, within_s: f64, from_s: f64) {
        let (at, got) = rig.fault.expect("a fault");
        assert_eq!(got, fault);
        assert!(at - from_s <= within_s, "{fault:?} after {} s", at - from_s);
        assert_eq!(rig.channel.fault(), Some(fault));
        // Output forced to 0 from then on.
        rig.run(5.0);
        for r in rig.since(at) {
            assert_eq!(r.duty, 0, "{r:?}");
        }
    }

    #[test]
    fn an_open_thermistor_stops_the_heater_within_a_second() {
        let mut rig = holding_hotend();
        let from = rig.time_s();
        rig.sensor.wiring = SensorWiring::Open;
        rig.run(2.0);
        assert_off_after(&mut rig, ThermalFault::SensorOpen, 1.0, from);
    }

    #[test]
    fn a_shorted_thermistor_stops_the_heater_within_a_second() {
        let mut rig = holding_hotend();
        let from = rig.time_s();
        rig.sensor.wiring = SensorWiring::Shorted;
        rig.run(2.0);
        assert_off_after(&mut rig, ThermalFault::SensorShorted, 1.0, from);
    }

    #[test]
    fn a_heater_that_stops_heating_while_holding_is_a_thermal_runaway() {
        let mut rig = holding_hotend();
        let from = rig.time_s();
        rig.plant.disconnect_heater();
        rig.run(120.0);
        // Issue 22: caught within 20 s (it was 45 s: 4 °C down, then the
        // 40 s period): below the band and still falling 8 s later.
        let (at, _) = rig.fault.expect("runaway");
        assert!(at - from <= 20.0, "{}", at - from);
        assert_off_after(&mut rig, ThermalFault::ThermalRunaway, 20.0, from);
    }

    #[test]
    fn a_heater_that_never_heats_fails_the_20_s_watch() {
        let mut rig = hotend_rig(Gains::MARLIN_HOTEND);
        rig.plant.disconnect_heater();
        rig.channel.set_target(Celsius(21_000)).unwrap();
        rig.run(30.0);
        assert_off_after(&mut rig, ThermalFault::HeatingFailed, 20.2, 0.0);
    }

    #[test]
    fn a_stuck_on_heater_trips_maxtemp() {
        let mut rig = holding_hotend();
        let from = rig.time_s();
        rig.plant.stick_output(1.0);
        rig.run(120.0);
        assert_off_after(&mut rig, ThermalFault::MaxTemp, 120.0, from);
        // The firmware commands 0; the stuck switch is why the watchdog and
        // the board's safe-state matter.
        assert!(rig.trace.iter().any(|r| r.plant_c > 275.0));
    }

    #[test]
    fn an_open_sensor_on_the_ssr_barrel_switches_it_off_within_a_second() {
        let mut rig = barrel_rig(PlantModel::BARREL_PUBLISHED);
        rig.channel.set_target(Celsius(21_000)).unwrap();
        rig.run(60.0);
        let from = rig.time_s();
        rig.sensor.wiring = SensorWiring::Open;
        rig.run(2.0);
        // Read every 100 ms although its PI runs every second.
        assert_off_after(&mut rig, ThermalFault::SensorOpen, 1.0, from);
    }
}
