//! Finding (or building) the Mega 2560 release ELF.
//!
//! Order: `$FERROSTEP_ELF` if set (the test command builds the ELF once
//! and passes it on; it is used as is); otherwise
//! `$CARGO_TARGET_DIR/avr-none/release/mega2560-ramps.elf` (default target
//! dir `target/` at the workspace root), rebuilt with `cargo avr`
//! when it is missing or older than any source it is built from. The build
//! runs at most once per process.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, OnceLock};
use std::time::SystemTime;

/// The workspace root (this crate lives in `tests/avr-bench/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .expect("tests/avr-bench has a workspace root")
        .to_path_buf()
}

/// The target directory cargo uses: `$CARGO_TARGET_DIR` or `<root>/target`.
pub fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) => {
            let dir = PathBuf::from(dir);
            if dir.is_absolute() {
                dir
            } else {
                workspace_root().join(dir)
            }
        }
        None => workspace_root().join("target"),
    }
}

/// The standard (115200 baud) release ELF, built if needed.
pub fn mega2560_elf() -> PathBuf {
    static ELF: OnceLock<PathBuf> = OnceLock::new();
    ELF.get_or_init(|| {
        if let Some(path) = std::env::var_os("FERROSTEP_ELF") {
            let path = PathBuf::from(path);
            assert!(
                path.exists(),
                "FERROSTEP_ELF={} does not exist",
                path.display()
            );
            return path;
        }
        build_variant(&target_dir(), &Machine::DEFAULT, false).unwrap_or_else(|e| panic!("{e}"))
    })
    .clone()
}

/// The newest modification time among the sources the board ELF is built
/// from (the firmware core, the board crate, the workspace manifests).
pub fn newest_source_mtime() -> Option<SystemTime> {
    let root = workspace_root();
    let mut newest: Option<SystemTime> = None;
    let mut visit = |path: &Path| {
        if let Ok(t) = std::fs::metadata(path).and_then(|m| m.modified()) {
            newest = Some(newest.map_or(t, |n| n.max(t)));
        }
    };
    for file in ["Cargo.toml", "Cargo.lock", ".cargo/config.toml"] {
        visit(&root.join(file));
    }
    for dir in ["firmware", "boards/mega2560-ramps", "machines", "tools/machine-file"] {
        walk(&root.join(dir), &mut visit);
    }
    newest
}

fn walk(dir: &Path, visit: &mut dyn FnMut(&Path)) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            if path.file_name().is_some_and(|n| n == "target") {
                continue;
            }
            walk(&path, visit);
        } else {
            visit(&path);
        }
    }
}

/// Is `elf` missing or older than its sources?
pub fn is_stale(elf: &Path) -> bool {
    let Ok(built) = std::fs::metadata(elf).and_then(|m| m.modified()) else {
        return true;
    };
    newest_source_mtime().is_some_and(|src| src > built)
}

/// A machine to build: a shipped machine file, or the Prusa i3's with
/// some of its text replaced (each `(from, to)` must occur exactly once):
/// the variants a test needs (250000 baud, the bed on a relay, …).
#[derive(Clone, Copy, Debug)]
pub enum Machine {
    /// A file under `machines/`, e.g. `"delta.toml"`.
    Shipped(&'static str),
    /// `machines/prusa-i3.toml` with these replacements.
    PrusaWith(&'static [(&'static str, &'static str)]),
}

impl Machine {
    /// What `cargo avr` builds without `FERROSTEP_MACHINE`.
    pub const DEFAULT: Machine = Machine::Shipped("prusa-i3.toml");
    /// The Prusa i3 at 250000 baud.
    pub const PRUSA_250000_BAUD: Machine = Machine::PrusaWith(&[("baud = 115200", "baud = 250000")]);
    /// The Prusa i3 with its RepRapDiscount display.
    pub const PRUSA_DISPLAY: Machine =
        Machine::PrusaWith(&[("enabled = false            # the display", "enabled = true             # the display")]);
    /// The Prusa i3 with its NSE-5310 encoder loops.
    pub const PRUSA_ENCODERS: Machine =
        Machine::PrusaWith(&[("enabled = false            # the encoder loops", "enabled = true             # the encoder loops")]);
    /// The Prusa i3 with its bed behind a solid-state relay.
    pub const PRUSA_BED_SSR: Machine = Machine::PrusaWith(&[(
        "control = \"pid\"            # \"bang-bang\"",
        "control = \"ssr-window\"     # \"bang-bang\"",
    )]);

    /// The machine file's text.
    pub fn text(&self) -> Result<String, String> {
        let read = |name: &str| {
            let path = workspace_root().join("machines").join(name);
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))
        };
        match *self {
            Machine::Shipped(name) => read(name),
            Machine::PrusaWith(replacements) => {
                let mut text = read("prusa-i3.toml")?;
                for (from, to) in replacements {
                    if text.matches(from).count() != 1 {
                        return Err(format!("{from:?} does not occur exactly once in machines/prusa-i3.toml"));
                    }
                    text = text.replacen(from, to, 1);
                }
                Ok(text)
            }
        }
    }
}

/// Build `mega2560-ramps` for `machine` with `cargo avr` into
/// `target` (its machine file written there as `machine.toml` and named by
/// `FERROSTEP_MACHINE`); returns the ELF's path. Without `force` the build
/// is skipped when the ELF there is newer than its sources and was built
/// from the same file; with `force` cargo always runs (it decides itself,
/// and takes a second when nothing changed). Builds are serialised within
/// the process.
pub fn build_variant(target: &Path, machine: &Machine, force: bool) -> Result<PathBuf, String> {
    static LOCK: Mutex<()> = Mutex::new(());
    let _guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let elf = target.join("avr-none/release/mega2560-ramps.elf");
    let text = machine.text()?;
    let file = target.join("machine.toml");
    if !force && !is_stale(&elf) && std::fs::read_to_string(&file).is_ok_and(|t| t == text) {
        return Ok(elf);
    }
    std::fs::create_dir_all(target).map_err(|e| format!("{}: {e}", target.display()))?;
    std::fs::write(&file, &text).map_err(|e| format!("{}: {e}", file.display()))?;
    let mut command = Command::new("cargo");
    command
        .args(["avr"])
        .current_dir(workspace_root())
        .env("CARGO_TARGET_DIR", target)
        .env("FERROSTEP_MACHINE", &file)
        .env_remove("FERROSTEP_ALL_OPTIONS");
    // Tests run under `cargo test`, which sets variables for the host
    // toolchain; the nested build must pick its own.
    for var in [
        "RUSTC",
        "RUSTDOC",
        "RUSTC_WRAPPER",
        "RUSTC_WORKSPACE_WRAPPER",
        "RUSTUP_TOOLCHAIN",
        "CARGO",
    ] {
        command.env_remove(var);
    }
    eprintln!(
        "avr-bench: building the Mega 2560 ELF for {machine:?}: FERROSTEP_MACHINE={} cargo avr (CARGO_TARGET_DIR={})",
        file.display(),
        target.display()
    );
    let status = command
        .status()
        .map_err(|e| format!("cannot run `cargo avr` ({e}); run `bash tests/scripts/test.sh` once to set up the toolchain"))?;
    if !status.success() {
        return Err(format!("`cargo avr` failed ({status})"));
    }
    Ok(elf)
}


/// The ELF of the shipped machine file `machines/{stem}.toml`: the one the
/// test command built (with every option) into `$FERROSTEP_MACHINES_DIR`
/// as `{stem}.elf`, else built here once under `target/machines/{stem}`.
/// Panics with the build's error: a test cannot run without its ELF.
pub fn shipped_elf(stem: &str) -> PathBuf {
    if let Some(dir) = std::env::var_os("FERROSTEP_MACHINES_DIR") {
        let elf = PathBuf::from(dir).join(format!("{stem}.elf"));
        if elf.exists() {
            return elf;
        }
    }
    // `Machine::Shipped` names its file for the life of the test process.
    let file: &'static str = Box::leak(format!("{stem}.toml").into_boxed_str());
    build_variant(&target_dir().join("machines").join(stem), &Machine::Shipped(file), false).unwrap_or_else(|e| panic!("{e}"))
}
