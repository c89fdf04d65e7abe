//! A simulated board for the firmware core (std only).
