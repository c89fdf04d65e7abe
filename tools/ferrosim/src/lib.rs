//! `ferrosim`: simulate a print on a laptop with the unchanged firmware
//! core. See the README's "Simulate on a laptop".
//!
//! | module | what |
//! |---|---|
//! | [`simulate`] | a whole G-code file in virtual time: print time, distances, peaks, starvation, temperatures |
//! | [`plots`] | PNG and SVG charts of a simulation or a replay (plotters) |
//! | [`serve`] | the virtual printer on a pseudo-terminal |
//! | [`replay`] | a recorded encoder trace through the firmware's encoder and loop code |
//! | [`tracking`] | the Prusa's encoder-closed X and Y following a simulated print (`--encoders`) |

pub mod plots;
pub mod replay;
pub mod serve;
pub mod simulate;
pub mod tracking;
