//! `M828` on the real ELF of the encoder build: the board streams every
//! loop sample of its NSE-5310s as `TR:` lines; the host's log replays in
//! `cargo sim replay` (ferrosim's replay of a capture) and shows what the
//! strip did: a clean move tracks its steps, a belt slip raises the
//! following-error alarm there (the loops are off on the board, which only
//! records).

use avr_bench::bench::{self, exchange};
use avr_bench::board::{Board, Nse5310Pair, RampsConfig};
use avr_bench::host::HostConfig;
use ferrosim::replay::Replay;

fn encoder_board() -> Board {
    let dir = avr_bench::build::target_dir().join("machines").join("encoders");
    let elf = avr_bench::build::build_variant(&dir, &avr_bench::build::Machine::PRUSA_ENCODERS, false)
        .unwrap_or_else(|e| panic!("the encoders build: {e}"));
    let mut config = RampsConfig::stock(115_200);
    config.host = HostConfig::raw(115_200);
    let mut board = bench::boot(&elf, config).expect("the firmware boots");
    board.attach_nse5310(Nse5310Pair::prusa());
    board
}

fn replies(board: &mut Board, lines: &[&str]) -> Vec<String> {
    exchange(board, lines, 10.0).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn an_m828_capture_from_the_board_replays_on_the_laptop() {
    let mut board = encoder_board();
    assert_eq!(replies(&mut board, &["M828"]), ["echo:Trace off", "ok"]);
    assert_eq!(replies(&mut board, &["M828 S1"]), ["TR:start 250 100000 100000", "ok"]);
    assert_eq!(replies(&mut board, &["M828"]).last().map(String::as_str), Some("ok"));
    // A 20 mm move on X and 10 mm on Y at 20 mm/s, then a rest.
    assert_eq!(replies(&mut board, &["G1 X20 Y10 F1200"]).last().map(String::as_str), Some("ok"));
    replies(&mut board, &["M400"]);
    board.run_for_ms(300.0);
    // (The samples the host has before the slip.)
    let before_slip = board.host().transcript().lines().filter(|l| l.starts_with("TR:") && !l.contains(' ')).count();
    // The X belt slips 2.5 mm (5120 counts) over 100 ms and stays there:
    // with the loops off the board only records it.
    for step in 1..=10 {
        board.nse5310().unwrap().slip_units[0] = -512.0 * f64::from(step);
        board.run_for_ms(10.0);
    }
    board.run_for_ms(1000.0);
    replies(&mut board, &["M828 S0"]);
    board.run_for_ms(50.0);
    let log = board.host().transcript();
    // FERROSTEP_CAPTURE_OUT=<file>: keep the host's log (for trying
    // `cargo sim replay <file>`).
    if let Some(path) = std::env::var_os("FERROSTEP_CAPTURE_OUT") {
        std::fs::write(&path, &log).expect("write the capture");
    }
    assert!(log.contains("TR:end "), "no end line: {}", &log[log.len().saturating_sub(400)..]);

    let replayed = ferrosim::replay::replay_capture_text(&log).unwrap_or_else(|e| panic!("{e}"));
    let capture = &replayed.capture;
    let (recorded, dropped) = capture.totals.unwrap();
    println!("{}", replayed.summary());
    // Every sample reached the host at 115200 baud, none dropped.
    assert_eq!((dropped, capture.gaps), (0, 0));
    assert_eq!(capture.axes[0].len() as u32, recorded);
    // ≈ 1.1 s of move, 0.3 s of rest, 1 s after the slip: 250 a second.
    assert!((500..800).contains(&recorded), "{recorded} samples");
    let [x, y] = &replayed.axes;
    let commanded = |axis: &Replay| axis.rows.last().and_then(|row| row.commanded_mm).unwrap();
    assert_eq!((commanded(x), commanded(y)), (20.0, 10.0));
    // Y tracked its steps all along (within two steps: the steps are
    // taken a moment before the chips are read, at 20 mm/s).
    assert_eq!(y.report.fault, None);
    assert!(y.report.max_error_mm < 0.05, "Y {}", y.report.max_error_mm);
    assert!((y.report.positions_mm.last().unwrap() - 10.0).abs() < 0.01);
    // X tracked until the slip, then followed the strip 2.5 mm off, and
    // the replayed following-error check stops the job 0.5 s after the
    // error passed 1 mm (the board's default limit: 1 mm for 0.5 s).
    let error_before_slip = x.rows[..before_slip]
        .iter()
        .zip(&x.report.positions_mm)
        .map(|(r, at)| (r.commanded_mm.unwrap() - at).abs())
        .fold(0.0, f64::max);
    assert!(error_before_slip < 0.05, "X before the slip {error_before_slip}");
    assert!((x.report.max_error_mm - 2.5).abs() < 0.05, "X {}", x.report.max_error_mm);
    let (row, fault) = x.report.fault.expect("the slip raises the alarm");
    assert!(format!("{fault:?}").starts_with("FollowingError"), "{fault:?}");
    let slipped = x
        .rows
        .iter()
        .zip(&x.report.positions_mm)
        .position(|(r, at)| (r.commanded_mm.unwrap() - at).abs() > 1.0)
        .expect("the replay sees the slip");
    let seconds = x.rows[row].time_s - x.rows[slipped].time_s;
    assert!((0.4..0.7).contains(&seconds), "alarm {seconds} s after the slip");
}
