//! Issue 23's figures alone (the rest of `cargo benchmark` skipped):
//!
//!   cargo run --release -p avr-bench --example even_steps -- ELF [even1|even3|lines|speed|trial AXES RATE]...
use avr_bench::bench;
use std::path::PathBuf;
fn main() {
    let mut args = std::env::args().skip(1);
    let elf = PathBuf::from(args.next().expect("ELF"));
    let what: Vec<String> = args.collect();
    let all = what.is_empty();
    let has = |w: &str| all || what.iter().any(|a| a == w);
    for axes in [1, 3] {
        if !has(&format!("even{axes}")) {
            continue;
        }
        match bench::even_step_rate(&elf, axes) {
            Ok(r) => {
                println!("step_rate_even_{axes}: {} per axis (limit {:?}); longest step ISR {} cycles", r.per_axis_hz, r.limit, r.longest_step_isr);
                for (rate, failure, worst) in &r.trials {
                    println!("  {rate:>8.0}: {:5.1} %  {}", worst * 100.0, failure.as_deref().unwrap_or("even"));
                }
            }
            Err(e) => println!("step_rate_even_{axes}: {e}"),
        }
    }
    if let Some(i) = what.iter().position(|a| a == "trial") {
        let axes: usize = what[i + 1].parse().unwrap();
        let rate: f64 = what[i + 2].parse().unwrap();
        let mut config = avr_bench::board::RampsConfig::stock(115_200);
        config.endstops = bench::far_endstops();
        let mut board = bench::boot(&elf, config).unwrap();
        let t = bench::even_trial(&mut board, axes, rate).unwrap();
        println!("trial {axes} x {rate}: longest ISR {} {:?}", t.longest_step_isr, t.verdicts);
    }
    if has("lines") {
        match bench::lines_per_s(&elf, 115_200, 400, 0.5) {
            Ok((rate, longest, _)) => println!("lines_per_s_0_5mm_115200: {rate:.1} (longest step ISR {longest})"),
            Err(e) => println!("lines_per_s_0_5mm_115200: {e}"),
        }
    }
    if has("speed") {
        for length in [0.5, 0.2] {
            match bench::segment_speed(&elf, 115_200, (60.0 / length) as usize, length) {
                Ok((ratio, lines, _)) => println!("segment_speed_ratio_{length}mm_115200: {ratio:.3} ({lines:.0} lines/s)"),
                Err(e) => println!("segment_speed {length}: {e}"),
            }
        }
    }
}
