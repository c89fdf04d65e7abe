//! How close streams of short segments at 100 mm/s come to full speed on
//! the real ELF (`cargo benchmark`'s `segment_speed_ratio_*`), for the
//! given segment lengths:
//!
//!   cargo run --release -p avr-bench --example segment_speed -- ELF BAUD 1 0.5 0.2
//!
//! (`cargo benchmark` uses the 250000-baud build and 60 mm of path.)

use avr_bench::bench;
use std::path::PathBuf;

fn main() {
    let mut args = std::env::args().skip(1);
    let elf = PathBuf::from(args.next().expect("ELF"));
    let baud: u32 = args.next().expect("baud").parse().expect("baud");
    for length in args.map(|a| a.parse::<f64>().expect("a length in mm")) {
        match bench::segment_speed(&elf, baud, (60.0 / length) as usize, length) {
            Ok((ratio, lines, _)) => println!("{length} mm: {ratio:.3} of full speed, {lines:.0} lines/s acknowledged"),
            Err(e) => println!("{length} mm: {e}"),
        }
    }
}
