//! End-to-end tests of the motion core on virtual time: the main loop
//! (`Motion::poll`) and the step interrupt (`StepGenerator::on_timer`)
//! interleaved as on the board, every pulse recorded by hal-sim's
//! `StepRecorder`.

use super::*;
use hal_sim::steps::StepRecorder;
use std::boxed::Box;
use std::collections::VecDeque;
use std::vec::Vec;

/// The main loop comes round every 0.5 ms of virtual time.
const MAIN_LOOP_TICKS: u64 = 1000;

#[derive(Clone, Copy, Debug)]
enum Command {
    Line([f32; 4], f32),
    Arc([f32; 4], ArcCentre, bool, f32),
    Home(u8),
}

/// Simulated switches: motor positions (steps) → triggered endstop bits.
type Endstops = Box<dyn Fn(&[i64; 4]) -> u8>;

struct Rig {
    motion: Motion<'static>,
    generator: StepGenerator<'static>,
    recorder: StepRecorder,
    commands: VecDeque<Command>,
    next_main: u64,
    /// Endstops as a function of the motor positions (steps).
    endstops: Endstops,
    errors: Vec<MotionError>,
    /// Entry speed of the block after the one being prepared, mm/s.
    planner_samples: Vec<f32>,
}

fn um(mm: f32) -> i32 {
    (mm * 1000.0).round() as i32
}

impl Rig {
    fn new(config: MotionConfig) -> Self {
        let queues: &'static mut StepQueues = Box::leak(Box::new(StepQueues::new()));
        let (feeder, generator) = queues.split(config.stepper());
        let recorder = StepRecorder::new(stepper::TIMER_HZ, config.stepper.dir_invert);
        Self {
            motion: Motion::new(config, feeder),
            generator,
            recorder,
            commands: VecDeque::new(),
            next_main: 0,
            endstops: Box::new(|_| 0),
            errors: Vec::new(),
            planner_samples: Vec::new(),
        }
    }

    fn line(&mut self, target: [f32; 4], feed_mm_s: f32) -> &mut Self {
        self.commands.push_back(Command::Line(target, feed_mm_s));
        self
    }

    fn now_ms(&self) -> u32 {
        (self.recorder.now / 2000) as u32
    }

    fn main_loop(&mut self) {
        // The executor: hand over commands while motion accepts them.
        while let Some(command) = self.commands.front().copied() {
            if !self.motion.ready() {
                break;
            }
            let result = match command {
                Command::Line(target, feed) => self.motion.line_to(&target.map(um), um(feed)),
                Command::Arc(target, centre, clockwise, feed) => self.motion.arc_to(crate::motion::Plane::Xy, &target.map(um), centre, clockwise, um(feed)),
                Command::Home(mask) => self.motion.home(mask),
            };
            self.commands.pop_front();
            if let Err(error) = result {
                self.errors.push(error);
            }
        }
        let status = self.generator.status();
        match self.motion.poll(&status, self.now_ms()) {
            StepperRequest::None => {}
            StepperRequest::ClearFault => self.generator.clear_fault(),
            StepperRequest::Halt => self.generator.halt(StepFault::Stopped),
            StepperRequest::Configure(config) => self.generator.set_config(config),
        }
        if let Some(error) = self.motion.take_error() {
            self.errors.push(error);
        }
        // While the host still has lines to send, the block after the one
        // being stepped out should be entered at full speed.
        if !self.commands.is_empty() {
            if let Some(next) = self.motion.planner().blocks().nth(1) {
                // Past the first acceleration (≈ 67 ms).
                if self.recorder.now > 300_000 {
                    self.planner_samples.push(sqrt(next.entry.mm2_s2()));
                }
            }
        }
    }

    /// Run until every command has been executed and the machine is idle.
    fn run(&mut self, max_seconds: f64) -> &mut Self {
        let limit = self.recorder.now + (max_seconds * stepper::TIMER_HZ as f64) as u64;
        loop {
            if self.recorder.now >= self.next_main {
                self.main_loop();
                self.next_main += MAIN_LOOP_TICKS;
                if self.commands.is_empty() && self.motion.is_idle() && !self.generator.status().busy {
                    return self;
                }
            }
            while self.recorder.now < self.next_main {
                if self.generator.endstop_mask() != 0 {
                    let triggered = (self.endstops)(&self.recorder.positions());
                    self.generator.on_endstops(triggered);
                }
                let action = self.generator.on_timer();
                self.recorder.record(action.step_mask, action.dir_mask, action.next_interval_ticks);
            }
            assert!(self.recorder.now < limit, "still moving after {max_seconds} s");
        }
    }

    fn seconds(&self, ticks: u64) -> f64 {
        self.recorder.seconds(ticks)
    }

    /// Position of a motor at a time (steps), from the recorded pulses.
    fn position_at(&self, motor: usize, ticks: u64) -> i64 {
        let steps = &self.recorder.motors[motor].steps;
        let count = steps.partition_point(|s| s.0 <= ticks);
        steps[..count].iter().map(|s| s.1 as i64).sum()
    }
}

fn cartesian() -> MotionConfig {
    let mut config = MotionConfig::prusa_i3();
    config.soft_limits = None;
    config.stepper.dir_invert = 0;
    config
}

#[test]
fn g1_x10_is_exactly_1000_steps() {
    let mut rig = Rig::new(cartesian());
    rig.line([10.0, 0.0, 0.0, 0.0], 50.0).run(5.0);
    assert_eq!(rig.recorder.positions(), [1000, 0, 0, 0]);
    assert_eq!(rig.recorder.motors[0].steps.len(), 1000);
    assert_eq!(rig.recorder.setup_violations, 0);
    assert_eq!(rig.motion.motor_steps(), [1000, 0, 0, 0]);
    assert_eq!(rig.motion.position_um(), [10_000, 0, 0, 0]);
    assert!(rig.errors.is_empty());
    // And back, with a reversal.
    rig.recorder.clear_steps();
    rig.line([0.0, 0.0, 0.0, 0.0], 50.0).run(5.0);
    assert_eq!(rig.recorder.positions(), [0, 0, 0, 0]);
    assert_eq!(rig.recorder.setup_violations, 0);
}

#[test]
fn y_motor_is_inverted_on_the_prusa_so_plus_y_is_the_nozzles_plus_y() {
    let mut config = MotionConfig::prusa_i3();
    config.soft_limits = None;
    let mut rig = Rig::new(config);
    rig.line([0.0, 5.0, 0.0, 0.0], 50.0).run(5.0);
    // The recorder knows the inversion: logically +500 steps...
    assert_eq!(rig.recorder.positions(), [0, 500, 0, 0]);
    // ...while the Y direction pin is held low (bit clear).
    let action = rig.generator.on_timer();
    assert_eq!(action.dir_mask & 0b10, 0);
}

#[test]
fn diagonal_axes_end_on_the_same_tick() {
    for (x, y) in [(10.0, 10.0), (10.0, 7.0), (3.33, 10.0), (-4.0, 9.99)] {
        let mut rig = Rig::new(cartesian());
        rig.motion.set_position_mm([20.0, 20.0, 0.0, 0.0]);
        rig.line([20.0 + x, 20.0 + y, 0.0, 0.0], 80.0).run(5.0);
        let expected = [(x * 100.0_f32).round() as i64, (y * 100.0_f32).round() as i64];
        assert_eq!(&rig.recorder.positions()[..2], &expected, "{x},{y}");
        let motors = &rig.recorder.motors;
        assert_eq!(motors[0].last_step(), motors[1].last_step(), "{x},{y}: last steps apart");
        // The dominant axis starts the move.
        let dominant = if x.abs() >= y.abs() { 0 } else { 1 };
        assert!(motors[dominant].first_step() <= motors[1 - dominant].first_step());
    }
}

/// G1 X100 at 100 mm/s, 1500 mm/s²: 66.7 ms to reach speed over 3.33 mm,
/// 933 ms of cruise, 66.7 ms to stop.
#[test]
fn trapezoid_timing_matches_the_analytic_profile() {
    let mut rig = Rig::new(cartesian());
    rig.line([100.0, 0.0, 0.0, 0.0], 100.0).run(5.0);
    let x = &rig.recorder.motors[0];
    assert_eq!(x.steps.len(), 10_000);
    let start = x.first_step().unwrap();
    let time_of = |step: usize| rig.seconds(x.steps[step - 1].0 - start);
    let accel_time = 100.0 / 1500.0;
    let accel_steps = (100.0 * 100.0 / (2.0 * 1500.0) * 100.0) as usize; // 333
    let within = |got: f64, want: f64| (got - want).abs() <= 0.1 * want;
    // The first step comes √(2/A) after the start, so measure from 0.
    let t_accel = time_of(accel_steps) + (2.0 / 150_000.0_f64).sqrt();
    assert!(within(t_accel, accel_time), "acceleration took {t_accel} s");
    let t_cruise = time_of(10_000 - accel_steps) - time_of(accel_steps);
    assert!(within(t_cruise, 93.333 / 100.0), "cruise took {t_cruise} s");
    let t_decel = time_of(10_000) - time_of(10_000 - accel_steps);
    assert!(within(t_decel, accel_time), "deceleration took {t_decel} s");
    let total = time_of(10_000) + (2.0 / 150_000.0_f64).sqrt();
    assert!((total - (1.0 + accel_time)).abs() < 0.01 * (1.0 + accel_time), "total {total} s");
    // Cruise at 100 mm/s = 10 000 steps/s: every interval 200 ticks.
    let cruise_intervals: Vec<u64> = x.steps[accel_steps + 20..10_000 - accel_steps - 20].windows(2).map(|w| w[1].0 - w[0].0).collect();
    assert!(cruise_intervals.iter().all(|&i| i == 200), "cruise intervals vary");
    // Acceleration measured over 2 ms windows stays within 10 % of 1500.
    let speeds = x.speeds(20, 2e6, 100_000);
    for pair in speeds.windows(2) {
        let accel = (pair[1].1 - pair[0].1) / (pair[1].0 - pair[0].0) / 100.0;
        assert!(accel.abs() <= 1500.0 * 1.1, "measured {accel} mm/s² at {} s", pair[0].0);
    }
}

#[test]
fn short_move_is_a_triangle() {
    let mut rig = Rig::new(cartesian());
    // 1 mm at 100 mm/s and 1500 mm/s²: peaks at √(1500) = 38.7 mm/s, 51.6 ms.
    rig.line([1.0, 0.0, 0.0, 0.0], 100.0).run(5.0);
    let x = &rig.recorder.motors[0];
    assert_eq!(x.steps.len(), 100);
    let duration = rig.seconds(x.last_step().unwrap()) - rig.seconds(x.first_step().unwrap()) + (2.0 / 150_000.0_f64).sqrt();
    let analytic = 2.0 * (1.0_f64 / 1500.0).sqrt() * 1.0;
    assert!((duration - analytic).abs() < 0.05 * analytic, "{duration} vs {analytic}");
    let fastest = x.min_interval().unwrap() as f64;
    let peak = 2e6 / fastest / 100.0;
    assert!((peak - 38.73).abs() < 0.1 * 38.73, "peak {peak} mm/s");
}

/// A 90° corner between two long moves is taken at the junction-deviation
/// speed √(a·δ·s/(1 − s)), s = sin 45°: 6.86 mm/s at 1500 mm/s², 0.013 mm.
#[test]
fn corner_keeps_the_junction_deviation_speed() {
    let mut rig = Rig::new(cartesian());
    rig.line([20.0, 0.0, 0.0, 0.0], 100.0).line([20.0, 20.0, 0.0, 0.0], 100.0).run(5.0);
    let s = core::f64::consts::FRAC_1_SQRT_2;
    let junction = (1500.0 * 0.013 * s / (1.0 - s)).sqrt();
    // The last X step covers 0.01 mm decelerating to the junction speed:
    // from v₁ = √(v_j² + 2·a·0.01) at the mean of the two speeds.
    let v1 = (junction * junction + 2.0 * 1500.0 * 0.01).sqrt();
    let expected_last = 0.01 / ((v1 + junction) / 2.0);
    let x = &rig.recorder.motors[0];
    let n = x.steps.len();
    let last = rig.seconds(x.steps[n - 1].0 - x.steps[n - 2].0);
    assert!((last - expected_last).abs() < 0.1 * expected_last, "last X interval {last} s, want {expected_last}");
    // Y starts right after X's last step, at the junction speed.
    let y = &rig.recorder.motors[1];
    let gap = rig.seconds(y.steps[0].0 - x.steps[n - 1].0);
    let v2 = (junction * junction + 2.0 * 1500.0 * 0.01).sqrt();
    let expected_first = 0.01 / ((v2 + junction) / 2.0);
    assert!((gap - expected_first).abs() < 0.1 * expected_first, "first Y step after {gap} s, want {expected_first}");
    assert_eq!(rig.recorder.positions(), [2000, 2000, 0, 0]);
}

/// Per-axis acceleration limits: with M201 X200 a diagonal move accelerates
/// X at ≤ 200 mm/s², measured from the pulse times.
#[test]
fn planner_never_exceeds_an_axis_acceleration() {
    let mut config = cartesian();
    config.max_accel[0] = 200.0;
    let mut rig = Rig::new(config);
    rig.motion.set_position_mm([50.0, 50.0, 0.0, 0.0]);
    // A zig-zag: colinear and angled moves at several speeds.
    rig.line([80.0, 60.0, 0.0, 0.0], 120.0)
        .line([100.0, 60.0, 0.0, 0.0], 60.0)
        .line([60.0, 40.0, 0.0, 0.0], 150.0)
        .line([61.0, 45.0, 0.0, 0.0], 150.0)
        .line([90.0, 45.0, 0.0, 0.0], 200.0)
        .run(20.0);
    assert_eq!(rig.recorder.positions(), [4000, -500, 0, 0]);
    for (motor, limit) in [(0, 200.0), (1, 1500.0)] {
        let speeds = rig.recorder.motors[motor].speeds(40, 2e6, 40_000);
        let mut worst: f64 = 0.0;
        for pair in speeds.windows(2) {
            // Skip windows that straddle a corner: junction deviation allows
            // a bounded step change in each axis' speed there.
            if pair[1].0 - pair[0].0 > 0.05 {
                continue;
            }
            let accel = ((pair[1].1 - pair[0].1) / (pair[1].0 - pair[0].0) / 100.0).abs();
            worst = worst.max(accel);
        }
        assert!(worst <= limit * 1.15 + 60.0, "motor {motor}: {worst} mm/s² (limit {limit})");
    }
}

/// Gentle curves at full speed: a 1000-sided polygon of 0.5 mm sides at
/// 100 mm/s must not stall nor slow down.
#[test]
fn circle_of_half_millimetre_segments_keeps_full_speed() {
    let mut rig = Rig::new(cartesian());
    let sides = 1000;
    let radius = 0.5 / (2.0 * (core::f32::consts::PI / sides as f32).sin());
    let centre = [100.0, 100.0];
    rig.motion.set_position_mm([centre[0] + radius, centre[1], 0.0, 0.0]);
    for i in 1..=sides {
        let angle = 2.0 * core::f32::consts::PI * i as f32 / sides as f32;
        let (s, c) = math::sin_cos(angle);
        rig.line([centre[0] + radius * c, centre[1] + radius * s, 0.0, 0.0], 100.0);
    }
    let start_steps = rig.motion.motor_steps();
    rig.run(20.0);
    assert!(rig.errors.is_empty(), "{:?}", rig.errors);
    assert_eq!(rig.generator.status().underruns, 0);
    // Closed polygon: back where it started, to the step.
    assert_eq!(rig.motion.motor_steps(), start_steps);
    assert_eq!(rig.recorder.positions(), [0, 0, 0, 0]);
    // 500 mm at 100 mm/s plus one ramp: ≈ 5.07 s.
    let start = rig.recorder.motors[0].first_step().unwrap().min(rig.recorder.motors[1].first_step().unwrap());
    let end = rig.recorder.motors[0].last_step().unwrap().max(rig.recorder.motors[1].last_step().unwrap());
    let total = rig.seconds(end - start);
    assert!(total < 5.0 + 0.0667 + 0.05, "took {total} s");
    // Path speed sampled every 10 ms stays at 100 mm/s (± 3 %) between the
    // ramps.
    let sample = 20_000;
    let mut t = start + 10 * sample;
    while t + sample < end - 10 * sample {
        let dx = (rig.position_at(0, t + sample) - rig.position_at(0, t)) as f64 / 100.0;
        let dy = (rig.position_at(1, t + sample) - rig.position_at(1, t)) as f64 / 100.0;
        let speed = (dx * dx + dy * dy).sqrt() / 0.01;
        assert!((speed - 100.0).abs() < 3.0, "path speed {speed} mm/s at {} s", rig.seconds(t));
        t += sample;
    }
    // The planner always saw its blocks entered at full speed.
    let slowest = rig.planner_samples.iter().copied().fold(f32::MAX, f32::min);
    assert!(slowest > 99.0, "slowest planned junction {slowest} mm/s");
}

/// The shortest slicer segments: 0.2 mm at 100 mm/s along a gentle curve
/// still cruise (the 23-block look-ahead holds 4.6 mm > the 3.3 mm needed
/// to stop from 100 mm/s).
#[test]
fn stream_of_fifth_millimetre_segments_keeps_full_speed() {
    let mut rig = Rig::new(cartesian());
    let radius = 60.0_f32;
    let step = 0.2 / radius;
    rig.motion.set_position_mm([100.0 + radius, 100.0, 0.0, 0.0]);
    for i in 1..=1500 {
        let (s, c) = math::sin_cos(step * i as f32);
        rig.line([100.0 + radius * c, 100.0 + radius * s, 0.0, 0.0], 100.0);
    }
    rig.run(20.0);
    assert_eq!(rig.generator.status().underruns, 0);
    let slowest = rig.planner_samples.iter().copied().fold(f32::MAX, f32::min);
    assert!(slowest > 99.0, "slowest planned junction {slowest} mm/s");
    let start = rig.recorder.motors[1].first_step().unwrap();
    let end = rig.recorder.motors[1].last_step().unwrap();
    assert!(rig.seconds(end - start) < 3.0 + 0.07 + 0.05);
}

#[test]
fn extrusion_follows_flow_and_retracts_use_their_acceleration() {
    let mut config = cartesian();
    config.flow_factor = 0.9;
    config.retract_accel = 500.0;
    let mut rig = Rig::new(config);
    rig.motion.set_position_mm([10.0, 10.0, 0.0, 0.0]);
    // 10 mm with 1 mm of filament at 93 steps/mm and 90 % flow: 83.7 → 84.
    rig.line([20.0, 10.0, 0.0, 1.0], 50.0).line([20.0, 10.0, 0.0, -1.0], 30.0).run(5.0);
    let e = &rig.recorder.motors[3];
    assert_eq!(e.steps.iter().filter(|s| s.1 > 0).count(), 84);
    // Back to E −1: −83.7 → −84 steps (rounding carried, never lost).
    assert_eq!(rig.recorder.positions()[3], -84);
    // The print move's X and E end together.
    let x_last = rig.recorder.motors[0].last_step();
    let e_forward_last = e.steps.iter().rfind(|s| s.1 > 0).map(|s| s.0);
    assert_eq!(x_last, e_forward_last);
}

#[test]
fn feed_override_speeds_up_new_moves() {
    let mut config = cartesian();
    config.feed_factor = 2.0;
    let mut rig = Rig::new(config);
    rig.line([100.0, 0.0, 0.0, 0.0], 40.0).run(5.0);
    let fastest = rig.recorder.motors[0].min_interval().unwrap();
    assert_eq!(fastest, 250, "80 mm/s = 8000 steps/s = 250 ticks");
}

#[test]
fn arcs_land_exactly_and_stay_on_the_circle() {
    let mut rig = Rig::new(cartesian());
    rig.motion.set_position_mm([50.0, 60.0, 0.0, 0.0]);
    // G2 X60 Y50 I0 J-10: a quarter circle around (50, 50), then G3 back
    // with R.
    rig.commands.push_back(Command::Arc([60.0, 50.0, 0.0, 0.0], ArcCentre::Offset([0, -10_000]), true, 50.0));
    rig.commands.push_back(Command::Arc([50.0, 60.0, 0.0, 0.0], ArcCentre::Radius(10_000), false, 50.0));
    rig.run(10.0);
    assert!(rig.errors.is_empty(), "{:?}", rig.errors);
    assert_eq!(&rig.recorder.positions()[..2], &[0, 0]);
    assert_eq!(rig.motion.position_um()[..2], [50_000, 60_000]);
    // Every 1 ms sample lies on the circle (steps of 0.01 mm, chords
    // within 0.002 mm).
    let x = &rig.recorder.motors[0];
    let (start, end) = (x.first_step().unwrap(), x.last_step().unwrap());
    let mut t = start;
    while t < end {
        let px = 50.0 + rig.position_at(0, t) as f64 / 100.0;
        let py = 60.0 + rig.position_at(1, t) as f64 / 100.0;
        let r = ((px - 50.0).powi(2) + (py - 50.0).powi(2)).sqrt();
        assert!((r - 10.0).abs() < 0.02, "r = {r} at ({px}, {py})");
        t += 2000;
    }
    // A bad arc is refused and nothing moves.
    let before = rig.recorder.positions();
    rig.commands.push_back(Command::Arc([90.0, 60.0, 0.0, 0.0], ArcCentre::Radius(5_000), false, 50.0));
    rig.run(1.0);
    assert_eq!(rig.errors, [MotionError::Arc(ArcError::RadiusTooSmall)]);
    assert_eq!(rig.recorder.positions(), before);
}

#[test]
fn soft_limits_refuse_targets_of_homed_axes_and_nothing_moves() {
    let mut rig = Rig::new(MotionConfig::prusa_i3());
    // Switches exactly at the start: homing ends where it began.
    rig.endstops = Box::new(|p: &[i64; 4]| (0..3).filter(|&m| p[m] <= 0).fold(0, |bits, m| bits | 1 << m));
    rig.commands.push_back(Command::Home(0));
    rig.run(60.0);
    assert_eq!(rig.motion.homed(), 0b111);
    let homed_at = rig.recorder.positions();
    rig.line([250.0, 0.0, 0.0, 0.0], 50.0).run(1.0);
    assert_eq!(rig.errors, [MotionError::OutsideSoftLimits]);
    assert_eq!(rig.recorder.positions(), homed_at);
}

/// Before homing, a Cartesian axis does not know where its limits are
/// (Marlin): it may be jogged, e.g. towards its switch.
#[test]
fn soft_limits_do_not_bind_before_homing() {
    let mut rig = Rig::new(MotionConfig::prusa_i3());
    rig.line([-5.0, 0.0, 0.0, 0.0], 50.0).run(1.0);
    assert!(rig.errors.is_empty(), "{:?}", rig.errors);
    assert_eq!(rig.recorder.positions(), [-500, 0, 0, 0]);
}

/// Bump homing on simulated endstops: X min at −3.21 mm from where the
/// machine thinks it is.
#[test]
fn cartesian_homing_finds_the_switch_and_sets_the_position() {
    let mut rig = Rig::new(cartesian());
    rig.motion.set_position_mm([50.0, 50.0, 10.0, 0.0]);
    // Switches at these motor positions (steps from the start): X min at
    // −5321, Y min at −2000, Z min at −400.
    rig.endstops = Box::new(|p: &[i64; 4]| {
        let mut bits = 0;
        if p[0] <= -5321 {
            bits |= 0b001;
        }
        if p[1] <= -2000 {
            bits |= 0b010;
        }
        if p[2] <= -400 {
            bits |= 0b100;
        }
        bits
    });
    rig.commands.push_back(Command::Home(0));
    rig.run(60.0);
    assert!(rig.errors.is_empty(), "{:?}", rig.errors);
    assert_eq!(rig.motion.homed(), 0b111);
    // Each motor ended exactly on its switch (the last re-approach stops on
    // the first triggered step) and that is now position 0.
    assert_eq!(&rig.recorder.positions()[..3], &[-5321, -2000, -400]);
    assert_eq!(&rig.motion.motor_steps()[..3], &[0, 0, 0]);
    assert_eq!(rig.motion.position_um()[..3], [0, 0, 0]);
    // X homed first, then Y, then Z.
    let first = |m: usize| rig.recorder.motors[m].first_step().unwrap();
    assert!(first(0) < first(1) && first(1) < first(2));
    // A move after homing goes where it should.
    rig.recorder.clear_steps();
    rig.line([10.0, 0.0, 0.0, 0.0], 50.0).run(5.0);
    assert_eq!(rig.recorder.positions()[0], -5321 + 1000);
}

#[test]
fn homing_fails_when_a_switch_never_triggers() {
    let mut config = cartesian();
    config.homing.axes[0].max_travel_steps = 2000;
    let mut rig = Rig::new(config);
    rig.commands.push_back(Command::Home(0b001));
    rig.run(10.0);
    assert_eq!(rig.errors, [MotionError::HomingFailed(0b001)]);
    assert_eq!(rig.motion.homed(), 0);
    assert_eq!(rig.recorder.positions()[0], -2000);
}

/// SPEC §2: all three towers home up to their max switches together, each
/// stops on its own; the trim of M666 then puts the nozzle at the centre.
#[test]
fn delta_homes_all_towers_up_and_applies_trim() {
    let mut config = MotionConfig::spec_delta(false);
    if let MachineKinematics::Delta(delta) = &mut config.kinematics {
        // Tower B's switch sits 3 mm (240 steps) low.
        delta.endstop_trim = [0.0, -3.0, 0.0];
    }
    let mut rig = Rig::new(config);
    // Switches 12 000, 11 760 and 12 000 steps above the starting carriage
    // positions (the carriages start at the origin's heights).
    rig.endstops = Box::new(|p: &[i64; 4]| {
        let mut bits = 0;
        for (motor, at) in [12_000, 11_760, 12_000].iter().enumerate() {
            if p[motor] >= *at {
                bits |= 0x10 << motor;
            }
        }
        bits
    });
    rig.commands.push_back(Command::Home(0));
    rig.run(60.0);
    assert!(rig.errors.is_empty(), "{:?}", rig.errors);
    assert_eq!(&rig.recorder.positions()[..3], &[12_000, 11_760, 12_000]);
    // All three carriages moved together on the first approach.
    let first = |m: usize| rig.recorder.motors[m].first_step().unwrap();
    assert_eq!(first(0), first(1));
    assert_eq!(first(1), first(2));
    // Tower B's carriage stopped 3 mm below the others: the effector is
    // where forward kinematics puts those carriage heights.
    let delta = match rig.motion.config.kinematics {
        MachineKinematics::Delta(delta) => delta,
        _ => unreachable!(),
    };
    let heights = delta.homed_carriage_heights();
    assert!((heights[0] - heights[1] - 3.0).abs() < 1e-3);
    let expected = delta.forward(heights).unwrap();
    let p = rig.motion.position_um();
    for axis in 0..3 {
        assert!((p[axis] - um(expected[axis])).abs() <= 2, "{p:?} vs {expected:?}");
    }
    // To the centre at Z 0.25, tower B goes down 3 mm = 240 steps less.
    rig.recorder.clear_steps();
    rig.line([0.0, 0.0, 0.25, 0.0], 100.0).run(20.0);
    let moved: Vec<i64> = rig.recorder.motors[..3].iter().map(|m| m.steps.iter().map(|s| s.1 as i64).sum()).collect();
    assert_eq!(moved[0], moved[2]);
    assert_eq!(moved[1], moved[0] + 240);
    // And every carriage is at the SPEC height 344.95 mm for (0, 0, 0.25)
    // (heights measured from the nozzle plane, so from the homed height).
    let nominal_top = heights[0];
    let landed = nominal_top + moved[0] as f32 / 80.0;
    assert!((landed - 344.95).abs() < 0.02, "{landed}");
}

/// SPEC §2 vectors through the whole chain: from the centre to (−25, 25,
/// 0.25) and (25, −25, 0.25), the carriages land on the vector heights (in
/// steps at 80/mm, ±1 step = 0.0125 mm).
#[test]
fn delta_lands_on_the_spec_vectors() {
    for (repetier, target, heights) in [
        (false, [-25.0, 25.0], [321.53, 369.29, 335.15]),
        (false, [25.0, -25.0], [362.40, 313.32, 350.08]),
        (true, [-25.0, 25.0], [362.40, 313.32, 350.08]),
        (true, [25.0, -25.0], [321.53, 369.29, 335.15]),
    ] {
        let mut rig = Rig::new(MotionConfig::spec_delta(repetier));
        rig.motion.set_position_mm([0.0, 0.0, 0.25, 0.0]);
        rig.line([target[0], target[1], 0.25, 0.0], 60.0).run(10.0);
        for tower in 0..3 {
            let moved = rig.recorder.positions()[tower] as f64 / 80.0;
            let want = heights[tower] - 344.95;
            assert!((moved - want).abs() <= 0.005 + 0.0125, "tower {tower}: moved {moved} mm, want {want}");
        }
    }
}

/// The delta limits each carriage, not only the effector: near the edge
/// one carriage moves up to 3× the effector's speed (SPEC §2).
#[test]
fn delta_carriage_speed_is_limited() {
    let mut config = MotionConfig::spec_delta(false);
    config.max_feed[..3].copy_from_slice(&[100.0; 3]);
    let mut rig = Rig::new(config);
    rig.motion.set_position_mm([-120.0, -40.0, 5.0, 0.0]);
    rig.line([-120.0, 40.0, 5.0, 0.0], 130.0).run(20.0);
    for tower in 0..3 {
        let fastest = rig.recorder.motors[tower].min_interval().unwrap();
        // 100 mm/s × 80 steps/mm = 8000 steps/s = 250 ticks; one tick of
        // Bresenham jitter on the minor towers.
        assert!(fastest >= 249, "tower {tower}: {fastest} ticks between steps");
    }
    assert!(rig.errors.is_empty());
}

#[test]
fn delta_refuses_unreachable_targets() {
    let mut rig = Rig::new(MotionConfig::spec_delta(false));
    rig.line([140.0, 0.0, 0.0, 0.0], 60.0).run(1.0);
    assert_eq!(rig.errors, [MotionError::Unreachable(KinematicsError::OutsidePrintable)]);
}

fn homed_arm() -> Rig {
    let mut rig = Rig::new(MotionConfig::spec_arm(200));
    // NC switches read "triggered" past these positions.
    rig.endstops = Box::new(|p: &[i64; 4]| {
        let mut bits = 0;
        if p[0] >= 3000 {
            bits |= 0x10;
        }
        if p[1] >= 900 {
            bits |= 0x20;
        }
        if p[2] <= -1200 {
            bits |= 0x04;
        }
        bits
    });
    rig.commands.push_back(Command::Home(0));
    rig.run(600.0);
    assert!(rig.errors.is_empty(), "{:?}", rig.errors);
    // The thesis' switches mark home, which lies inside the joints' range
    // over the travel box (the elbow's −72° is mid-range): after homing the
    // simulated switches stay released.
    rig.endstops = Box::new(|_| 0);
    rig
}

/// SPEC §3: Z, then Y, then X at 200 steps/s, 500 ms pause, back off at
/// 20 steps/s until the switch releases: that is home (−100, −107, 68).
#[test]
fn arm_homes_z_y_x_and_lands_on_its_home() {
    let mut rig = Rig::new(MotionConfig::spec_arm(200));
    rig.line([0.0, 0.0, 0.0, 0.0], 10.0).run(1.0);
    assert_eq!(rig.errors, [MotionError::NotHomed]);
    let rig = homed_arm();
    assert_eq!(rig.motion.homed(), 0b111);
    // The release points: one step back inside each switch's range.
    assert_eq!(&rig.recorder.positions()[..3], &[2999, 899, -1199]);
    let home = rig.motion.position_um();
    assert_eq!(home[..3], [-100_000, -107_000, 68_000]);
    // Motor positions are the SPEC vector for (−107, 68): −4019, −909.
    assert_eq!(&rig.motion.motor_steps()[..3], &[-5000, -4019, -909]);
    let first = |m: usize| rig.recorder.motors[m].first_step().unwrap();
    assert!(first(2) < first(1) && first(1) < first(0), "Z, then Y, then X");
    // Approach at 200 steps/s: 10 000 ticks between steps once up to speed.
    assert_eq!(rig.recorder.motors[2].min_interval(), Some(10_000));
}

/// SPEC §3 vectors through the whole chain: from home to each vector,
/// the joint motors land on the vector's pulses.
#[test]
fn arm_lands_on_the_spec_vectors() {
    let mut rig = homed_arm();
    // (0, 50) lies outside the ±40 Z travel.
    rig.motion.config.soft_limits = None;
    let origin = rig.recorder.positions();
    let home_motors = rig.motion.motor_steps();
    for (y, z, elbow, shoulder) in [(0.0, 0.0, -5000, 0), (50.0, 10.0, -5901, -97), (0.0, 50.0, -6188, -1360), (110.0, -40.0, -4781, 1747), (-107.0, 40.0, 0, 0)] {
        rig.line([-100.0, y, z, 0.0], 30.0).run(60.0);
        if (y, z) == (-107.0, 40.0) {
            continue;
        }
        assert!(rig.errors.is_empty(), "{:?}", rig.errors);
        let p = rig.recorder.positions();
        let motor = |m: usize| (p[m] - origin[m]) + home_motors[m] as i64;
        assert_eq!((motor(1), motor(2)), (elbow as i64, shoulder as i64), "({y}, {z})");
    }
}

/// SPEC §3's three failures of the thesis' line formula.
#[test]
fn arm_lines_pure_z_pure_x_and_no_overshoot() {
    let mut rig = homed_arm();
    rig.line([0.0, 0.0, 0.0, 0.0], 30.0).run(60.0);
    let arm = Arm::spec_arm(200);
    // Pure Z (0,0) → (0,30): every sampled point on the line, Z monotonic.
    let motors_before = rig.motion.motor_steps();
    rig.recorder.clear_steps();
    rig.line([0.0, 0.0, 30.0, 0.0], 20.0).run(60.0);
    let ppd = arm.joint_steps_per_degree as f64;
    // Steps recorded since `clear_steps`, on top of the motor positions.
    let joint = |rig: &Rig, m: usize, t: u64| motors_before[m] as f64 + rig.position_at(m, t) as f64;
    let (start, end) = (rig.recorder.motors[1].first_step().unwrap_or(0).min(rig.recorder.motors[2].first_step().unwrap()), rig.recorder.now);
    let mut last_z = -1.0;
    let mut t = start;
    while t <= end {
        let theta2 = joint(&rig, 1, t) / ppd;
        let theta1 = joint(&rig, 2, t) / ppd;
        let p = arm.forward([0.0, theta2 as f32, theta1 as f32]).unwrap();
        // One pulse of a joint is ≈ 0.07 mm at the tool, and Bresenham lets
        // the minor joint trail by up to one pulse.
        assert!(p[1].abs() < 0.2, "pure Z drifted to y = {}", p[1]);
        assert!(p[2] >= last_z - 0.15, "Z went backwards: {} after {last_z}", p[2]);
        last_z = p[2];
        t += 20_000;
    }
    assert!((last_z - 30.0).abs() < 0.1, "ended at z = {last_z}");
    // Pure X: moves, no NaN, X never overshoots the target.
    rig.recorder.clear_steps();
    let joints_before = rig.recorder.positions();
    rig.line([40.0, 0.0, 30.0, 0.0], 20.0).run(60.0);
    assert!(rig.errors.is_empty(), "{:?}", rig.errors);
    let x = &rig.recorder.motors[0];
    assert_eq!(x.steps.len(), 40 * 50);
    assert!(x.steps.iter().all(|s| s.1 > 0), "X reversed: overshoot");
    assert_eq!(&rig.recorder.positions()[1..3], &joints_before[1..3], "joints moved on a pure X move");
}

#[test]
fn arm_soft_limits_and_reach() {
    let mut rig = homed_arm();
    rig.line([0.0, -110.0, -40.0, 0.0], 10.0).run(1.0);
    assert_eq!(rig.errors, [MotionError::Unreachable(KinematicsError::OutOfReach)]);
    rig.errors.clear();
    rig.line([0.0, 0.0, 45.0, 0.0], 10.0).run(1.0);
    assert_eq!(rig.errors, [MotionError::OutsideSoftLimits]);
}

/// A hard limit (the arm's NC switches) hit outside homing stops at once,
/// reports the fault and requires re-homing.
#[test]
fn limit_switch_outside_homing_stops_and_requires_rehoming() {
    let mut rig = homed_arm();
    let at = rig.recorder.positions()[0];
    // The X switch trips 5 mm (250 steps) into the next move (towards max).
    rig.endstops = Box::new(move |p: &[i64; 4]| if p[0] >= at + 250 { 0x10 } else { 0 });
    rig.line([0.0, -107.0, 40.0, 0.0], 30.0).run(60.0);
    assert!(matches!(rig.errors.as_slice(), [MotionError::Fault(StepFault::LimitHit(0x10))]), "{:?}", rig.errors);
    assert_eq!(rig.recorder.positions()[0], at + 250);
    assert_eq!(rig.motion.homed(), 0);
    rig.errors.clear();
    rig.line([0.0, 0.0, 0.0, 0.0], 30.0).run(1.0);
    assert_eq!(rig.errors, [MotionError::NotHomed]);
}

/// `line_to` checks and stores a move; the next `poll` plans it. Until
/// then `ready()` holds back the next command, so an acknowledged move is
/// never lost or overtaken; a target the check refuses is never stored.
#[test]
fn a_move_is_planned_by_the_next_poll_and_holds_back_the_next_command() {
    let queues: &'static mut StepQueues = Box::leak(Box::new(StepQueues::new()));
    let config = cartesian();
    let (feeder, _generator) = queues.split(config.stepper());
    let mut motion = Motion::new(config, feeder);
    assert_eq!(motion.line_to(&[um(10.0), 0, 0, 0], um(50.0)), Ok(()));
    assert!(!motion.ready() && motion.planner().is_empty() && !motion.is_idle());
    assert_eq!(motion.line_to(&[um(20.0), 0, 0, 0], um(50.0)), Err(MotionError::Busy));
    motion.poll(&StepperStatus::default(), 0);
    assert!(motion.ready());
    assert_eq!(motion.motor_steps(), [1000, 0, 0, 0]);
    assert_eq!(motion.position_um(), [um(10.0), 0, 0, 0]);
    assert_eq!(motion.line_to(&[um(20.0), 0, 0, 0], um(50.0)), Ok(()));
}

#[test]
fn endstop_layout_conversion() {
    assert_eq!(pairs_to_endstop_bits(0b00_0001), 0b0000_0001);
    assert_eq!(pairs_to_endstop_bits(0b00_0010), 0b0001_0000);
    assert_eq!(pairs_to_endstop_bits(0b10_0100), 0b0100_0010);
}

#[test]
fn ram_sizes_stay_small() {
    use core::mem::size_of;
    // Host sizes (f32 aligned to 4); the AVR packs tighter (align 1).
    // (40: the integer entry speeds and the block's ramp, 2·a·L, which
    // make the look-ahead passes integer adds: 4 bytes a block.)
    assert!(size_of::<planner::Block>() <= 40, "{}", size_of::<planner::Block>());
    assert!(size_of::<Planner>() <= 40 * planner::PLANNER_SLOTS + 32);
    // (Blocks 24 bytes: prepared for the interrupt in the main loop, the
    // Bresenham thresholds and motor classes included. Segments 16 bytes
    // here, 15 on the AVR: the first of a block carries the block's head,
    // 5 bytes, so that the interrupt changes blocks inline.)
    assert!(size_of::<StepQueues>() <= 16 * 16 + 16 * 24 + 48, "{}", size_of::<StepQueues>());
    // + 8 bytes with the encoder loops: X's and Y's block origins.
    let origins = if cfg!(feature = "encoders") { 8 } else { 0 };
    assert!(size_of::<StepGenerator<'static>>() <= 96 + origins, "{}", size_of::<StepGenerator<'static>>());
    std::println!(
        "Block {} B, Planner {} B, StepQueues {} B, StepGenerator {} B, Prep {} B, Motion {} B",
        size_of::<planner::Block>(),
        size_of::<Planner>(),
        size_of::<StepQueues>(),
        size_of::<StepGenerator<'static>>(),
        size_of::<Prep>(),
        size_of::<Motion<'static>>()
    );
}

#[test]
fn the_prusa_i3_configuration_holds_the_prusa_i3_default_settings() {
    // The const configuration spells its tunable values out; they must be
    // the ones `M502` restores (the other way round:
    // `machine::tests::the_prusa_i3s_machine_file_gives_the_prusa_i3s_defaults`).
    let config = MotionConfig::prusa_i3();
    let mut applied = config;
    applied.apply_settings(&crate::settings::Settings::prusa_i3());
    assert_eq!(applied, config);
}
