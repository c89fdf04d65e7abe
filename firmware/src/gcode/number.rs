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

/// Largest magnitude that can take one more digit: `i32::MAX / 10`.
const TIMES_TEN_LIMIT: u32 = i32::MAX as u32 / 10;

/// `value · 10 + digit` when it stays within `i32::MAX`, else `None`.
///
/// The bound is a constant: a division per digit pulls in compiler-builtins'
/// generic 32-bit division on the AVR, thousands of cycles a call (the G1
/// benchmark spent most of its time there). And a comparison, not
/// `checked_mul`: on the AVR, `i32::checked_mul` calls compiler-builtins'
/// `__mulosi4`, which stores a 32-bit overflow flag where avr-gcc's ABI
/// reserves a 16-bit `int` and so corrupts the caller's stack (seen with
/// nightly 1.97 on simavr and QEMU).
///
/// Inline: it runs for every digit of every word (≈ 20 a slicer `G1`), and
/// out of line the call and the 32-bit argument shuffling cost the AVR more
/// than the arithmetic. Up to the limit, `value · 10 + digit` fits a `u32`
/// (at most `i32::MAX + 9`), so the last-digit test is the sign bit of the
/// result.
#[inline(always)]
fn times_ten_plus(value: u32, digit: u8) -> Option<u32> {
    if value > TIMES_TEN_LIMIT {
        return None;
    }
    // ·10 as ·8 + ·2: a 32-bit multiplication is a library call on the
    // AVR (≈ 100 cycles a digit more).
    let result = (value << 3) + (value << 1) + u32::from(digit);
    if result > i32::MAX as u32 {
        None
    } else {
        Some(result)
    }
}

const POWERS_OF_TEN: [i32; 10] =
    [1, 10, 100, 1_000, 10_000, 100_000, 1_000_000, 10_000_000, 100_000_000, 1_000_000_000];

/// `n / 10` and `n % 10`, by [`div_rem_small`].
#[inline(always)]
pub(crate) fn div_rem_10(n: u32) -> (u32, u32) {
    let (quotient, remainder) = div_rem_small(n, 10);
    (quotient, u32::from(remainder))
}

/// `n / divisor` and `n % divisor` for a divisor of 1–128: shift-and-
/// subtract with a one-byte remainder, about 350 AVR cycles in 100 bytes of
/// code, where a 32-bit `/` calls the library's 32-bit loop and the
/// shift-and-add `divu10` (100 cycles) took 300 bytes, 300 more inlined in
/// each `n / 60`. Never inlined: scaling, feed rates and decimal output
/// share the one copy.
#[cfg(not(target_arch = "avr"))]
#[inline(never)]
pub(crate) fn div_rem_small(mut n: u32, divisor: u8) -> (u32, u8) {
    let mut remainder: u8 = 0;
    for _ in 0..32 {
        // The remainder stays below the divisor (≤ 128), so the shifted
        // remainder with the next bit fits a byte.
        remainder = (remainder << 1) | (n >> 31) as u8;
        n <<= 1;
        if remainder >= divisor {
            remainder -= divisor;
            n |= 1;
        }
    }
    (n, remainder)
}

/// The same loop in AVR assembly: the compiler's took twice the cycles
/// (≈ 24 an iteration, here 11).
#[cfg(target_arch = "avr")]
#[inline(never)]
pub(crate) fn div_rem_small(n: u32, divisor: u8) -> (u32, u8) {
    let [mut b0, mut b1, mut b2, mut b3] = n.to_le_bytes();
    let mut remainder: u8 = 0;
    // SAFETY: registers only; the quotient's bits enter at the bottom of
    // `n` as its dividend bits leave at the top (into the remainder, which
    // stays below the divisor ≤ 128, so `rol` never carries out of it).
    unsafe {
        core::arch::asm!(
            "ldi {bits}, 32",
            "1:",
            "lsl {b0}",
            "rol {b1}",
            "rol {b2}",
            "rol {b3}",
            "rol {rem}",
            "cp {rem}, {div}",
            "brlo 2f",
            "sub {rem}, {div}",
            "inc {b0}",
            "2:",
            "dec {bits}",
            "brne 1b",
            b0 = inout(reg) b0,
            b1 = inout(reg) b1,
            b2 = inout(reg) b2,
            b3 = inout(reg) b3,
            rem = inout(reg) remainder,
            div = in(reg) divisor,
            bits = out(reg_upper) _,
            options(pure, nomem, nostack),
        );
    }
    (u32::from_le_bytes([b0, b1, b2, b3]), remainder)
}

/// `n / 60` (feed rates per minute to per second).
pub(crate) fn div_60(n: u32) -> u32 {
    div_rem_small(n, 60).0
}

/// `n / 10^k`, rounded half up (for magnitudes: half away from zero), with
/// `k` divisions by ten instead of one 32-bit division.
fn div_pow10_rounded(n: u32, k: u8) -> u32 {
    let mut quotient = n;
    // The remainder is at least half of 10^k exactly when the most
    // significant digit dropped (the last one) is 5 or more.
    let mut round_up = false;
    for _ in 0..k {
        let (q, r) = div_rem_10(quotient);
        round_up = r >= 5;
        quotient = q;
    }
    quotient + u32::from(round_up)
}

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
            // k steps of `times_ten_plus` (no table in RAM, no division,
            // no `checked_mul`), with its bound check at each step.
            let mut magnitude = self.mantissa.unsigned_abs();
            for _ in self.fraction_digits..digits {
                magnitude = times_ten_plus(magnitude, 0)?;
            }
            // At most i32::MAX (times_ten_plus), so the cast is exact; and
            // i32::MIN's magnitude is refused at the first step, or, with
            // no step, returned as is.
            Some(if self.mantissa < 0 { (magnitude as i32).wrapping_neg() } else { magnitude as i32 })
        } else {
            let magnitude = div_pow10_rounded(self.mantissa.unsigned_abs(), self.fraction_digits - digits) as i32;
            Some(if self.mantissa < 0 { -magnitude } else { magnitude })
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
        let mut magnitude: u32 = 0;
        let mut fraction_digits: u8 = 0;
        let mut seen_point = false;
        let mut seen_digit = false;
        // Fraction digits beyond what an i32 holds are read and dropped.
        let mut fraction_full = false;
        while let Some(&byte) = text.get(index) {
            match byte {
                b'0'..=b'9' => {
                    seen_digit = true;
                    let digit = byte - b'0';
                    // One call site for both parts (`fraction_full` is
                    // only ever set after the point).
                    if !fraction_full {
                        match times_ten_plus(magnitude, digit) {
                            Some(m) => {
                                magnitude = m;
                                if seen_point {
                                    fraction_digits += 1;
                                    fraction_full = fraction_digits == MAX_FRACTION_DIGITS;
                                }
                            }
                            None if seen_point => fraction_full = true,
                            None => return Err(NumberError::OutOfRange),
                        }
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
        // At most i32::MAX (times_ten_plus), so the cast is exact.
        let mantissa = if negative { -(magnitude as i32) } else { magnitude as i32 };
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
    fn the_largest_integer_part_is_i32_max_exactly() {
        assert_eq!(parsed("2147483647"), Ok((Decimal::new(i32::MAX, 0), 10)));
        assert_eq!(parsed("-2147483647"), Ok((Decimal::new(-i32::MAX, 0), 11)));
        assert_eq!(parsed("2147483648"), Err(NumberError::OutOfRange));
        assert_eq!(parsed("2147483650"), Err(NumberError::OutOfRange));
        assert_eq!(parsed("214748365"), Ok((Decimal::new(214_748_365, 0), 9)));
        // Fraction digits stop where the next one would overflow.
        assert_eq!(parsed("0.2147483647"), Ok((Decimal::new(214_748_364, 9), 12)));
        assert_eq!(parsed("21474836.48"), Ok((Decimal::new(214_748_364, 1), 11)));
    }

    #[test]
    fn scaling_down_rounds_on_the_first_dropped_digit() {
        assert_eq!(Decimal::new(12_345, 4).to_scaled(3), Some(1_235));
        assert_eq!(Decimal::new(1_234_499_999, 9).to_scaled(3), Some(1_234));
        assert_eq!(Decimal::new(1_234_500_000, 9).to_scaled(3), Some(1_235));
        assert_eq!(Decimal::new(-1_234_500_000, 9).to_scaled(0), Some(-1));
        assert_eq!(Decimal::new(i32::MAX, 9).to_scaled(0), Some(2));
        assert_eq!(Decimal::new(-i32::MAX, 1).to_scaled(0), Some(-214_748_365));
        assert_eq!(Decimal::new(99_999, 5).to_scaled(0), Some(1));
    }

    #[test]
    fn division_by_ten_is_exact_over_the_whole_range() {
        for n in (0..=u32::MAX).step_by(9_973).chain([u32::MAX, u32::MAX - 1, 9, 10, 11, 19, 20, 99, 100]) {
            assert_eq!(div_rem_10(n), (n / 10, n % 10), "{n}");
        }
    }

    #[test]
    fn scaling_matches_exact_arithmetic() {
        fn reference(mantissa: i32, from: u8, to: u8) -> Option<i32> {
            let m = i64::from(mantissa);
            let value = if to >= from {
                m.checked_mul(10i64.checked_pow(u32::from(to - from))?)?
            } else {
                let d = 10i64.pow(u32::from(from - to));
                let q = m.abs() / d + i64::from(m.abs() % d * 2 >= d);
                q * m.signum()
            };
            i32::try_from(value).ok()
        }
        for mantissa in (i32::MIN + 1..=i32::MAX).step_by(65_537).chain([-1, 0, 1, 5, -5, 49, 50, -50]) {
            for from in 0..=9 {
                for to in 0..=9 {
                    assert_eq!(
                        Decimal::new(mantissa, from).to_scaled(to),
                        reference(mantissa, from, to),
                        "{mantissa} e-{from} to e-{to}"
                    );
                }
            }
        }
    }

    #[test]
    fn small_divisions_are_exact() {
        for divisor in [1u8, 3, 7, 10, 60, 127, 128] {
            for n in (0..=u32::MAX).step_by(104_729).chain([
                u32::MAX,
                u32::MAX - 1,
                0,
                1,
                127,
                128,
                255,
                256,
            ]) {
                let d = u32::from(divisor);
                assert_eq!(
                    div_rem_small(n, divisor),
                    (n / d, (n % d) as u8),
                    "{n} / {divisor}"
                );
            }
        }
    }

    #[test]
    fn division_by_sixty_is_exact_over_the_whole_range() {
        for n in (0..=u32::MAX).step_by(7_919).chain([u32::MAX, 59, 60, 61, 119, 120, 179, 180, 1_799_999]) {
            assert_eq!(div_60(n), n / 60, "{n}");
        }
    }

    #[test]
    fn scaling_up_stops_at_the_limit() {
        assert_eq!(Decimal::new(2_147_483, 0).to_scaled(3), Some(2_147_483_000));
        assert_eq!(Decimal::new(2_147_484, 0).to_scaled(3), None);
        assert_eq!(Decimal::new(-2_147_483, 0).to_scaled(3), Some(-2_147_483_000));
        assert_eq!(Decimal::new(i32::MAX, 0).to_scaled(0), Some(i32::MAX));
        assert_eq!(Decimal::new(3, 0).to_scaled(10), None);
    }

    #[test]
    fn conversion_to_float() {
        assert_eq!(Decimal::new(-125, 2).to_f32(), -1.25);
    }
}
