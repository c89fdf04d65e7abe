//! The Arduino Mega 2560's pins: Arduino numbers, analog names and port
//! bits, so a machine file can say `54`, `"D54"`, `"A0"` or `"PF0"` for the
//! same pin (X STEP on RAMPS 1.4), and the RAMPS 1.4 defaults.

use crate::schema::PinValue;

/// One I/O pin: port letter (`'A'`–`'L'`) and bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Pin {
    pub port: char,
    pub bit: u8,
}

impl std::fmt::Display for Pin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.arduino() {
            Some(d) => write!(f, "D{d} (P{}{})", self.port, self.bit),
            None => write!(f, "P{}{}", self.port, self.bit),
        }
    }
}

/// Arduino Mega 2560 digital pin n → port and bit (D54–D69 are A0–A15).
const DIGITAL: [(char, u8); 70] = [
    ('E', 0), ('E', 1), ('E', 4), ('E', 5), ('G', 5), ('E', 3), ('H', 3), ('H', 4), ('H', 5), ('H', 6), // D0–D9
    ('B', 4), ('B', 5), ('B', 6), ('B', 7), ('J', 1), ('J', 0), ('H', 1), ('H', 0), ('D', 3), ('D', 2), // D10–D19
    ('D', 1), ('D', 0), ('A', 0), ('A', 1), ('A', 2), ('A', 3), ('A', 4), ('A', 5), ('A', 6), ('A', 7), // D20–D29
    ('C', 7), ('C', 6), ('C', 5), ('C', 4), ('C', 3), ('C', 2), ('C', 1), ('C', 0), ('D', 7), ('G', 2), // D30–D39
    ('G', 1), ('G', 0), ('L', 7), ('L', 6), ('L', 5), ('L', 4), ('L', 3), ('L', 2), ('L', 1), ('L', 0), // D40–D49
    ('B', 3), ('B', 2), ('B', 1), ('B', 0), ('F', 0), ('F', 1), ('F', 2), ('F', 3), ('F', 4), ('F', 5), // D50–D59
    ('F', 6), ('F', 7), ('K', 0), ('K', 1), ('K', 2), ('K', 3), ('K', 4), ('K', 5), ('K', 6), ('K', 7), // D60–D69
];

/// Ports that exist on the ATmega2560 (there is no port I).
const PORTS: &str = "ABCDEFGHJKL";

impl Pin {
    /// Arduino digital pin `n` (0–69).
    pub fn digital(n: u8) -> Option<Pin> {
        DIGITAL.get(usize::from(n)).map(|&(port, bit)| Pin { port, bit })
    }

    /// Its Arduino number, if it has one (every pin but a few of port G/J).
    pub fn arduino(self) -> Option<u8> {
        DIGITAL.iter().position(|&(port, bit)| port == self.port && bit == self.bit).map(|n| n as u8)
    }

    /// The ADC channel it can read (A0–A15), if any.
    pub fn adc_channel(self) -> Option<u8> {
        match self.arduino()? {
            n @ 54..=69 => Some(n - 54),
            _ => None,
        }
    }

    /// Parse a pin as written in a machine file.
    pub fn parse(value: &PinValue) -> Result<Pin, String> {
        let bad = || {
            format!("{value} is not a Mega 2560 pin (write an Arduino number 0–69, \"D0\"–\"D69\", \"A0\"–\"A15\" or a port bit such as \"PF0\")")
        };
        match value {
            PinValue::Number(n) => u8::try_from(*n).ok().and_then(Pin::digital).ok_or_else(bad),
            PinValue::Name(name) => {
                let upper = name.trim().to_ascii_uppercase();
                if let Some(rest) = upper.strip_prefix('D') {
                    rest.parse::<u8>().ok().and_then(Pin::digital).ok_or_else(bad)
                } else if let Some(rest) = upper.strip_prefix('A') {
                    rest.parse::<u8>().ok().filter(|&a| a < 16).and_then(|a| Pin::digital(54 + a)).ok_or_else(bad)
                } else if let Some(rest) = upper.strip_prefix('P') {
                    let mut chars = rest.chars();
                    let port = chars.next().filter(|c| PORTS.contains(*c)).ok_or_else(bad)?;
                    let bit = chars.as_str().parse::<u8>().ok().filter(|&b| b < 8).ok_or_else(bad)?;
                    Ok(Pin { port, bit })
                } else {
                    Err(bad())
                }
            }
        }
    }
}

/// RAMPS 1.4's pins for an axis role (`x`, `y`, `z`, `e`), Marlin's map:
/// STEP, DIR, ENABLE, MIN endstop, MAX endstop.
pub fn ramps_axis(role: &str) -> Option<[Option<u8>; 5]> {
    Some(match role {
        "x" => [Some(54), Some(55), Some(38), Some(3), Some(2)],
        "y" => [Some(60), Some(61), Some(56), Some(14), Some(15)],
        "z" => [Some(46), Some(48), Some(62), Some(18), Some(19)],
        "e" => [Some(26), Some(28), Some(24), None, None],
        _ => return None,
    })
}

/// RAMPS 1.4's heater outputs and thermistor inputs by heater role.
pub fn ramps_heater(role: &str) -> Option<(u8, u8)> {
    // (output pin, thermistor ADC pin as an Arduino number)
    Some(match role {
        "hotend" => (10, 54 + 13),
        "bed" => (8, 54 + 14),
        // The extrusion line's barrel: its SSR on D9, thermistor on A13.
        "barrel" => (9, 54 + 13),
        _ => return None,
    })
}

/// RAMPS 1.4's part-cooling fan (D9).
pub const RAMPS_FAN: u8 = 9;

/// The hardware PWM channels the Mega 2560 board drives for heaters and
/// fans: (Arduino pin, the board's name for the channel).
pub const PWM_CHANNELS: [(u8, &str); 3] = [(10, "Oc2a"), (9, "Oc2b"), (8, "Oc4c")];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramps_pins_are_marlins_port_bits() {
        let at = |n| Pin::digital(n).unwrap();
        assert_eq!(at(54), Pin { port: 'F', bit: 0 });
        assert_eq!(at(46), Pin { port: 'L', bit: 3 });
        assert_eq!(at(26), Pin { port: 'A', bit: 4 });
        assert_eq!(at(38), Pin { port: 'D', bit: 7 });
        assert_eq!(at(14), Pin { port: 'J', bit: 1 });
        assert_eq!(at(19), Pin { port: 'D', bit: 2 });
        assert_eq!(at(8), Pin { port: 'H', bit: 5 });
        assert_eq!(at(10), Pin { port: 'B', bit: 4 });
        assert_eq!(at(67).adc_channel(), Some(13));
    }

    #[test]
    fn every_spelling_of_a_pin_is_the_same_pin() {
        let x_step = Pin { port: 'F', bit: 0 };
        for value in [PinValue::Number(54), PinValue::Name("D54".into()), PinValue::Name("A0".into()), PinValue::Name("pf0".into())] {
            assert_eq!(Pin::parse(&value), Ok(x_step), "{value}");
        }
        assert!(Pin::parse(&PinValue::Number(70)).is_err());
        assert!(Pin::parse(&PinValue::Name("PI3".into())).is_err());
        assert!(Pin::parse(&PinValue::Name("A16".into())).is_err());
    }

    #[test]
    fn the_pin_map_names_each_port_bit_once() {
        let mut seen = std::collections::HashSet::new();
        for (port, bit) in DIGITAL {
            assert!(seen.insert((port, bit)), "P{port}{bit} twice");
        }
    }
}
