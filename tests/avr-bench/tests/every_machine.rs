//! Every shipped machine file's ELF, built with every option it names,
//! boots on the simulated Mega 2560, answers a tour of the commands that
//! reach deepest into the stack (reports, settings save and load) and stays
//! inside its budgets: 6 KiB of static RAM and at least 1 KiB of stack
//! margin (SP watched after every instruction), no reset.
//!
//! The ELFs are CI's (`test.sh` keeps `$FERROSTEP_MACHINES_DIR/NAME.elf`);
//! without that directory each file is built here.

use avr_bench::bench::{self, exchange, stack_budget, STACK_MARGIN_BYTES, STATIC_RAM_BUDGET_BYTES};
use avr_bench::board::RampsConfig;
use avr_bench::host::HostConfig;
use avr_bench::build::{shipped_elf, workspace_root};
use avr_bench::elf::{ElfInfo, RAM_BYTES};
use std::path::PathBuf;

fn machine_files() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(workspace_root().join("machines"))
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.ends_with(".toml"))
        .collect();
    names.sort();
    names
}

fn elf_of(name: &str) -> PathBuf {
    shipped_elf(name.trim_end_matches(".toml"))
}

#[test]
fn every_machine_file_boots_within_its_ram_and_stack_budgets() {
    let mut table = Vec::new();
    for name in machine_files() {
        let machine = machine_file::load(&workspace_root().join("machines").join(&name)).unwrap();
        let elf = elf_of(&name);
        let ram_static = ElfInfo::read(&elf).unwrap().ram_static_bytes();
        assert!(ram_static <= STATIC_RAM_BUDGET_BYTES, "{name}: static RAM {ram_static} B");
        let mut config = RampsConfig::stock(machine.baud);
        config.host = HostConfig::raw(machine.baud);
        let mut board = bench::boot(&elf, config).unwrap_or_else(|e| panic!("{name}: {e}"));
        let replies = exchange(&mut board, &["M115", "M105", "M114", "M119", "M503", "M500", "M501", "G4 P10"], 20.0)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let text = replies.join("\n");
        assert!(text.contains(&format!("MACHINE_TYPE:{} ", machine.name)), "{name}: {text}");
        assert!(text.contains("echo:Settings Stored ("), "{name}: {text}");
        assert!(text.contains("stored settings retrieved"), "{name}: {text}");
        let stack = board.stack_peak_sp();
        let margin = RAM_BYTES - ram_static - stack;
        table.push(format!("{name:<24} static {ram_static:>5} B  stack peak {stack:>5} B  margin {margin:>5} B"));
        assert!(stack > 0 && stack <= stack_budget(ram_static), "{name}: stack {stack} B leaves {margin} B, under {STACK_MARGIN_BYTES} B");
        assert_eq!(board.stats().resets, 0, "{name}");
    }
    eprintln!("{}", table.join("\n"));
}
