//! A printer that is not ours, described in one machine file and built
//! without touching Rust: `machines/e3d-i3-300.toml` (X motor inverted,
//! endstops that read low when triggered, Z homing to its max, a Semitec
//! 104GT-2 hot end, 250000 baud, 300 mm travel from X −5), its real ELF on
//! the simulated Mega 2560 + RAMPS.

use avr_bench::bench::{self, exchange};
use avr_bench::board::{Board, Endstop, RampsConfig, X, Y, Z};
use avr_bench::host::HostConfig;
use avr_bench::thermal::SensorInput;
use avr_bench::build::shipped_elf;
use avr_bench::thermal::Thermistor;
use std::path::PathBuf;

/// The ELF: CI's build of the file (test.sh keeps each machine's ELF in
/// `$FERROSTEP_MACHINES_DIR`), else built here.
fn elf() -> PathBuf {
    shipped_elf("e3d-i3-300")
}

/// ATC Semitec 104GT-2 on RAMPS's 4.7 kΩ pull-up (β 4267 K).
const SEMITEC: Thermistor = Thermistor { r25_ohm: 100_000.0, beta: 4267.0, pullup_ohm: 4_700.0 };

fn replies(board: &mut Board, lines: &[&str]) -> Vec<String> {
    let all = exchange(board, lines, 60.0).unwrap_or_else(|e| panic!("{e}"));
    all.into_iter().filter(|r| !r.starts_with("echo:busy")).collect()
}

fn boot() -> Board {
    let mut config = RampsConfig::stock(250_000);
    config.host = HostConfig::raw(250_000);
    // Positions count STEP edges by DIR pin level (high = +). The X motor
    // is inverted, so its min switch lies on the pin's positive side.
    // Every switch reads low when pressed (optical endstops).
    config.endstops = [None; 6];
    config.endstops[0] = Some(Endstop { axis: X, at_steps: 1234, is_min: false, pressed_level: false }); // X_MIN
    config.endstops[2] = Some(Endstop { axis: Y, at_steps: -567, is_min: true, pressed_level: false }); // Y_MIN
    config.endstops[5] = Some(Endstop { axis: Z, at_steps: 890, is_min: false, pressed_level: false }); // Z_MAX
    config.sensors[0].input = SensorInput::Fixed(SEMITEC.adc_counts(25.0));
    config.sensors[1].input = SensorInput::Fixed(977);
    bench::boot(&elf(), config).expect("the firmware boots")
}

#[test]
fn another_printers_machine_file_homes_moves_reads_and_reports_its_own_values() {
    let mut board = boot();

    // Its name, at its baud rate.
    let m115 = replies(&mut board, &["M115"]);
    assert!(m115[0].contains(" MACHINE_TYPE:i3 300 E3D EXTRUDER_COUNT:1"), "{m115:?}");

    // Each axis homes towards the end the file names, on switches that
    // read low, X against its inverted motor: Z to the top (300), X to −5,
    // Y to 0, in that order.
    assert_eq!(
        replies(&mut board, &["G28", "M114"]),
        ["ok", "X:-5.00 Y:0.00 Z:300.00 E:0.00 Count X:-400 Y:0 Z:120000", "ok"]
    );
    assert_eq!([X, Y, Z].map(|a| board.position(a)), [1234, -567, 890], "each motor stopped on its own switch");

    // Exact steps at 80 and 400 steps/mm; X's pin direction inverted.
    assert_eq!(
        replies(&mut board, &["G1 X10 Y5 Z290 F3000", "M400", "M114"]),
        ["ok", "ok", "X:10.00 Y:5.00 Z:290.00 E:0.00 Count X:800 Y:400 Z:116000", "ok"]
    );
    assert_eq!([X, Y, Z].map(|a| board.position(a)), [1234 - 1200, -567 + 400, 890 - 4000]);

    // Never outside its travel (X −5 … 295, Z 0 … 300): as Marlin does
    // with software endstops, a homed axis stops at the end of its travel
    // and not one step beyond it.
    for (line, expected) in [
        ("G1 X296", "X:295.00 Y:5.00 Z:290.00 E:0.00 Count X:23600 Y:400 Z:116000"),
        ("G1 X-6", "X:-5.00 Y:5.00 Z:290.00 E:0.00 Count X:-400 Y:400 Z:116000"),
        ("G1 Z301", "X:-5.00 Y:5.00 Z:300.00 E:0.00 Count X:-400 Y:400 Z:120000"),
    ] {
        assert_eq!(replies(&mut board, &[line, "M400", "M114"]), ["ok", "ok", expected, "ok"], "{line}");
    }
    // Back on the switches exactly where homing left them.
    assert_eq!([X, Y, Z].map(|a| board.position(a)), [1234, -567 + 400, 890]);

    // The Semitec table: 25 °C and 200 °C as the part reads them (the
    // stock β 3950 table would read 200 °C's counts as ≈ 223 °C).
    let hotend = |board: &mut Board| {
        let m105 = replies(board, &["M105"]);
        let t: f64 = m105[0].split_whitespace().nth(1).and_then(|w| w.strip_prefix("T:")).unwrap().parse().unwrap();
        t
    };
    let t25 = hotend(&mut board);
    assert!((t25 - 25.0).abs() < 0.5, "{t25}");
    board.set_sensor_input(13, SensorInput::Fixed(SEMITEC.adc_counts(200.0)));
    board.run_for_ms(1500.0);
    let t200 = hotend(&mut board);
    assert!((t200 - 200.0).abs() < 1.0, "{t200}");

    // M503 prints the file's values.
    let m503 = replies(&mut board, &["M503"]).join("\n");
    let expected = [
        "M92 X80.00 Y80.00 Z400.00 E415.00",
        "M203 X250.00 Y250.00 Z8.00 E40.00",
        "M201 X2000.00 Y2000.00 Z200.00 E5000.00",
        "M204 P1000.00 R2000.00 T1500.00",
        "M301 P18.00 I1.20 D65.00",
    ];
    for line in expected {
        assert!(m503.contains(line), "{line:?} not in:\n{m503}");
    }
    // M502 returns to the file's values, not the Prusa's.
    replies(&mut board, &["M92 X100 E93", "M301 P22.2 I1.08 D114"]);
    assert!(replies(&mut board, &["M503"]).join("\n").contains("M92 X100.00 Y80.00 Z400.00 E93.00"));
    replies(&mut board, &["M502"]);
    let m503 = replies(&mut board, &["M503"]).join("\n");
    for line in expected {
        assert!(m503.contains(line), "after M502: {line:?} not in:\n{m503}");
    }
}
