//! `M820`–`M824`: the printer's encoder loops on X and Y (SPEC §1; how
//! the loops work: [`crate::closed_loop::printer`]).
//!
//! The loops run in the board's timer tick, so the executor only keeps
//! what the host chose and hands it over: [`Machine::take_encoder_settings`]
//! (one axis per call, with its gains computed here in the main loop),
//! [`Machine::take_encoder_rehome`] after a homing. The board reports
//! back with [`Machine::set_encoder_reports`] (what `M822` prints) and
//! [`Machine::on_encoder_fault`] (an `Error:` line, the job stopped, moves
//! refused until `G28`, like a driver alarm).
//!
//! | command | effect | reply (then `ok`) |
//! |---|---|---|
//! | `M820 [X0/1] [Y0/1]` | loop off/on per axis (all off at boot) | `echo:Closed loop X:1 Y:0` |
//! | `M821 X\|Y S<0-2> [P<kp>] [G<γ>]` | S0 open loop (lost-step detection only), S1 P (P, default 4.3/s), S2 robust PID (G, default 0.5) | `echo:X S2 P4.300 G0.500 theta 0.020 s` |
//! | `M822` | encoder and loop report | `echo:X loop:1 enc:12.345 ref:12.340 err:-0.005 corr:-2 idx:6 glitch:0 bounce:0 missed:0 bad:0 fault:none` |
//! | `M823 X\|Y E<mm> [T<s>]` | following-error limit and how long it may last | `echo:X following error 1.000 mm for 0.500 s` |
//! | `M824 X\|Y T<θ s>` | the dead time the robust PID is tuned for | `echo:X S2 P4.300 G0.500 theta 0.020 s` |
//! | `M828 S1` / `S0` | start / stop streaming every loop sample (raw X/Y counts, Index edges, commanded steps) as `TR:` lines; bare: report | `TR:start 250 100000 100000`; after `S0`: `TR:end <recorded> <dropped>`; bare: `echo:Trace off` |
//!
//! Without an axis letter `M821`, `M823` and `M824` report both axes.
//! Bad values answer `Error:Value out of range for <letter>` and change
//! nothing. Not saved by `M500` (ours: a loop switched on by a stored
//! setting on a board whose encoder is unplugged would stop every job).

use super::commands::{Listing, Machines};
use super::{CommandError, Machine};
use crate::closed_loop::control::{FollowingErrorLimit, LoopGains};
use crate::closed_loop::printer::{AxisReport, LoopSettings, AXES, AXIS_LETTERS, LOOP_HZ};
use crate::closed_loop::{AxisFault, Strategy};
use crate::gcode::{Code, Command};
use crate::flash_str;
use crate::progmem::FlashStr;
use crate::reply::Fixed;
use ufmt::{uDisplay, uWrite};

/// `label` (kept in flash: on the AVR a `uwrite!` literal costs SRAM)
/// then `value`.
fn field<W: uWrite + ?Sized>(out: &mut W, label: FlashStr, value: impl uDisplay) -> Result<(), W::Error> {
    label.write_to(out)?;
    ufmt::uwrite!(out, "{}", value)
}

/// `echo:X` (the reply lines' common start).
fn echo_axis<W: uWrite + ?Sized>(out: &mut W, letter: u8) -> Result<(), W::Error> {
    field(out, flash_str!("echo:"), char::from(letter))
}

/// What the executor keeps of the loops.
pub struct EncoderState {
    settings: [LoopSettings; AXES],
    /// Axes whose settings the board has yet to install (bit 0 X, bit 1 Y).
    changed: u8,
    rehome: bool,
    reports: [AxisReport; AXES],
    /// `M828`: whether the host asked for the trace, and whether the
    /// board has yet to start or stop it.
    tracing: bool,
    trace_changed: bool,
}

impl EncoderState {
    pub const fn new() -> Self {
        Self {
            settings: [LoopSettings::DEFAULT; AXES],
            changed: 0,
            rehome: false,
            reports: [AxisReport::EMPTY; AXES],
            tracing: false,
            trace_changed: false,
        }
    }
}

impl Default for EncoderState {
    fn default() -> Self {
        Self::new()
    }
}

/// The codes of the printer's encoder loops (dispatched by
/// `Machine::encoder_command`; see [`super::commands`]). Their `M114`
/// addition is the core's `M114`.
pub const COMMANDS: &[Listing] = &[
    Listing::m(820).on(Machines::PRINTER).capability("CLOSED_LOOP"),
    Listing::m(821).to(824).on(Machines::PRINTER),
    Listing::m(828).on(Machines::PRINTER), // trace
];

impl Machine<'_> {
    /// The next axis whose loop settings changed, with its gains (the board
    /// installs them in the tick's loops). `None`: nothing new.
    pub fn take_encoder_settings(&mut self) -> Option<(usize, LoopSettings, LoopGains)> {
        let state = &mut self.encoders;
        let axis = (0..AXES).find(|axis| state.changed & (1 << axis) != 0)?;
        state.changed &= !(1 << axis);
        let settings = state.settings[axis];
        // The settings were checked when they were set: the tuning cannot
        // fail here; open loop if it ever did.
        Some((axis, settings, settings.gains().unwrap_or(<LoopGains>::OPEN_LOOP)))
    }

    /// `M828` switched the trace on (`Some(true)`) or off since the board
    /// last looked.
    pub fn take_trace_request(&mut self) -> Option<bool> {
        core::mem::replace(&mut self.encoders.trace_changed, false).then_some(self.encoders.tracing)
    }

    /// Whether a homing of X or Y finished (the board re-zeroes the
    /// encoders on the step position).
    pub fn take_encoder_rehome(&mut self) -> bool {
        core::mem::replace(&mut self.encoders.rehome, false)
    }

    /// The loops as the board last saw them (`M822`).
    pub fn set_encoder_reports(&mut self, reports: [AxisReport; AXES]) {
        self.encoders.reports = reports;
    }

    /// A loop stopped (following error, encoder fault): stop every motor,
    /// say why, refuse moves until `G28`.
    pub fn on_encoder_fault<W: uWrite + ?Sized>(&mut self, axis: u8, fault: AxisFault, out: &mut W) -> Result<(), W::Error> {
        if self.halted {
            return Ok(());
        }
        self.motion.request_stop();
        self.lose_alarmed_position();
        fault.write_error(axis, crate::closed_loop::nse5310::UNITS_PER_MM, out)
    }

    /// Homing finished for `motors` (bit 0 X, bit 1 Y, …).
    pub(super) fn encoders_homed(&mut self, motors: u8) {
        if motors & 0b11 != 0 {
            self.encoders.rehome = true;
        }
    }

    /// `M820`–`M824`; `None` for every other code. Out of line: inlined,
    /// its replies made the dispatch 4 KB larger.
    #[inline(never)]
    pub(super) fn encoder_command<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W) -> Result<Option<Result<(), CommandError>>, W::Error> {
        let result = match command.code {
            Code::M(820) => self.switch_loops(command, out)?,
            Code::M(822) => self.report_loops(out).map(Ok)?,
            Code::M(code @ (821 | 823 | 824)) => self.change_loops(code, command, out)?,
            Code::M(828) => self.trace_command(command, out)?,
            // M114 adds the measured position (issue #7: "where there is
            // one"), then runs as always.
            Code::M(114) => {
                self.report_measured(out)?;
                return Ok(None);
            }
            _ => return Ok(None),
        };
        Ok(Some(result))
    }

    #[inline(never)]
    fn switch_loops<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W) -> Result<Result<(), CommandError>, W::Error> {
        let mut enabled = [self.encoders.settings[0].enabled, self.encoders.settings[1].enabled];
        for (axis, letter) in AXIS_LETTERS.into_iter().enumerate() {
            match command.value(letter).map(|value| value.map(|v| v.to_int())) {
                Err(error) => return Ok(Err(error.into())),
                Ok(None) => {}
                Ok(Some(Some(on @ (0 | 1)))) => enabled[axis] = on == 1,
                Ok(Some(_)) => return Ok(Err(CommandError::OutOfRange(letter))),
            }
        }
        for (axis, on) in enabled.into_iter().enumerate() {
            if self.encoders.settings[axis].enabled != on {
                self.encoders.settings[axis].enabled = on;
                self.encoders.changed |= 1 << axis;
            }
        }
        field(out, flash_str!("echo:Closed loop X:"), u8::from(enabled[0]))?;
        field(out, flash_str!(" Y:"), u8::from(enabled[1]))?;
        out.write_str("\n")?;
        Ok(Ok(()))
    }

    /// `M828 S1`: the start line (loop rate, X's and Y's steps/mm) and the
    /// request to the board; `S0`: the request to stop (the board writes
    /// the end line once the last samples are out); bare: the state.
    #[inline(never)]
    fn trace_command<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W) -> Result<Result<(), CommandError>, W::Error> {
        let on = match command.value(b'S').map(|value| value.map(|v| v.to_int())) {
            Err(error) => return Ok(Err(error.into())),
            Ok(None) => {
                flash_str!("echo:Trace ").write_to(out)?;
                let state = if self.encoders.tracing { flash_str!("on\n") } else { flash_str!("off\n") };
                return state.write_to(out).map(Ok);
            }
            Ok(Some(Some(on @ (0 | 1)))) => on == 1,
            Ok(Some(_)) => return Ok(Err(CommandError::OutOfRange(b'S'))),
        };
        if on {
            let milli = &self.settings.steps_per_mm_milli;
            crate::closed_loop::trace::write_start(LOOP_HZ, [milli[0], milli[1]], out)?;
        }
        if on != self.encoders.tracing {
            self.encoders.tracing = on;
            self.encoders.trace_changed = true;
        } else if on {
            // Again while on: start over from sample 0 (a new start line).
            self.encoders.trace_changed = true;
        }
        Ok(Ok(()))
    }

    /// `M821`, `M823`, `M824` on the named axes (both reported if none).
    #[inline(never)]
    fn change_loops<W: uWrite + ?Sized>(&mut self, code: u16, command: &Command, out: &mut W) -> Result<Result<(), CommandError>, W::Error> {
        let named: [bool; AXES] = [command.has(b'X'), command.has(b'Y')];
        let mut updated = self.encoders.settings;
        if named.contains(&true) {
            for axis in 0..AXES {
                if named[axis] {
                    if let Err(error) = change_settings(code, command, &mut updated[axis]) {
                        return Ok(Err(error));
                    }
                }
            }
        }
        for axis in 0..AXES {
            if updated[axis] != self.encoders.settings[axis] {
                self.encoders.settings[axis] = updated[axis];
                self.encoders.changed |= 1 << axis;
            }
            if named[axis] || !named.contains(&true) {
                write_settings(AXIS_LETTERS[axis], code, &updated[axis], out)?;
            }
        }
        Ok(Ok(()))
    }

    /// `echo:Measured X=20.010 Y=0.000` (mm, the `M114` frame: the
    /// position less the loop's error) for the axes whose loop is on; not
    /// `X:`, which hosts would take for the position line.
    #[inline(never)]
    fn report_measured<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        if !self.encoders.settings.iter().any(|s| s.enabled) {
            return Ok(());
        }
        flash_str!("echo:Measured").write_to(out)?;
        let position = self.modal.logical_position();
        for (axis, letter) in AXIS_LETTERS.into_iter().enumerate() {
            if !self.encoders.settings[axis].enabled {
                continue;
            }
            let report = &self.encoders.reports[axis];
            let error_um = millimetres(report.reference.wrapping_sub(report.measured)).mantissa;
            ufmt::uwrite!(out, " {}", char::from(letter))?;
            field(out, flash_str!("="), Fixed::thousandths(position[axis].saturating_sub(error_um)))?;
        }
        out.write_str("\n")
    }

    #[inline(never)]
    fn report_loops<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        for (report, letter) in self.encoders.reports.iter().zip(AXIS_LETTERS) {
            let settings = &self.encoders.settings[usize::from(letter - b'X')];
            echo_axis(out, letter)?;
            field(out, flash_str!(" loop:"), u8::from(settings.enabled))?;
            field(out, flash_str!(" enc:"), millimetres(report.measured))?;
            field(out, flash_str!(" ref:"), millimetres(report.reference))?;
            field(out, flash_str!(" err:"), millimetres(report.reference.wrapping_sub(report.measured)))?;
            field(out, flash_str!(" corr:"), report.corrections)?;
            let counters = &report.counters;
            field(out, flash_str!(" idx:"), counters.index_accepted)?;
            field(out, flash_str!(" glitch:"), counters.index_glitches)?;
            field(out, flash_str!(" bounce:"), counters.index_bounces)?;
            field(out, flash_str!(" missed:"), counters.index_missed)?;
            field(out, flash_str!(" bad:"), counters.bad_reads)?;
            field(
                out,
                flash_str!(" fault:"),
                match report.fault {
                    None => flash_str!("none\n"),
                    Some(AxisFault::FollowingError { .. }) => flash_str!("following error\n"),
                    Some(AxisFault::Encoder(crate::closed_loop::EncoderFault::Stuck)) => flash_str!("encoder stuck\n"),
                    Some(AxisFault::Encoder(crate::closed_loop::EncoderFault::NoReading)) => flash_str!("no reading\n"),
                    Some(_) => flash_str!("stopped\n"),
                },
            )?;
        }
        Ok(())
    }
}

/// Encoder units (1/2048 mm) as millimetres with three decimals.
fn millimetres(units: i32) -> Fixed {
    // × 1000 / 2048 = × 125 / 256, rounded; |units| < 2^24 keeps it in i32.
    let clamped = units.clamp(-(1 << 24), 1 << 24);
    Fixed::thousandths((clamped * 125 + if clamped >= 0 { 128 } else { -128 }) / 256)
}

/// One axis' new settings from `M821`/`M823`/`M824`, checked (the tuning
/// must succeed) before anything changes.
fn change_settings(code: u16, command: &Command, settings: &mut LoopSettings) -> Result<(), CommandError> {
    let milli = |letter: u8| -> Result<Option<i32>, CommandError> {
        match command.value(letter)? {
            None => Ok(None),
            Some(value) => value.to_scaled(3).filter(|v| *v >= 0).map(Some).ok_or(CommandError::OutOfRange(letter)),
        }
    };
    let in_range = |letter: u8, value: i32, range: core::ops::RangeInclusive<i32>| -> Result<u16, CommandError> {
        if range.contains(&value) {
            Ok(value as u16)
        } else {
            Err(CommandError::OutOfRange(letter))
        }
    };
    let mut new = *settings;
    match code {
        821 => {
            let (kp, gamma) = match new.strategy {
                Strategy::PFeedforward { kp_milli } => (kp_milli, 500),
                Strategy::RobustPid { gamma_milli } => (4300, gamma_milli),
                _ => (4300, 500),
            };
            let kp = match milli(b'P')? {
                Some(value) => in_range(b'P', value, 1..=50_000)?,
                None => kp,
            };
            let gamma = match milli(b'G')? {
                Some(value) => in_range(b'G', value, 1..=750)?,
                None => gamma,
            };
            let strategy = match command.value(b'S')?.map(|s| s.to_int()) {
                None => new.strategy,
                Some(Some(0)) => Strategy::OpenLoop,
                Some(Some(1)) => Strategy::PFeedforward { kp_milli: kp },
                Some(Some(2)) => Strategy::RobustPid { gamma_milli: gamma },
                Some(_) => return Err(CommandError::OutOfRange(b'S')),
            };
            new.strategy = match strategy {
                Strategy::PFeedforward { .. } => Strategy::PFeedforward { kp_milli: kp },
                Strategy::RobustPid { .. } => Strategy::RobustPid { gamma_milli: gamma },
                other => other,
            };
        }
        823 => {
            if let Some(mm) = milli(b'E')? {
                // 0.05 mm (the encoder's and the steps' resolution) to 50 mm.
                let limit = in_range(b'E', mm, 50..=50_000)?;
                new.following.limit = (i32::from(limit) * 2048 + 500) / 1000;
            }
            if let Some(ms) = milli(b'T')? {
                let ms = in_range(b'T', ms, 0..=10_000)?;
                new.following.hold_ticks = (u32::from(ms) * u32::from(LOOP_HZ) / 1000) as u16;
            }
        }
        _ => {
            if let Some(ms) = milli(b'T')? {
                new.theta_ms = in_range(b'T', ms, 4..=1_000)?;
            }
        }
    }
    if new.gains().is_err() {
        return Err(CommandError::OutOfRange(if code == 824 { b'T' } else { b'G' }));
    }
    *settings = new;
    Ok(())
}

#[inline(never)]
fn write_settings<W: uWrite + ?Sized>(letter: u8, code: u16, settings: &LoopSettings, out: &mut W) -> Result<(), W::Error> {
    echo_axis(out, letter)?;
    if code == 823 {
        let FollowingErrorLimit { limit, hold_ticks } = settings.following;
        let hold_ms = u32::from(hold_ticks) * 1000 / u32::from(LOOP_HZ);
        field(out, flash_str!(" following error "), millimetres(limit))?;
        field(out, flash_str!(" mm for "), Fixed::thousandths(hold_ms as i32))?;
        return flash_str!(" s\n").write_to(out);
    }
    let (code, kp, gamma) = match settings.strategy {
        Strategy::OpenLoop => (0, 0, 0),
        Strategy::PFeedforward { kp_milli } => (1, kp_milli, 0),
        Strategy::RobustPid { gamma_milli } => (2, 0, gamma_milli),
        Strategy::ServoPid { .. } => (3, 0, 0),
    };
    field(out, flash_str!(" S"), code)?;
    if kp != 0 {
        field(out, flash_str!(" P"), Fixed::thousandths(i32::from(kp)))?;
    }
    if gamma != 0 {
        field(out, flash_str!(" G"), Fixed::thousandths(i32::from(gamma)))?;
    }
    field(out, flash_str!(" theta "), Fixed::thousandths(i32::from(settings.theta_ms)))?;
    flash_str!(" s\n").write_to(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::tests::{converse, new_machine};
    use crate::reply::test_support::Text;
    use std::vec::Vec;

    #[test]
    fn the_loops_are_off_at_boot_and_m820_switches_them_per_axis() {
        let mut machine = new_machine();
        assert_eq!(machine.take_encoder_settings(), None);
        assert_eq!(converse(&mut machine, 0, "M820\n"), "echo:Closed loop X:0 Y:0\nok\n");
        assert_eq!(converse(&mut machine, 0, "M820 X1\n"), "echo:Closed loop X:1 Y:0\nok\n");
        let (axis, settings, gains) = machine.take_encoder_settings().unwrap();
        assert_eq!((axis, settings.enabled), (0, true));
        assert_eq!(gains, settings.gains().unwrap());
        assert_eq!(machine.take_encoder_settings(), None);
        assert_eq!(converse(&mut machine, 0, "M820 X1 Y1\n"), "echo:Closed loop X:1 Y:1\nok\n");
        assert_eq!(machine.take_encoder_settings().map(|(axis, s, _)| (axis, s.enabled)), Some((1, true)));
        assert_eq!(machine.take_encoder_settings(), None);
    }

    #[test]
    fn m821_selects_the_strategy_and_reports_it() {
        let mut machine = new_machine();
        assert_eq!(converse(&mut machine, 0, "M821 X S1 P3\n"), "echo:X S1 P3.000 theta 0.020 s\nok\n");
        let (axis, settings, _) = machine.take_encoder_settings().unwrap();
        assert_eq!((axis, settings.strategy), (0, Strategy::PFeedforward { kp_milli: 3000 }));
        assert_eq!(converse(&mut machine, 0, "M821 Y S2 G0.3\n"), "echo:Y S2 G0.300 theta 0.020 s\nok\n");
        assert_eq!(converse(&mut machine, 0, "M821 X S0\n"), "echo:X S0 theta 0.020 s\nok\n");
        assert_eq!(converse(&mut machine, 0, "M821\n"), "echo:X S0 theta 0.020 s\necho:Y S2 G0.300 theta 0.020 s\nok\n");
        assert_eq!(converse(&mut machine, 0, "M824 Y T0.1\n"), "echo:Y S2 G0.300 theta 0.100 s\nok\n");
    }

    #[test]
    fn bad_loop_values_are_refused_and_change_nothing() {
        let mut machine = new_machine();
        for (line, error) in [
            ("M821 X S3\n", "Error:Value out of range for S\nok\n"),
            ("M821 X S2 G0.9\n", "Error:Value out of range for G\nok\n"),
            ("M821 X S1 P-2\n", "Error:Value out of range for P\nok\n"),
            ("M820 X2\n", "Error:Value out of range for X\nok\n"),
            ("M823 X E0.01\n", "Error:Value out of range for E\nok\n"),
            ("M824 Y T0\n", "Error:Value out of range for T\nok\n"),
        ] {
            assert_eq!(converse(&mut machine, 0, line), error, "{line}");
        }
        assert_eq!(machine.take_encoder_settings(), None);
    }

    #[test]
    fn m823_sets_the_following_error_limit_in_encoder_units_and_loop_ticks() {
        let mut machine = new_machine();
        assert_eq!(converse(&mut machine, 0, "M823 Y E2 T0.2\n"), "echo:Y following error 2.000 mm for 0.200 s\nok\n");
        let (axis, settings, _) = machine.take_encoder_settings().unwrap();
        assert_eq!((axis, settings.following), (1, FollowingErrorLimit { limit: 4096, hold_ticks: 50 }));
    }

    #[test]
    fn m822_prints_what_the_board_last_reported() {
        let mut machine = new_machine();
        let mut x = AxisReport::EMPTY;
        x.measured = 2048 * 12 + 706;
        x.reference = 2048 * 12 + 716;
        x.corrections = -2;
        x.counters.index_accepted = 6;
        machine.set_encoder_reports([x, AxisReport { fault: Some(AxisFault::Stopped), ..AxisReport::EMPTY }]);
        assert_eq!(
            converse(&mut machine, 0, "M822\n"),
            "echo:X loop:0 enc:12.345 ref:12.350 err:0.005 corr:-2 idx:6 glitch:0 bounce:0 missed:0 bad:0 fault:none\n\
             echo:Y loop:0 enc:0.000 ref:0.000 err:0.000 corr:0 idx:0 glitch:0 bounce:0 missed:0 bad:0 fault:stopped\nok\n"
        );
    }

    #[test]
    fn a_loop_fault_stops_the_job_with_an_error_and_moves_wait_for_g28() {
        let mut machine = new_machine();
        let mut out = Text::default();
        machine.on_encoder_fault(b'X', AxisFault::FollowingError { error: 2048 * 2 + 1024 }, &mut out).unwrap();
        assert_eq!(out.0, "Error:X following error 2.500 mm, job stopped (re-home with G28)\n");
        let reply = converse(&mut machine, 0, "G1 X10 F600\n");
        assert!(reply.starts_with("Error:") && reply.ends_with("ok\n"), "{reply}");
        assert!(reply.contains("G28"), "{reply}");
    }

    #[test]
    fn m114_adds_the_measured_position_of_the_axes_whose_loop_is_on() {
        let mut machine = new_machine();
        let plain = converse(&mut machine, 0, "G92 X20 Y5\nM114\n");
        assert!(!plain.contains("Measured"), "{plain}");
        converse(&mut machine, 0, "M820 X1\n");
        let mut x = AxisReport::EMPTY;
        // 20 counts (0.010 mm) short of the reference.
        x.reference = 40_960;
        x.measured = 40_940;
        machine.set_encoder_reports([x, AxisReport::EMPTY]);
        let reply = converse(&mut machine, 0, "M114\n");
        assert!(reply.starts_with("echo:Measured X=19.990\nX:20.00 Y:5.00 Z:0.00 E:0.00 Count X:"), "{reply}");
    }

    #[test]
    fn m115_lists_the_closed_loop_capability() {
        let reply = converse(&mut new_machine(), 0, "M115\n");
        let caps: Vec<&str> = reply.lines().filter(|l| l.starts_with("Cap:CLOSED_LOOP")).collect();
        assert_eq!(caps, ["Cap:CLOSED_LOOP:1"]);
    }
}
