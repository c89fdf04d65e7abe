//! The delta's own ELF (`machines/delta.toml`) on the simulated Mega 2560:
//! it homes its three carriages up to their MAX switches, moves with each
//! carriage's steps what the inverse kinematics say (checked against the
//! formula in f64 here), and comes back to exactly the same carriage steps
//! after a full circle.

use avr_bench::bench::{self, exchange};
use avr_bench::board::{Board, Endstop, RampsConfig, X, Y, Z};
use avr_bench::build::shipped_elf;
use avr_bench::host::HostConfig;
use std::path::PathBuf;

/// delta.toml: rod 361, radius 227, nozzle offset 64, towers at 0/120/240°,
/// homed height 300, 80 steps/mm.
const ROD: f64 = 361.0;
const RADIUS: f64 = 227.0;
const OFFSET: f64 = 64.0;
const HOMED_HEIGHT: f64 = 300.0;
const STEPS_PER_MM: f64 = 80.0;

/// Carriage heights above the nozzle plane for a nozzle at (x, y, z):
/// h = z + OF + √(L² − (R·cosθ − x)² − (R·sinθ − y)²).
fn carriage_heights(x: f64, y: f64, z: f64) -> [f64; 3] {
    [0.0f64, 120.0, 240.0].map(|angle| {
        let (sin, cos) = angle.to_radians().sin_cos();
        let (dx, dy) = (RADIUS * cos - x, RADIUS * sin - y);
        z + OFFSET + (ROD * ROD - dx * dx - dy * dy).sqrt()
    })
}

fn elf() -> PathBuf {
    shipped_elf("delta")
}

fn replies(board: &mut Board, lines: &[&str]) -> Vec<String> {
    let all = exchange(board, lines, 90.0).unwrap_or_else(|e| panic!("{e}"));
    all.into_iter().filter(|r| !r.starts_with("echo:busy")).collect()
}

/// `Count X:… Y:… Z:…` of an M114 line.
fn counts(m114: &str) -> [i64; 3] {
    let tail = m114.split("Count ").nth(1).unwrap_or_else(|| panic!("{m114}"));
    let mut values = tail.split_whitespace().map(|w| w[2..].parse::<i64>().unwrap());
    [values.next().unwrap(), values.next().unwrap(), values.next().unwrap()]
}

#[test]
fn the_delta_homes_up_moves_by_its_kinematics_and_closes_a_circle_exactly() {
    let mut config = RampsConfig::stock(115_200);
    config.host = HostConfig::raw(115_200);
    config.endstops = [None; 6];
    // Each carriage's MAX switch 500 steps above where it starts.
    for (slot, axis) in [(1, X), (3, Y), (5, Z)] {
        config.endstops[slot] = Some(Endstop { axis, at_steps: 500, is_min: false, pressed_level: true });
    }
    let mut board = bench::boot(&elf(), config).expect("the delta boots");

    let homed = replies(&mut board, &["G28", "M114"]);
    assert_eq!(homed[0], "ok", "{homed:?}");
    assert!(homed[1].starts_with("X:0.00 Y:0.00 Z:300.00 E:0.00 Count "), "{homed:?}");
    let home_counts = counts(&homed[1]);
    let expected_home = carriage_heights(0.0, 0.0, HOMED_HEIGHT).map(|h| (h * STEPS_PER_MM).round() as i64);
    for tower in 0..3 {
        assert!((home_counts[tower] - expected_home[tower]).abs() <= 1, "{home_counts:?} vs {expected_home:?}");
    }
    let at_switches = [X, Y, Z].map(|a| board.position(a));
    assert_eq!(at_switches, [500, 500, 500], "every carriage stopped on its switch");

    // A move: each carriage travels what the kinematics say, ±1 step.
    let moved = replies(&mut board, &["G1 X20 Y-10 Z280 F3000", "M400", "M114"]);
    assert!(moved[2].starts_with("X:20.00 Y:-10.00 Z:280.00 E:0.00 Count "), "{moved:?}");
    let target = carriage_heights(20.0, -10.0, 280.0);
    let home = carriage_heights(0.0, 0.0, HOMED_HEIGHT);
    for (tower, axis) in [X, Y, Z].into_iter().enumerate() {
        let expected = ((target[tower] - home[tower]) * STEPS_PER_MM).round() as i64;
        let travelled = board.position(axis) - at_switches[tower];
        assert!((travelled - expected).abs() <= 1, "tower {tower}: {travelled} steps, kinematics say {expected}");
        assert_eq!(travelled, counts(&moved[2])[tower] - home_counts[tower], "tower {tower}: M114's count is the steps made");
    }

    // A full circle (r 20 around the centre) ends on exactly the steps it
    // started from.
    let start = [X, Y, Z].map(|a| board.position(a));
    let circle = replies(&mut board, &["G2 X20 Y-10 I-20 J10 F3000", "M400", "M114"]);
    assert_eq!(circle[..2], ["ok", "ok"], "{circle:?}");
    assert_eq!([X, Y, Z].map(|a| board.position(a)), start, "{circle:?}");
    assert!(board.stats().resets == 0);
}
