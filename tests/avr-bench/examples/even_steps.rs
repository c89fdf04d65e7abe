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
        println!("trial {axes} x {rate}: longest ISR {} (cruise {}) {:?}", t.longest_step_isr, t.longest_cruise_step_isr, t.verdicts);
    }
    if let Some(i) = what.iter().position(|a| a == "diag") {
        // The longest runs of every interrupt during one trial, and where
        // the longest step-interrupt runs spent their cycles.
        let axes: usize = what[i + 1].parse().unwrap();
        let rate: f64 = what[i + 2].parse().unwrap();
        let mut config = avr_bench::board::RampsConfig::stock(115_200);
        config.endstops = bench::far_endstops();
        let mut board = bench::boot(&elf, config).unwrap();
        board.inclusive_profile(true);
        board.sample_pcs(7);
        let (setup, moves, _) = bench::even_job(axes, rate);
        let setup: Vec<&str> = setup.iter().map(String::as_str).collect();
        bench::exchange(&mut board, &setup, 5.0).unwrap();
        board.record_isr_intervals(true);
        let mut lines: Vec<&str> = moves.iter().map(String::as_str).collect();
        lines.push("M400");
        bench::exchange(&mut board, &lines, 20.0).unwrap();
        let mut worst: std::collections::BTreeMap<u32, (u64, usize)> = Default::default();
        for (&(a, b), v) in board.isr_intervals().iter().zip(board.isr_vector_numbers()) {
            let e = worst.entry(v).or_default();
            e.0 = e.0.max(b - a);
            e.1 += 1;
        }
        println!("longest run by vector (cycles, count): {worst:?}");
        let mut runs: Vec<(u64, u64)> = board.isr_intervals().iter().zip(board.isr_vector_numbers()).filter(|(_, v)| *v == bench::STEP_VECTOR).map(|(r, _)| *r).collect();
        runs.sort_by_key(|(a, b)| std::cmp::Reverse(b - a));
        let rises: Vec<u64> = board.step_edges(avr_bench::board::X).iter().filter(|e| e.rising).map(|e| e.cycle).collect();
        for &(a, b) in runs.iter().take(4) {
            let step = rises.partition_point(|&c| c < a);
            println!("step run of {} cycles after step {step}: {:?}", b - a, board.stack_samples_between(a, b).into_iter().take(12).collect::<Vec<_>>());
        }
        // Step-interrupt runs by what they did (no other handler nested):
        // a histogram of durations.
        let mut hist: std::collections::BTreeMap<u64, usize> = Default::default();
        for &(a, b) in &runs {
            *hist.entry((b - a) / 20 * 20).or_default() += 1;
        }
        println!("step runs by duration (20-cycle bins): {hist:?}");
        let long: Vec<usize> = runs.iter().filter(|(a, b)| b - a > 450).map(|(a, _)| rises.partition_point(|&c| c < *a)).collect();
        let mut long = long;
        long.sort();
        println!("{} step runs over 450 cycles, after steps {:?}", long.len(), &long[..long.len().min(60)]);
        let (_, _, steps) = bench::even_job(axes, rate);
        let verdict = bench::judge_even(board.step_edges(avr_bench::board::X), steps, rate);
        println!("{verdict:?}");
        let k = verdict.worst_interval.1 as usize;
        if k >= 2 {
            let (t0, t1) = (rises[k - 2], rises[k - 1]);
            let around: Vec<_> = board
                .isr_intervals()
                .iter()
                .zip(board.isr_vector_numbers())
                .filter(|(&(a, b), _)| b + 200 >= t0 && a <= t1)
                .map(|(&(a, b), v)| format!("v{v} {}..{}", a as i64 - t0 as i64, b as i64 - t0 as i64))
                .collect();
            println!("worst interval: edges at 0 and {}; interrupts {around:?}", t1 - t0);
            println!("samples: {:?}", board.timeline_between(t1.saturating_sub(250), t1 + 100).into_iter().take(40).collect::<Vec<_>>());
        }
        let mut locks = board.main_loop_interrupt_locks().to_vec();
        locks.sort_by_key(|l| std::cmp::Reverse(l.1));
        let named: Vec<_> = locks.iter().take(6).map(|&(pc, n)| (board.symbol_at(pc).map(avr_bench::board::demangle).unwrap_or_default(), n)).collect();
        println!("longest main-loop interrupt locks: {named:?}");
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
