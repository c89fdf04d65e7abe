//! The executor's motion commands: `G0`–`G3`, `G4`, `G28`, `M400`,
//! `M18`/`M84`, and the main loop's motion duty ([`Machine::poll_motion`]).
//!
//! The executor speaks the modal state's machine coordinates (µm, `G92`
//! offsets removed) and hands finished targets to [`crate::motion`]; it
//! never waits for a move to be stepped out except where the G-code says
//! so (`G4`, `M400`, `M18`/`M84`, `G28`).
//!
//! Choices that follow Marlin:
//! - Soft limits of a Cartesian machine clamp the target on the axes that
//!   have been homed (Marlin's `apply_motion_limits`); an axis that was
//!   never homed is not limited, so it can be jogged to its switch.
//!   Deltas and the arm refuse what they cannot reach instead.
//! - Cold extrusion (`M302`): a move that would push filament while the
//!   hot end is too cold still moves X/Y/Z, but not E
//!   (`echo: cold extrusion prevented`); retractions always run.
//! - `G28` names axes by their letters (`G28 X Y`); no letter: all.
//!
//! Our own: a motion fault (a hard limit hit outside homing, `M410`, a
//! step-queue stop) loses the position, so moves are refused with
//! `Error:` until the machine is homed again.

use super::error::CommandError;
#[cfg(feature = "printer")]
use super::modal::{MotionMode, AXES};
#[cfg(feature = "printer")]
use crate::motion::Plane;
use super::{Machine, Outcome, Running};
use crate::gcode::Command;
#[cfg(feature = "printer")]
use crate::gcode::Code;
#[cfg(feature = "printer")]
use crate::motion::kinematics::MachineKinematics;
#[cfg(feature = "printer")]
use crate::motion::{math::to_i32, ArcCentre, E};
use crate::motion::{MotionError, StepFault, StepperRequest, StepperStatus};
use ufmt::uWrite;

impl<'q> Machine<'q> {
    /// Every pass of the main loop, before [`Machine::poll`]: hand the step
    /// interrupt's status to the planner side, refill the step queues, and
    /// report what went wrong. The board then does what the returned
    /// request says to its step generator.
    pub fn poll_motion<W: uWrite + ?Sized>(
        &mut self,
        status: &StepperStatus,
        now_ms: u32,
        out: &mut W,
    ) -> Result<StepperRequest, W::Error> {
        let request = self.motion.poll(status, now_ms);
        if let Some(error) = self.motion.take_error() {
            self.motion_failed(error, out)?;
        }
        Ok(request)
    }

    /// Whether everything accepted has been stepped out.
    pub fn motion_idle(&self) -> bool {
        self.motion.is_idle()
    }

    /// Motor positions where queued motion ends, steps (X, Y, Z, E).
    pub fn motor_steps(&self) -> [i32; 4] {
        self.motion.motor_steps()
    }

    fn motion_failed<W: uWrite + ?Sized>(
        &mut self,
        error: MotionError,
        out: &mut W,
    ) -> Result<(), W::Error> {
        match error {
            MotionError::HomingFailed(_) => {
                // Marlin halts when a switch never triggers: the machine
                // may be pushing against its frame.
                out.write_str("Error:Homing Failed\n")?;
                self.kill(out)
            }
            MotionError::Fault(StepFault::Stopped) => {
                // M410 or a kill: the steps already made are not counted
                // back, so the position is unknown.
                self.lose_position();
                Ok(())
            }
            MotionError::Fault(StepFault::LimitHit(switches)) => {
                self.lose_position();
                ufmt::uwrite!(out, "Error:Endstop hit during a move (switches {}): motion stopped, home with G28\n", crate::reply::Whole(switches.into()))
            }
            other => {
                self.lose_position();
                CommandError::Motion(other).write(out)
            }
        }
    }

    /// An ALARM stopped the motors: as a lost position.
    pub(super) fn lose_alarmed_position(&mut self) {
        self.lose_position();
    }

    fn lose_position(&mut self) {
        self.position_lost = true;
        if matches!(
            self.running,
            Running::Homing | Running::WaitForMotion { .. } | Running::DwellAfterMotion { .. }
        ) {
            // What they waited for will not happen as planned; finish them
            // (their `ok` follows) rather than hang the host.
            self.wait_cancelled = true;
        }
    }

    /// Does a running command finish now? Moves the `G4` from "wait for
    /// motion" to "wait for the time".
    pub(super) fn running_done<W: uWrite + ?Sized>(
        &mut self,
        now_ms: u32,
        out: &mut W,
    ) -> Result<bool, W::Error> {
        if self.wait_cancelled {
            return Ok(true);
        }
        Ok(match self.running {
            Running::Idle => true,
            Running::DwellAfterMotion { ms } => {
                if self.motion.is_idle() {
                    self.running = Running::Dwell {
                        until_ms: now_ms.wrapping_add(ms),
                    };
                    ms == 0
                } else {
                    false
                }
            }
            Running::Dwell { until_ms } => (now_ms.wrapping_sub(until_ms) as i32) >= 0,
            Running::WaitForMotion { then_disable } => {
                let idle = self.motion.is_idle();
                if idle && then_disable {
                    self.steppers_enabled = false;
                    // A machine that must home (SPEC §3's arm) does not know
                    // where free motors went: home again.
                    if self.motion.config.must_home {
                        self.motion.forget_home();
                    }
                }
                idle
            }
            Running::Homing => {
                if self.motion.is_homing() {
                    false
                } else {
                    self.homing_finished(out)?;
                    true
                }
            }
            Running::HeatWait { .. } => return self.heat_wait_done(now_ms, out),
            Running::Autotune { .. } => false,
            Running::AutotuneDone => true,
            #[cfg(feature = "powder-bed")]
            Running::BedJob => self.bed_job_done(),
        })
    }

    #[cfg(feature = "printer")]
    /// `G0`/`G1` (or bare axis words): validate fully, then hand over.
    pub(super) fn linear_move<W: uWrite + ?Sized>(
        &mut self,
        command: &Command,
        out: &mut W,
    ) -> Result<(), CommandError> {
        let mode = match command.code {
            Code::G(0) => MotionMode::Rapid,
            Code::G(1) => MotionMode::Linear,
            _ => self.modal.motion_mode,
        };
        // A line with no axis word and no code (`F300` after `G2 …`, as
        // dxf2gcode writes) moves nothing in any motion mode (Grbl,
        // LinuxCNC, Marlin): its `F` is a modal setting.
        if command.code == Code::Modal && !super::modal::AXIS_LETTERS.iter().any(|&letter| command.has(letter)) {
            if let Some(feed) = self.modal.read_feed(command)? {
                self.modal.feed_um_per_s = feed;
            }
            return Ok(());
        }
        if matches!(
            mode,
            MotionMode::ClockwiseArc | MotionMode::CounterClockwiseArc
        ) {
            return self.arc_move(command, out);
        }
        let feed = self.modal.read_feed(command)?;
        let mut target = self.modal.target(command)?;
        self.modal.motion_mode = mode;
        if let Some(feed) = feed {
            self.modal.feed_um_per_s = feed;
        }
        self.prepare_target(&mut target, out)?;
        let result = self.motion.line_to(&target, self.modal.feed_um_per_s);
        self.commit_move(&target, result)
    }

    #[cfg(feature = "printer")]
    /// `G2`/`G3`: an arc needs a centre (`I`/`J`, relative to the start) or
    /// a radius (`R`; negative for the arc over half a turn).
    #[inline(never)]
    pub(super) fn arc_move<W: uWrite + ?Sized>(
        &mut self,
        command: &Command,
        out: &mut W,
    ) -> Result<(), CommandError> {
        if self.modal.machine_frame {
            return Err(CommandError::MachineFrameArc);
        }
        let clockwise = match command.code {
            Code::G(2) => true,
            Code::G(3) => false,
            _ => self.modal.motion_mode == MotionMode::ClockwiseArc,
        };
        let feed = self.modal.read_feed(command)?;
        let mut target = self.modal.target(command)?;
        // The centre's offset along the plane's two axes (Grbl: I J, K I, J K).
        let plane = self.modal.plane;
        let (first, second) = match plane {
            Plane::Xy => (b'I', b'J'),
            Plane::Zx => (b'K', b'I'),
            Plane::Yz => (b'J', b'K'),
        };
        // The three words in µm (0 when absent) and which were given (bit
        // 0, 1, 2): a loop and a mask, not three `Result<Option<i32>>`.
        let (mut values, mut given, mut bit) = ([0i32; 3], 0u8, 1u8);
        for (value, letter) in values.iter_mut().zip([first, second, b'R']) {
            if let Some(word) = command.value(letter)? {
                *value = self.modal.length_um(letter, word)?;
                given |= bit;
            }
            bit <<= 1;
        }
        let centre = match given {
            0b100 => ArcCentre::Radius(values[2]),
            0 => return Err(CommandError::Missing(b'R')),
            _ => ArcCentre::Offset([values[0], values[1]]),
        };
        self.modal.motion_mode = if clockwise {
            MotionMode::ClockwiseArc
        } else {
            MotionMode::CounterClockwiseArc
        };
        if let Some(feed) = feed {
            self.modal.feed_um_per_s = feed;
        }
        self.prepare_target(&mut target, out)?;
        let result = self
            .motion
            .arc_to(plane, &target, centre, clockwise, self.modal.feed_um_per_s);
        self.commit_move(&target, result)
    }

    #[cfg(feature = "printer")]
    /// Checks shared by lines and arcs, and the Marlin adjustments of the
    /// target (soft-limit clamp, cold extrusion), in place (by value the
    /// AVR copied the target in and out).
    fn prepare_target<W: uWrite + ?Sized>(
        &mut self,
        target: &mut [i32; AXES],
        out: &mut W,
    ) -> Result<(), CommandError> {
        // A safety trip not re-armed says so first: the operator has to
        // act on the machine before G28 can help.
        self.safety_check()?;
        if self.position_lost {
            return Err(CommandError::PositionLost);
        }
        if let Some(mode) = self.modal.unsupported {
            return Err(CommandError::UnsupportedMode(mode));
        }
        // By reference: copies of the configuration's parts cost flash.
        if let (MachineKinematics::Cartesian(_), Some(limits), false) = (
            &self.motion.config.kinematics,
            &self.motion.config.soft_limits,
            self.motion.config.must_home,
        ) {
            let homed = self.motion.homed();
            // Zipped, with a running axis bit: no bounds checks or variable
            // shifts. `max(min).min(max)` is `clamp` for the configured
            // min ≤ max, without clamp's panic path.
            let mut bit = 1;
            for ((value, min), max) in target.iter_mut().zip(&limits.min).zip(&limits.max) {
                if homed & bit != 0 {
                    let (min, max) = (to_i32(min * 1000.0), to_i32(max * 1000.0));
                    *value = (*value).max(min).min(max);
                }
                bit <<= 1;
            }
        }
        if target[E] > self.modal.position[E] && !self.extrusion_allowed() {
            let _ = out.write_str("echo: cold extrusion prevented\n");
            // Marlin drops the extrusion and keeps the new E as the
            // position, so the next absolute E does not catch it up.
            self.motion.set_extruder_position_um(target[E]);
        }
        Ok(())
    }

    #[cfg(feature = "printer")]
    // Out of line: shared by lines and arcs (12 bytes).
    #[inline(never)]
    fn commit_move(
        &mut self,
        target: &[i32; AXES],
        result: Result<(), MotionError>,
    ) -> Result<(), CommandError> {
        match result {
            Ok(()) => {
                self.modal.commit(target);
                self.steppers_enabled = true;
                Ok(())
            }
            Err(error) => Err(CommandError::Motion(error)),
        }
    }

    /// `G4 P<ms>` or `G4 S<s>`: first the queued moves finish (Marlin's
    /// `planner.synchronize()`), then the pause.
    pub(super) fn dwell(&mut self, command: &Command) -> Outcome {
        let ms = match (command.value(b'P'), command.value(b'S')) {
            (Ok(Some(p)), _) => p.to_int(),
            (_, Ok(Some(s))) => s.to_scaled(3),
            (Ok(None), Ok(None)) => Some(0),
            (Err(e), _) | (_, Err(e)) => return Outcome::Failed(e.into()),
        };
        match ms {
            Some(ms) if ms >= 0 => self.start(Running::DwellAfterMotion { ms: ms as u32 }),
            _ => Outcome::Failed(CommandError::OutOfRange(if command.has(b'P') {
                b'P'
            } else {
                b'S'
            })),
        }
    }

    #[cfg(feature = "printer")]
    /// `G28 [X] [Y] [Z]`: home the named axes (all when none is named),
    /// after the queued moves.
    pub(super) fn home(&mut self, command: &Command) -> Outcome {
        let mut motors = 0u8;
        // A running axis bit: a variable shift is a loop on the AVR.
        let mut bit = 1;
        for &letter in b"XYZ" {
            if command.has(letter) {
                motors |= bit;
            }
            bit <<= 1;
        }
        match self.motion.home(motors) {
            Ok(()) => {
                self.steppers_enabled = true;
                self.start(Running::Homing)
            }
            Err(error) => Outcome::Failed(CommandError::Motion(error)),
        }
    }

    /// Homing ended (successfully: a failure halted the machine). The homed
    /// axes' logical positions restart from the home position: their `G92`
    /// offsets are cleared, as in Marlin.
    fn homing_finished<W: uWrite + ?Sized>(&mut self, _out: &mut W) -> Result<(), W::Error> {
        let homed = self.motion.homed();
        #[cfg(feature = "encoders")]
        self.encoders_homed(homed);
        let position = self.motion.position_um();
        // A running axis bit: a variable shift is a loop on the AVR.
        let mut bit = 1;
        for axis in 0..3 {
            if homed & bit != 0 {
                self.modal.offset[axis] = 0;
            }
            bit <<= 1;
        }
        self.modal.position[..3].copy_from_slice(&position[..3]);
        self.modal.residue_nm[..3].fill(0);
        if homed & 0b111 == 0b111 {
            self.position_lost = false;
        }
        Ok(())
    }

    /// `M665 L<rod> R<radius> H<height>` (delta): new geometry, once the
    /// moves are done; positions are lost, so `G28` must follow (Marlin
    /// re-homes the same way). Bare `M665` reports the geometry.
    #[cfg(feature = "delta")]
    pub(super) fn delta_geometry<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W) -> Result<(), CommandError> {
        self.delta_setting(command, out, false)
    }

    /// `M666 X Y Z` (delta): endstop trims, mm (each tower's switch this
    /// far above the nominal one). Bare `M666` reports them.
    #[cfg(feature = "delta")]
    pub(super) fn delta_trim<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W) -> Result<(), CommandError> {
        self.delta_setting(command, out, true)
    }

    /// `M665` (`trim` false) and `M666` in one function: their reading,
    /// report and commit are the same but for the letters and checks (out
    /// of line: inlined into the dispatcher they cost 2 KB). The delta is
    /// changed in place, not through copies of it.
    #[cfg(feature = "delta")]
    #[inline(never)]
    fn delta_setting<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W, trim: bool) -> Result<(), CommandError> {
        let MachineKinematics::Delta(delta) = &self.motion.config.kinematics else {
            return Err(CommandError::NotThisMachine);
        };
        // One branch, the values copied in it (chosen value by value, the
        // copies cost 200 bytes).
        let mut values = delta.endstop_trim;
        let (code, letters) = if trim {
            (666, b"XYZ")
        } else {
            values = [delta.rod_length(), delta.radius(), delta.homed_height];
            (665, b"LRH")
        };
        let mut any = false;
        for (value, &letter) in values.iter_mut().zip(letters) {
            if let Some(given) = command.value(letter)? {
                match given.to_scaled(3) {
                    // M665: positive; M666: within ±20 mm (wrapping_abs:
                    // i32::MIN as the release build's abs()).
                    Some(um) if (if trim { um.wrapping_abs() <= 20_000 } else { um > 0 }) => {
                        *value = crate::motion::milli(um)
                    }
                    _ => return Err(CommandError::OutOfRange(letter)),
                }
                any = true;
            }
        }
        if !any {
            // `echo:  M665 L361.00 R227.00 H300.00` and the like.
            let _ = ufmt::uwrite!(out, "echo:  M{}", crate::reply::Whole(code as u16));
            for (&letter, &value) in letters.iter().zip(&values) {
                let _ = ufmt::uwrite!(
                    out,
                    " {}{}",
                    char::from(letter),
                    crate::reply::Fixed::hundredths(crate::motion::math::round_to_i32(value * 100.0))
                );
            }
            let _ = out.write_str("\n");
            return Ok(());
        }
        if !trim && values[0] <= values[1] {
            // The rod must be longer than the radius.
            return Err(CommandError::OutOfRange(b'L'));
        }
        self.change_delta(trim, &values)
    }

    /// New kinematics take effect for the moves that follow; where the
    /// carriages are in the new geometry is unknown until `G28`. The
    /// delta is changed in place (the caller checked that it is one), once
    /// the moves are done: the trims (`trim`), or rod, radius and height.
    #[cfg(feature = "delta")]
    fn change_delta(&mut self, trim: bool, values: &[f32; 3]) -> Result<(), CommandError> {
        if !self.motion.is_idle() {
            return Err(CommandError::Motion(MotionError::Busy));
        }
        self.position_lost = true;
        let delta = self.motion.delta_mut().ok_or(CommandError::NotThisMachine)?;
        if trim {
            delta.endstop_trim = *values;
        } else {
            delta.set_geometry(values[0], values[1]);
            delta.homed_height = values[2];
        }
        self.motion.kinematics_changed();
        // Kept with the settings: M500 saves them, M502 restores the file's.
        let um = values.map(|mm| crate::motion::math::round_to_i32(mm * 1000.0));
        if trim {
            self.settings.delta_trim_um = um;
        } else {
            self.settings.delta_geometry_um = um;
        }
        Ok(())
    }
}
