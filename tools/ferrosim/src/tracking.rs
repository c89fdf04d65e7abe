//! The Prusa i3's encoder-closed X and Y (SPEC §1) following a simulated
//! print: `ferrosim simulate FILE --encoders STRATEGY`.
//!
//! The reference is what the firmware commanded: the report's X and Y motor
//! positions ([`Report::xy_steps`]), one sample per loop tick (4 ms at
//! 250 Hz, [`sample_ms`]).
//! Each sample-to-sample chord is one piece of a
//! [`ReferencePath`] with a 0.1 s feedforward preview, exactly as
//! `hal_sim::axis_plant::run_circle` feeds the circle: the planner knows
//! its queued path ahead, which is what the preview stands for. Both axes
//! run the firmware's own [`EncoderAxis`] (NSE-5310 tracker, loop,
//! step-rate scale, built by `hal_sim::axis_plant::printer_axis`) against an
//! [`AxisPlant`] (SPEC §1's k'·e^(−θs)/s with step quantisation, encoder
//! noise and Index glitches, [`PlantConfig::printer_x`] / `printer_y`), one
//! loop tick per reference tick.
//!
//! Frame: the reference is in motor millimetres from power-on (steps /
//! steps per mm), not in the firmware's coordinates: homing and `G92` move
//! the firmware's zero, not the motors, so the reference never jumps. The
//! axes start at rest at the first sample.
//!
//! Homing: a board homes open loop against the switches, then zeroes the
//! encoders there. So while a `G28` runs ([`Report::homing`]) each axis
//! steps at the reference's (previewed) velocity alone, the tracker still
//! reads every tick (to keep unwrapping), and nothing is recorded; at the
//! end both axes are re-homed ([`EncoderAxis::rehome`]): the encoder reads
//! the reference where the carriage stands, the loop forgets its past and
//! an alarm in progress ends. (Run closed, the Prusa's homing seek, 50 mm/s
//! with 1000 mm/s² ramps, costs ≈ 0.5 mm of error with the robust PID.)
//!
//! The reference lags the samples by the preview (a path from rest holds
//! its start for the preview while the feedforward already runs); times
//! here are the samples' times, so tick k is at (k − preview) × period.
//!
//! Alarms: an [`AxisFault`] from an axis' tick is recorded, that tick's step
//! rate is zero, the controller is reset (and a latched encoder fault
//! cleared, keeping the position) and the run goes on, like
//! `CircleOptions { stop_on_fault: false, .. }`. A fault raised again while
//! the axis has not come back within the following-error limit is the same
//! alarm (its `raised` count grows): an open-loop axis 5 mm off raises it
//! on every tick.

use firmware::closed_loop::control::{DriverStatus, FollowingErrorLimit, Reference};
use firmware::closed_loop::nse5310::UNITS_PER_MM;
use firmware::closed_loop::output::StepRate;
use firmware::closed_loop::reference::ReferencePath;
use firmware::closed_loop::{AxisFault, EncoderAxis, EncoderFault, Reading, Strategy};
use hal_sim::axis_plant::{self, AxisPlant, CircleOptions, PlantConfig, SLIP_DURATION_S};
use std::fmt::Write as _;

use crate::simulate::{MachineKind, Report};

/// `--encoders` on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum EncoderStrategy {
    /// Step counting only: u = ẋd (the encoders only watch).
    OpenLoop,
    /// u = ẋd + Kp·e, Kp 4.3 (SPEC §1's best P+FF).
    PFf,
    /// Normey-Rico robust PID, γ 0.5 (SPEC §1's best).
    Pid,
}

impl EncoderStrategy {
    /// The firmware's strategy, with `--kp` (p-ff) or `--gamma` (pid).
    pub fn strategy(self, kp: Option<f64>, gamma: Option<f64>) -> Result<Strategy, String> {
        let milli = |value: f64, name: &str| -> Result<u16, String> {
            let m = (value * 1000.0).round();
            if !(1.0..=65_535.0).contains(&m) {
                return Err(format!("--{name} {value}: out of range"));
            }
            Ok(m as u16)
        };
        let strategy = match self {
            EncoderStrategy::OpenLoop if kp.is_some() || gamma.is_some() => {
                return Err("--kp and --gamma need --encoders p-ff or pid".into())
            }
            EncoderStrategy::OpenLoop => Strategy::OpenLoop,
            EncoderStrategy::PFf if gamma.is_some() => return Err("--gamma is for --encoders pid".into()),
            EncoderStrategy::PFf => Strategy::PFeedforward { kp_milli: milli(kp.unwrap_or(4.3), "kp")? },
            EncoderStrategy::Pid if kp.is_some() => return Err("--kp is for --encoders p-ff".into()),
            EncoderStrategy::Pid => Strategy::RobustPid { gamma_milli: milli(gamma.unwrap_or(0.5), "gamma")? },
        };
        let period = 1.0 / f32::from(CircleOptions::standard().loop_hz);
        strategy
            .loop_gains::<firmware::num::Native>(0.1, period)
            .map_err(|e| format!("{}: {e:?}", axis_plant::strategy_label(strategy)))?;
        Ok(strategy)
    }
}

/// How the axes run.
#[derive(Clone, Debug)]
pub struct EncoderOptions {
    pub strategy: Strategy,
    pub loop_hz: u16,
    /// Plant substeps per loop tick.
    pub substeps: u32,
    /// Feedforward preview, s (0.1: the identified dead time θ).
    pub preview_s: f64,
    /// The X and Y axes: [`PlantConfig::printer_x`] and `printer_y`
    /// (k' 0.90 and 0.94, θ 0.1 s).
    pub plants: [PlantConfig; 2],
    /// Encoder noise and Index glitches as in `plants` (false: none).
    pub noise_and_glitches: bool,
    pub following_error: FollowingErrorLimit,
    /// A belt slip on X: (sample time s, mm), taking [`SLIP_DURATION_S`].
    pub slip_x: Option<(f64, f64)>,
}

impl EncoderOptions {
    /// The circle benchmark's configuration ([`CircleOptions::standard`]):
    /// 250 Hz, 4 plant substeps, 0.1 s preview, noise and glitches on,
    /// 1 mm / 0.5 s following-error limit.
    pub fn standard(strategy: Strategy) -> Self {
        let circle = CircleOptions::standard();
        Self {
            strategy,
            loop_hz: circle.loop_hz,
            substeps: circle.substeps,
            preview_s: 0.1,
            plants: [PlantConfig::printer_x(), PlantConfig::printer_y()],
            noise_and_glitches: circle.noise_and_glitches,
            following_error: circle.following_error,
            slip_x: None,
        }
    }

    fn circle_options(&self) -> CircleOptions {
        CircleOptions {
            loop_hz: self.loop_hz,
            substeps: self.substeps,
            preview: self.preview_s > 0.0,
            noise_and_glitches: self.noise_and_glitches,
            slip_x: self.slip_x,
            stop_on_fault: false,
            following_error: self.following_error,
        }
    }
}

/// The report's sample period for a tracked run: one sample per loop tick.
pub fn sample_ms(loop_hz: u16) -> u32 {
    (1000 / u32::from(loop_hz.max(1))).max(1)
}

/// One alarm: an axis' fault, and how long the axis stayed out of limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alarm {
    /// Sample time when it was first raised, s.
    pub time_s: f64,
    pub axis: char,
    pub fault: AxisFault,
    /// When the axis was back within the following-error limit (None: not
    /// by the end of the run).
    pub end_s: Option<f64>,
    /// Times the controller raised a fault in this alarm (after each
    /// raise it is reset and runs again).
    pub raised: u32,
}

/// What the tracked run found.
#[derive(Clone, Debug)]
pub struct Tracking {
    pub strategy: Strategy,
    pub loop_hz: u16,
    pub preview_s: f64,
    pub noise_and_glitches: bool,
    /// Per tick: sample time (s) and X, Y error (reference − encoder
    /// reading, mm), from the moment the reference starts.
    pub errors: Vec<(f64, [f32; 2])>,
    /// Mean of error² over the ticks from the first to the last tick the
    /// reference moved, mm² (X, Y).
    pub mse_mm2: [f64; 2],
    /// Largest |error| (mm) and its time (s), X and Y, over the whole run.
    pub max_error: [(f64, f64); 2],
    /// The same against the true carriage position (the encoder's noise
    /// and quantisation left out), mm.
    pub max_true_error_mm: [f64; 2],
    /// Index edges the X and Y trackers rejected as glitches (saturates at
    /// 65 535 per axis, ≈ 9 print hours at 2 glitches/s).
    pub index_glitches_rejected: [u32; 2],
    pub alarms: Vec<Alarm>,
    /// Ticks from the first to the last reference move.
    pub moving_ticks: usize,
    /// Sample times of the first and the last reference move, s.
    pub moving_s: Option<(f64, f64)>,
    /// Wall-clock seconds the tracking took.
    pub wall_s: f64,
}

fn units(mm: f64) -> i32 {
    (mm * f64::from(UNITS_PER_MM)).round() as i32
}

fn mm(units: i32) -> f64 {
    f64::from(units) / f64::from(UNITS_PER_MM)
}

/// Run the X and Y axes of a Prusa report closed loop.
pub fn track(report: &Report, options: &EncoderOptions) -> Result<Tracking, String> {
    if report.machine != MachineKind::Prusa {
        return Err(format!(
            "--encoders: only the Prusa i3 (SPEC §1) has encoder-closed axes (NSE-5310 on X and Y); not the {:?}",
            report.machine
        ));
    }
    let started = std::time::Instant::now();
    let loop_hz = options.loop_hz;
    let period = 1.0 / f64::from(loop_hz);
    // The gains must fit the tick (printer_axis would panic otherwise).
    options
        .strategy
        .loop_gains::<firmware::num::Native>(0.1, period as f32)
        .map_err(|e| format!("{}: {e:?}", axis_plant::strategy_label(options.strategy)))?;
    let circle = options.circle_options();
    let substep = period / f64::from(options.substeps.max(1));
    // Reference pieces: each sample-to-sample chord, in encoder units.
    let to_units = |steps: &[i64; 2]| [0, 1].map(|m| units(steps[m] as f64 / report.steps_per_unit[m]));
    let Some(&(first_s, first_steps)) = report.xy_steps.first() else {
        return Err("no X/Y samples: simulate with Options::xy_sample_ms = Some(tracking::sample_ms(loop_hz))".into());
    };
    let start = to_units(&first_steps);
    let mut pieces: Vec<([i32; 2], u16)> = Vec::with_capacity(report.xy_steps.len());
    let mut last_tick = (first_s / period).round() as i64;
    for (time_s, steps) in &report.xy_steps[1..] {
        let tick = (time_s / period).round() as i64;
        let end = to_units(steps);
        let ticks = tick - last_tick;
        if ticks <= 0 {
            // Same tick (the report's final sample): move the last piece's end.
            if let Some(last) = pieces.last_mut() {
                last.0 = end;
            }
            continue;
        }
        let mut left = ticks;
        while left > 0 {
            let now = left.min(i64::from(u16::MAX));
            left -= now;
            pieces.push((end, now as u16));
        }
        last_tick = tick;
    }

    let [mut px, mut py] = options.plants.clone();
    if !options.noise_and_glitches {
        px = px.clean();
        py = py.clean();
    }
    let mut plants = [AxisPlant::new(px, mm(start[0]), substep), AxisPlant::new(py, mm(start[1]), substep)];
    let mut axes: [EncoderAxis; 2] =
        [axis_plant::printer_axis(options.strategy, &circle), axis_plant::printer_axis(options.strategy, &circle)];
    for (axis, (plant, &position)) in axes.iter_mut().zip(plants.iter_mut().zip(start.iter())) {
        axis.tracker.update(plant.read_raw(), 0, position).map_err(|e| format!("first read: {e:?}"))?;
        plant.take_index_edges();
        axis.rehome(position);
    }
    let preview_ticks = (options.preview_s * f64::from(loop_hz)).round() as u16;
    let mut path = ReferencePath::<2, 64>::new(start, loop_hz, preview_ticks);
    // Then 2 s at rest, like run_circle: the end of the last move settles.
    let settle_ticks = 2 * usize::from(loop_hz);

    let mut tracking = Tracking {
        strategy: options.strategy,
        loop_hz,
        preview_s: f64::from(preview_ticks) / f64::from(loop_hz),
        noise_and_glitches: options.noise_and_glitches,
        errors: Vec::with_capacity(pieces.len() + settle_ticks + 1),
        mse_mm2: [0.0; 2],
        max_error: [(0.0, 0.0); 2],
        max_true_error_mm: [0.0; 2],
        index_glitches_rejected: [0; 2],
        alarms: Vec::new(),
        moving_ticks: 0,
        moving_s: None,
        wall_s: 0.0,
    };
    // Alarm in progress per axis: index into `tracking.alarms`.
    let mut open: [Option<usize>; 2] = [None; 2];
    let mut next_piece = 0;
    let mut slip_done = options.slip_x.is_none();
    let mut tick: i64 = 0;
    let mut settled = 0;
    let mut previous_reference: Option<[i32; 2]> = None;
    // The MSE window: from the first to the last tick the reference moved.
    let mut first_move: Option<usize> = None;
    let mut last_move = 0usize;
    let limit = options.following_error.limit.unsigned_abs();
    let mut homing = report.homing.iter().copied().peekable();
    let mut was_homing = false;
    loop {
        // Main loop: keep the queue full (the planner's look-ahead).
        while next_piece < pieces.len() && path.free_slots() > 0 {
            let (end, ticks) = pieces[next_piece];
            path.push(end, ticks).map_err(|e| format!("reference piece {next_piece}: {e:?}"))?;
            next_piece += 1;
        }
        let started = tick >= i64::from(preview_ticks);
        if started && next_piece == pieces.len() && path.is_idle() {
            if settled >= settle_ticks {
                break;
            }
            settled += 1;
        }
        let time_s = first_s + (tick - i64::from(preview_ticks)) as f64 * period;
        if !slip_done {
            if let Some((at_s, slip_mm)) = options.slip_x {
                if time_s >= at_s {
                    plants[0].slip(slip_mm, SLIP_DURATION_S);
                    slip_done = true;
                }
            }
        }
        while homing.peek().is_some_and(|&(_, end)| time_s >= end) {
            homing.next();
        }
        let homing_now = homing.peek().is_some_and(|&(start, _)| time_s >= start);
        // Board tick.
        let references: [Reference; 2] = path.advance();
        if homing_now {
            // Open loop against the switches; keep the trackers unwrapping.
            for (index, (axis, plant)) in axes.iter_mut().zip(plants.iter_mut()).enumerate() {
                let (raw, edges) = (plant.read_raw(), plant.take_index_edges());
                let _ = axis.tracker.update(raw, edges, references[index].position);
                plant.set_step_rate(axis.scale.step_rate(references[index].velocity));
            }
            for plant in plants.iter_mut() {
                plant.advance(period);
            }
            was_homing = true;
            tick += 1;
            continue;
        }
        if was_homing {
            // Homed: the encoders read the reference here.
            for (index, axis) in axes.iter_mut().enumerate() {
                axis.rehome(references[index].position);
                if let Some(alarm) = open[index].take() {
                    tracking.alarms[alarm].end_s = Some(time_s);
                }
            }
            was_homing = false;
        }
        let mut errors = [0.0f32; 2];
        for (index, (axis, plant)) in axes.iter_mut().zip(plants.iter_mut()).enumerate() {
            let raw = plant.read_raw();
            let edges = plant.take_index_edges();
            let result = axis.tick(references[index], Reading::Raw(raw), edges, DriverStatus::default());
            let error_units = references[index].position.saturating_sub(axis.measured());
            let rate = match result {
                Ok(rate) => {
                    if error_units.unsigned_abs() <= limit {
                        if let Some(alarm) = open[index].take() {
                            tracking.alarms[alarm].end_s = Some(time_s.max(0.0));
                        }
                    }
                    rate
                }
                Err(fault) => {
                    match open[index] {
                        Some(alarm) => tracking.alarms[alarm].raised += 1,
                        None => {
                            open[index] = Some(tracking.alarms.len());
                            tracking.alarms.push(Alarm {
                                time_s: time_s.max(0.0),
                                axis: if index == 0 { 'X' } else { 'Y' },
                                fault,
                                end_s: None,
                                raised: 1,
                            });
                        }
                    }
                    if let AxisFault::Encoder(EncoderFault::Stuck | EncoderFault::NoReading) = fault {
                        // Clear the tracker's latch, keeping its position.
                        let position = axis.tracker.position();
                        axis.tracker.set_position(position, references[index].position);
                    }
                    axis.controller.reset();
                    StepRate(0)
                }
            };
            plant.set_step_rate(rate);
            if started {
                let reference_mm = mm(references[index].position);
                let error_mm = mm(error_units);
                errors[index] = error_mm as f32;
                if error_mm.abs() > tracking.max_error[index].0 {
                    tracking.max_error[index] = (error_mm.abs(), time_s);
                }
                let true_error = (reference_mm - plant.carriage_mm()).abs();
                tracking.max_true_error_mm[index] = tracking.max_true_error_mm[index].max(true_error);
            }
        }
        if started {
            let position = [references[0].position, references[1].position];
            if previous_reference.is_some_and(|p| p != position) {
                let n = tracking.errors.len();
                first_move.get_or_insert(n);
                last_move = n;
            }
            previous_reference = Some(position);
            tracking.errors.push((time_s, errors));
        }
        for plant in plants.iter_mut() {
            plant.advance(period);
        }
        tick += 1;
    }
    if let Some(first_move) = first_move {
        let moving = &tracking.errors[first_move..=last_move];
        tracking.moving_ticks = moving.len();
        tracking.moving_s = Some((moving[0].0, moving[moving.len() - 1].0));
        tracking.mse_mm2 =
            [0, 1].map(|i| moving.iter().map(|(_, e)| f64::from(e[i]).powi(2)).sum::<f64>() / moving.len() as f64);
    }
    tracking.index_glitches_rejected = [0, 1].map(|i| u32::from(axes[i].tracker.counters().index_glitches));
    tracking.wall_s = started.elapsed().as_secs_f64();
    Ok(tracking)
}

/// `FollowingError { error: 2100 }` → "following error 1.025 mm".
pub fn describe(fault: AxisFault) -> String {
    match fault {
        AxisFault::FollowingError { error } => format!("following error {:.3} mm", mm(error)),
        AxisFault::DriverAlarm => "driver ALARM".into(),
        AxisFault::BridgeFault => "motor bridge fault".into(),
        AxisFault::Encoder(EncoderFault::Stuck) => "encoder stuck".into(),
        AxisFault::Encoder(EncoderFault::NoReading) => "encoder not responding".into(),
        AxisFault::Stopped => "stopped".into(),
    }
}

impl Tracking {
    /// The lines `simulate --encoders` prints.
    pub fn summary(&self) -> String {
        let mut text = String::new();
        let _ = writeln!(
            text,
            "encoders: {} on X and Y (NSE-5310), {} Hz loop, {:.2} s preview, noise and glitches {}",
            axis_plant::strategy_label(self.strategy),
            self.loop_hz,
            self.preview_s,
            if self.noise_and_glitches { "on" } else { "off" }
        );
        for (i, axis) in ['X', 'Y'].into_iter().enumerate() {
            let _ = writeln!(
                text,
                "tracking {axis}: MSE {:.6} mm² while moving ({:.1} s), max |error| {:.4} mm at {:.3} s (true position {:.4} mm)",
                self.mse_mm2[i],
                self.moving_ticks as f64 / f64::from(self.loop_hz),
                self.max_error[i].0,
                self.max_error[i].1,
                self.max_true_error_mm[i]
            );
        }
        let _ = writeln!(
            text,
            "index glitches rejected: {} (X {}, Y {})",
            self.index_glitches_rejected[0] + self.index_glitches_rejected[1],
            self.index_glitches_rejected[0],
            self.index_glitches_rejected[1]
        );
        if self.alarms.is_empty() {
            let _ = writeln!(text, "alarms: no alarm");
        } else {
            let shown = self.alarms.len().min(20);
            let _ = writeln!(
                text,
                "alarms: {}{}",
                self.alarms.len(),
                if shown < self.alarms.len() { format!(" (the first {shown})") } else { String::new() }
            );
            for alarm in &self.alarms[..shown] {
                let until = match alarm.end_s {
                    Some(end) => format!("back within the limit after {:.3} s", end - alarm.time_s),
                    None => "never back within the limit".into(),
                };
                let _ = writeln!(
                    text,
                    "  {:>10.3} s {}: {}, {until}, raised {} time{}",
                    alarm.time_s,
                    alarm.axis,
                    describe(alarm.fault),
                    alarm.raised,
                    if alarm.raised == 1 { "" } else { "s" }
                );
            }
        }
        let _ = writeln!(text, "tracked in {:.2} s", self.wall_s);
        text
    }

    /// X and Y error over time, mm, from 1 s before the first reference
    /// move (a print heats for minutes at rest first) to the end.
    pub fn error_series(&self) -> [Vec<(f64, f64)>; 2] {
        let from = self.moving_s.map_or(f64::MIN, |(first, _)| first - 1.0);
        [0, 1].map(|i| self.errors.iter().filter(|(t, _)| *t >= from).map(|(t, e)| (*t, f64::from(e[i]))).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_line_strategies_are_spec_s_best_gains_unless_overridden() {
        assert_eq!(EncoderStrategy::OpenLoop.strategy(None, None), Ok(Strategy::OpenLoop));
        assert_eq!(EncoderStrategy::PFf.strategy(None, None), Ok(Strategy::PFeedforward { kp_milli: 4300 }));
        assert_eq!(EncoderStrategy::Pid.strategy(None, None), Ok(Strategy::RobustPid { gamma_milli: 500 }));
        assert_eq!(EncoderStrategy::PFf.strategy(Some(3.0), None), Ok(Strategy::PFeedforward { kp_milli: 3000 }));
        assert_eq!(EncoderStrategy::Pid.strategy(None, Some(0.75)), Ok(Strategy::RobustPid { gamma_milli: 750 }));
    }

    #[test]
    fn out_of_range_or_misplaced_gains_are_refused() {
        // Normey-Rico's γ is in (0, 0.75].
        assert!(EncoderStrategy::Pid.strategy(None, Some(0.8)).unwrap_err().contains("GammaOutOfRange"));
        assert!(EncoderStrategy::Pid.strategy(Some(4.0), None).is_err());
        assert!(EncoderStrategy::PFf.strategy(None, Some(0.5)).is_err());
        assert!(EncoderStrategy::OpenLoop.strategy(Some(1.0), None).is_err());
        assert!(EncoderStrategy::PFf.strategy(Some(-1.0), None).is_err());
    }

    #[test]
    fn faults_read_in_millimetres() {
        assert_eq!(describe(AxisFault::FollowingError { error: -3073 }), "following error -1.500 mm");
        assert_eq!(describe(AxisFault::Encoder(EncoderFault::Stuck)), "encoder stuck");
    }
}
