//! A simulated board for the firmware core (std only): the same core code as
//! on the boards, on virtual time.

pub mod axis_plant;
pub mod board;
pub mod encoder_trace;
pub mod steps;
pub mod extrusion_plant;
pub mod powder_bed_plant;
pub mod thermal_plant;
