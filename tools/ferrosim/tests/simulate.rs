//! The `simulate` and `replay` commands on known inputs.

use ferrosim::replay;
use ferrosim::simulate::{self, MachineKind, Options};
use std::path::Path;

#[test]
fn one_travel_move_takes_its_trapezoid_time_and_exact_distance() {
    // 100 mm at 100 mm/s with 1500 mm/s² (M204 T): 1 s at speed plus
    // v/a = 0.0667 s lost to the two ramps = 1.0667 s.
    let report = simulate::run("G1 X100 F6000\n", &Options::default(), |_, _| {});
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    assert!((1.066..1.08).contains(&report.print_time_s), "{}", report.print_time_s);
    let figures = report.figures();
    assert_eq!(figures.distance, [100.0, 0.0, 0.0, 0.0]);
    // 10 ms samples of a 100 mm/s cruise at 100 steps/mm: 10 000 steps/s.
    assert!((figures.peak_speed[0] - 100.0).abs() < 1.0, "{:?}", figures.peak_speed);
    assert!((figures.max_step_rate[0] - 10_000.0).abs() < 100.0, "{:?}", figures.max_step_rate);
    assert_eq!(report.underruns, 0);
}

#[test]
fn a_short_print_reports_its_layers_heaters_and_writes_every_plot() {
    let gcode = "; estimated printing time (normal mode) = 0h 1m 0s\nM104 S60\nM302 P1\nG1 Z0.2 F600\nG1 X10 Y0 E1 F1200\nG1 X10 Y10 E2\nG1 Z0.4\nG1 X0 Y10 E3\nG1 X0 Y0 E4\n";
    let report = simulate::run(gcode, &Options::default(), |_, _| {});
    assert_eq!(report.lines, 8);
    assert_eq!(report.slicer_estimate_s, Some(60.0));
    assert_eq!(report.layers(), [0.2, 0.4]);
    let figures = report.figures();
    assert!((figures.distance[0] - 20.0).abs() < 1e-9 && (figures.distance[1] - 20.0).abs() < 1e-9, "{figures:?}");
    assert!((figures.distance[3] - 4.0).abs() < 0.02, "{figures:?}");
    // (M302 P1: the hot end only goes to 60 °C, cold extrusion allowed.)
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    assert!(report.summary().contains("slicer's estimate 1m 00.0s"), "{}", report.summary());
    let dir = std::env::temp_dir().join(format!("ferrosim-test-{}", std::process::id()));
    let files = ferrosim::plots::simulation_plots(&report, &dir, Some(1)).unwrap();
    let names: Vec<String> = files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect();
    for stem in ["speed", "step_rates", "temperatures", "heater_duty", "layer"] {
        for ext in ["png", "svg"] {
            let name = format!("{stem}.{ext}");
            assert!(names.contains(&name), "{name} in {names:?}");
            let bytes = std::fs::read(dir.join(&name)).unwrap();
            assert!(bytes.len() > 2_000, "{name}: {} bytes", bytes.len());
            if ext == "svg" {
                assert!(String::from_utf8_lossy(&bytes).contains("<svg"), "{name}");
            } else {
                assert_eq!(&bytes[1..4], b"PNG", "{name}");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_delta_runs_a_file_through_its_own_kinematics() {
    let options = Options { machine: MachineKind::Delta, ..Options::default() };
    let report = simulate::run("G28\nG1 Z100 F3000\nG1 X20 Y0 F3000\n", &options, |_, _| {});
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    let (xyz, _) = report.tool_position(report.samples.last().unwrap()).unwrap();
    assert!((xyz[0] - 20.0).abs() < 0.02 && xyz[1].abs() < 0.02 && (xyz[2] - 100.0).abs() < 0.02, "{xyz:?}");
}

fn trace(name: &str) -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../hal-sim/traces").join(name)).unwrap()
}

#[test]
fn replaying_the_belt_slip_trace_raises_the_following_error_alarm() {
    let replayed = replay::replay_text(&trace("belt_slip.csv")).unwrap();
    let summary = replayed.summary();
    assert!(summary.contains("ALARM at row") && summary.contains("FollowingError"), "{summary}");
    let clean = replay::replay_text(&trace("clean_circle.csv")).unwrap();
    assert!(clean.summary().contains("no alarm"), "{}", clean.summary());
    assert!(clean.errors().iter().all(|(_, e)| e.abs() < 0.1));
}

#[test]
fn a_damaged_trace_is_refused_with_its_line_number() {
    let error = replay::replay_text("time_s,raw,index,commanded_mm\n0.0,12,0,0\n0.1,banana,0,0\n").err().unwrap();
    assert!(error.starts_with("line 3"), "{error}");
}
