//! The filament extrusion line (SPEC §4) as the executor drives it: the
//! screw and the puller as velocity-mode steppers, the diameter loop, and
//! the cold-extrusion interlock on the screw.
//!
//! The barrel heater (PI on the SSR's slow PWM), its thermistor and the
//! fans belong to the thermal module; this module only asks it whether the
//! screw may turn, through [`ColdExtrusionCheck`] (the thermal module's
//! cold-extrusion check, configured at 175 °C for this machine, with
//! `M302 P1` as the explicit override).

use super::diameter::{DiameterError, DiameterLoop, DiameterSettings, DiameterWarning, PiLaw, PullerMode};
use super::velocity::{DriveTrain, SpeedError, TimerChange, VelocityConfig, VelocityConfigError, VelocityStepper, MEGA_STEP_TIMER_HZ};
use crate::thermal::Celsius;

/// The screw's interlock temperature (SPEC §4).
pub const MIN_EXTRUSION_TEMPERATURE: Celsius = Celsius::from_degrees(175);

/// Whether the barrel is hot enough to turn the screw. Implemented by the
/// thermal module's cold-extrusion check (min temperature configurable,
/// `M302 S<°C>`; `M302 P1` overrides).
pub trait ColdExtrusionCheck {
    /// `Ok` when hot enough or overridden; otherwise the measured and the
    /// minimum temperature.
    fn check(&self) -> Result<(), ColdExtrusion>;
}

/// The barrel is too cold to turn the screw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ColdExtrusion {
    pub measured: Celsius,
    pub minimum: Celsius,
}

impl ColdExtrusion {
    /// `Error:Cold extrusion prevented: barrel 24.00 C, minimum 175.00 C (M302 P1 overrides)`
    pub fn write_refused<W: ufmt::uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        crate::flash_str!("Error:Cold extrusion prevented: barrel ").write_to(out)?;
        ufmt::uwrite!(out, "{}", self.measured)?;
        crate::flash_str!(" C, minimum ").write_to(out)?;
        ufmt::uwrite!(out, "{}", self.minimum)?;
        crate::flash_str!(" C (M302 P1 overrides)\n").write_to(out)
    }

    /// `Error:Barrel cooled to 170.00 C (minimum 175.00 C): screw stopped`
    pub fn write_stopped<W: ufmt::uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        crate::flash_str!("Error:Barrel cooled to ").write_to(out)?;
        ufmt::uwrite!(out, "{}", self.measured)?;
        crate::flash_str!(" C (minimum ").write_to(out)?;
        ufmt::uwrite!(out, "{}", self.minimum)?;
        crate::flash_str!(" C): screw stopped\n").write_to(out)
    }
}

/// Why the screw was not started.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScrewError {
    Cold(ColdExtrusion),
    Speed(SpeedError),
}

/// Constants of the line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExtrusionLineConfig {
    pub extruder: VelocityConfig,
    pub puller: VelocityConfig,
    pub diameter: DiameterSettings,
}

/// Ramp updates per second for both steppers (every 20 ms of the 1 kHz tick).
pub const RAMP_UPDATES_PER_S: u16 = 50;

impl ExtrusionLineConfig {
    /// SPEC §4: extruder 3000 steps/rev at 1/16 (up to 20 rpm, ours), the
    /// puller at 1/32 with `puller` (6:1 in the thesis code, 4:1 in its
    /// table) up to 15 rpm; both ramp at 5 rpm/s (ours), on the Mega's
    /// 2 MHz step timer.
    pub const fn thesis(puller: DriveTrain) -> Result<Self, VelocityConfigError> {
        let extruder = match VelocityConfig::new(DriveTrain::EXTRUDER_SCREW, MEGA_STEP_TIMER_HZ, 20, 5, RAMP_UPDATES_PER_S) {
            Ok(config) => config,
            Err(error) => return Err(error),
        };
        let puller = match VelocityConfig::new(puller, MEGA_STEP_TIMER_HZ, 15, 5, RAMP_UPDATES_PER_S) {
            Ok(config) => config,
            Err(error) => return Err(error),
        };
        Ok(Self { extruder, puller, diameter: DiameterSettings::THESIS })
    }
}

/// What happened in a second that the host must hear about.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SecondReport {
    pub diameter: Option<DiameterWarning>,
    /// The barrel fell below the minimum while the screw turned: the screw
    /// was stopped (print [`ColdExtrusion::write_stopped`]).
    pub screw_stopped: Option<ColdExtrusion>,
}

/// The line's running state (≈ 40 bytes + the PI).
#[derive(Clone, Copy, Debug)]
pub struct ExtrusionLine<P> {
    pub extruder: VelocityStepper,
    pub puller: VelocityStepper,
    pub diameter: DiameterLoop<P>,
}

impl<P: PiLaw> ExtrusionLine<P> {
    pub fn new(pi: P, config: &ExtrusionLineConfig) -> Self {
        Self { extruder: VelocityStepper::new(), puller: VelocityStepper::new(), diameter: DiameterLoop::new(pi, config.diameter) }
    }

    /// `M3 S<rpm>`: run the screw, if the barrel is hot enough (or the
    /// check overridden). 0 stops it (always allowed).
    pub fn set_screw(&mut self, config: &ExtrusionLineConfig, mrpm: u32, barrel: &impl ColdExtrusionCheck) -> Result<(), ScrewError> {
        if mrpm > 0 {
            barrel.check().map_err(ScrewError::Cold)?;
        }
        self.extruder.set_target(&config.extruder, mrpm).map_err(ScrewError::Speed)
    }

    /// `M860 S<rpm>`: the puller at a fixed speed; the puller goes to
    /// manual mode.
    pub fn set_puller_manual(&mut self, config: &ExtrusionLineConfig, mrpm: u32) -> Result<(), SpeedError> {
        self.puller.set_target(&config.puller, mrpm)?;
        self.diameter.set_mode(PullerMode::Manual, self.puller.current_mrpm());
        Ok(())
    }

    /// `M405` / `M406`: automatic diameter control on / off. Off leaves the
    /// puller at the speed it runs at.
    pub fn set_automatic(&mut self, config: &ExtrusionLineConfig, on: bool) {
        let now = self.puller.current_mrpm();
        if on {
            self.diameter.set_mode(PullerMode::Automatic, now);
        } else {
            self.diameter.set_mode(PullerMode::Manual, now);
            let _ = self.puller.set_target(&config.puller, now);
        }
    }

    /// `M861 P<px>` / `D<mm>`: one measurement from the camera (centi-px).
    /// In automatic mode the puller gets a new set speed.
    pub fn on_measurement_cpx(&mut self, config: &ExtrusionLineConfig, cpx: u32) -> Result<(), DiameterError> {
        let now = self.puller.current_mrpm();
        if let Some(mrpm) = self.diameter.on_measurement(cpx, now)? {
            // within 1–15 rpm by the loop's limits, which the config allows
            let _ = self.puller.set_target(&config.puller, mrpm);
        }
        Ok(())
    }

    /// Once per second from the main loop: the diameter watchdog and the
    /// interlock (a barrel that cools below the minimum stops the screw).
    pub fn on_second(&mut self, barrel: &impl ColdExtrusionCheck) -> SecondReport {
        let mut report = SecondReport { diameter: self.diameter.on_second(), screw_stopped: None };
        if self.extruder.target_mrpm() > 0 || self.extruder.is_running() {
            if let Err(cold) = barrel.check() {
                self.extruder.halt();
                report.screw_stopped = Some(cold);
            }
        }
        report
    }

    /// The ramp tick ([`RAMP_UPDATES_PER_S`]): (extruder, puller) timer changes.
    pub fn update(&mut self, config: &ExtrusionLineConfig) -> (TimerChange, TimerChange) {
        (self.extruder.update(&config.extruder), self.puller.update(&config.puller))
    }

    /// `M112`, a driver fault: both motors stop now.
    pub fn halt(&mut self) -> (TimerChange, TimerChange) {
        self.diameter.set_mode(PullerMode::Manual, 0);
        (self.extruder.halt(), self.puller.halt())
    }

    /// `M407`: `echo:Diameter 2.851 mm (132.91 px) setpoint 2.850 mm (132.87 px) puller 3.912 rpm auto`
    /// (`no measurement` before the first, `stale 7 s` when stale).
    pub fn write_report<W: ufmt::uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        let settings = self.diameter.settings();
        crate::flash_str!("echo:Diameter ").write_to(out)?;
        match self.diameter.last_measurement_cpx() {
            Some(cpx) => write_mm_px(out, settings, u32::from(cpx))?,
            None => crate::flash_str!("no measurement").write_to(out)?,
        }
        crate::flash_str!(" setpoint ").write_to(out)?;
        write_mm_px(out, settings, u32::from(settings.setpoint_cpx))?;
        crate::flash_str!(" puller ").write_to(out)?;
        super::diameter::write_milli(out, self.puller.current_mrpm())?;
        out.write_str(" rpm ")?;
        out.write_str(match self.diameter.mode() {
            PullerMode::Automatic => "auto",
            PullerMode::Manual => "manual",
        })?;
        if self.diameter.is_stale() {
            ufmt::uwrite!(out, " stale {} s", self.diameter.seconds_since_measurement())?;
        }
        out.write_str("\n")
    }
}

/// `2.851 mm (132.91 px)`
pub fn write_mm_px<W: ufmt::uWrite + ?Sized>(out: &mut W, settings: &DiameterSettings, cpx: u32) -> Result<(), W::Error> {
    super::diameter::write_milli(out, settings.um_from_cpx(cpx))?;
    ufmt::uwrite!(out, " mm ({}.", cpx / 100)?;
    if cpx % 100 < 10 {
        out.write_str("0")?;
    }
    ufmt::uwrite!(out, "{} px)", cpx % 100)
}

#[cfg(test)]
mod tests {
    use super::super::diameter::tests::Probe;
    use super::super::diameter::{THESIS_KI, THESIS_KP};
    use super::*;
    use std::string::String;

    struct Barrel {
        measured: Celsius,
        overridden: bool,
    }

    impl ColdExtrusionCheck for Barrel {
        fn check(&self) -> Result<(), ColdExtrusion> {
            if self.overridden || self.measured >= MIN_EXTRUSION_TEMPERATURE {
                Ok(())
            } else {
                Err(ColdExtrusion { measured: self.measured, minimum: MIN_EXTRUSION_TEMPERATURE })
            }
        }
    }

    fn cold() -> Barrel {
        Barrel { measured: Celsius(2400), overridden: false }
    }

    fn hot() -> Barrel {
        Barrel { measured: Celsius(21_000), overridden: false }
    }

    struct Out(String);
    impl ufmt::uWrite for Out {
        type Error = ();
        fn write_str(&mut self, s: &str) -> Result<(), ()> {
            self.0.push_str(s);
            Ok(())
        }
    }

    fn line() -> (ExtrusionLine<Probe>, ExtrusionLineConfig) {
        let config = ExtrusionLineConfig::thesis(DriveTrain::PULLER_6_TO_1).unwrap();
        let mut line = ExtrusionLine::new(Probe::default(), &config);
        line.diameter.set_gains(THESIS_KP, THESIS_KI).unwrap();
        (line, config)
    }

    #[test]
    fn the_screw_does_not_turn_below_175_c() {
        let (mut line, config) = line();
        let refused = line.set_screw(&config, 10_000, &cold());
        let Err(ScrewError::Cold(refusal)) = refused else { panic!("{refused:?}") };
        assert_eq!(line.extruder.target_mrpm(), 0);
        let mut out = Out(String::new());
        refusal.write_refused(&mut out).unwrap();
        assert_eq!(out.0, "Error:Cold extrusion prevented: barrel 24.00 C, minimum 175.00 C (M302 P1 overrides)\n");
        // stopping is always allowed
        line.set_screw(&config, 0, &cold()).unwrap();
    }

    #[test]
    fn the_override_lets_a_cold_screw_turn() {
        let (mut line, config) = line();
        line.set_screw(&config, 10_000, &Barrel { overridden: true, ..cold() }).unwrap();
        assert_eq!(line.extruder.target_mrpm(), 10_000);
    }

    #[test]
    fn a_barrel_that_cools_stops_the_screw() {
        let (mut line, config) = line();
        line.set_screw(&config, 10_000, &hot()).unwrap();
        line.update(&config);
        assert!(line.extruder.is_running());
        assert_eq!(line.on_second(&hot()).screw_stopped, None);
        let report = line.on_second(&Barrel { measured: Celsius(17_000), overridden: false });
        assert_eq!(report.screw_stopped, Some(ColdExtrusion { measured: Celsius(17_000), minimum: MIN_EXTRUSION_TEMPERATURE }));
        assert!(!line.extruder.is_running());
        let mut out = Out(String::new());
        report.screw_stopped.unwrap().write_stopped(&mut out).unwrap();
        assert_eq!(out.0, "Error:Barrel cooled to 170.00 C (minimum 175.00 C): screw stopped\n");
    }

    #[test]
    fn manual_and_automatic_puller_modes_are_distinct() {
        let (mut line, config) = line();
        line.set_puller_manual(&config, 4_000).unwrap();
        while !line.puller.at_speed() {
            line.update(&config);
        }
        // manual: a measurement does not move the puller
        line.on_measurement_cpx(&config, 14_000).unwrap();
        assert_eq!(line.puller.target_mrpm(), 4_000);
        // automatic: it does, starting from 4 rpm
        line.set_automatic(&config, true);
        line.on_measurement_cpx(&config, 14_000).unwrap();
        assert_eq!(line.diameter.pi().presets, [4.0]);
        assert!(line.puller.target_mrpm() > 4_000, "too thick: pull faster");
        // a manual speed ends automatic mode
        line.set_puller_manual(&config, 3_000).unwrap();
        assert_eq!(line.diameter.mode(), PullerMode::Manual);
    }

    #[test]
    fn automatic_off_keeps_the_puller_where_it_is() {
        let (mut line, config) = line();
        line.set_puller_manual(&config, 4_000).unwrap();
        for _ in 0..20 {
            line.update(&config);
        }
        let now = line.puller.current_mrpm();
        line.set_automatic(&config, true);
        line.set_automatic(&config, false);
        assert_eq!(line.puller.target_mrpm(), now);
    }

    #[test]
    fn report_line() {
        let (mut line, config) = line();
        let mut out = Out(String::new());
        line.write_report(&mut out).unwrap();
        assert_eq!(out.0, "echo:Diameter no measurement setpoint 2.850 mm (132.87 px) puller 0.000 rpm manual\n");
        line.on_measurement_cpx(&config, 13_291).unwrap();
        let mut out = Out(String::new());
        line.write_report(&mut out).unwrap();
        assert_eq!(out.0, "echo:Diameter 2.851 mm (132.91 px) setpoint 2.850 mm (132.87 px) puller 0.000 rpm manual\n");
    }

    #[test]
    fn the_4_to_1_puller_is_a_configuration() {
        let config = ExtrusionLineConfig::thesis(DriveTrain::PULLER_4_TO_1).unwrap();
        assert_eq!(config.puller.drive.steps_per_rev(), 800);
    }

    #[test]
    fn state_is_small() {
        // two steppers and the loop, without the PI
        assert!(core::mem::size_of::<ExtrusionLine<()>>() <= 80, "{}", core::mem::size_of::<ExtrusionLine<()>>());
    }
}
