//! The SKR Pro build (STM32F407) on QEMU's `netduinoplus2` (an STM32F405:
//! the same Cortex-M4F core and peripherals at the same addresses), with
//! USART1 on pipes; its flash size read from the ELF; and the step
//! interrupt's cost counted from an instruction trace.
//!
//! The firmware is linked at 0x08008000, behind the SKR Pro's SD-card
//! bootloader. QEMU has no bootloader: it is told to start with VTOR at
//! the ELF's vector table (`-global armv7m.init-nsvtor=…`), which is what
//! the bootloader's jump amounts to.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Duration;

use crate::emulated::{emulator_command, EmulatedSerial};

use crate::workspace_root;

/// The Rust target of the SKR Pro build.
pub const ARM_TARGET: &str = "thumbv7em-none-eabihf";
/// Where the STM32F4's flash is mapped.
const FLASH: std::ops::Range<u32> = 0x0800_0000..0x0810_0000;

/// The release ELFs of the SKR Pro board (firmware, step benchmark):
/// `$FERROSTEP_ARM_DIR/skr-pro` if set, otherwise built here with
/// `cargo arm` once per test process.
fn arm_release_dir() -> PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        if let Some(dir) = std::env::var_os("FERROSTEP_ARM_DIR") {
            let dir = PathBuf::from(dir);
            assert!(dir.join("skr-pro").exists(), "FERROSTEP_ARM_DIR={} holds no skr-pro ELF", dir.display());
            return dir;
        }
        let root = workspace_root();
        let target = std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from).unwrap_or_else(|| root.join("target"));
        let status = Command::new("cargo")
            .arg("arm")
            .current_dir(&root)
            .env("CARGO_TARGET_DIR", &target)
            .status()
            .expect("cannot run cargo arm");
        assert!(
            status.success(),
            "building the SKR Pro firmware failed (needs `rustup target add {ARM_TARGET}`; bash tests/scripts/test.sh sets it up)"
        );
        target.join(ARM_TARGET).join("release")
    })
    .clone()
}

/// The SKR Pro firmware ELF.
pub fn skr_pro_elf() -> PathBuf {
    arm_release_dir().join("skr-pro")
}

/// The step-interrupt benchmark ELF (built with the firmware).
pub fn skr_pro_bench_elf() -> PathBuf {
    arm_release_dir().join("skr-pro-step-bench")
}

// --- ELF ---------------------------------------------------------------------

/// What the tests need from a 32-bit little-endian ELF.
pub struct Elf {
    bytes: Vec<u8>,
}

impl Elf {
    pub fn read(path: &Path) -> Self {
        let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        assert!(
            bytes.len() > 52 && &bytes[..4] == b"\x7fELF" && bytes[4] == 1 && bytes[5] == 1,
            "not an ELF32 LE file"
        );
        Self { bytes }
    }

    fn u16_at(&self, at: usize) -> usize {
        u16::from_le_bytes([self.bytes[at], self.bytes[at + 1]]) as usize
    }

    fn u32_at(&self, at: usize) -> u32 {
        u32::from_le_bytes(self.bytes[at..at + 4].try_into().expect("4 bytes"))
    }

    /// Bytes written to flash: the file contents of every loadable segment
    /// whose load address is in flash (code, constants, the initial values
    /// of `.data`). `firmware.bin` is this plus alignment gaps.
    pub fn flash_bytes(&self) -> u32 {
        let (offset, size, count) = (self.u32_at(0x1C) as usize, self.u16_at(0x2A), self.u16_at(0x2C));
        (0..count)
            .map(|i| offset + i * size)
            .filter(|&ph| self.u32_at(ph) == 1) // PT_LOAD
            .filter(|&ph| FLASH.contains(&self.u32_at(ph + 12))) // p_paddr
            .map(|ph| self.u32_at(ph + 16)) // p_filesz
            .sum()
    }

    /// (name, address, size) of every section.
    fn sections(&self) -> Vec<(String, u32, u32, usize)> {
        let (offset, size, count, names) =
            (self.u32_at(0x20) as usize, self.u16_at(0x2E), self.u16_at(0x30), self.u16_at(0x32));
        let header = |i: usize| offset + i * size;
        let name_table = self.u32_at(header(names) + 16) as usize;
        (0..count)
            .map(|i| {
                let sh = header(i);
                let name = self.c_str(name_table + self.u32_at(sh) as usize);
                (name, self.u32_at(sh + 12), self.u32_at(sh + 20), sh)
            })
            .collect()
    }

    fn c_str(&self, at: usize) -> String {
        let end = self.bytes[at..].iter().position(|&b| b == 0).map_or(self.bytes.len(), |n| at + n);
        String::from_utf8_lossy(&self.bytes[at..end]).into_owned()
    }

    /// Address of the vector table (cortex-m-rt's `.vector_table`).
    pub fn vector_table(&self) -> u32 {
        self.sections().iter().find(|s| s.0 == ".vector_table").map(|s| s.1).expect("no .vector_table section")
    }

    /// Address (Thumb bit cleared) and size of a symbol.
    pub fn symbol(&self, wanted: &str) -> Option<(u32, u32)> {
        let sections = self.sections();
        let (_, _, _, symtab) = sections.iter().find(|s| self.u32_at(s.3 + 4) == 2)?; // SHT_SYMTAB
        let (start, size) = (self.u32_at(symtab + 16) as usize, self.u32_at(symtab + 20) as usize);
        let strtab = sections[self.u32_at(symtab + 24) as usize].3;
        let strings = self.u32_at(strtab + 16) as usize;
        (start..start + size).step_by(16).find_map(|sym| {
            (self.c_str(strings + self.u32_at(sym) as usize) == wanted)
                .then(|| (self.u32_at(sym + 4) & !1, self.u32_at(sym + 8)))
        })
    }
}

// --- QEMU ------------------------------------------------------------------------

/// `qemu-system-arm -M netduinoplus2` for `elf`, USART1 on stdin/stdout,
/// dying with the test process.
pub fn qemu_arm_command(elf: &Path) -> Command {
    let vtor = format!("armv7m.init-nsvtor={:#010x}", Elf::read(elf).vector_table());
    let args = ["-M", "netduinoplus2", "-global", &vtor, "-display", "none", "-serial", "stdio", "-monitor", "none", "-kernel"];
    emulator_command("qemu-system-arm", args.iter().map(std::ffi::OsStr::new).chain([elf.as_os_str()]))
}

/// A running emulated SKR Pro (its serial port: see [`EmulatedSerial`]).
pub type ArmBoard = EmulatedSerial;

/// Boot `elf` on the emulated SKR Pro.
pub fn boot(elf: &Path) -> ArmBoard {
    boot_with(qemu_arm_command(elf))
}

fn boot_with(command: Command) -> ArmBoard {
    EmulatedSerial::spawn(command, "cannot start qemu-system-arm (apt-get install --no-install-recommends qemu-system-arm)")
}

// --- the step-interrupt benchmark ------------------------------------------------------

/// What one step event costs on the Cortex-M4.
#[derive(Debug, Clone)]
pub struct StepCost {
    /// Instructions the interrupt handler executes per step event (exact:
    /// QEMU's instruction count, the handler's own instructions only).
    pub instructions: u32,
    /// Core cycles of the same path, exception entry and return included,
    /// from the Cortex-M4 timing model below: optimistic and pessimistic.
    pub cycles_min: u32,
    pub cycles_max: u32,
    /// Peripheral accesses the handler makes per event.
    pub peripheral_accesses: u32,
    /// The bench's own figures (`key=value` lines it printed).
    pub printed: HashMap<String, String>,
    /// The step timer's tick rate (the core's `TIMER_HZ`), a hard cap.
    pub timer_hz: u32,
    pub sysclk_hz: u32,
}

impl StepCost {
    /// Step events per second one stepper can get: the core clock over the
    /// pessimistic cycle count (the interrupt alone saturating the CPU, as
    /// Klipper's figures count it), capped by the step timer's resolution
    /// (one event per tick at most).
    pub fn step_rate_hz(&self) -> u32 {
        (self.sysclk_hz / self.cycles_max.max(1)).min(self.timer_hz)
    }

    /// One closed-loop law tick (robust PID) in `arithmetic` ("fixed" or
    /// "f32"), less the bare counter reads: instructions on QEMU (TIM2
    /// under `-icount shift=0`, scaled by the bench's calibration loop of
    /// known length), core cycles on silicon (DWT).
    pub fn loop_tick(&self, arithmetic: &str) -> f64 {
        let number = |key: &str| -> f64 {
            self.printed
                .get(key)
                .and_then(|v| v.parse::<f64>().ok())
                .unwrap_or_else(|| panic!("bench did not print {key}: {:?}", self.printed))
        };
        let samples = number("loop_samples");
        let ticks = (number(&format!("loop_{arithmetic}_sum")) - number("loop_bare_sum")) / samples;
        if self.printed.get("counter").map(String::as_str) == Some("dwt_cycles") {
            ticks
        } else {
            ticks * number("calibration_instructions") / number("calibration_ticks")
        }
    }
}

/// Cortex-M4 cycles of one executed instruction (ARM DDI 0439, table 3-1),
/// as (optimistic, pessimistic). `taken`: a branch went elsewhere than the
/// next instruction. `after_single_transfer`: the previous instruction was
/// a single load or store, with which this one pipelines.
///
/// - Data processing, moves, compares, shifts, MUL: 1. MLA/MLS: 2.
///   SDIV/UDIV: 2–12. IT: 0 (folded) – 1.
/// - LDR/STR (any width): 2, or 1 when it follows another single load or
///   store (the TRM: neighbouring transfers pipeline). LDRD/STRD: 3.
///   LDM/STM/PUSH/POP: 1 + N registers, + P when loading the PC.
/// - Branches taken: 1 + P, P (pipeline refill) 1–3; not taken: 1.
///   TBB/TBH: 2 + P.
///
/// Flash: the ART accelerator's 1 KiB instruction cache holds the whole
/// handler after its first run, so fetches are taken as 0-wait.
fn instruction_cycles(mnemonic: &str, operands: &str, taken: bool, after_single_transfer: bool) -> (u32, u32) {
    let base = mnemonic.trim_end_matches(".w").trim_end_matches(".n");
    let registers = || operands.matches(',').count() as u32 + 1;
    let loads_pc = operands.contains("pc");
    let is_branch = base == "b"
        || base == "bl"
        || base == "bx"
        || base == "blx"
        || base == "cbz"
        || base == "cbnz"
        || (base.starts_with('b') && base.len() == 3 && !base.starts_with("bi") && !base.starts_with("bf"));
    match base {
        "push" | "pop" | "vpush" | "vpop" => {
            let n = 1 + registers();
            if base == "pop" && loads_pc {
                (n + 1, n + 3)
            } else {
                (n, n)
            }
        }
        _ if base.starts_with("ldm") || base.starts_with("stm") => {
            let list = operands.split_once('{').map_or("", |(_, l)| l);
            let n = 1 + list.matches(',').count() as u32 + 1;
            if base.starts_with("ldm") && list.contains("pc") {
                (n + 1, n + 3)
            } else {
                (n, n)
            }
        }
        "ldrd" | "strd" => (3, 3),
        _ if base.starts_with("ldr") || base.starts_with("str") || base == "vldr" || base == "vstr" => {
            if after_single_transfer {
                (1, 2)
            } else {
                (2, 2)
            }
        }
        "tbb" | "tbh" => (3, 5),
        "sdiv" | "udiv" => (2, 12),
        "mla" | "mls" => (2, 2),
        _ if base.starts_with("it") => (0, 1),
        // Not taken, a branch costs 1, as the default below.
        _ if is_branch && taken => (2, 4),
        _ => (1, 1),
    }
}

fn is_single_transfer(mnemonic: &str) -> bool {
    let base = mnemonic.trim_end_matches(".w").trim_end_matches(".n");
    (base.starts_with("ldr") || base.starts_with("str")) && base != "ldrd" && base != "strd"
}

/// Exception entry (stacking eight registers, vector fetch) and return
/// (unstacking), in cycles, on the Cortex-M4 with no floating-point
/// context to save (the handler uses no FPU register, and lazy stacking
/// defers the rest).
const EXCEPTION_ENTRY_CYCLES: u32 = 12;
const EXCEPTION_RETURN_CYCLES: u32 = 10;

/// Extra cycles of a peripheral access (optimistic, pessimistic): APB1 runs
/// at a quarter of the core clock, so a read there waits for two APB
/// cycles; a write goes into the bus matrix' write buffer and costs
/// nothing until the next access. GPIO sits on AHB1 at full speed.
fn peripheral_cycles(address: u32, write: bool) -> (u32, u32) {
    match address {
        0x4000_0000..=0x4000_7FFF if write => (0, 4),
        0x4000_0000..=0x4000_7FFF => (4, 8),
        _ => (0, 1),
    }
}

/// Run the benchmark ELF on QEMU with `-icount shift=0` (virtual time =
/// instructions) and a per-instruction trace of the step handler, and
/// count what one steady-state step event costs.
pub fn measure_step_cost(bench_elf: &Path) -> StepCost {
    let elf = Elf::read(bench_elf);
    let (handler, handler_size) = elf.symbol("TIM5").expect("the bench ELF has a TIM5 handler");
    let log = std::env::temp_dir().join(format!("ferrostep-arm-trace-{}.log", std::process::id()));
    let mut command = qemu_arm_command(bench_elf);
    command
        .args(["-icount", "shift=0", "-singlestep", "-d", "in_asm,exec,nochain", "-trace", "memory_region_ops_*"])
        .args(["-dfilter", &format!("{:#x}..{:#x}", handler, handler + handler_size)])
        .arg("-D")
        .arg(&log);
    let mut board = boot_with(command);
    let lines = board.read_until(Duration::from_secs(120), |l| l == "done");
    drop(board);
    let printed: HashMap<String, String> =
        lines.iter().filter_map(|l| l.split_once('=')).map(|(k, v)| (k.to_string(), v.to_string())).collect();
    let trace = std::fs::read_to_string(&log).expect("QEMU wrote no trace");
    let _ = std::fs::remove_file(&log);

    // Disassembly (pc → size, mnemonic, operands) and the executed
    // sequence, with the peripheral accesses in between.
    #[derive(Clone)]
    enum Event {
        Exec(u32),
        Access(u32, bool),
    }
    let mut code: HashMap<u32, (u32, String, String)> = HashMap::new();
    let mut events = Vec::new();
    for line in trace.lines() {
        if let Some(rest) = line.strip_prefix("0x") {
            // "0x080081ec:  b5f0       push     {r4, r5, r6, r7, lr}"
            let Some((address, rest)) = rest.split_once(':') else { continue };
            let Ok(pc) = u32::from_str_radix(address, 16) else { continue };
            let fields: Vec<&str> = rest.split_whitespace().collect();
            let hex_words =
                fields.iter().take_while(|f| f.len() == 4 && f.chars().all(|c| c.is_ascii_hexdigit())).count();
            if hex_words == 0 || fields.len() <= hex_words {
                continue;
            }
            let operands = fields[hex_words + 1..].join(" ");
            code.insert(pc, (2 * hex_words as u32, fields[hex_words].to_string(), operands));
        } else if line.starts_with("Trace ") {
            // "Trace 0: 0x7f.. [00800408/080081ec/00000110/ff020201] TIM5"
            let Some(pc) = line.split('/').nth(1).and_then(|pc| u32::from_str_radix(pc, 16).ok()) else { continue };
            events.push(Event::Exec(pc));
        } else if line.starts_with("cpu_io_recompile") {
            // The last instruction is executed again: forget the first try.
            if let Some(i) = events.iter().rposition(|e| matches!(e, Event::Exec(_))) {
                events.truncate(i);
            }
        } else if let Some(rest) = line.strip_prefix("memory_region_ops_") {
            let write = rest.starts_with("write");
            let Some(address) = rest.split(" addr 0x").nth(1).and_then(|a| a.split(' ').next()) else { continue };
            let Ok(address) = u32::from_str_radix(address, 16) else { continue };
            // The handler's peripherals: TIM5 and the GPIO ports.
            if (0x4000_0C00..0x4000_1000).contains(&address) || (0x4002_0000..0x4002_2400).contains(&address) {
                events.push(Event::Access(address, write));
            }
        }
    }

    // One window per handler run: from its entry to the next entry.
    let mut windows: Vec<Vec<Event>> = Vec::new();
    for event in events {
        if let Event::Exec(pc) = event {
            if pc == handler {
                windows.push(Vec::new());
            }
        }
        if let Some(window) = windows.last_mut() {
            window.push(event);
        }
    }
    assert!(windows.len() > 100, "too few step interrupts traced ({}); bench printed {printed:?}", windows.len());
    // Each window's cost; the steady state is the most common path.
    let costs: Vec<(u32, u32, u32, u32)> = windows
        .iter()
        .map(|window| {
            let execs: Vec<u32> =
                window.iter().filter_map(|e| if let Event::Exec(pc) = e { Some(*pc) } else { None }).collect();
            let (mut min, mut max) =
                (EXCEPTION_ENTRY_CYCLES + EXCEPTION_RETURN_CYCLES, EXCEPTION_ENTRY_CYCLES + EXCEPTION_RETURN_CYCLES);
            let mut previous_single = false;
            for (i, pc) in execs.iter().enumerate() {
                let (size, mnemonic, operands) = code.get(pc).cloned().unwrap_or((2, String::from("?"), String::new()));
                let taken = execs.get(i + 1).is_some_and(|next| *next != pc + size);
                let (a, b) = instruction_cycles(&mnemonic, &operands, taken, previous_single);
                min += a;
                max += b;
                previous_single = is_single_transfer(&mnemonic);
            }
            let mut accesses = 0;
            for event in window {
                if let Event::Access(address, write) = event {
                    let (a, b) = peripheral_cycles(*address, *write);
                    min += a;
                    max += b;
                    accesses += 1;
                }
            }
            (execs.len() as u32, min, max, accesses)
        })
        .collect();
    let mut counts: HashMap<(u32, u32, u32, u32), usize> = HashMap::new();
    for cost in &costs {
        *counts.entry(*cost).or_default() += 1;
    }
    let (&(instructions, cycles_min, cycles_max, peripheral_accesses), _) =
        counts.iter().max_by_key(|(cost, n)| (**n, cost.0)).expect("windows");
    let number = |key: &str| {
        printed
            .get(key)
            .and_then(|v| v.parse::<u32>().ok())
            .unwrap_or_else(|| panic!("bench did not print {key}: {printed:?}"))
    };
    StepCost {
        instructions,
        cycles_min,
        cycles_max,
        peripheral_accesses,
        timer_hz: number("step_timer_hz"),
        sysclk_hz: number("sysclk_hz"),
        printed,
    }
}

/// Build (if needed) and measure; print the benchmark keys, one per line:
/// `arm_flash_bytes=…` and `arm_step_rate_1_stepper_hz=…`, with the
/// figures behind them.
pub fn print_arm_benchmark() -> (u32, StepCost) {
    let flash = Elf::read(&skr_pro_elf()).flash_bytes();
    let cost = measure_step_cost(&skr_pro_bench_elf());
    println!("arm_flash_bytes={flash}");
    println!("arm_step_rate_1_stepper_hz={}", cost.step_rate_hz());
    println!("arm_step_isr_instructions={}", cost.instructions);
    println!("arm_step_isr_cycles_min={}", cost.cycles_min);
    println!("arm_step_isr_cycles_max={}", cost.cycles_max);
    println!("arm_step_isr_peripheral_accesses={}", cost.peripheral_accesses);
    println!("arm_loop_tick_instructions_fixed={:.0}", cost.loop_tick("fixed"));
    println!("arm_loop_tick_instructions_f32={:.0}", cost.loop_tick("f32"));
    println!(
        "# counted on QEMU (-icount shift=0: exact instructions); cycles from the Cortex-M4 TRM timings, \
         entry {EXCEPTION_ENTRY_CYCLES} + return {EXCEPTION_RETURN_CYCLES}; rate = {} Hz / cycles_max, capped at the {} Hz step timer",
        cost.sysclk_hz, cost.timer_hz
    );
    (flash, cost)
}
