//! Machine files: one TOML file per machine (`machines/*.toml`) describes
//! everything about a machine the firmware needs at build time — serial
//! rate, kinematics and geometry, per-axis steps, travel, homing,
//! directions, endstops and limits, heaters with their thermistors and
//! control, the fan, every pin, the optional display and encoders.
//!
//! The build scripts of the firmware core and of the Mega 2560 board read
//! the file named by `FERROSTEP_MACHINE` (default `machines/prusa-i3.toml`)
//! with [`load`], which parses it ([`schema`]: unknown keys are errors),
//! checks it ([`check`]: every problem named with its key) and returns a
//! [`Machine`]; [`generate`] turns that into Rust constants. A wrong value
//! therefore stops the build with a message naming the file and the key;
//! it never reaches a motor or a heater.

#![forbid(unsafe_code)]

pub mod check;
pub mod generate;
pub mod pins;
pub mod schema;
pub mod thermistor;

pub use check::Machine;

/// The environment variable that names the machine file to build for.
pub const MACHINE_VARIABLE: &str = "FERROSTEP_MACHINE";
/// Set to `1`, options a machine file describes with `enabled = false`
/// (its display, its encoders) are built in as well: CI checks every
/// machine file's size with everything it names.
pub const ALL_OPTIONS_VARIABLE: &str = "FERROSTEP_ALL_OPTIONS";
/// The machine built when `FERROSTEP_MACHINE` is not set (relative to the
/// workspace).
pub const DEFAULT_MACHINE: &str = "machines/prusa-i3.toml";

/// Read and check the machine file at `path`. The error is a message for
/// a person: the file, then one line per problem (`key: problem`).
pub fn load(path: &std::path::Path) -> Result<Machine, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("machine file {}: cannot be read: {e}", path.display()))?;
    parse(&path.display().to_string(), &text)
}

/// Check the text of a machine file; `name` is how messages refer to it.
pub fn parse(name: &str, text: &str) -> Result<Machine, String> {
    let file: schema::File = toml::from_str(text).map_err(|e| format!("machine file {name}: {e}"))?;
    let all_options = std::env::var_os(ALL_OPTIONS_VARIABLE).is_some_and(|v| v == "1");
    check::check(name, file, all_options).map_err(|problems| {
        let mut message = format!("machine file {name}: {} problem{}:", problems.len(), if problems.len() == 1 { "" } else { "s" });
        for problem in problems {
            message.push_str("\n  ");
            message.push_str(&problem);
        }
        message
    })
}

/// The machine file a build uses: `FERROSTEP_MACHINE` if set (relative
/// paths are taken from the workspace root), else [`DEFAULT_MACHINE`].
/// `workspace` is the workspace root.
pub fn selected_path(workspace: &std::path::Path) -> std::path::PathBuf {
    match std::env::var_os(MACHINE_VARIABLE) {
        Some(path) if !path.is_empty() => {
            let path = std::path::PathBuf::from(path);
            if path.is_absolute() {
                path
            } else {
                workspace.join(path)
            }
        }
        _ => workspace.join(DEFAULT_MACHINE),
    }
}
