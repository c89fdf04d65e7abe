//! The executor's heaters: `M104`/`M109`, `M140`/`M190`, `M105`, `M155`,
//! `M301`, `M302`, `M303`, and the boards' sample hook
//! ([`Machine::on_thermal_samples`]).
//!
//! The thermal core (`crate::thermal`) decides; this file only routes
//! G-code to it and its verdicts back to the host, in Marlin's words:
//! - a latched fault prints its `Error:… Heater_ID: …` line and halts the
//!   machine (`kill`): heaters off, motion stopped, moves and heating
//!   refused until reset;
//! - `M109`/`M190` wait with Marlin's residency rule and print the `M105`
//!   line with ` W:<s>` once a second while they wait; `M108` ends the
//!   wait;
//! - `M303 E<n> S<°C> C<cycles> U1` tunes, prints each cycle and Marlin's
//!   closing block, and with `U1` applies the gains (`M500` saves them).

use super::{Machine, Running};
use crate::thermal::channel::TuningStep;
use crate::thermal::{write_temperatures, Gains, HeaterChannel, Oversampled, WaitStatus};
// The heater commands (not on the powder bed, which has no heaters).
#[cfg(feature = "heaters")]
use super::error::CommandError;
#[cfg(feature = "heaters")]
use super::Outcome;
#[cfg(feature = "heaters")]
use crate::gcode::Command;
#[cfg(feature = "heaters")]
use crate::thermal::{Autotune, Celsius, TemperatureWait, TuneConfig, WaitConfig};
use ufmt::uWrite;

/// Which of the machine's heaters a command means.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum HeaterSlot {
    Hotend,
    Bed,
}

/// Stored gains into a channel when they are valid (one copy for both
/// heaters).
#[inline(never)]
fn load_gains(channel: &mut HeaterChannel, &[kp, ki, kd]: &[i32; 3]) {
    if let Some(gains) = Gains::new(kp, ki, kd) {
        channel.set_gains(gains);
    }
}

impl<'q> Machine<'q> {
    fn channel(&mut self, slot: HeaterSlot) -> &mut HeaterChannel {
        match slot {
            HeaterSlot::Hotend => &mut self.hotend,
            HeaterSlot::Bed => &mut self.bed,
        }
    }

    /// Every sample period (100 ms): the averaged thermistor readings
    /// (`None`: no new reading this period). Runs the heater laws and
    /// protections, the `M303` tune, and reports a fault once.
    #[inline(never)]
    pub fn on_thermal_samples<W: uWrite + ?Sized>(
        &mut self,
        hotend: Option<Oversampled>,
        bed: Option<Oversampled>,
        out: &mut W,
    ) -> Result<(), W::Error> {
        let tuning = match self.running {
            Running::Autotune { slot, .. } => Some(slot),
            _ => None,
        };
        self.heater_sample(HeaterSlot::Hotend, hotend, tuning, out)?;
        self.heater_sample(HeaterSlot::Bed, bed, tuning, out)
    }

    /// One heater's part of [`on_thermal_samples`](Self::on_thermal_samples).
    #[inline(never)]
    fn heater_sample<W: uWrite + ?Sized>(&mut self, slot: HeaterSlot, reading: Option<Oversampled>, tuning: Option<HeaterSlot>, out: &mut W) -> Result<(), W::Error> {
        let Some(reading) = reading else { return Ok(()) };
        if tuning == Some(slot) {
            return self.tuning_sample(slot, reading, out);
        }
        if let Some(fault) = self.channel(slot).on_sample(reading) {
            let id = self.channel(slot).id();
            fault.write(id, out)?;
            self.kill(out)?;
        }
        Ok(())
    }

    fn tuning_sample<W: uWrite + ?Sized>(&mut self, slot: HeaterSlot, reading: Oversampled, out: &mut W) -> Result<(), W::Error> {
        // The tune is updated where it lies (no copy of it on the stack):
        // the channel and `running` are disjoint fields.
        let channel = match slot {
            HeaterSlot::Hotend => &mut self.hotend,
            HeaterSlot::Bed => &mut self.bed,
        };
        let Running::Autotune { slot: _, apply, ref mut tune } = self.running else { return Ok(()) };
        // The result stays in the tune (`last_cycle().result`): no copy.
        let progress = channel.tuning_step(reading, tune);
        if let TuningStep::Cycle = progress {
            tune.last_cycle().write(out)?;
        }
        let id = channel.id();
        match progress {
            TuningStep::Running | TuningStep::Cycle => {}
            TuningStep::Done => {
                let Some(result) = &tune.last_cycle().result else { return Ok(()) };
                result.write_finished(id, out)?;
                let gains = result.gains;
                if apply {
                    self.channel(slot).set_gains(gains);
                    self.store_gains(slot, gains);
                }
                self.running = Running::AutotuneDone;
            }
            TuningStep::Failed(error) => {
                error.write(out)?;
                self.running = Running::AutotuneDone;
            }
            TuningStep::Fault(fault) => {
                fault.write(id, out)?;
                self.kill(out)?;
            }
        }
        Ok(())
    }

    fn store_gains(&mut self, slot: HeaterSlot, gains: Gains) {
        let stored = [gains.kp as i32, gains.ki as i32, gains.kd as i32];
        match slot {
            HeaterSlot::Hotend => self.settings.hotend_pid = stored,
            HeaterSlot::Bed => self.settings.bed_pid = stored,
        }
    }

    /// The settings' gains into the channels (boot, `M501`, `M502`).
    pub(super) fn apply_heater_settings(&mut self) {
        load_gains(&mut self.hotend, &self.settings.hotend_pid);
        load_gains(&mut self.bed, &self.settings.bed_pid);
    }

    /// Drive the bed with `config` instead of RAMPS' MOSFET bed (e.g.
    /// [`BED_SSR`](crate::thermal::channel::BED_SSR) for a solid-state
    /// relay), keeping the gains; the board calls it at boot, before any
    /// command.
    pub fn use_bed_config(&mut self, config: &'static crate::progmem::Flash<crate::thermal::HeaterConfig>) {
        self.bed = HeaterChannel::new(config, self.bed.gains());
    }

    /// The 16×2 status screen (`drivers::status_screen`): what the machine
    /// is doing, Z, and the heaters (`Printing    Z0.20` /
    /// `T210/210 B60/60`).
    pub fn status_screen(&self) -> [u8; 32] {
        // The powder bed shows its job, not heaters it does not have.
        #[cfg(feature = "powder-bed")]
        if let Some(bed) = &self.powder {
            return bed.screen(self.halted);
        }
        let state = if self.halted {
            "Halted"
        } else {
            match self.running {
                Running::Homing => "Homing",
                Running::HeatWait { .. } => "Heating",
                Running::Autotune { .. } => "PID tuning",
                _ if !self.motion.is_idle() => "Printing",
                _ => "Ready",
            }
        };
        let temperature = |label, channel: &HeaterChannel| crate::drivers::status_screen::Temperature {
            label,
            measured: channel.measured(),
            target: channel.target(),
        };
        crate::drivers::status_screen::format_status(
            state,
            Some((b'Z', self.modal.logical_position()[2])),
            &[temperature(b'T', &self.hotend), temperature(b'B', &self.bed)],
        )
    }

    /// Duties for the heater outputs (hot end, bed), 0–255; 0 when halted.
    pub fn heater_duties(&self) -> (u8, u8) {
        if self.halted {
            (0, 0)
        } else {
            (self.hotend.duty(), self.bed.duty())
        }
    }

    /// Whether the hot end may push filament (`M302`'s interlock).
    pub fn extrusion_allowed(&self) -> bool {
        self.cold_extrusion.check(self.hotend.measured()).is_ok()
    }

    /// ` T:… /… B:… /… @:… B@:…` (used by `M105` and auto-reports).
    pub fn write_temperatures<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        write_temperatures(&self.hotend, Some(&self.bed), out)
    }

    #[cfg(feature = "heaters")]
    /// `M104`/`M140` (`wait: None`) and `M109`/`M190`: set the target;
    /// the waits start a [`Running::HeatWait`].
    pub(super) fn set_temperature<W: uWrite + ?Sized>(
        &mut self,
        command: &Command,
        slot: HeaterSlot,
        wait: Option<WaitConfig>,
        now_ms: u32,
        out: &mut W,
    ) -> Result<Outcome, W::Error> {
        let (value, cooling) = match (command.value(b'S'), command.value(b'R')) {
            (Ok(Some(s)), _) => (Some(s), false),
            (_, Ok(Some(r))) if wait.is_some() => (Some(r), true),
            (Err(e), _) | (_, Err(e)) => return Ok(Outcome::Failed(e.into())),
            _ => (None, false),
        };
        let Some(value) = value else { return Ok(Outcome::Done) };
        let Some(hundredths) = value.to_scaled(2) else {
            return Ok(Outcome::Failed(CommandError::OutOfRange(if cooling { b'R' } else { b'S' })));
        };
        let target = match self.channel(slot).set_target(Celsius(hundredths)) {
            Ok(target) => target,
            Err(fault) => {
                let id = self.channel(slot).id();
                fault.write(id, out)?;
                return Ok(Outcome::Failed(CommandError::Halted));
            }
        };
        Ok(match wait {
            None => Outcome::Done,
            Some(config) => {
                self.last_report_ms = now_ms;
                self.start(Running::HeatWait { slot, wait: TemperatureWait::new(config, target, cooling, now_ms) })
            }
        })
    }

    /// A running `M109`/`M190`: done when the wait says so; the `M105`
    /// line with ` W:` once a second meanwhile (Marlin's keep-alive while
    /// heating, so hosts see no `busy:` lines then).
    pub(super) fn heat_wait_done<W: uWrite + ?Sized>(&mut self, now_ms: u32, out: &mut W) -> Result<bool, W::Error> {
        let Running::HeatWait { slot, ref mut wait } = self.running else { return Ok(true) };
        let measured = match slot {
            HeaterSlot::Hotend => self.hotend.measured(),
            HeaterSlot::Bed => self.bed.measured(),
        };
        let status = wait.poll(now_ms, measured);
        match status {
            WaitStatus::Waiting(left) => {
                if now_ms.wrapping_sub(self.last_report_ms) >= 1000 {
                    self.last_report_ms = now_ms;
                    // Marlin's format: the report without its newline, then W.
                    out.write_str(" ")?;
                    crate::thermal::report::write_temperature_fields(&self.hotend, Some(&self.bed), out)?;
                    out.write_str(" W:")?;
                    match left {
                        Some(s) => ufmt::uwrite!(out, "{}\n", crate::reply::Whole(s.into()))?,
                        None => out.write_str("?\n")?,
                    }
                }
                // Keeps the executor from printing `busy:` as well.
                self.last_busy_ms = now_ms;
                Ok(false)
            }
            WaitStatus::Reached | WaitStatus::CoolingStalled => Ok(true),
            WaitStatus::TimedOut => {
                out.write_str("Error:Heating timed out\n")?;
                Ok(true)
            }
        }
    }

    #[cfg(feature = "heaters")]
    /// `M301 [P] [I] [D]` (hot end, Marlin's units): set what is given;
    /// bare `M301` reports.
    /// `M301` (hot end) and `M304` (bed): `P`, `I`, `D` in Marlin's units;
    /// without any, the current gains.
    pub(super) fn set_pid<W: uWrite + ?Sized>(&mut self, command: &Command, slot: HeaterSlot, out: &mut W) -> Result<(), CommandError> {
        let current = self.channel(slot).gains();
        if !(command.has(b'P') || command.has(b'I') || command.has(b'D')) {
            let _ = out.write_str("echo:");
            let _ = current.write_as(if slot == HeaterSlot::Bed { 304 } else { 301 }, out);
            let _ = out.write_str("\n");
            return Ok(());
        }
        // Each given word replaces its gain (× 10⁴), read by the settings'
        // reader; the gains' own bounds are checked together after.
        let mut values = [current.kp as i32, current.ki as i32, current.kd as i32];
        for (value, &letter) in values.iter_mut().zip(b"PID") {
            super::set_scaled(command, letter, 4, i32::MIN, i32::MAX, value)?;
        }
        let [kp, ki, kd] = values;
        let gains = Gains::new(kp, ki, kd).ok_or(CommandError::OutOfRange(b'P'))?;
        self.channel(slot).set_gains(gains);
        self.store_gains(slot, gains);
        Ok(())
    }

    #[cfg(feature = "heaters")]
    /// `M302 [S<°C>] [P<0|1>]`: the cold-extrusion interlock.
    pub(super) fn cold_extrusion_command<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W) -> Result<(), CommandError> {
        // Both words by the settings' reader; −1 (outside S's range) and
        // `has` tell whether each was given.
        let mut min = -1;
        super::set_scaled(command, b'S', 0, 0, 1000, &mut min)?;
        let min = (min >= 0).then(|| Celsius(min * 100));
        let mut allow = 0;
        super::set_scaled(command, b'P', 0, i32::MIN, i32::MAX, &mut allow)?;
        let allow = command.has(b'P').then_some(allow != 0);
        if self.cold_extrusion.m302(min, allow) {
            let _ = self.cold_extrusion.write_state(out);
        }
        Ok(())
    }

    #[cfg(feature = "heaters")]
    /// `M303 E<0|-1> S<°C> C<cycles> [U1]`: relay auto-tune of the hot end
    /// (`E0`) or the bed (`E-1`).
    pub(super) fn autotune<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W) -> Result<Outcome, W::Error> {
        // Each word through the settings' reader (`set_scaled`: a whole
        // number within its range, else out of range; absent, the default).
        let parsed = (|| -> Result<(HeaterSlot, i32, u8, bool), CommandError> {
            let mut e = 0;
            super::set_scaled(command, b'E', 0, -1, 0, &mut e)?;
            let slot = if e == 0 { HeaterSlot::Hotend } else { HeaterSlot::Bed };
            let mut target = if slot == HeaterSlot::Bed { 70 } else { 150 };
            super::set_scaled(command, b'S', 0, 1, 400, &mut target)?;
            let mut cycles = 5;
            super::set_scaled(command, b'C', 0, 3, 20, &mut cycles)?;
            let mut apply = 0;
            super::set_scaled(command, b'U', 0, i32::MIN, i32::MAX, &mut apply)?;
            Ok((slot, target, cycles as u8, apply != 0))
        })();
        let (slot, target, cycles, apply) = match parsed {
            Ok(p) => p,
            Err(e) => return Ok(Outcome::Failed(e)),
        };
        let period = self.channel(slot).config().sample_period_ms;
        let tune = Autotune::new(TuneConfig { cycles, ..TuneConfig::new(Celsius(target * 100), period) });
        if let Err(fault) = self.channel(slot).start_tuning(&tune) {
            let id = self.channel(slot).id();
            fault.write(id, out)?;
            return Ok(Outcome::Failed(CommandError::Halted));
        }
        crate::flash_str!("PID Autotune start\n").write_to(out)?;
        Ok(self.start(Running::Autotune { slot, apply, tune }))
    }
}
