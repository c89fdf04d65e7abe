//! A simulated board for the firmware core (std only): the same core code as
//! on the boards, on virtual time.

pub mod board;
