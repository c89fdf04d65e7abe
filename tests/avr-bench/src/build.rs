//! Finding (or building) the Mega 2560 release ELF.
//!
//! Order: `$FERROSTEP_ELF` if set (the test command builds the ELF once
//! and passes it on; it is used as is); otherwise
//! `$CARGO_TARGET_DIR/avr-none/release/mega2560-ramps.elf` (default target
//! dir `target/` at the workspace root), rebuilt with `cargo +nightly avr`
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
        build_variant(&target_dir(), &[], false).unwrap_or_else(|e| panic!("{e}"))
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
    for dir in ["firmware", "boards/mega2560-ramps"] {
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

/// Build `mega2560-ramps` with `cargo +nightly avr` and `features` into
/// `target`; returns the ELF's path. Without `force` the build is skipped
/// when the ELF there is newer than its sources (and was built with the
/// same features); with `force` cargo always runs (it decides itself, and
/// takes a second when nothing changed). Builds are serialised within the
/// process.
pub fn build_variant(target: &Path, features: &[&str], force: bool) -> Result<PathBuf, String> {
    static LOCK: Mutex<()> = Mutex::new(());
    let _guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let elf = target.join("avr-none/release/mega2560-ramps.elf");
    if !force && !is_stale(&elf) && features_match(target, features) {
        return Ok(elf);
    }
    let mut command = Command::new("cargo");
    command
        .args(["+nightly", "avr"])
        .current_dir(workspace_root())
        .env("CARGO_TARGET_DIR", target);
    // `--no-default-features` may come first (the extrusion line and the
    // powder bed are built without the printers); the rest are features.
    let (no_default, named) = match features.split_first() {
        Some((&"--no-default-features", rest)) => (true, rest),
        _ => (false, features),
    };
    if no_default {
        command.arg("--no-default-features");
    }
    if !named.is_empty() {
        command.arg("--features").arg(named.join(","));
    }
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
        "avr-bench: building the Mega 2560 ELF: cargo +nightly avr{} (CARGO_TARGET_DIR={})",
        if features.is_empty() {
            String::new()
        } else {
            format!(" --features {}", features.join(","))
        },
        target.display()
    );
    let status = command
        .status()
        .map_err(|e| format!("cannot run `cargo +nightly avr` ({e}); run `bash tests/scripts/test.sh` once to set up the toolchain"))?;
    if !status.success() {
        return Err(format!("`cargo +nightly avr` failed ({status})"));
    }
    let _ = std::fs::write(
        target.join("avr-none/release/.avr-bench-features"),
        features.join(","),
    );
    Ok(elf)
}

/// The features the ELF in `target` was last built with by this helper
/// (a plain `cargo +nightly avr` leaves no record: no features).
fn features_match(target: &Path, features: &[&str]) -> bool {
    let recorded = std::fs::read_to_string(target.join("avr-none/release/.avr-bench-features"))
        .unwrap_or_default();
    recorded == features.join(",")
}
