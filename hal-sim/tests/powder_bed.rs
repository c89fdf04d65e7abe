//! The powder-bed retrofit (SPEC §5) on the simulated machine: the
//! firmware's travel measurement and layer cycle driving M542 platforms
//! through their pins, reed switches read through their polarity, and the
//! carriage on its DC servo loop.

use firmware::closed_loop::output::ActiveLevel;
use firmware::machines::powder_bed::{
    CarriageEnd, LayerCommand, LayerCycle, LayerSettings, Platform, PlatformDriver, TravelFault, TravelLimits, TravelReport, Vertical,
};
use hal_sim::powder_bed_plant::*;

const DRIVER: PlatformDriver = PlatformDriver::M542;

#[test]
fn travel_measurement_reports_the_configured_travel_in_steps_and_mm() {
    // 40 000 steps at 200 steps/mm: 200 mm
    let mut plant = PlatformPlant::new(DRIVER, 40_000, 12_345);
    let (result, seconds) = measure_travel(&mut plant, &TravelLimits::DEFAULT, ActiveLevel::Low);
    assert_eq!(result, Ok(TravelReport { steps: 40_000, um: 200_000 }));
    assert_eq!(plant.position, 40_000, "it stops on the upper switch");
    assert_eq!(plant.edges_while_disabled, 0);
    // 12 345 down + 40 000 up at 1 kHz, plus the thesis' 2 s pause
    assert!(seconds > 54.3 && seconds < 54.5, "{seconds}");
}

#[test]
fn starting_on_the_lower_switch_gives_the_same_travel() {
    for start in [0, -30, -60] {
        let mut plant = PlatformPlant::new(DRIVER, 40_000, start);
        assert!(!plant.switch_levels().0, "starts on A (active low)");
        let (result, _) = measure_travel(&mut plant, &TravelLimits::DEFAULT, ActiveLevel::Low);
        assert_eq!(result, Ok(TravelReport { steps: 40_000, um: 200_000 }), "start {start}");
    }
}

#[test]
fn fractional_steps_per_mm_report_rounded_mm() {
    // a 3 mm lead at 800 ppr: 266.667 steps/mm; 32 000 steps = 120.000 mm
    let driver = PlatformDriver { steps_per_m: 266_667, ..DRIVER };
    let mut plant = PlatformPlant::new(driver, 32_000, 5_000);
    let (result, _) = measure_travel(&mut plant, &TravelLimits::DEFAULT, ActiveLevel::Low);
    assert_eq!(result, Ok(TravelReport { steps: 32_000, um: 120_000 }));
}

#[test]
fn a_missing_upper_switch_faults_after_the_step_limit() {
    let mut plant = PlatformPlant::new(DRIVER, 40_000, 5_000);
    plant.upper_zone = None;
    let limits = TravelLimits { max_steps: 45_000, ..TravelLimits::DEFAULT };
    let (result, _) = measure_travel(&mut plant, &limits, ActiveLevel::Low);
    assert_eq!(result, Err(TravelFault::UpperSwitchNotFound));
}

#[test]
fn a_missing_lower_switch_faults_after_the_step_limit() {
    let mut plant = PlatformPlant::new(DRIVER, 40_000, 5_000);
    plant.lower_zone = None;
    let limits = TravelLimits { max_steps: 45_000, ..TravelLimits::DEFAULT };
    let (result, _) = measure_travel(&mut plant, &limits, ActiveLevel::Low);
    assert_eq!(result, Err(TravelFault::LowerSwitchNotFound));
}

#[test]
fn the_wrong_switch_polarity_is_caught_not_measured() {
    // Configured active-high on active-low switches: both read "closed"
    // away from the switches.
    let mut plant = PlatformPlant::new(DRIVER, 40_000, 5_000);
    let (result, _) = measure_travel(&mut plant, &TravelLimits::DEFAULT, ActiveLevel::High);
    assert_eq!(result, Err(TravelFault::BothSwitchesActive));
    // Active-high switches with the matching configuration measure fine.
    let mut plant = PlatformPlant::new(DRIVER, 40_000, 5_000);
    plant.switch_active = ActiveLevel::High;
    let (result, _) = measure_travel(&mut plant, &TravelLimits::DEFAULT, ActiveLevel::High);
    assert_eq!(result, Ok(TravelReport { steps: 40_000, um: 200_000 }));
}

#[test]
fn m542_pins_step_on_the_falling_edge_with_enable_low_and_dir_high_down() {
    let mut plant = PlatformPlant::new(DRIVER, 40_000, 100);
    plant.set_enable(false); // low = enabled
    plant.set_dir(true); // high = down
    plant.set_step(false); // falling edge from the idle high
    assert_eq!(plant.position, 99);
    plant.set_step(true); // rising: nothing
    assert_eq!(plant.position, 99);
    plant.set_enable(true); // disabled
    plant.set_step(false);
    assert_eq!((plant.position, plant.edges_while_disabled), (99, 1));
}

fn run_layer(bed: &mut PowderBed, cycle: &mut LayerCycle) -> LayerCommand {
    let mut command = cycle.start(&DRIVER, &DRIVER, bed.carriage.at());
    while cycle.is_busy() {
        let event = bed.execute(command);
        command = cycle.on_event(event);
    }
    bed.execute(command);
    command
}

#[test]
fn a_layer_cycle_runs_in_order_and_moves_each_platform_by_exactly_one_layer() {
    let mut bed = PowderBed::new(DRIVER, 40_000);
    let mut cycle = LayerCycle::new(LayerSettings { thickness_um: 100, suction_while_spreading: true });
    let (feed0, build0) = (bed.feed.position, bed.build.position);
    assert_eq!(run_layer(&mut bed, &mut cycle), LayerCommand::Finished { layer: 1 });
    // one layer = 0.1 mm = 20 steps at 200 steps/mm
    assert_eq!(bed.feed.position - feed0, 20, "feed up one layer");
    assert_eq!(build0 - bed.build.position, 20, "build down one layer");
    assert!(!bed.roller_on && !bed.suction_on);
    let order: Vec<LayerCommand> = bed.log.iter().map(|e| e.command).collect();
    assert_eq!(
        order,
        [
            LayerCommand::Roller(true),
            LayerCommand::Suction(true),
            LayerCommand::MoveCarriage { to: CarriageEnd::Plus, print_pass: false },
            LayerCommand::Roller(false),
            LayerCommand::Suction(false),
            LayerCommand::MoveCarriage { to: CarriageEnd::Minus, print_pass: true },
            LayerCommand::StepPlatform { platform: Platform::Feed, direction: Vertical::Up, steps: 20 },
            LayerCommand::StepPlatform { platform: Platform::Build, direction: Vertical::Down, steps: 20 },
            LayerCommand::Finished { layer: 1 },
        ]
    );
    // the spread starts at C− with the roller turning; the print pass
    // starts at C+ with it stopped; the platforms move with the carriage home
    assert_eq!((bed.log[2].carriage_at, bed.log[2].roller_on), (Some(CarriageEnd::Minus), true));
    assert_eq!((bed.log[5].carriage_at, bed.log[5].roller_on), (Some(CarriageEnd::Plus), false));
    assert_eq!(bed.log[6].carriage_at, Some(CarriageEnd::Minus));
    assert_eq!(bed.carriage.at(), Some(CarriageEnd::Minus));
    assert_eq!(bed.carriage.decoder.illegal_transitions(), 0);
}

#[test]
fn fifty_layers_of_0_05_mm_at_a_fractional_pitch_move_exactly_2_5_mm() {
    // 266.667 steps/mm: 13.33 steps per layer; 50 layers = 666.67 → 666 steps
    let driver = PlatformDriver { steps_per_m: 266_667, ..DRIVER };
    let mut bed = PowderBed::new(driver, 40_000);
    bed.carriage.speed_counts_per_s = 8000;
    let mut cycle = LayerCycle::new(LayerSettings { thickness_um: 50, suction_while_spreading: false });
    let (feed0, build0) = (bed.feed.position, bed.build.position);
    for layer in 1..=50 {
        let mut command = cycle.start(&driver, &driver, bed.carriage.at());
        while cycle.is_busy() {
            let event = bed.execute(command);
            command = cycle.on_event(event);
        }
        assert_eq!(command, LayerCommand::Finished { layer });
    }
    assert_eq!(bed.feed.position - feed0, 666);
    assert_eq!(build0 - bed.build.position, 666);
}

#[test]
fn a_carriage_left_in_the_middle_returns_to_c_minus_before_spreading() {
    let mut bed = PowderBed::new(DRIVER, 40_000);
    bed.carriage.stroke(CarriageEnd::Plus).unwrap();
    let mut cycle = LayerCycle::new(LayerSettings { thickness_um: 100, suction_while_spreading: false });
    run_layer(&mut bed, &mut cycle);
    assert_eq!(bed.log[0].command, LayerCommand::MoveCarriage { to: CarriageEnd::Minus, print_pass: false });
    assert!(!bed.log[0].roller_on);
    assert_eq!(bed.log[1].command, LayerCommand::Roller(true));
}

#[test]
fn a_carriage_that_cannot_reach_its_sensor_aborts_the_layer_with_everything_off() {
    let mut bed = PowderBed::new(DRIVER, 40_000);
    bed.carriage.c_plus_counts = 1_000_000; // sensor unplugged
    let mut cycle = LayerCycle::new(LayerSettings { thickness_um: 100, suction_while_spreading: true });
    let last = run_layer(&mut bed, &mut cycle);
    assert!(matches!(last, LayerCommand::Aborted(_)), "{last:?}");
    assert!(!bed.roller_on && !bed.suction_on);
    let feed_moves = bed.log.iter().filter(|e| matches!(e.command, LayerCommand::StepPlatform { .. })).count();
    assert_eq!(feed_moves, 0, "no platform moves after a failed spread");
}

// --- the firmware's executor, over the serial line ------------------------------

use hal_sim::board::SimBoard;


/// G-code in, platforms and carriage moved: the powder bed as the firmware
/// runs it (M880 travel, M881 layers, M882 carriage, roller, no heaters).
#[test]
fn the_powder_bed_measures_its_travel_and_runs_layers_under_gcode() {
    let mut board = SimBoard::powder_bed();
    assert!(board.reply_to("M115", 100).contains("Cap:POWDER_BED:1\n"));
    assert_eq!(board.reply_to("M109 S200", 100), "echo:M109 ignored: this machine has no heaters\nok\n");
    assert_eq!(board.reply_to("G1 Z10", 100), "Error:Not available on this machine\nok\n");
    // Both platforms: 40 000 steps between the switches = 200 mm.
    assert_eq!(
        board.reply_to("M880", 400_000),
        "echo:Feed platform travel 40000 steps 200.000 mm\necho:Build platform travel 40000 steps 200.000 mm\nok\n"
    );
    let bed = board.powder_bed.as_ref().unwrap();
    let (feed0, build0) = (bed.feed.position, bed.build.position);
    assert_eq!(bed.feed.edges_while_disabled + bed.build.edges_while_disabled, 0);
    // Two layers of 0.1 mm: 20 steps each way per layer.
    assert_eq!(board.reply_to("M881 L0.1 N2", 60_000), "echo:Layer 1 done\necho:Layer 2 done\nok\n");
    let bed = board.powder_bed.as_ref().unwrap();
    assert_eq!(bed.feed.position - feed0, 40, "feed up two layers");
    assert_eq!(build0 - bed.build.position, 40, "build down two layers");
    assert!(!bed.roller_on && !bed.suction_on);
    assert_eq!(bed.carriage.at(), Some(firmware::machines::powder_bed::CarriageEnd::Minus));
    assert_eq!(bed.carriage.decoder.illegal_transitions(), 0);
    // The carriage on its own, and the roller.
    assert_eq!(board.reply_to("M882 S1", 10_000), "echo:Carriage at C+\nok\n");
    assert_eq!(board.reply_to("M3", 100), "ok\n");
    assert!(board.powder_bed.as_ref().unwrap().roller_on);
    assert_eq!(board.reply_to("M5", 100), "ok\n");
    assert!(!board.powder_bed.as_ref().unwrap().roller_on);
    assert_eq!(board.reply_to("M881 L0", 100), "Error:Value out of range for L\nok\n");
}

/// The powder bed's 16×2 screen (SPEC §5's HD44780): the job on row 0, the
/// layers done, roller and suction on row 1 — none of a printer's hot-end
/// and bed temperatures, which this machine does not have. The layer
/// cycle runs the suction while the roller spreads (not only by M10).
#[test]
fn the_powder_bed_screen_shows_its_job_and_the_suction_runs_while_spreading() {
    let mut board = SimBoard::powder_bed();
    let screen = |board: &SimBoard| {
        let bytes = board.link.machine.status_screen();
        (String::from_utf8_lossy(&bytes[..16]).into_owned(), String::from_utf8_lossy(&bytes[16..]).into_owned())
    };
    assert_eq!(screen(&board), ("Ready           ".into(), "Done 0  R:0 S:0 ".into()));
    board.receive(b"M881 L0.1 N3\n");
    let mut spreading = None;
    for _ in 0..60_000 {
        board.advance(1);
        let bed = board.powder_bed.as_ref().unwrap();
        // Suction comes on right after the roller, before the spreading
        // stroke starts.
        if bed.roller_on && bed.suction_on && spreading.is_none() {
            spreading = Some(screen(&board));
        }
        if board.take_output().contains("Layer 1 done") {
            break;
        }
    }
    assert_eq!(spreading, Some(("Layer 1   2 left".into(), "Done 0  R:1 S:1 ".into())));
    let mut output = String::new();
    for _ in 0..120_000 {
        board.advance(1);
        output.push_str(&board.take_output());
        if output.ends_with("ok\n") {
            break;
        }
    }
    assert!(output.contains("Layer 3 done"), "{output:?}");
    assert_eq!(screen(&board), ("Ready           ".into(), "Done 3  R:0 S:0 ".into()));
    assert_eq!(board.reply_to("M10", 100), "ok\n");
    assert_eq!(screen(&board).1, "Done 3  R:0 S:1 ");
    board.reply_to("M112", 100);
    assert_eq!(screen(&board).0, "Halted          ");
}

/// A carriage whose end sensor never trips (unplugged) ends the layer
/// cycle with an error, roller off, nothing else moved.
#[test]
fn a_carriage_sensor_that_never_trips_aborts_the_layer() {
    let mut board = SimBoard::powder_bed();
    board.powder_bed.as_mut().unwrap().carriage.c_plus_counts = 1_000_000;
    let (feed0, build0) = {
        let bed = board.powder_bed.as_ref().unwrap();
        (bed.feed.position, bed.build.position)
    };
    let reply = board.reply_to("M881", 60_000);
    assert_eq!(reply, "Error:Layer cycle aborted\nok\n");
    let bed = board.powder_bed.as_ref().unwrap();
    assert!(!bed.roller_on && !bed.suction_on);
    assert_eq!((bed.feed.position, bed.build.position), (feed0, build0));
}

/// SPEC §5's relay auto-tune of the carriage's DC servo loop over G-code:
/// the relay oscillates the axis, the report gives Ku, Pu and the
/// Ziegler–Nichols gains, `A1` puts them in the loop, and the carriage
/// still makes its strokes with them.
#[test]
fn m825_tunes_the_carriage_servo_and_the_tuned_loop_strokes() {
    let mut board = SimBoard::powder_bed();
    let reply = board.reply_to("M825 S127 A1", 30_000);
    assert!(reply.starts_with("echo:Carriage relay d:127 a:"), "{reply}");
    let field = |name: &str| -> f64 {
        reply.split(&format!("{name}:")).nth(1).and_then(|r| r.split([' ', '\n']).next()).and_then(|v| v.parse().ok()).unwrap_or(f64::NAN)
    };
    let (amplitude, period, ku) = (field("a"), field("Pu"), field("Ku"));
    // What the plant implies, by the describing function of a relay with
    // hysteresis (d 127, band ε 5 counts) around G(s) = K·e^(−Ls)/(s(τs+1)),
    // K 40 counts/s per duty unit, τ 30 ms, L 4 ms + half the 1 ms tick
    // (the zero-order hold): the oscillation sits where
    // arg G(jω) = −π + asin(ε/a) and |G(jω)| = πa/(4d), which gives
    // ω 70.25 rad/s (Pu 89.4 ms) and a 39.5 counts (measured: 41, 92 ms).
    // ±20 %, the describing function's own error on a non-sinusoid.
    let (expected_a, expected_pu) = (39.5, 0.0894);
    assert!((amplitude - expected_a).abs() <= 0.2 * expected_a, "{reply}");
    assert!((period - expected_pu).abs() <= 0.2 * expected_pu, "{reply}");
    assert!((ku - 4.0 * 127.0 / (std::f64::consts::PI * amplitude)).abs() < 0.01 * ku, "{reply}");
    println!("{reply}");
    assert!(reply.ends_with("ok\n"), "{reply}");
    assert_eq!(board.reply_to("M882 S1", 10_000), "echo:Carriage at C+\nok\n");
    assert_eq!(board.reply_to("M882 S0", 10_000), "echo:Carriage at C-\nok\n");
    assert_eq!(board.reply_to("M825 S300", 100), "Error:Value out of range for S\nok\n");
}

/// The carriage loop's own commands (listed in M115 as CLOSED_LOOP): gains
/// set by hand, the encoder report, the following-error limit.
#[test]
fn the_carriage_loop_takes_its_gains_and_limits_at_run_time() {
    let mut board = SimBoard::powder_bed();
    assert!(board.reply_to("M115", 100).contains("Cap:CLOSED_LOOP:1\n"));
    assert_eq!(board.reply_to("M821 P2 I40 D0.02", 100), "echo:Carriage PID Kp:2.0000 Ki:40.0000 Kd:0.0200\nok\n");
    assert_eq!(board.reply_to("M821", 100), "echo:Carriage PID Kp:2.0000 Ki:40.0000 Kd:0.0200\nok\n");
    assert_eq!(board.reply_to("M821 P-1", 100), "Error:Value out of range for P\nok\n");
    assert_eq!(board.reply_to("M822", 100), "echo:Carriage enc:0 at:C- fault:none\nok\n");
    assert_eq!(board.reply_to("M882 S1", 10_000), "echo:Carriage at C+\nok\n");
    let report = board.reply_to("M822", 100);
    assert!(report.starts_with("echo:Carriage enc:40") && report.ends_with(" at:C+ fault:none\nok\n"), "{report}");
    assert_eq!(board.reply_to("M823 E200 T50", 100), "echo:Carriage following error 200 counts for 50 ms\nok\n");
    // A limit the stroke cannot keep: the stroke stops with an error.
    assert_eq!(board.reply_to("M821 P0.01 I0 D0", 100), "echo:Carriage PID Kp:0.0100 Ki:0.0000 Kd:0.0000\nok\n");
    let reply = board.reply_to("M882 S0", 10_000);
    assert_eq!(reply, "Error:Carriage stroke failed (sensor not reached or servo fault)\nok\n");
}

/// SPEC §5: the carriage's X and Y follow G-code (the print pass's moves,
/// which the thesis sent to a second board running Grbl): each move ends
/// on its point within 2 counts (0.1 mm), M114 reports it, and Z or E
/// words are refused (the platforms move only through their jobs).
#[test]
fn the_carriage_follows_g1_moves_in_x_and_y() {
    let mut board = SimBoard::powder_bed();
    assert_eq!(board.reply_to("G1 X20 Y10 F1200", 10_000), "ok\n");
    let at = |board: &SimBoard| {
        let bed = board.powder_bed.as_ref().unwrap();
        (bed.carriage.decoder.count(), bed.carriage_y.decoder.count())
    };
    let (x, y) = at(&board);
    assert!((x - 400).abs() <= 2 && (y - 200).abs() <= 2, "{x} {y}");
    assert!(board.reply_to("M114", 100).starts_with("X:20.00 Y:10.00"));
    assert_eq!(board.reply_to("G91", 100), "ok\n");
    assert_eq!(board.reply_to("G0 X-5 Y5", 10_000), "ok\n");
    let (x, y) = at(&board);
    assert!((x - 300).abs() <= 2 && (y - 300).abs() <= 2, "{x} {y}");
    assert_eq!(board.reply_to("G1 Z1", 100), "Error:Not available on this machine\nok\n");
    assert_eq!(board.reply_to("G1 X1 E1", 100), "Error:Not available on this machine\nok\n");
}

/// A carriage that does not move (motor unplugged) never oscillates: the
/// relay experiment gives up after 20 s with an error and the bridge off,
/// instead of driving it for ever.
#[test]
fn a_relay_tune_on_a_carriage_that_does_not_move_gives_up() {
    let mut board = SimBoard::powder_bed();
    // The motor's gain to zero: duty no longer turns it.
    board.powder_bed.as_mut().unwrap().carriage.plant = hal_sim::axis_plant::DcServoPlant::new(0.0, 0.03, 0.004, 0.0001);
    let reply = board.reply_to("M825", 25_000);
    assert_eq!(reply, "Error:Carriage relay tune failed (no steady oscillation)\nok\n");
}
