//! Replies to the host, in Marlin's exact words, and decimal formatting.
//!
//! Hosts parse these strings (Printrun, OctoPrint and Repetier-Host match
//! `ok`, `Error:`, `Resend:`, `echo:`, `T:` and `FIRMWARE_NAME:`), so they
//! are kept in one place. `ufmt` has no floats: values are printed from
//! fixed-point integers by [`write_fixed`].

use ufmt::{uWrite, Formatter};

/// Write `mantissa × 10^(−digits)` with exactly `digits` decimals
/// (`digits` up to 9, as an `i32` holds).
///
/// The characters are made from the last with shift-and-add divisions by
/// ten, then written in order: smaller on the AVR than printing the whole
/// part with `ufmt` and the decimals with three 32-bit divisions each.
pub fn write_fixed<W: uWrite + ?Sized>(f: &mut Formatter<'_, W>, mantissa: i32, digits: u8) -> Result<(), W::Error> {
    // Sign, ten digits, a point, and the zeros before the first digit,
    // made from the end and written in one piece.
    const LEN: u8 = 24;
    let mut text = [core::mem::MaybeUninit::<u8>::uninit(); LEN as usize];
    let mut start = LEN;
    let mut put = |start: &mut u8, byte: u8| {
        *start -= 1;
        // SAFETY: an iteration of the loop below starts with `start` ≥ 3
        // (it stops at ≤ 2) and takes at most two places, the sign one
        // more: `start` stays within `text`.
        unsafe { text.get_unchecked_mut(usize::from(*start)).write(byte) };
    };
    let mut rest = mantissa.unsigned_abs();
    let mut made = 0u8;
    loop {
        let (quotient, digit) = crate::gcode::number::div_rem_10(rest);
        rest = quotient;
        put(&mut start, b'0' + digit as u8);
        made += 1;
        if made == digits {
            put(&mut start, b'.');
        }
        if (rest == 0 && made > digits) || start <= 2 {
            break;
        }
    }
    if mantissa < 0 {
        put(&mut start, b'-');
    }
    // SAFETY: `text[start..]` has been written, with digits, '.' and '-'
    // only: ASCII, valid UTF-8.
    f.write_str(unsafe {
        core::str::from_utf8_unchecked(core::slice::from_raw_parts(
            text.as_ptr().add(usize::from(start)).cast::<u8>(),
            usize::from(LEN - start),
        ))
    })
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

    /// A whole number, as `ufmt` prints an `i32` (`-12` → `-12`): with
    /// every integer printed this way, `ufmt`'s own `i32` formatting is
    /// not in the firmware.
    pub const fn whole(mantissa: i32) -> Self {
        Self { mantissa, digits: 0 }
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

/// An unsigned whole number (`u8`, `u16`) printed by [`write_fixed`]:
/// with every one printed this way, `ufmt`'s `u8`, `u16` and `usize`
/// printers (≈ 270 bytes on the AVR) are not in the firmware. The value
/// goes to one out-of-line writer in two registers, not as a pointer to a
/// copy on the stack nor as an `i32` and a digit count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Whole(pub u16);

impl ufmt::uDisplay for Whole {
    #[inline(always)]
    fn fmt<W: uWrite + ?Sized>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error> {
        write_whole(f, self.0)
    }
}

#[inline(never)]
fn write_whole<W: uWrite + ?Sized>(f: &mut Formatter<'_, W>, value: u16) -> Result<(), W::Error> {
    write_fixed(f, i32::from(value), 0)
}

/// `c`'s UTF-8 bytes, in order, to `put` (what `char::encode_utf8`
/// makes, without its buffer and panic path: a board's `write_char`).
/// The firmware writes ASCII; the longer forms are there for the contract.
#[inline(always)]
pub fn utf8_bytes(c: char, mut put: impl FnMut(u8)) {
    let code = u32::from(c);
    if code < 0x80 {
        put(code as u8);
        return;
    }
    // Continuation bytes after the lead byte, and the lead's marker.
    let (mut extra, lead) = if code < 0x800 {
        (1u8, 0xC0)
    } else if code < 0x1_0000 {
        (2, 0xE0)
    } else {
        (3, 0xF0)
    };
    put(lead | (code >> (6 * u32::from(extra))) as u8);
    while extra > 0 {
        extra -= 1;
        put(0x80 | ((code >> (6 * u32::from(extra))) & 0x3F) as u8);
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
        assert_eq!(shown(Fixed { mantissa: i32::MAX, digits: 0 }), "2147483647");
        assert_eq!(shown(Fixed { mantissa: i32::MIN, digits: 0 }), "-2147483648");
        assert_eq!(shown(Fixed { mantissa: 0, digits: 0 }), "0");
        assert_eq!(shown(Fixed { mantissa: -7, digits: 9 }), "-0.000000007");
        assert_eq!(shown(Fixed { mantissa: i32::MIN, digits: 9 }), "-2.147483648");
        assert_eq!(shown(Fixed { mantissa: 100, digits: 2 }), "1.00");
    }

    #[test]
    fn a_whole_fixed_prints_as_ufmt_prints_the_i32() {
        for n in [0, 1, -1, 9, 10, -10, 99, 100, 12345, -70000, i32::MAX, i32::MIN, i32::MIN + 1] {
            assert_eq!(shown(Fixed::whole(n)), shown(n), "{n}");
        }
    }

    #[test]
    fn a_whole_prints_as_ufmt_prints_the_u16() {
        for n in [0u16, 1, 9, 10, 99, 100, 255, 256, 12345, u16::MAX] {
            assert_eq!(shown(Whole(n)), shown(n), "{n}");
        }
    }

    #[test]
    fn utf8_bytes_are_what_encode_utf8_makes() {
        for c in ['\0', 'A', '\x7f', '\u{80}', 'é', '\u{7ff}', '\u{800}', '€', '\u{ffff}', '\u{10000}', '😀', char::MAX] {
            let mut bytes = std::vec::Vec::new();
            utf8_bytes(c, |b| bytes.push(b));
            assert_eq!(bytes, c.encode_utf8(&mut [0; 4]).as_bytes(), "{c:?}");
        }
    }

    #[test]
    fn unprintable_bytes_are_masked() {
        assert_eq!(shown(Printable(b"M9\x00\xff\"")), "M9???");
    }
}
