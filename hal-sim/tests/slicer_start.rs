//! A PrusaSlicer start sequence, streamed as a host would send it: every
//! line is answered without an `Error:` (Prusa-only codes are echoed as
//! unknown, as Marlin does), the heaters reach their targets before the
//! purge line, and the purge extrudes exactly what it asks for.

use hal_sim::board::SimBoard;

const START: &str = "\
M862.3 P \"MK3S\" ; printer model check
M862.1 P0.4 ; nozzle diameter check
M115 U3.13.0 ; tell printer latest fw version
M73 P0 R45
M201 X1000 Y1000 Z200 E5000
M203 X200 Y200 Z12 E120
M204 P1250 R1250 T1250
M205 X8.00 Y8.00 Z0.40 E4.50
M107
G90 ; use absolute coordinates
M83 ; extruder relative mode
M104 S215 ; set extruder temp
M140 S60 ; set bed temp
M190 S60 ; wait for bed temp
M109 S215 ; wait for extruder temp
G28 W ; home all without mesh bed level
G80 ; mesh bed leveling
G1 Y-3.0 F1000.0 ; go outside print area
G92 E0.0
G1 X60.0 E9.0 F1000.0 ; intro line
G1 X100.0 E12.5 F1000.0 ; intro line
G92 E0.0
M221 S95
G21 ; set units to millimeters
G1 Z.2 F720
G1 E-.8 F2100
M400
";

#[test]
fn a_prusaslicer_start_sequence_runs_without_errors_and_purges_exactly() {
    let mut board = SimBoard::new();
    board.take_output();
    // Gains for this hot end first (M303 U1), as a user does once: Marlin's
    // stock gains undershoot on the 40 W plant near the target, slowly
    // enough for the heating watch to call it a failure.
    let tune = board.run_gcode("M303 E0 S215 C5 U1\n", 1_500_000);
    assert!(tune.contains("PID Autotune finished!"), "{tune}");
    let output = board.run_gcode(START, 1_500_000);
    assert!(!output.contains("Error"), "{output}");
    let oks = output.lines().filter(|l| *l == "ok" || l.starts_with("ok ")).count();
    assert_eq!(oks, START.lines().count(), "{output}");
    // (PrusaSlicer's G80, Prusa's mesh levelling, is Grbl's "cancel canned
    // cycle" here: accepted, nothing to cancel.)
    for unknown in ["M862.3", "M862.1"] {
        assert!(output.contains(&format!("echo:Unknown command: \"{unknown}")), "{unknown} in {output}");
    }
    // M73 (progress) is accepted silently, as by Marlin without a display
    // (issue 22).
    assert!(!output.contains("M73"), "{output}");
    assert!(output.contains("FIRMWARE_NAME:Ferrostep"));
    // Hot when the purge ran; E: 9 + 12.5 mm at 93 steps/mm (1999.5,
    // rounded), then the 0.8 mm retraction at 95 % flow (70.7 steps).
    assert!((board.hotend_plant.temperature_c() - 215.0).abs() < 3.0);
    assert!((board.bed_plant.temperature_c() - 60.0).abs() < 3.0);
    let e = board.steps.positions()[3];
    assert_eq!(e, 2000 - 71, "{e}");
    // X at 100 mm; Y clamped to 0 by the soft limit (the machine is homed).
    assert_eq!(board.steps.positions()[..2], [10_000, 0]);
}
