//! The stack margin of an ELF (any machine file's build): the tour of
//! `every_machine.rs` (the commands that reach deepest) and then 200 chords
//! of `lines_per_s`' stream, with the lowest SP watched after every
//! instruction:
//!
//!   cargo run --release -p avr-bench --example stack_tour -- ELF [BAUD]
use avr_bench::bench::{self, exchange};
use avr_bench::board::RampsConfig;
use avr_bench::elf::{ElfInfo, RAM_BYTES};
use avr_bench::host::HostConfig;
use std::path::PathBuf;

fn main() {
    let mut args = std::env::args().skip(1);
    let elf = PathBuf::from(args.next().expect("ELF"));
    let baud: u32 = args.next().map_or(115_200, |a| a.parse().expect("baud"));
    let ram_static = ElfInfo::read(&elf).unwrap().ram_static_bytes();
    let mut config = RampsConfig::stock(baud);
    config.host = HostConfig::raw(baud);
    let mut board = bench::boot(&elf, config).unwrap_or_else(|e| panic!("{e}"));
    let replies = exchange(&mut board, &["M115", "M105", "M114", "M119", "M503", "M500", "M501", "G4 P10"], 20.0).unwrap_or_else(|e| panic!("{e}"));
    let tour = board.stack_peak_sp();
    let mut job = bench::segments_of(200, 0.5);
    job.insert(0, "M203 X250 Y250".into());
    board.send(job.iter());
    let done = board.run_until_host_done(20.0);
    let stack = board.stack_peak_sp();
    println!(
        "static {ram_static} B, stack peak {tour} B after the tour, {stack} B after the chords{}: margin {} B (budget ≥ {} B); {} replies, resets {}",
        if done { "" } else { " (stream unfinished)" },
        RAM_BYTES - ram_static - stack,
        bench::STACK_MARGIN_BYTES,
        replies.len(),
        board.stats().resets
    );
}
