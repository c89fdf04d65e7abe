//! The number format of G-code values.
//!
//! A value is kept exactly as written, as a decimal: an `i32` mantissa and
//! the count of digits after the point (`-1.25` is `-125 × 10⁻²`). No float
//! is involved in lexing, so parsing costs a multiply-by-ten and an add per
//! digit on the AVR. Consumers convert to the fixed-point unit they need with
//! [`Decimal::to_scaled`] (e.g. micrometres: `to_scaled(3)`), rounding half
//! away from zero, or to `f32` where float is acceptable (the main loop).
//!
//! Digits after the ninth significant one in the fraction are dropped (a
//! slicer's `E0.0412345678` keeps `0.041234567`); an integer part that does
//! not fit an `i32` is an error, never a wrap-around.

/// Most fractional digits stored; more are read and ignored.
pub const MAX_FRACTION_DIGITS: u8 = 9;

/// An exact decimal value as written in the G-code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decimal {
    mantissa: i32,
    fraction_digits: u8,
}

/// Why the characters after a word letter are not a number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NumberError {
    /// No digit at all (`X-`, `X.`), a second point (`X1.2.3`), or an
    /// exponent (`x1e30`: exponents are not G-code).
    Malformed,
    /// The integer part does not fit (`X99999999999`).
    OutOfRange,
}

/// `value · 10 + digit` for a non-negative `value`, or `None` on overflow.
///
/// Written with a comparison instead of `checked_mul`: on the AVR,
/// `i32::checked_mul` calls compiler-builtins' `__mulosi4`, which stores a
/// 32-bit overflow flag where avr-gcc's ABI reserves a 16-bit `int` and so
/// corrupts the caller's stack (seen with nightly 1.97 on simavr and QEMU).
fn times_ten_plus(value: i32, digit: i32) -> Option<i32> {
    if value > (i32::MAX - digit) / 10 {
        None
    } else {
        Some(value * 10 + digit)
    }
}

const POWERS_OF_TEN: [i32; 10] =
    [1, 10, 100, 1_000, 10_000, 100_000, 1_000_000, 10_000_000, 100_000_000, 1_000_000_000];

impl Decimal {
    /// `mantissa × 10^(−fraction_digits)`.
    pub const fn new(mantissa: i32, fraction_digits: u8) -> Self {
        Self { mantissa, fraction_digits }
    }

    /// A whole number.
    pub const fn from_int(value: i32) -> Self {
        Self { mantissa: value, fraction_digits: 0 }
    }

    pub const fn mantissa(self) -> i32 {
        self.mantissa
    }

    pub const fn fraction_digits(self) -> u8 {
        self.fraction_digits
    }

    pub const fn is_negative(self) -> bool {
        self.mantissa < 0
    }

    pub const fn is_zero(self) -> bool {
        self.mantissa == 0
    }

    /// The value in units of `10^(−digits)`, rounded half away from zero;
    /// `None` when it does not fit an `i32`.
    pub fn to_scaled(self, digits: u8) -> Option<i32> {
        if digits >= self.fraction_digits {
            let factor = *POWERS_OF_TEN.get(usize::from(digits - self.fraction_digits))?;
            // A bound check, not `checked_mul` (see `times_ten_plus`).
            if self.mantissa.unsigned_abs() > (i32::MAX / factor) as u32 {
                None
            } else {
                Some(self.mantissa * factor)
            }
        } else {
            let divisor = POWERS_OF_TEN[usize::from(self.fraction_digits - digits)];
            let half = divisor / 2;
            let rounded = if self.mantissa >= 0 {
                (self.mantissa / divisor) + i32::from(self.mantissa % divisor >= half)
            } else {
                (self.mantissa / divisor) - i32::from(-(self.mantissa % divisor) >= half)
            };
            Some(rounded)
        }
    }

    /// The value rounded to a whole number.
    pub fn to_int(self) -> Option<i32> {
        self.to_scaled(0)
    }

    /// The value as `f32` (for the main loop's float code, never interrupts).
    pub fn to_f32(self) -> f32 {
        self.mantissa as f32 / POWERS_OF_TEN[usize::from(self.fraction_digits)] as f32
    }

    /// Read a number at the start of `text`; returns it and the bytes used.
    ///
    /// Accepts an optional sign, digits, at most one point, and at least one
    /// digit (`5`, `-0.5`, `+.5`, `5.`). Stops at the first other byte.
    pub fn parse(text: &[u8]) -> Result<(Self, usize), NumberError> {
        let mut index = 0;
        let negative = match text.first() {
            Some(b'-') => {
                index = 1;
                true
            }
            Some(b'+') => {
                index = 1;
                false
            }
            _ => false,
        };
        let mut magnitude: i32 = 0;
        let mut fraction_digits: u8 = 0;
        let mut seen_point = false;
        let mut seen_digit = false;
        // Fraction digits beyond what an i32 holds are read and dropped.
        let mut fraction_full = false;
        while let Some(&byte) = text.get(index) {
            match byte {
                b'0'..=b'9' => {
                    seen_digit = true;
                    let digit = i32::from(byte - b'0');
                    if seen_point {
                        if !fraction_full && fraction_digits < MAX_FRACTION_DIGITS {
                            match times_ten_plus(magnitude, digit) {
                                Some(m) => {
                                    magnitude = m;
                                    fraction_digits += 1;
                                }
                                None => fraction_full = true,
                            }
                        }
                    } else {
                        magnitude = times_ten_plus(magnitude, digit).ok_or(NumberError::OutOfRange)?;
                    }
                }
                b'.' if !seen_point => seen_point = true,
                b'.' => return Err(NumberError::Malformed),
                // `1e30`: an exponent is not G-code; refuse rather than read X1 E30.
                b'e' if seen_digit
                    && matches!(text.get(index + 1), Some(b'0'..=b'9' | b'+' | b'-')) =>
                {
                    return Err(NumberError::Malformed)
                }
                _ => break,
            }
            index += 1;
        }
        if !seen_digit {
            return Err(NumberError::Malformed);
        }
        let mantissa = if negative { -magnitude } else { magnitude };
        Ok((Self { mantissa, fraction_digits }, index))
    }
}

impl ufmt::uDisplay for Decimal {
    fn fmt<W: ufmt::uWrite + ?Sized>(&self, f: &mut ufmt::Formatter<'_, W>) -> Result<(), W::Error> {
        crate::reply::write_fixed(f, self.mantissa, self.fraction_digits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parsed(text: &str) -> Result<(Decimal, usize), NumberError> {
        Decimal::parse(text.as_bytes())
    }

    #[test]
    fn integers_decimals_and_signs_are_exact() {
        assert_eq!(parsed("10"), Ok((Decimal::new(10, 0), 2)));
        assert_eq!(parsed("-1.25"), Ok((Decimal::new(-125, 2), 5)));
        assert_eq!(parsed("+.5"), Ok((Decimal::new(5, 1), 3)));
        assert_eq!(parsed("5."), Ok((Decimal::new(5, 0), 2)));
        assert_eq!(parsed("0.00000"), Ok((Decimal::new(0, 5), 7)));
    }

    #[test]
    fn parsing_stops_at_the_next_word() {
        assert_eq!(parsed("12.5Y3"), Ok((Decimal::new(125, 1), 4)));
        assert_eq!(parsed("3 X"), Ok((Decimal::new(3, 0), 1)));
    }

    #[test]
    fn malformed_numbers_are_errors() {
        assert_eq!(parsed("1.2.3"), Err(NumberError::Malformed));
        assert_eq!(parsed("-"), Err(NumberError::Malformed));
        assert_eq!(parsed("."), Err(NumberError::Malformed));
        assert_eq!(parsed(""), Err(NumberError::Malformed));
        assert_eq!(parsed("1e30"), Err(NumberError::Malformed));
        assert_eq!(parsed("2.5e-3"), Err(NumberError::Malformed));
    }

    #[test]
    fn an_integer_part_too_large_is_out_of_range() {
        assert_eq!(parsed("99999999999"), Err(NumberError::OutOfRange));
        assert_eq!(parsed("2147483647"), Ok((Decimal::new(i32::MAX, 0), 10)));
    }

    #[test]
    fn excess_fraction_digits_are_dropped_not_wrapped() {
        let (value, used) = parsed("0.0412345678901").unwrap();
        assert_eq!(used, 15);
        assert_eq!(value, Decimal::new(41_234_567, 9));
        let (value, _) = parsed("1234567.123456").unwrap();
        assert_eq!(value.to_scaled(3), Some(1_234_567_123));
    }

    #[test]
    fn scaling_rounds_half_away_from_zero() {
        assert_eq!(Decimal::new(12345, 4).to_scaled(3), Some(1235));
        assert_eq!(Decimal::new(-12345, 4).to_scaled(3), Some(-1235));
        assert_eq!(Decimal::new(12344, 4).to_scaled(3), Some(1234));
        assert_eq!(Decimal::new(15, 0).to_scaled(3), Some(15_000));
        assert_eq!(Decimal::new(3_000_000, 0).to_scaled(3), None);
        assert_eq!(Decimal::new(25, 1).to_int(), Some(3));
    }

    #[test]
    fn conversion_to_float() {
        assert_eq!(Decimal::new(-125, 2).to_f32(), -1.25);
    }
}
