//! The filament extrusion line (SPEC §4) as a machine the executor runs:
//! its G-code, and its duties in the main loop. Compiled with the
//! `extrusion-line` feature; a board makes its machine the line with
//! [`Machine::become_extrusion_line`] at boot (the host builds keep every
//! machine, so hal-sim runs this one beside the printers).
//!
//! The line has no planner moves: its two motors are velocity-mode
//! steppers (the screw on E0's pins, the puller on X's), so `G0`–`G3`,
//! `G28` and `G92` are refused. The barrel is heater 0 (`M104`/`M109`,
//! SPEC §4's thermistor and PI, a solid-state relay), the interlock is
//! `M302` at 175 °C, fans (D8) run from power-on
//! (`fans_on_at_start`) and are `M106`/`M107`.
//!
//! | command | effect |
//! |---|---|
//! | `M3 S<rpm>` | screw speed (decimals allowed, ≤ 20 rpm), ramped; refused while the barrel is cold |
//! | `M5` | screw stop (ramped) |
//! | `M4` | refused: the screw does not run in reverse |
//! | `M860 S<rpm>` | puller at a fixed speed (0, or up to 15 rpm); manual mode |
//! | `M861 P<px>` / `D<mm>` | one camera measurement (once a second) |
//! | `M404 [W<mm>] [P<px>]` | diameter set point; bare: report |
//! | `M405` / `M406` | automatic diameter control on (bumpless) / off |
//! | `M407` | diameter, set point, puller speed, mode |
//! | `M862 [P<kp>] [I<ki>]` | diameter PI gains (rpm/px, both ≤ 0); bare: report |
//! | `M863 S<s>` | stale-measurement watchdog, 1–255 s |
//!
//! Every 20 ms ([`RAMP_UPDATES_PER_S`]) the ramps advance and the board is
//! told what to do with its two step timers ([`LineTimers`]); every second
//! the diameter watchdog and the interlock run (a barrel that cools below
//! the minimum stops the screw with an `Error:` line).

use super::error::CommandError;
use super::commands::{Listing, Machines};
use super::Machine;
use crate::gcode::{Code, Command, Decimal};
use crate::machines::config::EXTRUSION_LINE;
use crate::machines::diameter::{write_milli, ClosedLoopPi, DiameterError, THESIS_KI, THESIS_KP};
use crate::machines::extrusion_line::{write_mm_px, ExtrusionLine, ExtrusionLineConfig, ScrewError, RAMP_UPDATES_PER_S};
use crate::machines::velocity::{DriveTrain, SpeedError, TimerChange};
use crate::thermal::channel::BARREL;
use crate::thermal::guard::ColdExtrusionReading;
use crate::thermal::{ColdExtrusionGuard, Gains, HeaterChannel};
use ufmt::uWrite;

/// The line of SPEC §4 (puller 6:1 as in the thesis' code).
pub const LINE_CONFIG: ExtrusionLineConfig = match ExtrusionLineConfig::thesis(DriveTrain::PULLER_6_TO_1) {
    Ok(config) => config,
    Err(_) => panic!("the thesis' drive trains fit the step timer"),
};

const RAMP_PERIOD_MS: u32 = 1000 / RAMP_UPDATES_PER_S as u32;

/// The line's running state inside the machine.
#[derive(Clone, Copy, Debug)]
pub struct LineState {
    pub line: ExtrusionLine<ClosedLoopPi>,
    next_ramp_ms: u32,
    next_second_ms: u32,
}

/// What the board does with its two velocity step timers after
/// [`Machine::poll_line`]: for each, follow the model
/// (`VelocityStepper::follow`) and start or stop the timer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LineTimers {
    pub screw: TimerChange,
    pub puller: TimerChange,
    /// The models changed this pass (a ramp update, a stop, a halt): only
    /// then must the interrupts' copies follow them.
    pub changed: bool,
}

impl LineTimers {
    pub const NONE: LineTimers = LineTimers { screw: TimerChange::None, puller: TimerChange::None, changed: false };
}

/// `S10.5` rpm → milli-rpm.
fn mrpm(value: Decimal, letter: u8) -> Result<u32, CommandError> {
    let milli = value.to_scaled(3).ok_or(CommandError::OutOfRange(letter))?;
    u32::try_from(milli).map_err(|_| CommandError::OutOfRange(letter))
}

fn speed_error(error: SpeedError) -> CommandError {
    match error {
        SpeedError::TooFast { .. } => CommandError::OutOfRange(b'S'),
    }
}

fn diameter_error(error: DiameterError, letter: u8) -> CommandError {
    match error {
        DiameterError::Implausible => CommandError::OutOfRange(letter),
        DiameterError::GainSign => CommandError::DiameterGainSign,
    }
}

/// The line's own codes (dispatched by `Machine::line_command`; see
/// [`super::commands`]). The printers' codes it refuses (`G0`–`G3`, `G28`,
/// `G92`, `M4`, `M17`/`M18`/`M84`) and those it handles as the screw
/// (`M3`, `M5`) are the core's rows.
pub const COMMANDS: &[Listing] = &[
    Listing::m(404).to(406).on(Machines::LINE), // diameter set point, automatic on / off
    Listing::m(407).on(Machines::LINE).runs_halted(), // report
    Listing::m(860).on(Machines::LINE).capability("EXTRUSION_LINE"), // puller
    Listing::m(861).to(863).on(Machines::LINE), // measurement, PI gains, watchdog
];

impl Machine<'_> {
    /// Make this machine the extrusion line: the barrel on heater 0 (SPEC
    /// §4's 4.8 kΩ thermistor, the thesis PI, SSR time-proportioning), the
    /// interlock at 175 °C, the diameter PI at the thesis' gains. The board
    /// calls it once at boot, before any command.
    pub fn become_extrusion_line(&mut self) {
        let mut line = ExtrusionLine::new(ClosedLoopPi::new(), &LINE_CONFIG);
        let _ = line.diameter.set_gains(THESIS_KP, THESIS_KI);
        self.hotend = HeaterChannel::new(&BARREL, Gains::THESIS_BARREL);
        self.cold_extrusion = ColdExtrusionGuard::EXTRUSION_LINE;
        self.line = Some(LineState { line, next_ramp_ms: 0, next_second_ms: 1000 });
        // SPEC §4: the fans (D8) run from power-on, before any command;
        // `M107` stops them.
        if EXTRUSION_LINE.fans_on_at_start {
            self.fan_duty = 255;
        }
    }

    /// The line, if this machine is one.
    pub fn extrusion_line(&self) -> Option<&ExtrusionLine<ClosedLoopPi>> {
        self.line.as_ref().map(|state| &state.line)
    }

    /// Every main-loop pass: the ramps (every 20 ms), the watchdog and the
    /// interlock (every second), and the halt. Returns what the board does
    /// with its step timers. Nothing for a machine that is not the line.
    pub fn poll_line<W: uWrite + ?Sized>(&mut self, now_ms: u32, out: &mut W) -> Result<LineTimers, W::Error> {
        let halted = self.halted;
        let measured = self.hotend.measured();
        let guard = self.cold_extrusion;
        let Some(state) = self.line.as_mut() else { return Ok(LineTimers::NONE) };
        if halted {
            let (screw, puller) = state.line.halt();
            return Ok(LineTimers { screw, puller, changed: true });
        }
        let mut timers = LineTimers::NONE;
        if now_ms.wrapping_sub(state.next_ramp_ms) < u32::MAX / 2 {
            state.next_ramp_ms = now_ms.wrapping_add(RAMP_PERIOD_MS);
            let (screw, puller) = state.line.update(&LINE_CONFIG);
            timers = LineTimers { screw, puller, changed: true };
        }
        if now_ms.wrapping_sub(state.next_second_ms) < u32::MAX / 2 {
            state.next_second_ms = state.next_second_ms.wrapping_add(1000);
            let report = state.line.on_second(&ColdExtrusionReading { guard: &guard, measured });
            if let Some(warning) = report.diameter {
                warning.write(out)?;
            }
            if let Some(cold) = report.screw_stopped {
                cold.write_stopped(out)?;
                timers.screw = TimerChange::Stop;
                timers.changed = true;
            }
        }
        Ok(timers)
    }

    /// The line's own commands; `None` for a command it leaves to the
    /// printer's executor (heaters, fans, reports, settings).
    pub(super) fn line_command<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W) -> Result<Option<Result<(), CommandError>>, W::Error> {
        let reading = ColdExtrusionReading { guard: &self.cold_extrusion, measured: self.hotend.measured() };
        let Some(state) = self.line.as_mut() else { return Ok(None) };
        let line = &mut state.line;
        let result = match command.code {
            // No planner moves, and the drivers are the line's own.
            Code::G(0..=3 | 28 | 92) | Code::Modal | Code::M(17 | 18 | 84) => Err(CommandError::NotThisMachine),
            Code::M(3) => match required(command, b'S').and_then(|value| mrpm(value, b'S')) {
                Err(error) => Err(error),
                Ok(speed) => match line.set_screw(&LINE_CONFIG, speed, &reading) {
                    Ok(()) => Ok(()),
                    Err(ScrewError::Cold(cold)) => {
                        // The reply is the refusal itself (an `Error:` line).
                        cold.write_refused(out)?;
                        return Ok(Some(Ok(())));
                    }
                    Err(ScrewError::Speed(error)) => Err(speed_error(error)),
                },
            },
            Code::M(5) => {
                let _ = line.set_screw(&LINE_CONFIG, 0, &reading);
                Ok(())
            }
            Code::M(4) => Err(CommandError::NotThisMachine),
            Code::M(860) => {
                let speed = required(command, b'S').and_then(|value| mrpm(value, b'S'));
                match speed.and_then(|speed| line.set_puller_manual(&LINE_CONFIG, speed).map(|()| speed).map_err(speed_error)) {
                    Ok(speed) => {
                        crate::flash_str!("echo:Puller manual ").write_to(out)?;
                        write_milli(out, speed)?;
                        crate::flash_str!(" rpm\n").write_to(out)?;
                        Ok(())
                    }
                    Err(error) => Err(error),
                }
            }
            Code::M(861) => measurement(line, command),
            Code::M(404) => set_point(line, command, out)?,
            Code::M(405) => {
                line.set_automatic(&LINE_CONFIG, true);
                crate::flash_str!("echo:Diameter control on\n").write_to(out)?;
                Ok(())
            }
            Code::M(406) => {
                line.set_automatic(&LINE_CONFIG, false);
                crate::flash_str!("echo:Diameter control off, puller ").write_to(out)?;
                write_milli(out, line.puller.current_mrpm())?;
                crate::flash_str!(" rpm\n").write_to(out)?;
                Ok(())
            }
            Code::M(407) => {
                line.write_report(out)?;
                Ok(())
            }
            Code::M(862) => gains(line, command, out)?,
            Code::M(863) => match required(command, b'S') {
                Err(error) => Err(error),
                Ok(value) => match value.to_int() {
                    Some(seconds @ 1..=255) => {
                        line.diameter.set_stale_after(seconds as u8);
                        crate::flash_str!("echo:Diameter watchdog ").write_to(out)?;
                        ufmt::uwrite!(out, "{} s\n", seconds)?;
                        Ok(())
                    }
                    _ => Err(CommandError::OutOfRange(b'S')),
                },
            },
            _ => return Ok(None),
        };
        Ok(Some(result))
    }
}

/// The value of a word the command needs.
fn required(command: &Command, letter: u8) -> Result<Decimal, CommandError> {
    command.value(letter)?.ok_or(CommandError::Missing(letter))
}

/// `M861 P<px>` (pixels, decimals allowed) or `D<mm>`.
fn measurement(line: &mut ExtrusionLine<ClosedLoopPi>, command: &Command) -> Result<(), CommandError> {
    if let Some(px) = command.value(b'P')? {
        let cpx = px.to_scaled(2).and_then(|v| u32::try_from(v).ok()).ok_or(CommandError::OutOfRange(b'P'))?;
        return line.on_measurement_cpx(&LINE_CONFIG, cpx).map_err(|e| diameter_error(e, b'P'));
    }
    let mm = command.value(b'D')?.ok_or(CommandError::Missing(b'P'))?;
    let um = mm.to_scaled(3).and_then(|v| u32::try_from(v).ok()).ok_or(CommandError::OutOfRange(b'D'))?;
    let cpx = line.diameter.settings().cpx_from_um(um);
    line.on_measurement_cpx(&LINE_CONFIG, cpx).map_err(|e| diameter_error(e, b'D'))
}

/// `M404 [W<mm>] [P<px>]`; bare: report.
fn set_point<W: uWrite + ?Sized>(line: &mut ExtrusionLine<ClosedLoopPi>, command: &Command, out: &mut W) -> Result<Result<(), CommandError>, W::Error> {
    let result = (|| {
        if let Some(mm) = command.value(b'W')? {
            let um = mm.to_scaled(3).and_then(|v| u32::try_from(v).ok()).ok_or(CommandError::OutOfRange(b'W'))?;
            line.diameter.set_setpoint_um(um).map_err(|e| diameter_error(e, b'W'))?;
        } else if let Some(px) = command.value(b'P')? {
            let cpx = px.to_scaled(2).and_then(|v| u32::try_from(v).ok()).ok_or(CommandError::OutOfRange(b'P'))?;
            line.diameter.set_setpoint_cpx(cpx).map_err(|e| diameter_error(e, b'P'))?;
        }
        Ok(())
    })();
    if result.is_ok() {
        let settings = *line.diameter.settings();
        crate::flash_str!("echo:Diameter setpoint ").write_to(out)?;
        write_mm_px(out, &settings, u32::from(settings.setpoint_cpx))?;
        out.write_str("\n")?;
    }
    Ok(result)
}

/// `M862 [P<kp>] [I<ki>]`; bare: report.
fn gains<W: uWrite + ?Sized>(line: &mut ExtrusionLine<ClosedLoopPi>, command: &Command, out: &mut W) -> Result<Result<(), CommandError>, W::Error> {
    let result = (|| {
        let (kp, ki) = line.diameter.gains();
        let read = |letter| -> Result<Option<f32>, CommandError> {
            Ok(command.value(letter)?.map(|v| v.to_scaled(4).map_or(f32::NAN, |x| x as f32 / 10_000.0)))
        };
        let (new_kp, new_ki) = (read(b'P')?.unwrap_or(kp), read(b'I')?.unwrap_or(ki));
        if command.has(b'P') || command.has(b'I') {
            line.diameter.set_gains(new_kp, new_ki).map_err(|e| diameter_error(e, b'P'))?;
        }
        Ok(())
    })();
    if result.is_ok() {
        let (kp, ki) = line.diameter.gains();
        crate::flash_str!("echo:Diameter PI Kp:").write_to(out)?;
        write_signed_ten_thousandths(out, kp)?;
        out.write_str(" Ki:")?;
        write_signed_ten_thousandths(out, ki)?;
        out.write_str("\n")?;
    }
    Ok(result)
}

/// `-0.0700`
fn write_signed_ten_thousandths<W: uWrite + ?Sized>(out: &mut W, value: f32) -> Result<(), W::Error> {
    let scaled = value * 10_000.0;
    let rounded = if scaled >= 0.0 { scaled + 0.5 } else { scaled - 0.5 } as i32;
    if rounded < 0 {
        out.write_str("-")?;
    }
    let magnitude = rounded.unsigned_abs();
    ufmt::uwrite!(out, "{}.", magnitude / 10_000)?;
    let fraction = magnitude % 10_000;
    for place in [1000, 100, 10, 1] {
        ufmt::uwrite!(out, "{}", (fraction / place) % 10)?;
    }
    Ok(())
}
