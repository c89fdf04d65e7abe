//! The executor, specified by conversations: lines in, exact replies out.

use super::*;
use super::commands::{self, Halted, Kind};
use super::modal::AXES;
use crate::line::LineAssembler;
use crate::reply::test_support::Text;
use crate::storage::MemoryStorage;
use crate::motion::{MotionConfig, StepQueues, StepperStatus};
use std::boxed::Box;
use std::format;
use std::string::String;

/// An executor for the Prusa i3 whose step interrupt never runs (for
/// commands that do not wait for motion; hal-sim's board steps).
pub(super) fn new_machine() -> Machine<'static> {
    let queues: &'static mut StepQueues = Box::leak(Box::new(StepQueues::new()));
    let config = MotionConfig::prusa_i3();
    let (feeder, _generator) = queues.split(config.stepper());
    Machine::new(Motion::new(config, feeder))
}

/// Feed `input` byte by byte as the board does, polling at `now_ms`
/// (motion first, then the executor, as in the boards' main loops: an
/// acknowledged move is planned by the next motion poll).
pub(super) fn converse(machine: &mut Machine, now_ms: u32, input: &str) -> String {
    let mut out = Text::default();
    let mut assembler = LineAssembler::new();
    for &byte in input.as_bytes() {
        assert!(machine.can_accept_line());
        if let Some(line) = assembler.push(byte) {
            machine.receive_line(line, &mut out).unwrap();
        }
        machine.poll_motion(&StepperStatus::default(), now_ms, &mut out).unwrap();
        machine.poll(now_ms, &mut MemoryStorage::<512>::new(), &mut out).unwrap();
    }
    out.0
}

fn reply(input: &str) -> String {
    converse(&mut new_machine(), 0, input)
}

#[test]
fn every_line_gets_one_ok_after_its_output() {
    assert_eq!(reply("G90\nM83\nG21\n"), "ok\nok\nok\n");
    assert_eq!(reply("M9999 S1\n"), "echo:Unknown command: \"M9999 S1\"\nok\n");
    assert_eq!(reply("; only a comment\n"), "ok\n");
}

#[test]
fn m105_carries_its_ok_on_the_report_line() {
    assert_eq!(reply("M105\n"), "ok T:0.00 /0.00 B:0.00 /0.00 @:0 B@:0\n");
}

#[test]
fn malformed_lines_get_an_error_then_ok_and_nothing_changes() {
    let mut machine = new_machine();
    for (line, error) in [
        ("G92 X1.2.3\n", "Error:Bad number after X\nok\n"),
        ("G92 x1e30\n", "Error:Bad number after X\nok\n"),
        ("G1 X10 F0\n", "Error:Invalid feed rate (F must be > 0)\nok\n"),
        ("G1 X10 F-100\n", "Error:Invalid feed rate (F must be > 0)\nok\n"),
        ("G1 X\n", "Error:Missing value after X\nok\n"),
        ("G1 (oops X1\n", "Error:Unterminated comment\nok\n"),
        // NUL is the receive ring's lost-bytes marker: the line is refused
        // as damaged in reception (a NUL from the wire never is the marker:
        // the receive ring stores it as 0xFF, see `rx::NUL_ON_THE_WIRE`).
        ("G1 X1 \u{0}\n", "Error:Serial receive overrun, line lost (checksum not verified)\nok\n"),
        ("G1 X\u{e9}\n", "Error:Unexpected character (byte 195)\nok\n"),
        ("G92 X3000000\n", "Error:Value out of range for X\nok\n"),
    ] {
        assert_eq!(converse(&mut machine, 0, line), error, "for {line:?}");
    }
    assert_eq!(machine.modal().logical_position(), [0; AXES]);
    assert_eq!(machine.modal().feed_um_per_s, 25_000);
}

#[test]
fn a_three_hundred_byte_line_is_refused_and_the_next_line_works() {
    let long = format!("G1 X1 ({})\nM114\n", "x".repeat(300));
    assert_eq!(reply(&long), "Error:Line too long\nok\nX:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0 \nok\n".replace(" \nok", "\nok"));
}

/// Issue 22, finding 4: Marlin ignores a `;` comment whatever its
/// length; only the command before it must fit.
#[test]
fn an_overlong_semicolon_comment_is_ignored() {
    let long = format!("G1 X1 ;{}\nM114\n", "x".repeat(300));
    assert_eq!(reply(&long), "ok\nX:1.00 Y:0.00 Z:0.00 E:0.00 Count X:100 Y:0 Z:0\nok\n");
}

#[test]
fn garbage_then_a_numbered_stream_resumes_with_resends() {
    let mut machine = new_machine();
    let garbage = converse(&mut machine, 0, "\u{1}\u{2}zz%%\n");
    assert_eq!(garbage, "Error:Unexpected character (byte 1)\nok\n");
    let n1 = checksummed("N1 M110 N0");
    assert_eq!(converse(&mut machine, 0, &format!("{n1}\n")), "ok\n");
    assert_eq!(converse(&mut machine, 0, &format!("{}\n", checksummed("N1 G91"))), "ok\n");
    // A corrupted line: checksum error and a resend of the same number.
    assert_eq!(
        converse(&mut machine, 0, "N2 G92 X9*0\n"),
        "Error:checksum mismatch, Last Line: 1\nResend: 2\nok\n"
    );
    assert_eq!(converse(&mut machine, 0, &format!("{}\n", checksummed("N2 G92 X9"))), "ok\n");
    assert_eq!(machine.modal().logical_position()[0], 9_000);
}

fn checksummed(line: &str) -> String {
    let sum = line.bytes().fold(0u8, |s, b| s ^ b);
    format!("{line}*{sum}")
}

#[test]
fn modal_state_follows_g90_g91_m82_m83_g20_g21_g92() {
    let mut machine = new_machine();
    converse(&mut machine, 0, "G92 X10 E5\nG91\nM82\nG20\n");
    let modal = machine.modal();
    assert_eq!(modal.logical_position(), [10_000, 0, 0, 5_000]);
    assert_eq!((modal.distance, modal.extruder_distance, modal.units), (Distance::Relative, Distance::Absolute, Units::Inches));
}

#[test]
fn the_feed_rate_persists_between_lines_in_mm_per_minute() {
    let mut machine = new_machine();
    converse(&mut machine, 0, "G1 X1 F1200\nG1 X2\n");
    assert_eq!(machine.modal().feed_um_per_s, 20_000);
}

#[test]
fn g4_blocks_the_queue_and_reports_busy_every_two_seconds() {
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "G4 S5\nM114\n"), "");
    let mut out = Text::default();
    for now in [1_000, 2_000, 3_999, 4_000, 4_999] {
        machine.poll(now, &mut MemoryStorage::<512>::new(), &mut out).unwrap();
    }
    assert_eq!(out.0, "echo:busy: processing\necho:busy: processing\n");
    machine.poll(5_000, &mut MemoryStorage::<512>::new(), &mut out).unwrap();
    assert!(out.0.ends_with("busy: processing\nok\nX:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0\nok\n"), "{}", out.0);
}

/// Issue 22, finding 6: a line waiting for room in the planner got no
/// `busy` (OctoPrint timed out after 6.4 s of silence).
#[test]
fn a_line_waiting_for_the_planner_hears_busy_every_two_seconds_and_m113_sets_it() {
    let mut machine = new_machine();
    let mut out = Text::default();
    let mut assembler = LineAssembler::new();
    let storage = &mut MemoryStorage::<512>::new();
    let mut x = 0;
    // The step interrupt never runs: the planner fills, then lines wait.
    while machine.can_accept_line() && x < 200 {
        x += 1;
        for &b in format!("G1 X{x}\n").as_bytes() {
            if let Some(l) = assembler.push(b) {
                machine.receive_line(l, &mut out).unwrap();
            }
        }
        machine.poll_motion(&StepperStatus::default(), 0, &mut out).unwrap();
        machine.poll(0, storage, &mut out).unwrap();
    }
    assert!(!machine.can_accept_line(), "the planner never filled");
    out.0.clear();
    for now in [1_000, 1_999, 2_000, 3_000, 4_000] {
        machine.poll(now, storage, &mut out).unwrap();
    }
    assert_eq!(out.0, "echo:busy: processing\necho:busy: processing\n");
    // M113 S0 (taken once the queue moves) stops it; M113 S1 sets 1 s.
    let mut m = new_machine();
    assert_eq!(converse(&mut m, 0, "M113\n"), "echo:M113 S2\nok\n");
    assert_eq!(converse(&mut m, 0, "M113 S0\nM113\n"), "ok\necho:M113 S0\nok\n");
    assert_eq!(converse(&mut m, 0, "G4 S5\n"), "");
    let mut out = Text::default();
    for now in [2_000, 4_000] {
        m.poll(now, storage, &mut out).unwrap();
    }
    assert_eq!(out.0, "");
    assert_eq!(converse(&mut m, 0, "M113 S61\n"), "");
    let mut out = Text::default();
    m.poll(5_000, storage, &mut out).unwrap();
    m.poll(5_000, storage, &mut out).unwrap();
    assert_eq!(out.0, "ok\nError:Value out of range for S\nok\n");
}

/// Issue 22, finding 4: PrusaSlicer's M73 got `Unknown command`; M115
/// did not say that `( … )` comments are parsed.
#[test]
fn m73_is_accepted_silently_and_m115_reports_paren_comments() {
    assert_eq!(reply("M73 P10 R35\nM73 Q10 S35\n"), "ok\nok\n");
    assert!(reply("M115\n").contains("\nCap:PAREN_COMMENTS:1\n"));
}

#[test]
fn m108_ends_a_wait() {
    let mut machine = new_machine();
    converse(&mut machine, 0, "G4 P60000\n");
    machine.cancel_wait();
    let mut out = Text::default();
    machine.poll(1, &mut MemoryStorage::<512>::new(), &mut out).unwrap();
    assert_eq!(out.0, "ok\n");
}

#[test]
fn the_queue_holds_four_lines_while_a_command_blocks() {
    let mut machine = new_machine();
    let mut out = Text::default();
    let mut assembler = LineAssembler::new();
    for line in ["G4 P100\n", "M114\n", "M114\n", "M114\n", "M114\n"] {
        for &b in line.as_bytes() {
            if let Some(l) = assembler.push(b) {
                machine.receive_line(l, &mut out).unwrap();
            }
        }
        machine.poll(0, &mut MemoryStorage::<512>::new(), &mut out).unwrap();
    }
    assert!(!machine.can_accept_line());
    machine.poll(100, &mut MemoryStorage::<512>::new(), &mut out).unwrap();
    assert_eq!(out.0.matches("ok\n").count(), 5);
}

#[test]
fn m112_halts_and_refuses_everything_after() {
    let mut machine = new_machine();
    let out = converse(&mut machine, 0, "M17\nM112\nG92 X1\n");
    assert_eq!(out, "ok\nError:Printer halted. kill() called!\nok\nError:Printer halted. kill() called!\nok\n");
    assert!(machine.is_halted() && !machine.steppers_enabled());
}

#[test]
fn a_halted_machine_still_echoes_unknown_codes_as_unknown() {
    let mut machine = new_machine();
    converse(&mut machine, 0, "M112\n");
    let out = converse(&mut machine, 0, "M9999 S1\nG1 X1\n");
    assert_eq!(out, "echo:Unknown command: \"M9999 S1\"\nok\nError:Printer halted. kill() called!\nok\n");
}

#[test]
fn settings_commands_change_what_m503_prints() {
    let mut machine = new_machine();
    converse(&mut machine, 0, "M92 X80 E415.5\nM203 Z10\nM201 X1000\nM204 P800 T2000\nM205 J0.02\nM220 S150\n");
    let report = converse(&mut machine, 0, "M503\n");
    assert!(report.contains("echo:  M92 X80.00 Y100.00 Z400.00 E415.50\n"), "{report}");
    assert!(report.contains("echo:  M203 X300.00 Y300.00 Z10.00 E25.00\n"), "{report}");
    assert!(report.contains("echo:  M201 X1000.00 Y3000.00 Z100.00 E10000.00\n"), "{report}");
    assert!(report.contains("echo:  M204 P800.00 R1500.00 T2000.00\n"), "{report}");
    assert!(report.contains("J0.020\n"), "{report}");
    assert!(report.contains("echo:  M220 S150\n"), "{report}");
    assert_eq!(converse(&mut machine, 0, "M502\n"), "echo:Hardcoded Default Settings Loaded\nok\n");
}

#[test]
fn m303_refuses_each_word_out_of_its_range() {
    for (line, expected) in [
        ("M303 E1 S200\n", "Error:Value out of range for E\nok\n"),
        ("M303 E-2\n", "Error:Value out of range for E\nok\n"),
        ("M303 S0\n", "Error:Value out of range for S\nok\n"),
        ("M303 E-1 S400.6\n", "Error:Value out of range for S\nok\n"),
        ("M303 C2\n", "Error:Value out of range for C\nok\n"),
        ("M303 C20.5\n", "Error:Value out of range for C\nok\n"),
        ("M303 E5 C2\n", "Error:Value out of range for E\nok\n"),
        ("M303 U\n", "Error:Missing value after U\nok\n"),
    ] {
        assert_eq!(reply(line), expected, "{line}");
    }
    assert_eq!(reply("M303 E0.4 S399.5 C2.5 U-7\n"), "PID Autotune start\n");
}

#[test]
fn m301_refuses_bad_gains_and_keeps_the_old_ones() {
    let mut machine = new_machine();
    for (line, expected) in [
        ("M301 P-1\n", "Error:Value out of range for P\nok\n"),
        ("M301 I-0.5 D3\n", "Error:Value out of range for P\nok\n"),
        ("M301 D300000\n", "Error:Value out of range for D\nok\n"),
        ("M301 P1 I\n", "Error:Missing value after I\nok\n"),
        ("M301 P1 I2 D\n", "Error:Missing value after D\nok\n"),
    ] {
        assert_eq!(converse(&mut machine, 0, line), expected, "{line}");
    }
    assert_eq!(converse(&mut machine, 0, "M301\n"), "echo:M301 P22.20 I1.08 D114.00\nok\n");
    assert_eq!(converse(&mut machine, 0, "M301 D0.5\nM301\n"), "ok\necho:M301 P22.20 I1.08 D0.50\nok\n");
}

#[test]
fn m302_sets_and_reports_the_cold_extrusion_interlock() {
    let mut machine = new_machine();
    for (line, expected) in [
        ("M302\n", "echo:Cold extrudes are disabled (min temp 170C)\nok\n"),
        ("M302 S1001\n", "Error:Value out of range for S\nok\n"),
        ("M302 S-1\n", "Error:Value out of range for S\nok\n"),
        ("M302 S\n", "Error:Missing value after S\nok\n"),
        ("M302 S180 P\n", "Error:Missing value after P\nok\n"),
        ("M302\n", "echo:Cold extrudes are disabled (min temp 170C)\nok\n"),
        ("M302 S0\n", "ok\n"),
        ("M302\n", "echo:Cold extrudes are enabled (min temp 0C)\nok\n"),
        ("M302 P-2\n", "ok\n"),
        ("M302\n", "echo:Cold extrudes are enabled (min temp 0C)\nok\n"),
        ("M302 S1000.4 P0\n", "ok\n"),
        ("M302\n", "echo:Cold extrudes are disabled (min temp 1000C)\nok\n"),
    ] {
        assert_eq!(converse(&mut machine, 0, line), expected, "{line}");
    }
}

#[test]
fn invalid_settings_are_refused_whole() {
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "M92 X80 Y-1\n"), "Error:Value out of range for Y\nok\n");
    assert_eq!(machine.settings().steps_per_mm_milli[0], 100_000);
    assert_eq!(converse(&mut machine, 0, "M220 S0\n"), "Error:Value out of range for S\nok\n");
}

#[test]
fn every_settings_word_reaches_its_field_and_a_refused_one_changes_nothing() {
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "M204 S900\n"), "ok\n");
    let s = machine.settings();
    assert_eq!((s.print_accel_um_per_s2, s.retract_accel_um_per_s2, s.travel_accel_um_per_s2), (900_000, 1_500_000, 900_000));
    // P and T on the same line as S win over it.
    assert_eq!(converse(&mut machine, 0, "M204 T300 S800 P700 R600\n"), "ok\n");
    let s = machine.settings();
    assert_eq!((s.print_accel_um_per_s2, s.retract_accel_um_per_s2, s.travel_accel_um_per_s2), (700_000, 600_000, 300_000));
    assert_eq!(converse(&mut machine, 0, "M205 S1.5 T2 B30000 J0.3\nM221 S90\nM203 E30 X200\nM201 Z50 Y2000\n"), "ok\nok\nok\nok\n");
    let s = machine.settings().clone();
    assert_eq!((s.min_feed_um_per_s, s.min_travel_feed_um_per_s, s.min_segment_time_us, s.junction_deviation_um), (1_500, 2_000, 30_000, 300));
    assert_eq!((s.feed_percent, s.flow_percent), (100, 90));
    assert_eq!(s.max_feed_um_per_s, [200_000, 300_000, 5_000, 30_000]);
    assert_eq!(s.max_accel_um_per_s2, [3_000_000, 2_000_000, 50_000, 10_000_000]);
    // Each refusal names the first bad word, in the command's order, and
    // leaves every value as it was, the valid words' too.
    for (line, reply) in [
        ("M205 S3 J0.301\n", "Error:Value out of range for J\nok\n"),
        ("M205 J0 S3\n", "Error:Value out of range for J\nok\n"),
        ("M205 T-1 S3\n", "Error:Value out of range for T\nok\n"),
        ("M205 S3 B1000001\n", "Error:Value out of range for B\nok\n"),
        ("M204 P5 S0\n", "Error:Value out of range for S\nok\n"),
        ("M204 P5 T\n", "Error:Missing value after T\nok\n"),
        ("M221 S1000\n", "Error:Value out of range for S\nok\n"),
        ("M203 X1 E0\n", "Error:Value out of range for E\nok\n"),
    ] {
        assert_eq!(converse(&mut machine, 0, line), reply, "{line}");
        assert_eq!(machine.settings(), &s, "{line}");
    }
    // Words a command does not take are ignored, as before.
    assert_eq!(converse(&mut machine, 0, "M220 S120 X5\n"), "ok\n");
    assert_eq!(machine.settings().feed_percent, 120);
}

#[test]
fn m118_echoes_text() {
    assert_eq!(reply("M118 hello world\n"), "hello world\nok\n");
    assert_eq!(reply("M118 E1 line 7\n"), "echo:line 7\nok\n");
    assert_eq!(reply("M118 e1 lower\n"), "echo:lower\nok\n");
    assert_eq!(reply("M118 E1\n"), "E1\nok\n");
    assert_eq!(reply("M118 E12 x\n"), "E12 x\nok\n");
    assert_eq!(reply("M118 E1 \n"), "echo:\nok\n");
}

#[test]
fn m119_reports_each_endstop() {
    let mut machine = new_machine();
    machine.set_endstop_levels(0b00_0001);
    let report = converse(&mut machine, 0, "M119\n");
    assert_eq!(
        report,
        "Reporting endstop status\nx_min: TRIGGERED\nx_max: open\ny_min: open\ny_max: open\nz_min: open\nz_max: open\nok\n"
    );
}

#[test]
fn m155_reports_temperatures_on_its_own() {
    let mut machine = new_machine();
    converse(&mut machine, 0, "M155 S2\n");
    let mut out = Text::default();
    machine.poll(1_999, &mut MemoryStorage::<512>::new(), &mut out).unwrap();
    assert_eq!(out.0, "");
    machine.poll(2_000, &mut MemoryStorage::<512>::new(), &mut out).unwrap();
    assert_eq!(out.0, " T:0.00 /0.00 B:0.00 /0.00 @:0 B@:0\n");
}

#[test]
fn tool_changes_accept_only_existing_extruders() {
    assert_eq!(reply("T0\n"), "ok\n");
    assert_eq!(reply("T1\n"), "echo:T1 Invalid extruder\nok\n");
}

#[test]
fn fan_commands_set_the_duty() {
    let mut machine = new_machine();
    converse(&mut machine, 0, "M106 S128\n");
    assert_eq!(machine.fan_duty(), 128);
    converse(&mut machine, 0, "M106\n");
    assert_eq!(machine.fan_duty(), 255);
    assert_eq!(converse(&mut machine, 0, "M106 S256\n"), "Error:Value out of range for S\nok\n");
    converse(&mut machine, 0, "M107\n");
    assert_eq!(machine.fan_duty(), 0);
}

/// Issue 22, finding 2: `F300` after an arc was refused with `Missing R
/// word`; a line without axis words moves nothing, and its F is modal.
#[test]
fn a_feed_only_line_after_an_arc_moves_nothing_and_sets_the_feed() {
    // The arc modes as a `G2`/`G3` leaves them (with no step interrupt
    // here, a real arc fills the planner and the next line waits).
    for mode in [MotionMode::ClockwiseArc, MotionMode::CounterClockwiseArc] {
        let mut machine = new_machine();
        machine.modal.motion_mode = mode;
        assert_eq!(converse(&mut machine, 0, "F300\n"), "ok\n");
        assert_eq!(machine.modal().feed_um_per_s, 5_000);
        assert_eq!(converse(&mut machine, 0, " F600 (feed)\n"), "ok\n");
        assert_eq!(machine.modal().feed_um_per_s, 10_000);
        assert_eq!(converse(&mut machine, 0, "F0\n"), "Error:Invalid feed rate (F must be > 0)\nok\n");
        assert_eq!(machine.modal().logical_position(), [0; AXES]);
        assert_eq!(machine.modal().motion_mode, mode);
    }
    // An arc followed by its feed line, as dxf2gcode writes them.
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "G2 X1 Y1 I1\n"), "ok\n");
    assert_eq!(machine.modal().logical_position()[..2], [1_000, 1_000]);
}

#[test]
fn arcs_need_a_centre_or_a_radius() {
    assert_eq!(reply("G2 X10 Y10\n"), "Error:Missing R word\nok\n");
    // Every word is read (in the order I, J, R) before the centre is chosen.
    assert_eq!(reply("G2 X10 I5 R\n"), "Error:Missing value after R\nok\n");
    assert_eq!(reply("G2 X10 J R5 I\n"), "Error:Missing value after I\nok\n");
    assert_eq!(reply("G2 X10 I5 R99999999\n"), "Error:Value out of range for R\nok\n");
    // A centre offset wins over R; R alone is the radius.
    assert_eq!(reply("G2 X10 Y10 R10\n"), "ok\n");
    assert_eq!(reply("G3 X10 Y10 I5 J5 R1\n"), "ok\n");
    assert_eq!(reply("G2 X10 J5\n"), "Error:Arc end is not on the circle\nok\n");
    assert_eq!(reply("G2 X10 R-10\n"), "ok\n");
}

#[test]
fn m500_saves_and_m501_restores_over_later_changes() {
    let mut machine = new_machine();
    let mut eeprom = MemoryStorage::<4096>::new();
    let mut out = Text::default();
    let mut send = |machine: &mut Machine, line: &str, out: &mut Text| {
        let mut assembler = LineAssembler::new();
        for &b in line.as_bytes() {
            if let Some(l) = assembler.push(b) {
                machine.receive_line(l, out).unwrap();
            }
        }
        machine.poll(0, &mut eeprom, out).unwrap();
    };
    send(&mut machine, "M92 X80\nM500\n", &mut out);
    assert!(out.0.starts_with("ok\necho:Settings Stored (145 bytes; crc "), "{}", out.0);
    send(&mut machine, "M92 X90\nM501\n", &mut out);
    assert!(out.0.contains("echo:V3 stored settings retrieved (145 bytes; crc "), "{}", out.0);
    assert_eq!(machine.settings().steps_per_mm_milli[0], 80_000);
}

#[test]
fn a_corrupt_image_at_boot_is_reported_and_the_defaults_stay() {
    let mut eeprom = MemoryStorage::<4096>::new();
    let mut custom = Settings::default();
    custom.steps_per_mm_milli[0] = 80_000;
    crate::storage::save(&mut eeprom, &custom).unwrap();
    eeprom.bytes[20] ^= 0x10;
    let mut machine = new_machine();
    let mut out = Text::default();
    machine.load_settings(&mut eeprom, &mut out).unwrap();
    assert!(out.0.starts_with("echo:EEPROM CRC mismatch - (stored) "), "{}", out.0);
    assert!(out.0.ends_with("echo:Hardcoded Default Settings Loaded\n"), "{}", out.0);
    assert_eq!(machine.settings(), &Settings::default());
}

#[test]
fn an_image_of_another_layout_is_reported_with_both_versions() {
    let mut eeprom = MemoryStorage::<4096>::new();
    crate::storage::save(&mut eeprom, &Settings::default()).unwrap();
    eeprom.bytes[2] = 1;
    let mut machine = new_machine();
    let mut out = Text::default();
    machine.load_settings(&mut eeprom, &mut out).unwrap();
    assert!(out.0.starts_with("echo:EEPROM version mismatch (EEPROM=V1 Firmware=V3)\n"), "{}", out.0);
    assert_eq!(machine.settings(), &Settings::default());
}

#[test]
fn each_machine_starts_from_its_own_defaults_and_m502_restores_them() {
    let queues: &'static mut StepQueues = Box::leak(Box::new(StepQueues::new()));
    let config = MotionConfig::spec_delta(false);
    let (feeder, _generator) = queues.split(config.stepper());
    let mut machine = Machine::new(Motion::new(config, feeder));
    assert_eq!(machine.settings().steps_per_mm_milli, [80_000, 80_000, 80_000, 102_000]);
    assert_eq!(machine.settings().max_feed_um_per_s[0], 150_000);
    assert_eq!(converse(&mut machine, 0, "M92 X100\nM502\n"), "ok\necho:Hardcoded Default Settings Loaded\nok\n");
    assert_eq!(machine.settings().steps_per_mm_milli[0], 80_000);
}

/// PrusaSlicer's first lines: `M115 U<version>` asks for the capabilities
/// (Marlin answers them), `M862.x` checks are Prusa-only codes with quoted
/// arguments: echoed as unknown, never an `Error:` a host would treat as
/// fatal.
#[test]
fn slicer_checks_get_marlins_answers_not_errors() {
    let caps = reply("M115 U3.13.0\n");
    assert!(caps.starts_with("FIRMWARE_NAME:Ferrostep "), "{caps}");
    assert!(caps.ends_with("ok\n") && !caps.contains("Error"), "{caps}");
    // (quotes inside the echoed command print as `?`, as every
    // non-printable byte does, so the quoted form stays unambiguous)
    assert_eq!(reply("M862.3 P \"MK3S\"\n"), "echo:Unknown command: \"M862.3 P ?MK3S?\"\nok\n");
    assert_eq!(reply("M862.1 P0.4\n"), "echo:Unknown command: \"M862.1 P0.4\"\nok\n");
    assert_eq!(reply("M23 model.gco\n"), "echo:Unknown command: \"M23 model.gco\"\nok\n");
    // A command we run still refuses arguments that do not parse.
    assert_eq!(reply("G1 X1.2.3\n"), "Error:Bad number after X\nok\n");
}

#[test]
fn m304_sets_the_bed_gains_which_m503_reports() {
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "M304\n"), "echo:M304 P10.00 I0.023 D305.40\nok\n");
    assert_eq!(converse(&mut machine, 0, "M304 P20 I1.5 D300\n"), "ok\n");
    let report = converse(&mut machine, 0, "M503\n");
    assert!(report.contains("echo:  M301 P22.20 I1.08 D114.00\necho:; Bed PID:\necho:  M304 P20.00 I1.50 D300.00\n"), "{report}");
    // The hot end keeps its own.
    assert_eq!(converse(&mut machine, 0, "M301\n"), "echo:M301 P22.20 I1.08 D114.00\nok\n");
}

#[test]
fn the_status_screen_shows_state_z_and_heaters() {
    let screen = |machine: &Machine| {
        let bytes = machine.status_screen();
        (std::string::String::from_utf8_lossy(&bytes[..16]).into_owned(), std::string::String::from_utf8_lossy(&bytes[16..]).into_owned())
    };
    let mut machine = new_machine();
    assert_eq!(screen(&machine), ("Ready      Z0.00".into(), "T0/0 B0/0       ".into()));
    converse(&mut machine, 0, "M104 S210\nG92 Z12.345\n");
    assert_eq!(screen(&machine), ("Ready     Z12.35".into(), "T0/210 B0/0     ".into()));
    converse(&mut machine, 0, "M112\n");
    assert_eq!(screen(&machine).0, "Halted    Z12.35");
}

/// CAM programs (Fusion 360, FreeCAD and others for Grbl) put several
/// modes on one line, open and close with `%`, and end with `M2`/`M30`.
#[test]
fn cam_preambles_set_their_modes_and_get_one_ok_per_line() {
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "%\nG90 G94\nG17\nG21\nG17 G91\n"), "ok\nok\nok\nok\nok\n");
    assert_eq!(machine.modal().distance, Distance::Relative);
    assert_eq!(converse(&mut machine, 0, "G54\nG40 G49 G80\nM5\nM9\nG90 G17 G21\n"), "ok\nok\nok\nok\nok\n");
    assert_eq!(machine.modal().distance, Distance::Absolute);
    assert_eq!(converse(&mut machine, 0, "S10000 M3\n"), "echo:M3 ignored: no spindle or coolant on this machine\nok\n");
}

#[test]
fn a_mode_set_on_a_move_line_applies_to_that_move() {
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "G92 X10\nG91 G0 X5\n"), "ok\nok\n");
    assert_eq!(machine.modal().logical_position()[0], 15_000);
    assert_eq!(converse(&mut machine, 0, "G0 X5 G90\n"), "ok\n");
    assert_eq!(machine.modal().logical_position()[0], 5_000);
}

/// Inverse-time feed (`G93`) is not run: a program that asks for it gets
/// an error, and its moves are refused (not run at a feed it did not mean)
/// until it switches back to `G94`.
#[test]
fn inverse_time_feed_is_refused_and_holds_moves_until_g94() {
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "G93 G1 X6 F2\n"), "Error:G93 is not supported: moves are refused until G94\nok\n");
    assert_eq!(converse(&mut machine, 0, "G1 X5\n"), "Error:G93 is not supported: moves are refused until G94\nok\n");
    assert_eq!(machine.modal().logical_position()[0], 0);
    assert_eq!(converse(&mut machine, 0, "G94\nG1 X6\n"), "ok\nok\n");
    assert_eq!(machine.modal().logical_position()[0], 6_000);
}

/// Grbl's work coordinates: `G10 L2 P<n>` puts system n's zero at machine
/// coordinates, `G10 L20` so that the machine stands at the given place in
/// it; `G54`–`G59` choose; `G92` shifts on top; `G53` ignores both.
#[test]
fn work_coordinate_systems_follow_grbl() {
    let mut machine = new_machine();
    // G55's zero at machine (10, 20, 0).
    assert_eq!(converse(&mut machine, 0, "G10 L2 P2 X10 Y20\nG55\nG0 X0 Y0\n"), "ok\nok\nok\n");
    assert_eq!(machine.modal().position[..2], [10_000, 20_000]);
    assert_eq!(machine.modal().logical_position()[..2], [0, 0]);
    // G54 is still the machine frame.
    assert_eq!(converse(&mut machine, 0, "G54\nG0 X5\n"), "ok\nok\n");
    assert_eq!(machine.modal().position[0], 5_000);
    // L20: here (machine X 5) is X 1 in G56: its zero is at machine 4.
    assert_eq!(converse(&mut machine, 0, "G10 L20 P3 X1\nG56\nG0 X2\n"), "ok\nok\nok\n");
    assert_eq!(machine.modal().position[0], 6_000);
    // G92 on top, G53 ignores both, M2 returns to G54.
    assert_eq!(converse(&mut machine, 0, "G92 X0\nG0 X1\n"), "ok\nok\n");
    assert_eq!(machine.modal().position[0], 7_000);
    assert_eq!(converse(&mut machine, 0, "G53 G0 X3\n"), "ok\n");
    assert_eq!(machine.modal().position[0], 3_000);
    assert_eq!(converse(&mut machine, 0, "G10 L3 P1 X0\nG10 L2 P7 X0\n"), "Error:Value out of range for L\nok\nError:Value out of range for P\nok\n");
    assert_eq!(machine.modal().work, 2);
}


/// In G18 the centre comes from K and I (Grbl): a J offset is not one.
#[test]
fn a_g18_arc_reads_its_centre_from_k_and_i() {
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "G18\nG2 X10 J5\n"), "ok\nError:Missing R word\nok\n");
    assert_eq!(machine.modal().plane, modal::Plane::Zx);
    assert_eq!(machine.modal().logical_position(), [0; AXES]);
    assert_eq!(converse(&mut machine, 0, "G17\n"), "ok\n");
    assert_eq!(machine.modal().plane, modal::Plane::Xy);
}

#[test]
fn m2_and_m30_end_the_program_and_restore_the_default_modes() {
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "G91\nG18\nG93\nG57\nM30\n"), "ok\nok\nError:G93 is not supported: moves are refused until G94\nok\nok\nok\n");
    assert_eq!(machine.modal().work, 0);
    assert_eq!(machine.modal().distance, Distance::Absolute);
    assert_eq!(machine.modal().plane, modal::Plane::Xy);
    assert_eq!(machine.modal().unsupported, None);
    assert_eq!(converse(&mut machine, 0, "M2\n"), "ok\n");
}

/// G53: this line's target in machine coordinates, whatever G92 shifted
/// or G91 set; the next line is back in the program's frame.
#[test]
fn g53_moves_in_machine_coordinates_for_its_own_line() {
    let mut machine = new_machine();
    assert_eq!(converse(&mut machine, 0, "G1 X20 Z5 F600\nG92 X0 Z0\nG91\n"), "ok\nok\nok\n");
    assert_eq!(converse(&mut machine, 0, "G53 G0 Z10\n"), "ok\n");
    assert_eq!(machine.modal().position[..3], [20_000, 0, 10_000]);
    assert_eq!(machine.modal().logical_position()[..3], [0, 0, 5_000]);
    // Back to relative, shifted coordinates.
    assert_eq!(converse(&mut machine, 0, "G0 Z1\n"), "ok\n");
    assert_eq!(machine.modal().position[2], 11_000);
    assert_eq!(converse(&mut machine, 0, "G53 G2 X1 I1\n"), "Error:G53 moves with G0 or G1 only\nok\n");
    assert_eq!(machine.modal().position[..3], [20_000, 0, 11_000]);
}

#[test]
fn m503_reports_every_setting_in_marlins_layout() {
    let mut machine = new_machine();
    converse(&mut machine, 0, "M92 X80.125 E415.5\nM205 B1234 J0.007 S0.005 T0.004\nM221 S99\nM204 R1234.5678\n");
    let report = converse(&mut machine, 0, "M503\n");
    assert_eq!(report, M503_EXPECTED, "{report}");
}

/// `M503` after the settings of the test above, exactly.
const M503_EXPECTED: &str = concat!(
    "echo:; Steps per unit:\n",
    "echo:  M92 X80.13 Y100.00 Z400.00 E415.50\n",
    "echo:; Max feedrates (units/s):\n",
    "echo:  M203 X300.00 Y300.00 Z5.00 E25.00\n",
    "echo:; Max Acceleration (units/s2):\n",
    "echo:  M201 X3000.00 Y3000.00 Z100.00 E10000.00\n",
    "echo:; Acceleration (units/s2) (P<print-accel> R<retract-accel> T<travel-accel>):\n",
    "echo:  M204 P1500.00 R1234.57 T1500.00\n",
    "echo:; Advanced (B<min_segment_time_us> S<min_feedrate> T<min_travel_feedrate> J<junc_dev>):\n",
    "echo:  M205 B1234 S0.01 T0.00 J0.007\n",
    "echo:; Feedrate and flow:\n",
    "echo:  M220 S100\n",
    "echo:  M221 S99\n",
    "echo:; Hotend PID:\n",
    "echo:  M301 P22.20 I1.08 D114.00\n",
    "echo:; Bed PID:\n",
    "echo:  M304 P10.00 I0.023 D305.40\n",
    "ok\n",
);

#[test]
fn the_default_machine_file_is_the_prusa_i3_the_simulator_runs() {
    // machines/prusa-i3.toml, generated into `machine_file`, and the
    // `MotionConfig::prusa_i3` fixture that hal-sim and the tests use are
    // one machine: a change to either shows here.
    assert_eq!(crate::machine_file::MOTION, MotionConfig::prusa_i3());
    assert_eq!(crate::machine_file::NAME, "Prusa i3");
    assert_eq!(crate::machine_file::BAUD, 115_200);
    assert_eq!(crate::machine_file::ENDSTOP_TRIGGER_LEVELS, 0b11_1111);
    let [hotend, bed] = crate::machine_file::heaters();
    let (hotend, hotend_gains) = hotend.unwrap();
    let (bed, bed_gains) = bed.unwrap();
    assert_eq!((hotend_gains, bed_gains), (Gains::MARLIN_HOTEND, Gains::MARLIN_BED));
    let (file, stock) = (hotend.load(), HOTEND_0.load());
    assert_eq!((file.guard, file.control, file.output, file.id), (stock.guard, stock.control, stock.output, stock.id));
    let (file, stock) = (bed.load(), BED.load());
    assert_eq!((file.guard, file.control, file.output, file.id), (stock.guard, stock.control, stock.output, stock.id));
}

#[test]
fn m115_names_the_machine_files_machine() {
    let mut out = Text(String::new());
    new_machine().write_capabilities(&mut out).unwrap();
    assert!(out.0.contains(" MACHINE_TYPE:Prusa i3 EXTRUDER_COUNT:1\n"), "{}", out.0);
}

/// A delta's calibration survives a reset: `M665`/`M666` are settings,
/// saved by `M500`, loaded at boot, printed by `M503`, and `M502`
/// returns to the machine's own geometry.
#[test]
fn a_deltas_m665_and_m666_are_saved_loaded_and_reported() {
    let delta = || {
        let queues: &'static mut StepQueues = Box::leak(Box::new(StepQueues::new()));
        let config = MotionConfig::spec_delta(false);
        let (feeder, _generator) = queues.split(config.stepper());
        Machine::new(Motion::new(config, feeder))
    };
    let mut eeprom = MemoryStorage::<4096>::new();
    let mut machine = delta();
    let mut out = Text::default();
    for line in ["M665 L360.5 R226 H298.25\n", "M666 X-1.2 Y0 Z0.75\n", "M500\n"] {
        let mut assembler = LineAssembler::new();
        for &b in line.as_bytes() {
            if let Some(l) = assembler.push(b) {
                machine.receive_line(l, &mut out).unwrap();
            }
        }
        machine.poll(0, &mut eeprom, &mut out).unwrap();
    }
    assert!(out.0.contains("echo:Settings Stored (145 bytes;"), "{}", out.0);

    let mut rebooted = delta();
    let mut out = Text::default();
    rebooted.load_settings(&mut eeprom, &mut out).unwrap();
    assert!(out.0.contains("stored settings retrieved"), "{}", out.0);
    let crate::motion::kinematics::MachineKinematics::Delta(loaded) = rebooted.motion.config.kinematics else { panic!("a delta") };
    assert_eq!((loaded.rod_length(), loaded.radius(), loaded.homed_height), (360.5, 226.0, 298.25));
    assert_eq!(loaded.endstop_trim, [-1.2, 0.0, 0.75]);
    let report = converse(&mut rebooted, 0, "M503\n");
    assert!(report.contains("echo:  M665 L360.50 R226.00 H298.25\n"), "{report}");
    assert!(report.contains("echo:  M666 X-1.20 Y0.00 Z0.75\n"), "{report}");

    converse(&mut rebooted, 0, "M502\n");
    let crate::motion::kinematics::MachineKinematics::Delta(restored) = rebooted.motion.config.kinematics else { panic!("a delta") };
    assert_eq!((restored.rod_length(), restored.radius(), restored.homed_height), (361.0, 227.0, 300.0));
    assert_eq!(restored.endstop_trim, [0.0; 3]);
}

// --- the command table (issue 24) ------------------------------------------

fn powder_bed() -> Machine<'static> {
    let mut machine = new_machine();
    machine.become_powder_bed();
    machine
}

fn extrusion_line() -> Machine<'static> {
    let mut machine = new_machine();
    machine.become_extrusion_line();
    machine
}

#[test]
fn a_malformed_m880_on_the_powder_bed_is_refused_not_echoed_as_unknown() {
    assert_eq!(converse(&mut powder_bed(), 0, "M880 F1.2.3\n"), "Error:Bad number after F\nok\n");
    assert_eq!(converse(&mut powder_bed(), 0, "M10 S1.2.3\n"), "Error:Bad number after S\nok\n");
}

#[test]
fn a_malformed_line_command_is_refused_not_echoed_as_unknown() {
    assert_eq!(converse(&mut extrusion_line(), 0, "M860 S1.2.3\n"), "Error:Bad number after S\nok\n");
    assert_eq!(converse(&mut extrusion_line(), 0, "M404 W1.2.3\n"), "Error:Bad number after W\nok\n");
}

#[test]
fn a_halted_powder_bed_refuses_its_jobs_and_its_suction() {
    let mut bed = powder_bed();
    converse(&mut bed, 0, "M112\n");
    let halted = "Error:Printer halted. kill() called!\nok\n";
    for line in ["M880\n", "M881\n", "M882 S1\n", "M10\n", "M825\n"] {
        assert_eq!(converse(&mut bed, 0, line), halted, "for {line:?}");
    }
    assert!(!bed.powder_bed().unwrap().is_busy());
}

#[test]
fn a_halted_extrusion_line_refuses_its_commands_and_still_reports() {
    let mut line = extrusion_line();
    converse(&mut line, 0, "M112\n");
    let halted = "Error:Printer halted. kill() called!\nok\n";
    for command in ["M405\n", "M406\n", "M860 S1\n", "M863 S5\n"] {
        assert_eq!(converse(&mut line, 0, command), halted, "for {command:?}");
    }
    assert!(converse(&mut line, 0, "M407\n").starts_with("echo:"));
}

#[test]
fn codes_of_another_machine_are_unknown_on_a_printer() {
    for code in ["M10", "M404", "M407", "M860", "M880", "M116"] {
        assert_eq!(reply(&format!("{code}\n")), format!("echo:Unknown command: \"{code}\"\nok\n"));
    }
}

/// A fresh machine of each kind, as the boards make them.
fn machine_of(kind: Kind) -> Machine<'static> {
    match kind {
        Kind::Printer => new_machine(),
        Kind::Line => extrusion_line(),
        Kind::Bed => powder_bed(),
    }
}

std::thread_local! {
    /// Set: the dispatch runs codes no row lists (see `Machine::dispatch`).
    pub(super) static GATE_OPEN: core::cell::Cell<bool> = const { core::cell::Cell::new(false) };
}

/// Every code a table could list (and a few past the bitmap), as sent.
fn every_code() -> impl Iterator<Item = (Code, String)> {
    let numbers = || (0..=1_000).chain([2_000, u16::MAX]);
    numbers()
        .map(|n| (Code::G(n), format!("G{n}")))
        .chain(numbers().map(|n| (Code::M(n), format!("M{n}"))))
        .chain([(Code::T(0), "T0".into()), (Code::T(7), "T7".into()), (Code::Modal, "X1".into()), (Code::Other, "M862.3".into())])
}

fn unknown(text: &str) -> String {
    format!("echo:Unknown command: \"{text}\"\nok\n")
}

#[test]
fn every_listed_code_is_dispatched_and_every_other_is_unknown() {
    for kind in commands::KINDS {
        assert_eq!(machine_of(kind).kind(), kind);
        let mut listed = 0;
        for (code, text) in every_code() {
            // Bare, and with an argument that does not parse: a listed
            // code refuses it, an unlisted one is echoed whatever follows.
            let bare = converse(&mut machine_of(kind), 0, &format!("{text}\n"));
            let malformed_text = format!("{text} Q1.2.3");
            let malformed = converse(&mut machine_of(kind), 0, &format!("{malformed_text}\n"));
            if commands::listing(code, kind).is_some() {
                listed += 1;
                assert!(!bare.contains("Unknown command"), "{kind:?} lists {text} but does not run it: {bare:?}");
                if code != Code::M(115) && !matches!(code, Code::M(117 | 118)) {
                    assert_eq!(malformed, "Error:Bad number after Q\nok\n", "{kind:?} {malformed_text}");
                }
            } else {
                assert_eq!(bare, unknown(&text), "{kind:?}");
                assert_eq!(malformed, unknown(&malformed_text), "{kind:?}");
                // The table is not only a gate: without it, the code
                // still reaches no handler.
                GATE_OPEN.set(true);
                let ungated = converse(&mut machine_of(kind), 0, &format!("{text}\n"));
                GATE_OPEN.set(false);
                assert_eq!(ungated, unknown(&text), "{kind:?} runs {text} but does not list it");
            }
        }
        // Not a vacuous walk: the core alone lists about ninety codes.
        assert!(listed > 80, "{kind:?}: {listed} codes");
    }
}

#[test]
fn the_halted_policy_comes_from_the_table() {
    let halted = "Error:Printer halted. kill() called!\nok\n";
    for kind in commands::KINDS {
        for (code, text) in every_code() {
            let Some(policy) = commands::listing(code, kind) else { continue };
            let mut machine = machine_of(kind);
            converse(&mut machine, 0, "M112\n");
            let reply = converse(&mut machine, 0, &format!("{text}\n"));
            match policy {
                Halted::Refused => assert_eq!(reply, halted, "{kind:?} {text}"),
                Halted::Runs => assert_ne!(reply, halted, "{kind:?} {text}"),
            }
        }
    }
    // The answers hosts rely on while halted, spelled out.
    for code in ["G4", "M105", "M108", "M110", "M112", "M113", "M114", "M115", "M117", "M118", "M119", "M410", "M503"] {
        let text = code.strip_prefix(['G', 'M']).unwrap().parse().unwrap();
        let code = if code.starts_with('G') { Code::G(text) } else { Code::M(text) };
        assert_eq!(commands::listing(code, Kind::Printer), Some(Halted::Runs), "{code:?}");
    }
    assert_eq!(commands::listing(Code::M(407), Kind::Line), Some(Halted::Runs));
}

/// `M115` on the Prusa i3 (the host build's printer), exactly: the table
/// names Marlin's capabilities in Marlin's order.
const M115_PRINTER: &str = concat!(
    "Cap:SERIAL_XON_XOFF:0\nCap:BINARY_FILE_TRANSFER:0\nCap:EEPROM:1\nCap:VOLUMETRIC:0\nCap:AUTOREPORT_TEMP:1\n",
    "Cap:AUTOREPORT_POS:0\nCap:PROGRESS:0\nCap:PRINT_JOB:0\nCap:AUTOLEVEL:0\nCap:Z_PROBE:0\nCap:LEVELING_DATA:0\n",
    "Cap:SOFTWARE_POWER:0\nCap:TOGGLE_LIGHTS:0\nCap:EMERGENCY_PARSER:1\nCap:HOST_ACTION_COMMANDS:0\nCap:PROMPT_SUPPORT:0\n",
    "Cap:SDCARD:0\nCap:AUTOREPORT_SD_STATUS:0\nCap:THERMAL_PROTECTION:1\nCap:MOTION_MODES:0\nCap:ARCS:1\n",
    "Cap:BABYSTEPPING:0\nCap:CHAMBER_TEMPERATURE:0\nCap:PAREN_COMMENTS:1\n",
);

#[test]
fn m115_names_what_the_tables_list_for_each_machine() {
    let firmware = format!(
        "FIRMWARE_NAME:Ferrostep {} (Rust) SOURCE_CODE_URL:local PROTOCOL_VERSION:1.0 MACHINE_TYPE:Prusa i3 EXTRUDER_COUNT:1\n",
        crate::FIRMWARE_VERSION
    );
    assert_eq!(reply("M115\n"), format!("{firmware}{M115_PRINTER}Cap:CLOSED_LOOP:1\nok\n"));
    assert_eq!(converse(&mut extrusion_line(), 0, "M115\n"), format!("{firmware}{M115_PRINTER}Cap:EXTRUSION_LINE:1\nok\n"));
    assert_eq!(converse(&mut powder_bed(), 0, "M115\n"), format!("{firmware}{M115_PRINTER}Cap:POWDER_BED:1\nCap:CLOSED_LOOP:1\nok\n"));
    // PrusaSlicer's version check: the same reply, whatever the arguments.
    assert_eq!(converse(&mut powder_bed(), 0, "M115 U3.13.0\n"), converse(&mut powder_bed(), 0, "M115\n"));
}

// --- the settings declaration (issue 24) --------------------------------------

#[test]
fn every_configured_figure_lands_in_its_default_setting() {
    let mut config = MotionConfig::prusa_i3();
    config.steps_per_mm = [1.0, 2.0, 3.0, 4.0];
    config.max_feed = [5.0, 6.0, 7.0, 8.0];
    config.max_accel = [9.0, 10.0, 11.0, 12.0];
    config.print_accel = 13.0;
    config.retract_accel = 14.0;
    config.travel_accel = 15.0;
    config.junction_deviation = 0.0165;
    let mut slot = MaybeUninit::uninit();
    init_defaults(&mut slot, &config);
    // SAFETY: `init_defaults` writes the whole value.
    let settings = unsafe { slot.assume_init() };
    assert_eq!(settings.steps_per_mm_milli, [1000, 2000, 3000, 4000]);
    assert_eq!(settings.max_feed_um_per_s, [5000, 6000, 7000, 8000]);
    assert_eq!(settings.max_accel_um_per_s2, [9000, 10000, 11000, 12000]);
    assert_eq!((settings.print_accel_um_per_s2, settings.retract_accel_um_per_s2, settings.travel_accel_um_per_s2), (13000, 14000, 15000));
    assert_eq!(settings.junction_deviation_um, 17);
    let prusa = Settings::prusa_i3();
    assert_eq!(settings.min_segment_time_us, prusa.min_segment_time_us);
    assert_eq!((settings.hotend_pid, settings.bed_pid), (prusa.hotend_pid, prusa.bed_pid));
}

#[test]
fn the_prusa_i3s_machine_file_gives_the_prusa_i3s_defaults() {
    assert_eq!(new_machine().settings(), &Settings::prusa_i3());
}
