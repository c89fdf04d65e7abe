//! Generates, from `tools/machine-file`:
//! - the stock thermistor tables (`thermistor_tables.rs`, see
//!   `src/thermal/thermistor.rs`): the RAMPS 1.4 hot end's 100 k β 3950 on
//!   4.7 kΩ and the extrusion line's on 4.8 kΩ, which the simulator and
//!   the tests use;
//! - the machine the firmware is built for (`machine_file.rs`, the module
//!   `firmware::machine_file`): with the `machine-file` feature (the
//!   boards) the file named by `FERROSTEP_MACHINE`, else the default
//!   `machines/prusa-i3.toml`. With `machine-file`, the core's features
//!   (`printer`, `heaters`, `delta`, …) are derived from that file too.

use machine_file::thermistor::{self, Divider};
use std::fmt::Write as _;
use std::path::Path;

fn main() {
    let out_dir = std::env::var("OUT_DIR").unwrap();
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap();
    let workspace = Path::new(&manifest).parent().unwrap();

    let mut tables = String::new();
    let ntc = thermistor::find("ntc-100k-3950").unwrap();
    for (name, pullup_ohms) in [("NTC100K_B3950_4K7", 4_700.0), ("NTC100K_B3950_4K8", 4_800.0)] {
        let divider = Divider { curve: ntc.curve, pullup_ohms };
        let table = divider.table().expect("the stock thermistor tables");
        tables.push_str(&thermistor::table_source(name, ntc.description, &divider, &table, "crate"));
    }
    writeln!(tables, "/// Rows of every table.\npub const ROWS: usize = {};", thermistor::ROWS).unwrap();
    writeln!(tables, "/// What is added to hundredths of °C to store them as `u16`.\nconst STORED_OFFSET: i32 = {};", thermistor::STORED_OFFSET).unwrap();
    std::fs::write(Path::new(&out_dir).join("thermistor_tables.rs"), tables).unwrap();

    let from_environment = std::env::var_os("CARGO_FEATURE_MACHINE_FILE").is_some();
    let path = if from_environment { machine_file::selected_path(workspace) } else { workspace.join(machine_file::DEFAULT_MACHINE) };
    println!("cargo:rerun-if-env-changed={}", machine_file::MACHINE_VARIABLE);
    println!("cargo:rerun-if-env-changed={}", machine_file::ALL_OPTIONS_VARIABLE);
    println!("cargo:rerun-if-changed={}", path.display());
    println!("cargo:rerun-if-changed=build.rs");
    let machine = match machine_file::load(&path) {
        Ok(machine) => machine,
        Err(message) => {
            // One line per problem, each shown by cargo as an error.
            for line in message.lines() {
                println!("cargo:warning={line}");
            }
            eprintln!("{message}");
            std::process::exit(1);
        }
    };
    if from_environment {
        for feature in machine_file::generate::features(&machine) {
            println!("cargo:rustc-cfg=feature=\"{feature}\"");
        }
    }
    std::fs::write(Path::new(&out_dir).join("machine_file.rs"), machine_file::generate::core_source(&machine, "crate")).unwrap();
}
