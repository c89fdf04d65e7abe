//! Shared helpers of the end-to-end tests: finding (or building) the Mega
//! 2560 release ELF, and talking to it on an emulated board.

pub mod emulated;
pub mod octoprint;
pub mod printcore;
pub mod qemu;
pub mod qemu_arm;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The workspace root (this crate lives in `tests/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("tests/ has a parent").to_path_buf()
}

/// The release ELF of the Mega 2560 board: `$FERROSTEP_ELF` if set (the
/// test command builds it once and passes it), otherwise built here with
/// `cargo avr` once per test process.
pub fn mega2560_elf() -> PathBuf {
    static ELF: OnceLock<PathBuf> = OnceLock::new();
    ELF.get_or_init(|| {
        if let Some(path) = std::env::var_os("FERROSTEP_ELF") {
            let path = PathBuf::from(path);
            assert!(path.exists(), "FERROSTEP_ELF={} does not exist", path.display());
            return path;
        }
        let root = workspace_root();
        let target = std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from).unwrap_or_else(|| root.join("target"));
        let status = Command::new("cargo")
            .args(["avr"])
            .current_dir(&root)
            .env("CARGO_TARGET_DIR", &target)
            .status()
            .expect("cannot run cargo avr (run bash tests/scripts/test.sh to set up the toolchain)");
        assert!(status.success(), "building the Mega 2560 firmware failed");
        target.join("avr-none/release/mega2560-ramps.elf")
    })
    .clone()
}
