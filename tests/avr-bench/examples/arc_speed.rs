//! How close a G2 circle at 100 mm/s (radius 20 mm: 125.7 mm of path, cut
//! into chords on the board) comes to full speed on the real ELF: the path
//! length over 100 mm/s divided by the time from the first to the last
//! X/Y STEP edge, the two ramps included (Arc Welder and similar
//! post-processors turn a slicer's curves into such arcs):
//!
//!   cargo run --release -p avr-bench --example arc_speed -- ELF [RADIUS_MM]
use avr_bench::bench;
use avr_bench::board::RampsConfig;
use std::path::PathBuf;

fn main() {
    let mut args = std::env::args().skip(1);
    let elf = PathBuf::from(args.next().expect("ELF"));
    let radius: f64 = args.next().map_or(20.0, |r| r.parse().expect("a radius in mm"));
    let mut board = bench::boot(&elf, RampsConfig::stock(115_200)).unwrap_or_else(|e| panic!("{e}"));
    let job = ["G90".to_string(), "G92 X120 Y100 E0".into(), "G1 F6000".into(), format!("G2 X120 Y100 I-{radius} J0")];
    board.send(job.iter());
    board.run_until_host_done(30.0);
    board.run_for_ms(2000.0);
    let (x, y) = (0, 1);
    let edges: Vec<u64> = [x, y].iter().flat_map(|&axis| board.step_edges(axis).iter().filter(|e| e.rising).map(|e| e.cycle)).collect();
    let (first, last) = (edges.iter().min().expect("steps"), edges.iter().max().expect("steps"));
    let seconds = (last - first) as f64 / 16e6;
    let ideal = 2.0 * std::f64::consts::PI * radius / 100.0;
    println!("circle of radius {radius} mm at 100 mm/s: {:.3} of full speed ({seconds:.3} s for {ideal:.3} s ideal), replies {:?}", ideal / seconds, board.host().replies.iter().map(|r| r.text.clone()).filter(|t| t != "ok").collect::<Vec<_>>());
}
