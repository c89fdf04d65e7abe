//! Simulated closed-loop axes (SPEC §1, §5) and the thesis' circle
//! experiment, run through the firmware's own encoder and loop code.
//!
//! # The printer axis ([`AxisPlant`])
//!
//! SPEC §1 identified each axis, from the velocity command to the encoder,
//! as G(s) = k'·e^(−θs)/s (k'x 0.90, k'y 0.94, θ 0.1 s). Here:
//!
//! 1. the firmware's velocity mode turns the commanded
//!    [`StepRate`] into whole steps (step quantisation, 100 steps/mm);
//! 2. the carriage follows the motor θ later with gain k':
//!    x(t) = x0 + k'·(steps(t − θ) − steps0)/steps_per_mm + slip;
//! 3. the NSE-5310 reads x over the 2 mm pole-pair strip: 4096 counts per
//!    2 mm, rounded, plus Gaussian noise (σ in counts), modulo 4096, with
//!    the strip's zero at an arbitrary count; the Index line fires when the
//!    carriage crosses the index phase, plus random glitches and bursts.
//!
//! Faults: [`AxisPlant::slip`] (the belt jumps: the carriage moves by some
//! mm with the motor standing), [`AxisPlant::stick_sensor`] (the reading
//! freezes), [`AxisPlant::glitch_burst`].
//!
//! Everything random comes from a seeded xorshift64* ([`Rng`]): runs repeat
//! exactly.
//!
//! # The circle ([`circle_experiment`])
//!
//! SPEC §1's test trajectory: centre (50, 50) mm, radius 10 mm, start angle
//! 0 (the point (60, 50)), counter-clockwise, cut into 126 pieces of equal
//! arc (2π·10/126 = 0.49867 mm, the nearest count to 0.5 mm pieces that
//! closes the circle: 62.83/0.5 = 125.66 rounded up). Each piece is a
//! straight chord between vertices rounded to encoder units (1/2048 mm),
//! lasting arc length / mean speed; piece end times are rounded to whole
//! loop ticks from the cumulative ideal time (no drift). The error is
//! sampled every tick, from the moment the reference starts moving until it
//! stops, as (reference − encoder reading)², per axis, in mm²; total = X + Y.

use firmware::closed_loop::control::{AxisController, DriverStatus, FollowingErrorLimit, Reference};
use firmware::closed_loop::nse5310::{LinearTracker, TrackerConfig, UNITS_PER_MM};
use firmware::closed_loop::output::{StepRate, StepperScale};
use firmware::closed_loop::reference::ReferencePath;
use firmware::closed_loop::tuning::Strategy;
use firmware::closed_loop::{AxisFault, EncoderAxis, LoopGains, Reading};
use std::collections::VecDeque;
use std::fmt::Write as _;

/// A small seeded generator (xorshift64*): reproducible noise.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x9E37_79B9_7F4A_7C15 | 1)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    pub fn gaussian(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// One printer axis as identified in SPEC §1, with its encoder.
#[derive(Clone, Debug)]
pub struct PlantConfig {
    /// k': mm of carriage per mm of commanded motion.
    pub gain: f64,
    /// θ, seconds.
    pub dead_time_s: f64,
    pub steps_per_mm: f64,
    /// Encoder noise, σ in counts (0: none).
    pub noise_counts: f64,
    /// Random Index glitches per second (0: none).
    pub glitch_rate_hz: f64,
    /// Raw count where the Index fires.
    pub index_phase: u16,
    /// Raw count the encoder reads at carriage position 0 mm.
    pub strip_offset: u16,
    pub seed: u64,
}

impl PlantConfig {
    /// SPEC §1's X axis: k' 0.90, θ 0.1 s, 100 steps/mm, σ 1 count of
    /// noise, 2 Index glitches per second.
    pub fn printer_x() -> Self {
        Self {
            gain: 0.90,
            dead_time_s: 0.1,
            steps_per_mm: 100.0,
            noise_counts: 1.0,
            glitch_rate_hz: 2.0,
            index_phase: 0,
            strip_offset: 1234,
            seed: 1,
        }
    }

    /// SPEC §1's Y axis: k' 0.94.
    pub fn printer_y() -> Self {
        Self { gain: 0.94, strip_offset: 3210, seed: 2, ..Self::printer_x() }
    }

    /// No noise and no glitches.
    pub fn clean(self) -> Self {
        Self { noise_counts: 0.0, glitch_rate_hz: 0.0, ..self }
    }
}

/// The simulated axis: velocity mode, dead time, gain, encoder.
#[derive(Clone, Debug)]
pub struct AxisPlant {
    config: PlantConfig,
    rng: Rng,
    substep_s: f64,
    /// Steps/s commanded (from the Q24.8 rate).
    rate_steps_per_s: f64,
    motor_steps: i64,
    step_phase: f64,
    /// Motor steps over the last θ, one entry per substep.
    history: VecDeque<i64>,
    start_mm: f64,
    start_steps: i64,
    slip_mm: f64,
    /// mm/s of belt slip still going on, and for how many substeps.
    slip_rate: f64,
    slip_substeps_left: u32,
    carriage_mm: f64,
    stuck_raw: Option<u16>,
    pending_edges: u8,
    burst_left: u32,
    time_s: f64,
}

const COUNTS_PER_MM: f64 = 2048.0;

impl AxisPlant {
    /// An axis at rest at `start_mm`, simulated in substeps of `substep_s`.
    pub fn new(config: PlantConfig, start_mm: f64, substep_s: f64) -> Self {
        let delay = (config.dead_time_s / substep_s).round() as usize;
        let rng = Rng::new(config.seed);
        Self {
            rng,
            substep_s,
            rate_steps_per_s: 0.0,
            motor_steps: 0,
            step_phase: 0.0,
            history: VecDeque::from(vec![0; delay.max(1)]),
            start_mm,
            start_steps: 0,
            slip_mm: 0.0,
            slip_rate: 0.0,
            slip_substeps_left: 0,
            carriage_mm: start_mm,
            stuck_raw: None,
            pending_edges: 0,
            burst_left: 0,
            time_s: 0.0,
            config,
        }
    }

    /// The velocity mode's command until the next call.
    pub fn set_step_rate(&mut self, rate: StepRate) {
        self.rate_steps_per_s = f64::from(rate.0) / 256.0;
    }

    /// Move time on by `duration_s` (a whole number of substeps).
    pub fn advance(&mut self, duration_s: f64) {
        let substeps = (duration_s / self.substep_s).round() as usize;
        for _ in 0..substeps {
            self.substep();
        }
    }

    fn substep(&mut self) {
        self.time_s += self.substep_s;
        self.step_phase += self.rate_steps_per_s * self.substep_s;
        while self.step_phase >= 1.0 {
            self.motor_steps += 1;
            self.step_phase -= 1.0;
        }
        while self.step_phase <= -1.0 {
            self.motor_steps -= 1;
            self.step_phase += 1.0;
        }
        if self.slip_substeps_left > 0 {
            self.slip_substeps_left -= 1;
            self.slip_mm += self.slip_rate * self.substep_s;
        }
        self.history.push_back(self.motor_steps);
        let delayed = self.history.pop_front().unwrap_or(self.motor_steps);
        let before = self.carriage_mm;
        self.carriage_mm =
            self.start_mm + self.config.gain * (delayed - self.start_steps) as f64 / self.config.steps_per_mm + self.slip_mm;
        let crossings = self.index_crossings(before, self.carriage_mm);
        self.pending_edges = self.pending_edges.saturating_add(crossings);
        if self.config.glitch_rate_hz > 0.0 && self.rng.uniform() < self.config.glitch_rate_hz * self.substep_s {
            self.pending_edges = self.pending_edges.saturating_add(1);
        }
        if self.burst_left > 0 {
            self.burst_left -= 1;
            self.pending_edges = self.pending_edges.saturating_add(1);
        }
    }

    fn index_crossings(&self, from_mm: f64, to_mm: f64) -> u8 {
        let pole = |mm: f64| {
            ((mm * COUNTS_PER_MM + f64::from(self.config.strip_offset) - f64::from(self.config.index_phase)) / 4096.0).floor()
        };
        (pole(to_mm) - pole(from_mm)).abs().min(255.0) as u8
    }

    /// Where the carriage really is, mm.
    pub fn carriage_mm(&self) -> f64 {
        self.carriage_mm
    }

    /// Where the motor is (whole steps), mm.
    pub fn motor_mm(&self) -> f64 {
        self.start_mm + (self.motor_steps - self.start_steps) as f64 / self.config.steps_per_mm
    }

    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// What the NSE-5310 reads now: 12 bits, noise included.
    pub fn read_raw(&mut self) -> u16 {
        if let Some(raw) = self.stuck_raw {
            return raw;
        }
        let noise = if self.config.noise_counts > 0.0 { self.config.noise_counts * self.rng.gaussian() } else { 0.0 };
        let counts = (self.carriage_mm * COUNTS_PER_MM + noise).round() as i64 + i64::from(self.config.strip_offset);
        counts.rem_euclid(4096) as u16
    }

    /// Index edges since the last call (real crossings and glitches).
    pub fn take_index_edges(&mut self) -> u8 {
        std::mem::take(&mut self.pending_edges)
    }

    /// The belt jumps teeth: over `duration_s` the carriage moves `mm` more
    /// than the motor drives it. (A jump of exactly one 2 mm pole pair
    /// between two reads would be invisible to the NSE-5310; a real belt
    /// takes milliseconds to skip, and the loop reads faster than that.)
    pub fn slip(&mut self, mm: f64, duration_s: f64) {
        let substeps = (duration_s / self.substep_s).round().max(1.0);
        self.slip_rate = mm / (substeps * self.substep_s);
        self.slip_substeps_left = substeps as u32;
    }

    /// The sensor freezes at its current reading.
    pub fn stick_sensor(&mut self) {
        self.stuck_raw = Some(self.read_raw());
    }

    /// One glitch edge per substep for the next `edges` substeps.
    pub fn glitch_burst(&mut self, edges: u32) {
        self.burst_left += edges;
    }
}

/// Options of one circle run.
#[derive(Clone, Debug)]
pub struct CircleOptions {
    pub loop_hz: u16,
    /// Plant substeps per loop tick.
    pub substeps: u32,
    /// Feed the velocity forward θ early (ours, see the firmware's
    /// `reference` module); false: plain ẋd feedforward.
    pub preview: bool,
    /// Encoder noise and Index glitches as in [`PlantConfig::printer_x`].
    pub noise_and_glitches: bool,
    /// A belt slip on X: (time after the start of the circle, mm), taking
    /// [`SLIP_DURATION_S`].
    pub slip_x: Option<(f64, f64)>,
    /// Stop the run at the first fault (else record it and go on).
    pub stop_on_fault: bool,
    pub following_error: FollowingErrorLimit,
}

impl CircleOptions {
    /// The configuration the benchmark reports: 250 Hz loop, preview on,
    /// noise and glitches on, 1 mm / 0.5 s following-error limit.
    pub fn standard() -> Self {
        Self {
            loop_hz: DEFAULT_LOOP_HZ,
            substeps: 4,
            preview: true,
            noise_and_glitches: true,
            slip_x: None,
            stop_on_fault: false,
            following_error: FollowingErrorLimit::printer_default(DEFAULT_LOOP_HZ),
        }
    }
}

/// How long a simulated belt slip takes (a GT2 tooth skipping).
pub const SLIP_DURATION_S: f64 = 0.02;

/// The loop rate we propose for the printer: every 4th ms of the Mega's
/// 1 kHz tick. It reads each encoder every 0.8 mm at 200 mm/s (SPEC §1:
/// at least once per 1 mm), costs ≈ 10 % of the AVR for X and Y (≈ 6400
/// cycles per tick measured on simavr), and the circle's MSE is the same as
/// at 500 or 1000 Hz (the 0.1 s dead time dominates, not the sampling).
pub const DEFAULT_LOOP_HZ: u16 = 250;

/// SPEC §1's circle.
pub const CIRCLE_CENTRE_MM: (f64, f64) = (50.0, 50.0);
pub const CIRCLE_RADIUS_MM: f64 = 10.0;
pub const CIRCLE_PIECES: usize = 126;
/// The speeds of the experiment, mm/s.
pub const CIRCLE_SPEEDS: [f64; 3] = [2.5, 5.0, 10.0];

/// Every strategy of the thesis' table.
pub fn thesis_strategies() -> Vec<Strategy> {
    vec![
        Strategy::OpenLoop,
        Strategy::PFeedforward { kp_milli: 3000 },
        Strategy::PFeedforward { kp_milli: 4000 },
        Strategy::PFeedforward { kp_milli: 4300 },
        Strategy::PFeedforward { kp_milli: 5000 },
        Strategy::RobustPid { gamma_milli: 300 },
        Strategy::RobustPid { gamma_milli: 500 },
        Strategy::RobustPid { gamma_milli: 700 },
        Strategy::RobustPid { gamma_milli: 750 },
    ]
}

/// The thesis' measured X / Y / total MSE for a strategy (SPEC §1), mm².
pub fn thesis_reference(strategy: Strategy) -> Option<(f64, f64, f64)> {
    Some(match strategy {
        Strategy::OpenLoop => (0.0355, 0.0339, 0.0694),
        Strategy::PFeedforward { kp_milli: 3000 } => (0.0042, 0.0439, 0.0481),
        Strategy::PFeedforward { kp_milli: 4000 } => (0.0030, 0.0475, 0.0505),
        Strategy::PFeedforward { kp_milli: 4300 } => (0.0100, 0.0080, 0.0180),
        Strategy::PFeedforward { kp_milli: 5000 } => (0.2265, 0.6557, 0.8822),
        Strategy::RobustPid { gamma_milli: 300 } => (0.0786, 0.4265, 0.5051),
        Strategy::RobustPid { gamma_milli: 500 } => (0.0014, 0.0033, 0.0047),
        Strategy::RobustPid { gamma_milli: 700 } => (0.0829, 0.3964, 0.4793),
        Strategy::RobustPid { gamma_milli: 750 } => (0.0502, 0.4191, 0.4693),
        _ => return None,
    })
}

/// A short name for tables.
pub fn strategy_label(strategy: Strategy) -> String {
    match strategy {
        Strategy::OpenLoop => "open loop".into(),
        Strategy::PFeedforward { kp_milli } => format!("P+FF Kp {:.1}", f64::from(kp_milli) / 1000.0),
        Strategy::RobustPid { gamma_milli } => format!("PID γ {:.2}", f64::from(gamma_milli) / 1000.0),
        Strategy::ServoPid { .. } => "servo PID".into(),
    }
}

/// One row of the table.
#[derive(Clone, Debug)]
pub struct CircleRow {
    pub strategy: Strategy,
    pub speed_mm_s: f64,
    /// MSE of reference − encoder reading, mm².
    pub mse_x: f64,
    pub mse_y: f64,
    /// mse_x + mse_y.
    pub mse_total: f64,
    /// The same against the true carriage position.
    pub true_mse_total: f64,
    /// |reference − carriage| at the end of the circle, mm (max of X, Y).
    pub final_error_mm: f64,
    /// The first fault, with the time it was raised (s from the start).
    pub fault: Option<(char, AxisFault, f64)>,
    /// Index edges the X and Y trackers rejected as glitches.
    pub index_glitches_rejected: u32,
    pub samples: usize,
}

/// Gains of `strategy` for θ and the loop period.
pub fn gains_for(strategy: Strategy, loop_hz: u16) -> LoopGains {
    strategy.loop_gains(0.1, 1.0 / f32::from(loop_hz)).expect("the thesis' gains fit the tick")
}

/// The axis as the board builds it: NSE-5310 tracker, loop, 100 steps/mm.
pub fn printer_axis(strategy: Strategy, options: &CircleOptions) -> EncoderAxis {
    let max_speed = i32::from(max_speed_mm_s(options.loop_hz));
    let controller = AxisController::new(gains_for(strategy, options.loop_hz), max_speed * UNITS_PER_MM, options.following_error);
    EncoderAxis::new(
        LinearTracker::new(TrackerConfig::for_read_rate(max_speed_mm_s(options.loop_hz), options.loop_hz).expect("unwrappable")),
        controller,
        StepperScale::new(100.0, UNITS_PER_MM as f32).expect("scale"),
    )
}

/// The axis' speed limit: 200 mm/s, or less when the loop reads the
/// encoder too rarely to unwrap at 200 mm/s (0.8 mm per read at most).
pub fn max_speed_mm_s(loop_hz: u16) -> u16 {
    (u32::from(loop_hz) * 8 / 10).min(200) as u16
}

fn units(mm: f64) -> i32 {
    (mm * f64::from(UNITS_PER_MM)).round() as i32
}

/// The circle's vertices (mm) and each piece's end time (s).
pub fn circle_pieces(speed_mm_s: f64) -> Vec<((f64, f64), f64)> {
    let arc = 2.0 * std::f64::consts::PI * CIRCLE_RADIUS_MM / CIRCLE_PIECES as f64;
    (1..=CIRCLE_PIECES)
        .map(|i| {
            let angle = 2.0 * std::f64::consts::PI * i as f64 / CIRCLE_PIECES as f64;
            let point = (
                CIRCLE_CENTRE_MM.0 + CIRCLE_RADIUS_MM * angle.cos(),
                CIRCLE_CENTRE_MM.1 + CIRCLE_RADIUS_MM * angle.sin(),
            );
            (point, i as f64 * arc / speed_mm_s)
        })
        .collect()
}

/// Run the circle once with one strategy on both axes.
pub fn run_circle(strategy: Strategy, speed_mm_s: f64, options: &CircleOptions) -> CircleRow {
    let period = 1.0 / f64::from(options.loop_hz);
    let substep = period / f64::from(options.substeps);
    let start = (CIRCLE_CENTRE_MM.0 + CIRCLE_RADIUS_MM, CIRCLE_CENTRE_MM.1);
    let (mut px, mut py) = (PlantConfig::printer_x(), PlantConfig::printer_y());
    if !options.noise_and_glitches {
        px = px.clean();
        py = py.clean();
    }
    let mut plants = [AxisPlant::new(px, start.0, substep), AxisPlant::new(py, start.1, substep)];
    let mut axes = [printer_axis(strategy, options), printer_axis(strategy, options)];
    // Homing: the first reading is the start position.
    for (axis, (plant, start_mm)) in axes.iter_mut().zip(plants.iter_mut().zip([start.0, start.1])) {
        axis.tracker.update(plant.read_raw(), 0, 0).expect("first read");
        plant.take_index_edges();
        axis.rehome(units(start_mm));
    }
    let preview_ticks = if options.preview { (0.1 * f64::from(options.loop_hz)).round() as u16 } else { 0 };
    let mut path = ReferencePath::<2, 8>::new([units(start.0), units(start.1)], options.loop_hz, preview_ticks);
    let pieces = circle_pieces(speed_mm_s);
    let mut next_piece = 0;
    let mut ticks_queued: i64 = 0;

    let mut sum = [0.0f64; 2];
    let mut true_sum = 0.0;
    let mut samples = 0usize;
    let mut fault = None;
    let mut tick: i64 = 0;
    let mut slip_done = options.slip_x.is_none();
    loop {
        // Main loop: keep the queue full.
        while next_piece < pieces.len() && path.free_slots() > 0 {
            let ((x, y), end_s) = pieces[next_piece];
            let end_tick = (end_s * f64::from(options.loop_hz)).round() as i64;
            let ticks = (end_tick - ticks_queued).max(1);
            path.push([units(x), units(y)], ticks as u16).expect("queue has room");
            ticks_queued += ticks;
            next_piece += 1;
        }
        let started = tick >= i64::from(preview_ticks);
        if started && next_piece == pieces.len() && path.is_idle() {
            break;
        }
        let circle_time = (tick - i64::from(preview_ticks)) as f64 * period;
        if !slip_done {
            if let Some((at_s, mm)) = options.slip_x {
                if circle_time >= at_s {
                    plants[0].slip(mm, SLIP_DURATION_S);
                    slip_done = true;
                }
            }
        }
        // Board tick.
        let references: [Reference; 2] = path.advance();
        for (index, (axis, plant)) in axes.iter_mut().zip(plants.iter_mut()).enumerate() {
            let raw = plant.read_raw();
            let edges = plant.take_index_edges();
            let result = axis.tick(references[index], Reading::Raw(raw), edges, DriverStatus::default());
            let rate = match result {
                Ok(rate) => rate,
                Err(error) => {
                    if fault.is_none() {
                        fault = Some((if index == 0 { 'X' } else { 'Y' }, error, circle_time.max(0.0)));
                    }
                    if !options.stop_on_fault {
                        axis.controller.reset();
                    }
                    StepRate(0)
                }
            };
            plant.set_step_rate(rate);
            if started {
                let reference_mm = f64::from(references[index].position) / f64::from(UNITS_PER_MM);
                let measured_mm = f64::from(axis.measured()) / f64::from(UNITS_PER_MM);
                sum[index] += (reference_mm - measured_mm).powi(2);
                true_sum += (reference_mm - plant.carriage_mm()).powi(2);
            }
        }
        if started {
            samples += 1;
        }
        if fault.is_some() && options.stop_on_fault {
            break;
        }
        for plant in plants.iter_mut() {
            plant.advance(period);
        }
        tick += 1;
    }
    // Let the axes settle for 2 s at the end point, then measure.
    let end = path.position();
    for _ in 0..(2 * u32::from(options.loop_hz)) {
        let references = path.advance();
        for (index, (axis, plant)) in axes.iter_mut().zip(plants.iter_mut()).enumerate() {
            let raw = plant.read_raw();
            let edges = plant.take_index_edges();
            let rate = axis.tick(references[index], Reading::Raw(raw), edges, DriverStatus::default()).unwrap_or(StepRate(0));
            plant.set_step_rate(rate);
        }
        for plant in plants.iter_mut() {
            plant.advance(period);
        }
    }
    let final_error_mm = (0..2)
        .map(|i| (f64::from(end[i]) / f64::from(UNITS_PER_MM) - plants[i].carriage_mm()).abs())
        .fold(0.0, f64::max);
    let n = samples.max(1) as f64;
    CircleRow {
        strategy,
        speed_mm_s,
        mse_x: sum[0] / n,
        mse_y: sum[1] / n,
        mse_total: (sum[0] + sum[1]) / n,
        true_mse_total: true_sum / n,
        final_error_mm,
        fault,
        index_glitches_rejected: axes.iter().map(|a| u32::from(a.tracker.counters().index_glitches)).sum(),
        samples,
    }
}

/// The whole table: every strategy at 2.5, 5 and 10 mm/s.
pub fn circle_experiment(options: &CircleOptions) -> Vec<CircleRow> {
    let mut rows = Vec::new();
    for speed in CIRCLE_SPEEDS {
        for strategy in thesis_strategies() {
            rows.push(run_circle(strategy, speed, options));
        }
    }
    rows
}

/// The benchmark figure `circle_mse_total_mm2`: robust PID γ 0.5 at 5 mm/s,
/// noise and glitches on, [`CircleOptions::standard`].
pub fn circle_mse_total_mm2() -> f64 {
    run_circle(Strategy::RobustPid { gamma_milli: 500 }, 5.0, &CircleOptions::standard()).mse_total
}

/// The table as text, beside the thesis' figures (which were measured at
/// ≈ 5 mm/s on the real machine).
pub fn format_circle_table(rows: &[CircleRow]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<14} {:>5} {:>10} {:>10} {:>10} {:>10} {:>8}  {:<28} thesis X / Y / total",
        "strategy", "mm/s", "MSE X", "MSE Y", "total", "true tot", "end mm", "fault"
    );
    for row in rows {
        let fault = match row.fault {
            Some((axis, fault, at)) => format!("{axis} {fault:?} @{at:.2}s"),
            None => "-".into(),
        };
        let thesis = match thesis_reference(row.strategy) {
            Some((x, y, t)) if row.speed_mm_s == 5.0 => format!("{x:.4} / {y:.4} / {t:.4}"),
            _ => String::new(),
        };
        let _ = writeln!(
            out,
            "{:<14} {:>5.1} {:>10.6} {:>10.6} {:>10.6} {:>10.6} {:>8.4}  {:<28} {}",
            strategy_label(row.strategy),
            row.speed_mm_s,
            row.mse_x,
            row.mse_y,
            row.mse_total,
            row.true_mse_total,
            row.final_error_mm,
            fault,
            thesis
        );
    }
    out
}

/// A DC servo axis for SPEC §5: duty → motor speed through a first-order
/// lag, a small dead time (PWM, current build-up), integrated into
/// quadrature counts. Feeds a firmware `QuadratureDecoder` edge by edge.
#[derive(Clone, Debug)]
pub struct DcServoPlant {
    /// Counts per second per unit of duty at steady state.
    pub counts_per_s_per_duty: f64,
    pub time_constant_s: f64,
    delay: VecDeque<f64>,
    speed: f64,
    /// True position in counts (fractional).
    pub position_counts: f64,
    duty: f64,
    substep_s: f64,
}

impl DcServoPlant {
    pub fn new(counts_per_s_per_duty: f64, time_constant_s: f64, dead_time_s: f64, substep_s: f64) -> Self {
        let delay = (dead_time_s / substep_s).round().max(1.0) as usize;
        Self {
            counts_per_s_per_duty,
            time_constant_s,
            delay: VecDeque::from(vec![0.0; delay]),
            speed: 0.0,
            position_counts: 0.0,
            duty: 0.0,
            substep_s,
        }
    }

    pub fn set_duty(&mut self, duty: i32) {
        self.duty = f64::from(duty);
    }

    /// Advance, calling `edge(a, b)` for every quadrature edge on the way.
    pub fn advance(&mut self, duration_s: f64, mut edge: impl FnMut(bool, bool)) {
        let substeps = (duration_s / self.substep_s).round() as usize;
        for _ in 0..substeps {
            self.delay.push_back(self.duty);
            let applied = self.delay.pop_front().unwrap_or(0.0);
            let target = applied * self.counts_per_s_per_duty;
            self.speed += (target - self.speed) * (self.substep_s / self.time_constant_s).min(1.0);
            let before = self.position_counts.floor() as i64;
            self.position_counts += self.speed * self.substep_s;
            let after = self.position_counts.floor() as i64;
            let mut count = before;
            while count != after {
                count += if after > count { 1 } else { -1 };
                let (a, b) = quadrature_levels(count);
                edge(a, b);
            }
        }
    }
}

/// A/B levels at a count (Gray sequence 00, 10, 11, 01: A leads B forward).
pub fn quadrature_levels(count: i64) -> (bool, bool) {
    match count.rem_euclid(4) {
        0 => (false, false),
        1 => (true, false),
        2 => (true, true),
        _ => (false, true),
    }
}
