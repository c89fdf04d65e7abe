//! Heater control laws: PID in fixed point, and bang-bang with hysteresis.
//!
//! # Units
//! - Gains ([`Gains`]) are Marlin's (`M301 P I D`), kept as integers in
//!   ten-thousandths so that every value a host types survives exactly:
//!   Kp in duty counts (0–255) per °C, Ki in counts per °C·s, Kd in
//!   counts·s/°C. `kp: 222_000` is Kp 22.2.
//! - Inside the law, output is in **micro-counts** (10⁻⁶ of a duty count,
//!   `i32`, ±2147 counts of room): Kp[10⁻⁴] × error[10⁻² °C] is already in
//!   micro-counts, so the proportional term is one multiplication.
//!
//! # The law, once per sample of period T (ms)
//! ```text
//! e = target − measured                                   (hundredths of °C)
//! P = Kp·e
//! D ← D + (Kd·(measured − previous)·1000/T − D) / 2^shift (on the measurement, filtered)
//! I ← clamp(I + Ki·e·T/1000, 0, max)      unless that pushes a saturated output further
//! u = clamp(P + I − D, 0, max)
//! ```
//! Marlin's scaling is the same: it multiplies Ki by the sample period and
//! divides Kd by it (`PID_dT`); here that happens with T in ms, so the
//! gains a host sets mean the same thing at any sample period.
//!
//! Anti-windup is **conditional integration** (the integral does not move
//! while the output is saturated in the direction it would push) plus a
//! clamp of the integral to the output range. Optionally, Marlin's
//! `PID_FUNCTIONAL_RANGE`: farther than N °C below the target the output is
//! full and the integral is reset, farther above it is off.
//!
//! Every product goes through `math::saturating_mul`, never `checked_mul`.

use super::math::{clamp, saturating_mul, scale};
use super::Celsius;

/// Micro-counts in one duty count.
const MICRO: i32 = 1_000_000;

/// PID gains in Marlin's units, in ten-thousandths (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Gains {
    /// Kp × 10⁴: duty counts per °C.
    pub kp: u32,
    /// Ki × 10⁴: duty counts per °C per second.
    pub ki: u32,
    /// Kd × 10⁴: duty counts per °C/s.
    pub kd: u32,
}

impl Gains {
    /// Largest accepted gain, × 10⁴ (Kp, Ki or Kd of 10 000).
    pub const MAX: u32 = 100_000_000;

    /// Marlin's stock hot end (E3D-like): Kp 22.2, Ki 1.08, Kd 114.
    pub const MARLIN_HOTEND: Gains = Gains { kp: 222_000, ki: 10_800, kd: 1_140_000 };
    /// Marlin's stock bed: Kp 10.00, Ki 0.023, Kd 305.4.
    pub const MARLIN_BED: Gains = Gains { kp: 100_000, ki: 230, kd: 3_054_000 };
    /// SPEC §4 thesis PI (Kp 2.4 %/°C, Ki 0.008 %/(°C·s)) on the 0–255
    /// scale: Kp 6.12, Ki 0.0204, no D.
    pub const THESIS_BARREL: Gains = Gains { kp: 61_200, ki: 204, kd: 0 };

    /// Gains × 10⁴ (e.g. from `Decimal::to_scaled(4)`); `None` if one is
    /// negative or above [`Gains::MAX`].
    pub fn new(kp: i32, ki: i32, kd: i32) -> Option<Self> {
        let check = |value: i32| {
            if (0..=Self::MAX as i32).contains(&value) {
                Some(value as u32)
            } else {
                None
            }
        };
        Some(Self { kp: check(kp)?, ki: check(ki)?, kd: check(kd)? })
    }

    /// `M301 P22.20 I1.08 D114.00` (no newline), the `M503` line.
    pub fn write_m301<W: ufmt::uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        self.write_as(301, out)
    }

    /// `M<code> P… I… D…` (no newline): `M301` for a hot end, `M304` for
    /// the bed.
    pub fn write_as<W: ufmt::uWrite + ?Sized>(&self, code: u16, out: &mut W) -> Result<(), W::Error> {
        ufmt::uwrite!(out, "M{} P{} I{} D{}", crate::reply::Whole(code.into()), Gain(self.kp), Gain(self.ki), Gain(self.kd))
    }
}

/// ` Kp: 22.20 Ki: 1.08 Kd: 114.00`, Marlin's line after `M303` cycles
/// (the leading space is Marlin's).
impl ufmt::uDisplay for Gains {
    fn fmt<W: ufmt::uWrite + ?Sized>(&self, f: &mut ufmt::Formatter<'_, W>) -> Result<(), W::Error> {
        ufmt::uwrite!(f, " Kp: {} Ki: {} Kd: {}", Gain(self.kp), Gain(self.ki), Gain(self.kd))
    }
}

/// A gain × 10⁴ printed with two decimals, or up to four when needed
/// (`22.20`, `1.08`, `0.0204`, `9.7021`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Gain(pub u32);

impl ufmt::uDisplay for Gain {
    fn fmt<W: ufmt::uWrite + ?Sized>(&self, f: &mut ufmt::Formatter<'_, W>) -> Result<(), W::Error> {
        // Gains are at most `Gains::MAX` (10⁸): they fit an `i32`.
        // Trailing zeros dropped down to two decimals (`div_rem_10` is
        // linked anyway; no division here).
        let (mut mantissa, mut digits) = (self.0, 4);
        while digits > 2 {
            let (tenth, last) = crate::gcode::number::div_rem_10(mantissa);
            if last != 0 {
                break;
            }
            mantissa = tenth;
            digits -= 1;
        }
        crate::reply::write_fixed(f, mantissa as i32, digits)
    }
}

/// How a heater is controlled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// PID with [`Gains`].
    Pid {
        /// Marlin's `PID_FUNCTIONAL_RANGE` in °C (0: off): farther than
        /// this below the target, full power and no integral; above, off.
        functional_range_c: u8,
        /// The derivative's low-pass filter: each sample moves it
        /// 1/2^shift of the way to the new value (0: no filter).
        derivative_filter_shift: u8,
    },
    /// On below `target − hysteresis`, off above `target + hysteresis`,
    /// unchanged in between (Marlin's `BED_HYSTERESIS`).
    BangBang {
        /// Hysteresis in tenths of °C.
        hysteresis_tenths: u8,
    },
}

impl Control {
    /// Marlin's defaults: functional range 10 °C, and a derivative filter
    /// of 15/16 per sample, close to Marlin's `PID_K1` 0.95 (at 100 ms
    /// samples a 1.5 s time constant: Kd 114 would otherwise turn 0.1 °C
    /// of reading noise into 100 counts of output noise).
    pub const PID: Control = Control::Pid { functional_range_c: 10, derivative_filter_shift: 4 };
    /// A plain PID/PI with no functional range (SPEC §4's thesis PI).
    pub const PLAIN_PID: Control = Control::Pid { functional_range_c: 0, derivative_filter_shift: 4 };
    /// Bang-bang with Marlin's 2 °C bed hysteresis.
    pub const BANG_BANG: Control = Control::BangBang { hysteresis_tenths: 20 };
}

/// The inputs of one run of the law ([`PidState::control`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Law {
    /// See [`Control::Pid`].
    pub functional_range_c: u8,
    /// T, ms.
    pub control_period_ms: u16,
    /// Largest duty.
    pub max_power: u8,
    pub target: Celsius,
    pub measured: Celsius,
}

/// The memory of the PID law: 8 bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PidState {
    /// Integral term, micro-counts, within 0..=max.
    integral: i32,
    /// Filtered derivative term (on the measurement), micro-counts.
    derivative: i32,
}

impl PidState {
    pub const fn new() -> Self {
        Self { integral: 0, derivative: 0 }
    }

    /// Forget the integral and the derivative (heater switched off).
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// The integral term in duty counts (for tests and diagnostics).
    pub fn integral_counts(&self) -> i32 {
        self.integral / MICRO
    }

    /// One sample: the duty (0..=`max_power`) for `measured` now and
    /// `previous` one sample ago, `period_ms` apart ([`observe`](Self::observe)
    /// then [`control`](Self::control) with the same period).
    #[allow(clippy::too_many_arguments)]
    pub fn update(
        &mut self,
        gains: &Gains,
        functional_range_c: u8,
        derivative_filter_shift: u8,
        period_ms: u16,
        max_power: u8,
        target: Celsius,
        measured: Celsius,
        previous: Celsius,
    ) -> u8 {
        self.observe(gains, derivative_filter_shift, period_ms, measured, previous);
        self.control(gains, &Law { functional_range_c, control_period_ms: period_ms, max_power, target, measured })
    }

    /// Every sample: the derivative on the measurement (no kick when the
    /// target changes), a rate, so it may be sampled faster than the law
    /// runs.
    pub fn observe(&mut self, gains: &Gains, derivative_filter_shift: u8, sample_period_ms: u16, measured: Celsius, previous: Celsius) {
        let period = i32::from(sample_period_ms.max(1));
        // Temperatures are table values (−30..420 °C): no overflow.
        let rise = measured.0 - previous.0;
        let raw = bounded(scale(saturating_mul(gains.kd as i32, rise), 1000, period));
        let shift = u32::from(derivative_filter_shift.min(16));
        // Both within ±2²⁹: the difference and the result fit.
        self.derivative += (raw - self.derivative) >> shift;
    }

    /// The law, every `control_period_ms`: the duty (0..=`max_power`).
    ///
    /// The inputs come bundled in [`Law`], passed by reference: as separate
    /// arguments (and with LLVM turning `&Gains` into its values) they took
    /// more than the 18 argument registers, and LLVM passed the
    /// temperatures on the stack, where it reads them one byte off on the
    /// ATmega2560 (a 3-byte return address; `tests/scripts/size-check.sh`
    /// refuses such code).
    pub fn control(&mut self, gains: &Gains, law: &Law) -> u8 {
        let Law { functional_range_c, control_period_ms, max_power, target, measured } = *law;
        let period = i32::from(control_period_ms.max(1));
        let max = i32::from(max_power) * MICRO;
        let error = target.0 - measured.0;
        let range = i32::from(u16::from(functional_range_c) * 100);
        if range > 0 && error > range {
            self.integral = 0;
            return max_power;
        }
        if range > 0 && error < -range {
            self.integral = 0;
            return 0;
        }

        // Every term within ±2²⁹ (the integral within 0..2²⁸): sums of
        // three fit an i32, so plain arithmetic below.
        let proportional = bounded(saturating_mul(gains.kp as i32, error));
        let increment = bounded(scale(saturating_mul(gains.ki as i32, error), period, 1000));
        let unclamped = proportional + self.integral - self.derivative;
        let winding_up = (unclamped >= max && increment > 0) || (unclamped <= 0 && increment < 0);
        if !winding_up {
            self.integral = clamp(self.integral + increment, 0, max);
        }
        let output = clamp(proportional + self.integral - self.derivative, 0, max);
        ((output + MICRO / 2) / MICRO) as u8
    }
}

/// Terms of the law are kept within ±2²⁹ micro-counts (±536 counts, twice
/// any output), so that sums of three of them cannot overflow.
#[inline(never)]
fn bounded(value: i32) -> i32 {
    clamp(value, -(1 << 29), 1 << 29)
}

/// Bang-bang with hysteresis: `on` is the heater's state before this sample.
pub fn bang_bang(hysteresis_tenths: u8, max_power: u8, target: Celsius, measured: Celsius, on: bool) -> u8 {
    let band = i32::from(u16::from(hysteresis_tenths) * 10);
    let on = if measured.0 <= target.0.saturating_sub(band) {
        true
    } else if measured.0 >= target.0.saturating_add(band) {
        false
    } else {
        on
    };
    if on {
        max_power
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reply::test_support::Text;

    const T: u16 = 1000;

    fn shown(value: impl ufmt::uDisplay) -> std::string::String {
        let mut out = Text::default();
        ufmt::uwrite!(out, "{}", value).unwrap();
        out.0
    }

    fn pi(kp: u32, ki: u32) -> Gains {
        Gains { kp, ki, kd: 0 }
    }

    #[test]
    fn proportional_only_gives_kp_times_error() {
        // Kp 2.0 × 10 °C = 20 counts; Kp 2.0 × 0.25 °C = 0.5 → rounds to 1.
        let mut pid = PidState::new();
        let out = pid.update(&pi(20_000, 0), 0, 0, T, 255, Celsius(20_000), Celsius(19_000), Celsius(19_000));
        assert_eq!(out, 20);
        let out = pid.update(&pi(20_000, 0), 0, 0, T, 255, Celsius(20_000), Celsius(19_975), Celsius(19_975));
        assert_eq!(out, 1);
    }

    #[test]
    fn integral_adds_ki_times_error_times_the_period_each_sample() {
        // Ki 0.5 /s, 2 °C error, T 1 s → +1 count per sample; at T 100 ms,
        // 10 samples make the same count.
        let mut pid = PidState::new();
        for expected in 1..=5 {
            pid.update(&pi(0, 5_000), 0, 0, 1000, 255, Celsius(20_200), Celsius(20_000), Celsius(20_000));
            assert_eq!(pid.integral_counts(), expected);
        }
        let mut fast = PidState::new();
        for _ in 0..10 {
            fast.update(&pi(0, 5_000), 0, 0, 100, 255, Celsius(20_200), Celsius(20_000), Celsius(20_000));
        }
        assert_eq!(fast.integral_counts(), 1);
    }

    #[test]
    fn derivative_acts_on_the_measurement_not_on_a_target_step() {
        // Kd 10 counts·s/°C, no filter: a 0.5 °C rise in 1 s takes 5 counts
        // off; a target step with a steady measurement takes nothing.
        let gains = Gains { kp: 0, ki: 0, kd: 100_000 };
        let mut pid = PidState::new();
        let base = pid.update(&Gains { kp: 100_000, ..gains }, 0, 0, T, 255, Celsius(10_000), Celsius(9_000), Celsius(9_000));
        assert_eq!(base, 100);
        let out = pid.update(&Gains { kp: 100_000, ..gains }, 0, 0, T, 255, Celsius(10_000), Celsius(9_050), Celsius(9_000));
        // P = 10 × 9.5 = 95, D = 10 × 0.5 = 5.
        assert_eq!(out, 90);
        let mut pid = PidState::new();
        let out = pid.update(&Gains { kp: 0, ..gains }, 0, 0, T, 255, Celsius(30_000), Celsius(9_000), Celsius(9_000));
        assert_eq!(out, 0);
    }

    #[test]
    fn derivative_scales_with_the_sample_period() {
        // The same 0.5 °C/s rise sampled every 100 ms (0.05 °C per sample)
        // is the same derivative: Kd 10 × 0.5 = 5 counts.
        let gains = Gains { kp: 100_000, ki: 0, kd: 100_000 };
        let mut pid = PidState::new();
        let out = pid.update(&gains, 0, 0, 100, 255, Celsius(10_000), Celsius(9_005), Celsius(9_000));
        // P = 10 × 9.95 = 99.5, D = 5 → 94.5 → 95 (rounding half up).
        assert_eq!(out, 95);
    }

    #[test]
    fn derivative_filter_moves_a_quarter_of_the_way_with_shift_two() {
        let gains = Gains { kp: 1_000_000, ki: 0, kd: 400_000 }; // Kp 100, Kd 40
        let mut pid = PidState::new();
        // Rise 1 °C in 1 s: raw D = 40; filtered: 10, then 17.5, ...
        let out = pid.update(&gains, 0, 2, T, 255, Celsius(10_000), Celsius(9_900), Celsius(9_800));
        assert_eq!(out, 100 - 10);
        let out = pid.update(&gains, 0, 2, T, 255, Celsius(10_000), Celsius(9_900), Celsius(9_800));
        assert_eq!(out, 83); // 100 − 17.5 = 82.5, rounded half up
    }

    #[test]
    fn conditional_integration_freezes_the_integral_while_saturated() {
        // Kp 6.12 × 186 °C saturates: the integral must not grow at all.
        let mut pid = PidState::new();
        for _ in 0..1000 {
            let out = pid.update(&Gains::THESIS_BARREL, 0, 0, T, 255, Celsius(21_000), Celsius(2_400), Celsius(2_400));
            assert_eq!(out, 255);
        }
        assert_eq!(pid.integral_counts(), 0);
    }

    #[test]
    fn integral_is_clamped_to_the_output_range_and_never_negative() {
        let mut pid = PidState::new();
        for _ in 0..100 {
            pid.update(&pi(0, 10_000_000), 0, 0, T, 200, Celsius(5_000), Celsius(4_000), Celsius(4_000));
        }
        assert_eq!(pid.integral_counts(), 200);
        for _ in 0..100 {
            pid.update(&pi(0, 10_000_000), 0, 0, T, 200, Celsius(5_000), Celsius(6_000), Celsius(6_000));
        }
        assert_eq!(pid.integral_counts(), 0);
    }

    #[test]
    fn output_is_limited_to_max_power() {
        let mut pid = PidState::new();
        let out = pid.update(&pi(1_000_000, 0), 0, 0, T, 127, Celsius(20_000), Celsius(2_000), Celsius(2_000));
        assert_eq!(out, 127);
        let out = pid.update(&pi(1_000_000, 0), 0, 0, T, 127, Celsius(2_000), Celsius(20_000), Celsius(20_000));
        assert_eq!(out, 0);
    }

    #[test]
    fn functional_range_gives_full_power_far_below_and_off_far_above() {
        let mut pid = PidState::new();
        let gains = Gains::MARLIN_HOTEND;
        assert_eq!(pid.update(&gains, 10, 2, 100, 255, Celsius(21_000), Celsius(19_999), Celsius(19_999)), 255);
        assert_eq!(pid.update(&gains, 10, 2, 100, 255, Celsius(21_000), Celsius(22_001), Celsius(22_001)), 0);
        assert_eq!(pid.integral_counts(), 0);
        // Within 10 °C the law runs: Kp 22.2 × 5 °C = 111 counts, plus the
        // first integral step Ki 1.08 × 5 °C × 0.1 s = 0.54 → 111.54 → 112.
        let mut pid = PidState::new();
        assert_eq!(pid.update(&gains, 10, 2, 100, 255, Celsius(21_000), Celsius(20_500), Celsius(20_500)), 112);
    }

    #[test]
    fn huge_gains_and_errors_saturate_instead_of_wrapping() {
        let gains = Gains { kp: Gains::MAX, ki: Gains::MAX, kd: Gains::MAX };
        let mut pid = PidState::new();
        assert_eq!(pid.update(&gains, 0, 0, 1, 255, Celsius(100_000), Celsius(-100_000), Celsius(-100_000)), 255);
        assert_eq!(pid.update(&gains, 0, 0, 1, 255, Celsius(-100_000), Celsius(100_000), Celsius(-100_000)), 0);
    }

    #[test]
    fn bang_bang_switches_outside_the_hysteresis_band_only() {
        let (target, band) = (Celsius(6_000), 20); // 60 °C ± 2 °C
        assert_eq!(bang_bang(band, 255, target, Celsius(5_800), false), 255);
        assert_eq!(bang_bang(band, 255, target, Celsius(5_900), false), 0);
        assert_eq!(bang_bang(band, 255, target, Celsius(5_900), true), 255);
        assert_eq!(bang_bang(band, 255, target, Celsius(6_199), true), 255);
        assert_eq!(bang_bang(band, 255, target, Celsius(6_200), true), 0);
        assert_eq!(bang_bang(band, 200, target, Celsius(2_000), false), 200);
    }

    #[test]
    fn gains_print_like_marlin_with_extra_digits_only_when_needed() {
        assert_eq!(shown(Gain(222_000)), "22.20");
        assert_eq!(shown(Gain(10_800)), "1.08");
        assert_eq!(shown(Gain(204)), "0.0204");
        assert_eq!(shown(Gain(97_021)), "9.7021");
        assert_eq!(shown(Gain(1_234_560)), "123.456");
        assert_eq!(shown(Gain(0)), "0.00");
        let mut out = Text::default();
        Gains::MARLIN_HOTEND.write_m301(&mut out).unwrap();
        assert_eq!(out.0, "M301 P22.20 I1.08 D114.00");
        assert_eq!(shown(Gains::THESIS_BARREL), " Kp: 6.12 Ki: 0.0204 Kd: 0.00");
    }

    /// The previous digit-by-digit formatting, as the reference.
    fn reference_gain(value: u32) -> std::string::String {
        let (whole, fraction) = (value / 10_000, value % 10_000);
        let digits = if fraction % 100 == 0 {
            2
        } else if fraction % 10 == 0 {
            3
        } else {
            4
        };
        let text = std::format!("{fraction:04}");
        std::format!("{whole}.{}", &text[..digits])
    }

    #[test]
    fn gains_print_as_before_over_their_whole_range() {
        let mut values: std::vec::Vec<u32> = (0..200_000).collect();
        values.extend((0..100_000u32).map(|i| i.wrapping_mul(2_654_435_761) % (Gains::MAX + 1)));
        values.extend([Gains::MAX, Gains::MAX - 1, Gains::MAX - 10, 99_999_999, 12_345_670]);
        for value in values {
            assert_eq!(shown(Gain(value)), reference_gain(value), "{value}");
        }
    }

    #[test]
    fn gains_from_scaled_decimals_reject_negative_and_huge_values() {
        assert_eq!(Gains::new(222_000, 10_800, 1_140_000), Some(Gains::MARLIN_HOTEND));
        assert_eq!(Gains::new(-1, 0, 0), None);
        assert_eq!(Gains::new(0, 100_000_001, 0), None);
    }
}
