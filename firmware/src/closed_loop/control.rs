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
//! Arithmetic: the law is generic over [`LoopArithmetic`] ([`crate::num`]):
//! f32 on a board with an FPU, fixed point otherwise (the AVR). In fixed
//! point, gains are Q16.16 ([`Q16`]); the integral is kept exactly
//! (whole units/s + 16 fraction bits: tiny errors still integrate, nothing
//! is rounded away); products go through [`mul_q16`], which uses one 32-bit
//! multiply when bound comparisons show the product fits (an error under
//! 1 mm times a gain under 16, a velocity under 16 mm/s times a decay, …)
//! and four 16 × 16-bit products otherwise. No 64-bit arithmetic, no
//! division, no float, no checked multiply in the tick.

use super::nse5310::EncoderFault;
use super::{AxisFault, Units};
use crate::num::{LoopArithmetic, Native};
pub use crate::num::{mul_q16, mul_shift, Q16};

/// What the derivative acts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DerivativeOn {
    /// d(xd − x)/dt: the printer's PID (with ẋd feedforward the reference
    /// path keeps the phase lead the tuning assumed).
    Error,
    /// −dx/dt: no kick on set-point steps (SPEC §5's servo PID).
    Measurement,
}

/// Gains for one sample period, in the law's arithmetic `A` (Q16.16 or
/// f32, see [`crate::num`]). Built in the main loop by
/// [`tuning`](super::tuning); the tick only multiplies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopGains<A: LoopArithmetic = Native> {
    /// On the reference velocity (1: the step generator follows vd).
    pub feedforward: A::Gain,
    /// On the error, 1/s (K0 + Kp for the robust PID).
    pub proportional: A::Gain,
    /// Ki·T: added to the integral per tick per unit of error, 1/s.
    pub integral_per_tick: A::Gain,
    /// Kd/(Tf + T), 1/s per unit of change per tick.
    pub derivative: A::Gain,
    /// Tf/(Tf + T): how much of the derivative term survives a tick.
    pub derivative_decay: A::Gain,
    pub derivative_on: DerivativeOn,
}

/// The gains in fixed point (what the AVR runs, whatever the board).
pub type FixedGains = LoopGains<crate::num::FixedPoint>;

impl<A: LoopArithmetic> LoopGains<A> {
    /// Open loop: the velocity command is the reference velocity.
    pub const OPEN_LOOP: Self = LoopGains {
        feedforward: A::ONE,
        proportional: A::ZERO,
        integral_per_tick: A::ZERO,
        derivative: A::ZERO,
        derivative_decay: A::ZERO,
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
pub struct AxisController<A: LoopArithmetic = Native> {
    gains: LoopGains<A>,
    /// |u| never exceeds this (units/s or duty).
    output_limit: i32,
    following: FollowingErrorLimit,
    over_limit_ticks: u16,
    /// The integral, units/s (fixed point: whole part and 16 fraction
    /// bits, the exact sum of (Ki·T in Q16) × error).
    integral: A::Integral,
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

impl<A: LoopArithmetic> AxisController<A> {
    /// `output_limit`: the largest |u| (e.g. the axis' max speed in units/s,
    /// or the PWM's max duty); at most 2^23.
    pub const fn new(gains: LoopGains<A>, output_limit: i32, following: FollowingErrorLimit) -> Self {
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
            integral: A::EMPTY_INTEGRAL,
            derivative: 0,
            previous_signal: 0,
            primed: false,
            fault: None,
        }
    }

    /// One loop sample: returns the command (units/s or duty, within
    /// ±output_limit), or the latched fault (the axis must then stop: zero
    /// step rate, or brake).
    #[inline(never)]
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
        if self.gains.derivative != A::ZERO {
            let change = signal.saturating_sub(self.previous_signal);
            self.derivative =
                A::scale(self.derivative, self.gains.derivative_decay).saturating_add(A::scale(change, self.gains.derivative));
        }
        self.previous_signal = signal;

        let mut known = self.derivative;
        if self.gains.proportional != A::ZERO {
            known = known.saturating_add(A::scale(error, self.gains.proportional));
        }
        let feedforward = self.gains.feedforward;
        if feedforward == A::ONE {
            known = known.saturating_add(reference.velocity);
        } else if feedforward != A::ZERO {
            known = known.saturating_add(A::scale(reference.velocity, feedforward));
        }
        let integral_gain = self.gains.integral_per_tick;
        if integral_gain != A::ZERO {
            let before = known.saturating_add(A::whole(self.integral));
            let pushing_up = before >= self.output_limit && error > 0;
            let pushing_down = before <= -self.output_limit && error < 0;
            if !pushing_up && !pushing_down {
                A::integrate(&mut self.integral, error, integral_gain);
                A::bound(&mut self.integral, self.output_limit);
            }
        }
        let output = known.saturating_add(A::whole(self.integral));
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
        self.integral = A::EMPTY_INTEGRAL;
        self.derivative = 0;
        self.primed = false;
    }

    /// Switch strategy or gains (from the main loop, inside a critical
    /// section on the AVR). Resets the loop's memory.
    pub fn set_gains(&mut self, gains: LoopGains<A>) {
        self.gains = gains;
        self.integral = A::EMPTY_INTEGRAL;
        self.derivative = 0;
        self.primed = false;
    }

    pub fn gains(&self) -> LoopGains<A> {
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
        A::whole(self.integral)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::num::FixedPoint;

    const FOLLOW: FollowingErrorLimit = FollowingErrorLimit { limit: 2048, hold_ticks: 10 };

    fn gains<A: LoopArithmetic>(kp: f32, ki_tick: f32, kd: f32, decay: f32, on: DerivativeOn) -> LoopGains<A> {
        LoopGains {
            feedforward: A::ONE,
            proportional: A::gain(kp).unwrap(),
            integral_per_tick: A::gain(ki_tick).unwrap(),
            derivative: A::gain(kd).unwrap(),
            derivative_decay: A::gain(decay).unwrap(),
            derivative_on: on,
        }
    }

    /// Runs a behaviour for both arithmetics: what the law promises holds
    /// in fixed point (AVR) and in f32 (FPU boards) alike.
    macro_rules! for_both {
        ($($name:ident),* $(,)?) => {$(
            mod $name {
                use crate::num::{FixedPoint, Float};
                #[test]
                fn fixed_point() {
                    super::$name::<FixedPoint>();
                }
                #[test]
                fn float() {
                    super::$name::<Float>();
                }
            }
        )*};
    }

    fn at(position: i32, velocity: i32) -> Reference {
        Reference { position, velocity }
    }

    const OK: DriverStatus = DriverStatus { alarm: false, bridge_fault: false };

    fn open_loop_commands_the_reference_velocity_only<A: LoopArithmetic>() {
        let mut c = AxisController::<A>::new(LoopGains::OPEN_LOOP, 409_600, FOLLOW);
        assert_eq!(c.tick(at(100, 10_240), Ok(0), OK), Ok(10_240));
        assert_eq!(c.tick(at(100, -10_240), Ok(50), OK), Ok(-10_240));
    }

    fn p_plus_feedforward_is_velocity_plus_kp_times_error<A: LoopArithmetic>() {
        let mut c = AxisController::<A>::new(gains(4.3, 0.0, 0.0, 0.0, DerivativeOn::Error), 409_600, FOLLOW);
        // xd − x = 1000 units, vd = 10240 units/s (5 mm/s): u = 10240 + 4300
        assert_eq!(c.tick(at(1000, 10_240), Ok(0), OK), Ok(14_540));
    }

    fn output_saturates_at_the_limit<A: LoopArithmetic>() {
        let mut c = AxisController::<A>::new(gains(5.0, 0.0, 0.0, 0.0, DerivativeOn::Error), 1000, FOLLOW);
        assert_eq!(c.tick(at(1000, 0), Ok(0), OK), Ok(1000));
        assert_eq!(c.tick(at(-1000, 0), Ok(0), OK), Ok(-1000));
    }

    fn integral_accumulates_ki_t_times_error_each_tick<A: LoopArithmetic>() {
        let mut c = AxisController::<A>::new(gains(0.0, 0.5, 0.0, 0.0, DerivativeOn::Error), 100_000, FOLLOW);
        assert_eq!(c.tick(at(100, 0), Ok(0), OK), Ok(50));
        assert_eq!(c.tick(at(100, 0), Ok(0), OK), Ok(100));
        assert_eq!(c.integral(), 100);
    }

    fn integral_stops_growing_while_the_output_is_saturated_anti_windup<A: LoopArithmetic>() {
        let mut c = AxisController::<A>::new(gains(1.0, 0.5, 0.0, 0.0, DerivativeOn::Error), 1000, FOLLOW);
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
        let mut c = AxisController::<FixedPoint>::new(gains(0.0, 0.01, 0.0, 0.0, DerivativeOn::Error), 100_000, FOLLOW);
        for _ in 0..1000 {
            c.tick(at(1, 0), Ok(0), OK).unwrap();
        }
        // 1000 × round(0.01 × 65536) / 65536 = 9.99 → 9 whole units/s
        assert_eq!(c.integral(), 9);
    }

    fn derivative_on_error_filters_a_ramp_to_kd_times_slope<A: LoopArithmetic>() {
        // Kd/(Tf+T) = 1, decay 0.5: a ramp of 10 units per tick converges
        // to 10 / (1 − 0.5) = 20.
        let mut c = AxisController::<A>::new(gains(0.0, 0.0, 1.0, 0.5, DerivativeOn::Error), 100_000, FOLLOW);
        let mut out = 0;
        for k in 0..40 {
            out = c.tick(at(10 * k, 0), Ok(0), OK).unwrap();
        }
        assert_eq!(out, 20);
    }

    fn derivative_on_measurement_ignores_reference_steps<A: LoopArithmetic>() {
        let mut c = AxisController::<A>::new(gains(0.0, 0.0, 1.0, 0.5, DerivativeOn::Measurement), 100_000, FOLLOW);
        c.tick(at(0, 0), Ok(0), OK).unwrap();
        assert_eq!(c.tick(at(1000, 0), Ok(0), OK), Ok(0));
        // the axis moving up by 10 brakes
        assert_eq!(c.tick(at(1000, 0), Ok(10), OK), Ok(-10));
    }

    fn following_error_above_limit_for_longer_than_hold_is_a_fault<A: LoopArithmetic>() {
        let mut c = AxisController::<A>::new(gains(1.0, 0.0, 0.0, 0.0, DerivativeOn::Error), 100_000, FOLLOW);
        for _ in 0..10 {
            assert!(c.tick(at(3000, 0), Ok(0), OK).is_ok());
        }
        assert_eq!(c.tick(at(3000, 0), Ok(0), OK), Err(AxisFault::FollowingError { error: 3000 }));
        // latched: stays stopped until reset
        assert_eq!(c.tick(at(0, 0), Ok(0), OK), Err(AxisFault::FollowingError { error: 3000 }));
        c.reset();
        assert!(c.tick(at(0, 0), Ok(0), OK).is_ok());
    }

    fn a_short_excursion_above_the_limit_recovers_without_fault<A: LoopArithmetic>() {
        let mut c = AxisController::<A>::new(gains(1.0, 0.0, 0.0, 0.0, DerivativeOn::Error), 100_000, FOLLOW);
        for _ in 0..10 {
            assert!(c.tick(at(3000, 0), Ok(0), OK).is_ok());
        }
        assert!(c.tick(at(3000, 0), Ok(2500), OK).is_ok());
        for _ in 0..10 {
            assert!(c.tick(at(3000, 0), Ok(0), OK).is_ok());
        }
    }

    fn an_error_over_four_times_the_limit_is_a_fault_at_once<A: LoopArithmetic>() {
        let mut c = AxisController::<A>::new(LoopGains::OPEN_LOOP, 100_000, FOLLOW);
        assert_eq!(c.tick(at(4 * 2048 + 4, 0), Ok(0), OK), Err(AxisFault::FollowingError { error: 8196 }));
    }

    fn driver_alarm_bridge_fault_and_encoder_fault_stop_the_axis<A: LoopArithmetic>() {
        let mut c = AxisController::<A>::new(LoopGains::OPEN_LOOP, 100_000, FOLLOW);
        assert_eq!(c.tick(at(0, 0), Ok(0), DriverStatus { alarm: true, bridge_fault: false }), Err(AxisFault::DriverAlarm));
        let mut c = AxisController::<A>::new(LoopGains::OPEN_LOOP, 100_000, FOLLOW);
        assert_eq!(c.tick(at(0, 0), Ok(0), DriverStatus { alarm: false, bridge_fault: true }), Err(AxisFault::BridgeFault));
        let mut c = AxisController::<A>::new(LoopGains::OPEN_LOOP, 100_000, FOLLOW);
        assert_eq!(c.tick(at(0, 0), Err(EncoderFault::Stuck), OK), Err(AxisFault::Encoder(EncoderFault::Stuck)));
    }

    #[test]
    fn the_loop_state_is_small() {
        assert!(core::mem::size_of::<AxisController>() <= 64, "{}", core::mem::size_of::<AxisController>());
    }

    for_both!(
        open_loop_commands_the_reference_velocity_only,
        p_plus_feedforward_is_velocity_plus_kp_times_error,
        output_saturates_at_the_limit,
        integral_accumulates_ki_t_times_error_each_tick,
        integral_stops_growing_while_the_output_is_saturated_anti_windup,
        derivative_on_error_filters_a_ramp_to_kd_times_slope,
        derivative_on_measurement_ignores_reference_steps,
        following_error_above_limit_for_longer_than_hold_is_a_fault,
        a_short_excursion_above_the_limit_recovers_without_fault,
        an_error_over_four_times_the_limit_is_a_fault_at_once,
        driver_alarm_bridge_fault_and_encoder_fault_stop_the_axis,
    );
}
