//! SPEC §1's encoder loops on a printer whose planner drives the steps.
//!
//! # Design (ours)
//!
//! The thesis ran X and Y in a velocity mode commanded by the loop. On this
//! firmware the planner already turns every move into exact steps with
//! bounded acceleration (the loop's feedforward, done perfectly), so the
//! loop only has to act on what the steps did not achieve:
//!
//! ```text
//! reference  xd = the steps the interrupt has made × units/step
//! measured   x  = the NSE-5310, unwrapped (1/2048 mm)
//! correction u  = the selected law on e = xd − x, with no feedforward
//!                 (the planner's steps are the feedforward)
//! ```
//!
//! `u` (units/s) becomes a correction step rate that the board's 1 kHz tick
//! turns into extra STEP pulses ([`EncoderLoops::emit`], at most one per
//! axis per millisecond: 1000 steps/s, 10 mm/s at 100 steps/mm). The
//! correction steps are not counted in `xd`: they move the carriage back to
//! where the planner's steps say it is. So:
//! - open loop (`M821 S0`): no correction; the following error is still
//!   supervised, i.e. a lost step or a slipped belt is *detected* and stops
//!   the job instead of being printed over;
//! - P (`S1`, Kp 4.3/s): a slip of `d` decays as e^(−Kp·t);
//! - robust PID (`S2`, γ 0.5): K0 + Kp on the error, integral and
//!   filtered derivative, SPEC §1's tuning for θ = 20 ms by default
//!   ([`DEFAULT_THETA_MS`]; `M824 T` changes it).
//!
//! Every strategy stops the job with an `Error:` line when |e| stays above
//! the following-error limit (`M823`, 1 mm for 0.5 s by default) or
//! exceeds four times it at once; a read that fails five times in a row or
//! a sensor that stays bit-identical while the axis is commanded to move
//! stops it too. After a fault, or a homing, the encoder is re-zeroed on the
//! step position ([`EncoderLoops::rehome`]).
//!
//! The loop runs at [`LOOP_HZ`] in the board's timer tick; this module is
//! integer only (the gains are computed in the main loop, [`LoopSettings`]).

use super::control::{AxisController, DriverStatus, FollowingErrorLimit, LoopGains, Reference};
use super::nse5310::{LinearTracker, TrackerConfig, TrackerCounters, UNITS_PER_MM};
use super::output::StepperScale;
use super::trace::{TraceRecorder, TraceSample};
use super::tuning::{Strategy, TuningError};
use super::{AxisFault, EncoderAxis, Reading};
use crate::num::{mul_q16, Q16};

/// Loop samples per second (every 4th millisecond of the board's tick).
pub const LOOP_HZ: u16 = 250;
/// Milliseconds between loop samples.
pub const LOOP_PERIOD_MS: u8 = (1000 / LOOP_HZ as u32) as u8;
/// The fastest correction: one step per axis per millisecond.
pub const MAX_CORRECTION_STEPS_PER_S: i32 = 1000;
/// The axes with an encoder: X and Y.
pub const AXES: usize = 2;
/// Their letters, for replies.
pub const AXIS_LETTERS: [u8; AXES] = [b'X', b'Y'];
/// The dead time the robust PID is tuned for unless `M824 T` says
/// otherwise, milliseconds. Ours: SPEC §1's θ = 0.1 s is the thesis'
/// velocity-mode plant; the corrector's own delay is one loop period plus
/// the emission (≈ 6 ms), and tuned for 0.1 s it took 0.3 s to take up a
/// 0.5 mm slip and 1 s to settle its overshoot (the test below); tuned
/// for 20 ms: 0.07 s and 0.3 s.
pub const DEFAULT_THETA_MS: u16 = 20;

/// What the host chose for one axis (`M820`, `M821`, `M823`, `M824`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoopSettings {
    pub enabled: bool,
    pub strategy: Strategy,
    pub following: FollowingErrorLimit,
    /// θ for the robust PID's tuning, milliseconds.
    pub theta_ms: u16,
}

impl LoopSettings {
    /// Off (a printer without encoders must print as before), robust PID
    /// γ 0.5 once switched on, 1 mm for 0.5 s.
    pub const DEFAULT: Self = Self {
        enabled: false,
        strategy: Strategy::RobustPid { gamma_milli: 500 },
        following: FollowingErrorLimit::printer_default(LOOP_HZ),
        theta_ms: DEFAULT_THETA_MS,
    };

    /// The tick's gains for this strategy with the feedforward removed (the
    /// planner's steps are the feedforward). Main loop only: f32.
    pub fn gains(&self) -> Result<LoopGains, TuningError> {
        let mut gains: LoopGains = self.strategy.loop_gains(f32::from(self.theta_ms) / 1000.0, 1.0 / f32::from(LOOP_HZ))?;
        gains.feedforward = <LoopGains>::OPEN_LOOP.proportional;
        Ok(gains)
    }
}

/// One encoder axis and its correction emitter.
#[derive(Clone, Copy, Debug)]
struct CorrectedAxis {
    axis: EncoderAxis,
    enabled: bool,
    /// Units per step, Q16.16 (2048/100 mm on the Prusa i3: 20.48).
    units_per_step: Q16,
    /// Step position (since boot) where the encoder reads 0.
    zero_steps: i32,
    /// Correction rate until the next sample, steps/s Q24.8.
    rate: i32,
    /// The emitter's remainder, Q24.8 step·ms (emits at ±1000 steps/s·ms).
    remainder: i32,
    /// Correction steps emitted since the last re-zero (signed).
    corrections: i32,
    /// The last reference and measurement, units (for `M822`).
    reference: i32,
}

/// The emitter steps once this much rate has accumulated: 1000 ms × 256.
const EMIT_THRESHOLD: i32 = 1000 * 256;

impl CorrectedAxis {
    /// `None` when the axis is too fast to be read at [`LOOP_HZ`] (SPEC §1:
    /// at least one read per 1 mm) or its steps/mm make no scale.
    fn new(steps_per_mm: f32, max_speed_mm_s: u16) -> Option<Self> {
        let units_per_mm = UNITS_PER_MM as f32;
        // The tracker unwraps around the commanded travel, so any speed is
        // readable; a read may deviate from the prediction by up to 0.5 mm.
        let _ = max_speed_mm_s;
        let tracker = TrackerConfig::default_for_printer();
        let scale = StepperScale::new(steps_per_mm, units_per_mm)?;
        let units_per_step = Q16::from_f32(units_per_mm / steps_per_mm)?;
        let limit = MAX_CORRECTION_STEPS_PER_S as f32 * units_per_mm / steps_per_mm;
        Some(Self {
            axis: EncoderAxis::new(
                LinearTracker::new(tracker),
                AxisController::new(LoopGains::OPEN_LOOP, limit as i32, LoopSettings::DEFAULT.following),
                scale,
            ),
            enabled: false,
            units_per_step,
            zero_steps: 0,
            rate: 0,
            remainder: 0,
            corrections: 0,
            reference: 0,
        })
    }

    fn reference_units(&self, steps: i32) -> i32 {
        mul_q16(steps.wrapping_sub(self.zero_steps), self.units_per_step)
    }
}

/// A snapshot for `M822`, taken by the board now and then.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AxisReport {
    /// Units from the encoder's zero.
    pub measured: i32,
    pub reference: i32,
    pub corrections: i32,
    pub counters: TrackerCounters,
    pub fault: Option<AxisFault>,
}

impl AxisReport {
    pub const EMPTY: Self = Self {
        measured: 0,
        reference: 0,
        corrections: 0,
        counters: TrackerCounters { index_accepted: 0, index_glitches: 0, index_bounces: 0, index_missed: 0, bad_reads: 0 },
        fault: None,
    };
}

/// X's and Y's loops, as the board keeps them (in a `static`, shared by
/// the tick and the main loop under a critical section).
#[derive(Clone, Copy, Debug)]
pub struct EncoderLoops {
    axes: [CorrectedAxis; AXES],
    /// The first fault since the main loop last looked.
    posted: Option<(u8, AxisFault)>,
    /// `M828`'s capture of every sample.
    trace: TraceRecorder,
}

impl EncoderLoops {
    /// `steps_per_mm` and the fastest speed of X and Y (the speed sizes the
    /// largest plausible jump between two reads). `None`: an axis cannot
    /// be read often enough at [`LOOP_HZ`] for its speed (or has no
    /// usable steps/mm).
    pub fn new(steps_per_mm: [f32; AXES], max_speed_mm_s: [u16; AXES]) -> Option<Self> {
        Some(Self {
            axes: [CorrectedAxis::new(steps_per_mm[0], max_speed_mm_s[0])?, CorrectedAxis::new(steps_per_mm[1], max_speed_mm_s[1])?],
            posted: None,
            trace: TraceRecorder::new(),
        })
    }

    /// Whether any axis' loop is on (the board skips the I²C reads if not).
    pub fn any_enabled(&self) -> bool {
        self.axes.iter().any(|axis| axis.enabled)
    }

    /// Whether the board must read the encoders every sample: a loop is
    /// on, or `M828` records (loops off: the readings are recorded and
    /// nothing is corrected).
    pub fn needs_readings(&self) -> bool {
        self.any_enabled() || self.trace.is_on()
    }

    /// `M828`: start (from sample number 0) or stop recording every sample.
    pub fn set_tracing(&mut self, on: bool) {
        self.trace.set(on);
    }

    /// The oldest recorded sample not yet taken (main loop).
    pub fn take_trace_sample(&mut self) -> Option<TraceSample> {
        self.trace.take()
    }

    /// Samples recorded and dropped (ring full) since the capture started.
    pub fn trace_totals(&self) -> (u32, u32) {
        self.trace.totals()
    }

    /// Install one axis' settings (gains from [`LoopSettings::gains`]).
    /// Switching a loop on re-zeroes its encoder at `steps_now`.
    pub fn configure(&mut self, axis: usize, settings: &LoopSettings, gains: LoopGains, steps_now: i32) {
        let Some(corrected) = self.axes.get_mut(axis) else { return };
        let was_enabled = corrected.enabled;
        corrected.enabled = settings.enabled;
        corrected.axis.controller.set_gains(gains);
        corrected.axis.controller.set_following_error(settings.following);
        if settings.enabled && !was_enabled {
            Self::rezero(corrected, steps_now);
        }
        if !settings.enabled {
            corrected.rate = 0;
        }
    }

    /// `M92` changed an axis' steps/mm: its scale follows, and its encoder
    /// is re-zeroed on the step position (the reference's scale changed
    /// under the loop). `false`: no usable scale, nothing changed.
    pub fn set_steps_per_mm(&mut self, axis: usize, steps_per_mm: f32, steps_now: i32) -> bool {
        let Some(corrected) = self.axes.get_mut(axis) else { return false };
        let Some(fresh) = CorrectedAxis::new(steps_per_mm, 0) else { return false };
        let controller = &corrected.axis.controller;
        let (gains, following) = (controller.gains(), controller.following_error());
        corrected.axis.controller = AxisController::new(gains, fresh.axis.controller.output_limit(), following);
        corrected.axis.scale = fresh.axis.scale;
        corrected.units_per_step = fresh.units_per_step;
        Self::rezero(corrected, steps_now);
        true
    }

    /// Homing finished (or a fault is being cleared): each encoder reads
    /// the step position as its new zero, the loops forget their past.
    pub fn rehome(&mut self, steps_now: [i32; AXES]) {
        for (axis, steps) in self.axes.iter_mut().zip(steps_now) {
            Self::rezero(axis, steps);
        }
        self.posted = None;
    }

    fn rezero(axis: &mut CorrectedAxis, steps: i32) {
        axis.zero_steps = steps;
        axis.axis.rehome(0);
        // The strip may have moved while the loop was off or stopped: the
        // next reading is the new zero.
        axis.axis.tracker.restart();
        axis.rate = 0;
        axis.remainder = 0;
        axis.corrections = 0;
        axis.reference = 0;
    }

    /// One loop sample (the board's tick, every [`LOOP_PERIOD_MS`]):
    /// `steps_now` from the step interrupt, the two readings and the
    /// debounced Index edges since the last sample.
    pub fn tick(&mut self, steps_now: [i32; AXES], readings: [Reading; AXES], index_edges: [u8; AXES]) {
        self.trace.record(readings, index_edges, steps_now);
        for index in 0..AXES {
            let corrected = &mut self.axes[index];
            // A latched fault was posted when it happened; it stays until
            // re-homing (`rehome`) without being posted again.
            if !corrected.enabled || corrected.axis.controller.fault().is_some() {
                corrected.rate = 0;
                continue;
            }
            let position = corrected.reference_units(steps_now[index]);
            corrected.reference = position;
            let reference = Reference { position, velocity: 0 };
            match corrected.axis.tick(reference, readings[index], index_edges[index], DriverStatus::default()) {
                Ok(rate) => {
                    let limit = MAX_CORRECTION_STEPS_PER_S * 256;
                    corrected.rate = if rate.0 > limit {
                        limit
                    } else if rate.0 < -limit {
                        -limit
                    } else {
                        rate.0
                    };
                }
                Err(fault) => {
                    self.stop_all(AxisFault::Stopped);
                    if self.posted.is_none() {
                        self.posted = Some((AXIS_LETTERS[index], fault));
                    }
                    return;
                }
            }
        }
    }

    /// Every millisecond: which axes take a correction step now (bit 0 X,
    /// bit 1 Y) and in which direction (bit set: positive).
    pub fn emit(&mut self) -> (u8, u8) {
        let mut steps = 0;
        let mut positive = 0;
        for (bit, axis) in [1u8, 2].into_iter().zip(self.axes.iter_mut()) {
            if axis.rate == 0 {
                continue;
            }
            axis.remainder = axis.remainder.saturating_add(axis.rate);
            if axis.remainder >= EMIT_THRESHOLD {
                axis.remainder -= EMIT_THRESHOLD;
                axis.corrections = axis.corrections.wrapping_add(1);
                steps |= bit;
                positive |= bit;
            } else if axis.remainder <= -EMIT_THRESHOLD {
                axis.remainder += EMIT_THRESHOLD;
                axis.corrections = axis.corrections.wrapping_sub(1);
                steps |= bit;
            }
        }
        (steps, positive)
    }

    /// Stop both loops' corrections (a fault, `M112`, `M410`).
    pub fn stop_all(&mut self, fault: AxisFault) {
        for axis in &mut self.axes {
            axis.rate = 0;
            axis.remainder = 0;
            if axis.enabled {
                axis.axis.controller.stop(fault);
            }
        }
    }

    /// The fault the tick posted (axis letter and why), once.
    pub fn take_fault(&mut self) -> Option<(u8, AxisFault)> {
        self.posted.take()
    }

    /// What `M822` shows.
    pub fn report(&self, axis: usize) -> AxisReport {
        let Some(corrected) = self.axes.get(axis) else { return AxisReport::default() };
        AxisReport {
            measured: corrected.axis.measured(),
            reference: corrected.reference,
            corrections: corrected.corrections,
            counters: corrected.axis.tracker.counters(),
            fault: corrected.axis.controller.fault(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Prusa i3: 100 steps/mm, 200 mm/s.
    fn prusa() -> EncoderLoops {
        EncoderLoops::new([100.0, 100.0], [200, 200]).unwrap()
    }

    fn switch_on(loops: &mut EncoderLoops, strategy: Strategy) {
        let settings = LoopSettings { enabled: true, strategy, ..LoopSettings::DEFAULT };
        for axis in 0..AXES {
            loops.configure(axis, &settings, settings.gains().unwrap(), 0);
        }
    }

    /// An NSE-5310 over the strip at `units` from where it started.
    fn raw_at(units: i32) -> Reading {
        Reading::Raw((units.rem_euclid(4096)) as u16)
    }

    /// Run `samples` loop periods of a carriage that ends up `slip_units`
    /// away from its steps (a belt that jumped), X moving at `speed_steps`
    /// steps per sample; returns the final error (reference − measured) and
    /// the correction steps made.
    fn run_with_slip(loops: &mut EncoderLoops, slip_units: i32, samples: u32, speed_steps: i32) -> (i32, i32, Option<(u8, AxisFault)>) {
        let mut steps = 0i32;
        let mut corrections = 0i32;
        let mut fault = None;
        // The first read primes the tracker at 0.
        loops.tick([0, 0], [raw_at(0), raw_at(0)], [0, 0]);
        for sample in 0..samples {
            steps += speed_steps;
            // The belt slips from the 10th sample on, 0.125 mm a sample
            // (31 mm/s: a jump the encoder can follow between two reads).
            let slip = (i64::from(sample.saturating_sub(10)) * 256).min(i64::from(slip_units.abs())) as i32 * slip_units.signum();
            // The carriage: the planner's steps and the corrections, 20.48 units each, less the slip.
            let carriage = ((steps + corrections) as i64 * 2048 / 100) as i32 - slip;
            loops.tick([steps, 0], [raw_at(carriage), raw_at(0)], [0, 0]);
            if let Some(posted) = loops.take_fault() {
                fault = Some(posted);
                break;
            }
            for _ in 0..LOOP_PERIOD_MS {
                let (mask, positive) = loops.emit();
                if mask & 1 != 0 {
                    corrections += if positive & 1 != 0 { 1 } else { -1 };
                }
            }
        }
        let carriage = ((steps + corrections) as i64 * 2048 / 100) as i32 - slip_units;
        let reference = (steps as i64 * 2048 / 100) as i32;
        (reference - carriage, corrections, fault)
    }

    #[test]
    fn the_loops_are_off_until_switched_on_and_then_emit_nothing_while_the_carriage_follows_its_steps() {
        let mut loops = prusa();
        assert!(!loops.any_enabled());
        switch_on(&mut loops, Strategy::RobustPid { gamma_milli: 500 });
        assert!(loops.any_enabled());
        let (error, corrections, fault) = run_with_slip(&mut loops, 0, 250, 40);
        assert!(error.abs() <= 21, "error {error} units");
        // At most one step of dither from the encoder's rounding.
        assert!(corrections.abs() <= 1, "{corrections} correction steps");
        assert_eq!(fault, None);
    }

    #[test]
    fn a_belt_slip_of_half_a_millimetre_is_corrected_by_the_robust_pid_within_a_second() {
        let mut loops = prusa();
        switch_on(&mut loops, Strategy::RobustPid { gamma_milli: 500 });
        // 0.5 mm = 1024 units = 50 steps lost while X moves at 10 mm/s.
        let (error, corrections, fault) = run_with_slip(&mut loops, 1024, 260, 4);
        assert_eq!(fault, None);
        assert!(error.abs() <= 21, "left {error} units after 1 s");
        assert!((49..=51).contains(&corrections), "{corrections} correction steps");
    }

    #[test]
    fn the_p_strategy_corrects_a_slip_too() {
        let mut loops = prusa();
        switch_on(&mut loops, Strategy::PFeedforward { kp_milli: 4300 });
        let (error, corrections, fault) = run_with_slip(&mut loops, 1024, 500, 0);
        assert_eq!(fault, None);
        assert!(error.abs() <= 21, "left {error} units after 2 s");
        assert!((49..=51).contains(&corrections), "{corrections} correction steps");
    }

    #[test]
    fn open_loop_detects_a_two_millimetre_slip_as_a_following_error_and_corrects_nothing() {
        let mut loops = prusa();
        switch_on(&mut loops, Strategy::OpenLoop);
        let (_, corrections, fault) = run_with_slip(&mut loops, 2 * 2048, 400, 4);
        assert_eq!(corrections, 0);
        match fault {
            Some((b'X', AxisFault::FollowingError { error })) => assert!(error >= 2048, "error {error}"),
            other => panic!("expected X's following error, got {other:?}"),
        }
        assert_eq!(loops.report(0).fault.map(|f| matches!(f, AxisFault::FollowingError { .. })), Some(true));
        // Y stopped with it.
        assert_eq!(loops.report(1).fault, Some(AxisFault::Stopped));
        // Nothing more is emitted after the fault.
        assert_eq!(loops.emit(), (0, 0));
    }

    #[test]
    fn a_jammed_carriage_stops_the_job_even_with_the_pid_correcting() {
        let mut loops = prusa();
        switch_on(&mut loops, Strategy::RobustPid { gamma_milli: 500 });
        loops.tick([0, 0], [raw_at(0), raw_at(0)], [0, 0]);
        let mut fault = None;
        // X is commanded at 20 mm/s (8 steps a sample) but does not move;
        // the sensor reads noise around 0 so it is not "stuck".
        for sample in 1..300 {
            loops.tick([8 * sample, 0], [raw_at(sample % 3), raw_at(0)], [0, 0]);
            for _ in 0..LOOP_PERIOD_MS {
                loops.emit();
            }
            if let Some(posted) = loops.take_fault() {
                fault = Some((sample, posted));
                break;
            }
        }
        let (sample, (letter, why)) = fault.expect("a jam must stop the job");
        assert_eq!(letter, b'X');
        assert!(matches!(why, AxisFault::FollowingError { .. }), "{why:?}");
        // 4 mm (four times the 1 mm limit: no waiting for the 0.5 s hold)
        // after 50 samples of 8 steps.
        assert_eq!(sample, 51);
    }

    #[test]
    fn an_encoder_that_stops_answering_stops_the_job_after_five_failed_reads() {
        let mut loops = prusa();
        switch_on(&mut loops, Strategy::RobustPid { gamma_milli: 500 });
        loops.tick([0, 0], [raw_at(0), raw_at(0)], [0, 0]);
        for _ in 0..4 {
            loops.tick([0, 0], [Reading::Failed, raw_at(0)], [0, 0]);
            assert_eq!(loops.take_fault(), None);
        }
        loops.tick([0, 0], [Reading::Failed, raw_at(0)], [0, 0]);
        assert_eq!(loops.take_fault(), Some((b'X', AxisFault::Encoder(super::super::EncoderFault::NoReading))));
        // Posted once: the latched fault does not come back every sample.
        loops.tick([0, 0], [Reading::Failed, raw_at(0)], [0, 0]);
        assert_eq!(loops.take_fault(), None);
        // Re-homed with the chip answering again: running, no fault.
        loops.rehome([0, 0]);
        loops.tick([0, 0], [raw_at(0), raw_at(0)], [0, 0]);
        assert_eq!(loops.take_fault(), None);
        assert_eq!(loops.report(0).fault, None);
    }

    #[test]
    fn rehoming_clears_a_fault_and_takes_the_step_position_as_the_encoders_zero() {
        let mut loops = prusa();
        switch_on(&mut loops, Strategy::OpenLoop);
        loops.tick([0, 0], [raw_at(0), raw_at(0)], [0, 0]);
        loops.tick([500, 0], [raw_at(0), raw_at(0)], [0, 0]);
        assert!(loops.take_fault().is_some());
        loops.rehome([500, 7]);
        assert_eq!(loops.report(0).fault, None);
        // Whatever the encoder reads now (3000) is the new zero at 500
        // steps; 10 steps on (204.8 units) it reads 205 counts further.
        loops.tick([500, 7], [raw_at(3000), raw_at(0)], [0, 0]);
        loops.tick([510, 7], [raw_at(3205), raw_at(0)], [0, 0]);
        assert_eq!(loops.take_fault(), None);
        let report = loops.report(0);
        assert_eq!((report.reference, report.measured), (205, 205));
    }

    #[test]
    fn a_new_steps_per_mm_rescales_the_reference_and_keeps_the_strategy() {
        let mut loops = prusa();
        switch_on(&mut loops, Strategy::PFeedforward { kp_milli: 4300 });
        loops.tick([0, 0], [raw_at(0), raw_at(0)], [0, 0]);
        // M92 X80: 25.6 counts a step; re-zeroed at 1000 steps.
        assert!(loops.set_steps_per_mm(0, 80.0, 1000));
        loops.tick([1000, 0], [raw_at(77), raw_at(0)], [0, 0]);
        loops.tick([1010, 0], [raw_at(77 + 256), raw_at(0)], [0, 0]);
        let report = loops.report(0);
        assert_eq!((report.reference, report.measured, report.fault), (256, 256, None));
        // 2 mm behind: P at 4.3/s asks 8.6 mm/s = 688 steps/s at 80 steps/mm.
        for steps in (1010..=1170).step_by(20) {
            loops.tick([steps, 0], [raw_at(77 + 256 + (steps / 20) % 2), raw_at(0)], [0, 0]);
        }
        let emitted: u32 = (0..100).map(|_| u32::from(loops.emit().0 & 1)).sum();
        assert_eq!(emitted, 68);
        assert!(!loops.set_steps_per_mm(0, 0.0, 0));
    }

    #[test]
    fn the_correction_rate_is_capped_at_one_step_per_millisecond() {
        let mut loops = prusa();
        switch_on(&mut loops, Strategy::PFeedforward { kp_milli: 4300 });
        loops.tick([0, 0], [raw_at(0), raw_at(0)], [0, 0]);
        // X commanded 1.5 mm on while the carriage stays (0.25 mm a sample:
        // a read never strays more than 0.5 mm from the prediction)...
        // (A count of noise: a bit-identical sensor would be "stuck".)
        for steps in (25..=150).step_by(25) {
            loops.tick([steps, 0], [raw_at(steps % 2), raw_at(0)], [0, 0]);
        }
        // ... Kp·e = 6.45 mm/s: 645 steps/s.
        let emitted: u32 = (0..100).map(|_| u32::from(loops.emit().0 & 1)).sum();
        assert_eq!(emitted, 64);
        // 3 mm behind: 12.9 mm/s, capped at 10 (1000 steps/s).
        for steps in (175..=300).step_by(25) {
            loops.tick([steps, 0], [raw_at(steps % 2), raw_at(0)], [0, 0]);
        }
        let emitted: u32 = (0..100).map(|_| u32::from(loops.emit().0 & 1)).sum();
        assert_eq!(emitted, 100);
    }

    #[test]
    fn the_settings_gains_have_no_feedforward_and_keep_the_strategys_feedback() {
        let settings = LoopSettings { enabled: true, strategy: Strategy::PFeedforward { kp_milli: 4300 }, ..LoopSettings::DEFAULT };
        let gains = settings.gains().unwrap();
        let full: LoopGains = Strategy::PFeedforward { kp_milli: 4300 }.loop_gains(0.1, 0.004).unwrap();
        assert_eq!(gains.feedforward, <LoopGains>::OPEN_LOOP.proportional);
        assert_eq!(gains.proportional, full.proportional);
    }
}
