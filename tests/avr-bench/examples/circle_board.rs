//! SPEC §1's circle on the encoder build's own loops (issue 26):
//! `cargo run -p avr-bench --release --example circle_board [SPEED] [ROW…]`
//! (ROW: a label's start, e.g. "M821 S2"; default every row, 5 mm/s).

use avr_bench::board::{Nse5310Pair, RampsConfig};
use avr_bench::carriage::*;

fn main() {
    let mut args = std::env::args().skip(1);
    let speed: f64 = args.next().map(|s| s.parse().expect("speed")).unwrap_or(5.0);
    let rows: Vec<String> = args.collect();
    let dir = avr_bench::build::target_dir().join("machines").join("encoders");
    let elf = avr_bench::build::build_variant(&dir, &avr_bench::build::Machine::PRUSA_ENCODERS, false).expect("the encoders build");
    for strategy in ALL_STRATEGIES {
        let name = strategy.label;
        if !rows.is_empty() && !rows.iter().any(|r| name.starts_with(r.as_str())) {
            continue;
        }
        let mut board = avr_bench::bench::boot(&elf, RampsConfig::stock(115_200)).expect("boots");
        board.attach_nse5310(Nse5310Pair::prusa());
        let started = std::time::Instant::now();
        match run_circle(&mut board, &strategy, speed) {
            Ok(run) => println!(
                "{:<28} {:>5} mm/s  X {:.6}  Y {:.6}  total {:.6} mm²  max {:.4} mm  glitches {}/{} (idx {} bounce {} missed {})  corr {:?}  {:?}  ({} samples, {:.0} s wall)",
                run.label, run.speed_mm_s, run.mse_x, run.mse_y, run.mse_total, run.max_error_mm, run.glitches_counted, run.glitches_injected,
                run.index_accepted, run.index_bounces, run.index_missed, run.corrections, run.error, run.samples, started.elapsed().as_secs_f64()
            ),
            Err(e) => println!("{name}: {e}"),
        }
    }
}
