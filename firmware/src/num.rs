//! The numeric abstraction: how the control laws that run in interrupts
//! and fixed-rate ticks multiply.
//!
//! A law is written once, generic over [`LoopArithmetic`]; the board picks
//! the implementation with the `fpu` feature of this crate:
//!
//! - [`FixedPoint`] (default; the Mega 2560): gains in Q16.16, values in
//!   whole units, the integral kept exactly (whole part + 16 fraction
//!   bits). Products use one 32-bit multiply when bound comparisons show it
//!   fits and four 16 × 16-bit products otherwise: no 64-bit arithmetic, no
//!   division, no float — the AVR has no FPU and the standards forbid float
//!   in its interrupts.
//! - [`Float`] (`fpu`; the SKR Pro's Cortex-M4F): gains and the integral in
//!   `f32`, one `vmul`/`vadd` per product and a `vcvt` back to units.
//!
//! Measured, not guessed (one robust-PID tick of
//! [`AxisController`](crate::closed_loop::AxisController), the same gains
//! and inputs, the benches of both boards):
//!
//! | | Q16.16 fixed point | f32 |
//! |---|---|---|
//! | ATmega2560, 16 MHz, cycles (simavr) | **1 741** (109 µs) | 4 584 (soft float, 287 µs) |
//! | Cortex-M4F, instructions (QEMU `-icount`) | 189 | **148** |
//!
//! Bold: the board's choice. `cargo benchmark` prints them
//! (`avr_loop_tick_cycles_fixed`/`_f32`, `arm_loop_tick_instructions_fixed`/`_f32`);
//! `tests/avr-bench/tests/quick_bench.rs` and `tests/tests/emulated_arm.rs`
//! fail if either board's choice stops being the faster one. The benches:
//! `boards/mega2560-ramps/src/bin/loop_bench.rs` (Timer1 counts cycles),
//! `boards/skr-pro/src/bin/step_bench.rs` (TIM2 under `-icount`; DWT on a
//! real board).
//!
//! What is not behind this abstraction, and why: the planner, the segment
//! preparation and the kinematics are `f32` on both boards. They run in the
//! main loop, never in an interrupt, on values that span many decades
//! (steps/s² to mm, squared speeds up to 10⁹): a fixed-point version needs
//! 64-bit products, which the AVR only has as compiler-builtins' generic
//! `__muldi3` (≈ 1 000 cycles), slower than avr-libc's hand-written float
//! multiply (≈ 150). The heater PID is integer on both boards (10 Hz, its
//! cost is immaterial; integers keep `M301` gains exact).

use core::fmt::Debug;

/// A signed Q16.16 fixed-point number (gains, coefficients).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Q16(pub i32);

impl Q16 {
    pub const ZERO: Q16 = Q16(0);
    pub const ONE: Q16 = Q16(1 << 16);

    /// Nearest Q16.16 value; `None` outside ±32767.
    pub fn from_f32(value: f32) -> Option<Q16> {
        let scaled = value * 65536.0;
        if !(scaled > -2_147_418_112.0 && scaled < 2_147_418_112.0) {
            return None;
        }
        // Round half away from zero without libm.
        let rounded = if scaled >= 0.0 { scaled + 0.5 } else { scaled - 0.5 };
        Some(Q16(rounded as i32))
    }

    pub fn to_f32(self) -> f32 {
        self.0 as f32 / 65536.0
    }
}

/// `value × gain`, rounded, saturated to the i32 range.
pub fn mul_q16(value: i32, gain: Q16) -> i32 {
    mul_shift::<16>(value, gain.0)
}

/// |a| × |b| as a 64-bit magnitude `(high word, low word)`, from four
/// 16 × 16 → 32-bit products: on the AVR each is one `__umulhisi3`
/// (≈ 20 cycles), where an `i64` multiply would be compiler-builtins'
/// generic `__muldi3` (≈ 1000).
#[inline]
fn wide_magnitude(a: u32, b: u32) -> (u32, u32) {
    let (a_high, a_low) = (u32::from((a >> 16) as u16), u32::from(a as u16));
    let (b_high, b_low) = (u32::from((b >> 16) as u16), u32::from(b as u16));
    let low_low = a_low * b_low;
    let (middle, middle_carry) = (a_low * b_high).overflowing_add(a_high * b_low);
    let (low, low_carry) = low_low.overflowing_add(middle << 16);
    // The true product is below 2^64, so the high word cannot overflow.
    let high = (a_high * b_high)
        .wrapping_add(middle >> 16)
        .wrapping_add(u32::from(middle_carry) << 16)
        .wrapping_add(u32::from(low_carry));
    (high, low)
}

/// Whether |a| × |b| < 2^31, by bound comparisons only (no multiply, no
/// leading-zero count): the three shapes the loop meets (an error times a
/// gain, a velocity times a decay, a velocity times a step scale).
#[inline(always)]
fn fits_i32(a: u32, b: u32) -> bool {
    (a < 1 << 11 && b < 1 << 20) || (a < 1 << 15 && b < 1 << 16) || (a < 1 << 19 && b < 1 << 12)
}

/// `value × factor / 2^SHIFT` rounded half away from zero, saturated.
/// One 32-bit multiply (libgcc's `__mulsi3`, ≈ 40 cycles on the AVR) when
/// the product provably fits (bound comparisons, never a checked multiply:
/// see the README on `__mulosi4`); otherwise four 16-bit partial products,
/// still no 64-bit arithmetic.
#[inline]
pub fn mul_shift<const SHIFT: u32>(value: i32, factor: i32) -> i32 {
    let half = 1i32 << (SHIFT - 1);
    if fits_i32(value.unsigned_abs(), factor.unsigned_abs()) {
        // |product| < 2^31 and SHIFT ≥ 1, so ± half cannot overflow.
        let product = value * factor;
        return if product >= 0 { (product + half) >> SHIFT } else { -((half - product) >> SHIFT) };
    }
    mul_shift_wide::<SHIFT>(value, factor)
}

#[inline(never)]
fn mul_shift_wide<const SHIFT: u32>(value: i32, factor: i32) -> i32 {
    let half = 1u32 << (SHIFT - 1);
    let negative = (value < 0) != (factor < 0);
    let (high, low) = wide_magnitude(value.unsigned_abs(), factor.unsigned_abs());
    let (low, carry) = low.overflowing_add(half);
    let high = high.wrapping_add(u32::from(carry));
    let magnitude = if high >> SHIFT != 0 { u32::MAX } else { (high << (32 - SHIFT)) | (low >> SHIFT) };
    if negative {
        if magnitude > 1 << 31 {
            i32::MIN
        } else {
            (magnitude as i32).wrapping_neg()
        }
    } else if magnitude > i32::MAX as u32 {
        i32::MAX
    } else {
        magnitude as i32
    }
}

/// `value × factor` in Q16 as (floor of the product / 2^16, the 16
/// fraction bits), saturated: the integral's exact increment.
pub(crate) fn mul_q16_split(value: i32, factor: i32) -> (i32, u16) {
    if fits_i32(value.unsigned_abs(), factor.unsigned_abs()) {
        let product = value * factor;
        // The arithmetic shift is the floor; the low bits are the fraction.
        return (product >> 16, product as u16);
    }
    let negative = (value < 0) != (factor < 0);
    let (high, low) = wide_magnitude(value.unsigned_abs(), factor.unsigned_abs());
    let whole = if high >> 15 != 0 { i32::MAX as u32 } else { (high << 16) | (low >> 16) };
    let fraction = low as u16;
    if !negative {
        (whole as i32, fraction)
    } else if fraction == 0 {
        (-(whole as i32), 0)
    } else {
        (-(whole as i32) - 1, 0u16.wrapping_sub(fraction))
    }
}

/// How a control law multiplies and integrates. Values (errors, positions,
/// velocities, outputs) are whole units in `i32` on both sides of the law;
/// only gains and the integral take the implementation's own format.
pub trait LoopArithmetic: Copy + Debug + PartialEq + 'static {
    /// A gain as the tick stores it.
    type Gain: Copy + Debug + PartialEq;
    /// The integral term's accumulator.
    type Integral: Copy + Debug + PartialEq;
    /// Name for reports and benchmarks.
    const NAME: &'static str;
    const ZERO: Self::Gain;
    const ONE: Self::Gain;
    const EMPTY_INTEGRAL: Self::Integral;

    /// A gain from the main loop's f32 (tuning); `None` if it does not fit.
    fn gain(value: f32) -> Option<Self::Gain>;
    /// The gain's value (reports).
    fn gain_value(gain: Self::Gain) -> f32;
    /// `value × gain`, rounded half away from zero, saturated to `i32`.
    fn scale(value: i32, gain: Self::Gain) -> i32;
    /// `integral += value × gain`, exactly where the format allows.
    fn integrate(integral: &mut Self::Integral, value: i32, gain: Self::Gain);
    /// The integral in whole units (floor), saturated.
    fn whole(integral: Self::Integral) -> i32;
    /// Clamp the integral into ±`limit` (anti-windup's hard bound).
    fn bound(integral: &mut Self::Integral, limit: i32);
}

/// Q16.16 gains, exact integral: the AVR's choice (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FixedPoint;

/// The fixed-point integral: floor in whole units and 16 fraction bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ExactIntegral {
    pub whole: i32,
    pub fraction: u16,
}

impl LoopArithmetic for FixedPoint {
    type Gain = Q16;
    type Integral = ExactIntegral;
    const NAME: &'static str = "Q16.16";
    const ZERO: Q16 = Q16::ZERO;
    const ONE: Q16 = Q16::ONE;
    const EMPTY_INTEGRAL: ExactIntegral = ExactIntegral { whole: 0, fraction: 0 };

    fn gain(value: f32) -> Option<Q16> {
        Q16::from_f32(value)
    }

    fn gain_value(gain: Q16) -> f32 {
        gain.to_f32()
    }

    #[inline]
    fn scale(value: i32, gain: Q16) -> i32 {
        mul_q16(value, gain)
    }

    #[inline]
    fn integrate(integral: &mut ExactIntegral, value: i32, gain: Q16) {
        let (whole, fraction) = mul_q16_split(value, gain.0);
        let (fraction, carry) = integral.fraction.overflowing_add(fraction);
        integral.fraction = fraction;
        integral.whole = integral.whole.saturating_add(whole).saturating_add(i32::from(carry));
    }

    #[inline]
    fn whole(integral: ExactIntegral) -> i32 {
        integral.whole
    }

    #[inline]
    fn bound(integral: &mut ExactIntegral, limit: i32) {
        if integral.whole >= limit {
            *integral = ExactIntegral { whole: limit, fraction: 0 };
        } else if integral.whole < -limit {
            *integral = ExactIntegral { whole: -limit, fraction: 0 };
        }
    }
}

/// `f32` gains and integral: the Cortex-M4F's choice (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Float;

/// Nearest `i32`, half away from zero; saturated (Rust's float → int cast
/// saturates, NaN gives 0).
#[inline]
fn round_to_i32(value: f32) -> i32 {
    (if value >= 0.0 { value + 0.5 } else { value - 0.5 }) as i32
}

impl LoopArithmetic for Float {
    type Gain = f32;
    type Integral = f32;
    const NAME: &'static str = "f32";
    const ZERO: f32 = 0.0;
    const ONE: f32 = 1.0;
    const EMPTY_INTEGRAL: f32 = 0.0;

    /// Any finite value (the same gains as fixed point and more).
    fn gain(value: f32) -> Option<f32> {
        value.is_finite().then_some(value)
    }

    fn gain_value(gain: f32) -> f32 {
        gain
    }

    #[inline]
    fn scale(value: i32, gain: f32) -> i32 {
        round_to_i32(value as f32 * gain)
    }

    #[inline]
    fn integrate(integral: &mut f32, value: i32, gain: f32) {
        *integral += value as f32 * gain;
    }

    #[inline]
    fn whole(integral: f32) -> i32 {
        let truncated = integral as i32;
        if (truncated as f32) > integral {
            truncated - 1
        } else {
            truncated
        }
    }

    #[inline]
    fn bound(integral: &mut f32, limit: i32) {
        let limit = limit as f32;
        if *integral >= limit {
            *integral = limit;
        } else if *integral < -limit {
            *integral = -limit;
        }
    }
}

/// The board's choice: [`Float`] with the `fpu` feature, else [`FixedPoint`].
#[cfg(feature = "fpu")]
pub type Native = Float;
/// The board's choice: [`Float`] with the `fpu` feature, else [`FixedPoint`].
#[cfg(not(feature = "fpu"))]
pub type Native = FixedPoint;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mul_q16_rounds_and_saturates() {
        assert_eq!(mul_q16(1000, Q16::from_f32(4.3).unwrap()), 4300);
        assert_eq!(mul_q16(-1000, Q16::from_f32(4.3).unwrap()), -4300);
        assert_eq!(mul_q16(3, Q16(1 << 15)), 2); // 1.5 rounds up
        assert_eq!(mul_q16(1_000_000, Q16::from_f32(5.0).unwrap()), 5_000_000);
        assert_eq!(mul_q16(i32::MAX, Q16::from_f32(100.0).unwrap()), i32::MAX);
        assert_eq!(mul_q16(i32::MIN, Q16::from_f32(100.0).unwrap()), i32::MIN);
        assert_eq!(mul_shift::<8>(10_240, 3200), 128_000);
        assert_eq!(mul_shift::<8>(-10_240, 3200), -128_000);
    }

    #[test]
    fn the_wide_multiply_agrees_with_64_bit_arithmetic() {
        let values = [0i32, 1, -1, 2047, -2048, 65_535, 65_536, -65_537, 1 << 20, -(1 << 23) + 3, 123_456_789, i32::MAX, i32::MIN];
        for &a in &values {
            for &b in &values {
                let exact = i64::from(a) * i64::from(b);
                let rounded = if exact >= 0 { (exact + (1 << 15)) >> 16 } else { -((-exact + (1 << 15)) >> 16) };
                let expected = rounded.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32;
                assert_eq!(mul_shift::<16>(a, b), expected, "{a} × {b}");
                if exact.abs() < (1i64 << 46) {
                    let (whole, fraction) = mul_q16_split(a, b);
                    assert_eq!(i64::from(whole) * 65_536 + i64::from(fraction), exact, "{a} × {b}");
                }
            }
        }
    }

    #[test]
    fn q16_from_f32_rejects_out_of_range_and_nan() {
        assert_eq!(Q16::from_f32(1.0), Some(Q16::ONE));
        assert_eq!(Q16::from_f32(40000.0), None);
        assert_eq!(Q16::from_f32(f32::NAN), None);
    }

    /// Both implementations scale the same way where both are exact.
    fn scales_like_the_spec<A: LoopArithmetic>() {
        let gain = A::gain(4.3).unwrap();
        assert_eq!(A::scale(1000, gain), 4300, "{}", A::NAME);
        assert_eq!(A::scale(-1000, gain), -4300, "{}", A::NAME);
        assert_eq!(A::scale(3, A::gain(0.5).unwrap()), 2, "{}: 1.5 rounds away from zero", A::NAME);
        assert_eq!(A::scale(-3, A::gain(0.5).unwrap()), -2, "{}", A::NAME);
        assert_eq!(A::scale(i32::MAX, A::gain(100.0).unwrap()), i32::MAX, "{}: saturates", A::NAME);
        assert_eq!(A::scale(i32::MIN, A::gain(100.0).unwrap()), i32::MIN, "{}: saturates", A::NAME);
    }

    fn integrates_and_floors<A: LoopArithmetic>() {
        let mut integral = A::EMPTY_INTEGRAL;
        let quarter = A::gain(0.25).unwrap();
        for _ in 0..7 {
            A::integrate(&mut integral, 1, quarter);
        }
        assert_eq!(A::whole(integral), 1, "{}: 1.75 floors to 1", A::NAME);
        for _ in 0..14 {
            A::integrate(&mut integral, -1, quarter);
        }
        assert_eq!(A::whole(integral), -2, "{}: -1.75 floors to -2", A::NAME);
        A::bound(&mut integral, 1);
        assert_eq!(A::whole(integral), -1, "{}: bounded to -1", A::NAME);
    }

    #[test]
    fn fixed_point_and_float_scale_alike() {
        scales_like_the_spec::<FixedPoint>();
        scales_like_the_spec::<Float>();
    }

    #[test]
    fn fixed_point_and_float_integrate_alike() {
        integrates_and_floors::<FixedPoint>();
        integrates_and_floors::<Float>();
    }

    #[test]
    fn float_refuses_only_non_finite_gains() {
        assert_eq!(Float::gain(40_000.0), Some(40_000.0));
        assert_eq!(Float::gain(f32::NAN), None);
        assert_eq!(Float::gain(f32::INFINITY), None);
        assert_eq!(FixedPoint::gain(40_000.0), None);
    }
}
