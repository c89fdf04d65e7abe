//! Replies to the host, in Marlin's exact words, and decimal formatting.
//!
//! Hosts parse these strings (Printrun, OctoPrint and Repetier-Host match
//! `ok`, `Error:`, `Resend:`, `echo:`, `T:` and `FIRMWARE_NAME:`), so they
//! are kept in one place. `ufmt` has no floats: values are printed from
//! fixed-point integers by [`write_fixed`].

use ufmt::{uWrite, Formatter};

/// Write `mantissa × 10^(−digits)` with exactly `digits` decimals.
pub fn write_fixed<W: uWrite + ?Sized>(f: &mut Formatter<'_, W>, mantissa: i32, digits: u8) -> Result<(), W::Error> {
    let mut divisor: u32 = 1;
    for _ in 0..digits {
        divisor *= 10;
    }
    let magnitude = mantissa.unsigned_abs();
    if mantissa < 0 {
        f.write_str("-")?;
    }
    ufmt::uwrite!(f, "{}", magnitude / divisor)?;
    if digits > 0 {
        f.write_str(".")?;
        let mut fraction = magnitude % divisor;
        let mut place = divisor / 10;
        while place > 0 {
            let digit = (fraction / place) as u8;
            f.write_char(char::from(b'0' + digit))?;
            fraction %= place;
            place /= 10;
        }
    }
    Ok(())
}

/// A fixed-point number printed with a set number of decimals.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fixed {
    pub mantissa: i32,
    pub digits: u8,
}

impl Fixed {
    /// Hundredths (`1234` → `12.34`), Marlin's usual precision.
    pub const fn hundredths(mantissa: i32) -> Self {
        Self { mantissa, digits: 2 }
    }

    /// Thousandths (`1234` → `1.234`).
    pub const fn thousandths(mantissa: i32) -> Self {
        Self { mantissa, digits: 3 }
    }
}

impl ufmt::uDisplay for Fixed {
    fn fmt<W: uWrite + ?Sized>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error> {
        write_fixed(f, self.mantissa, self.digits)
    }
}

/// Bytes shown to the user as text, with anything unprintable replaced by `?`
/// (an echo of garbage must not become garbage on the host's terminal).
pub struct Printable<'a>(pub &'a [u8]);

impl ufmt::uDisplay for Printable<'_> {
    fn fmt<W: uWrite + ?Sized>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error> {
        for &byte in self.0 {
            let shown = if (0x20..0x7f).contains(&byte) && byte != b'"' { byte } else { b'?' };
            f.write_char(char::from(shown))?;
        }
        Ok(())
    }
}

#[cfg(test)]
pub(crate) mod test_support {
    /// A `uWrite` sink for tests.
    #[derive(Default)]
    pub struct Text(pub std::string::String);

    impl ufmt::uWrite for Text {
        type Error = core::convert::Infallible;
        fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
            self.0.push_str(s);
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::Text;
    use super::*;

    fn shown(value: impl ufmt::uDisplay) -> std::string::String {
        let mut out = Text::default();
        ufmt::uwrite!(out, "{}", value).unwrap();
        out.0
    }

    #[test]
    fn fixed_point_prints_every_decimal() {
        assert_eq!(shown(Fixed::hundredths(21050)), "210.50");
        assert_eq!(shown(Fixed::hundredths(-5)), "-0.05");
        assert_eq!(shown(Fixed::hundredths(0)), "0.00");
        assert_eq!(shown(Fixed { mantissa: 7, digits: 0 }), "7");
        assert_eq!(shown(Fixed { mantissa: i32::MIN, digits: 3 }), "-2147483.648");
    }

    #[test]
    fn unprintable_bytes_are_masked() {
        assert_eq!(shown(Printable(b"M9\x00\xff\"")), "M9???");
    }
}
