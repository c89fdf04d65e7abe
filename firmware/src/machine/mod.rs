//! The command executor: from received lines to actions and replies.
//!
//! Lines travel in two steps, as in Marlin:
//! 1. [`Machine::receive_line`] (as soon as a line is complete): the host
//!    protocol checks line number and checksum; a refused line is answered
//!    at once (`Error:`, `Resend:`, `ok`); an accepted one is queued as
//!    text in the command queue ([`COMMAND_QUEUE_DEPTH`] lines).
//! 2. [`Machine::poll`] (every pass of the main loop): the next queued line
//!    is parsed and executed. Its `ok` goes out when it is done — at once
//!    for most commands, later for the blocking ones (`G4`, `M400`, ...),
//!    which report `echo:busy: processing` every 2 s while they wait.
//!
//! Every line gets exactly one `ok`, after its error or report, so a host
//! that waits for `ok` never stalls, and nothing that was acknowledged is
//! dropped. The board stops taking bytes out of its receive ring while the
//! queue is full ([`Machine::can_accept_line`]); `M112`, `M108` and `M410`
//! still act from the receive interrupt (see [`crate::emergency`]).


pub mod commands;
pub mod error;
pub mod modal;
mod motion_commands;
pub mod safety;
mod thermal;
#[cfg(feature = "extrusion-line")]
pub mod line;
#[cfg(feature = "powder-bed")]
pub mod powder_bed;
#[cfg(feature = "encoders")]
pub mod encoders;


use crate::gcode::{self, Code, Command, ParseError};
use crate::motion::{Motion, MotionConfig, StepFeeder};
use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use crate::line::{Line, MAX_LINE};
use crate::protocol::HostProtocol;
use crate::reply::{Printable, Whole};
#[cfg(feature = "printer")]
use crate::reply::Fixed;
use crate::settings::{self, Settings};
use crate::storage::{self, LoadError, NonVolatile};
use crate::thermal::channel::{BED, HOTEND_0};
use crate::thermal::{AutoReport, Autotune, ColdExtrusionGuard, Gains, HeaterChannel, TemperatureWait};
#[cfg(feature = "heaters")]
use crate::thermal::WaitConfig;
use thermal::HeaterSlot;
use commands::{Halted, Kind};
use error::CommandError;
use modal::{Distance, ModalState, MotionMode, Plane, Units, AXIS_LETTERS};
use ufmt::uWrite;

/// Lines the command queue holds (Marlin's BUFSIZE is 4).
pub const COMMAND_QUEUE_DEPTH: usize = 4;
/// Interval of `echo:busy: processing` while a line waits, ms (Marlin's
/// default host keep-alive, 2 s; `M113 S<s>` changes it, `S0` stops it).
pub const BUSY_INTERVAL_MS: u32 = 2_000;
/// Longest `M113` interval, seconds (Marlin's).
pub const MAX_KEEPALIVE_S: u8 = 60;

/// Number of extruders (`T0` only).
pub const EXTRUDERS: u16 = 1;

type LineText = heapless::Vec<u8, MAX_LINE>;

/// A command that has started and not yet finished.
#[derive(Clone, Copy, Debug)]
enum Running {
    Idle,
    /// `G4`: wait for queued motion to finish, then `ms` more.
    DwellAfterMotion { ms: u32 },
    /// `G4`: wait until `until_ms`.
    Dwell { until_ms: u32 },
    /// `M400` (and `M18`/`M84`, which then disable the drivers): wait for
    /// queued motion to finish.
    WaitForMotion { then_disable: bool },
    /// `G28`: homing runs in the main loop.
    #[cfg_attr(not(feature = "printer"), allow(dead_code))] // never built without it; its match arms stay
    Homing,
    /// `M109`/`M190`: waiting for a heater.
    #[cfg_attr(not(feature = "heaters"), allow(dead_code))] // never built without it; its match arms stay
    HeatWait { slot: HeaterSlot, wait: TemperatureWait },
    /// `M303`: the relay auto-tune runs on the samples.
    #[cfg_attr(not(feature = "heaters"), allow(dead_code))] // never built without it; its match arms stay
    Autotune { slot: HeaterSlot, apply: bool, tune: Autotune },
    /// `M303` ended (its report is out): `ok` at the next poll.
    AutotuneDone,
    /// `M880`–`M882`: the powder bed's job runs in its 1 kHz tick.
    #[cfg(feature = "powder-bed")]
    BedJob,
}

/// Raw endstop levels as the board reads them, one bit per switch:
/// bit 0 X_MIN, 1 X_MAX, 2 Y_MIN, 3 Y_MAX, 4 Z_MIN, 5 Z_MAX.
pub type EndstopLevels = u8;

#[cfg(feature = "printer")]
/// The endstops `M119` reports, in bit order: `x_min`, `x_max`, `y_min`,
/// `y_max`, `z_min`, `z_max`.
const ENDSTOPS: u8 = 6;

/// Everything the executor remembers between lines.
pub struct Machine<'q> {
    protocol: HostProtocol,
    queue: heapless::Deque<LineText, COMMAND_QUEUE_DEPTH>,
    modal: ModalState,
    settings: Settings,
    running: Running,
    /// `M108` arrived while a command waited: it finishes at the next poll.
    wait_cancelled: bool,
    last_busy_ms: u32,
    /// `M113 S<s>`: seconds between `busy: processing` lines (0: none).
    keepalive_s: u8,
    /// `M155 S<n>`: automatic temperature reports.
    auto_report: AutoReport,
    /// Last temperature line of a heating wait.
    last_report_ms: u32,
    /// `M112` (or a safety fault): outputs off until reset.
    halted: bool,
    steppers_enabled: bool,
    /// `M106`/`M107`: part-cooling fan duty, 0–255.
    fan_duty: u8,
    /// Levels that mean "triggered" (bit set: high = triggered).
    endstop_trigger_levels: EndstopLevels,
    endstop_levels: EndstopLevels,
    hotend: HeaterChannel,
    bed: HeaterChannel,
    /// `M302`: the cold-extrusion interlock.
    cold_extrusion: ColdExtrusionGuard,
    /// The planner and everything behind it, up to the step queues.
    motion: Motion<'q>,
    /// A motion fault (limit switch, lost position) happened: moves are
    /// refused until `G28`.
    position_lost: bool,
    /// The machine's own defaults (`M502`, and when no stored image loads).
    defaults: Settings,
    /// Driver ALARM inputs active at the last reading (bit i: motor i).
    driver_alarms: u8,
    /// SPEC §3's safety inputs at the last reading ([`safety`]'s bits).
    safety_levels: u8,
    /// Safety trips not yet re-armed ([`safety::RELAY_TRIPPED`],
    /// [`safety::EMERGENCY_STOP`]): moves and `G28` are refused.
    safety_latched: u8,
    /// The extrusion line's state, when this machine is one
    /// ([`Machine::become_extrusion_line`]).
    #[cfg(feature = "extrusion-line")]
    line: Option<line::LineState>,
    /// The powder bed's state, when this machine is one
    /// ([`Machine::become_powder_bed`]).
    #[cfg(feature = "powder-bed")]
    powder: Option<powder_bed::BedState>,
    /// `M820`–`M824`: the printer's X/Y encoder loops.
    #[cfg(feature = "encoders")]
    encoders: encoders::EncoderState,
}


impl<'q> Machine<'q> {
    /// An executor driving `motion` (the board's machine configuration).
    /// The settings start as the machine's defaults, which `motion`
    /// receives.
    pub fn new(motion: Motion<'q>) -> Self {
        let mut slot = MaybeUninit::<Self>::uninit();
        let p = slot.as_mut_ptr();
        // SAFETY: `p` points to the slot; the field is written once.
        unsafe { addr_of_mut!((*p).motion).write(motion) };
        // SAFETY: `motion` is initialised; `init_other_fields` writes every
        // other field.
        unsafe {
            Self::init_other_fields(p);
            slot.assume_init()
        }
    }

    /// The same machine built directly in `slot` (a `static` on the boards):
    /// `new` returns a value that is moved into place, and on the AVR the
    /// moved temporaries (the planner ring, the command queue) would need
    /// kilobytes of stack at boot.
    pub fn init_in<'s>(slot: &'s mut MaybeUninit<Self>, config: MotionConfig, feeder: StepFeeder<'q>) -> &'s mut Self {
        let p = slot.as_mut_ptr();
        // SAFETY: `p` points to the slot; `Motion::init_in` writes the whole
        // `motion` field in place and `init_other_fields` every other one.
        unsafe {
            Motion::init_in(&mut *addr_of_mut!((*p).motion).cast::<MaybeUninit<Motion<'q>>>(), config, feeder);
            Self::init_other_fields(p);
            slot.assume_init_mut()
        }
    }

    /// Write every field but `motion` (already initialised) and give the
    /// machine's default settings to the motion.
    ///
    /// # Safety
    /// `p` is valid for writes and its `motion` field is initialised.
    unsafe fn init_other_fields(p: *mut Self) {
        // SAFETY: `motion` is initialised (caller), so reading it is sound;
        // the defaults are built in their field (no copy through the stack).
        unsafe {
            init_defaults(&mut *addr_of_mut!((*p).defaults).cast(), &(*p).motion.config);
        }
        // SAFETY: `defaults` is initialised now; `apply_settings` touches
        // `motion` only.
        #[cfg(feature = "printer")]
        unsafe {
            (*p).motion.apply_settings(&(*p).defaults)
        };
        // SAFETY: each write is to a field of the valid slot `p`; none of
        // these fields has been initialised, so nothing is dropped.
        unsafe {
            addr_of_mut!((*p).protocol).write(HostProtocol::new());
            addr_of_mut!((*p).queue).write(heapless::Deque::new());
            ModalState::init_in(addr_of_mut!((*p).modal));
            addr_of_mut!((*p).settings).write((*p).defaults.clone());
            addr_of_mut!((*p).running).write(Running::Idle);
            addr_of_mut!((*p).wait_cancelled).write(false);
            addr_of_mut!((*p).last_busy_ms).write(0);
            addr_of_mut!((*p).keepalive_s).write((BUSY_INTERVAL_MS / 1000) as u8);
            addr_of_mut!((*p).auto_report).write(AutoReport::new());
            addr_of_mut!((*p).last_report_ms).write(0);
            addr_of_mut!((*p).halted).write(false);
            addr_of_mut!((*p).steppers_enabled).write(false);
            addr_of_mut!((*p).fan_duty).write(0);
            // RAMPS with mechanical switches and pull-ups: pressed = high
            // (Marlin's *_ENDSTOP_INVERTING false).
            addr_of_mut!((*p).endstop_trigger_levels).write(0b11_1111);
            addr_of_mut!((*p).endstop_levels).write(0);
            addr_of_mut!((*p).hotend).write(HeaterChannel::new(&HOTEND_0, Gains::MARLIN_HOTEND));
            addr_of_mut!((*p).bed).write(HeaterChannel::new(&BED, Gains::MARLIN_BED));
            addr_of_mut!((*p).cold_extrusion).write(ColdExtrusionGuard::HOTEND);
            addr_of_mut!((*p).position_lost).write(false);
            addr_of_mut!((*p).driver_alarms).write(0);
            addr_of_mut!((*p).safety_levels).write(0);
            addr_of_mut!((*p).safety_latched).write(0);
            #[cfg(feature = "extrusion-line")]
            addr_of_mut!((*p).line).write(None);
            #[cfg(feature = "powder-bed")]
            addr_of_mut!((*p).powder).write(None);
            #[cfg(feature = "encoders")]
            addr_of_mut!((*p).encoders).write(encoders::EncoderState::new());
        }
    }

    /// Never called: the compiler checks that this pattern names every
    /// field, so a field added to `Machine` without a write in
    /// `init_other_fields` does not build.
    #[allow(dead_code)]
    fn every_field_is_initialised(&self) {
        let Self {
            protocol: _,
            queue: _,
            modal: _,
            settings: _,
            running: _,
            wait_cancelled: _,
            last_busy_ms: _,
            keepalive_s: _,
            auto_report: _,
            last_report_ms: _,
            halted: _,
            steppers_enabled: _,
            fan_duty: _,
            endstop_trigger_levels: _,
            endstop_levels: _,
            hotend: _,
            bed: _,
            cold_extrusion: _,
            motion: _,
            position_lost: _,
            defaults: _,
            driver_alarms: _,
            safety_levels: _,
            safety_latched: _,
            #[cfg(feature = "extrusion-line")]
            line: _,
            #[cfg(feature = "powder-bed")]
            powder: _,
            #[cfg(feature = "encoders")]
            encoders: _,
        } = self;
    }

    /// The start banner, printed once at boot. `start` is what Printrun and
    /// OctoPrint look for to learn that the firmware (re)started.
    pub fn write_banner<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        crate::flash_concat!("start\necho:", crate::FIRMWARE_NAME, " ", crate::FIRMWARE_VERSION, " ready\n").write_to(out)
    }

    // --- what the board reads back -----------------------------------------

    pub fn modal(&self) -> &ModalState {
        &self.modal
    }

    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Whether the stepper drivers should be enabled.
    pub fn steppers_enabled(&self) -> bool {
        self.steppers_enabled && !self.halted
    }

    /// Part-cooling fan duty, 0–255 (0 while halted).
    pub fn fan_duty(&self) -> u8 {
        if self.halted {
            0
        } else {
            self.fan_duty
        }
    }

    /// Whether the firmware is halted (`M112` or a safety fault).
    pub fn is_halted(&self) -> bool {
        self.halted
    }

    // --- what the board tells us -------------------------------------------

    /// Latest raw endstop levels.
    pub fn set_endstop_levels(&mut self, levels: EndstopLevels) {
        self.endstop_levels = levels;
    }

    /// The drivers' ALARM inputs (SPEC §3: a closed-loop driver lost
    /// sync), as the board read them with their polarity: bit i = motor i.
    /// A new alarm stops every motor at once, says which, and refuses
    /// moves until `G28`, which waits until no alarm is active.
    pub fn on_driver_alarms<W: uWrite + ?Sized>(&mut self, alarms: u8, out: &mut W) -> Result<(), W::Error> {
        let new = alarms & !self.driver_alarms;
        self.driver_alarms = alarms;
        if new == 0 || self.halted {
            return Ok(());
        }
        self.motion.request_stop();
        self.lose_alarmed_position();
        let motor = new.trailing_zeros() as usize;
        let letter = AXIS_LETTERS.get(motor).copied().unwrap_or(b'?');
        ufmt::uwrite!(out, "Error:Driver alarm on {}: motion stopped, home with G28\n", char::from(letter))
    }

    /// Lines waiting in the command queue.
    pub fn queued_lines(&self) -> usize {
        self.queue.len()
    }

    /// Whether another line fits in the command queue.
    pub fn can_accept_line(&self) -> bool {
        !self.queue.is_full()
    }

    /// `M112` from the receive interrupt (or the queue): stop everything.
    /// The board has already forced its outputs off.
    #[inline(never)]
    pub fn kill<W: uWrite + ?Sized>(&mut self, out: &mut W) -> Result<(), W::Error> {
        if self.halted {
            return Ok(());
        }
        self.halted = true;
        self.hotend.turn_off();
        self.bed.turn_off();
        self.motion.request_stop();
        // The refused command's line: one copy of the text, in flash.
        CommandError::Halted.write(out)?;
        // The command that was running ends here and gets its `ok`; the
        // queued ones stay, to be refused one by one (each its `Error:`
        // and `ok`): a host waiting for `ok` is never left hanging.
        if !matches!(core::mem::replace(&mut self.running, Running::Idle), Running::Idle) {
            write_ok(out)?;
        }
        Ok(())
    }

    /// `M108` from the receive interrupt: end the current wait for a
    /// temperature or a dwell (motion waits and homing are not cut short:
    /// Marlin's `M108` only breaks heating waits and `M0`/`M1`).
    pub fn cancel_wait(&mut self) {
        self.wait_cancelled = matches!(self.running, Running::Dwell { .. } | Running::DwellAfterMotion { .. } | Running::HeatWait { .. });
    }

    /// `M410` from the receive interrupt: stop all motion now. The queued
    /// moves are dropped and, as the steps already made are not counted
    /// back, the position is lost until `G28`.
    pub fn quick_stop(&mut self) {
        self.motion.request_stop();
    }

    // --- the two steps -----------------------------------------------------

    /// Step 1: a complete line arrived. Refusals are answered now; accepted
    /// lines are queued (the caller checked [`Machine::can_accept_line`]).
    /// Free to inline into the board's one caller (`HostLink::service`),
    /// as `poll`: measured smaller on the AVR.
    pub fn receive_line<W: uWrite + ?Sized>(&mut self, line: Line<'_>, out: &mut W) -> Result<(), W::Error> {
        self.receive_line_then(line, out, || ())
    }

    /// [`Self::receive_line`]; a refusal that asks for a resend calls
    /// `before_resend` just before its `Resend:` line (the board discards
    /// the lines in flight there, see `HostLink::service`).
    pub fn receive_line_then<W: uWrite + ?Sized>(&mut self, line: Line<'_>, out: &mut W, before_resend: impl FnOnce()) -> Result<(), W::Error> {
        let body = match self.protocol.accept(line) {
            Ok(body) => body,
            Err(rejection) => return self.protocol.write_rejection_then(rejection, out, before_resend),
        };
        // Queue an empty line and fill it in place: no line-sized copy.
        if self.queue.push_back(LineText::new()).is_err() {
            // Only reachable if the board ignored can_accept_line(): say so
            // rather than drop the line silently.
            return self.protocol.write_rejection(crate::protocol::LineRejection::Damaged, out);
        }
        if let Some(text) = self.queue.back_mut() {
            // The body is a part of a line, so it always fits.
            let _ = text.extend_from_slice(body);
        }
        Ok(())
    }

    /// Take what the machine file says beyond the motion configuration
    /// ([`crate::machine_file`]): its heaters (thermistor tables, control,
    /// output, protections) with their default gains — which become the
    /// `M502` defaults — and its endstops' triggered levels (`M119`). The
    /// board calls it once at boot, after any `become_…`, before loading
    /// the stored settings.
    pub fn use_machine_file(&mut self) {
        let [hotend, bed] = crate::machine_file::heaters();
        if let Some((config, gains)) = hotend {
            self.hotend = HeaterChannel::new(config, gains);
            self.defaults.hotend_pid = gains_setting(gains);
        }
        if let Some((config, gains)) = bed {
            self.bed = HeaterChannel::new(config, gains);
            self.defaults.bed_pid = gains_setting(gains);
        }
        self.settings = self.defaults.clone();
        self.endstop_trigger_levels = crate::machine_file::ENDSTOP_TRIGGER_LEVELS;
    }

    /// Load the stored settings (at boot, and for `M501`), reporting the
    /// outcome; on any problem the defaults stay in force.
    pub fn load_settings<W: uWrite + ?Sized>(&mut self, storage: &mut dyn NonVolatile, out: &mut W) -> Result<(), W::Error> {
        let reported = self.report_loaded_settings(storage, out);
        self.apply_motion_settings();
        self.apply_heater_settings();
        reported
    }

    fn report_loaded_settings<W: uWrite + ?Sized>(&mut self, storage: &mut dyn NonVolatile, out: &mut W) -> Result<(), W::Error> {
        match storage::load_into(storage, &mut self.settings) {
            Ok(stored) => {
                crate::flash_concat!("echo:V", LAYOUT_VERSION_TEXT, " stored settings retrieved (").write_to(out)?;
                write_stored(&stored, out)
            }
            Err(error) => {
                match error {
                    LoadError::NoImage => out.write_str("echo:No stored settings\n")?,
                    LoadError::Corrupt { stored, computed } => ufmt::uwrite!(
                        out,
                        "echo:EEPROM CRC mismatch - (stored) {} != {} (calculated)!\n",
                        Whole(stored.into()),
                        Whole(computed.into())
                    )?,
                    LoadError::OldVersion(version) => {
                        ufmt::uwrite!(out, "echo:EEPROM version mismatch (EEPROM=V{}", Whole(version.into()))?;
                        crate::flash_concat!(" Firmware=V", LAYOUT_VERSION_TEXT, ")\n").write_to(out)?
                    }
                    LoadError::TooSmall => out.write_str("echo:EEPROM too small for the settings\n")?,
                    LoadError::OtherMachine => {
                        crate::flash_str!("echo:Stored settings belong to another machine file: not loaded (M500 saves this machine's)\n")
                            .write_to(out)?
                    }
                }
                self.settings = self.defaults.clone();
                out.write_str("echo:Hardcoded Default Settings Loaded\n")
            }
        }
    }

    #[inline(never)]
    fn save_settings<W: uWrite + ?Sized>(&self, storage: &mut dyn NonVolatile, out: &mut W) -> Result<(), W::Error> {
        match storage::save(storage, &self.settings) {
            Ok(stored) => {
                out.write_str("echo:Settings Stored (")?;
                write_stored(&stored, out)
            }
            Err(storage::SaveError::TooSmall) => out.write_str("Error:EEPROM too small for the settings\n"),
            Err(storage::SaveError::WriteFailed) => out.write_str("Error:Settings not stored: the storage did not take the write\n"),
        }
    }

    /// Step 2: run queued commands. `now_ms` is a free-running millisecond
    /// clock (wrapping); `storage` holds the settings for `M500`/`M501`.
    pub fn poll<W: uWrite + ?Sized>(
        &mut self,
        now_ms: u32,
        storage: &mut dyn NonVolatile,
        out: &mut W,
    ) -> Result<(), W::Error> {
        self.auto_report(now_ms, out)?;
        loop {
            if !matches!(self.running, Running::Idle) {
                if !self.running_done(now_ms, out)? {
                    return self.keep_alive(now_ms, out);
                }
                self.running = Running::Idle;
                self.wait_cancelled = false;
                write_ok(out)?;
            }
            // A line still being cut into a full planner holds back the
            // next command (as Marlin blocks in its planner), so commands
            // take effect in the order they were sent.
            if !self.motion.ready() {
                // A line waits for room in the planner: the host waits for
                // its `ok`, so it hears `busy` as during `G28` or `M109`
                // (issue 22: 6.4 s of silence and OctoPrint timed out).
                if !self.queue.is_empty() {
                    return self.keep_alive(now_ms, out);
                }
                return Ok(());
            }
            let Some(text) = self.queue.pop_front() else { return Ok(()) };
            self.last_busy_ms = now_ms;
            self.run_line(&text, now_ms, storage, out)?;
        }
    }

    /// `echo:busy: processing` when a line has waited another keep-alive
    /// interval (Marlin's host keep-alive; `M113 S0`: never).
    fn keep_alive<W: uWrite + ?Sized>(&mut self, now_ms: u32, out: &mut W) -> Result<(), W::Error> {
        let interval = u32::from(self.keepalive_s) * 1000;
        if interval != 0 && now_ms.wrapping_sub(self.last_busy_ms) >= interval {
            self.last_busy_ms = now_ms;
            out.write_str("echo:busy: processing\n")?;
        }
        Ok(())
    }

    /// `M113 S<s>` sets the keep-alive interval (0–60 s, 0: off); bare
    /// `M113` reports it, as Marlin.
    fn keep_alive_command<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W) -> Result<Result<(), CommandError>, W::Error> {
        match command.value(b'S') {
            Err(error) => return Ok(Err(error.into())),
            Ok(Some(value)) => match value.to_int() {
                Some(seconds @ 0..=60) => self.keepalive_s = seconds as u8,
                _ => return Ok(Err(CommandError::OutOfRange(b'S'))),
            },
            Ok(None) => ufmt::uwrite!(out, "echo:M113 S{}\n", Whole(self.keepalive_s.into()))?,
        }
        Ok(Ok(()))
    }

    /// Execute one line and answer it (or start it). Out of line, with the
    /// `Outcome` in its frame: in `poll`'s, beside the line, it made the
    /// frame larger and its accesses longer (measured: 68 bytes more).
    #[inline(never)]
    fn run_line<W: uWrite + ?Sized>(
        &mut self,
        text: &[u8],
        now_ms: u32,
        storage: &mut dyn NonVolatile,
        out: &mut W,
    ) -> Result<(), W::Error> {
        match self.execute(text, now_ms, storage, out)? {
            Outcome::Done => write_ok(out),
            Outcome::Acknowledged => Ok(()),
            Outcome::Failed(error) => {
                error.write(out)?;
                write_ok(out)
            }
            // `running` is already set.
            Outcome::Started => Ok(()),
        }
    }


    fn auto_report<W: uWrite + ?Sized>(&mut self, now_ms: u32, out: &mut W) -> Result<(), W::Error> {
        if self.auto_report.due(now_ms) {
            out.write_str(" ")?;
            self.write_temperatures(out)?;
        }
        Ok(())
    }

    /// Inlined into its one caller, `run_line`.
    #[inline(always)]
    fn execute<W: uWrite + ?Sized>(
        &mut self,
        text: &[u8],
        now_ms: u32,
        storage: &mut dyn NonVolatile,
        out: &mut W,
    ) -> Result<Outcome, W::Error> {
        // SAFETY: the main loop; the protocol's use of the command ended
        // with the line's reception.
        #[cfg(target_arch = "avr")]
        let command = unsafe { Command::scratch() };
        #[cfg(not(target_arch = "avr"))]
        let command = &mut Command::new(Code::Other);
        match gcode::parse_into(text, command) {
            Ok(()) => {}
            Err(ParseError::Empty) => return Ok(Outcome::Done),
            // Arguments that do not parse are an error only for commands we
            // run: Marlin answers `M115 U3.13.0` (PrusaSlicer's version
            // check) and echoes unknown ones (`M862.3 P "MK3S"`) whatever
            // their arguments, and hosts treat an `Error:` line as fatal.
            Err(error) => match gcode::code_of(text) {
                Some(Code::M(115)) => {
                    self.write_capabilities(out)?;
                    return Ok(Outcome::Done);
                }
                Some(code) if commands::listing(code, self.kind()).is_none() => {
                    self.unknown_command(text, out)?;
                    return Ok(Outcome::Done);
                }
                _ => return Ok(Outcome::Failed(error.into())),
            },
        };
        for &code in command.settings.iter() {
            if self.halted {
                return Ok(Outcome::Failed(CommandError::Halted));
            }
            if let Err(error) = self.apply_setting(code, out)? {
                self.modal.machine_frame = false;
                return Ok(Outcome::Failed(error));
            }
        }
        let outcome = self.dispatch(command, text, now_ms, storage, out);
        self.modal.machine_frame = false;
        outcome
    }

    /// A code that only sets a mode (`gcode::is_mode_setting`), alone or
    /// as one of several on a CAM line (`G17 G90 G94`).
    #[inline(never)]
    fn apply_setting<W: uWrite + ?Sized>(&mut self, code: Code, out: &mut W) -> Result<Result<(), CommandError>, W::Error> {
        let modal = &mut self.modal;
        match code {
            Code::G(17) => modal.plane = Plane::Xy,
            Code::G(18) => modal.plane = Plane::Zx,
            Code::G(19) => modal.plane = Plane::Yz,
            // This line's move in machine coordinates (G0/G1 only, Grbl).
            Code::G(53) => modal.machine_frame = true,
            Code::G(20) => modal.units = Units::Inches,
            Code::G(21) => modal.units = Units::Millimetres,
            Code::G(90) => self.set_distance(Distance::Absolute),
            Code::G(91) => self.set_distance(Distance::Relative),
            // Work coordinate systems (offsets from G10 L2/L20).
            Code::G(n @ 54..=59) => modal.work = (n - 54) as u8,
            // The only feed mode.
            Code::G(94) if modal.unsupported == Some(Code::G(93)) => modal.unsupported = None,
            Code::G(93) => {
                modal.unsupported = Some(code);
                return Ok(Err(CommandError::UnsupportedMode(code)));
            }
            // Spindle and coolant: this machine has neither, so "off" holds.
            Code::M(3 | 4 | 7 | 8) => {
                let Code::M(number) = code else { return Ok(Ok(())) };
                ufmt::uwrite!(out, "echo:M{} ignored: no spindle or coolant on this machine\n", Whole(number.into()))?;
            }
            // Nothing of these is ever active: no cutter or tool-length
            // compensation, no canned cycles; path blending is the planner's.
            _ => {}
        }
        Ok(Ok(()))
    }

    /// `M2`/`M30`: the program is over (Grbl): back to the default modes.
    fn end_program(&mut self) {
        self.set_distance(Distance::Absolute);
        self.modal.plane = Plane::Xy;
        self.modal.work = 0;
        self.modal.unsupported = None;
        self.modal.motion_mode = MotionMode::Linear;
    }

    /// Run a parsed command. Out of line from `execute` so that the parsed
    /// words stay in `execute`'s frame: on the AVR a frame larger than 64
    /// bytes makes every access to it several instructions longer.
    ///
    /// The arms' bodies are small functions of their own, for reading; most
    /// are `inline(always)`: measured on the AVR, each one called out of
    /// line cost more (the `Outcome` copied through memory, the arguments
    /// set up again) than it saved in this function.
    #[inline(never)]
    fn dispatch<W: uWrite + ?Sized>(
        &mut self,
        command: &Command,
        text: &[u8],
        now_ms: u32,
        storage: &mut dyn NonVolatile,
        out: &mut W,
    ) -> Result<Outcome, W::Error> {
        // The command table decides: a code this machine does not list is
        // unknown; halted, the machine still answers what only reports or
        // waits (hosts keep polling M105) and refuses what would act.
        let listing = commands::listing(command.code, self.kind());
        // The table test's second half: with the gate open, a code no row
        // lists must still reach the `match`'s "unknown" arm.
        #[cfg(test)]
        let listing = listing.or(tests::GATE_OPEN.get().then_some(Halted::Runs));
        match listing {
            None => return self.unknown_command(text, out).map(|()| Outcome::Done),
            Some(Halted::Refused) if self.halted => return Ok(Outcome::Failed(CommandError::Halted)),
            Some(_) => {}
        }
        #[cfg(feature = "powder-bed")]
        if let Some(result) = self.bed_command(command, out)? {
            return Ok(match result {
                Ok(Some(running)) => self.start(running),
                Ok(None) => Outcome::Done,
                Err(error) => Outcome::Failed(error),
            });
        }
        // The encoder loops are a printer's (host builds keep every
        // machine: not the line's or the bed's, which has its own M821–M823).
        #[cfg(feature = "encoders")]
        if self.kind() == Kind::Printer {
            if let Some(result) = self.encoder_command(command, out)? {
                return Ok(match result {
                    Ok(()) => Outcome::Done,
                    Err(error) => Outcome::Failed(error),
                });
            }
        }
        #[cfg(feature = "extrusion-line")]
        if let Some(result) = self.line_command(command, out)? {
            return Ok(match result {
                Ok(()) => Outcome::Done,
                Err(error) => Outcome::Failed(error),
            });
        }
        let result = match command.code {
            #[cfg(feature = "printer")]
            Code::G(0 | 1) | Code::Modal => self.linear_move(command, out),
            #[cfg(feature = "printer")]
            Code::G(2 | 3) => self.arc_move(command, out),
            Code::G(4) => return Ok(self.dwell_command(command)),
            #[cfg(feature = "printer")]
            Code::G(28) => return Ok(self.home_command(command)),
            // A build without the printers (the extrusion line or the
            // powder bed alone): their motion commands are not here.
            #[cfg(not(feature = "printer"))]
            Code::G(0..=3 | 28) | Code::Modal => Err(CommandError::NotThisMachine),
            // Reports and switches hosts send on their own (OctoPrint and
            // Printrun poll M114): an echo, not an `Error:` a host might
            // take as fatal.
            #[cfg(not(feature = "printer"))]
            Code::M(code @ (114 | 119 | 120 | 121)) => {
                ufmt::uwrite!(out, "echo:M{} ignored: this machine has no printer axes\n", Whole(code.into()))?;
                Ok(())
            }
            code if gcode::is_mode_setting(code) => self.apply_setting(code, out)?,
            Code::M(2 | 30) => {
                self.end_program();
                return Ok(self.start(Running::WaitForMotion { then_disable: false }));
            }
            Code::G(92) => self.modal.set_logical_position(command),
            Code::M(82) => {
                self.modal.extruder_distance = Distance::Absolute;
                Ok(())
            }
            Code::M(83) => {
                self.modal.extruder_distance = Distance::Relative;
                Ok(())
            }
            Code::M(17) => {
                self.steppers_enabled = true;
                Ok(())
            }
            Code::M(18 | 84) => return Ok(self.start(Running::WaitForMotion { then_disable: true })),
            Code::M(105) => {
                self.report_temperatures_on_ok(out)?;
                return Ok(Outcome::Acknowledged);
            }
            Code::M(106) => self.set_fan(command),
            Code::M(107) => {
                self.fan_duty = 0;
                Ok(())
            }
            // M108 and M410 act from the receive interrupt; M110 in the
            // protocol layer. Here they only get their `ok`.
            Code::M(108 | 110 | 410) => Ok(()),
            Code::M(112) => {
                self.kill(out)?;
                Ok(())
            }
            #[cfg(feature = "printer")]
            Code::M(114) => self.report_position(out).map(Ok)?,
            Code::M(115) => self.write_capabilities(out).map(Ok)?,
            // M73 (PrusaSlicer's progress): no display here, accepted
            // silently as Marlin without one; M117 likewise.
            Code::M(73 | 117) => Ok(()),
            Code::M(113) => self.keep_alive_command(command, out)?,
            Code::M(118) => self.echo(text, out).map(Ok)?,
            #[cfg(feature = "printer")]
            Code::M(119) => self.report_endstops(out).map(Ok)?,
            Code::M(155) => self.set_auto_report(command, now_ms),
            Code::M(400) => return Ok(self.start(Running::WaitForMotion { then_disable: false })),
            #[cfg(feature = "printer")]
            Code::M(code @ (120 | 121)) => self.set_endstops_always(code == 120),
            #[cfg(feature = "delta")]
            Code::M(665) => self.delta_geometry(command, out),
            #[cfg(feature = "delta")]
            Code::M(666) => self.delta_trim(command, out),
            Code::M(number @ (92 | 201 | 203 | 204 | 205 | 220 | 221)) => self.change_settings(number, command),
            Code::M(500) => self.save_settings(storage, out).map(Ok)?,
            Code::M(501) => {
                self.load_settings(storage, out)?;
                Ok(())
            }
            Code::M(502) => self.restore_defaults(out).map(Ok)?,
            Code::M(503) => self.settings.report(out).map(Ok)?,
            Code::T(tool) => self.select_tool(tool, out).map(Ok)?,
            // The heaters (not on the powder bed, which has none).
            #[cfg(feature = "heaters")]
            Code::M(104 | 140 | 109 | 190 | 303) => return self.heater_command(command, now_ms, out),
            #[cfg(feature = "heaters")]
            Code::M(code @ (301 | 304)) => {
                self.set_pid(command, if code == 301 { HeaterSlot::Hotend } else { HeaterSlot::Bed }, out)
            }
            #[cfg(feature = "heaters")]
            Code::M(302) => self.cold_extrusion_command(command, out),
            #[cfg(not(feature = "heaters"))]
            Code::M(104 | 109 | 140 | 190 | 301 | 302 | 303 | 304) => Err(CommandError::NotThisMachine),
            // Grbl's G10 L2 / L20: work offsets. Without L it would be
            // Marlin's firmware retraction, which this build does not have.
            Code::G(10) if command.has(b'L') => self.modal.work_offsets_command(command),
            Code::G(10 | 11) => self.not_yet_available(text, out).map(Ok)?,
            _ => self.unknown_command(text, out).map(Ok)?,
        };
        Ok(match result {
            Ok(()) => Outcome::Done,
            Err(error) => Outcome::Failed(error),
        })
    }

    /// Start a command that runs on (`ok` when it finishes).
    #[inline(always)]
    fn start(&mut self, running: Running) -> Outcome {
        self.running = running;
        Outcome::Started
    }

    /// `M105`: Marlin puts the report on the `ok` line itself.
    #[inline(always)]
    fn report_temperatures_on_ok<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        out.write_str("ok ")?;
        self.write_temperatures(out)
    }

    /// `G4`.
    #[inline(always)]
    fn dwell_command(&mut self, command: &Command) -> Outcome {
        self.dwell(command)
    }

    #[cfg(feature = "printer")]
    /// `G28`; refused while a driver alarms or a safety trip is not re-armed.
    #[inline(always)]
    fn home_command(&mut self, command: &Command) -> Outcome {
        if let Err(refusal) = self.safety_check() {
            return Outcome::Failed(refusal);
        }
        if self.driver_alarms != 0 {
            return Outcome::Failed(CommandError::DriverAlarm);
        }
        self.home(command)
    }

    #[cfg(feature = "printer")]
    /// `M120`/`M121`: endstops checked during every move, or while homing only.
    #[inline(always)]
    fn set_endstops_always(&mut self, always: bool) -> Result<(), CommandError> {
        self.motion.set_endstops_always(always);
        Ok(())
    }

    /// `M502`: back to the machine's defaults (in force, not stored).
    #[inline(always)]
    fn restore_defaults<W: uWrite + ?Sized>(&mut self, out: &mut W) -> Result<(), W::Error> {
        self.settings = self.defaults.clone();
        self.apply_motion_settings();
        self.apply_heater_settings();
        out.write_str("echo:Hardcoded Default Settings Loaded\n")
    }

    /// `T<n>`: only `T0` exists.
    #[inline(always)]
    fn select_tool<W: uWrite + ?Sized>(&self, tool: u16, out: &mut W) -> Result<(), W::Error> {
        if tool < EXTRUDERS {
            return Ok(());
        }
        ufmt::uwrite!(out, "echo:T{} Invalid extruder\n", Whole(tool.into()))
    }

    #[cfg(feature = "heaters")]
    /// The heater commands that may start a wait or a tune (`M104`,
    /// `M140`, `M109`, `M190`, `M303`).
    #[inline(always)]
    fn heater_command<W: uWrite + ?Sized>(&mut self, command: &Command, now_ms: u32, out: &mut W) -> Result<Outcome, W::Error> {
        match command.code {
            // One call site for the four: each call set up its arguments
            // (the wait's configuration on the stack) anew.
            Code::M(code @ (104 | 140 | 109 | 190)) => {
                let slot = if matches!(code, 104 | 109) { HeaterSlot::Hotend } else { HeaterSlot::Bed };
                let wait = match code {
                    109 => Some(WaitConfig::HOTEND),
                    190 => Some(WaitConfig::BED),
                    _ => None,
                };
                self.set_temperature(command, slot, wait, now_ms, out)
            }
            _ => self.autotune(command, out),
        }
    }

    /// The kind of machine this is ([`commands::Kind`]): the `become_…`
    /// the board called, a printer otherwise.
    pub fn kind(&self) -> Kind {
        #[cfg(feature = "extrusion-line")]
        if self.line.is_some() {
            return Kind::Line;
        }
        #[cfg(feature = "powder-bed")]
        if self.powder.is_some() {
            return Kind::Bed;
        }
        Kind::Printer
    }

    /// `M115`, as the command table has it for this machine.
    fn write_capabilities<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        commands::capabilities(self.kind()).write_to(out)
    }

    /// A code the executor does not run: echoed, as Marlin does.
    #[inline(always)]
    fn unknown_command<W: uWrite + ?Sized>(&self, text: &[u8], out: &mut W) -> Result<(), W::Error> {
        write_quoted(out, "echo:Unknown command: \"", text, "\"\n")
    }

    /// Hand the settings to the motion core (printers only: the extrusion
    /// line and the powder bed do not move through it).
    fn apply_motion_settings(&mut self) {
        #[cfg(feature = "printer")]
        self.motion.apply_settings(&self.settings);
    }

    #[inline(always)]
    fn not_yet_available<W: uWrite + ?Sized>(&self, text: &[u8], out: &mut W) -> Result<(), W::Error> {
        write_quoted(out, "echo:\"", text, "\" is not available yet in this build\n")
    }

    fn set_distance(&mut self, distance: Distance) {
        // G90/G91 switch E too (Marlin); M82/M83 then override E alone.
        self.modal.distance = distance;
        self.modal.extruder_distance = distance;
    }

    /// `M92`, `M201`, `M203`, `M204`, `M205`, `M220`, `M221`: change the
    /// settings all or nothing (a refused word leaves every value as it
    /// was), then hand them to motion (they apply to the moves accepted
    /// from now on). Driven by [`SETTING_WORDS`]: one loop for every
    /// command, where a function per command cost a kilobyte on the AVR.
    ///
    /// Two passes, read then store, rather than a changed copy of the
    /// settings: the copy (108 bytes) made the frame too large for the
    /// AVR's short stack addressing. Left to inline into `dispatch`, its
    /// one caller (measured smaller), as are `report_position` and
    /// `report_endstops`.
    fn change_settings(&mut self, number: u16, command: &Command) -> Result<(), CommandError> {
        // The command's values in table order; i32::MIN (below every
        // range) for a word not given.
        let mut values = [i32::MIN; MAX_SETTING_WORDS];
        let mut given = values.iter_mut();
        for index in 0..SETTING_WORDS.len() {
            let Some(word) = SETTING_WORDS.get(index).filter(|word| word.code == number) else { continue };
            let Some(value) = given.next() else { break };
            let Some((min, max)) = settings::RANGES.get(usize::from(word.range)) else { continue };
            set_scaled(command, word.letter, word.digits, min, max, value)?;
        }
        let mut given = values.iter();
        for index in 0..SETTING_WORDS.len() {
            let Some(word) = SETTING_WORDS.get(index).filter(|word| word.code == number) else { continue };
            let Some(&value) = given.next() else { break };
            if value == i32::MIN {
                continue;
            }
            // `M204 S` sets print and travel together (older hosts send
            // it); its row comes first, so `P` and `T` on the same line win.
            if word.slot == BOTH_ACCELERATIONS {
                self.settings.print_accel_um_per_s2 = value;
                self.settings.travel_accel_um_per_s2 = value;
            } else {
                self.settings.set_slot(usize::from(word.slot), value);
            }
        }
        self.apply_motion_settings();
        Ok(())
    }

    fn set_fan(&mut self, command: &Command) -> Result<(), CommandError> {
        let mut duty = 255;
        set_scaled(command, b'S', 0, 0, 255, &mut duty)?;
        self.fan_duty = duty as u8;
        Ok(())
    }

    fn set_auto_report(&mut self, command: &Command, now_ms: u32) -> Result<(), CommandError> {
        let mut seconds = 1;
        set_scaled(command, b'S', 0, 0, 60, &mut seconds)?;
        self.auto_report.set_interval(seconds as u8, now_ms);
        Ok(())
    }

    #[cfg(feature = "printer")]
    /// `M114`: `X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0`.
    fn report_position<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        for (axis, letter) in AXIS_LETTERS.iter().enumerate() {
            ufmt::uwrite!(out, "{}:{} ", char::from(*letter), micrometres_as_mm(self.modal.logical(axis)))?;
        }
        let [x, y, z, _] = self.motion.motor_steps();
        ufmt::uwrite!(out, "Count X:{} Y:{} Z:{}\n", Fixed::whole(x), Fixed::whole(y), Fixed::whole(z))
    }

    /// `M118 [E1] <text>`: print the text (with `echo:` when `E1`).
    #[inline(always)]
    fn echo<W: uWrite + ?Sized>(&self, text: &[u8], out: &mut W) -> Result<(), W::Error> {
        let mut message = gcode::text_argument(text);
        // `E1 ` or `e1 ` first: the line is an `echo:`.
        if let [b'E' | b'e', b'1', b' ', rest @ ..] = message {
            out.write_str("echo:")?;
            message = rest;
        }
        ufmt::uwrite!(out, "{}\n", Printable(message))
    }

    #[cfg(feature = "printer")]
    /// `M119`: Marlin's endstop report.
    fn report_endstops<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        out.write_str("Reporting endstop status\n")?;
        // `x_min`, `x_max`, `y_min`, ...: built from the bit number rather
        // than a table of six names (which lived in RAM).
        // Bit set: the level is the triggered one. A running mask rather
        // than shifts by the bit number (a loop each on the AVR).
        let triggered_bits = !(self.endstop_levels ^ self.endstop_trigger_levels);
        let mut mask = 1u8;
        for bit in 0..ENDSTOPS {
            let triggered = triggered_bits & mask != 0;
            mask <<= 1;
            out.write_char(char::from(b'x' + (bit >> 1)))?;
            out.write_str(if bit & 1 == 0 { "_min" } else { "_max" })?;
            out.write_str(if triggered { ": TRIGGERED\n" } else { ": open\n" })?;
        }
        Ok(())
    }
}

/// `<bytes> bytes; crc <crc>)`, the end of `M500`'s and `M501`'s report:
/// one copy of the code for both.
#[inline(never)]
fn write_stored<W: uWrite + ?Sized>(stored: &storage::Stored, out: &mut W) -> Result<(), W::Error> {
    ufmt::uwrite!(out, "{} bytes; crc {})\n", Whole(stored.bytes as u16), Whole(stored.crc.into()))
}

/// `before`, the line's text (trimmed, unprintable bytes masked), `after`:
/// one copy of the code for every echo of a line.
#[inline(never)]
fn write_quoted<W: uWrite + ?Sized>(out: &mut W, before: &str, text: &[u8], after: &str) -> Result<(), W::Error> {
    out.write_str(before)?;
    ufmt::uwrite!(out, "{}", Printable(trim(text)))?;
    out.write_str(after)
}

/// `ok`: one call with no text argument to set up, from every place that
/// acknowledges a line.
#[inline(never)]
fn write_ok<W: uWrite + ?Sized>(out: &mut W) -> Result<(), W::Error> {
    out.write_str("ok\n")
}

/// What executing a command led to.
enum Outcome {
    /// Finished: send `ok`.
    Done,
    /// Finished, and the reply already carried the `ok` (`M105`).
    Acknowledged,
    /// Refused: send the error, then `ok`.
    Failed(CommandError),
    /// Still running (`Machine::running` says what): `ok` when it
    /// finishes. The running state is stored where it is kept, not
    /// carried here: with the auto-tune in it, this made the executor's
    /// frame larger than the 63 bytes the AVR reaches in one instruction.
    Started,
}

#[cfg(feature = "printer")]
/// Micrometres shown as millimetres with two decimals, rounded.
fn micrometres_as_mm(um: i32) -> Fixed {
    let rounded = if um >= 0 { (um + 5) / 10 } else { (um - 5) / 10 };
    Fixed::hundredths(rounded)
}

fn trim(text: &[u8]) -> &[u8] {
    let start = text.iter().position(|&b| b != b' ').unwrap_or(text.len());
    let end = text.iter().rposition(|&b| b != b' ').map_or(start, |i| i + 1);
    &text[start..end.max(start)]
}

/// If `command` has `letter`, its value in units of 10^-`digits` goes to
/// `slot`; out of range unless it lies in `min..=max`. One out-of-line
/// helper for every numeric setting: the same steps inlined in each
/// command came to several hundred bytes more on the AVR.
#[inline(never)]
fn set_scaled(command: &Command, letter: u8, digits: u8, min: i32, max: i32, slot: &mut i32) -> Result<(), CommandError> {
    if let Some(value) = command.value(letter)? {
        match value.to_scaled(digits) {
            Some(scaled) if scaled >= min && scaled <= max => *slot = scaled,
            _ => return Err(CommandError::OutOfRange(letter)),
        }
    }
    Ok(())
}

/// Most words one settings command takes (`M92 X Y Z E`).
const MAX_SETTING_WORDS: usize = 4;

/// `Word::slot` of `M204 S`: print and travel acceleration both.
const BOTH_ACCELERATIONS: u8 = u8::MAX;

/// Every word the settings commands take, in the order they are read (the
/// first refused one is the error reported): the settings declaration's
/// (`settings::words`), after `M204 S`, which sets two of them.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
static SETTING_WORDS: crate::progmem::Flash<[settings::Word; settings::WORDS + 1]> = crate::progmem::Flash::new({
    let declared = settings::words();
    let range = settings::range::POSITIVE;
    let mut words = [settings::Word { code: 204, letter: b'S', digits: 3, range, slot: BOTH_ACCELERATIONS }; settings::WORDS + 1];
    let mut i = 0;
    while i < declared.len() {
        assert!(declared[i].slot != BOTH_ACCELERATIONS);
        words[i + 1] = declared[i];
        i += 1;
    }
    words
});

/// The machine's default settings, in place: what its machine file's
/// motion configuration says (steps/mm, feeds, accelerations, junction
/// deviation, a delta's geometry) in milli-units, the rest as on the Prusa
/// i3 ([`settings::PRUSA_I3`]); the heaters' gains follow in
/// [`Machine::use_machine_file`]. Here, above both the settings and the
/// motion core, so that neither imports the other's.
///
/// The boot is where the Prusa i3 with every option reaches its deepest
/// stack: `Settings::prusa_i3()` written in place would save 8 bytes
/// there, but that build reset in a loop on QEMU's Mega 2560 right after
/// boot (not understood yet; simavr ran it): the copy out of flash stays.
fn init_defaults(slot: &mut MaybeUninit<Settings>, config: &MotionConfig) {
    let milli = |figure: f32| crate::motion::math::round_to_i32(figure * 1000.0);
    let defaults = slot.write(settings::PRUSA_I3.load());
    defaults.steps_per_mm_milli = config.steps_per_mm.map(milli);
    defaults.max_feed_um_per_s = config.max_feed.map(milli);
    defaults.max_accel_um_per_s2 = config.max_accel.map(milli);
    defaults.print_accel_um_per_s2 = milli(config.print_accel);
    defaults.retract_accel_um_per_s2 = milli(config.retract_accel);
    defaults.travel_accel_um_per_s2 = milli(config.travel_accel);
    defaults.junction_deviation_um = milli(config.junction_deviation);
    #[cfg(feature = "delta")]
    if let crate::motion::kinematics::MachineKinematics::Delta(delta) = &config.kinematics {
        defaults.delta_geometry_um = [milli(delta.rod_length()), milli(delta.radius()), milli(delta.homed_height)];
        defaults.delta_trim_um = delta.endstop_trim.map(milli);
    }
}

/// Gains as the settings keep them (Marlin's units × 10⁴ in `i32`s).
fn gains_setting(gains: Gains) -> [i32; 3] {
    [gains.kp, gains.ki, gains.kd].map(|g| g.min(i32::MAX as u32) as i32)
}

/// [`storage::LAYOUT_VERSION`] as text, for the constant parts of the
/// `M501` replies (one string in flash, no number to print).
const LAYOUT_VERSION_TEXT: &str = ["0", "1", "2", "3", "4", "5", "6", "7", "8", "9"][storage::LAYOUT_VERSION as usize];

/// [`EXTRUDERS`] as text, for the constant `M115` reply.
const EXTRUDERS_TEXT: &str = ["0", "1", "2", "3", "4", "5", "6", "7", "8", "9"][EXTRUDERS as usize];

#[cfg(test)]
mod tests;
