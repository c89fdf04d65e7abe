//! The control core of the firmware: everything that decides something.
//!
//! This crate is `no_std` and allocation-free. It never touches a register:
//! boards hand it bytes, ADC samples and timer events through small traits and
//! plain function calls, so the very same code runs on the Mega 2560, on the
//! ARM board and on the PC against `hal-sim`.
//!
//! Layout (one concept per module):
//! - [`rx`]: the serial receive ring between the RX interrupt and the main loop;
//! - [`emergency`]: `M112`/`M108`/`M410` recognised inside the RX interrupt;
//! - [`line`]: assembling received bytes into bounded lines;
//! - [`host_link`]: the main loop's serial duties, shared by all boards;
//! - [`gcode`]: the allocation-free G-code lexer/parser and its number format;
//! - [`protocol`]: Marlin's host protocol (line numbers, checksums, resends);
//! - [`reply`]: the exact reply strings hosts parse, and decimal formatting;
//! - [`machine`]: the command queue, the executor and the modal state;
//! - [`settings`]: tunable values (`M92`, `M201`–`M205`, ...), `M503`;
//! - [`storage`]: `M500`/`M501` images in non-volatile memory, two slots + CRC;
//! - [`flash_pages`]: that memory on a flash-only chip (pages appended in a sector);
//! - [`thermal`]: thermistors and heaters;
//! - [`closed_loop`]: encoders (NSE-5310, quadrature) and closed position loops;
//! - [`machines`]: the filament extrusion line and the powder-bed retrofit
//!   (velocity-mode steppers, diameter loop, travel measurement, layer cycle);
//! - [`drivers`]: small device drivers (HD44780 character LCD, status screen);
//! - [`num`]: the numeric abstraction of the control laws (fixed point on
//!   the AVR, f32 on an FPU), chosen by the board;
//! - [`progmem`]: constant tables kept in flash on the AVR;
//! - [`ring`]: the lock-free queues between the main loop and interrupts.
#![no_std]
#![deny(unsafe_op_in_unsafe_fn)]
#![cfg_attr(target_arch = "avr", feature(asm_experimental_arch))]

#[cfg(test)]
extern crate std;

pub mod closed_loop;
pub mod drivers;
pub mod emergency;
pub mod flash_pages;
pub mod gcode;
pub mod host_link;
pub mod line;
pub mod machine;
/// The machine this firmware is built for, generated from its machine file
/// (`machines/*.toml`, see `tools/machine-file`): name, motion, heaters,
/// endstop polarity.
pub mod machine_file {
    include!(concat!(env!("OUT_DIR"), "/machine_file.rs"));
}
pub mod machines;
pub mod motion;
pub mod num;
pub mod progmem;
pub mod protocol;
pub mod reply;
pub mod ring;
pub mod rx;
pub mod settings;
pub mod storage;
pub mod thermal;

/// Name and version reported in the boot banner and by `M115`.
pub const FIRMWARE_NAME: &str = "Ferrostep";
/// Crate version, reported beside the name.
pub const FIRMWARE_VERSION: &str = env!("CARGO_PKG_VERSION");
