//! Integer helpers that are safe on the AVR.
//!
//! On `avr-none`, `i32::checked_mul`/`overflowing_mul` call compiler-builtins'
//! `__mulosi4`, which corrupts the stack, and `u64` division pulls in a
//! kilobyte of 64-bit division code. So: overflow is decided by comparing
//! with a bound (one `u32` division, already linked), and the few 64-bit
//! quotients (auto-tune gains) use a shift-and-subtract loop.

/// `a · b`, saturating at `i32::MIN`/`i32::MAX`.
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
pub fn scale(x: i32, numerator: i32, denominator: i32) -> i32 {
    if denominator <= 0 {
        return 0;
    }
    let whole = saturating_mul(x / denominator, numerator);
    let part = saturating_mul(x % denominator, numerator) / denominator;
    whole.saturating_add(part)
}

/// `a · b` as a 64-bit product from four 16-bit products (no `__muldi3`).
pub fn wide_mul(a: u32, b: u32) -> u64 {
    let (a_high, a_low) = (a >> 16, a & 0xFFFF);
    let (b_high, b_low) = (b >> 16, b & 0xFFFF);
    let low = u64::from(a_low * b_low);
    let middle = u64::from(a_high * b_low) + u64::from(a_low * b_high);
    let high = u64::from(a_high * b_high);
    (high << 32) + (middle << 16) + low
}

/// `a · b` for a 64-bit `a`, saturating at `u64::MAX`.
pub fn mul_u64(a: u64, b: u32) -> u64 {
    let high = wide_mul((a >> 32) as u32, b);
    if high >> 32 != 0 {
        return u64::MAX;
    }
    (high << 32).saturating_add(wide_mul(a as u32, b))
}

/// `numerator / denominator` rounded to nearest (halves up), by shift and
/// subtract; `u64::MAX` for a zero denominator.
pub fn div_round(numerator: u64, denominator: u64) -> u64 {
    if denominator == 0 {
        return u64::MAX;
    }
    let mut rest = numerator.saturating_add(denominator >> 1);
    let mut remainder = 0u64;
    let mut quotient = 0u64;
    for _ in 0..64 {
        remainder = (remainder << 1) | (rest >> 63);
        rest <<= 1;
        quotient <<= 1;
        if remainder >= denominator {
            remainder -= denominator;
            quotient |= 1;
        }
    }
    quotient
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn wide_mul_and_div_round_match_u128() {
        let values = [0u32, 1, 2, 3, 355, 0xFFFF, 0x1_0000, 0xDEAD_BEEF, u32::MAX];
        for a in values {
            for b in values {
                assert_eq!(wide_mul(a, b), u64::from(a) * u64::from(b), "{a} × {b}");
                let product = u64::from(a) * u64::from(b);
                if b != 0 {
                    let expected = ((u128::from(product) + u128::from(b) / 2) / u128::from(b)) as u64;
                    assert_eq!(div_round(product, u64::from(b)), expected, "{product} / {b}");
                }
            }
        }
        assert_eq!(div_round(7, 2), 4);
        assert_eq!(div_round(5, 0), u64::MAX);
        assert_eq!(mul_u64(1 << 50, 1 << 20), u64::MAX);
        assert_eq!(mul_u64(1 << 40, 1 << 20), 1 << 60);
        assert_eq!(mul_u64(1 << 40, 1000), 1000 << 40);
    }
}
