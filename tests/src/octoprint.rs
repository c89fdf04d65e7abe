//! A real OctoPrint server for the end-to-end tests: OctoPrint 1.11.8,
//! installed with pip into a venv under `target/` on first use (as
//! [`crate::printcore`] installs Printrun). The server itself is driven by
//! `tests/hosts/octoprint_print.py` through OctoPrint's REST API.

use std::path::PathBuf;
use std::process::Command;

use crate::workspace_root;

/// The pinned OctoPrint release.
pub const OCTOPRINT_VERSION: &str = "1.11.8";

/// The venv's Python, with OctoPrint installed (created on first use).
/// Fails with a clear message when it cannot be installed (no network,
/// no `python3-venv`): the test must not pass without it.
pub fn octoprint_python() -> PathBuf {
    static PYTHON: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    PYTHON.get_or_init(create_octoprint_venv).clone()
}

fn create_octoprint_venv() -> PathBuf {
    let root = workspace_root();
    let target = std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from).unwrap_or_else(|| root.join("target"));
    let venv = target.join("octoprint-venv");
    let python = venv.join("bin/python");
    let ready = venv.join(format!(".installed-{OCTOPRINT_VERSION}"));
    if !ready.exists() {
        let status = Command::new("python3").arg("-m").arg("venv").arg(&venv).status().expect("python3 is needed");
        assert!(status.success(), "python3 -m venv failed (Debian: apt-get install python3-venv)");
        let status = Command::new(&python)
            .args(["-m", "pip", "install", "--quiet", &format!("OctoPrint=={OCTOPRINT_VERSION}")])
            .status()
            .expect("pip");
        assert!(
            status.success(),
            "pip install OctoPrint=={OCTOPRINT_VERSION} failed (it needs PyPI): the OctoPrint test cannot run"
        );
        std::fs::write(&ready, b"").unwrap();
    }
    python
}
