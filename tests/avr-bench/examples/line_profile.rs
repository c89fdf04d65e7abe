//! Where a chord stream's cycles go: the `lines_per_s_0_5mm_115200` job
//! (unnumbered 0.5 mm chords at 250 mm/s, one line in flight, 115200 baud)
//! on the real ELF with the per-function profiler, main loop only
//! (interrupt handlers listed by their own cycles):
//!
//!   cargo run --release -p avr-bench --example line_profile -- ELF [SEGMENTS] [LENGTH_MM]
//!
//! With `--parse` (`ELF --parse`): only `cargo benchmark`'s
//! `parse_cycles_per_g1_line` and its parts.
use avr_bench::bench;
use avr_bench::board::RampsConfig;
use avr_bench::host::HostConfig;
use std::path::PathBuf;

fn main() {
    let mut args = std::env::args().skip(1);
    let elf = PathBuf::from(args.next().expect("ELF"));
    let mut args = args.peekable();
    if args.peek().is_some_and(|a| a == "--parse") {
        let p = bench::parse_cycles(&elf, 4).unwrap_or_else(|e| panic!("{e}"));
        println!(
            "parse_cycles_per_g1_line: {:.0} (G1 to its ok {:.0} − empty line {:.0}, medians of {}; then planning {:.0})",
            p.cycles_per_line(),
            p.g1_median,
            p.baseline_median,
            p.lines,
            p.planning_mean
        );
        return;
    }
    let segments: usize = args.next().map_or(200, |a| a.parse().expect("a count"));
    let length: f64 = args.next().map_or(0.5, |a| a.parse().expect("a length in mm"));
    let mut config = RampsConfig::stock(115_200);
    config.host = HostConfig::raw(115_200);
    let mut board = bench::boot(&elf, config).unwrap_or_else(|e| panic!("{e}"));
    let mut job = bench::segments_of(segments, length);
    job[3] = format!("G1 F{:.0}", bench::LINES_FEED_MM_S * 60.0);
    job.insert(0, format!("M203 X{0:.0} Y{0:.0}", bench::LINES_FEED_MM_S));
    let header: Vec<&str> = job[..6].iter().map(String::as_str).collect();
    bench::exchange(&mut board, &header, 5.0).unwrap_or_else(|e| panic!("{e}"));
    board.profile(true);
    board.inclusive_profile(true);
    board.inclusive_main_loop_only(true);
    let start = board.cycle();
    let isr_start = board.stats().isr_cycles;
    board.send(job[6..].iter());
    assert!(board.run_until_host_done(segments as f64 * 0.02 + 10.0), "the stream did not finish");
    let total = board.cycle() - start;
    let n = segments as f64;
    println!(
        "{segments} chords: {total} cycles, {:.0} a line ({:.1} lines/s), {:.0} a line in interrupt handlers",
        total as f64 / n,
        n * 16e6 / total as f64,
        (board.stats().isr_cycles - isr_start) as f64 / n
    );
    println!("exclusive, cycles a line:");
    for (function, cycles) in board.profile_by_function().iter().take(50) {
        println!("{:>8.0}  {function}", *cycles as f64 / n);
    }
    println!("inclusive (main loop only), cycles a line:");
    for (function, cycles) in board.inclusive_by_function().iter().take(70) {
        println!("{:>8.0}  {function}", *cycles as f64 / n);
    }
}
