//! One step-rate trial per given rate on the real ELF, with the verdict of
//! every axis (the figures `cargo benchmark` bisects over):
//!
//!   cargo run --release -p avr-bench --example step_trials -- [--elf E] [--axes 1|3] 21000 25000 30000

use avr_bench::bench;
use avr_bench::board::RampsConfig;
use avr_bench::build::mega2560_elf;
use std::path::PathBuf;

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut take = |flag: &str| args.iter().position(|a| a == flag).map(|i| {
        args.remove(i);
        args.remove(i)
    });
    let elf = take("--elf").map(PathBuf::from).unwrap_or_else(mega2560_elf);
    let axes: usize = take("--axes").map_or(1, |a| a.parse().expect("--axes 1 or 3"));
    let mut config = RampsConfig::stock(115_200);
    config.endstops = bench::far_endstops();
    let mut board = bench::boot(&elf, config).unwrap_or_else(|e| panic!("{e}"));
    board.record_isr_intervals(true);
    for rate in args.iter().map(|r| r.parse::<f64>().expect("a rate in steps/s")) {
        board.record_isr_intervals(false);
        board.record_isr_intervals(true);
        let trial = bench::step_trial(&mut board, axes, rate).unwrap_or_else(|e| panic!("{e}"));
        for (index, (axis, verdict)) in ["X", "Y", "Z"].iter().zip(&trial.verdicts).enumerate() {
            println!(
                "{rate:>8.0} {axis}: {} steps, cruise {:.1} steps/s, worst lateness {:.1} % of the interval, shortest STEP pulse {} cycles: {}",
                verdict.steps,
                verdict.cruise_hz,
                verdict.worst_late * 100.0,
                board.min_step_pulse_cycles(index).map_or("-".into(), |c| c.to_string()),
                verdict.failure.as_deref().unwrap_or("on time")
            );
        }
        // Handler runs by length: where the step interrupt's time goes.
        let mut lengths: Vec<u64> = board.isr_intervals().iter().map(|&(a, b)| b - a).collect();
        lengths.sort_unstable();
        if !lengths.is_empty() {
            let at = |q: f64| lengths[((lengths.len() - 1) as f64 * q) as usize];
            println!(
                "         handler runs: {}, cycles median {}, 90 % {}, 99 % {}, 99.9 % {}, longest {}",
                lengths.len(), at(0.5), at(0.9), at(0.99), at(0.999), lengths[lengths.len() - 1]
            );
            let vectors = board.isr_vector_numbers();
            let mut by_vector: std::collections::BTreeMap<u32, (usize, u64)> = Default::default();
            for (&(a, b), &v) in board.isr_intervals().iter().zip(&vectors) {
                let e = by_vector.entry(v).or_default();
                e.0 += 1;
                e.1 = e.1.max(b - a);
            }
            for (v, (n, longest)) in by_vector {
                println!("         vector {v}: {n} runs, longest {longest} cycles");
            }
            // The step interrupt's commonest run lengths (ordinary event,
            // segment change, ...).
            let mut lengths17: std::collections::BTreeMap<u64, usize> = Default::default();
            for (&(a, b), &v) in board.isr_intervals().iter().zip(&vectors) {
                if v == 17 {
                    *lengths17.entry(b - a).or_default() += 1;
                }
            }
            let mut common: Vec<(u64, usize)> = lengths17.into_iter().collect();
            common.sort_by_key(|&(_, n)| std::cmp::Reverse(n));
            let common: Vec<String> = common.iter().take(6).map(|(c, n)| format!("{c} ×{n}")).collect();
            println!("         vector 17 commonest lengths (cycles ×runs): {}", common.join(", "));
            let mut locks: std::collections::BTreeMap<String, (usize, u64)> = Default::default();
            for &(pc, cycles) in board.main_loop_interrupt_locks() {
                let name = board.symbol_at(pc).map_or(String::new(), avr_bench::board::demangle);
                let e = locks.entry(format!("{name} at {pc:#x}")).or_default();
                e.0 += 1;
                e.1 = e.1.max(cycles);
            }
            let mut locks: Vec<_> = locks.into_iter().collect();
            locks.sort_by_key(|(_, (_, longest))| std::cmp::Reverse(*longest));
            for (name, (n, longest)) in locks.iter().take(6) {
                println!("         main loop, interrupts off: {n} times, longest {longest} cycles, in {name}");
            }
            // Around the latest plateau edge: what ran before it.
            if let (Some(step), Some(_)) = (trial.verdicts[0].failure.as_ref().and_then(|f| f.split("step ").nth(1)?.split(' ').next()?.parse::<usize>().ok()), Some(())) {
                let rises: Vec<u64> = board.step_edges(0).iter().filter(|e| e.rising).map(|e| e.cycle).collect();
                let edge = rises[step - 1];
                println!("         late step {step} rose at {edge}; previous rises {:?}", &rises[step.saturating_sub(4)..step - 1].iter().map(|c| edge - c).collect::<Vec<_>>());
                for (&(a, b), &v) in board.isr_intervals().iter().zip(&vectors) {
                    if b + 1500 > edge && a < edge + 100 {
                        println!("           vector {v:>2} from {:>6} to {:>6} before the edge ({} cycles)", edge as i64 - a as i64, edge as i64 - b as i64, b - a);
                    }
                }
            }
        }
    }
}
