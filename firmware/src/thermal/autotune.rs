//! Relay auto-tune (`M303`): Åström–Hägglund with the Ziegler–Nichols
//! rules of SPEC §5, integer only.
//!
//! The heater is driven like a relay around the target: `bias + d` while
//! below `target − band`, `bias − d` once above `target + band` (the noise
//! band keeps sensor noise from chattering the relay). A heater heats
//! faster than it cools, so, like Marlin, every cycle moves the bias by
//! `d·(t_high − t_low)/(t_high + t_low)` (kept within 20..max−20) and sets
//! `d` to the distance from the bias to the nearer end of the range: the
//! oscillation becomes symmetric.
//!
//! Each cycle (from one switch to heating to the next) measures
//! `a = (max − min)/2` of the temperature — the peak after switching off
//! and the trough after switching on, as Marlin does — and `Pu`. From the
//! third cycle on, the result is computed; the experiment ends when two
//! successive cycles agree within 5 % in both `a` and `Pu`, or after
//! `cycles` cycles (Marlin's `C`, default 5) with the last cycle's result
//! (`converged: false`). It fails if the temperature overshoots the target
//! by more than 30 °C (Marlin's `MAX_OVERSHOOT_PID_AUTOTUNE`) or a half-cycle
//! takes longer than the timeout (Marlin's 20 min).
//!
//! Gains (SPEC §5): Ku = 4d/(πa), Kp = 0.6·Ku, Ki = 1.2·Ku/Pu,
//! Kd = 0.075·Ku·Pu, with d in duty counts, a in °C and Pu in s, so they
//! come out in Marlin's units ([`Gains`]). [`relay_gains`] computes them
//! with 32-bit operations on 64-bit products (`math::mul_div_round`) and
//! π ≈ 104348/33215 (3·10⁻¹⁰): Ku in 1/256 of 10⁻⁴ first, the rest from it.

use super::math::{mul_div_round, saturating_mul};
use super::pid::{Gain, Gains};
use super::{Celsius, HeaterId};
use crate::flash_str;

/// Ku and the gains from one relay experiment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RelayGains {
    /// Ku × 10⁴.
    pub ku: u32,
    pub gains: Gains,
}

/// SPEC §5's rules for relay amplitude `d` (duty counts), oscillation
/// amplitude `a` (hundredths of °C) and period `Pu` (ms). `None` when `a`
/// or `Pu` is zero, Ku exceeds 1677 or a gain does not fit [`Gains::MAX`].
pub fn relay_gains(relay_amplitude: u8, oscillation: Celsius, period_ms: u32) -> Option<RelayGains> {
    let a = u32::try_from(oscillation.0).ok().filter(|a| *a > 0 && *a <= u32::MAX / 104_348)?;
    if period_ms == 0 || period_ms > u32::MAX / 256 {
        return None;
    }
    // (Bounds are compared, never `checked_mul`: see `math`.)
    // Ku·10⁴·256 = 4d·10⁴·100·256/(π·a_centi), π = 104348/33215.
    let ku256 = mul_div_round(4_000_000 * u32::from(relay_amplitude), 33_215 * 256, a * 104_348)?;
    // Ku; 0.6·Ku; 1.2·Ku·1000/Pu_ms; 0.075·Ku·Pu_ms/1000 (one call site).
    let mut gains = [0u32; 4];
    for (index, gain) in gains.iter_mut().enumerate() {
        let (m, n) = match index {
            0 => (1, 256),
            1 => (3, 5 * 256),
            2 => (1200, period_ms * 256),
            _ => (3 * period_ms, 40_000 * 256),
        };
        *gain = mul_div_round(ku256, m, n).filter(|g| *g <= Gains::MAX)?;
    }
    let [ku, kp, ki, kd] = gains;
    Some(RelayGains { ku, gains: Gains { kp, ki, kd } })
}

/// Settings of one `M303` run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TuneConfig {
    /// `S`: the temperature to oscillate around.
    pub target: Celsius,
    /// `C`: most cycles (at least 3).
    pub cycles: u8,
    /// The heater's maximum duty (255, or Marlin's `MAX_BED_POWER`).
    pub max_power: u8,
    /// Relay noise band, hundredths of °C either side of the target.
    pub noise_band: i16,
    /// The heater's sample period.
    pub sample_period_ms: u16,
    /// Longest half-cycle (and the initial heat-up), seconds.
    pub timeout_s: u16,
}

impl TuneConfig {
    /// Marlin-like defaults: 5 cycles, a 0.3 °C band, 20 min timeout.
    pub const fn new(target: Celsius, sample_period_ms: u16) -> Self {
        Self { target, cycles: 5, max_power: 255, noise_band: 30, sample_period_ms, timeout_s: 1200 }
    }
}

/// Why a tune stopped without a result.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TuneError {
    /// More than 30 °C above the target.
    TemperatureTooHigh,
    /// No relay switch within the timeout.
    Timeout,
}

impl TuneError {
    /// `PID Autotune failed! Temperature too high` / `... timeout` (Marlin).
    pub fn write<W: ufmt::uWrite + ?Sized>(self, out: &mut W) -> Result<(), W::Error> {
        flash_str!("PID Autotune failed! ").write_to(out)?;
        match self {
            Self::TemperatureTooHigh => flash_str!("Temperature too high\n"),
            Self::Timeout => flash_str!("timeout\n"),
        }
        .write_to(out)
    }
}

/// The measurement of one completed cycle (Marlin prints it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CycleReport {
    pub bias: u8,
    pub d: u8,
    pub min: Celsius,
    pub max: Celsius,
    /// From the third cycle on.
    pub result: Option<TuneResult>,
}

impl CycleReport {
    /// Marlin's lines: ` bias: 92 d: 92 min: 196.56 max: 203.75` and, with
    /// a result, ` Ku: 33.18 Tu: 21.34` / ` Classic PID ` /
    /// ` Kp: 19.91 Ki: 1.87 Kd: 53.00`.
    pub fn write<W: ufmt::uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        ufmt::uwrite!(out, " bias: {} d: {} min: {} max: {}", crate::reply::Whole(self.bias.into()), crate::reply::Whole(self.d.into()), self.min, self.max)?;
        match &self.result {
            Some(result) => {
                let tu = crate::reply::Fixed { mantissa: (result.period_ms / 10) as i32, digits: 2 };
                ufmt::uwrite!(out, " Ku: {} Tu: {}", Gain(result.ku), tu)?;
                flash_str!("\n Classic PID \n").write_to(out)?;
                ufmt::uwrite!(out, "{}\n", result.gains)
            }
            None => out.write_str("\n"),
        }
    }
}

/// The outcome of a tune.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TuneResult {
    /// d, duty counts.
    pub relay_amplitude: u8,
    /// a, hundredths of °C.
    pub oscillation: Celsius,
    /// Pu, ms.
    pub period_ms: u32,
    /// Ku × 10⁴.
    pub ku: u32,
    pub gains: Gains,
    /// Two successive cycles agreed within 5 %.
    pub converged: bool,
}

impl TuneResult {
    /// Marlin's closing block:
    /// ```text
    /// PID Autotune finished! Put the last Kp, Ki and Kd constants from below into Configuration.h
    /// #define DEFAULT_Kp 19.91
    /// #define DEFAULT_Ki 1.87
    /// #define DEFAULT_Kd 53.00
    /// ```
    /// (`DEFAULT_bedKp`… for the bed, `DEFAULT_chamberKp`… for a chamber).
    pub fn write_finished<W: ufmt::uWrite + ?Sized>(&self, heater: HeaterId, out: &mut W) -> Result<(), W::Error> {
        flash_str!("PID Autotune finished! Put the last Kp, Ki and Kd constants from below into Configuration.h\n").write_to(out)?;
        let prefix = match heater {
            HeaterId::Hotend(_) => "",
            HeaterId::Bed => "bed",
            HeaterId::Chamber => "chamber",
        };
        let mut value = self.gains.kp;
        for name in *b"pid" {
            flash_str!("#define DEFAULT_").write_to(out)?;
            out.write_str(prefix)?;
            out.write_char('K')?;
            out.write_char(char::from(name))?;
            ufmt::uwrite!(out, " {}\n", Gain(value))?;
            value = if name == b'p' { self.gains.ki } else { self.gains.kd };
        }
        Ok(())
    }
}

/// What to do after one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TuneStep {
    /// Drive the heater with this duty.
    Heat(u8),
    /// A cycle completed (print [`Autotune::last_cycle`]); drive the
    /// heater with this duty.
    Cycle(u8),
    /// Finished: heater off; apply the gains on `U1`.
    Done(TuneResult),
    /// Failed: heater off.
    Failed(TuneError),
}

/// [`TuneStep`] without the result (the firmware's own path: no copy of
/// it; on `Done` it is [`Autotune::last_cycle`]'s).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Step {
    Heat(u8),
    Cycle(u8),
    Done,
    Failed(TuneError),
}

/// The relay experiment: 76 bytes on the AVR, alive only during `M303`.
#[derive(Clone, Copy, Debug)]
pub struct Autotune {
    config: TuneConfig,
    heating: bool,
    cycles: u8,
    bias: u8,
    d: u8,
    /// Samples since the start.
    now: u32,
    /// Sample of the last switch to heating / to cooling.
    heat_started: u32,
    cool_started: u32,
    t_high: u32,
    max: Celsius,
    min: Celsius,
    /// The last completed cycle (and its result from the third on).
    last: CycleReport,
}

impl Autotune {
    pub fn new(config: TuneConfig) -> Self {
        let half = config.max_power / 2;
        Self {
            config,
            heating: true,
            cycles: 0,
            bias: half,
            d: half,
            now: 0,
            heat_started: 0,
            cool_started: 0,
            t_high: 0,
            max: config.target,
            min: config.target,
            last: CycleReport { bias: half, d: half, min: config.target, max: config.target, result: None },
        }
    }

    pub fn config(&self) -> &TuneConfig {
        &self.config
    }

    /// The last completed cycle, for Marlin's per-cycle lines.
    pub fn last_cycle(&self) -> &CycleReport {
        &self.last
    }

    fn power(&self) -> u8 {
        let (bias, d) = (u16::from(self.bias), u16::from(self.d));
        let power = if self.heating { bias + d } else { bias.saturating_sub(d) };
        power.min(u16::from(self.config.max_power)) as u8
    }

    /// One sample with the measured temperature.
    pub fn on_sample(&mut self, measured: Celsius) -> TuneStep {
        match self.step(measured) {
            Step::Heat(duty) => TuneStep::Heat(duty),
            Step::Cycle(duty) => TuneStep::Cycle(duty),
            // `step` says `Done` only with a result.
            Step::Done => self.last.result.map_or(TuneStep::Cycle(self.power()), TuneStep::Done),
            Step::Failed(error) => TuneStep::Failed(error),
        }
    }

    /// [`on_sample`](Self::on_sample) without copying the result out:
    /// on [`Step::Done`] it is `last_cycle().result`.
    #[inline(never)]
    pub(crate) fn step(&mut self, measured: Celsius) -> Step {
        // Through a pointer register (`ldd`/`std`, 2 bytes) rather than
        // the static's absolute address LTO would fold in (`lds`/`sts`, 4).
        let this = core::hint::black_box(self);
        this.step_at(measured)
    }

    fn step_at(&mut self, measured: Celsius) -> Step {
        self.now = self.now.wrapping_add(1);
        // `measured > target + c` and `measured < target − c`, saturating
        // (see `excess`).
        let excess = super::excess(measured, self.config.target);
        if excess > 3000 {
            return Step::Failed(TuneError::TemperatureTooHigh);
        }
        let last_switch = if self.heating { self.heat_started } else { self.cool_started };
        let timeout = super::millis(self.config.timeout_s) / u32::from(self.config.sample_period_ms.max(1));
        if self.now.wrapping_sub(last_switch) > timeout {
            return Step::Failed(TuneError::Timeout);
        }
        self.max = self.max.max(measured);
        self.min = self.min.min(measured);
        let band = i32::from(self.config.noise_band.max(0));

        if self.heating && excess > band {
            self.heating = false;
            self.cool_started = self.now;
            self.t_high = self.now.wrapping_sub(self.heat_started);
            self.max = measured;
        } else if !self.heating && excess < -band {
            self.heating = true;
            let t_low = self.now.wrapping_sub(self.cool_started);
            self.heat_started = self.now;
            let first = self.cycles == 0;
            self.cycles = self.cycles.saturating_add(1);
            if !first {
                let done = self.cycle_completed(t_low);
                self.min = measured;
                if done && self.last.result.is_some() {
                    return Step::Done;
                }
                return Step::Cycle(self.power());
            }
            self.min = measured;
        }
        Step::Heat(self.power())
    }

    /// End of a cycle (`cycles` counts it): adapt the bias, measure, and
    /// say whether the experiment is over.
    fn cycle_completed(&mut self, t_low: u32) -> bool {
        let max_power = i32::from(self.config.max_power);
        let samples = |t: u32| t.min(1 << 24) as i32;
        let (t_high, t_low) = (samples(self.t_high), samples(t_low));
        // The result of the cycle just measured uses the d it ran with.
        let measured_d = self.d;
        let shift = saturating_mul(i32::from(measured_d), t_high - t_low) / (t_high + t_low).max(1);
        let bias = super::math::clamp(i32::from(self.bias) + shift, 20.min(max_power / 2), (max_power - 20).max(max_power / 2));
        self.bias = bias as u8;
        self.d = (if bias > max_power / 2 { max_power - 1 - bias } else { bias }) as u8;
        // Only what the agreement test needs of the previous result.
        let previous = self.last.result.map(|p| (p.oscillation.0 as u32, p.period_ms));
        self.last = CycleReport { bias: self.bias, d: self.d, min: self.min, max: self.max, result: None };
        if self.cycles <= 3 {
            return false;
        }
        let amplitude = super::excess(self.max, self.min) / 2;
        // 0 ≤ t_high + t_low ≤ 2²⁵. A product that saturates (at
        // `i32::MAX`) is refused by `relay_gains` (Pu above 2³²/256 ms)
        // exactly as the true one would be.
        let period_ms = saturating_mul(t_high + t_low, i32::from(self.config.sample_period_ms.max(1))) as u32;
        let Some(gains) = relay_gains(measured_d, Celsius(amplitude), period_ms) else {
            return false;
        };
        let converged = previous.is_some_and(|(oscillation, period)| within_5_percent(amplitude as u32, oscillation) && within_5_percent(period_ms, period));
        self.last.result = Some(TuneResult { relay_amplitude: measured_d, oscillation: Celsius(amplitude), period_ms, ku: gains.ku, gains: gains.gains, converged });
        converged || self.cycles > self.config.cycles.max(3)
    }
}

/// |a − b| ≤ 5 % of the larger, without division.
fn within_5_percent(a: u32, b: u32) -> bool {
    let difference = a.abs_diff(b);
    let larger = a.max(b);
    // difference ≤ ⌊larger/20⌋ ⟺ 20·difference ≤ larger; a difference
    // whose 20-fold overflows is larger than any u32.
    difference <= u32::MAX / 20 && (difference << 4) + (difference << 2) <= larger
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reply::test_support::Text;

    #[test]
    fn spec_section_5_vector_d127_a10_pu0_2() {
        let g = relay_gains(127, Celsius(1000), 200).unwrap();
        assert_eq!(g.ku, 161_701); // Ku 16.1701
        assert_eq!(g.gains, Gains { kp: 97_021, ki: 970_209, kd: 2_426 }); // 9.7021, 97.0209, 0.2426
    }

    #[test]
    fn spec_section_5_vector_d100_a50_pu1() {
        let g = relay_gains(100, Celsius(5000), 1000).unwrap();
        assert_eq!(g.ku, 25_465); // Ku 2.5465
        assert_eq!(g.gains, Gains { kp: 15_279, ki: 30_558, kd: 1_910 }); // 1.5279, 3.0558, 0.1910
    }

    /// The rules with exact 128-bit arithmetic, as the reference.
    fn reference_gains(d: u8, a: i32, period_ms: u32) -> Option<RelayGains> {
        let a = u32::try_from(a).ok().filter(|a| *a > 0 && *a <= u32::MAX / 104_348)?;
        if period_ms == 0 || period_ms > u32::MAX / 256 {
            return None;
        }
        let round = |x: u128, m: u128, n: u128| u32::try_from((x * m + n / 2) / n).ok();
        let ku256 = round(4_000_000 * u128::from(d), 33_215 * 256, u128::from(a) * 104_348)?;
        let gain = |m: u32, n: u32| round(u128::from(ku256), u128::from(m), u128::from(n)).filter(|g| *g <= Gains::MAX);
        Some(RelayGains {
            ku: gain(1, 256)?,
            gains: Gains { kp: gain(3, 5 * 256)?, ki: gain(1200, period_ms * 256)?, kd: gain(3 * period_ms, 40_000 * 256)? },
        })
    }

    #[test]
    fn relay_gains_match_exact_arithmetic_over_their_range() {
        let periods = [1, 2, 99, 100, 200, 1_000, 21_340, 65_535, 1_000_000, 16_777_215, 16_777_216, u32::MAX];
        for d in [0u8, 1, 2, 50, 92, 127, 128, 200, 254, 255] {
            for a in (-3..3_000).chain((3_000..41_200).step_by(37)).chain([41_159, 41_160, 41_161, i32::MAX]) {
                for period in periods {
                    assert_eq!(relay_gains(d, Celsius(a), period), reference_gains(d, a, period), "d {d} a {a} Pu {period}");
                }
            }
        }
    }

    #[test]
    fn relay_gains_refuse_a_zero_amplitude_or_period() {
        assert_eq!(relay_gains(127, Celsius(0), 200), None);
        assert_eq!(relay_gains(127, Celsius(-5), 200), None);
        assert_eq!(relay_gains(127, Celsius(1000), 0), None);
    }

    #[test]
    fn typical_hot_end_relay_gives_marlin_like_gains() {
        // d 127, a 3.6 °C, Pu 21.34 s: Ku 44.9171, Kp 26.9502, Ki 2.5258,
        // Kd 71.8898 (f64: 44.917062, 26.950237, 2.525795, 71.889757).
        let g = relay_gains(127, Celsius(360), 21_340).unwrap();
        assert_eq!(g.ku, 449_171);
        assert_eq!(g.gains, Gains { kp: 269_502, ki: 25_258, kd: 718_898 });
    }

    /// A first-order plant with dead time, sampled every second:
    /// heats `gain` °C per count at steady state.
    fn relay_on_plant(config: TuneConfig) -> (TuneStep, std::vec::Vec<CycleReport>) {
        let (gain, tau, dead) = (1.8f64, 120.0f64, 4usize);
        let mut temperature = 25.0f64;
        let mut pipeline = std::collections::VecDeque::from(std::vec![0u8; dead]);
        let mut tune = Autotune::new(config);
        let mut cycles = std::vec::Vec::new();
        for _ in 0..100_000 {
            let step = tune.on_sample(Celsius((temperature * 100.0).round() as i32));
            let duty = match step {
                TuneStep::Heat(duty) => duty,
                TuneStep::Cycle(duty) => {
                    cycles.push(*tune.last_cycle());
                    duty
                }
                other => return (other, cycles),
            };
            pipeline.push_back(duty);
            let applied = f64::from(pipeline.pop_front().unwrap());
            temperature += (25.0 + gain * applied - temperature) / tau;
        }
        panic!("no result");
    }

    #[test]
    fn relay_on_a_plant_converges_with_a_symmetric_oscillation() {
        let (step, cycles) = relay_on_plant(TuneConfig { sample_period_ms: 1000, ..TuneConfig::new(Celsius(20_000), 1000) });
        let TuneStep::Done(result) = step else { panic!("{step:?}") };
        assert!(result.converged, "{result:?}");
        // Steady duty for 200 °C is (200 − 25)/1.8 = 97: the bias moves there.
        let last = cycles.last().unwrap();
        assert!((90..=105).contains(&last.bias), "{cycles:?}");
        assert!(result.gains.kp > 0 && result.gains.ki > 0 && result.gains.kd > 0);
        // The oscillation straddles the target.
        assert!(last.min < Celsius(20_000) && last.max > Celsius(20_000));
    }

    #[test]
    fn relay_stops_after_c_cycles_without_agreement() {
        // With C = 3, the third cycle is the last whatever it measured.
        let (step, cycles) = relay_on_plant(TuneConfig { cycles: 3, ..TuneConfig::new(Celsius(20_000), 1000) });
        assert!(matches!(step, TuneStep::Done(_)), "{step:?}");
        assert_eq!(cycles.len(), 2); // cycles 1 and 2 printed; the third finished
    }

    #[test]
    fn relay_fails_when_30_degrees_above_target() {
        let mut tune = Autotune::new(TuneConfig::new(Celsius(20_000), 100));
        assert_eq!(tune.on_sample(Celsius(23_000)), TuneStep::Heat(0));
        assert_eq!(tune.on_sample(Celsius(23_001)), TuneStep::Failed(TuneError::TemperatureTooHigh));
    }

    #[test]
    fn relay_fails_when_the_heat_up_exceeds_the_timeout() {
        let mut tune = Autotune::new(TuneConfig { timeout_s: 10, ..TuneConfig::new(Celsius(20_000), 100) });
        for _ in 0..100 {
            assert_eq!(tune.on_sample(Celsius(5_000)), TuneStep::Heat(254));
        }
        assert_eq!(tune.on_sample(Celsius(5_000)), TuneStep::Failed(TuneError::Timeout));
    }

    #[test]
    fn relay_switches_outside_the_noise_band_only() {
        let mut tune = Autotune::new(TuneConfig::new(Celsius(20_000), 100)); // band 0.3 °C
        assert_eq!(tune.on_sample(Celsius(20_030)), TuneStep::Heat(254));
        assert_eq!(tune.on_sample(Celsius(20_031)), TuneStep::Heat(0));
        assert_eq!(tune.on_sample(Celsius(19_970)), TuneStep::Heat(0));
        assert_eq!(tune.on_sample(Celsius(19_969)), TuneStep::Heat(254));
    }

    #[test]
    fn within_5_percent_is_the_larger_divided_by_20() {
        let mut values: std::vec::Vec<u32> = (0..2_000).collect();
        values.extend((0..2_000u32).map(|i| i.wrapping_mul(2_654_435_761)));
        values.extend([u32::MAX, u32::MAX - 1, u32::MAX / 20, u32::MAX / 20 + 1, 214_748_364, 4_294_967_280]);
        for &a in &values {
            for &b in values.iter().step_by(7) {
                assert_eq!(within_5_percent(a, b), a.abs_diff(b) <= a.max(b) / 20, "{a} {b}");
            }
        }
        for a in 0..3_000u32 {
            for b in a..a + 200 {
                assert_eq!(within_5_percent(a, b), a.abs_diff(b) <= a.max(b) / 20, "{a} {b}");
            }
        }
    }

    #[test]
    fn reports_print_like_marlin() {
        let result = TuneResult {
            relay_amplitude: 127,
            oscillation: Celsius(360),
            period_ms: 21_340,
            ku: 449_171,
            gains: Gains { kp: 269_502, ki: 25_258, kd: 718_898 },
            converged: true,
        };
        let report = CycleReport { bias: 92, d: 92, min: Celsius(19_656), max: Celsius(20_375), result: Some(result) };
        let mut out = Text::default();
        report.write(&mut out).unwrap();
        CycleReport { result: None, ..report }.write(&mut out).unwrap();
        result.write_finished(HeaterId::Hotend(0), &mut out).unwrap();
        result.write_finished(HeaterId::Bed, &mut out).unwrap();
        TuneError::Timeout.write(&mut out).unwrap();
        assert_eq!(
            out.0,
            " bias: 92 d: 92 min: 196.56 max: 203.75 Ku: 44.9171 Tu: 21.34\n Classic PID \n Kp: 26.9502 Ki: 2.5258 Kd: 71.8898\n\
             \x20bias: 92 d: 92 min: 196.56 max: 203.75\n\
             PID Autotune finished! Put the last Kp, Ki and Kd constants from below into Configuration.h\n\
             #define DEFAULT_Kp 26.9502\n#define DEFAULT_Ki 2.5258\n#define DEFAULT_Kd 71.8898\n\
             PID Autotune finished! Put the last Kp, Ki and Kd constants from below into Configuration.h\n\
             #define DEFAULT_bedKp 26.9502\n#define DEFAULT_bedKi 2.5258\n#define DEFAULT_bedKd 71.8898\n\
             PID Autotune failed! timeout\n"
        );
    }
}
