//! The shipped machine files check out, and each kind of mistake a user
//! can make in one is refused with a message naming the file, the key and
//! the problem.

use machine_file::check::{Control, HeaterRole, HomeEnd, Kinematics};
use machine_file::{generate, parse};
use std::path::Path;

fn workspace() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().parent().unwrap()
}

fn shipped(name: &str) -> String {
    std::fs::read_to_string(workspace().join("machines").join(name)).unwrap()
}

/// The Prusa i3's file with `from` replaced by `to` (exactly once).
fn prusa_with(from: &str, to: &str) -> String {
    let text = shipped("prusa-i3.toml");
    assert_eq!(text.matches(from).count(), 1, "{from:?} must occur once in prusa-i3.toml");
    text.replacen(from, to, 1)
}

fn error_of(text: &str) -> String {
    match parse("my-printer.toml", text) {
        Ok(_) => panic!("the file was accepted"),
        Err(message) => message,
    }
}

#[test]
fn every_shipped_machine_file_checks_out_and_generates() {
    let mut names: Vec<_> = std::fs::read_dir(workspace().join("machines"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    names.sort();
    assert!(names.len() >= 6, "{names:?}");
    for path in names {
        let machine = machine_file::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let core = generate::core_source(&machine, "firmware");
        let board = generate::board_source(&machine);
        assert!(core.contains("pub const NAME"), "{}", path.display());
        assert!(board.contains("pub const STEP"), "{}", path.display());
    }
}

#[test]
fn the_prusa_i3_file_says_what_the_prusa_i3_is() {
    let m = parse("prusa-i3.toml", &shipped("prusa-i3.toml")).unwrap();
    assert_eq!(m.name, "Prusa i3");
    assert_eq!(m.baud, 115_200);
    assert_eq!(m.kinematics, Kinematics::Cartesian);
    let axes = m.axes.as_ref().unwrap();
    assert_eq!(axes.iter().map(|a| a.steps_per_mm).collect::<Vec<_>>(), [100.0, 100.0, 400.0, 93.0]);
    assert!(axes[1].invert_direction && !axes[0].invert_direction);
    assert_eq!(axes[2].home, HomeEnd::Min);
    assert_eq!(m.heaters.len(), 2);
    assert_eq!(m.heaters[0].role, HeaterRole::Hotend);
    assert_eq!(m.heaters[0].thermistor.marlin_type, 11);
    assert_eq!(m.heaters[0].control, Control::Pid([22.2, 1.08, 114.0]));
    assert!(!m.display && !m.encoders, "described but not enabled");
}

#[test]
fn the_other_cartesian_printer_differs_where_the_e2e_test_needs_it() {
    let m = parse("e3d-i3-300.toml", &shipped("e3d-i3-300.toml")).unwrap();
    let axes = m.axes.as_ref().unwrap();
    assert!(axes[0].invert_direction);
    assert_eq!(axes[2].home, HomeEnd::Max);
    assert!(axes.iter().take(3).all(|a| !a.endstop_high));
    assert_eq!(m.heaters[0].thermistor.marlin_type, 5);
    assert_eq!(m.baud, 250_000);
    let board = generate::board_source(&m);
    assert!(board.contains("pub const ENDSTOP_ACTIVE_LOW: u8 = 0b01110111;"), "{board}");
    let core = generate::core_source(&m, "firmware");
    assert!(core.contains("dir_invert: 0b1001"), "X and E inverted: {core}");
    assert!(core.contains("pub const ENDSTOP_TRIGGER_LEVELS: u8 = 0b00000000;"), "{core}");
}

#[test]
fn an_unknown_key_is_an_error_not_ignored() {
    let message = error_of(&prusa_with("steps_per_mm = 93.0", "steps_per_mm = 93.0\nstepz_per_mm = 1.0"));
    assert!(message.starts_with("machine file my-printer.toml:"), "{message}");
    assert!(message.contains("unknown field `stepz_per_mm`"), "{message}");
}

#[test]
fn a_missing_required_key_is_named() {
    let message = error_of(&prusa_with("max_feed = 25.0            # mm/s of filament\n", ""));
    assert!(message.contains("missing field `max_feed`"), "{message}");
    let message = error_of(&prusa_with("steps_per_mm = 400.0       # M5 lead screws (0.8 mm a turn)\n", ""));
    assert!(message.contains("axes.z.steps_per_mm: missing"), "{message}");
}

#[test]
fn a_pin_used_twice_names_both_keys() {
    let message = error_of(&prusa_with("dir_pin = 61               # PF7", "dir_pin = 54"));
    assert!(message.contains("axes.y.dir_pin: pin D54 (PF0) is already used by axes.x.step_pin"), "{message}");
}

#[test]
fn travel_min_must_be_below_max() {
    let message = error_of(&prusa_with("max = 180.0", "max = -1.0"));
    assert!(message.contains("axes.z.min: travel min must be below max (0 ≥ -1)"), "{message}");
}

#[test]
fn steps_per_mm_must_be_positive() {
    let message = error_of(&prusa_with("steps_per_mm = 93.0", "steps_per_mm = 0.0"));
    assert!(message.contains("axes.e.steps_per_mm: must be above 0 steps/mm (is 0)"), "{message}");
    let message = error_of(&prusa_with("steps_per_mm = 93.0", "steps_per_mm = -93.0"));
    assert!(message.contains("axes.e.steps_per_mm: must be above 0"), "{message}");
}

#[test]
fn an_unknown_thermistor_lists_the_known_ones() {
    let message = error_of(&prusa_with("thermistor = \"ntc-100k-3950\" # epcos", "thermistor = \"pt1000\" # epcos"));
    assert!(message.contains("heaters.hotend.thermistor: \"pt1000\" is not a thermistor"), "{message}");
    assert!(message.contains("\"semitec-104gt2\" (Marlin 5)"), "{message}");
}

#[test]
fn a_heater_without_a_thermistor_is_refused() {
    let message = error_of(&prusa_with("thermistor = \"ntc-100k-3950\" # epcos", "# no sensor"));
    assert!(message.contains("heaters.hotend: has no thermistor"), "{message}");
}

#[test]
fn a_maximum_temperature_above_the_thermistor_table_is_refused() {
    let message = error_of(&prusa_with("max_temp = 275.0", "max_temp = 350.0"));
    assert!(message.contains("heaters.hotend.max_temp: 350 °C is above what the 100 kΩ NTC, β 3950"), "{message}");
}

#[test]
fn options_the_board_or_kinematics_cannot_carry_are_refused() {
    let message = error_of(&prusa_with("type = \"hd44780\"", "type = \"st7920\""));
    assert!(message.contains("display.type: \"st7920\" is not a display this board drives"), "{message}");
    let delta = shipped("delta.toml") + "\n[encoders]\ntype = \"nse5310\"\n";
    let message = error_of(&delta);
    assert!(message.contains("encoders: the NSE-5310 loops close X and Y of a Cartesian printer only"), "{message}");
    let message = error_of(&prusa_with("board = \"mega2560-ramps\"", "board = \"skr-pro\""));
    assert!(message.contains("machine.board: \"skr-pro\" is not a board"), "{message}");
}

#[test]
fn a_heater_on_a_pin_without_pwm_is_refused() {
    let message = error_of(&prusa_with("output_pin = 10", "output_pin = 11"));
    assert!(message.contains("heaters.hotend.output_pin: D11 (PB5) has no PWM channel"), "{message}");
}

#[test]
fn a_baud_rate_the_uart_cannot_make_is_refused() {
    let message = error_of(&prusa_with("baud = 115200", "baud = 230400"));
    assert!(message.contains("machine.baud: 230400 baud is not a rate"), "{message}");
    assert!(parse("x", &prusa_with("baud = 115200", "baud = 250000")).is_ok());
}

#[test]
fn every_problem_is_reported_at_once() {
    let text = prusa_with("max = 180.0", "max = -1.0").replacen("steps_per_mm = 93.0", "steps_per_mm = 0.0", 1);
    let message = error_of(&text);
    assert!(message.contains("2 problems"), "{message}");
}

#[test]
fn described_options_are_built_in_only_when_enabled() {
    let m = parse("p", &prusa_with("type = \"hd44780\"           # RepRapDiscount Smart Controller, 16x2 on EXP1 (D16, D17, D23–D29)\nenabled = false", "type = \"hd44780\"\nenabled = true")).unwrap();
    assert!(m.display && !m.encoders);
    assert_eq!(generate::board_features(&m), ["motion", "printer", "heaters", "display-hd44780"]);
}

#[test]
fn the_delta_links_the_delta_and_the_arm_links_no_heaters() {
    let delta = parse("delta.toml", &shipped("delta.toml")).unwrap();
    assert_eq!(generate::features(&delta), ["printer", "heaters", "delta"]);
    let arm = parse("arm.toml", &shipped("arm.toml")).unwrap();
    assert_eq!(generate::features(&arm), ["printer", "arm"]);
    assert_eq!(generate::board_features(&arm), ["motion", "machine-arm"]);
    let line = parse("extrusion-line.toml", &shipped("extrusion-line.toml")).unwrap();
    assert_eq!(generate::board_features(&line), ["heaters", "machine-extrusion-line"]);
}

#[test]
fn different_machines_have_different_fingerprints() {
    let prusa = parse("a", &shipped("prusa-i3.toml")).unwrap();
    let renamed = parse("b", &prusa_with("name = \"Prusa i3\"", "name = \"My i3\"")).unwrap();
    let faster = parse("c", &prusa_with("max_feed = 300.0           # mm/s, highest speed (M203)", "max_feed = 350.0")).unwrap();
    assert_ne!(generate::fingerprint(&prusa), generate::fingerprint(&renamed));
    assert_eq!(generate::fingerprint(&prusa), generate::fingerprint(&faster), "a tuned value is the same machine");
}

/// The arm's safety inputs (D40 relay, D42 e-stop, D44 re-arm) are the
/// board's, like its ALARM inputs: a machine file cannot put anything
/// else on them.
#[test]
fn the_arms_safety_inputs_are_reserved() {
    let arm = shipped("arm.toml");
    for (pin, what) in [(40, "the safety relay input"), (42, "the emergency stop input"), (44, "the re-arm input")] {
        let from = "min_endstop_pin = 3            # switch at the min end";
        assert_eq!(arm.matches(from).count(), 1);
        let message = error_of(&arm.replacen(from, &format!("min_endstop_pin = {pin}"), 1));
        assert!(message.contains(&format!("{what}: pin D{pin} ")) && message.contains("already used by axes.x.min_endstop_pin"), "{message}");
    }
}
