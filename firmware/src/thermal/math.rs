//! Integer helpers that are safe on the AVR.
//!
//! On `avr-none`, `i32::checked_mul`/`overflowing_mul` call compiler-builtins'
//! `__mulosi4`, which corrupts the stack, and `u64` division pulls in a
//! kilobyte of 64-bit division code. So: overflow is decided by comparing
//! with a bound (one `u32` division, already linked), and the few 64-bit
//! quotients (auto-tune gains) use a shift-and-subtract loop.

/// `value` within `low..=high` (`low` ≤ `high`): `i32::clamp` without its
/// assertion of that, whose panic path and checks cost the AVR bytes at
/// every one of its callers, all of which pass ordered bounds.
#[inline(never)]
pub fn clamp(value: i32, low: i32, high: i32) -> i32 {
    if value < low {
        low
    } else if value > high {
        high
    } else {
        value
    }
}

/// `a · b`, saturating at `i32::MIN`/`i32::MAX`.
#[inline(never)]
pub fn saturating_mul(a: i32, b: i32) -> i32 {
    if a == 0 || b == 0 {
        return 0;
    }
    let negative = (a < 0) != (b < 0);
    let limit: u32 = if negative { 1 << 31 } else { i32::MAX as u32 };
    let (a, b) = (a.unsigned_abs(), b.unsigned_abs());
    if b > limit / a {
        return if negative { i32::MIN } else { i32::MAX };
    }
    let product = a.wrapping_mul(b);
    if negative {
        0u32.wrapping_sub(product) as i32
    } else {
        product as i32
    }
}

/// `x · numerator / denominator` for a positive `denominator`, without
/// forming the full product (`x / d · n + x % d · n / d`), saturating.
/// Exact (truncated toward zero) while `denominator · numerator < 2³¹`.
#[inline(never)]
pub fn scale(x: i32, numerator: i32, denominator: i32) -> i32 {
    if denominator <= 0 {
        return 0;
    }
    let whole = saturating_mul(x / denominator, numerator);
    let part = saturating_mul(x % denominator, numerator) / denominator;
    whole.saturating_add(part)
}

/// `round(x · m / n)` (halves up) with the full 64-bit product, from
/// 32-bit operations only (16-bit partial products, then 32 steps of
/// shift-and-subtract); `None` when `n` is 0 or the quotient does not fit.
#[inline(never)]
pub fn mul_div_round(x: u32, m: u32, n: u32) -> Option<u32> {
    if n == 0 {
        return None;
    }
    let (x_high, x_low, m_high, m_low) = (x >> 16, x & 0xFFFF, m >> 16, m & 0xFFFF);
    let (low_low, low_high, high_low) = (x_low * m_low, x_low * m_high, x_high * m_low);
    let middle = (low_low >> 16) + (low_high & 0xFFFF) + (high_low & 0xFFFF);
    let mut low = (middle << 16) | (low_low & 0xFFFF);
    let mut high = x_high * m_high + (low_high >> 16) + (high_low >> 16) + (middle >> 16);
    // + n/2 for rounding.
    let (sum, carry) = low.overflowing_add(n / 2);
    low = sum;
    high = high.wrapping_add(u32::from(carry));
    if high >= n {
        return None;
    }
    // The quotient's bits are shifted into `low` as its bits move out
    // into the remainder (`high`); a `u8` count.
    let mut remainder = high;
    let mut count = 32u8;
    while count > 0 {
        count -= 1;
        let overflow = remainder >> 31;
        remainder = (remainder << 1) | (low >> 31);
        low <<= 1;
        if overflow != 0 || remainder >= n {
            remainder = remainder.wrapping_sub(n);
            low |= 1;
        }
    }
    Some(low)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clamp_matches_the_core_clamp_for_ordered_bounds() {
        let values = [i32::MIN, -1 << 29, -21, -1, 0, 1, 20, 127, 255, 1 << 29, i32::MAX];
        for value in values {
            for low in values {
                for high in values.into_iter().filter(|&high| high >= low) {
                    assert_eq!(clamp(value, low, high), value.clamp(low, high), "{value} {low} {high}");
                }
            }
        }
    }

    #[test]
    fn saturating_mul_matches_i64_or_saturates() {
        let values = [0, 1, -1, 7, -7, 46_340, 46_341, -46_341, 65_536, -65_536, 32_768, i32::MAX, i32::MIN, i32::MIN + 1];
        for a in values {
            for b in values {
                let exact = i64::from(a) * i64::from(b);
                let expected = exact.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32;
                assert_eq!(saturating_mul(a, b), expected, "{a} × {b}");
            }
        }
    }

    #[test]
    fn scale_multiplies_then_divides_without_overflow() {
        assert_eq!(scale(2_000_000_000, 1000, 2000), 1_000_000_000);
        assert_eq!(scale(-7, 1000, 3), -2333);
        assert_eq!(scale(1_000_000, 100, 1000), 100_000);
        assert_eq!(scale(i32::MAX, 1000, 1), i32::MAX);
        assert_eq!(scale(5, 1, 0), 0);
    }

    #[test]
    fn mul_div_round_matches_u128_and_refuses_what_does_not_fit() {
        let values = [0u32, 1, 2, 3, 355, 0xFFFF, 0x1_0000, 104_348, 0xDEAD_BEEF, u32::MAX];
        for x in values {
            for m in values {
                for n in values {
                    let exact = (u128::from(x) * u128::from(m) + u128::from(n / 2)).checked_div(u128::from(n));
                    let expected = exact.and_then(|q| u32::try_from(q).ok());
                    assert_eq!(mul_div_round(x, m, n), expected, "{x} × {m} / {n}");
                }
            }
        }
        assert_eq!(mul_div_round(7, 1, 2), Some(4));
        // Pseudo-random operands, and quotients near 2³².
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for i in 0..400_000u32 {
            let r = next();
            let (x, m) = ((r >> 32) as u32 >> (i % 32), r as u32 >> (i / 32 % 32));
            let n = match i % 4 {
                0 => next() as u32,
                1 => (next() as u32) >> (i % 31),
                2 => ((u64::from(x) * u64::from(m)) >> 32) as u32 + (i % 3),
                _ => u32::MAX - (i % 5),
            };
            let exact = (u128::from(x) * u128::from(m) + u128::from(n / 2)).checked_div(u128::from(n));
            let expected = exact.and_then(|q| u32::try_from(q).ok());
            assert_eq!(mul_div_round(x, m, n), expected, "{x} × {m} / {n}");
        }
        assert_eq!(mul_div_round(5, 1, 0), None);
    }
}
