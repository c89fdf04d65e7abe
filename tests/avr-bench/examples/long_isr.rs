//! Where the longest step-interrupt runs spend their cycles: streams 120
//! half-millimetre segments at 115200 baud and prints, for the six longest
//! runs of the step interrupt (vector 17), the functions on the stack in
//! PC samples taken every 7 cycles (handlers nested in a run included):
//!
//!   cargo run --release -p avr-bench --example long_isr -- ELF
use avr_bench::bench;
use avr_bench::board::RampsConfig;
use std::path::PathBuf;
fn main() {
    let mut args = std::env::args().skip(1);
    let elf = PathBuf::from(args.next().unwrap());
    let mut board = bench::boot(&elf, RampsConfig::stock(115_200)).unwrap();
    board.record_isr_intervals(true);
    board.inclusive_profile(true);
    board.sample_pcs(7);
    let job = bench::segments_of(120, 0.5);
    board.send(job.iter());
    board.run_until_host_done(20.0);
    let mut runs: Vec<(u64, u64)> = board.isr_intervals().iter().zip(board.isr_vector_numbers()).filter(|(_, v)| *v == 17).map(|(r, _)| *r).collect();
    runs.sort_by_key(|(a, b)| std::cmp::Reverse(b - a));
    for &(a, b) in runs.iter().take(6) {
        println!("run of {} cycles: {:?}", b - a, board.stack_samples_between(a, b));
    }
}
