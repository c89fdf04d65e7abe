//! Temperatures and heaters.

pub mod thermistor;

/// A temperature in hundredths of a degree Celsius (`21050` is 210.50 °C):
/// exact decimal printing, and integer arithmetic on every board.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub struct Celsius(pub i32);

impl Celsius {
    pub const fn from_degrees(degrees: i32) -> Self {
        Self(degrees * 100)
    }
}

impl ufmt::uDisplay for Celsius {
    fn fmt<W: ufmt::uWrite + ?Sized>(&self, f: &mut ufmt::Formatter<'_, W>) -> Result<(), W::Error> {
        crate::reply::write_fixed(f, self.0, 2)
    }
}

/// What is known about one heater: measured and target temperature, and the
/// power applied (0–127, Marlin's `@:` scale).
#[derive(Clone, Copy, Debug, Default)]
pub struct Heater {
    pub measured: Celsius,
    pub target: Celsius,
    pub power: u8,
}

impl Heater {
    pub const fn new() -> Self {
        Self { measured: Celsius(0), target: Celsius(0), power: 0 }
    }
}
