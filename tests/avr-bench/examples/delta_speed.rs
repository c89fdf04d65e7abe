//! The delta's kinematics on the real ELF: how fast a stream of short
//! segments is taken (lines acknowledged per second, as `segment_speed`
//! measures the Prusa's; at 100 mm/s, 1 mm lines cannot go faster than
//! 100 a second, shorter ones show what the main loop manages), and the
//! main-loop cycles per inverse-kinematics call while it runs.
//!
//!   cargo run --release -p avr-bench --example delta_speed -- [ELF [SEGMENTS [MM]]]
//!
//! Without an ELF, builds `machines/delta.toml`'s. The moves circle the
//! bed's centre 40 mm out (inside the 130 mm printable radius), at 100
//! mm/s, from a position set with G92: no homing needed.

use avr_bench::bench;
use avr_bench::board::{RampsConfig, CPU_HZ};
use std::path::PathBuf;

/// The Rust symbol of the kinematics dispatch every segment goes through.
const INVERSE: &str = "MachineKinematicsNtB5_10Kinematics7inverse";

fn main() {
    let mut args = std::env::args().skip(1);
    let elf = match args.next() {
        Some(path) if path != "-" => PathBuf::from(path),
        _ => {
            let dir = avr_bench::build::workspace_root().join("target").join("avr-bench-delta");
            avr_bench::build::build_variant(&dir, &avr_bench::build::Machine::Shipped("delta.toml"), false)
                .unwrap_or_else(|e| panic!("{e}"))
        }
    };
    let segments: usize = args.next().map_or(300, |n| n.parse().expect("a segment count"));
    let length: f64 = args.next().map_or(1.0, |mm| mm.parse().expect("a segment length in mm"));
    let mut job = vec!["G90".to_string(), "M83".to_string(), "G92 X40 Y0 Z50 E0".to_string(), "G1 F6000".to_string(), "M302 P1".to_string()];
    let preamble = job.len();
    for i in 1..=segments {
        // `length` of arc per line on a 40 mm radius.
        let angle = i as f64 * length / 40.0;
        job.push(format!("G1 X{:.3} Y{:.3} E.0{:04}", 40.0 * angle.cos(), 40.0 * angle.sin(), 1700 + (i * 37) % 500));
    }
    let mut board = bench::boot(&elf, RampsConfig::stock(115_200)).unwrap_or_else(|e| panic!("{e}"));
    board.profile(true);
    board.inclusive_profile(true);
    board.inclusive_main_loop_only(true);
    board.send(job.iter());
    if !board.run_until_host_done(segments as f64 / 20.0 + 10.0) {
        panic!("the stream did not finish: {} lines acknowledged", board.host().lines_acknowledged());
    }
    board.run_for_ms(200.0);
    if let Some(reply) = board.host().replies.iter().find(|r| r.text.starts_with("Error") || r.text.contains("refused")) {
        panic!("the firmware answered {:?}", reply.text);
    }
    // Lines per second from the first streamed segment's start (after 5
    // lines of warm-up) to the last one's ok.
    let host = board.host();
    let sent: Vec<_> = host.sent.iter().filter(|s| s.job_index.is_some_and(|i| i >= preamble + 5)).collect();
    let (first, last) = (sent.first().expect("sent"), sent.last().expect("sent"));
    let ok = &host.replies[last.ok_reply.expect("last ok")];
    let lines_per_s = sent.len() as f64 / ((ok.arrived_cycle - first.start_cycle) as f64 / f64::from(CPU_HZ));
    // Calls: the entry instruction (a 2-cycle `push`) runs once per call.
    let range = board.function_range(INVERSE).expect("the inverse kinematics in the ELF");
    let calls = board.profile_at(range.start) / 2;
    let inclusive = board
        .inclusive_by_function()
        .into_iter()
        .find(|(name, _)| name.contains("MachineKinematics") && name.ends_with("::inverse"))
        .map_or(0, |(_, cycles)| cycles);
    println!("{segments} segments of {length} mm at 100 mm/s: {lines_per_s:.1} lines/s acknowledged");
    println!(
        "inverse kinematics: {calls} calls, {inclusive} cycles in all, {} cycles ({:.0} µs) per call",
        inclusive / calls.max(1),
        inclusive as f64 / calls.max(1) as f64 / 16.0
    );
}
