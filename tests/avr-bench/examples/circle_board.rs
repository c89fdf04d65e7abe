//! SPEC §1's circle on the encoder build's own loops (issue 26):
//! `cargo run -p avr-bench --release --example circle_board [SPEED] [ROW…]`
//! (ROW: a label's start, e.g. "M821 S2"; default every row, 5 mm/s;
//! CIRCLE_WINDOWS=1: the MSE every 0.25 s; CIRCLE_PLANT="0.9 0.94 0.005": other carriages).

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
        // CIRCLE_PLANT="k'x k'y lag_s": other carriages (the rigid row keeps its own).
        let last = match std::env::var("CIRCLE_PLANT") {
            Ok(text) if strategy.thesis_plant => {
                let v: Vec<f64> = text.split_whitespace().map(|f| f.parse().expect("CIRCLE_PLANT")).collect();
                run_circle_on(&mut board, &strategy, speed, CarriagePlant::new([v[0], v[1]], v[2]))
            }
            _ => run_circle(&mut board, &strategy, speed),
        };
        match &last {
            Ok(run) => println!(
                "{:<28} {:>5} mm/s  X {:.6}  Y {:.6}  total {:.6} mm²  max {:.4} mm  glitches {}/{} (idx {} bounce {} missed {})  corr {:?}  {:?}  ({} samples, {:.0} s wall)",
                run.label, run.speed_mm_s, run.mse_x, run.mse_y, run.mse_total, run.max_error_mm, run.glitches_counted, run.glitches_injected,
                run.index_accepted, run.index_bounces, run.index_missed, run.corrections, run.error, run.samples, started.elapsed().as_secs_f64()
            ),
            Err(e) => println!("{name}: {e}"),
        }
        if let (Ok(from), Ok(run)) = (std::env::var("CIRCLE_DUMP_FROM"), &last) {
            let from: f64 = from.parse().expect("CIRCLE_DUMP_FROM");
            for e in run.errors.iter().filter(|e| e.0 >= from).take(120) {
                println!("  {:.3} {:+.4} {:+.4}", e.0, e.1, e.2);
            }
        }
        if std::env::var_os("CIRCLE_WINDOWS").is_some() {
            if let Ok(run) = &last {
                for window in run.errors.chunks(250) {
                    let n = window.len() as f64;
                    let (mx, my) = (window.iter().map(|e| e.1 * e.1).sum::<f64>() / n, window.iter().map(|e| e.2 * e.2).sum::<f64>() / n);
                    let peak = window.iter().map(|e| e.1.abs().max(e.2.abs())).fold(0.0, f64::max);
                    println!("  t {:6.2}  X {:.6}  Y {:.6}  peak {:.4}", window[0].0, mx, my, peak);
                }
            }
        }
    }
}
