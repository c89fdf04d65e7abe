//! Where the cycles go: send G-code lines to the real ELF on simavr and
//! print the replies and the cycles spent per function while handling them.
//!
//!   cargo run --release -p avr-bench --example profile -- "G1 X103.474 Y98.612 E.02538" M105
//!   cargo run --release -p avr-bench --example profile -- --elf path/to.elf M503
//!
//! Lines go out one at a time after each `ok`, verbatim, at 115200 baud.

use avr_bench::bench;
use avr_bench::board::RampsConfig;
use avr_bench::build::mega2560_elf;
use avr_bench::host::HostConfig;
use std::path::PathBuf;

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let elf = match args.iter().position(|a| a == "--elf") {
        Some(i) => {
            args.remove(i);
            PathBuf::from(args.remove(i))
        }
        None => mega2560_elf(),
    };
    if args.is_empty() {
        args.push("G1 X103.474 Y98.612 E.02538".into());
    }
    let mut config = RampsConfig::stock(115_200);
    config.host = HostConfig::raw(115_200);
    let mut board = bench::boot(&elf, config).unwrap_or_else(|e| panic!("{e}"));
    board.profile(true);
    board.inclusive_profile(true);
    // FERROSTEP_PROFILE_MAIN_ONLY: the inclusive figures leave out the
    // handlers that interrupted each function (the main loop's own cost).
    board.inclusive_main_loop_only(std::env::var_os("FERROSTEP_PROFILE_MAIN_ONLY").is_some());
    board.sample_pcs(2_000);
    let start = board.cycle();
    let isr_start = board.stats().isr_cycles;
    let lines: Vec<&str> = args.iter().map(String::as_str).collect();
    for reply in bench::exchange(&mut board, &lines, 30.0).unwrap_or_else(|e| panic!("{e}")) {
        println!("< {reply}");
    }
    let total = board.cycle() - start;
    // Each line's answer time: from its last byte's start bit to the first
    // byte of its `ok` leaving the chip.
    let host = board.host();
    let answers: Vec<String> = host
        .sent
        .iter()
        .filter_map(|s| Some((s.text.clone(), host.replies[s.ok_reply?].first_byte_cycle - s.last_byte_start_cycle?)))
        .map(|(text, cycles)| format!("{text}: {cycles}"))
        .collect();
    if answers.len() <= 12 {
        println!("cycles from each line's last byte to its ok: {answers:?}");
    }
    println!(
        "{} cycles ({:.2} ms) from the first byte sent to the last ok, {} in interrupt handlers",
        total,
        total as f64 / 16_000.0,
        board.stats().isr_cycles - isr_start
    );
    println!("(the main loop's idle polling is part of its own line)");
    for (function, cycles) in board.profile_by_function().iter().take(60) {
        println!(
            "{cycles:>10} {:5.1} %  {function}",
            *cycles as f64 * 100.0 / total as f64
        );
    }
    println!("inclusive (with everything called; handlers count for what they interrupted):");
    for (function, cycles) in board.inclusive_by_function().iter().take(90) {
        println!("{cycles:>10} {:5.1} %  {function}", *cycles as f64 * 100.0 / total as f64);
    }
    // Who calls memcpy, how often (FERROSTEP_PROFILE_CALLS=memcpy): each
    // `call` instruction's cycles / 5 = its executions.
    if let Ok(callee) = std::env::var("FERROSTEP_PROFILE_CALLS") {
        let dump = std::process::Command::new("avr-objdump").arg("-d").arg(&elf).output().expect("avr-objdump");
        let mut sites: Vec<(u64, String)> = String::from_utf8_lossy(&dump.stdout)
            .lines()
            .filter(|l| l.contains("call") && l.contains(&format!("<{callee}>")))
            .filter_map(|l| u32::from_str_radix(l.trim().split(':').next()?, 16).ok())
            .map(|pc| (board.profile_at(pc) / 5, board.symbol_at(pc).map_or(format!("{pc:#x}"), |s| format!("{} at {pc:#x}", avr_bench::board::demangle(s)))))
            .filter(|(n, _)| *n > 0)
            .collect();
        sites.sort_by_key(|s| std::cmp::Reverse(s.0));
        for (n, site) in sites.iter().take(15) {
            println!("{n:>8} calls of {callee} from {site}");
        }
    }
    let (cycles, functions) = board.longest_pass_samples();
    println!("longest main-loop pass: {cycles} cycles ({:.2} ms); PC samples every 2000 cycles in it:", cycles as f64 / 16_000.0);
    for (function, samples) in functions.iter().take(15) {
        println!("{samples:>6}  {function}");
    }
}
