//! Small device drivers over embedded-hal traits, for the machine
//! configurations that have the device (absent from the others' builds:
//! nothing here is linked unless a board uses it).
//!
//! - [`hd44780`]: a 16×2 character LCD in 4-bit mode (SPEC §5);
//! - [`status_screen`]: the 32 characters of a status screen.

pub mod hd44780;
pub mod status_screen;
