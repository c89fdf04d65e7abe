//! Single-precision maths for the main loop: square root, arc tangent and
//! sine/cosine, written out because `core` has none of them and a soft-float
//! AVR cannot afford the slow generic routines.
//!
//! Never call these from the step interrupt: they are float code.
//!
//! Accuracy (checked against `f64` in the tests): `sqrt` within 2 ulp,
//! `atan`/`atan2` within 3·10⁻⁷ rad, `sin_cos` within 6·10⁻⁷ over ±7 rad
//! (the reduction's rounding grows with the angle). The arm's
//! inverse kinematics needs 1 pulse = 1.57·10⁻⁴ rad at 200 ppr, so this is
//! three orders of magnitude to spare.

//! On the AVR, `sqrt`, `atan`, `atan2` and `sin_cos` call avr-libc's
//! libm instead (hand-written assembly for the AVR's 32-bit `double`,
//! correctly rounded to within 1–2 ulp): the same results to the precision
//! above, in 1.5 KB less flash. The Rust versions below are what the host,
//! the ARM board and the tests run.

pub const PI: f32 = core::f32::consts::PI;

#[cfg(target_arch = "avr")]
mod avr_libm {
    // avr-libc's `double` is 32 bits: these are single precision.
    extern "C" {
        pub fn sqrt(x: f32) -> f32;
        pub fn atan(x: f32) -> f32;
        pub fn atan2(y: f32, x: f32) -> f32;
        pub fn sin(x: f32) -> f32;
        pub fn cos(x: f32) -> f32;
    }
}
const HALF_PI: f32 = core::f32::consts::FRAC_PI_2;
const SIXTH_PI: f32 = core::f32::consts::FRAC_PI_6;
/// tan(π/12): above it, the arc tangent is shifted by π/6 first.
const TAN_TWELFTH_PI: f32 = 0.267_949_2;
const SQRT_3: f32 = 1.732_050_8;

/// Square root; 0 for zero, negative and NaN input.
///
/// One guess from the exponent bits, then four Newton steps on 1/√x, which
/// need only multiplications (a soft-float division costs several of them).
// Out of line: the zero/negative test inlined at every call cost 284
// bytes on the AVR.
#[inline(never)]
pub fn sqrt(value: f32) -> f32 {
    // `!(value > 0.0)` on the bits: the positive floats (subnormals to
    // +∞) are exactly the bit patterns 1..=0x7F80_0000; zero, negatives
    // and NaN fall outside. A soft-float comparison cost ≈ 60 AVR cycles
    // of every square root (about ten a line of a slicer stream).
    if value.to_bits().wrapping_sub(1) >= 0x7F80_0000 {
        return 0.0;
    }
    #[cfg(target_arch = "avr")]
    // SAFETY: a pure function of its argument (avr-libc libm).
    return unsafe { avr_libm::sqrt(value) };
    #[cfg(not(target_arch = "avr"))]
    sqrt_newton(value)
}

#[cfg_attr(target_arch = "avr", allow(dead_code))]
fn sqrt_newton(value: f32) -> f32 {
    if value == f32::INFINITY {
        return value;
    }
    // Halving the biased exponent gives 1/√x within a few per cent.
    let mut inverse = f32::from_bits(0x5f37_59df_u32.wrapping_sub(value.to_bits() >> 1));
    let half = 0.5 * value;
    for _ in 0..4 {
        inverse *= 1.5 - half * inverse * inverse;
    }
    let root = value * inverse;
    // One Newton step on the root itself, 1/(2√x) taken from `inverse`:
    // removes the rounding bias of the product above.
    root + 0.5 * inverse * (value - root * root)
}

/// √(x² + y²), out of line (several callers: each inline copy of the
/// soft-float calls cost flash).
#[inline(never)]
pub fn length2(x: f32, y: f32) -> f32 {
    sqrt(x * x + y * y)
}

/// v² + 2·a·d: the speed² after accelerating at `accel` over `distance`
/// from speed² `v_sqr` (the planner's passes and the segment profile; out
/// of line: five call sites).
#[inline(never)]
pub fn speed_sqr_after(v_sqr: f32, accel: f32, distance: f32) -> f32 {
    v_sqr + 2.0 * accel * distance
}

/// Arc tangent in (−π/2, π/2).
pub fn atan(value: f32) -> f32 {
    if value.is_nan() {
        return value;
    }
    #[cfg(target_arch = "avr")]
    // SAFETY: a pure function of its argument (avr-libc libm).
    return unsafe { avr_libm::atan(value) };
    #[cfg(not(target_arch = "avr"))]
    atan_series(value)
}

#[cfg_attr(target_arch = "avr", allow(dead_code))]
fn atan_series(value: f32) -> f32 {
    let negative = value < 0.0;
    let mut x = if negative { -value } else { value };
    let mut offset = 0.0;
    if x > 1.0 {
        // atan(x) = π/2 − atan(1/x)
        x = 1.0 / x;
        offset = HALF_PI;
    }
    let mut shift = 0.0;
    if x > TAN_TWELFTH_PI {
        // atan(x) = π/6 + atan((x√3 − 1)/(x + √3)), which lands in ±tan(π/12).
        x = (x * SQRT_3 - 1.0) / (x + SQRT_3);
        shift = SIXTH_PI;
    }
    // Taylor series to x¹¹: the next term is below 3·10⁻⁹ for |x| ≤ tan(π/12).
    let x2 = x * x;
    let series = x
        * (1.0
            - x2 * (1.0 / 3.0
                - x2 * (1.0 / 5.0 - x2 * (1.0 / 7.0 - x2 * (1.0 / 9.0 - x2 * (1.0 / 11.0))))));
    let mut angle = shift + series;
    if offset != 0.0 {
        angle = offset - angle;
    }
    if negative {
        -angle
    } else {
        angle
    }
}

/// Angle of the vector (x, y) in (−π, π]; 0 for the zero vector.
pub fn atan2(y: f32, x: f32) -> f32 {
    #[cfg(target_arch = "avr")]
    if !(x == 0.0 && y == 0.0) {
        // SAFETY: a pure function of its arguments (avr-libc libm).
        return unsafe { avr_libm::atan2(y, x) };
    }
    if x > 0.0 {
        atan(y / x)
    } else if x < 0.0 {
        if y >= 0.0 {
            atan(y / x) + PI
        } else {
            atan(y / x) - PI
        }
    } else if y > 0.0 {
        HALF_PI
    } else if y < 0.0 {
        -HALF_PI
    } else {
        0.0
    }
}

/// Sine and cosine of an angle in radians (best within a few turns of 0).
pub fn sin_cos(angle: f32) -> (f32, f32) {
    #[cfg(target_arch = "avr")]
    // SAFETY: pure functions of their argument (avr-libc libm).
    return unsafe { (avr_libm::sin(angle), avr_libm::cos(angle)) };
    #[cfg(not(target_arch = "avr"))]
    sin_cos_series(angle)
}

#[cfg_attr(target_arch = "avr", allow(dead_code))]
fn sin_cos_series(angle: f32) -> (f32, f32) {
    // Reduce to r in [−π/4, π/4] and a quadrant.
    let turns = angle * (2.0 / PI);
    let quadrant = round_to_i32(turns);
    let r = (angle - quadrant as f32 * HALF_PI) - quadrant as f32 * HALF_PI_LOW;
    let r2 = r * r;
    // Taylor series; at |r| = π/4 the first omitted terms are below 4·10⁻⁹.
    let sin_r = r * (1.0 - r2 / 6.0 * (1.0 - r2 / 20.0 * (1.0 - r2 / 42.0 * (1.0 - r2 / 72.0))));
    let cos_r = 1.0 - r2 / 2.0 * (1.0 - r2 / 12.0 * (1.0 - r2 / 30.0 * (1.0 - r2 / 56.0 * (1.0 - r2 / 90.0))));
    match quadrant & 3 {
        0 => (sin_r, cos_r),
        1 => (cos_r, -sin_r),
        2 => (-sin_r, -cos_r),
        _ => (-cos_r, sin_r),
    }
}

/// π/2 − (π/2 rounded to f32): keeps the reduction exact to a few ulp.
const HALF_PI_LOW: f32 = -4.371_139e-8;

/// Round half away from zero, saturating at the `i32` range (NaN → 0):
/// `f32::round` then `as i32`, exactly (the tests compare them).
///
/// Integer work on the float's bits: `value ± 0.5` then a truncating cast
/// was four soft-float calls on the AVR for every step count, and wrong
/// for the float just below ½ (0.49999997 + 0.5 rounds to 1.0; C's
/// `lroundf`, which Marlin uses, gives 0).
#[inline(never)]
pub fn round_to_i32(value: f32) -> i32 {
    signed(value, magnitude(value, true))
}

/// `value as u32` (truncating towards zero, saturating, NaN → 0), from the
/// float's bits: the saturating cast was four soft-float calls on the AVR.
#[inline(never)]
pub fn to_u32(value: f32) -> u32 {
    if value.is_sign_negative() {
        return 0;
    }
    match magnitude(value, false) {
        Magnitude::Exact(m) => m,
        Magnitude::Huge => u32::MAX,
        Magnitude::NotANumber => 0,
    }
}

/// `value as i32` (truncating, saturating, NaN → 0), as [`to_u32`].
#[inline(never)]
pub fn to_i32(value: f32) -> i32 {
    signed(value, magnitude(value, false))
}

/// |value| as an integer, truncated or rounded half away from zero.
enum Magnitude {
    Exact(u32),
    /// 2³² or more (or infinite).
    Huge,
    NotANumber,
}

/// An f32 is `mantissa · 2^(exponent − 150)` with the implicit 24th bit:
/// truncating is a right shift, rounding half away from zero adds half of
/// the last bit kept first (exact: the sum fits in 25 bits).
fn magnitude(value: f32, round: bool) -> Magnitude {
    let bits = value.to_bits();
    let exponent = (bits >> 23) as u8;
    if exponent == 0xFF {
        return if bits & 0x7F_FFFF != 0 { Magnitude::NotANumber } else { Magnitude::Huge };
    }
    // Below ½ everything (zero, subnormals) is 0; below 1 it truncates to 0.
    if exponent < if round { 126 } else { 127 } {
        return Magnitude::Exact(0);
    }
    let mantissa = bits & 0x7F_FFFF | 0x80_0000;
    if exponent <= 150 {
        let shift = 150 - exponent;
        if round && shift > 0 {
            // Keep one bit more, add it, drop it: + ½ of the last bit kept.
            Magnitude::Exact((shift_right(mantissa, shift - 1) + 1) >> 1)
        } else {
            Magnitude::Exact(shift_right(mantissa, shift))
        }
    } else if exponent < 159 {
        // (`exponent` 158: the mantissa shifted by 8, below 2³².)
        Magnitude::Exact(mantissa << (exponent - 150))
    } else {
        Magnitude::Huge
    }
}

/// `value >> shift` (shift ≤ 24): whole bytes first, which the AVR moves
/// in one instruction each, then at most 7 single-bit shifts (a variable
/// 32-bit shift is a loop of `shift` rounds of four instructions).
fn shift_right(value: u32, shift: u8) -> u32 {
    let (mut value, mut shift) = (value, shift);
    if shift >= 16 {
        value >>= 16;
        shift -= 16;
    }
    if shift >= 8 {
        value >>= 8;
        shift -= 8;
    }
    value >> shift
}

/// Apply `value`'s sign to its magnitude, saturating at the `i32` range.
fn signed(value: f32, magnitude: Magnitude) -> i32 {
    let negative = value.is_sign_negative();
    match magnitude {
        Magnitude::Exact(m) if m <= i32::MAX as u32 => {
            if negative {
                -(m as i32)
            } else {
                m as i32
            }
        }
        Magnitude::NotANumber => 0,
        _ => {
            if negative {
                i32::MIN
            } else {
                i32::MAX
            }
        }
    }
}

/// `value.clamp(min, max)` without its check that `min <= max`, whose
/// panic path cost flash: every caller passes bounds in order (the
/// motion layer's: 0 ≤ events; 0.1 µm < a radius of whole µm).
#[inline(never)]
pub fn clamp(value: f32, min: f32, max: f32) -> f32 {
    let mut value = value;
    if value < min {
        value = min;
    }
    if value > max {
        value = max;
    }
    value
}

/// The larger of `value` and `floor`. `f32::max` compiles to
/// compiler-builtins' `fmaximum_num` (142 bytes on the AVR, with its own
/// NaN and signed-zero handling, ≈ 150 cycles a call); one soft-float
/// comparison does here. A NaN `value` gives `floor`, as `f32::max` does;
/// `floor` is never NaN at our call sites (a constant or a finite speed).
#[inline(never)]
pub fn max(value: f32, floor: f32) -> f32 {
    if value > floor {
        value
    } else {
        floor
    }
}

/// The smaller of `value` and `ceiling`; [`max`]'s twin (`f32::min` is
/// compiler-builtins' `fminimum_num`). A NaN `value` gives `ceiling`.
#[inline(never)]
pub fn min(value: f32, ceiling: f32) -> f32 {
    if value < ceiling {
        value
    } else {
        ceiling
    }
}

/// |value| without `std`: the sign bit cleared (`f32::abs` of `core`),
/// no soft-float comparison. (−0.0 gives +0.0, which compares equal.)
pub fn abs(value: f32) -> f32 {
    value.abs()
}

/// Degrees to radians.
pub fn radians(degrees: f32) -> f32 {
    degrees * (PI / 180.0)
}

/// Radians to degrees.
pub fn degrees(radians: f32) -> f32 {
    radians * (180.0 / PI)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_and_min_agree_with_core_and_a_nan_value_gives_the_bound() {
        for (a, b) in [(1.0, 2.0), (2.0, 1.0), (-3.5, 0.0), (0.0, 0.0), (1.0e7, 1.0e6)] {
            assert_eq!((max(a, b), min(a, b)), (f32::max(a, b), f32::min(a, b)));
        }
        assert_eq!((max(f32::NAN, 0.0), min(f32::NAN, 1.0e6)), (0.0, 1.0e6));
    }

    /// Every float class, every exponent, the neighbours of every
    /// half-integer near zero: the bit versions agree with `f32::round` and
    /// Rust's saturating casts exactly.
    #[test]
    fn conversions_from_bits_agree_with_the_casts() {
        let mut values = std::vec![0.0_f32, -0.0, 0.5, -0.5, 1.5, -2.5, 0.49999997, -0.49999997, 0.50000006,
            8_388_607.5, 8_388_608.0, 16_777_217.0, 2_147_483_520.0, 2_147_483_648.0, -2_147_483_648.0,
            4_294_967_040.0, 4_294_967_296.0, 1.0e20, -1.0e20, f32::MAX, f32::MIN, f32::INFINITY,
            f32::NEG_INFINITY, f32::NAN, -f32::NAN, f32::MIN_POSITIVE, 1.0e-40];
        for k in -40..40 {
            let half = k as f32 + 0.5;
            values.extend([half, f32::from_bits(half.to_bits() - 1), f32::from_bits(half.to_bits() + 1), k as f32]);
        }
        let mut x = 1.0e-3_f32;
        while x < 1.0e11 {
            values.extend([x, -x]);
            x *= 1.37;
        }
        for v in values {
            let rounded = if v.is_nan() { 0 } else { v.round() as i32 };
            assert_eq!(round_to_i32(v), rounded, "round_to_i32({v:e})");
            assert_eq!(to_i32(v), v as i32, "to_i32({v:e})");
            assert_eq!(to_u32(v), v as u32, "to_u32({v:e})");
        }
        // The float just below ½ (which `v + 0.5` rounded up to 1).
        assert_eq!(round_to_i32(0.49999997), 0);
    }

    #[test]
    fn sqrt_is_within_two_ulp() {
        let mut x = 1.0e-6_f32;
        while x < 1.0e12 {
            let exact = (x as f64).sqrt();
            let got = sqrt(x) as f64;
            assert!(((got - exact) / exact).abs() < 2.5e-7, "sqrt({x}) = {got}, want {exact}");
            x *= 1.013;
        }
        assert_eq!(sqrt(0.0), 0.0);
        assert_eq!(sqrt(-4.0), 0.0);
        assert_eq!(sqrt(f32::NAN), 0.0);
        assert_eq!(sqrt(-f32::NAN), 0.0);
        assert_eq!(sqrt(-0.0), 0.0);
        assert_eq!(sqrt(f32::NEG_INFINITY), 0.0);
        assert_eq!(sqrt(f32::INFINITY), f32::INFINITY);
        assert!(sqrt(f32::from_bits(1)) > 0.0);
        assert_eq!(sqrt(4.0), 2.0);
        assert_eq!(sqrt(1_000_000.0), 1000.0);
    }

    #[test]
    fn atan2_matches_f64_everywhere() {
        let mut worst = 0.0_f64;
        for i in -200..=200 {
            for j in -200..=200 {
                let (y, x) = (i as f32 * 0.37, j as f32 * 0.53);
                let exact = (y as f64).atan2(x as f64);
                let got = atan2(y, x) as f64;
                worst = worst.max((got - exact).abs());
            }
        }
        assert!(worst < 3.0e-7, "worst atan2 error {worst}");
        assert!((atan(1.0e30) as f64 - core::f64::consts::FRAC_PI_2).abs() < 1e-7);
    }

    #[test]
    fn sin_cos_match_f64() {
        let mut worst = 0.0_f64;
        let mut a = -7.0_f32;
        while a < 7.0 {
            let (s, c) = sin_cos(a);
            worst = worst.max((s as f64 - (a as f64).sin()).abs());
            worst = worst.max((c as f64 - (a as f64).cos()).abs());
            a += 0.0011;
        }
        assert!(worst < 6.0e-7, "worst sin/cos error {worst}");
    }

    #[test]
    fn rounding_is_half_away_from_zero() {
        assert_eq!(round_to_i32(2.5), 3);
        assert_eq!(round_to_i32(-2.5), -3);
        assert_eq!(round_to_i32(-4019.489), -4019);
        assert_eq!(round_to_i32(1e20), i32::MAX);
        assert_eq!(round_to_i32(f32::NAN), 0);
    }
}
