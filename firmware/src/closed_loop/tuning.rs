//! Gain computation, in the main loop (f32 allowed here, never in the tick):
//! the Normey-Rico robust PID tuner of SPEC §1, the relay (Åström–Hägglund,
//! Ziegler–Nichols) rules of SPEC §5, and the conversion of continuous gains
//! into the tick's [`LoopGains`] (Q16.16 or f32, [`crate::num`]) for one
//! sample period.
//!
//! Comparisons are written `!(x > 0.0)` on purpose: they reject NaN too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::control::{DerivativeOn, LoopGains, Q16};
use crate::num::LoopArithmetic;

/// Why gains could not be computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TuningError {
    /// γ must be in (0, 0.75].
    GammaOutOfRange,
    /// A time or amplitude that must be positive is not.
    NotPositive,
    /// A gain does not fit the tick's Q16.16 format (|gain| ≥ 32768), or
    /// Ki·T is ≥ 8 per tick (sample faster).
    GainOutOfRange,
}

/// Square root by Newton's method (main loop only; one call per tuning).
pub fn sqrt_f32(value: f32) -> f32 {
    if value <= 0.0 || value.is_nan() {
        return 0.0;
    }
    let mut root = if value > 1.0 { value / 2.0 } else { 1.0 };
    for _ in 0..40 {
        let next = 0.5 * (root + value / root);
        if (next - root).abs() <= f32::EPSILON * next {
            return next;
        }
        root = next;
    }
    root
}

/// The robust PID of Normey-Rico et al. (2001) for k'·e^(−θs)/s, SPEC §1:
/// inner gain K0 and an ideal PID with a derivative filter,
/// u = Kp(1 + 1/(Ti·s) + Td·s/(1 + Tf·s)). k' does not enter the tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobustPid {
    pub k0: f32,
    pub kp: f32,
    pub ti: f32,
    pub td: f32,
    pub tf: f32,
}

/// (θ, γ) → (K0, Kp, Ti, Td, Tf), 0 < γ ≤ 0.75 (larger: more robust, slower).
pub fn normey_rico(theta_s: f32, gamma: f32) -> Result<RobustPid, TuningError> {
    if !(gamma > 0.0 && gamma <= 0.75) {
        return Err(TuningError::GammaOutOfRange);
    }
    if !(theta_s > 0.0) {
        return Err(TuningError::NotPositive);
    }
    let lead = 1.5 - gamma;
    Ok(RobustPid {
        k0: 1.0 / (2.0 * theta_s),
        kp: (lead / theta_s) * (4.0 * gamma + 1.0 - 4.0 * sqrt_f32(gamma * gamma + gamma / 2.0)),
        ti: lead * theta_s,
        td: theta_s / lead - gamma * theta_s,
        tf: gamma * theta_s,
    })
}

/// Ultimate gain and Ziegler–Nichols PID gains from a relay experiment
/// (SPEC §5): Ku = 4d/(πa), Kp = 0.6Ku, Ki = 1.2Ku/Pu, Kd = 0.075·Ku·Pu.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelayGains {
    pub ku: f32,
    pub kp: f32,
    pub ki: f32,
    pub kd: f32,
}

/// `relay_amplitude` d and `oscillation_amplitude` a in the same units as
/// the output and the measurement; `period_s` Pu in seconds.
pub fn relay_ziegler_nichols(relay_amplitude: f32, oscillation_amplitude: f32, period_s: f32) -> Result<RelayGains, TuningError> {
    if !(relay_amplitude > 0.0 && oscillation_amplitude > 0.0 && period_s > 0.0) {
        return Err(TuningError::NotPositive);
    }
    let ku = 4.0 * relay_amplitude / (core::f32::consts::PI * oscillation_amplitude);
    Ok(RelayGains { ku, kp: 0.6 * ku, ki: 1.2 * ku / period_s, kd: 0.075 * ku * period_s })
}

fn gain<A: LoopArithmetic>(value: f32) -> Result<A::Gain, TuningError> {
    A::gain(value).ok_or(TuningError::GainOutOfRange)
}

/// The terms of a parallel PID u = Kff·vd + Kp·e + Ki∫e + Kd·s/(1 + Tf·s)(·):
/// `ki` in 1/s² (or duty/(unit·s)), `kd` and `tf` in s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParallelPid {
    pub feedforward: f32,
    pub kp: f32,
    pub ki: f32,
    pub kd: f32,
    pub tf: f32,
}

impl<A: LoopArithmetic> LoopGains<A> {
    /// u = ẋd + Kp·e.
    pub fn p_feedforward(kp: f32) -> Result<Self, TuningError> {
        Ok(LoopGains { proportional: gain::<A>(kp)?, ..Self::OPEN_LOOP })
    }

    /// The robust PID with the ẋd feedforward and K0 on the error (ours,
    /// see [`control`](super::control)), discretised for `period_s`:
    /// backward Euler for the integral and the filtered derivative.
    pub fn robust_pid(pid: &RobustPid, period_s: f32) -> Result<Self, TuningError> {
        let terms = ParallelPid { feedforward: 1.0, kp: pid.k0 + pid.kp, ki: pid.kp / pid.ti, kd: pid.kp * pid.td, tf: pid.tf };
        Self::parallel(&terms, period_s, DerivativeOn::Error)
    }

    /// A parallel PID u = Kff·vd + Kp·e + Ki∫e + Kd·s/(1 + Tf·s)(·), for
    /// `period_s`. The terms travel by reference: on the ATmega2560 more
    /// than 18 bytes of arguments go on the stack, which LLVM's AVR back end
    /// reads one byte off (tests/scripts/size-check.sh).
    pub fn parallel(terms: &ParallelPid, period_s: f32, derivative_on: DerivativeOn) -> Result<Self, TuningError> {
        let ParallelPid { feedforward, kp, ki, kd, tf } = *terms;
        if !(period_s > 0.0) || !(tf >= 0.0) {
            return Err(TuningError::NotPositive);
        }
        let integral_per_tick = ki * period_s;
        if !(integral_per_tick.abs() < 8.0) {
            return Err(TuningError::GainOutOfRange);
        }
        Ok(LoopGains {
            feedforward: gain::<A>(feedforward)?,
            proportional: gain::<A>(kp)?,
            integral_per_tick: gain::<A>(integral_per_tick)?,
            derivative: gain::<A>(kd / (tf + period_s))?,
            derivative_decay: gain::<A>(tf / (tf + period_s))?,
            derivative_on,
        })
    }

    /// SPEC §5's servo PID from relay gains: derivative on the measurement,
    /// derivative filter Tf = Td/10 (ours), no feedforward.
    pub fn servo_pid(gains: &RelayGains, period_s: f32) -> Result<Self, TuningError> {
        let td = if gains.kp > 0.0 { gains.kd / gains.kp } else { 0.0 };
        let terms = ParallelPid { feedforward: 0.0, kp: gains.kp, ki: gains.ki, kd: gains.kd, tf: td / 10.0 };
        Self::parallel(&terms, period_s, DerivativeOn::Measurement)
    }
}

/// The strategies a host selects at run time (`M821`), small enough to
/// store in the settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strategy {
    /// Step counting only: u = ẋd.
    OpenLoop,
    /// u = ẋd + Kp·e, Kp in thousandths (4300 = 4.3).
    PFeedforward { kp_milli: u16 },
    /// Normey-Rico robust PID, γ in thousandths (500 = 0.5).
    RobustPid { gamma_milli: u16 },
    /// A servo PID (SPEC §5) with gains in Q16.16 (from the relay tune or
    /// typed by the user), derivative on the measurement.
    ServoPid { kp: Q16, ki: Q16, kd: Q16 },
}

impl Strategy {
    /// The tick's gains for `dead_time_s` (θ, for the robust PID) and the
    /// loop's `period_s`.
    pub fn loop_gains<A: LoopArithmetic>(self, dead_time_s: f32, period_s: f32) -> Result<LoopGains<A>, TuningError> {
        match self {
            Strategy::OpenLoop => Ok(LoopGains::OPEN_LOOP),
            Strategy::PFeedforward { kp_milli } => LoopGains::p_feedforward(f32::from(kp_milli) / 1000.0),
            Strategy::RobustPid { gamma_milli } => {
                LoopGains::robust_pid(&normey_rico(dead_time_s, f32::from(gamma_milli) / 1000.0)?, period_s)
            }
            Strategy::ServoPid { kp, ki, kd } => {
                let gains = RelayGains { ku: 0.0, kp: kp.to_f32(), ki: ki.to_f32(), kd: kd.to_f32() };
                LoopGains::servo_pid(&gains, period_s)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::closed_loop::control::FixedGains;
    use crate::num::FixedPoint;

    fn close(actual: f32, expected: f32, tolerance: f32) -> bool {
        (actual - expected).abs() <= tolerance
    }

    #[test]
    fn normey_rico_reproduces_the_spec_gamma_table_at_theta_0_1() {
        // γ → Kp, Ti, Td, Tf (SPEC §1); K0 = 5 in every row.
        let table = [
            (0.3, 2.884898, 0.1200, 0.053333, 0.03),
            (0.5, 1.715729, 0.1000, 0.050000, 0.05),
            (0.7, 1.071516, 0.0800, 0.055000, 0.07),
            (0.75, 0.952625, 0.0750, 0.058333, 0.075),
        ];
        for (gamma, kp, ti, td, tf) in table {
            let pid = normey_rico(0.1, gamma).unwrap();
            assert!(close(pid.k0, 5.0, 1e-6), "γ {gamma}: K0 {}", pid.k0);
            assert!(close(pid.kp, kp, 5e-6), "γ {gamma}: Kp {} ≠ {kp}", pid.kp);
            assert!(close(pid.ti, ti, 5e-7), "γ {gamma}: Ti {} ≠ {ti}", pid.ti);
            assert!(close(pid.td, td, 5e-7), "γ {gamma}: Td {} ≠ {td}", pid.td);
            assert!(close(pid.tf, tf, 5e-7), "γ {gamma}: Tf {} ≠ {tf}", pid.tf);
        }
    }

    #[test]
    fn normey_rico_rejects_gamma_outside_0_to_0_75_and_non_positive_theta() {
        assert_eq!(normey_rico(0.1, 0.0), Err(TuningError::GammaOutOfRange));
        assert_eq!(normey_rico(0.1, 0.76), Err(TuningError::GammaOutOfRange));
        assert_eq!(normey_rico(0.1, f32::NAN), Err(TuningError::GammaOutOfRange));
        assert_eq!(normey_rico(0.0, 0.5), Err(TuningError::NotPositive));
    }

    #[test]
    fn relay_rules_reproduce_the_spec_vectors() {
        let g = relay_ziegler_nichols(127.0, 10.0, 0.2).unwrap();
        assert!(close(g.ku, 16.1701, 5e-5) && close(g.kp, 9.7021, 5e-5), "{g:?}");
        assert!(close(g.ki, 97.0209, 5e-4) && close(g.kd, 0.2426, 5e-5), "{g:?}");
        let g = relay_ziegler_nichols(100.0, 50.0, 1.0).unwrap();
        assert!(close(g.ku, 2.5465, 5e-5) && close(g.kp, 1.5279, 5e-5), "{g:?}");
        assert!(close(g.ki, 3.0558, 5e-5) && close(g.kd, 0.1910, 5e-5), "{g:?}");
        assert_eq!(relay_ziegler_nichols(0.0, 1.0, 1.0), Err(TuningError::NotPositive));
    }

    #[test]
    fn sqrt_matches_known_roots() {
        for (x, r) in [(0.24f32, 0.48989795), (2.0, core::f32::consts::SQRT_2), (1e-6, 1e-3), (1e6, 1000.0), (0.0, 0.0)] {
            assert!(close(sqrt_f32(x), r, r * 1e-6 + 1e-9), "√{x} = {}", sqrt_f32(x));
        }
    }

    #[test]
    fn robust_pid_at_1_khz_becomes_these_fixed_gains() {
        // γ 0.5: K0 + Kp = 6.715729, Ki·T = 1.715729/0.1 × 0.001,
        // Kd/(Tf + T) = 1.715729 × 0.05 / 0.051, Tf/(Tf + T) = 0.05/0.051.
        let g = Strategy::RobustPid { gamma_milli: 500 }.loop_gains::<FixedPoint>(0.1, 0.001).unwrap();
        assert_eq!(g.feedforward, Q16::ONE);
        assert!(close(g.proportional.to_f32(), 6.715729, 2e-5));
        assert!(close(g.integral_per_tick.to_f32(), 0.01715729, 2e-5));
        assert!(close(g.derivative.to_f32(), 1.682087, 2e-5));
        assert!(close(g.derivative_decay.to_f32(), 0.980392, 2e-5));
        assert_eq!(g.derivative_on, DerivativeOn::Error);
    }

    #[test]
    fn p_feedforward_and_open_loop_gains() {
        let g = Strategy::PFeedforward { kp_milli: 4300 }.loop_gains::<FixedPoint>(0.1, 0.001).unwrap();
        assert_eq!((g.feedforward, g.proportional, g.integral_per_tick), (Q16::ONE, Q16::from_f32(4.3).unwrap(), Q16::ZERO));
        assert_eq!(Strategy::OpenLoop.loop_gains::<FixedPoint>(0.1, 0.001), Ok(FixedGains::OPEN_LOOP));
    }

    #[test]
    fn servo_pid_has_no_feedforward_and_derivative_on_measurement() {
        let relay = relay_ziegler_nichols(127.0, 10.0, 0.2).unwrap();
        let g = FixedGains::servo_pid(&relay, 0.001).unwrap();
        assert_eq!(g.feedforward, Q16::ZERO);
        assert_eq!(g.derivative_on, DerivativeOn::Measurement);
        assert!(close(g.proportional.to_f32(), 9.7021, 1e-4));
        assert!(close(g.integral_per_tick.to_f32(), 0.0970209, 2e-5));
    }

    #[test]
    fn gains_that_do_not_fit_the_tick_are_refused() {
        assert_eq!(FixedGains::p_feedforward(40_000.0), Err(TuningError::GainOutOfRange));
        // Ki·T = 97 × 0.1 s: too coarse a sample period
        let relay = relay_ziegler_nichols(127.0, 10.0, 0.2).unwrap();
        assert_eq!(FixedGains::servo_pid(&relay, 0.1), Err(TuningError::GainOutOfRange));
    }
}
