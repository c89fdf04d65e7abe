//! Heaters end to end on the simulated board: G-code in, the thermal core
//! driving the 40 W hot-end plant and a bed plant through the RAMPS
//! thermistor divider, replies out. Every protection is injected on the
//! plant or the sensor and must end with the heater off, Marlin's `Error:`
//! line naming the fault, and the machine halted.

use hal_sim::board::{SimBoard, Thermistor};
use hal_sim::thermal_plant::{HeaterPlant, PlantModel};

fn booted() -> SimBoard {
    SimBoard::booted()
}

/// Run until `text` shows up in the output or `max_ms` pass; the output.
fn run_until_output(board: &mut SimBoard, text: &str, max_ms: u32) -> String {
    let mut output = String::new();
    for _ in 0..max_ms {
        board.advance(1);
        output.push_str(&board.take_output());
        if output.contains(text) {
            break;
        }
    }
    output
}

fn assert_halted_and_cold(board: &mut SimBoard) {
    assert!(board.link.machine.is_halted());
    assert_eq!(board.link.machine.heater_duties(), (0, 0));
    let refused = board.run_gcode("M104 S200\nG1 X10\n", 1_000);
    assert_eq!(refused, "Error:Printer halted. kill() called!\nok\nError:Printer halted. kill() called!\nok\n");
    // Reports still work.
    assert!(board.run_gcode("M105\n", 1_000).starts_with("ok T:"));
}

#[test]
fn m109_heats_the_hot_end_and_answers_ok_once_held_at_the_target() {
    let mut board = booted();
    let output = board.run_gcode("M109 S200\n", 400_000);
    assert!(output.ends_with("ok\n"), "{output}");
    // Marlin's keep-alive while heating, once a second, with the
    // residency countdown once within the window.
    assert!(output.starts_with(" T:"), "{output}");
    assert!(output.contains(" W:?\n") && output.contains(" W:9\n"), "{output}");
    let t = board.hotend_plant.temperature_c();
    assert!((t - 200.0).abs() < 2.0, "{t}");
    let report = board.run_gcode("M105\n", 1_000);
    assert!(report.starts_with("ok T:19") || report.starts_with("ok T:20"), "{report}");
    assert!(report.contains(" /200.00 B:"), "{report}");
}

#[test]
fn m190_heats_the_bed_and_m140_s0_turns_it_off() {
    let mut board = booted();
    let output = board.run_gcode("M190 S60\n", 900_000);
    assert!(output.ends_with("ok\n"), "{output}");
    assert!((board.bed_plant.temperature_c() - 60.0).abs() < 2.0);
    board.run_gcode("M140 S0\n", 1_000);
    assert_eq!(board.link.machine.heater_duties().1, 0);
}

#[test]
fn a_thermistor_that_opens_halts_within_a_second() {
    let mut board = booted();
    board.run_gcode("M104 S200\n", 5_000);
    board.hotend_sensor = Thermistor::Count(1023);
    let output = run_until_output(&mut board, "kill() called", 1_000);
    assert!(output.contains("Error:MINTEMP triggered (thermistor open), system stopped! Heater_ID: 0\n"), "{output}");
    assert_halted_and_cold(&mut board);
}

#[test]
fn a_shorted_bed_thermistor_halts_within_a_second() {
    let mut board = booted();
    board.bed_sensor = Thermistor::Count(0);
    let output = run_until_output(&mut board, "kill() called", 1_000);
    assert!(output.contains("Error:MAXTEMP triggered (thermistor shorted), system stopped! Heater_ID: bed\n"), "{output}");
    assert_halted_and_cold(&mut board);
}

#[test]
fn a_heater_that_does_not_heat_is_caught_by_the_watch_period() {
    let mut board = booted();
    board.hotend_plant.disconnect_heater();
    board.receive(b"M104 S200\n");
    let output = run_until_output(&mut board, "kill() called", 30_000);
    assert!(output.contains("Error:Heating failed, system stopped! Heater_ID: 0\n"), "{output}");
    // Marlin's watch: 2 °C within 20 s.
    assert!(board.now_ms() >= 20_000 && board.now_ms() <= 21_500, "{}", board.now_ms());
    assert_halted_and_cold(&mut board);
}

#[test]
fn a_heater_lost_while_holding_is_a_thermal_runaway() {
    let mut board = booted();
    board.run_gcode("M109 S200\n", 400_000);
    let reached = board.now_ms();
    board.hotend_plant.disconnect_heater();
    let output = run_until_output(&mut board, "kill() called", 120_000);
    assert!(output.contains("Error:Thermal Runaway, system stopped! Heater_ID: 0\n"), "{output}");
    // Issue 22: within 20 s (was 4 °C below the target for 40 s, ≈ 45 s):
    // below the band and still falling 8 s later.
    let after = board.now_ms() - reached;
    assert!(after <= 20_000, "{after} ms");
    assert_halted_and_cold(&mut board);
}

#[test]
fn a_heater_stuck_on_is_caught_at_the_maximum_temperature() {
    let mut board = booted();
    // A shorted MOSFET: full power whatever the firmware says.
    board.hotend_plant.stick_output(1.0);
    let output = run_until_output(&mut board, "kill() called", 400_000);
    assert!(output.contains("Error:MAXTEMP triggered, system stopped! Heater_ID: 0\n"), "{output}");
    assert!(board.hotend_plant.temperature_c() >= 275.0 && board.hotend_plant.temperature_c() < 285.0);
    assert!(board.link.machine.is_halted());
}

#[test]
fn m303_tunes_the_hot_end_and_u1_applies_the_gains() {
    let mut board = booted();
    let output = board.run_gcode("M303 E0 S200 C5 U1\n", 900_000);
    assert!(output.starts_with("PID Autotune start\n"), "{output}");
    assert!(output.contains("PID Autotune finished! Put the last Kp, Ki and Kd constants from below into Configuration.h\n"), "{output}");
    assert!(output.contains("#define DEFAULT_Kp "), "{output}");
    assert!(output.ends_with("ok\n"), "{output}");
    let kp = output.lines().find_map(|l| l.strip_prefix("#define DEFAULT_Kp ")).unwrap().to_string();
    let report = board.run_gcode("M503\n", 2_000);
    assert!(report.contains(&format!("echo:  M301 P{kp} I")), "{report}");
    assert_eq!(board.link.machine.heater_duties().0, 0, "the heater is off after the tune");
}

#[test]
fn m302_p1_allows_cold_extrusion_and_m302_reports() {
    let mut board = booted();
    assert_eq!(board.run_gcode("M302\n", 1_000), "echo:Cold extrudes are disabled (min temp 170C)\nok\n");
    assert_eq!(board.run_gcode("G1 E5 F600\nM400\n", 5_000), "echo: cold extrusion prevented\nok\nok\n");
    assert_eq!(board.steps.positions()[3], 0);
    assert_eq!(board.run_gcode("M302 P1\nM302\n", 1_000), "ok\necho:Cold extrudes are enabled (min temp 170C)\nok\n");
    board.run_gcode("G1 E10 F600\nM400\n", 5_000);
    // 93 steps/mm: the 5 mm from E5 to E10.
    assert_eq!(board.steps.positions()[3], 465);
}

#[test]
fn m112_turns_the_heaters_off_at_once() {
    let mut board = booted();
    board.run_gcode("M104 S200\nM140 S60\n", 3_000);
    assert!(board.link.machine.heater_duties().0 > 0);
    board.inject(b"M112\n");
    board.advance(2);
    assert_eq!(board.link.machine.heater_duties(), (0, 0));
}

#[test]
fn m155_reports_every_n_seconds() {
    let mut board = booted();
    board.run_gcode("M155 S2\n", 10);
    board.take_output();
    board.advance(4_100);
    let output = board.take_output();
    assert_eq!(output.matches(" T:").count(), 2, "{output}");
}

/// Issue 22, finding 7: a PrusaSlicer start sets Marlin's stock bed gains
/// and waits for 60 °C on a 200 W bed with a 600 s time constant. The
/// PID backs off to ≈ 0.38 duty from 50 °C and gains under 2 °C a minute;
/// it used to be halted for `Heating failed … Heater_ID: bed` at ≈ 51 °C.
/// Now `M190` waits for it (≈ 20 min: the stock gains' tiny Ki) and ends
/// with `ok`.
#[test]
fn m190_with_the_slicers_bed_gains_reaches_60_on_a_slow_200w_bed() {
    let mut board = booted();
    board.bed_plant = HeaterPlant::new(PlantModel::BED_200W);
    assert_eq!(board.run_gcode("M304 P10 I0.023 D305.4\n", 1_000), "ok\n");
    let output = board.run_gcode("M190 S60\n", 1_800_000);
    assert!(!output.contains("Error:"), "{output}");
    assert!(output.ends_with("ok\n"), "{}", &output[output.len().saturating_sub(300)..]);
    assert!(!board.link.machine.is_halted());
    let t = board.bed_plant.temperature_c();
    assert!((t - 60.0).abs() < 1.5, "{t}");
    println!("M190 S60 with the stock bed gains: ok after {} s", board.now_ms() / 1000);
}

/// The same bed with its heater's wire cut: at full power it gains
/// nothing, and the watch (2 °C in 60 s) still halts it.
#[test]
fn m190_on_a_dead_bed_heater_is_still_a_heating_failure() {
    let mut board = booted();
    board.bed_plant = HeaterPlant::new(PlantModel::BED_200W);
    board.bed_plant.disconnect_heater();
    board.receive(b"M190 S60\n");
    let output = run_until_output(&mut board, "kill() called", 90_000);
    assert!(output.contains("Error:Heating failed, system stopped! Heater_ID: bed\n"), "{output}");
    assert!(board.now_ms() >= 60_000 && board.now_ms() <= 61_500, "{}", board.now_ms());
    assert_halted_and_cold(&mut board);
}
