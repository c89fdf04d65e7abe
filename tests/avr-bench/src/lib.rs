//! The board in the loop: the real Mega 2560 release ELF, cycle-accurately
//! on simavr, with a virtual RAMPS 1.4 around it. See README.md.

pub mod bench;
pub mod board;
pub mod build;
pub mod carriage;
pub mod elf;
pub mod host;
pub mod steps;
pub mod thermal;
