//! The per-axis position loop that runs in the fixed-rate tick.
//!
//! One control law covers every strategy (SPEC §1 and §5); a strategy is
//! only a choice of gains ([`FixedGains`], built by
//! [`tuning`](super::tuning) in the main loop):
//!
//! ```text
//! e = xd − x
//! u = Kff·vd  +  Kp·e  +  I  +  D          clamped to ±output_limit
//! I += Ki·T·e            (not while u is saturated in e's direction)
//! D = Kd·s/(1 + Tf·s) applied to e (printer) or to −x (DC servo, SPEC §5)
//! ```
//!
//! - open loop: Kff = 1, no feedback (the step generator integrates vd:
//!   step counting only);
//! - P + feedforward: Kff = 1, Kp (3.0, 4.0, 4.3, 5.0 in the thesis);
//! - robust PID (Normey-Rico): Kff = 1, proportional K0 + Kp, Ki = Kp/Ti,
//!   Kd = Kp·Td, filter Tf. **Ours**: K0 acts on the error, not on x, and
//!   the PID has the ẋd feedforward. Both give exactly the closed-loop poles
//!   of Normey-Rico's design (the characteristic equation
//!   1 + P·(K0 + C) = 0 is the same whether K0 feeds back x or e), but with
//!   K0 on x and no feedforward the reference path has to push the whole
//!   velocity through the integrator: on the 5 mm/s circle (ω = 0.5 rad/s,
//!   k' 0.9, θ 0.1 s, γ 0.5) the steady error amplitude is, in continuous
//!   time, |1 + P·K0| / |1 + P·(K0 + C)| × 10 mm ≈ 1.46 mm, against
//!   |1 − k'·e^(−jωθ)| / |1 + P·(K0 + C)| × 10 mm ≈ 0.018 mm with K0 on
//!   the error and the feedforward;
//! - DC servo PID (SPEC §5): Kff = 0 (or a velocity feedforward), derivative
//!   on the measurement, output in duty units.
//!
//! Units: positions in [`Units`] (1/2048 mm for the NSE-5310,
//! counts for a quadrature axis), velocities in units/s, the output in
//! units/s (stepper axes: turn it into a step rate with
//! [`StepperScale`](super::output::StepperScale)) or duty (servo axes).
//!
//! Fixed point: gains are Q16.16 ([`Q16`]); the integral is kept exactly
//! (whole units/s + 16 fraction bits: tiny errors still integrate, nothing
//! is rounded away); products go through [`mul_q16`], which uses one 32-bit
//! multiply when bound comparisons show the product fits (an error under
//! 1 mm times a gain under 16, a velocity under 16 mm/s times a decay, …)
//! and four 16 × 16-bit products otherwise. No 64-bit arithmetic, no
//! division, no float, no checked multiply in the tick.

use super::nse5310::EncoderFault;
use super::{AxisFault, Units};

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
fn mul_q16_split(value: i32, factor: i32) -> (i32, u16) {
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

/// What the derivative acts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DerivativeOn {
    /// d(xd − x)/dt: the printer's PID (with ẋd feedforward the reference
    /// path keeps the phase lead the tuning assumed).
    Error,
    /// −dx/dt: no kick on set-point steps (SPEC §5's servo PID).
    Measurement,
}

/// Gains for one sample period, in fixed point. Built in the main loop by
/// [`tuning`](super::tuning); the tick only multiplies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FixedGains {
    /// On the reference velocity (1: the step generator follows vd).
    pub feedforward: Q16,
    /// On the error, 1/s (K0 + Kp for the robust PID).
    pub proportional: Q16,
    /// Ki·T: added to the integral per tick per unit of error, 1/s.
    pub integral_per_tick: Q16,
    /// Kd/(Tf + T), 1/s per unit of change per tick.
    pub derivative: Q16,
    /// Tf/(Tf + T): how much of the derivative term survives a tick.
    pub derivative_decay: Q16,
    pub derivative_on: DerivativeOn,
}

impl FixedGains {
    /// Open loop: the velocity command is the reference velocity.
    pub const OPEN_LOOP: FixedGains = FixedGains {
        feedforward: Q16::ONE,
        proportional: Q16::ZERO,
        integral_per_tick: Q16::ZERO,
        derivative: Q16::ZERO,
        derivative_decay: Q16::ZERO,
        derivative_on: DerivativeOn::Error,
    };
}

/// Following-error supervision: a fault when |xd − x| stays above `limit`
/// for more than `hold_ticks` ticks in a row, or exceeds `4 × limit` at once.
///
/// The hold lets a closed loop recover from a short disturbance (a belt
/// that jumped a tooth is back within ≈ 0.3 s) while a position that stays
/// wrong (open loop after a slip, a jammed axis, lost steps) is caught.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FollowingErrorLimit {
    /// Units (1/2048 mm on the printer).
    pub limit: Units,
    pub hold_ticks: u16,
}

impl FollowingErrorLimit {
    /// 1 mm held for 0.5 s at the given loop rate.
    pub const fn printer_default(loop_hz: u16) -> Self {
        Self { limit: super::nse5310::UNITS_PER_MM, hold_ticks: loop_hz / 2 }
    }
}

/// One axis' loop state and gains (≤ 64 bytes on the host, see the tests).
#[derive(Clone, Copy, Debug)]
pub struct AxisController {
    gains: FixedGains,
    /// |u| never exceeds this (units/s or duty).
    output_limit: i32,
    following: FollowingErrorLimit,
    over_limit_ticks: u16,
    /// The integral, units/s: whole part (floor) and 16 fraction bits, the
    /// exact sum of (Ki·T in Q16) × error.
    integral: i32,
    integral_fraction: u16,
    derivative: i32,
    previous_signal: i32,
    primed: bool,
    fault: Option<AxisFault>,
}

/// The reference for one tick: where the axis should be now, and the
/// velocity to feed forward (the planner's velocity, possibly taken a
/// preview time ahead: see [`ReferencePath`](super::reference::ReferencePath)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Reference {
    pub position: Units,
    /// Units per second.
    pub velocity: i32,
}

/// What the tick measured besides the position.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DriverStatus {
    /// A driver ALARM input (SPEC §3) is active (polarity already applied).
    pub alarm: bool,
    /// The H-bridge's EN/DIAG line reports a fault (SPEC §5).
    pub bridge_fault: bool,
}

impl AxisController {
    /// `output_limit`: the largest |u| (e.g. the axis' max speed in units/s,
    /// or the PWM's max duty); at most 2^23.
    pub const fn new(gains: FixedGains, output_limit: i32, following: FollowingErrorLimit) -> Self {
        let output_limit = if output_limit > (1 << 23) - 1 {
            (1 << 23) - 1
        } else if output_limit < 0 {
            0
        } else {
            output_limit
        };
        Self {
            gains,
            output_limit,
            following,
            over_limit_ticks: 0,
            integral: 0,
            integral_fraction: 0,
            derivative: 0,
            previous_signal: 0,
            primed: false,
            fault: None,
        }
    }

    /// One loop sample: returns the command (units/s or duty, within
    /// ±output_limit), or the latched fault (the axis must then stop: zero
    /// step rate, or brake).
    pub fn tick(&mut self, reference: Reference, measured: Result<Units, EncoderFault>, driver: DriverStatus) -> Result<i32, AxisFault> {
        if let Some(fault) = self.fault {
            return Err(fault);
        }
        if driver.alarm {
            return Err(self.latch(AxisFault::DriverAlarm));
        }
        if driver.bridge_fault {
            return Err(self.latch(AxisFault::BridgeFault));
        }
        let measured = match measured {
            Ok(position) => position,
            Err(fault) => return Err(self.latch(AxisFault::Encoder(fault))),
        };
        let error = reference.position.saturating_sub(measured);
        if error.unsigned_abs() > self.following.limit.unsigned_abs() {
            self.over_limit_ticks = self.over_limit_ticks.saturating_add(1);
            if self.over_limit_ticks > self.following.hold_ticks
                || error.unsigned_abs() / 4 > self.following.limit.unsigned_abs()
            {
                return Err(self.latch(AxisFault::FollowingError { error }));
            }
        } else {
            self.over_limit_ticks = 0;
        }

        // Field by field: copying `self.gains` costs a memcpy on the AVR.
        let signal = match self.gains.derivative_on {
            DerivativeOn::Error => error,
            DerivativeOn::Measurement => measured.saturating_neg(),
        };
        if !self.primed {
            self.previous_signal = signal;
            self.primed = true;
        }
        if self.gains.derivative.0 != 0 {
            let change = signal.saturating_sub(self.previous_signal);
            self.derivative =
                mul_q16(self.derivative, self.gains.derivative_decay).saturating_add(mul_q16(change, self.gains.derivative));
        }
        self.previous_signal = signal;

        let mut known = self.derivative;
        if self.gains.proportional.0 != 0 {
            known = known.saturating_add(mul_q16(error, self.gains.proportional));
        }
        let feedforward = self.gains.feedforward;
        if feedforward == Q16::ONE {
            known = known.saturating_add(reference.velocity);
        } else if feedforward.0 != 0 {
            known = known.saturating_add(mul_q16(reference.velocity, feedforward));
        }
        let integral_gain = self.gains.integral_per_tick.0;
        if integral_gain != 0 {
            let before = known.saturating_add(self.integral);
            let pushing_up = before >= self.output_limit && error > 0;
            let pushing_down = before <= -self.output_limit && error < 0;
            if !pushing_up && !pushing_down {
                let (whole, fraction) = mul_q16_split(error, integral_gain);
                let (fraction, carry) = self.integral_fraction.overflowing_add(fraction);
                self.integral_fraction = fraction;
                self.integral = self.integral.saturating_add(whole).saturating_add(i32::from(carry));
                if self.integral >= self.output_limit {
                    self.integral = self.output_limit;
                    self.integral_fraction = 0;
                } else if self.integral < -self.output_limit {
                    self.integral = -self.output_limit;
                    self.integral_fraction = 0;
                }
            }
        }
        let output = known.saturating_add(self.integral);
        // Not `clamp`: it carries a panic path for min > max.
        Ok(if output > self.output_limit {
            self.output_limit
        } else if output < -self.output_limit {
            -self.output_limit
        } else {
            output
        })
    }

    fn latch(&mut self, fault: AxisFault) -> AxisFault {
        self.fault = Some(fault);
        fault
    }

    /// Stop the axis from outside (another axis faulted, M112, M410).
    pub fn stop(&mut self, fault: AxisFault) {
        self.fault.get_or_insert(fault);
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<AxisFault> {
        self.fault
    }

    /// Clear a fault and the loop's memory (after re-homing, or `M820`
    /// enabling the loop again). The integral and derivative start at zero.
    pub fn reset(&mut self) {
        self.fault = None;
        self.over_limit_ticks = 0;
        self.integral = 0;
        self.integral_fraction = 0;
        self.derivative = 0;
        self.primed = false;
    }

    /// Switch strategy or gains (from the main loop, inside a critical
    /// section on the AVR). Resets the loop's memory.
    pub fn set_gains(&mut self, gains: FixedGains) {
        self.gains = gains;
        self.integral = 0;
        self.integral_fraction = 0;
        self.derivative = 0;
        self.primed = false;
    }

    pub fn gains(&self) -> FixedGains {
        self.gains
    }

    pub fn set_following_error(&mut self, following: FollowingErrorLimit) {
        self.following = following;
    }

    pub fn following_error(&self) -> FollowingErrorLimit {
        self.following
    }

    pub fn output_limit(&self) -> i32 {
        self.output_limit
    }

    /// The integral term, units/s (for reports and tests).
    pub fn integral(&self) -> i32 {
        self.integral
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FOLLOW: FollowingErrorLimit = FollowingErrorLimit { limit: 2048, hold_ticks: 10 };

    fn gains(kp: f32, ki_tick: f32, kd: f32, decay: f32, on: DerivativeOn) -> FixedGains {
        FixedGains {
            feedforward: Q16::ONE,
            proportional: Q16::from_f32(kp).unwrap(),
            integral_per_tick: Q16::from_f32(ki_tick).unwrap(),
            derivative: Q16::from_f32(kd).unwrap(),
            derivative_decay: Q16::from_f32(decay).unwrap(),
            derivative_on: on,
        }
    }

    fn at(position: i32, velocity: i32) -> Reference {
        Reference { position, velocity }
    }

    const OK: DriverStatus = DriverStatus { alarm: false, bridge_fault: false };

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

    #[test]
    fn open_loop_commands_the_reference_velocity_only() {
        let mut c = AxisController::new(FixedGains::OPEN_LOOP, 409_600, FOLLOW);
        assert_eq!(c.tick(at(100, 10_240), Ok(0), OK), Ok(10_240));
        assert_eq!(c.tick(at(100, -10_240), Ok(50), OK), Ok(-10_240));
    }

    #[test]
    fn p_plus_feedforward_is_velocity_plus_kp_times_error() {
        let mut c = AxisController::new(gains(4.3, 0.0, 0.0, 0.0, DerivativeOn::Error), 409_600, FOLLOW);
        // xd − x = 1000 units, vd = 10240 units/s (5 mm/s): u = 10240 + 4300
        assert_eq!(c.tick(at(1000, 10_240), Ok(0), OK), Ok(14_540));
    }

    #[test]
    fn output_saturates_at_the_limit() {
        let mut c = AxisController::new(gains(5.0, 0.0, 0.0, 0.0, DerivativeOn::Error), 1000, FOLLOW);
        assert_eq!(c.tick(at(1000, 0), Ok(0), OK), Ok(1000));
        assert_eq!(c.tick(at(-1000, 0), Ok(0), OK), Ok(-1000));
    }

    #[test]
    fn integral_accumulates_ki_t_times_error_each_tick() {
        let mut c = AxisController::new(gains(0.0, 0.5, 0.0, 0.0, DerivativeOn::Error), 100_000, FOLLOW);
        assert_eq!(c.tick(at(100, 0), Ok(0), OK), Ok(50));
        assert_eq!(c.tick(at(100, 0), Ok(0), OK), Ok(100));
        assert_eq!(c.integral(), 100);
    }

    #[test]
    fn integral_stops_growing_while_the_output_is_saturated_anti_windup() {
        let mut c = AxisController::new(gains(1.0, 0.5, 0.0, 0.0, DerivativeOn::Error), 1000, FOLLOW);
        for _ in 0..1000 {
            assert_eq!(c.tick(at(2000, 0), Ok(0), OK), Ok(1000));
        }
        // P alone saturates: nothing was integrated
        assert_eq!(c.integral(), 0);
        // error reverses: the output leaves saturation at once
        assert_eq!(c.tick(at(0, 0), Ok(100), OK), Ok(-150));
    }

    #[test]
    fn small_errors_still_integrate_exactly() {
        // Ki·T = 0.01: one unit of error adds 0.01 units/s per tick.
        let mut c = AxisController::new(gains(0.0, 0.01, 0.0, 0.0, DerivativeOn::Error), 100_000, FOLLOW);
        for _ in 0..1000 {
            c.tick(at(1, 0), Ok(0), OK).unwrap();
        }
        // 1000 × round(0.01 × 65536) / 65536 = 9.99 → 9 whole units/s
        assert_eq!(c.integral(), 9);
    }

    #[test]
    fn derivative_on_error_filters_a_ramp_to_kd_times_slope() {
        // Kd/(Tf+T) = 1, decay 0.5: a ramp of 10 units per tick converges
        // to 10 / (1 − 0.5) = 20.
        let mut c = AxisController::new(gains(0.0, 0.0, 1.0, 0.5, DerivativeOn::Error), 100_000, FOLLOW);
        let mut out = 0;
        for k in 0..40 {
            out = c.tick(at(10 * k, 0), Ok(0), OK).unwrap();
        }
        assert_eq!(out, 20);
    }

    #[test]
    fn derivative_on_measurement_ignores_reference_steps() {
        let mut c = AxisController::new(gains(0.0, 0.0, 1.0, 0.5, DerivativeOn::Measurement), 100_000, FOLLOW);
        c.tick(at(0, 0), Ok(0), OK).unwrap();
        assert_eq!(c.tick(at(1000, 0), Ok(0), OK), Ok(0));
        // the axis moving up by 10 brakes
        assert_eq!(c.tick(at(1000, 0), Ok(10), OK), Ok(-10));
    }

    #[test]
    fn following_error_above_limit_for_longer_than_hold_is_a_fault() {
        let mut c = AxisController::new(gains(1.0, 0.0, 0.0, 0.0, DerivativeOn::Error), 100_000, FOLLOW);
        for _ in 0..10 {
            assert!(c.tick(at(3000, 0), Ok(0), OK).is_ok());
        }
        assert_eq!(c.tick(at(3000, 0), Ok(0), OK), Err(AxisFault::FollowingError { error: 3000 }));
        // latched: stays stopped until reset
        assert_eq!(c.tick(at(0, 0), Ok(0), OK), Err(AxisFault::FollowingError { error: 3000 }));
        c.reset();
        assert!(c.tick(at(0, 0), Ok(0), OK).is_ok());
    }

    #[test]
    fn a_short_excursion_above_the_limit_recovers_without_fault() {
        let mut c = AxisController::new(gains(1.0, 0.0, 0.0, 0.0, DerivativeOn::Error), 100_000, FOLLOW);
        for _ in 0..10 {
            assert!(c.tick(at(3000, 0), Ok(0), OK).is_ok());
        }
        assert!(c.tick(at(3000, 0), Ok(2500), OK).is_ok());
        for _ in 0..10 {
            assert!(c.tick(at(3000, 0), Ok(0), OK).is_ok());
        }
    }

    #[test]
    fn an_error_over_four_times_the_limit_is_a_fault_at_once() {
        let mut c = AxisController::new(FixedGains::OPEN_LOOP, 100_000, FOLLOW);
        assert_eq!(c.tick(at(4 * 2048 + 4, 0), Ok(0), OK), Err(AxisFault::FollowingError { error: 8196 }));
    }

    #[test]
    fn driver_alarm_bridge_fault_and_encoder_fault_stop_the_axis() {
        let mut c = AxisController::new(FixedGains::OPEN_LOOP, 100_000, FOLLOW);
        assert_eq!(c.tick(at(0, 0), Ok(0), DriverStatus { alarm: true, bridge_fault: false }), Err(AxisFault::DriverAlarm));
        let mut c = AxisController::new(FixedGains::OPEN_LOOP, 100_000, FOLLOW);
        assert_eq!(c.tick(at(0, 0), Ok(0), DriverStatus { alarm: false, bridge_fault: true }), Err(AxisFault::BridgeFault));
        let mut c = AxisController::new(FixedGains::OPEN_LOOP, 100_000, FOLLOW);
        assert_eq!(c.tick(at(0, 0), Err(EncoderFault::Stuck), OK), Err(AxisFault::Encoder(EncoderFault::Stuck)));
    }

    #[test]
    fn the_loop_state_is_small() {
        assert!(core::mem::size_of::<AxisController>() <= 64, "{}", core::mem::size_of::<AxisController>());
    }
}
