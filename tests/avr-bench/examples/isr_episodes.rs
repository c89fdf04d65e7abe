//! The longest run of each interrupt vector on the real ELF (the figures
//! of `boards/mega2560-ramps/src/interrupts.rs`): boots the ELF, sends the
//! lines given (one after each `ok`), optionally streams short segments,
//! and prints per vector the number of top-level runs and the longest, in
//! cycles from the vector's entry (5 cycles included) to the `reti` that
//! brings the nesting back to zero, so handlers nested inside a run count
//! in it, and the longest run of the handler's own code (the nested runs
//! taken out). Then the longest main-loop stretches with interrupts off.
//!
//!   cargo run --release -p avr-bench --example isr_episodes -- ELF BAUD [--segments N MM] [--nse5310] [LINE...]
use avr_bench::bench;
use avr_bench::board::{Nse5310Pair, RampsConfig};
use avr_bench::host::HostConfig;
use std::collections::BTreeMap;
use std::path::PathBuf;

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let elf = PathBuf::from(args.remove(0));
    let baud: u32 = args.remove(0).parse().expect("baud");
    let mut segments = None;
    if let Some(i) = args.iter().position(|a| a == "--segments") {
        args.remove(i);
        let count: usize = args.remove(i).parse().expect("segment count");
        let length: f64 = args.remove(i).parse().expect("segment length, mm");
        segments = Some((count, length));
    }
    let nse5310 = args.iter().position(|a| a == "--nse5310").map(|i| args.remove(i)).is_some();
    let mut config = RampsConfig::stock(baud);
    config.host = HostConfig::raw(baud);
    let mut board = bench::boot(&elf, config).unwrap_or_else(|e| panic!("{e}"));
    if nse5310 {
        board.attach_nse5310(Nse5310Pair::prusa());
    }
    board.record_isr_intervals(true);
    let lines: Vec<&str> = args.iter().map(String::as_str).collect();
    for reply in bench::exchange(&mut board, &lines, 30.0).unwrap_or_else(|e| panic!("{e}")) {
        println!("< {reply}");
    }
    if let Some((count, length)) = segments {
        let job = bench::segments_of(count, length);
        board.send(job.iter());
        board.run_until_host_done(60.0);
    }
    let mut worst: BTreeMap<u32, (u64, usize)> = BTreeMap::new();
    for (&(a, b), v) in board.isr_intervals().iter().zip(board.isr_vector_numbers()) {
        let entry = worst.entry(v).or_default();
        entry.0 = entry.0.max(b - a);
        entry.1 += 1;
    }
    let own: BTreeMap<u32, u64> = board.isr_own_longest().into_iter().map(|(v, cycles, _)| (v, cycles)).collect();
    println!("vector  runs  longest run  longest own (cycles; own = without nested handlers)");
    for (v, (longest, runs)) in &worst {
        println!("{v:>6} {runs:>5}  {longest:>11}  {:>11}", own.get(v).copied().unwrap_or(0));
    }
    for (v, cycles) in own.iter().filter(|(v, _)| !worst.contains_key(v)) {
        println!("{v:>6}  nested only  {cycles:>11}");
    }
    let mut locks = board.main_loop_interrupt_locks().to_vec();
    locks.sort_by_key(|l| std::cmp::Reverse(l.1));
    for &(pc, cycles) in locks.iter().take(5) {
        let name = board.symbol_at(pc).map(avr_bench::board::demangle).unwrap_or_default();
        println!("main-loop lock {cycles:>5} cycles at {name}");
    }
    println!("resets {}", board.stats().resets);
}
