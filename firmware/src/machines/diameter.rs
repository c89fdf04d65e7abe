//! The filament diameter loop of the extrusion line (SPEC §4).
//!
//! A camera on the PC measures the filament once per second (with a 3 s
//! transport delay) and sends the diameter over the serial line, in pixels
//! (0.02145 mm/px) or in mm. A reverse-acting PI in pixels (thesis: Kp
//! −0.07 rpm/px, Ki −0.004 rpm/px per sample, T = 1 s) sets the puller
//! speed, clamped to 1–15 rpm: too thick → error negative → pull faster.
//!
//! Ours (the thesis had none of these):
//! - **anti-windup**: the PI's own (conditional integration);
//! - **bumpless start**: switching to automatic, or resuming after a
//!   stale spell, presets the PI so that its first output is the puller's
//!   speed at that moment (from a zero integral the thesis' loop dropped
//!   the puller to 1 rpm at once);
//! - **stale-measurement watchdog**: no measurement for
//!   [`DiameterSettings::stale_after_s`] seconds in automatic mode holds
//!   the puller at its last speed and warns once; the next measurement
//!   resumes bumplessly;
//! - measurements outside a plausible range are refused, never used;
//! - gains and setpoint settable at run time; positive gains (which would
//!   make the loop run away) are refused.
//!
//! Manual and automatic puller modes are distinct ([`PullerMode`]): in
//! manual mode measurements are recorded and reported but never move the
//! puller; only an explicit speed does.
//!
//! Units: diameters in centi-pixels (`13287` = 132.87 px = 2.850 mm),
//! speeds in milli-RPM. The loop runs once per measurement (1 Hz) in the
//! main loop, so its PI is f32 ([`PiLaw`]).
//!
//! The PI law itself is not written here (one PI in the firmware): the
//! loop is generic over [`PiLaw`], to be implemented for the thermal
//! module's PI (Kp 2.4, Ki 0.008, conditional integration, the same law
//! with other gains and limits) when it lands; until then
//! [`ClosedLoopPi`] adapts the closed-loop module's fixed-point loop law.

use crate::closed_loop::control::{AxisController, DerivativeOn, DriverStatus, FixedGains, FollowingErrorLimit, Reference, Q16};
use crate::num::FixedPoint;

/// What the diameter loop needs from a sampled PI controller. The loop
/// calls it once per measurement; all values in the loop's units (error in
/// px, output in rpm).
pub trait PiLaw {
    /// One sample: `error` = setpoint − measured; returns the output within
    /// the limits, integrating only while that does not drive the output
    /// further into a limit (anti-windup).
    fn update(&mut self, error: f32) -> f32;
    /// Bumpless transfer: set the integral so that a zero error gives
    /// `output` (clamped to the limits).
    fn preset(&mut self, output: f32);
    /// Kp (output per unit of error) and Ki (output per unit of error per
    /// sample). The integral is kept as an output value, so a gain change
    /// does not bump the output.
    fn set_gains(&mut self, kp: f32, ki_per_sample: f32);
    fn gains(&self) -> (f32, f32);
    fn set_limits(&mut self, min: f32, max: f32);
}

/// Which way the puller is driven.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PullerMode {
    /// At the speed the operator set (`M860 S`); measurements are only recorded.
    Manual,
    /// The diameter loop sets the speed from each measurement.
    Automatic,
}

/// Settings of the loop (M404, M862, M863).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiameterSettings {
    /// Setpoint, centi-pixels.
    pub setpoint_cpx: u16,
    /// Camera scale: nanometres per pixel (21 450 = 0.02145 mm/px).
    pub nm_per_px: u32,
    /// Puller limits, milli-RPM (1–15 rpm).
    pub min_mrpm: u32,
    pub max_mrpm: u32,
    /// Seconds without a measurement before the loop holds and warns.
    pub stale_after_s: u8,
    /// Plausible measurements, centi-pixels; others are refused.
    pub min_valid_cpx: u16,
    pub max_valid_cpx: u16,
}

impl DiameterSettings {
    /// SPEC §4: 2.85 mm (132.87 px at 0.02145 mm/px), 1–15 rpm; a 5 s
    /// watchdog (the camera sends every second) and 0.5–6 mm plausible (ours).
    pub const THESIS: DiameterSettings = DiameterSettings {
        setpoint_cpx: 13_287,
        nm_per_px: 21_450,
        min_mrpm: 1_000,
        max_mrpm: 15_000,
        stale_after_s: 5,
        min_valid_cpx: 2_331,
        max_valid_cpx: 27_972,
    };

    /// µm → centi-pixels, rounded (µm ≤ 42 949).
    pub fn cpx_from_um(&self, um: u32) -> u32 {
        let per_px = self.nm_per_px.max(1);
        (um.min(42_949) * 100_000 + per_px / 2) / per_px
    }

    /// centi-pixels → µm, rounded.
    pub fn um_from_cpx(&self, cpx: u32) -> u32 {
        // cpx ≤ 65 535 and nm/px ≤ 65 535 keep the product in 32 bits
        (cpx.min(65_535) * self.nm_per_px.min(65_535) + 50_000) / 100_000
    }
}

/// The thesis' gains: Kp −0.07 rpm/px, Ki −0.004 rpm/px per sample.
pub const THESIS_KP: f32 = -0.07;
pub const THESIS_KI: f32 = -0.004;

/// Why a measurement or setting was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DiameterError {
    /// Outside [`DiameterSettings::min_valid_cpx`]…`max_valid_cpx`.
    Implausible,
    /// A gain above zero (the loop is reverse acting) or not finite.
    GainSign,
}

/// Something the host should be told about (an `echo:` line).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DiameterWarning {
    /// No measurement for `seconds`: the puller is held at `held_mrpm`.
    Stale { seconds: u16, held_mrpm: u32 },
}

impl DiameterWarning {
    /// `echo:Diameter measurement stale (5 s), puller held at 3.878 rpm`
    pub fn write<W: ufmt::uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        match *self {
            DiameterWarning::Stale { seconds, held_mrpm } => {
                crate::flash_str!("echo:Diameter measurement stale (").write_to(out)?;
                ufmt::uwrite!(out, "{}", seconds)?;
                crate::flash_str!(" s), puller held at ").write_to(out)?;
                write_milli(out, held_mrpm)?;
                crate::flash_str!(" rpm\n").write_to(out)
            }
        }
    }
}

/// `value / 1000` with three decimals.
pub fn write_milli<W: ufmt::uWrite + ?Sized>(out: &mut W, value: u32) -> Result<(), W::Error> {
    let fraction = value % 1000;
    ufmt::uwrite!(out, "{}.", value / 1000)?;
    if fraction < 100 {
        out.write_str("0")?;
    }
    if fraction < 10 {
        out.write_str("0")?;
    }
    ufmt::uwrite!(out, "{}", fraction)
}

/// The loop's state (≈ 24 bytes plus the PI's).
#[derive(Clone, Copy, Debug)]
pub struct DiameterLoop<P> {
    pi: P,
    settings: DiameterSettings,
    mode: PullerMode,
    /// The puller speed the loop last asked for (automatic mode).
    output_mrpm: u32,
    last_cpx: Option<u16>,
    /// Seconds since the last measurement (saturating).
    age_s: u16,
    stale: bool,
    /// Preset the PI from the puller's speed before the next update.
    needs_preset: bool,
}

impl<P: PiLaw> DiameterLoop<P> {
    /// Starts in manual mode. `pi` gets the settings' limits.
    pub fn new(mut pi: P, settings: DiameterSettings) -> Self {
        pi.set_limits(settings.min_mrpm as f32 / 1000.0, settings.max_mrpm as f32 / 1000.0);
        Self { pi, settings, mode: PullerMode::Manual, output_mrpm: settings.min_mrpm, last_cpx: None, age_s: 0, stale: false, needs_preset: true }
    }

    pub fn mode(&self) -> PullerMode {
        self.mode
    }

    /// Switch mode. To automatic: the PI starts from `puller_mrpm` (the
    /// speed the puller runs at now), bumplessly. To manual: nothing moves.
    pub fn set_mode(&mut self, mode: PullerMode, puller_mrpm: u32) {
        if mode == PullerMode::Automatic && self.mode != PullerMode::Automatic {
            self.needs_preset = true;
            self.output_mrpm = puller_mrpm.clamp(self.settings.min_mrpm, self.settings.max_mrpm);
            self.stale = false;
        }
        self.mode = mode;
    }

    /// A measurement in centi-pixels. In automatic mode returns the new
    /// puller speed (milli-RPM); in manual mode `Ok(None)`.
    pub fn on_measurement(&mut self, cpx: u32, puller_mrpm: u32) -> Result<Option<u32>, DiameterError> {
        if cpx < u32::from(self.settings.min_valid_cpx) || cpx > u32::from(self.settings.max_valid_cpx) {
            return Err(DiameterError::Implausible);
        }
        self.last_cpx = Some(cpx as u16);
        self.age_s = 0;
        if self.mode != PullerMode::Automatic {
            return Ok(None);
        }
        if self.needs_preset || self.stale {
            self.pi.preset(puller_mrpm.clamp(self.settings.min_mrpm, self.settings.max_mrpm) as f32 / 1000.0);
            self.needs_preset = false;
            self.stale = false;
        }
        let error_px = (i32::from(self.settings.setpoint_cpx) - cpx as i32) as f32 / 100.0;
        let rpm = self.pi.update(error_px);
        let mrpm = if rpm.is_finite() { (rpm * 1000.0 + 0.5) as u32 } else { self.output_mrpm };
        self.output_mrpm = mrpm.clamp(self.settings.min_mrpm, self.settings.max_mrpm);
        Ok(Some(self.output_mrpm))
    }

    /// A measurement in µm.
    pub fn on_measurement_um(&mut self, um: u32, puller_mrpm: u32) -> Result<Option<u32>, DiameterError> {
        self.on_measurement(self.settings.cpx_from_um(um), puller_mrpm)
    }

    /// Once per second: the watchdog. In automatic mode, after
    /// `stale_after_s` seconds without a measurement, warns once; the
    /// puller keeps its speed (nothing to do for the caller but print).
    pub fn on_second(&mut self) -> Option<DiameterWarning> {
        self.age_s = self.age_s.saturating_add(1);
        if self.mode == PullerMode::Automatic && !self.stale && self.age_s >= u16::from(self.settings.stale_after_s.max(1)) {
            self.stale = true;
            return Some(DiameterWarning::Stale { seconds: self.age_s, held_mrpm: self.output_mrpm });
        }
        None
    }

    /// New setpoint (centi-pixels), within the plausible range.
    pub fn set_setpoint_cpx(&mut self, cpx: u32) -> Result<(), DiameterError> {
        if cpx < u32::from(self.settings.min_valid_cpx) || cpx > u32::from(self.settings.max_valid_cpx) {
            return Err(DiameterError::Implausible);
        }
        self.settings.setpoint_cpx = cpx as u16;
        Ok(())
    }

    pub fn set_setpoint_um(&mut self, um: u32) -> Result<(), DiameterError> {
        self.set_setpoint_cpx(self.settings.cpx_from_um(um))
    }

    /// Gains at run time (both ≤ 0: reverse acting).
    pub fn set_gains(&mut self, kp: f32, ki_per_sample: f32) -> Result<(), DiameterError> {
        if !(kp <= 0.0 && ki_per_sample <= 0.0 && kp > -1000.0 && ki_per_sample > -1000.0) {
            return Err(DiameterError::GainSign);
        }
        self.pi.set_gains(kp, ki_per_sample);
        Ok(())
    }

    pub fn gains(&self) -> (f32, f32) {
        self.pi.gains()
    }

    pub fn set_stale_after(&mut self, seconds: u8) {
        self.settings.stale_after_s = seconds.max(1);
    }

    pub fn settings(&self) -> &DiameterSettings {
        &self.settings
    }

    /// The last measurement (centi-pixels), if any.
    pub fn last_measurement_cpx(&self) -> Option<u16> {
        self.last_cpx
    }

    pub fn is_stale(&self) -> bool {
        self.stale
    }

    pub fn seconds_since_measurement(&self) -> u16 {
        self.age_s
    }

    /// The speed the loop last set (automatic mode).
    pub fn output_mrpm(&self) -> u32 {
        self.output_mrpm
    }

    pub fn pi(&self) -> &P {
        &self.pi
    }
}

/// [`PiLaw`] over the firmware's existing fixed-point loop law, the
/// closed-loop module's [`AxisController`] (PI gains, no derivative), until
/// the thermal module's PI lands (then implement [`PiLaw`] for that and
/// drop this adapter).
///
/// Mapping: output = centre + u, with centre = (min + max)/2 and
/// u ∈ ±(max − min)/2, so the controller's symmetric clamp is the 1–15 rpm
/// clamp; errors in centi-pixels, outputs in milli-RPM. The controller's
/// conditional integration assumes direct action, so it is fed
/// measured − setpoint with the gains' signs flipped (the same law).
/// Bumpless preset: the controller's feedforward input carries a bias
/// (preset − centre) and its integral restarts at zero. Limitation: the
/// integral alone spans ±(max − min)/2 around the bias, so after a preset
/// far from the centre the integral cannot reach the far limit by itself
/// (the proportional term still can); at the thesis' operating point
/// (≈ 4 rpm, centre 8 rpm) every speed from 1 to 11 rpm is reachable by
/// the integral alone.
#[derive(Clone, Copy, Debug)]
pub struct ClosedLoopPi {
    /// Fixed point on every board: a 1 Hz law, and its exact integral
    /// keeps the thesis' figures reproducible bit for bit.
    controller: AxisController<FixedPoint>,
    centre_mrpm: i32,
    bias_mrpm: i32,
    kp: f32,
    ki: f32,
    last_output_mrpm: i32,
}

impl Default for ClosedLoopPi {
    fn default() -> Self {
        Self::new()
    }
}

impl ClosedLoopPi {
    pub const fn new() -> Self {
        Self {
            controller: AxisController::new(Self::fixed(0.0, 0.0), 7_000, NO_FOLLOWING_LIMIT),
            centre_mrpm: 8_000,
            bias_mrpm: 0,
            kp: 0.0,
            ki: 0.0,
            last_output_mrpm: 8_000,
        }
    }

    /// rpm/px → mrpm/cpx is ×10; the sign flips (see the type's docs).
    const fn fixed(kp: f32, ki: f32) -> FixedGains {
        FixedGains {
            feedforward: Q16::ONE,
            proportional: Q16((-kp * 10.0 * 65536.0) as i32),
            integral_per_tick: Q16((-ki * 10.0 * 65536.0) as i32),
            derivative: Q16::ZERO,
            derivative_decay: Q16::ZERO,
            derivative_on: DerivativeOn::Error,
        }
    }

    fn restart_at(&mut self, output_mrpm: i32) {
        let limit = self.controller.output_limit();
        let output = output_mrpm.clamp(self.centre_mrpm - limit, self.centre_mrpm + limit);
        self.bias_mrpm = output - self.centre_mrpm;
        self.last_output_mrpm = output;
        self.controller.reset();
    }
}

/// The diameter loop has no following-error supervision.
const NO_FOLLOWING_LIMIT: FollowingErrorLimit = FollowingErrorLimit { limit: i32::MAX, hold_ticks: u16::MAX };

impl PiLaw for ClosedLoopPi {
    fn update(&mut self, error: f32) -> f32 {
        let scaled = error * 100.0;
        let error_cpx = if !scaled.is_finite() {
            0
        } else if scaled > 1.0e6 {
            1_000_000
        } else if scaled < -1.0e6 {
            -1_000_000
        } else if scaled >= 0.0 {
            (scaled + 0.5) as i32
        } else {
            (scaled - 0.5) as i32
        };
        let reference = Reference { position: -error_cpx, velocity: self.bias_mrpm };
        let u = self.controller.tick(reference, Ok(0), DriverStatus::default()).unwrap_or(self.bias_mrpm);
        self.last_output_mrpm = self.centre_mrpm + u;
        self.last_output_mrpm as f32 / 1000.0
    }

    fn preset(&mut self, output: f32) {
        let mrpm = if output.is_finite() { (output * 1000.0 + 0.5) as i32 } else { self.centre_mrpm };
        self.restart_at(mrpm);
    }

    fn set_gains(&mut self, kp: f32, ki_per_sample: f32) {
        self.kp = kp;
        self.ki = ki_per_sample;
        self.controller.set_gains(Self::fixed(kp, ki_per_sample));
        // the controller forgot its integral: carry the output in the bias
        self.restart_at(self.last_output_mrpm);
    }

    fn gains(&self) -> (f32, f32) {
        (self.kp, self.ki)
    }

    fn set_limits(&mut self, min: f32, max: f32) {
        let min = (min * 1000.0) as i32;
        let max = (max * 1000.0) as i32;
        self.centre_mrpm = (min + max) / 2;
        let limit = (max - min) / 2;
        self.controller = AxisController::new(Self::fixed(self.kp, self.ki), limit, NO_FOLLOWING_LIMIT);
        self.restart_at(self.last_output_mrpm);
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::string::String;
    use std::vec::Vec;

    /// A recording stand-in for the PI (not a controller: it only logs
    /// what the loop asks and answers `integral + kp·error`), so these
    /// tests check the loop's own duties.
    #[derive(Clone, Debug, Default)]
    pub struct Probe {
        pub presets: Vec<f32>,
        pub errors: Vec<f32>,
        pub gains: (f32, f32),
        pub limits: (f32, f32),
        pub integral: f32,
    }

    impl PiLaw for Probe {
        fn update(&mut self, error: f32) -> f32 {
            self.errors.push(error);
            (self.integral + self.gains.0 * error).clamp(self.limits.0, self.limits.1)
        }
        fn preset(&mut self, output: f32) {
            self.presets.push(output);
            self.integral = output;
        }
        fn set_gains(&mut self, kp: f32, ki: f32) {
            self.gains = (kp, ki);
        }
        fn gains(&self) -> (f32, f32) {
            self.gains
        }
        fn set_limits(&mut self, min: f32, max: f32) {
            self.limits = (min, max);
        }
    }

    fn looped() -> DiameterLoop<Probe> {
        let mut l = DiameterLoop::new(Probe::default(), DiameterSettings::THESIS);
        l.set_gains(THESIS_KP, THESIS_KI).unwrap();
        l
    }

    #[test]
    fn the_setpoint_is_2_85_mm_or_132_87_px() {
        let s = DiameterSettings::THESIS;
        assert_eq!(s.cpx_from_um(2_850), 13_287);
        assert_eq!(s.um_from_cpx(13_287), 2_850);
        // the thesis' 131 px = 2.81 mm and 120 px ≈ 2.574 mm
        assert_eq!(s.um_from_cpx(13_100), 2_810);
        assert_eq!(s.um_from_cpx(12_000), 2_574);
    }

    #[test]
    fn limits_are_1_to_15_rpm() {
        assert_eq!(looped().pi().limits, (1.0, 15.0));
    }

    #[test]
    fn manual_mode_records_measurements_and_never_moves_the_puller() {
        let mut l = looped();
        assert_eq!(l.on_measurement(14_000, 5_000), Ok(None));
        assert_eq!(l.last_measurement_cpx(), Some(14_000));
        assert!(l.pi().errors.is_empty());
    }

    #[test]
    fn automatic_mode_starts_bumplessly_from_the_pullers_speed() {
        let mut l = looped();
        l.set_mode(PullerMode::Automatic, 4_000);
        // at the setpoint the first output is the speed the puller had
        assert_eq!(l.on_measurement(13_287, 4_000), Ok(Some(4_000)));
        assert_eq!(l.pi().presets, [4.0]);
    }

    #[test]
    fn too_thick_pulls_faster_error_is_setpoint_minus_measured_in_px() {
        let mut l = looped();
        l.set_mode(PullerMode::Automatic, 4_000);
        let faster = l.on_measurement(13_387, 4_000).unwrap().unwrap();
        assert_eq!(l.pi().errors, [-1.0]);
        assert_eq!(faster, 4_070); // −0.07 · −1 px
    }

    #[test]
    fn implausible_measurements_are_refused_and_not_used() {
        let mut l = looped();
        l.set_mode(PullerMode::Automatic, 4_000);
        assert_eq!(l.on_measurement(0, 4_000), Err(DiameterError::Implausible));
        assert_eq!(l.on_measurement(50_000, 4_000), Err(DiameterError::Implausible));
        assert!(l.pi().errors.is_empty());
        assert_eq!(l.last_measurement_cpx(), None);
    }

    #[test]
    fn positive_gains_are_refused() {
        let mut l = looped();
        assert_eq!(l.set_gains(0.07, -0.004), Err(DiameterError::GainSign));
        assert_eq!(l.set_gains(-0.07, f32::NAN), Err(DiameterError::GainSign));
        assert_eq!(l.gains(), (THESIS_KP, THESIS_KI));
        l.set_gains(-0.05, -0.002).unwrap();
        assert_eq!(l.gains(), (-0.05, -0.002));
    }

    struct Out(String);
    impl ufmt::uWrite for Out {
        type Error = ();
        fn write_str(&mut self, s: &str) -> Result<(), ()> {
            self.0.push_str(s);
            Ok(())
        }
    }

    #[test]
    fn stale_measurements_hold_the_puller_warn_once_and_resume_bumplessly() {
        let mut l = looped();
        l.set_mode(PullerMode::Automatic, 4_000);
        let held = l.on_measurement(13_400, 4_000).unwrap().unwrap();
        for _ in 0..4 {
            assert_eq!(l.on_second(), None);
        }
        let warning = l.on_second().expect("warns at 5 s");
        assert_eq!(warning, DiameterWarning::Stale { seconds: 5, held_mrpm: held });
        let mut out = Out(String::new());
        warning.write(&mut out).unwrap();
        assert_eq!(out.0, "echo:Diameter measurement stale (5 s), puller held at 4.079 rpm\n");
        assert_eq!(l.on_second(), None, "once");
        assert!(l.is_stale());
        // the next measurement presets from the speed the puller holds
        l.on_measurement(13_287, held).unwrap();
        assert_eq!(l.pi().presets, [4.0, held as f32 / 1000.0]);
        assert!(!l.is_stale());
    }

    #[test]
    fn no_watchdog_in_manual_mode() {
        let mut l = looped();
        for _ in 0..100 {
            assert_eq!(l.on_second(), None);
        }
    }

    #[test]
    fn the_setpoint_is_settable_in_mm_or_px() {
        let mut l = looped();
        l.set_setpoint_um(2_574).unwrap();
        assert_eq!(l.settings().setpoint_cpx, 12_000);
        l.set_setpoint_cpx(13_290).unwrap();
        assert_eq!(l.settings().setpoint_cpx, 13_290);
        assert_eq!(l.set_setpoint_cpx(100), Err(DiameterError::Implausible));
    }

    #[test]
    fn the_adapter_is_the_thesis_pi_with_clamp_and_anti_windup() {
        let mut pi = ClosedLoopPi::new();
        pi.set_limits(1.0, 15.0);
        pi.set_gains(THESIS_KP, THESIS_KI);
        pi.preset(4.0);
        // zero error: the preset comes out
        assert!((pi.update(0.0) - 4.0).abs() < 1e-3);
        // −1 px (too thick): P gives +0.07, the integral +0.004 per sample
        assert!((pi.update(-1.0) - 4.074).abs() < 1e-3, "{}", pi.update(0.0));
        let mut pi = ClosedLoopPi::new();
        pi.set_limits(1.0, 15.0);
        pi.set_gains(THESIS_KP, THESIS_KI);
        pi.preset(4.0);
        pi.update(-1.0);
        let after = pi.update(0.0);
        // 0.04 mrpm/cpx is 2621/65536 in Q16: 3.999 mrpm, floored to 3
        assert!((after - 4.004).abs() <= 1.01e-3, "{after}");
        // saturate for a long time, then come back at once (no windup)
        for _ in 0..10_000 {
            assert!(pi.update(-200.0) <= 15.0);
        }
        assert!((pi.update(-200.0) - 15.0).abs() < 1e-3);
        let back = pi.update(10.0);
        assert!(back < 15.0, "leaves the limit as soon as the error turns: {back}");
        for _ in 0..10_000 {
            assert!(pi.update(200.0) >= 1.0);
        }
        assert!((pi.update(200.0) - 1.0).abs() < 1e-3);
    }

    #[test]
    fn the_adapter_changes_gains_without_a_bump() {
        let mut pi = ClosedLoopPi::new();
        pi.set_limits(1.0, 15.0);
        pi.set_gains(THESIS_KP, THESIS_KI);
        pi.preset(4.0);
        for _ in 0..50 {
            pi.update(-2.0);
        }
        let before = pi.update(0.0);
        pi.set_gains(-0.05, -0.002);
        assert!((pi.update(0.0) - before).abs() < 1e-3);
        assert_eq!(pi.gains(), (-0.05, -0.002));
    }
}
