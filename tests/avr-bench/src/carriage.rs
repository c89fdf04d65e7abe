//! The printer's X and Y carriages behind their stepper motors, for the
//! encoder loops on the board (SPEC §1, thesis 003; issue 26).
//!
//! # The plant (ours, from SPEC §1's identification)
//!
//! SPEC §1 identified each axis, velocity command → carriage position, as
//! `G(s) = k'·e^(−θs)/s` with k'x = 0.90, k'y = 0.94, θ = 0.1 s. Of that:
//!
//! - **k' is kept**: the carriage travels k' of what its motor turns, i.e.
//!   1 − k' of every move is lost between the pulley and the carriage
//!   (belt slip and stretch under load). Proportional to the motion, in
//!   both directions, so it is a function of the motor's position:
//!   `target = k' · motor`. This is the disturbance the loop has to
//!   correct: with the steps alone (open loop) the carriage ends 10 % of
//!   each move short on X and 6 % on Y.
//! - **θ is not a dead time here**: the thesis commanded a *velocity* to a
//!   step generator of its own over its own software path, and θ is that
//!   path's delay as identified from a velocity step. On this firmware the
//!   step interrupt drives the motor directly (the planner's steps arrive
//!   at the driver within microseconds) and nothing in a belt delays a
//!   carriage by 0.1 s. What a belt does have is compliance: the carriage
//!   is a mass on a spring, which we take as a first-order lag behind the
//!   motor, `τ·ċ = k'·motor − c`, τ = [`BELT_LAG_S`] (5 ms: a GT2 belt
//!   carriage rings at some tens of Hz).
//!
//! The hal-sim model (`hal_sim::axis_plant`) keeps θ because it simulates
//! the thesis' own velocity mode; this one simulates the firmware's.
//!
//! # Evaluation
//!
//! The motor's position only changes at a STEP edge, so between two events
//! the lag's input is constant and its solution exact:
//! `c(t) = target + (c(t0) − target)·e^(−(t − t0)/τ)`. The board advances
//! each axis at every STEP rising edge and at every read (an encoder read,
//! an Index check, the test sampling the carriage).

/// SPEC §1's k': carriage travel per motor travel, X and Y.
pub const THESIS_GAIN: [f64; 2] = [0.90, 0.94];
/// The belt's lag, seconds (ours; see the module comment).
pub const BELT_LAG_S: f64 = 0.005;
/// The simulated CPU's clock.
const CYCLES_PER_S: f64 = 16_000_000.0;

#[derive(Clone, Copy, Debug, Default)]
struct AxisState {
    /// Motor position, steps, as the bench counts them.
    motor: i64,
    /// Carriage position, in motor steps (k' < 1: fewer than the motor's).
    carriage: f64,
    /// Cycle the state is valid at.
    at_cycle: u64,
}

/// X's and Y's carriages (index 0 and 1, the NSE-5310 chips' order).
#[derive(Clone, Debug)]
pub struct CarriagePlant {
    /// k' per axis.
    pub gain: [f64; 2],
    /// The belt's lag, seconds (0: the carriage follows at once).
    pub lag_s: f64,
    state: [AxisState; 2],
}

impl CarriagePlant {
    /// SPEC §1's k' with our belt lag, both carriages at motor position 0.
    pub fn thesis() -> Self {
        Self::new(THESIS_GAIN, BELT_LAG_S)
    }

    /// A carriage that follows its motor exactly (k' 1, no lag).
    pub fn rigid() -> Self {
        Self::new([1.0, 1.0], 0.0)
    }

    pub fn new(gain: [f64; 2], lag_s: f64) -> Self {
        Self { gain, lag_s, state: [AxisState::default(); 2] }
    }

    /// Axis `axis`'s carriage at cycle `now`, with its motor at `motor`
    /// steps from `now` on (a STEP edge, or unchanged for a read). Returns
    /// the carriage position in motor steps.
    pub fn carriage_steps(&mut self, axis: usize, motor: i64, now: u64) -> f64 {
        let gain = self.gain[axis];
        let lag_s = self.lag_s;
        let state = &mut self.state[axis];
        if now > state.at_cycle {
            let target = gain * state.motor as f64;
            if lag_s > 0.0 {
                let decay = (-((now - state.at_cycle) as f64 / CYCLES_PER_S) / lag_s).exp();
                state.carriage = target + (state.carriage - target) * decay;
            } else {
                state.carriage = target;
            }
            state.at_cycle = now;
        }
        state.motor = motor;
        if lag_s == 0.0 {
            state.carriage = gain * motor as f64;
        }
        state.carriage
    }
}

// ------------------------------------------------------------ the circle

/// SPEC §1's circle: centre (50, 50), radius 10 mm, 126 pieces of equal
/// arc, from angle 0 ((60, 50)) counter-clockwise.
pub const CIRCLE_CENTRE: (f64, f64) = (50.0, 50.0);
pub const CIRCLE_RADIUS_MM: f64 = 10.0;
pub const CIRCLE_PIECES: usize = 126;
/// The thesis' best total (PID γ 0.5 at ≈ 5 mm/s), mm².
pub const THESIS_BEST_MSE_MM2: f64 = 0.0047;

/// The circle's corners as sent: rounded to the 4 decimals of the G-code,
/// so that the commanded path is exactly what the board was told.
pub fn circle_points() -> Vec<(f64, f64)> {
    let round = |v: f64| (v * 10_000.0).round() / 10_000.0;
    (0..=CIRCLE_PIECES)
        .map(|k| {
            let angle = std::f64::consts::TAU * k as f64 / CIRCLE_PIECES as f64;
            (round(CIRCLE_CENTRE.0 + CIRCLE_RADIUS_MM * angle.cos()), round(CIRCLE_CENTRE.1 + CIRCLE_RADIUS_MM * angle.sin()))
        })
        .collect()
}

/// The 126 `G1` lines at `speed_mm_s` (the carriage stands at the first
/// corner, (60, 50)).
pub fn circle_gcode(speed_mm_s: f64) -> Vec<String> {
    let feed = speed_mm_s * 60.0;
    circle_points().iter().skip(1).map(|(x, y)| format!("G1 X{x:.4} Y{y:.4} F{feed:.0}")).collect()
}

/// The commanded path: the corners joined by straight pieces (what `G1`
/// means), travelled at `speed_mm_s` from `t = 0`; after the end, the end.
/// (Each piece's time is its chord over the speed: the chord of 0.498614
/// mm is 0.01 % shorter than SPEC's arc of 0.498666 mm.)
pub struct CommandedPath {
    points: Vec<(f64, f64)>,
    /// Time at each corner, seconds.
    times: Vec<f64>,
}

impl CommandedPath {
    pub fn circle(speed_mm_s: f64) -> Self {
        let points = circle_points();
        let mut times = vec![0.0];
        for pair in points.windows(2) {
            let length = ((pair[1].0 - pair[0].0).powi(2) + (pair[1].1 - pair[0].1).powi(2)).sqrt();
            times.push(times.last().unwrap() + length / speed_mm_s);
        }
        Self { points, times }
    }

    /// The whole path's time, seconds.
    pub fn duration_s(&self) -> f64 {
        *self.times.last().unwrap()
    }

    /// Where the path is at `t` seconds.
    pub fn at(&self, t: f64) -> (f64, f64) {
        if t <= 0.0 {
            return self.points[0];
        }
        let piece = self.times.partition_point(|&corner| corner <= t);
        if piece >= self.times.len() {
            return *self.points.last().unwrap();
        }
        let (t0, t1) = (self.times[piece - 1], self.times[piece]);
        let (a, b) = (self.points[piece - 1], self.points[piece]);
        let f = (t - t0) / (t1 - t0);
        (a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f)
    }
}

/// One loop strategy as the host sets it up before the circle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CircleStrategy {
    pub label: &'static str,
    /// Lines sent before the circle (the loops are switched on last: that
    /// re-zeroes the encoders where the carriages stand).
    pub setup: &'static [&'static str],
    /// The carriages: SPEC §1's k' with a belt lag, or rigid.
    pub thesis_plant: bool,
}

/// The planner's steps alone on rigid carriages: how far the steps
/// themselves are from the commanded path (acceleration at the start and
/// end, the corners' junction speeds, the step grid).
pub const PLANNER_ALONE: CircleStrategy = CircleStrategy { label: "steps only, rigid carriage", setup: &["M820 X0 Y0"], thesis_plant: false };
/// The thesis' open loop: step counting only, loops off.
pub const OPEN_LOOP: CircleStrategy = CircleStrategy { label: "open loop (loops off)", setup: &["M820 X0 Y0"], thesis_plant: true };
/// `M821 S0`: no correction, following error supervised.
pub const SUPERVISED: CircleStrategy =
    CircleStrategy { label: "M821 S0 (supervised)", setup: &["M821 X S0", "M821 Y S0", "M820 X1 Y1"], thesis_plant: true };
/// `M821 S1`: P on the step error, Kp 4.3/s (the thesis' best P+FF).
pub const P_4_3: CircleStrategy =
    CircleStrategy { label: "M821 S1 P4.3", setup: &["M821 X S1 P4.3", "M821 Y S1 P4.3", "M820 X1 Y1"], thesis_plant: true };
/// `M821 S2`: the robust PID, γ 0.5, tuned for the default θ 20 ms.
pub const PID_0_5: CircleStrategy =
    CircleStrategy { label: "M821 S2 G0.5 (θ 20 ms)", setup: &["M821 X S2 G0.5", "M821 Y S2 G0.5", "M820 X1 Y1"], thesis_plant: true };
/// `M821 S2` tuned for the thesis' θ 0.1 s (`M824 T0.1`).
pub const PID_0_5_THETA_100: CircleStrategy = CircleStrategy {
    label: "M821 S2 G0.5 M824 T0.1",
    setup: &["M821 X S2 G0.5", "M821 Y S2 G0.5", "M824 X T0.1", "M824 Y T0.1", "M820 X1 Y1"],
    thesis_plant: true,
};

/// `M821 S1` with the thesis' other gains, and `M821 S2` with its other γ
/// (θ 20 ms): the rows of SPEC §1's table.
pub const P_3_0: CircleStrategy = CircleStrategy { label: "M821 S1 P3", setup: &["M821 X S1 P3", "M821 Y S1 P3", "M820 X1 Y1"], thesis_plant: true };
pub const P_4_0: CircleStrategy = CircleStrategy { label: "M821 S1 P4", setup: &["M821 X S1 P4", "M821 Y S1 P4", "M820 X1 Y1"], thesis_plant: true };
pub const P_5_0: CircleStrategy = CircleStrategy { label: "M821 S1 P5", setup: &["M821 X S1 P5", "M821 Y S1 P5", "M820 X1 Y1"], thesis_plant: true };
pub const PID_0_3: CircleStrategy =
    CircleStrategy { label: "M821 S2 G0.3 (θ 20 ms)", setup: &["M821 X S2 G0.3", "M821 Y S2 G0.3", "M820 X1 Y1"], thesis_plant: true };
pub const PID_0_7: CircleStrategy =
    CircleStrategy { label: "M821 S2 G0.7 (θ 20 ms)", setup: &["M821 X S2 G0.7", "M821 Y S2 G0.7", "M820 X1 Y1"], thesis_plant: true };
pub const PID_0_75: CircleStrategy =
    CircleStrategy { label: "M821 S2 G0.75 (θ 20 ms)", setup: &["M821 X S2 G0.75", "M821 Y S2 G0.75", "M820 X1 Y1"], thesis_plant: true };

/// Every row: the planner's floor, open loop, S0, then SPEC §1's strategies.
pub const ALL_STRATEGIES: [CircleStrategy; 12] =
    [PLANNER_ALONE, OPEN_LOOP, SUPERVISED, P_3_0, P_4_0, P_4_3, P_5_0, PID_0_3, PID_0_5, PID_0_7, PID_0_75, PID_0_5_THETA_100];

/// What one circle on the board gave.
#[derive(Clone, Debug)]
pub struct CircleRun {
    pub label: &'static str,
    pub speed_mm_s: f64,
    /// Mean squared error of the carriage against the commanded path, mm²,
    /// sampled every millisecond from the first step for the path's time.
    pub mse_x: f64,
    pub mse_y: f64,
    pub mse_total: f64,
    /// The largest distance of the carriage from where the path was, mm.
    pub max_error_mm: f64,
    pub samples: usize,
    /// Every sample: seconds from the first step, X and Y error, mm.
    pub errors: Vec<(f64, f64, f64)>,
    /// Index glitches the bench injected, and those the firmware counted
    /// as glitches (`M822`'s `glitch:`), X + Y.
    pub glitches_injected: u64,
    pub glitches_counted: u64,
    /// Correction steps the loops made since they were switched on, net
    /// (`M822`'s `corr:`), X and Y.
    pub corrections: [i64; 2],
    /// Index pulses the firmware accepted (`idx:`), took for bounces
    /// (`bounce:`) and found missing (`missed:`), X + Y.
    pub index_accepted: u64,
    pub index_bounces: u64,
    pub index_missed: u64,
    /// The first `Error:` line, if the board reported one, and when:
    /// seconds from the first step.
    pub error: Option<(f64, String)>,
}

/// How often the bench glitches an Index line during the circle (the
/// two chips in turn): ≈ 10 a second, 60 on the 5 mm/s circle.
const GLITCH_EVERY_MS: u32 = 97;

fn m822_field(line: &str, field: &str) -> Option<i64> {
    let start = line.find(field)? + field.len();
    line[start..].split(' ').next()?.parse().ok()
}

/// The circle at `speed_mm_s` with `strategy` on the board `board` (booted
/// with a fresh [`super::board::Nse5310Pair`] attached; the plant is put in
/// here). The carriage starts at (60, 50) by `G92` where it stands at boot.
pub fn run_circle(board: &mut crate::board::Board, strategy: &CircleStrategy, speed_mm_s: f64) -> Result<CircleRun, String> {
    let plant = if strategy.thesis_plant { CarriagePlant::thesis() } else { CarriagePlant::rigid() };
    run_circle_on(board, strategy, speed_mm_s, plant)
}

/// [`run_circle`] with other carriages than the strategy's.
pub fn run_circle_on(board: &mut crate::board::Board, strategy: &CircleStrategy, speed_mm_s: f64, plant: CarriagePlant) -> Result<CircleRun, String> {
    use crate::bench::exchange;
    board.nse5310().ok_or("no NSE-5310s attached")?.plant = Some(plant);
    let start = [board.encoder_carriage_mm(0).unwrap(), board.encoder_carriage_mm(1).unwrap()];
    exchange(board, &["G90", "G92 X60 Y50"], 5.0)?;
    let replies_before = board.host().replies.len();
    exchange(board, strategy.setup, 5.0)?;
    board.clear_step_edges();
    let path = CommandedPath::circle(speed_mm_s);
    board.send(circle_gcode(speed_mm_s));
    // Sample the carriages every millisecond until the path's time plus
    // half a second has passed since the first step.
    let mut samples: Vec<(u64, f64, f64)> = Vec::new();
    let mut glitches_injected = 0u64;
    let mut first_step: Option<u64> = None;
    let give_up = board.cycle() + (5.0 * CYCLES_PER_S) as u64;
    for ms in 1u32.. {
        board.run_for_ms(1.0);
        if board.halted_reason().is_some() {
            return Err(format!("the CPU stopped: {:?}", board.halted_reason()));
        }
        let now = board.cycle();
        let (x, y) = (board.encoder_carriage_mm(0).unwrap() - start[0], board.encoder_carriage_mm(1).unwrap() - start[1]);
        samples.push((now, 60.0 + x, 50.0 + y));
        if first_step.is_none() {
            first_step = (0..2).filter_map(|axis| board.step_edges(axis).iter().find(|e| e.rising).map(|e| e.cycle)).min();
            if first_step.is_none() && now > give_up {
                return Err("the circle never started".into());
            }
        }
        if first_step.is_some() && ms % GLITCH_EVERY_MS == 0 {
            board.glitch_index((ms / GLITCH_EVERY_MS % 2) as usize);
            glitches_injected += 1;
        }
        if let Some(t0) = first_step {
            if now as f64 > t0 as f64 + (path.duration_s() + 0.5) * CYCLES_PER_S {
                break;
            }
        }
    }
    let t0 = first_step.unwrap();
    let (mut sum_x, mut sum_y, mut max_error, mut count) = (0.0, 0.0, 0.0f64, 0usize);
    let mut errors = Vec::with_capacity(samples.len());
    for &(cycle, x, y) in &samples {
        if cycle < t0 {
            continue;
        }
        let t = (cycle - t0) as f64 / CYCLES_PER_S;
        if t > path.duration_s() {
            break;
        }
        let (rx, ry) = path.at(t);
        let (ex, ey) = (x - rx, y - ry);
        sum_x += ex * ex;
        sum_y += ey * ey;
        max_error = max_error.max((ex * ex + ey * ey).sqrt());
        errors.push((t, ex, ey));
        count += 1;
    }
    let report = exchange(board, &["M822"], 5.0)?;
    let error = board.host().replies[replies_before..]
        .iter()
        .find(|r| r.text.starts_with("Error:"))
        .map(|r| ((r.first_byte_cycle as f64 - t0 as f64) / CYCLES_PER_S, r.text.clone()));
    let (mut glitches_counted, mut index_accepted, mut index_bounces, mut index_missed) = (0, 0, 0, 0);
    let mut corrections = [0; 2];
    for (axis, letter) in ["echo:X ", "echo:Y "].iter().enumerate() {
        if let Some(line) = report.iter().find(|l| l.starts_with(letter)) {
            let field = |name: &str| m822_field(line, name).unwrap_or(0);
            glitches_counted += field("glitch:") as u64;
            index_accepted += field("idx:") as u64;
            index_bounces += field("bounce:") as u64;
            index_missed += field("missed:") as u64;
            corrections[axis] = field("corr:");
        }
    }
    let (mse_x, mse_y) = (sum_x / count as f64, sum_y / count as f64);
    Ok(CircleRun {
        label: strategy.label,
        speed_mm_s,
        mse_x,
        mse_y,
        mse_total: mse_x + mse_y,
        max_error_mm: max_error,
        samples: count,
        errors,
        glitches_injected,
        glitches_counted,
        corrections,
        index_accepted,
        index_bounces,
        index_missed,
        error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_carriage_travels_k_prime_of_its_motor_once_the_belt_has_settled() {
        let mut plant = CarriagePlant::thesis();
        plant.carriage_steps(0, 1000, 0);
        // Right after the step the carriage has not moved yet.
        assert_eq!(plant.carriage_steps(0, 1000, 0), 0.0);
        // One lag later: 1 − 1/e of the way to 900 steps.
        let one_lag = (BELT_LAG_S * CYCLES_PER_S) as u64;
        let at_lag = plant.carriage_steps(0, 1000, one_lag);
        assert!((at_lag - 900.0 * (1.0 - (-1.0f64).exp())).abs() < 1e-9, "{at_lag}");
        // Ten lags later: 900 to within 0.005 steps.
        assert!((plant.carriage_steps(0, 1000, 10 * one_lag) - 900.0).abs() < 0.005 * 900.0);
        // Y: 94 %.
        plant.carriage_steps(1, -500, 0);
        assert!((plant.carriage_steps(1, -500, 20 * one_lag) + 470.0).abs() < 1e-3);
    }

    #[test]
    fn a_rigid_carriage_is_its_motor() {
        let mut plant = CarriagePlant::rigid();
        assert_eq!(plant.carriage_steps(0, 12, 5), 12.0);
        assert_eq!(plant.carriage_steps(0, 13, 5), 13.0);
    }
}
