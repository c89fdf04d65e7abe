//! cortex-m-rt's `link.x` includes `memory.x`: put the workspace's one copy
//! (the top-level `memory.x`) on the linker's search path.

use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let memory = manifest.join("../../memory.x");
    std::fs::copy(&memory, out.join("memory.x")).expect("cannot copy the top-level memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory.display());
    println!("cargo:rerun-if-changed=build.rs");
}
