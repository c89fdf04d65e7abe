//! SPEC §1's experiment 003 on the shipped encoder build (issue 26): the
//! thesis' circle (r 10 mm around (50, 50), 126 pieces, counter-clockwise)
//! run by the firmware's own loops (`closed_loop/printer.rs`: correction
//! steps on top of the planner's) on the simulated Mega 2560, its NSE-5310
//! pair glitching its Index lines ≈ 10 times a second, its carriages
//! travelling k' of their motors (X 0.90, Y 0.94, SPEC §1) behind a 5 ms
//! belt lag (`avr_bench::carriage`). The MSE is the carriage's, against
//! the commanded path, every millisecond from the first step.

use avr_bench::board::{Board, Nse5310Pair, RampsConfig};
use avr_bench::carriage::*;

fn encoder_board() -> Board {
    let dir = avr_bench::build::target_dir().join("machines").join("encoders");
    let elf = avr_bench::build::build_variant(&dir, &avr_bench::build::Machine::PRUSA_ENCODERS, false)
        .unwrap_or_else(|e| panic!("the encoders build: {e}"));
    let mut board = avr_bench::bench::boot(&elf, RampsConfig::stock(115_200)).expect("the firmware boots");
    board.attach_nse5310(Nse5310Pair::prusa());
    board
}

fn circle(strategy: &CircleStrategy, speed_mm_s: f64) -> CircleRun {
    let run = run_circle(&mut encoder_board(), strategy, speed_mm_s).unwrap_or_else(|e| panic!("{}: {e}", strategy.label));
    println!("{run:?}");
    run
}

/// SPEC §1's k': the carriage misses 1 − k' of every move.
const LOST: [f64; 2] = [1.0 - THESIS_GAIN[0], 1.0 - THESIS_GAIN[1]];

#[test]
fn the_robust_pid_holds_the_5_mm_s_circle_ten_times_below_the_thesis_through_index_glitches() {
    let pid = circle(&PID_0_5, 5.0);
    assert_eq!(pid.error, None);
    assert!((12_565..=12_567).contains(&pid.samples), "12.566 s of circle at 1 kHz: {}", pid.samples);
    // Required: below the thesis' 0.0047 mm²; goal: ten times below.
    assert!(pid.mse_total < THESIS_BEST_MSE_MM2 / 10.0, "{pid:?}");
    // What is left is the steps' own distance from the path (the planner's
    // ramps and the 0.01 mm step grid on rigid carriages: 0.000056 mm²):
    // the loop took out all of the lost k' (1.68 mm² in open loop).
    let floor = circle(&PLANNER_ALONE, 5.0);
    assert!(floor.mse_total < 0.00007, "{floor:?}");
    assert!(pid.mse_total < floor.mse_total * 1.2, "PID {} against the steps alone {}", pid.mse_total, floor.mse_total);
    assert!(pid.max_error_mm < 0.03, "{pid:?}");
    // 134 glitches; those 0.125 mm or less from a pole pair's edge (X
    // starts and ends on one) pass as Index pulses, the rest are counted
    // as glitches; the Index only cross-checks, no position moved.
    assert_eq!(pid.glitches_injected, 134);
    assert!(pid.glitches_counted >= 90, "{pid:?}");
    // The loop gave back on the way out what it added on the way in.
    assert!(pid.corrections.iter().all(|c| c.abs() <= 2), "{pid:?}");
}

#[test]
fn the_robust_pid_stays_below_the_thesis_at_2_5_and_10_mm_s() {
    let slow = circle(&PID_0_5, 2.5);
    assert_eq!(slow.error, None);
    assert!(slow.mse_total < 0.00008, "{slow:?}");
    // At 10 mm/s the loop leaves more (0.0006 mm², as much on rigid
    // carriages: docs/benchmarks.md): still seven times below the thesis'
    // 5 mm/s figure.
    let fast = circle(&PID_0_5, 10.0);
    assert_eq!(fast.error, None);
    assert!(fast.mse_total < THESIS_BEST_MSE_MM2 / 6.0, "{fast:?}");
    assert!(fast.mse_total > slow.mse_total, "{fast:?}");
}

#[test]
fn the_p_loop_leaves_the_first_order_error_of_the_lost_k_prime() {
    // Correction u = Kp·e on top of the planner's steps: the carriage
    // moves k'·(ẋd + u), so ė = (1 − k')·ẋd − k'·Kp·e. On the circle ẋd is
    // a sine of v at ω = v/r: e is a sine of (1 − k')·v / |jω + k'·Kp|,
    // its mean square half that squared.
    let run = circle(&P_4_3, 5.0);
    assert_eq!(run.error, None);
    let omega = 5.0 / CIRCLE_RADIUS_MM;
    for (axis, mse) in [run.mse_x, run.mse_y].into_iter().enumerate() {
        let pole = THESIS_GAIN[axis] * 4.3;
        let model = (LOST[axis] * 5.0).powi(2) / (pole * pole + omega * omega) / 2.0;
        assert!((mse / model - 1.0).abs() < 0.12, "axis {axis}: {mse} against the model's {model}");
    }
    // Above the thesis' best and far below open loop.
    assert!(run.mse_total > THESIS_BEST_MSE_MM2 && run.mse_total < 0.02, "{run:?}");
}

#[test]
fn open_loop_misses_the_circle_by_the_lost_k_prime_and_s0_stops_the_job() {
    // Loops off: the carriage travels k' of the path from (60, 50):
    // X misses 0.1 × 10 × (1 − cos φ), Y 0.06 × 10 × sin φ; their mean
    // squares over a turn are 1.5 and 0.18 mm².
    let open = circle(&OPEN_LOOP, 5.0);
    assert_eq!(open.error, None);
    let r2 = CIRCLE_RADIUS_MM * CIRCLE_RADIUS_MM;
    let (model_x, model_y) = (LOST[0] * LOST[0] * r2 * 1.5, LOST[1] * LOST[1] * r2 * 0.5);
    assert!((open.mse_x / model_x - 1.0).abs() < 0.01, "{open:?}");
    assert!((open.mse_y / model_y - 1.0).abs() < 0.01, "{open:?}");
    // `M821 S0` corrects nothing and supervises: X is 1 mm short a quarter
    // turn in (π/2 × r / v = 3.14 s), and the limit holds 0.5 s.
    let supervised = circle(&SUPERVISED, 5.0);
    let (at, line) = supervised.error.expect("a following error");
    assert!(line.starts_with("Error:X following error -1.") && line.ends_with("job stopped (re-home with G28)"), "{line}");
    let expected = std::f64::consts::FRAC_PI_2 * CIRCLE_RADIUS_MM / 5.0 + 0.5;
    assert!((at - expected).abs() < 0.05, "stopped at {at} s, expected {expected} s");
}
