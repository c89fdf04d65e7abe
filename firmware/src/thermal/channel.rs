//! One heater from reading to output: sensor → guard → controller → duty.
//!
//! [`HeaterChannel::on_sample`] is called once per sample period (the
//! board's main loop, every `config.sample_period_ms`) with the averaged
//! ADC reading; it converts it, lets the [`HeaterGuard`] judge it, runs the
//! PID or bang-bang law and leaves the duty in [`HeaterChannel::duty`]. A
//! latched fault is returned once and keeps the duty at 0.

use super::autotune::{Autotune, Step, TuneError, TuneResult};
use super::guard::{GuardConfig, HeaterGuard, ThermalFault, Verdict};
use super::output::{OutputMode, TimeProportioning};
use super::pid::{bang_bang, Control, Gains, Law, PidState};
use super::thermistor::{Oversampled, Thermistor};
use super::{Celsius, Heater, HeaterId};
use crate::progmem::Flash;

/// Everything fixed about one heater: 28 bytes (its one pointer, the
/// thermistor table, is itself in flash), kept in
/// flash ([`Flash`]) and copied out when a sample needs it, so it costs no
/// RAM on the AVR. The stock ones are [`HOTEND_0`], [`BED`] and [`BARREL`];
/// a board with others declares its own
/// `#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]`
/// `static MINE: Flash<HeaterConfig> = Flash::new(HeaterConfig { .. });`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HeaterConfig {
    pub id: HeaterId,
    pub sensor: Thermistor,
    /// A reading is judged (and the derivative sampled) once per this
    /// period: 100 ms keeps sensor faults well within 1 s.
    pub sample_period_ms: u16,
    /// The control law runs every this many samples (1: every sample; the
    /// thesis barrel PI runs at T = 1 s on 100 ms samples: 10).
    pub control_every: u8,
    /// Largest duty (Marlin's `PID_MAX` / `MAX_BED_POWER`).
    pub max_power: u8,
    pub control: Control,
    pub output: OutputMode,
    pub guard: GuardConfig,
}

impl HeaterConfig {
    /// RAMPS hot end `index` on D10/D9…: 4.7 kΩ thermistor, PID at 10 Hz
    /// with Marlin's functional range, hardware PWM, Marlin's protections.
    pub const fn hotend(index: u8) -> Self {
        Self {
            id: HeaterId::Hotend(index),
            sensor: Thermistor::Ntc100kB3950Pullup4k7,
            sample_period_ms: 100,
            control_every: 1,
            max_power: 255,
            control: Control::PID,
            output: OutputMode::HardwarePwm,
            guard: GuardConfig::HOTEND,
        }
    }

    /// RAMPS bed on D8: PID at 10 Hz (use [`Control::BANG_BANG`] for
    /// relays), hardware PWM, Marlin's bed protections.
    pub const fn bed() -> Self {
        Self {
            id: HeaterId::Bed,
            sensor: Thermistor::Ntc100kB3950Pullup4k7,
            sample_period_ms: 100,
            control_every: 1,
            max_power: 255,
            control: Control::PID,
            output: OutputMode::HardwarePwm,
            guard: GuardConfig::BED,
        }
    }

    /// SPEC §4's barrel: 4.8 kΩ thermistor read every 100 ms, the thesis
    /// PI at T = 1 s (every 10th sample, no functional range), SSR
    /// time-proportioning (200 ms / 10 ms).
    pub const fn barrel() -> Self {
        Self {
            id: HeaterId::Hotend(0),
            sensor: Thermistor::Ntc100kB3950Pullup4k8,
            sample_period_ms: 100,
            control_every: 10,
            max_power: 255,
            control: Control::PLAIN_PID,
            output: OutputMode::TimeProportioning(TimeProportioning::SSR),
            guard: GuardConfig::BARREL,
        }
    }

    /// The control law's period T, ms.
    pub fn control_period_ms(&self) -> u16 {
        self.sample_period_ms.saturating_mul(u16::from(self.control_every.max(1)))
    }

    /// The highest target [`HeaterChannel::set_target`] accepts.
    pub fn max_target(&self) -> Celsius {
        Celsius(super::guard::centi(self.guard.max_c) - i32::from(u16::from(self.guard.target_margin_c) * 100))
    }
}

/// [`HeaterConfig::hotend`]`(0)` in flash.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
pub static HOTEND_0: Flash<HeaterConfig> = Flash::new(HeaterConfig::hotend(0));
/// [`HeaterConfig::hotend`]`(1)` in flash.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
pub static HOTEND_1: Flash<HeaterConfig> = Flash::new(HeaterConfig::hotend(1));
/// [`HeaterConfig::bed`] in flash.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
pub static BED: Flash<HeaterConfig> = Flash::new(HeaterConfig::bed());
/// [`HeaterConfig::bed`] with bang-bang control, in flash.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
pub static BED_BANG_BANG: Flash<HeaterConfig> = Flash::new(HeaterConfig { control: Control::BANG_BANG, ..HeaterConfig::bed() });
/// [`HeaterConfig::bed`] behind a solid-state relay: the same PID, its
/// duty as time-proportioning (200 ms window, slots ≥ 10 ms), in flash.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
pub static BED_SSR: Flash<HeaterConfig> =
    Flash::new(HeaterConfig { output: OutputMode::TimeProportioning(TimeProportioning::SSR), ..HeaterConfig::bed() });
/// [`HeaterConfig::barrel`] in flash.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
pub static BARREL: Flash<HeaterConfig> = Flash::new(HeaterConfig::barrel());

/// What happened on a tuning sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TuneProgress {
    /// Still oscillating.
    Running,
    /// A cycle completed: print `tune.last_cycle().write(out)`
    /// ([`CycleReport::write`](super::autotune::CycleReport::write)).
    Cycle,
    /// Finished (heater off, target 0): print
    /// [`TuneResult::write_finished`]; on `U1`, [`HeaterChannel::set_gains`].
    Done(TuneResult),
    /// Gave up (heater off, target 0): print [`TuneError::write`].
    Failed(TuneError),
    /// The guard latched a fault (heater off): report and halt as for
    /// [`HeaterChannel::on_sample`].
    Fault(ThermalFault),
}

/// [`TuneProgress`] without the result (the executor's path: on `Done`
/// the result is `tune.last_cycle().result`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum TuningStep {
    Running,
    Cycle,
    Done,
    Failed(TuneError),
    Fault(ThermalFault),
}

/// One heater's state: 44 bytes of RAM on the AVR (checked at compile
/// time), its configuration in flash.
#[derive(Clone, Copy)]
pub struct HeaterChannel {
    config: &'static Flash<HeaterConfig>,
    gains: Gains,
    pid: PidState,
    guard: HeaterGuard,
    measured: Celsius,
    target: Celsius,
    duty: u8,
    /// `measured` holds a real reading (the derivative needs a previous one).
    has_reading: bool,
    /// Samples until the law runs again.
    countdown: u8,
}

// 46: the guard's fall window (issue 22's faster runaway check) took 2.
#[cfg(target_arch = "avr")]
const _: () = assert!(core::mem::size_of::<HeaterChannel>() <= 46);

impl core::fmt::Debug for HeaterChannel {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("HeaterChannel")
            .field("id", &self.config.load().id)
            .field("measured", &self.measured)
            .field("target", &self.target)
            .field("duty", &self.duty)
            .field("fault", &self.guard.fault())
            .finish()
    }
}

impl HeaterChannel {
    pub const fn new(config: &'static Flash<HeaterConfig>, gains: Gains) -> Self {
        Self {
            config,
            gains,
            pid: PidState::new(),
            guard: HeaterGuard::new(),
            measured: Celsius(0),
            target: Celsius(0),
            duty: 0,
            has_reading: false,
            countdown: 0,
        }
    }

    /// A copy of the configuration (out of flash on the AVR).
    pub fn config(&self) -> HeaterConfig {
        self.config.load()
    }

    pub fn id(&self) -> HeaterId {
        self.config().id
    }

    /// The latest good temperature (0 before the first one).
    pub fn measured(&self) -> Celsius {
        self.measured
    }

    pub fn target(&self) -> Celsius {
        self.target
    }

    /// The duty to apply now, 0..=`max_power` (0 while faulted): the
    /// compare value for hardware PWM, or the input of
    /// [`SlowPwm::level`](super::output::SlowPwm::level).
    pub fn duty(&self) -> u8 {
        self.duty
    }

    /// Marlin's `@:` value: the duty halved (0–127).
    pub fn power_report(&self) -> u8 {
        self.duty / 2
    }

    /// A snapshot for the executor's `M105` (`Heater` as it has it).
    pub fn heater(&self) -> Heater {
        Heater { measured: self.measured, target: self.target, power: self.power_report() }
    }

    pub fn fault(&self) -> Option<ThermalFault> {
        self.guard.fault()
    }

    pub fn gains(&self) -> Gains {
        self.gains
    }

    /// `M301` / `M303 U1` / settings load. Takes effect at the next sample;
    /// the integral is kept (no bump).
    pub fn set_gains(&mut self, gains: Gains) {
        self.gains = gains;
    }

    /// `M104`/`M140`/`M109`/`M190`: set the target (0 or below: off),
    /// clamped to [`HeaterConfig::max_target`] as Marlin does. Returns the
    /// target applied, or the latched fault (then nothing changes).
    pub fn set_target(&mut self, target: Celsius) -> Result<Celsius, ThermalFault> {
        if let Some(fault) = self.guard.fault() {
            return Err(fault);
        }
        let config = self.config();
        let target = Celsius(super::math::clamp(target.0, 0, config.max_target().0.max(0)));
        if target != self.target {
            self.target = target;
            let measured = if self.has_reading { Some(self.measured) } else { None };
            self.guard.on_target(&config.guard, config.sample_period_ms, target, measured);
        }
        if target.0 == 0 {
            self.duty = 0;
            self.pid.reset();
        }
        Ok(target)
    }

    /// Forget a latched fault (the executor's reset, `M999`): heater off,
    /// target 0, protections re-armed.
    pub fn clear_fault(&mut self) {
        self.guard.clear();
        self.target = Celsius(0);
        self.duty = 0;
        self.pid.reset();
    }

    /// Off now (the executor's `kill()`, `M112`): target 0, duty 0.
    pub fn turn_off(&mut self) {
        let _ = self.set_target(Celsius(0));
        self.duty = 0;
    }

    /// Judge a reading; `Ok(measured)` when the controller may run.
    fn judge(&mut self, config: &HeaterConfig, reading: Oversampled, tuning: bool) -> Result<Celsius, Option<ThermalFault>> {
        let converted = config.sensor.celsius(reading);
        let verdict = self.guard.check(&config.guard, config.sample_period_ms, converted, self.target, tuning);
        match verdict {
            Verdict::Run(measured) => Ok(measured),
            Verdict::Hold => Err(None),
            Verdict::Latched(fault) => {
                self.target = Celsius(0);
                self.pid.reset();
                Err(Some(fault))
            }
            Verdict::Faulted(measured) => {
                if let Some(t) = measured {
                    self.measured = t;
                }
                Err(None)
            }
        }
    }

    fn accept(&mut self, measured: Celsius) -> Celsius {
        let previous = if self.has_reading { self.measured } else { measured };
        self.measured = measured;
        self.has_reading = true;
        previous
    }

    /// One sample period's averaged reading. Returns a fault on the sample
    /// it latched (once): print [`ThermalFault::write`] and halt.
    pub fn on_sample(&mut self, reading: Oversampled) -> Option<ThermalFault> {
        let c = self.config();
        let measured = match self.judge(&c, reading, false) {
            Ok(measured) => measured,
            Err(fault) => {
                self.duty = 0;
                return fault;
            }
        };
        let previous = self.accept(measured);
        if self.target.0 <= 0 {
            self.pid.reset();
            self.duty = 0;
            self.countdown = 0;
            return None;
        }
        if let Control::Pid { derivative_filter_shift, .. } = c.control {
            self.pid.observe(&self.gains, derivative_filter_shift, c.sample_period_ms, measured, previous);
        }
        if self.countdown > 0 {
            self.countdown -= 1;
            return None;
        }
        self.countdown = c.control_every.max(1) - 1;
        self.duty = match c.control {
            Control::Pid { functional_range_c, .. } => {
                let law = Law { functional_range_c, control_period_ms: c.control_period_ms(), max_power: c.max_power, target: self.target, measured };
                self.pid.control(&self.gains, &law)
            }
            Control::BangBang { hysteresis_tenths } => bang_bang(hysteresis_tenths, c.max_power, self.target, measured, self.duty > 0),
        };
        self.guard.on_output(&c.guard, c.sample_period_ms, self.target, measured, self.duty, c.max_power);
        None
    }

    /// `M303`: start a relay auto-tune on this heater (its target becomes
    /// the tune's; the tune's `max_power` is limited to the heater's).
    /// Then call [`on_tuning_sample`](Self::on_tuning_sample) instead of
    /// [`on_sample`](Self::on_sample) every sample until it is not
    /// [`TuneProgress::Running`]/[`TuneProgress::Cycle`].
    pub fn start_tuning(&mut self, tune: &Autotune) -> Result<(), ThermalFault> {
        self.set_target(tune.config().target)?;
        self.pid.reset();
        Ok(())
    }

    /// One sample during `M303`: the guard still watches (sensor, max/min
    /// temperature, heating watch); the runaway check is suspended.
    pub fn on_tuning_sample(&mut self, reading: Oversampled, tune: &mut Autotune) -> TuneProgress {
        match self.tuning_step(reading, tune) {
            TuningStep::Running => TuneProgress::Running,
            TuningStep::Cycle => TuneProgress::Cycle,
            // `Done` comes only with a result.
            TuningStep::Done => tune.last_cycle().result.map_or(TuneProgress::Running, TuneProgress::Done),
            TuningStep::Failed(error) => TuneProgress::Failed(error),
            TuningStep::Fault(fault) => TuneProgress::Fault(fault),
        }
    }

    /// [`on_tuning_sample`](Self::on_tuning_sample) without copying the
    /// result out: on [`TuningStep::Done`] it is
    /// `tune.last_cycle().result`.
    pub(crate) fn tuning_step(&mut self, reading: Oversampled, tune: &mut Autotune) -> TuningStep {
        let config = self.config();
        let measured = match self.judge(&config, reading, true) {
            Ok(measured) => measured,
            Err(Some(fault)) => {
                self.duty = 0;
                return TuningStep::Fault(fault);
            }
            Err(None) => {
                self.duty = 0;
                return TuningStep::Running;
            }
        };
        self.accept(measured);
        let limit = |duty: u8| duty.min(config.max_power);
        match tune.step(measured) {
            Step::Heat(duty) => {
                self.duty = limit(duty);
                TuningStep::Running
            }
            Step::Cycle(duty) => {
                self.duty = limit(duty);
                TuningStep::Cycle
            }
            Step::Done => {
                self.turn_off();
                TuningStep::Done
            }
            Step::Failed(error) => {
                self.turn_off();
                TuningStep::Failed(error)
            }
        }
    }

    /// `Error:…, system stopped! Heater_ID: …` for the latched fault.
    pub fn write_fault<W: ufmt::uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        match self.guard.fault() {
            Some(fault) => fault.write(self.id(), out),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::autotune::TuneConfig;
    use super::*;
    use crate::reply::test_support::Text;

    /// ADC count of `degrees` on the 4.7 kΩ table (nearest sixteenth).
    fn reading(degrees: f64) -> Oversampled {
        let r = 100_000.0 * (3950.0 * (1.0 / (degrees + 273.15) - 1.0 / 298.15)).exp();
        Oversampled((1023.0 * r / (r + 4700.0) * 16.0).round() as u16)
    }

    fn hotend() -> HeaterChannel {
        HeaterChannel::new(&HOTEND_0, Gains::MARLIN_HOTEND)
    }

    #[test]
    fn control_period_is_the_saturating_product() {
        for period in (0..=u16::MAX).step_by(7).chain([u16::MAX, 256, 257, 6553, 6554]) {
            for every in 0..=u8::MAX {
                let config = HeaterConfig { sample_period_ms: period, control_every: every, ..HeaterConfig::hotend(0) };
                assert_eq!(config.control_period_ms(), period.saturating_mul(u16::from(every.max(1))), "{period} × {every}");
            }
        }
    }

    #[test]
    fn a_cold_hot_end_with_a_target_heats_at_full_power() {
        let mut heater = hotend();
        assert_eq!(heater.on_sample(reading(25.0)), None);
        assert_eq!(heater.duty(), 0);
        assert_eq!(heater.set_target(Celsius(21_000)), Ok(Celsius(21_000)));
        assert_eq!(heater.on_sample(reading(25.0)), None);
        assert_eq!(heater.duty(), 255);
        assert_eq!(heater.power_report(), 127);
        assert!((heater.measured().0 - 2_500).abs() <= 5, "{:?}", heater.measured());
    }

    #[test]
    fn targets_above_max_minus_margin_are_clamped_and_negative_ones_are_off() {
        let mut heater = hotend();
        assert_eq!(heater.set_target(Celsius(30_000)), Ok(Celsius(26_000)));
        assert_eq!(heater.set_target(Celsius(-5)), Ok(Celsius(0)));
        let mut bed = HeaterChannel::new(&BED, Gains::MARLIN_BED);
        assert_eq!(bed.set_target(Celsius(15_000)), Ok(Celsius(14_000)));
    }

    #[test]
    fn target_zero_turns_the_heater_off_at_once() {
        let mut heater = hotend();
        heater.set_target(Celsius(21_000)).unwrap();
        heater.on_sample(reading(25.0));
        assert_eq!(heater.duty(), 255);
        heater.set_target(Celsius(0)).unwrap();
        assert_eq!(heater.duty(), 0);
        heater.on_sample(reading(25.0));
        assert_eq!(heater.duty(), 0);
    }

    #[test]
    fn an_open_thermistor_latches_once_with_its_message_and_blocks_new_targets() {
        let mut heater = hotend();
        heater.set_target(Celsius(21_000)).unwrap();
        heater.on_sample(reading(100.0));
        assert_eq!(heater.duty(), 255);
        let open = Oversampled::from_count(1023);
        assert_eq!(heater.on_sample(open), None);
        assert_eq!(heater.duty(), 0); // held off while unconfirmed
        assert_eq!(heater.on_sample(open), None);
        assert_eq!(heater.on_sample(open), Some(ThermalFault::SensorOpen));
        assert_eq!(heater.on_sample(open), None); // reported once
        assert_eq!(heater.on_sample(reading(100.0)), None);
        assert_eq!((heater.duty(), heater.target()), (0, Celsius(0)));
        assert_eq!(heater.set_target(Celsius(20_000)), Err(ThermalFault::SensorOpen));
        let mut out = Text::default();
        heater.write_fault(&mut out).unwrap();
        assert_eq!(out.0, "Error:MINTEMP triggered (thermistor open), system stopped! Heater_ID: 0\n");
        heater.clear_fault();
        assert_eq!(heater.set_target(Celsius(20_000)), Ok(Celsius(20_000)));
    }

    #[test]
    fn bang_bang_bed_holds_between_the_hysteresis_limits() {
        let mut bed = HeaterChannel::new(&BED_BANG_BANG, Gains::MARLIN_BED);
        bed.on_sample(reading(57.0));
        bed.set_target(Celsius(6_000)).unwrap();
        bed.on_sample(reading(57.0));
        assert_eq!(bed.duty(), 255);
        bed.on_sample(reading(61.0));
        assert_eq!(bed.duty(), 255);
        bed.on_sample(reading(62.2));
        assert_eq!(bed.duty(), 0);
        bed.on_sample(reading(59.0));
        assert_eq!(bed.duty(), 0);
        bed.on_sample(reading(57.9));
        assert_eq!(bed.duty(), 255);
    }

    #[test]
    fn the_snapshot_for_m105_carries_measured_target_and_marlin_power() {
        let mut heater = hotend();
        heater.set_target(Celsius(21_000)).unwrap();
        heater.on_sample(reading(25.0));
        let snapshot = heater.heater();
        assert_eq!((snapshot.target, snapshot.power), (Celsius(21_000), 127));
    }

    #[test]
    fn tuning_drives_the_relay_and_turns_off_when_it_fails() {
        let mut heater = hotend();
        heater.on_sample(reading(25.0));
        let mut tune = Autotune::new(TuneConfig::new(Celsius(20_000), 100));
        heater.start_tuning(&tune).unwrap();
        assert_eq!(heater.target(), Celsius(20_000));
        assert_eq!(heater.on_tuning_sample(reading(25.0), &mut tune), TuneProgress::Running);
        assert_eq!(heater.duty(), 254);
        assert_eq!(heater.on_tuning_sample(reading(240.0), &mut tune), TuneProgress::Failed(TuneError::TemperatureTooHigh));
        assert_eq!((heater.duty(), heater.target()), (0, Celsius(0)));
    }

    #[test]
    fn tuning_still_latches_sensor_faults() {
        let mut heater = hotend();
        let mut tune = Autotune::new(TuneConfig::new(Celsius(20_000), 100));
        heater.start_tuning(&tune).unwrap();
        let shorted = Oversampled::from_count(0);
        heater.on_tuning_sample(shorted, &mut tune);
        heater.on_tuning_sample(shorted, &mut tune);
        assert_eq!(heater.on_tuning_sample(shorted, &mut tune), TuneProgress::Fault(ThermalFault::SensorShorted));
        assert_eq!(heater.duty(), 0);
    }

    #[test]
    fn the_barrel_law_runs_every_tenth_sample_and_holds_its_duty_between() {
        fn reading48(degrees: f64) -> Oversampled {
            let r = 100_000.0 * (3950.0 * (1.0 / (degrees + 273.15) - 1.0 / 298.15)).exp();
            Oversampled((1023.0 * r / (r + 4800.0) * 16.0).round() as u16)
        }
        let mut barrel = HeaterChannel::new(&BARREL, Gains::THESIS_BARREL);
        barrel.on_sample(reading48(200.0));
        barrel.set_target(Celsius(21_000)).unwrap();
        barrel.on_sample(reading48(200.0));
        // Kp 6.12 × 10 °C = 61.2 (+ Ki 0.0204 × 10 °C × 1 s = 0.2) → 61.
        assert_eq!(barrel.duty(), 61);
        for _ in 0..9 {
            barrel.on_sample(reading48(209.0));
            assert_eq!(barrel.duty(), 61);
        }
        barrel.on_sample(reading48(209.0));
        assert!((6..=8).contains(&barrel.duty()), "{}", barrel.duty());
    }

    #[test]
    fn stock_configurations_read_back_from_flash() {
        assert_eq!(HOTEND_0.load(), HeaterConfig::hotend(0));
        assert_eq!(BARREL.load().control_period_ms(), 1000);
        assert_eq!(HeaterChannel::new(&BED, Gains::MARLIN_BED).id(), HeaterId::Bed);
        assert_eq!(HeaterConfig::hotend(0).max_target(), Celsius(26_000));
    }
}
