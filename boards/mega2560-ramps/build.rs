//! Link with avr-ld's own ATmega2560 script (`avr-ld --verbose -mavr6`),
//! changed in one respect: `.data`'s initial values are placed right after
//! the vectors, progmem and start-up code, in the low 64 KiB of flash,
//! ahead of the program code, instead of after all of it.
//!
//! Why: the start-up code copies `.data` with `elpm` and RAMPZ; QEMU 7.2's
//! AVR (Debian 12's, which the end-to-end tests run) ignores
//! RAMPZ, so once the image passes 64 KiB it copied the wrong bytes and the
//! firmware panicked at boot there. Real chips and simavr read either
//! layout; with this one every tool reads the same bytes.
//!
//! The script is generated from the installed binutils at build time, not
//! kept in the repository.
//!
//! Before that, the machine: the file named by `FERROSTEP_MACHINE`
//! (default `machines/prusa-i3.toml`) is read and checked by
//! `tools/machine-file` — a wrong value stops the build with the file, the
//! key and the problem — and becomes `$OUT_DIR/pins.rs` (every pin, PWM
//! channel, thermistor channel and endstop polarity, included by
//! `src/pins.rs`) and this crate's `feature = "…"` switches (what is
//! linked in: motion, heaters, the machine's own modules, display, …).

use std::path::PathBuf;
use std::process::Command;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    machine();
    if std::env::var("CARGO_CFG_TARGET_ARCH").as_deref() != Ok("avr") {
        return;
    }
    let output = Command::new("avr-ld")
        .args(["--verbose", "-mavr6"])
        .output()
        .expect("avr-ld (binutils-avr) is needed to link the AVR firmware; run tests/scripts/setup.sh");
    let text = String::from_utf8(output.stdout).expect("avr-ld prints text");
    let script = low_data_script(&text).expect("avr-ld's default script has the expected shape");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").unwrap()).join("atmega2560-low-data.x");
    std::fs::write(&out, script).unwrap();
    println!("cargo:rustc-link-arg=-Wl,-T,{}", out.display());
}

/// The machine file: pins and feature switches (see the module comment).
fn machine() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap());
    let workspace = manifest.parent().and_then(|p| p.parent()).unwrap();
    let path = machine_file::selected_path(workspace);
    println!("cargo:rerun-if-env-changed={}", machine_file::MACHINE_VARIABLE);
    println!("cargo:rerun-if-env-changed={}", machine_file::ALL_OPTIONS_VARIABLE);
    println!("cargo:rerun-if-changed={}", path.display());
    let machine = match machine_file::load(&path) {
        Ok(machine) => machine,
        Err(message) => {
            eprintln!("{message}");
            std::process::exit(1);
        }
    };
    let all = machine_file::generate::ALL_BOARD_FEATURES.iter().map(|f| format!("\"{f}\"")).collect::<Vec<_>>().join(", ");
    println!("cargo::rustc-check-cfg=cfg(feature, values({all}))");
    for feature in machine_file::generate::board_features(&machine) {
        println!("cargo::rustc-cfg=feature=\"{feature}\"");
    }
    let out = PathBuf::from(std::env::var_os("OUT_DIR").unwrap()).join("pins.rs");
    std::fs::write(out, machine_file::generate::board_source(&machine)).unwrap();
}

/// The default script between its `=====` rulers, with `.data` moved in
/// front of `.text`'s code: `.text` is closed after `.init9`, `.data`
/// follows (its load address continuing in the `text` region), and the code
/// and `.fini*` go into `.text.code`.
fn low_data_script(verbose: &str) -> Option<String> {
    let ruler = "==================================================";
    let start = verbose.find(ruler)? + ruler.len();
    let end = start + verbose[start..].find(ruler)?;
    let mut script = verbose[start..end].to_string();
    let data_start = script.find("  .data          :")?;
    let data_end = data_start + script[data_start..].find("}  > data AT> text")? + "}  > data AT> text".len();
    let data = script[data_start..data_end].to_string();
    script.replace_range(data_start..data_end, "");
    let code = "    *(.text)\n";
    let at = script.find(code)?;
    script.replace_range(at..at, &format!("  }}  > text\n{data}\n  .text.code :\n  {{\n"));
    Some(script)
}
