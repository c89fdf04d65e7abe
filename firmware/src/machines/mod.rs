//! The machines that are not printers (SPEC §4 filament extrusion line,
//! SPEC §5 powder-bed retrofit). Integration notes follow once complete.

pub mod velocity;
pub mod powder_bed;
pub mod diameter;
pub mod extrusion_line;
