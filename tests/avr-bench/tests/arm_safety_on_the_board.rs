//! The arm's own ELF (`machines/arm.toml`) on the simulated Mega 2560 with
//! its safety circuit (SPEC §3): the light curtain's relay trips in the
//! middle of a move, every STEP line falls silent at once, the host is told
//! which input tripped, moves and `G28` are refused until the re-arm button
//! is pressed with the curtain clear, and the arm moves again once homed.
//! The emergency stop is told apart.

use avr_bench::bench::{self, exchange};
use avr_bench::board::{Board, Endstop, RampsConfig, ARM_SAFETY_CLEAR, CPU_HZ, EMERGENCY_STOP_PIN, REARM_PIN, SAFETY_RELAY_PIN, X, Y, Z};
use avr_bench::build::shipped_elf;
use avr_bench::host::HostConfig;
use std::path::PathBuf;

fn elf() -> PathBuf {
    shipped_elf("arm")
}

fn replies(board: &mut Board, lines: &[&str]) -> Vec<String> {
    let all = exchange(board, lines, 90.0).unwrap_or_else(|e| panic!("{e}"));
    all.into_iter().filter(|r| !r.starts_with("echo:busy")).collect()
}

/// Replies that arrived since `from` (an index into the host's replies).
fn said_since(board: &Board, from: usize) -> Vec<String> {
    board.host().replies[from..].iter().map(|r| r.text.clone()).filter(|t| !t.starts_with("echo:busy")).collect()
}

/// A normally-closed switch (open = high = pressed) at `at_steps`.
fn nc(axis: usize, at_steps: i64, is_min: bool) -> Option<Endstop> {
    Some(Endstop { axis, at_steps, is_min, pressed_level: true })
}

/// The six NC limit switches: the three home switches (X max, Y max, Z
/// min) 300 steps from the start when `homing`, else out of the way (the
/// bench's switches are not the arm's geometry; the host tests check the
/// homing itself).
fn switches(board: &mut Board, homing: bool) {
    let far = 1_000_000;
    let near = if homing { 300 } else { far };
    for (slot, switch) in [
        (0, nc(X, -far, true)),
        (1, nc(X, near, false)),
        (2, nc(Y, -far, true)),
        (3, nc(Y, near, false)),
        (4, nc(Z, -near, true)),
        (5, nc(Z, far, false)),
    ] {
        board.set_endstop(slot, switch);
    }
}

fn home(board: &mut Board) {
    switches(board, true);
    assert_eq!(replies(board, &["G28"]), ["ok"]);
    switches(board, false);
}

fn press(board: &mut Board, pin: avr_bench::board::Pin, level: bool) {
    board.drive_input(pin, Some(level));
    board.run_for_ms(20.0);
}

#[test]
fn a_relay_trip_mid_move_stops_every_step_and_needs_rearm_and_home() {
    let mut config = RampsConfig::stock(115_200);
    config.host = HostConfig::raw(115_200);
    config.inputs = ARM_SAFETY_CLEAR.to_vec();
    let mut board = bench::boot(&elf(), config).expect("the arm boots");
    home(&mut board);

    // A long move (≈ 127 mm at up to 50 mm/s); the relay trips 1 s into it,
    // at speed.
    let start = [X, Y, Z].map(|a| board.position(a));
    board.send(["G1 Y0 Z0 F3000"]);
    board.run_for_ms(1000.0);
    let moving = [X, Y, Z].map(|a| board.position(a));
    assert!(moving[1] != start[1] && moving[2] != start[2], "the joints are moving: {start:?} → {moving:?}");
    let before = board.host().replies.len();
    let tripped_at = board.cycle();
    board.drive_input(SAFETY_RELAY_PIN, Some(true));
    board.run_for_ms(1000.0);
    let stopped = [X, Y, Z].map(|a| board.position(a));
    // The last STEP edge of any motor after the trip.
    let last_edge = [X, Y, Z]
        .iter()
        .filter_map(|&a| board.step_edges(a).last().map(|e| e.cycle))
        .max()
        .unwrap();
    let latency_us = (last_edge as f64 - tripped_at as f64) * 1e6 / f64::from(CPU_HZ);
    // The step rates at the trip: the edges of the last 10 ms before it.
    let window = u64::from(CPU_HZ) / 100;
    let rates = [X, Y, Z].map(|a| board.step_edges(a).iter().filter(|e| e.rising && e.cycle < tripped_at && e.cycle + window >= tripped_at).count() * 100);
    eprintln!("relay trip → last STEP edge: {latency_us:+.0} µs (rates at the trip {rates:?} steps/s); stopped at {stopped:?} (moving at {moving:?})");
    // Within one pass of the main loop, which reads the inputs (the arm's
    // passes are long: each cuts a segment through the kinematics).
    assert!(latency_us < 5000.0, "a STEP edge {latency_us:.0} µs after the trip");
    let said = said_since(&board, before);
    assert_eq!(said, ["Error:Safety relay tripped: motion stopped, re-arm then home with G28"], "{said:?}");

    // Refused, naming the relay; not one step.
    let refusal = "Error:Safety relay tripped: clear the light curtain, press re-arm, then G28";
    assert_eq!(replies(&mut board, &["G1 Y10 Z10"]), [refusal, "ok"]);
    assert_eq!(replies(&mut board, &["G28"]), [refusal, "ok"]);
    // Re-arm while the curtain is still broken: ignored.
    let before = board.host().replies.len();
    press(&mut board, REARM_PIN, false);
    press(&mut board, REARM_PIN, true);
    assert_eq!(said_since(&board, before), ["echo:Re-arm ignored: a safety input is still active"]);
    assert_eq!(replies(&mut board, &["G1 Y10 Z10"]), [refusal, "ok"]);
    // Curtain clear, re-arm: G28 is allowed, moves wait for it.
    let before = board.host().replies.len();
    press(&mut board, SAFETY_RELAY_PIN, false);
    press(&mut board, REARM_PIN, false);
    press(&mut board, REARM_PIN, true);
    assert_eq!(said_since(&board, before), ["echo:Safety re-armed: home with G28"]);
    assert_eq!(replies(&mut board, &["G1 Y10 Z10"]), ["Error:Position unknown after a motion stop: home with G28 first", "ok"]);
    assert_eq!([X, Y, Z].map(|a| board.position(a)), stopped, "nothing moved while tripped");
    home(&mut board);
    let homed = [X, Y, Z].map(|a| board.position(a));
    assert_eq!(replies(&mut board, &["G1 Y-50 Z20 F600", "M400"]), ["ok", "ok"]);
    assert_ne!([X, Y, Z].map(|a| board.position(a)), homed, "the arm moves again");

    // The emergency stop, at rest: its own message and refusal.
    let before = board.host().replies.len();
    press(&mut board, EMERGENCY_STOP_PIN, true);
    assert_eq!(said_since(&board, before), ["Error:Emergency stop pressed: motion stopped, release it, re-arm, then home with G28"]);
    assert_eq!(replies(&mut board, &["G1 Y-40"]), ["Error:Emergency stop pressed: release it, press re-arm, then G28", "ok"]);
    assert_eq!(board.stats().resets, 0);
}
