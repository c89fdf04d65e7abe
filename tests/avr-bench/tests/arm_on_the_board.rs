//! The arm's own ELF (`machines/arm.toml`) runs SPEC §3's experiment on the
//! simulated Mega 2560: it homes the shoulder (Z), then the elbow (Y), then
//! the lead screw (X), one after the other, and then draws straight lines
//! through the travel box. After each line every joint stands within one
//! pulse of the exact inverse kinematics computed here in f64 (SPEC's
//! formulas verbatim, acos and all) — which checks the firmware's
//! single-precision maths as the AVR runs it: avr-libc's `atan2` and `sqrt`
//! (`firmware/src/motion/math.rs` links them), not the host's libm that
//! `firmware`'s unit tests use. The motors' STEP edges are counted too: the
//! pulses the joints received are the ones `M114` reports.

use avr_bench::bench::{self, exchange};
use avr_bench::board::{Board, Endstop, RampsConfig, ARM_SAFETY_CLEAR, X, Y, Z};
use avr_bench::build::shipped_elf;
use avr_bench::host::HostConfig;
use std::path::PathBuf;

/// arm.toml: 100:1 gearboxes at 400 driver pulses per motor turn, 100
/// steps/mm on the lead screws, home (x, y, z) = (−100, −107, 68).
const PULSES_PER_DEGREE: f64 = 100.0 * 400.0 / 360.0;
const X_STEPS_PER_MM: f64 = 100.0;
const HOME: [f64; 3] = [-100.0, -107.0, 68.0];

/// SPEC §3 in f64: (elbow, shoulder) pulses for the tool at (y, z),
/// rounded to nearest. py = 120 − y, pz = 200 − z,
/// θ2 = −acos((py² + pz² − L1² − L2²)/(2·L1·L2)),
/// θ1 = atan2(pz, py) + atan2(L2·sinθ2, L1 + L2·cosθ2).
fn exact_joint_pulses(y: f64, z: f64) -> [i64; 2] {
    let (l1, l2) = (120.0_f64, 200.0_f64);
    let (py, pz) = (120.0 - y, 200.0 - z);
    let cos2 = (py * py + pz * pz - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
    assert!(cos2.abs() <= 1.0, "({y}, {z}) is out of reach");
    let t2 = -cos2.acos();
    let t1 = pz.atan2(py) + (l2 * t2.sin()).atan2(l1 + l2 * t2.cos());
    [t2, t1].map(|angle| (angle.to_degrees() * PULSES_PER_DEGREE).round() as i64)
}

/// The motor counts (X screw, Y elbow, Z shoulder) of the tool at (x, y, z).
fn exact_counts([x, y, z]: [f64; 3]) -> [i64; 3] {
    let [elbow, shoulder] = exact_joint_pulses(y, z);
    [(x * X_STEPS_PER_MM).round() as i64, elbow, shoulder]
}

fn elf() -> PathBuf {
    shipped_elf("arm")
}

fn replies(board: &mut Board, lines: &[&str]) -> Vec<String> {
    let all = exchange(board, lines, 300.0).unwrap_or_else(|e| panic!("{e}"));
    all.into_iter().filter(|r| !r.starts_with("echo:busy")).collect()
}

/// `Count X:… Y:… Z:…` of an M114 line.
fn counts(m114: &str) -> [i64; 3] {
    let tail = m114.split("Count ").nth(1).unwrap_or_else(|| panic!("{m114}"));
    let mut values = tail.split_whitespace().map(|w| w[2..].parse::<i64>().unwrap());
    [values.next().unwrap(), values.next().unwrap(), values.next().unwrap()]
}

/// A normally-closed switch (open = high = pressed) at `at_steps`.
fn nc(axis: usize, at_steps: i64, is_min: bool) -> Option<Endstop> {
    Some(Endstop { axis, at_steps, is_min, pressed_level: true })
}

/// The first and last rising STEP edge of `axis`, in cycles.
fn span(board: &Board, axis: usize) -> (u64, u64) {
    let rising: Vec<u64> = board.step_edges(axis).iter().filter(|e| e.rising).map(|e| e.cycle).collect();
    (*rising.first().unwrap_or_else(|| panic!("axis {axis} never stepped")), *rising.last().unwrap())
}

#[test]
fn the_arm_homes_z_then_y_then_x_and_its_lines_end_within_a_pulse_of_the_exact_maths() {
    let mut config = RampsConfig::stock(115_200);
    config.host = HostConfig::raw(115_200);
    config.inputs = ARM_SAFETY_CLEAR.to_vec();
    // The home switches (Z min, Y max, X max) 300 steps from where each
    // motor starts; the other ends far away. Normally closed, as on the arm.
    let far = 1_000_000;
    config.endstops = [nc(X, -far, true), nc(X, 300, false), nc(Y, -far, true), nc(Y, 300, false), nc(Z, -300, true), nc(Z, far, false)];
    let mut board = bench::boot(&elf(), config).expect("the arm boots");

    // Moves are refused until homed (SPEC §3: positions invalid until homed).
    let refused = replies(&mut board, &["G1 Y0 Z0"]);
    assert_eq!(refused.len(), 2, "{refused:?}");
    assert!(refused[0].starts_with("Error:"), "{refused:?}");
    assert_eq!([X, Y, Z].map(|a| board.step_count(a)), [0, 0, 0], "nothing moved before homing");

    let homed = replies(&mut board, &["G28", "M114"]);
    assert_eq!(homed[0], "ok", "{homed:?}");
    assert!(homed[1].starts_with("X:-100.00 Y:-107.00 Z:68.00 E:0.00 Count "), "{homed:?}");
    // Homing order: the shoulder finishes before the elbow starts, the
    // elbow before the screw.
    let (z, y, x) = (span(&board, Z), span(&board, Y), span(&board, X));
    eprintln!("homing spans (s): Z {:.2}–{:.2}, Y {:.2}–{:.2}, X {:.2}–{:.2}", z.0 as f64 / 16e6, z.1 as f64 / 16e6, y.0 as f64 / 16e6, y.1 as f64 / 16e6, x.0 as f64 / 16e6, x.1 as f64 / 16e6);
    assert!(z.1 < y.0 && y.1 < x.0, "Z {z:?}, Y {y:?}, X {x:?}");
    // Each motor ends one step inside its switch (Z approached negative,
    // Y and X positive): where the slow back-off releases it.
    let at_home = [299, 299, -299];
    assert_eq!([X, Y, Z].map(|a| board.position(a)), at_home);
    let home_counts = counts(&homed[1]);
    let exact_home = exact_counts(HOME);
    for motor in 0..3 {
        assert!((home_counts[motor] - exact_home[motor]).abs() <= 1, "home: {home_counts:?} vs exact {exact_home:?}");
    }

    // The bench's switches are not the arm's geometry: once homed, every
    // switch goes out of the way of the lines.
    for (slot, switch) in [nc(X, -far, true), nc(X, far, false), nc(Y, -far, true), nc(Y, far, false), nc(Z, -far, true), nc(Z, far, false)].into_iter().enumerate() {
        board.set_endstop(slot, switch);
    }

    // SPEC §3's vectors in the travel box and points around it, each
    // reached by one straight G1 (cut into 0.35 mm pieces, each through
    // the AVR's inverse kinematics).
    let targets: [[f64; 3]; 8] = [
        [0.0, 0.0, 0.0],
        [0.0, 50.0, 10.0],
        [25.0, 110.0, -40.0],
        [25.0, 110.0, 40.0],
        [-40.0, -60.0, 35.0],
        [-40.0, -110.0, 0.0],
        [60.0, 85.5, -22.25],
        [0.0, 0.0, 0.0],
    ];
    let mut worst = 0;
    for target in targets {
        let line = format!("G1 X{} Y{} Z{} F3000", target[0], target[1], target[2]);
        let moved = replies(&mut board, &[line.as_str(), "M400", "M114"]);
        assert_eq!(moved[..2], ["ok", "ok"], "{line}: {moved:?}");
        let expected_text = format!("X:{:.2} Y:{:.2} Z:{:.2} E:0.00 Count ", target[0], target[1], target[2]);
        assert!(moved[2].starts_with(&expected_text), "{line}: {moved:?}");
        let reported = counts(&moved[2]);
        let exact = exact_counts(target);
        assert_eq!(reported[0], exact[0], "{line}: the screw's steps are exact");
        for motor in 1..3 {
            let off = (reported[motor] - exact[motor]).abs();
            worst = worst.max(off);
            assert!(off <= 1, "{line}: counts {reported:?}, exact {exact:?}");
        }
        // The pulses the drivers received are the counts M114 reports.
        for (motor, axis) in [X, Y, Z].into_iter().enumerate() {
            assert_eq!(board.position(axis) - at_home[motor], reported[motor] - home_counts[motor], "{line}: motor {motor}");
        }
        eprintln!("{line}: counts {reported:?}, exact {exact:?}");
    }
    eprintln!("worst joint error after a line: {worst} pulse(s)");
    assert_eq!(board.stats().resets, 0);
}
