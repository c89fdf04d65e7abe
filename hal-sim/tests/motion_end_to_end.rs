//! G-code in, steps out: the executor, planner and step generator together
//! on the simulated board (Prusa i3: 100 steps/mm X/Y, 400 Z, 93 E; the Y
//! motor's direction pin is inverted so +Y is the nozzle's +Y).

use hal_sim::board::SimBoard;

fn booted() -> SimBoard {
    SimBoard::booted()
}

fn homed() -> SimBoard {
    let board = SimBoard::homed().expect("G28 answers ok");
    assert_eq!(board.steps.setup_violations, 0);
    board
}

#[test]
fn g1_x10_makes_exactly_1000_x_steps_and_m114_reports_them() {
    let mut board = homed();
    let start = board.steps.positions();
    let output = board.run_gcode("G1 X10 Y-0 F600\nM400\nM114\n", 10_000);
    assert_eq!(
        output,
        "ok\nok\nX:10.00 Y:0.00 Z:0.00 E:0.00 Count X:1000 Y:0 Z:0\nok\n"
    );
    assert_eq!(board.steps.positions()[0] - start[0], 1000);
    assert_eq!(board.steps.positions()[1..], start[1..]);
}

#[test]
fn m400_answers_only_once_the_move_has_been_stepped_out() {
    let mut board = homed();
    // 100 mm at 100 mm/s with 1500 mm/s² ramps: 1.07 s.
    board.receive(b"G1 X100 F6000\nM400\n");
    let begun = board.now_ms();
    let mut output = String::new();
    while !output.contains("ok\nok\n") {
        board.advance(1);
        output.push_str(&board.take_output());
        assert!(board.now_ms() - begun < 5_000, "{output}");
    }
    let last_step = board.steps.motors[0].last_step().unwrap() / 2_000;
    assert!(
        board.now_ms() as u64 >= last_step,
        "ok at {} ms, last step at {last_step} ms",
        board.now_ms()
    );
    assert!(
        board.now_ms() - begun >= 1_060,
        "{} ms",
        board.now_ms() - begun
    );
    assert_eq!(board.steps.positions()[0], 10_000);
}

#[test]
fn relative_moves_g92_and_inches_land_on_exact_steps() {
    let mut board = homed();
    let output = board.run_gcode(
        "G91\nG1 X5 Y5 Z0.25 F3000\nG1 X-2\nG90\nG92 X0\nG1 X1\nG20\nG1 Y1\nG21\nM114\n",
        20_000,
    );
    assert!(
        output.ends_with("X:1.00 Y:25.40 Z:0.25 E:0.00 Count X:400 Y:2540 Z:100\nok\n"),
        "{output}"
    );
    assert_eq!(board.steps.positions()[..3], [400, 2540, 100]);
}

#[test]
fn a_full_circle_with_g2_ends_where_it_started() {
    let mut board = homed();
    let output = board.run_gcode(
        "G1 X50 Y50 F6000\nG2 X50 Y50 I10 J0 F3000\nG3 X70 Y50 R10\nM400\n",
        30_000,
    );
    assert_eq!(output, "ok\nok\nok\nok\n");
    assert_eq!(board.steps.positions()[..2], [7000, 5000]);
    // The circle passed through (60, 40) and (60, 60), ±1 step.
    let xs: Vec<i64> = board.steps.motors[0]
        .steps
        .iter()
        .scan(0i64, |p, s| {
            *p += s.1 as i64;
            Some(*p)
        })
        .collect();
    assert!(xs.iter().max().unwrap() >= &7000);
}

#[test]
fn soft_limits_clamp_moves_of_homed_axes_like_marlin() {
    let mut board = homed();
    let output = board.run_gcode("G1 X250 Y-10 F12000\nM400\nM114\n", 20_000);
    assert!(
        output.ends_with("X:200.00 Y:0.00 Z:0.00 E:0.00 Count X:20000 Y:0 Z:0\nok\n"),
        "{output}"
    );
    assert_eq!(board.steps.positions()[..2], [20_000, 0]);
}

#[test]
fn a_cold_hot_end_moves_x_but_never_pushes_filament() {
    let mut board = homed();
    // Marlin keeps E = 5 as the position: E4 is a 1 mm retraction.
    let output = board.run_gcode("G1 X10 E5 F600\nG1 E4\nM400\n", 10_000);
    assert_eq!(output, "echo: cold extrusion prevented\nok\nok\nok\n");
    assert_eq!(board.steps.positions()[0], 1000);
    // The retraction ran (93 steps/mm): only E moves backwards.
    assert_eq!(board.steps.positions()[3], -93);
}

#[test]
fn m410_stops_a_move_at_once_and_moves_wait_for_homing() {
    let mut board = homed();
    board.receive(b"G1 X150 F6000\n");
    board.advance(500);
    board.take_output();
    let before = board.steps.positions()[0];
    assert!(before > 0 && before < 15_000, "{before}");
    board.inject(b"M410\n");
    board.advance(20);
    let stopped_at = board.steps.positions()[0];
    assert!(
        stopped_at - before < 300,
        "{} steps after M410",
        stopped_at - before
    );
    board.advance(500);
    assert_eq!(board.steps.positions()[0], stopped_at);
    let output = board.run_gcode("G1 X10\n", 1_000);
    assert!(
        output
            .contains("ok\nError:Position unknown after a motion stop: home with G28 first\nok\n"),
        "{output}"
    );
    assert_eq!(board.steps.positions()[0], stopped_at);
    // Homing makes the machine usable again.
    board.set_endstops(Box::new(move |p: &[i64; 4]| {
        (0..3).filter(|&m| p[m] <= 0).fold(0, |b, m| b | 1 << m)
    }));
    let output = board.run_gcode("G28\nG1 X10\nM400\n", 60_000);
    assert_eq!(
        output.replace("echo:busy: processing\n", ""),
        "ok\nok\nok\n"
    );
    assert_eq!(board.steps.positions()[0], 1000);
}

#[test]
fn m112_during_a_fast_move_stops_the_steps_and_refuses_more() {
    let mut board = homed();
    board.receive(b"G1 X180 F12000\n");
    board.advance(400);
    board.inject(b"M112\n");
    board.advance(2);
    let at = board.steps.positions()[0];
    board.advance(1_000);
    assert_eq!(board.steps.positions()[0], at);
    assert!(board.link.machine.is_halted());
    assert!(!board.link.machine.steppers_enabled());
    let output = board.run_gcode("G1 X0\n", 200);
    assert!(
        output.contains("Error:Printer halted. kill() called!\nok\n"),
        "{output}"
    );
}

#[test]
fn homing_without_a_switch_fails_and_halts() {
    let mut board = booted();
    board.set_endstops(Box::new(|_: &[i64; 4]| 0));
    let output = board.run_gcode("G28 X\n", 120_000);
    assert!(
        output.ends_with("Error:Homing Failed\nError:Printer halted. kill() called!\nok\n"),
        "{output}"
    );
    assert!(board.link.machine.is_halted());
}

#[test]
fn busy_keepalives_go_out_while_homing_takes_long() {
    let mut board = booted();
    // X's switch 150 mm away: the fast approach takes 3 s at 50 mm/s.
    board.set_endstops(Box::new(|p: &[i64; 4]| {
        let mut bits = if p[0] <= -15_000 { 1 } else { 0 };
        bits |= (1..3).filter(|&m| p[m] <= 0).fold(0, |b, m| b | 1 << m);
        bits
    }));
    let output = board.run_gcode("G28\n", 60_000);
    assert!(output.starts_with("echo:busy: processing\n"), "{output}");
    assert!(output.ends_with("ok\n"));
    assert_eq!(board.steps.positions()[0], -15_000);
}

/// SPEC §2's delta on the simulated board: towers home up to their max
/// switches, the nozzle is then at (0, 0, 300); a move straight down moves
/// the three carriages by the same exact amount.
#[test]
fn the_delta_homes_up_and_moves_its_three_carriages_together() {
    use firmware::motion::MotionConfig;
    use hal_sim::board::SimEeprom;
    let mut board = SimBoard::with_machine(MotionConfig::spec_delta(false), SimEeprom::new());
    board.take_output();
    // Max switches 20 mm (1600 steps) above where the carriages start; at
    // them each carriage is 300 + 64 + √(361² − 227²) = 644.7 mm up.
    board.set_endstops(Box::new(|p: &[i64; 4]| (0..3).filter(|&m| p[m] >= 1600).fold(0, |b, m| b | 0x10 << m)));
    let output = board.run_gcode("G28\nM114\n", 60_000);
    assert!(output.ends_with("X:0.00 Y:0.00 Z:300.00 E:0.00 Count X:51576 Y:51576 Z:51576\nok\n"), "{output}");
    let homed = board.steps.positions();
    assert_eq!(homed[..3], [1600, 1600, 1600]);
    board.run_gcode("G1 Z290 F3000\nM400\n", 10_000);
    let down = board.steps.positions();
    for tower in 0..3 {
        assert_eq!(down[tower] - homed[tower], -800, "tower {tower}");
    }
    assert_eq!(board.run_gcode("M665\nM666\n", 1_000), "echo:  M665 L361.00 R227.00 H300.00\nok\necho:  M666 X0.00 Y0.00 Z0.00\nok\n");
    // New trims need a new homing before anything moves.
    let output = board.run_gcode("M666 X-0.5\nG1 Z280\n", 1_000);
    assert!(output.ends_with("Error:Position unknown after a motion stop: home with G28 first\nok\n"), "{output}");
}

/// SPEC §3's arm: nothing moves before homing; G28 homes Z, Y, X and the
/// arm is then at (−100, −107, 68).
#[test]
fn the_arm_refuses_moves_until_homed_then_homes_z_y_x() {
    use firmware::motion::MotionConfig;
    use hal_sim::board::SimEeprom;
    let mut board = SimBoard::with_machine(MotionConfig::spec_arm(400), SimEeprom::new());
    board.take_output();
    assert_eq!(board.run_gcode("G1 X10\n", 1_000), "Error:Home XYZ first (G28)\nok\n");
    assert_eq!(board.steps.positions(), [0, 0, 0, 0]);
    // X max 400 steps up the screw, Y max 300 pulses, Z min −300 pulses.
    board.set_endstops(Box::new(|p: &[i64; 4]| {
        u8::from(p[0] >= 400) << 4 | u8::from(p[1] >= 300) << 5 | u8::from(p[2] <= -300) << 2
    }));
    let output = board.run_gcode("G28\nM114\n", 120_000);
    assert!(output.contains("X:-100.00 Y:-107.00 Z:68.00"), "{output}");
    let first = |m: usize| board.steps.motors[m].first_step().unwrap();
    assert!(first(2) < first(1) && first(1) < first(0), "Z, then Y, then X");
}

/// `M120` (Marlin: endstops on during every move): a switch hit in the
/// middle of a print stops everything, says so, and moves wait for `G28`;
/// `M121` goes back to switches watched only while homing.
#[test]
fn with_m120_a_switch_hit_mid_move_stops_everything_until_homed() {
    let mut board = homed();
    board.run_gcode("G1 X50 F6000\nM400\n", 10_000);
    // The X min switch now also trips 20 mm above its homing position (a
    // misplaced clip, a crash): the move back to X10 runs into it.
    board.set_endstops(Box::new(|p: &[i64; 4]| u8::from(p[0] <= 2000) | (1..3).filter(|&m| p[m] <= 0).fold(0, |b, m| b | 1 << m)));
    let output = board.run_gcode("M120\nG1 X10\n", 10_000);
    assert!(output.contains("Error:Endstop hit during a move (switches 1): motion stopped, home with G28\n"), "{output}");
    let stopped = board.steps.positions()[0];
    assert!((1995..=2000).contains(&stopped), "{stopped}");
    let output = board.run_gcode("G1 X30\n", 1_000);
    assert!(output.contains("Error:Position unknown"), "{output}");
    assert_eq!(board.steps.positions()[0], stopped);
    // M121: the same switch is ignored outside homing again.
    board.set_endstops(Box::new(|p: &[i64; 4]| (0..3).filter(|&m| p[m] <= 0).fold(0, |b, m| b | 1 << m)));
    board.run_gcode("G28\n", 60_000);
    board.set_endstops(Box::new(|p: &[i64; 4]| u8::from(p[0] <= 2000) | (1..3).filter(|&m| p[m] <= 0).fold(0, |b, m| b | 1 << m)));
    let output = board.run_gcode("M121\nG1 X50\nG1 X10\nM400\n", 10_000);
    assert_eq!(output.replace("echo:busy: processing\n", ""), "ok\nok\nok\nok\n");
}

/// A FreeCAD Grbl-post program (preamble with two modes per line, a
/// profile with an arc, `M05`/`M2` postamble), streamed whole: every line
/// answers `ok`, no `Error:`, and the motors land on the exact steps.
#[test]
fn a_cam_program_for_grbl_runs_to_its_exact_end_point() {
    let mut board = homed();
    let program = "%\n(Exported by FreeCAD)\nG17 G90\nG21\n(begin operation: Profile)\nG0 Z5.000\nG0 X10.000 Y10.000\n\
                   G1 Z0.500 F60.000\nG1 X20.000 Y10.000 F300.000\nG1 X20.000 Y20.000\nG2 X10.000 Y20.000 I-5.000 J0.000\n\
                   G1 X10.000 Y10.000\nG91 G0 Z4.5\nG90\nM05\nG17 G90\nM2\n%\n";
    let output = board.run_gcode(program, 120_000);
    let lines = program.lines().count();
    // M2 waits for the moves: busy keep-alives meanwhile, as for M400.
    let replies: String = output.lines().filter(|l| *l != "echo:busy: processing").map(|l| format!("{l}\n")).collect();
    assert_eq!(replies, "ok\n".repeat(lines), "{output}");
    // X 10 mm, Y 10 mm at 100 steps/mm; Z 5 mm at 400.
    assert_eq!(board.steps.positions()[..3], [1000, 1000, 2000]);
    assert_eq!(board.steps.setup_violations, 0);
}

/// Arcs in the ZX (G18) and YZ (G19) planes, as 3D CAM toolpaths use
/// them: centres from the plane's offset words (K I, J K), exact ends.
#[test]
fn g18_and_g19_arcs_land_on_their_exact_end_points() {
    let mut board = homed();
    let output = board.run_gcode(
        "G1 X10 Z10 F600\nG18 G2 X20 Z10 I5 K0\nG2 X10 J5\nG19 G3 Y10 Z10 J5 K0\nM400\nM114\n",
        60_000,
    );
    // Lines waiting for the planner hear `busy` (issue 22): not counted.
    let output: String = output.lines().filter(|l| *l != "echo:busy: processing").map(|l| format!("{l}\n")).collect();
    assert_eq!(
        output,
        "ok\nok\nError:Missing R word\nok\nok\nok\nX:20.00 Y:10.00 Z:10.00 E:0.00 Count X:2000 Y:1000 Z:4000\nok\n"
    );
    assert_eq!(board.steps.positions()[..3], [2000, 1000, 4000]);
}

/// SPEC §3: a driver's ALARM (a closed-loop driver lost sync) stops the
/// job at once, names the motor, and the position is invalid: moves wait
/// for `G28`, which waits until the alarm clears. Releasing the motors
/// (`M18`) invalidates the arm's position the same way.
#[test]
fn a_driver_alarm_stops_the_arm_and_moves_wait_for_a_new_homing() {
    use firmware::motion::MotionConfig;
    use hal_sim::board::SimEeprom;
    let mut board = SimBoard::with_machine(MotionConfig::spec_arm(400), SimEeprom::new());
    board.take_output();
    board.set_endstops(Box::new(|p: &[i64; 4]| u8::from(p[0] >= 400) << 4 | u8::from(p[1] >= 300) << 5 | u8::from(p[2] <= -300) << 2));
    let homed = board.run_gcode("G28\n", 120_000);
    assert_eq!(homed.replace("echo:busy: processing\n", ""), "ok\n");
    // A long move, and 200 ms into it the Y driver alarms.
    board.receive(b"G1 X100 F600\n");
    board.advance(200);
    board.set_driver_alarms(0b0010);
    board.advance(20);
    let stopped_at = board.steps.positions();
    board.advance(500);
    assert_eq!(board.steps.positions(), stopped_at, "every motor stopped");
    let output = board.take_output();
    assert!(output.contains("Error:Driver alarm on Y: motion stopped, home with G28\n"), "{output}");
    assert_eq!(board.run_gcode("G1 X0\n", 1_000), "Error:Position unknown after a motion stop: home with G28 first\nok\n");
    assert_eq!(board.run_gcode("G28\n", 1_000), "Error:A driver ALARM is active: clear it before homing\nok\n");
    board.set_driver_alarms(0);
    let rehomed = board.run_gcode("G28\nM114\n", 120_000);
    assert!(rehomed.contains("X:-100.00 Y:-107.00 Z:68.00"), "{rehomed}");
    // M18 releases the motors: home again.
    assert_eq!(board.run_gcode("M18\nG1 X-90\n", 1_000), "ok\nError:Home XYZ first (G28)\nok\n");
}
