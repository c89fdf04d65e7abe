//! Motion: from a parsed `G0`/`G1`/`G2`/`G3`/`G28` to exact, timed steps.
//!
//! ```text
//!  executor ──line_to / arc_to / home──▶ Motion (main loop)
//!                                          │ cut into pieces (arc chords,
//!                                          │ kinematic segments), inverse
//!                                          │ kinematics, steps
//!                                          ▼
//!                                       Planner (16-block ring, look-ahead)
//!                                          │
//!                                          ▼
//!                                       Prep (trapezoid → timed segments)
//!                                          │ StepQueues: SPSC, lock-free
//!                                          ▼
//!                       step-timer ISR: StepGenerator::on_timer()
//! ```
//!
//! Module by module: [`kinematics`] (Cartesian, delta, RR arm), [`arc`]
//! (chord cutter), [`planner`] (look-ahead, junction deviation), [`prep`]
//! (segments), [`stepper`] (the interrupt), [`homing`] (`G28` sequences),
//! [`math`] (float helpers for the main loop).
//!
//! # Integration
//!
//! **Set-up (board, once).** Keep a `static mut QUEUES: StepQueues` and a
//! [`MotionConfig`] (the board's machine: [`MotionConfig::prusa_i3`],
//! [`MotionConfig::spec_delta`], [`MotionConfig::spec_arm`], then
//! [`MotionConfig::apply_settings`] with the loaded `Settings`). Split:
//! `let (feeder, generator) = QUEUES.split(config.stepper());` Give the
//! feeder to `Motion::new(config, feeder)` (main loop) and put the
//! generator where the step interrupt reaches it (an
//! `avr_device::interrupt::Mutex<RefCell<Option<StepGenerator<'static>>>>`).
//! Start Timer1 free-running with compare interrupts at 2 MHz
//! ([`stepper::TIMER_HZ`]).
//!
//! **Step-timer interrupt (TIMER1_COMPA), every compare:**
//! ```text
//! if generator.endstop_mask() != 0 {            // homing or hard limits
//!     generator.on_endstops(endstop_bits());    // bit i: motor i min, bit 4+i: max;
//! }                                             // 1 = triggered (polarity applied)
//! let (steps, dirs) = generator.pins_now();     // the event computed last time
//! write DIR pins from dirs (bit 0 X, 1 Y, 2 Z, 3 E)   — first
//! raise STEP pins of steps                      // edge time independent of the work below
//! let a = generator.on_timer();                 // fires it, computes the next
//! OCR1A = OCR1A + a.next_interval_ticks         // from the last compare, not from now
//! lower the STEP pins after ≥ the driver's pulse width
//! ```
//! (`boards/mega2560-ramps/src/stepping.rs` is this, for Timer1.)
//! The generator never presents a direction change together with a step;
//! it gives the new directions `dir_setup_ticks` ahead (config).
//! [`pairs_to_endstop_bits`] converts the executor's X_MIN, X_MAX, Y_MIN…
//! layout; [`homing::endstops_triggered`] applies each switch's polarity
//! (NO/NC, active level). Reading pins only when `endstop_mask()` is
//! non-zero keeps them out of the per-step cost outside homing unless the
//! machine has hard limits (the arm).
//!
//! **Main loop, every pass:**
//! ```text
//! let status = interrupt::free(|cs| generator.status());   // a copy, no maths
//! match motion.poll(&status, now_ms) {
//!     StepperRequest::None => {}
//!     StepperRequest::ClearFault => interrupt::free(|cs| generator.clear_fault()),
//!     StepperRequest::Halt => interrupt::free(|cs| generator.halt(StepFault::Stopped)),
//!     StepperRequest::Configure(c) => interrupt::free(|cs| generator.set_config(c)),
//! }
//! if let Some(error) = motion.take_error() { reply "Error:…" (and after a
//!     fault: the position is lost, re-home) }
//! ```
//! `poll` cuts pending lines/arcs into the planner and keeps the segment
//! queue full (≤ 15 segments of ≤ 5 ms), so the main loop must come round at
//! least every ≈ 50 ms while moving. Anything that blocks longer (EEPROM
//! writes of many bytes) should call `poll` in between.
//!
//! **Executor.**
//! - `G0`/`G1`: when [`Motion::ready`] is false, keep the command queued
//!   and try again next pass (Marlin blocks the same way). Else
//!   `motion.line_to(&target_um, feed_um_per_s)` with the *machine*
//!   coordinates of the target (X, Y, Z, E in µm, `G92` offsets removed) and
//!   the modal feed in µm/s. `M220`/`M221` are applied inside from the
//!   settings given to [`Motion::apply_settings`], as are `M92`, `M201`,
//!   `M203`, `M204`, `M205 J`; they apply to moves accepted after the
//!   change (blocks already planned keep their speeds). Errors (`Unreachable`, `OutsideSoftLimits`,
//!   `NotHomed`) mean nothing moved: answer `Error:` and keep the position.
//! - `G2`/`G3`: `motion.arc_to(plane, &target_um, ArcCentre::Offset([i, j]) or
//!   ArcCentre::Radius(r), clockwise, feed_um_per_s)`, all µm.
//! - `G28 [X][Y][Z]`: `motion.home(mask)` (bit i: motor i; 0 = all), then
//!   wait (busy keep-alive) until `!motion.is_homing()`; `take_error()` tells
//!   `HomingFailed`. Then set the modal position from
//!   [`Motion::position_um`].
//! - `M400`, `G4` and anything that needs motion finished: wait until
//!   [`Motion::is_idle`].
//! - `M114`: [`Motion::position_um`] (where queued motion ends) and
//!   [`Motion::motor_steps`] for `Count`.
//! - `M665`/`M666`: change `config.kinematics` (`Delta::set_geometry`,
//!   `endstop_trim`) while idle, then re-home.
//!
//! **Flash.** Functions marked `#[inline(never)]` here and in
//! `machine/` are cold (once per line or per block): inlined into the
//! board's main loop they were duplicated, 8 KB more on the AVR.

// Comparisons are written `!(x > 0.0)` on purpose: they reject NaN too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Per-motor arrays read clearest indexed by motor number, as in the SPEC.
#![allow(clippy::needless_range_loop)]

pub mod arc;
pub mod homing;
pub mod kinematics;
pub mod math;
pub mod planner;
pub mod prep;
pub mod stepper;

#[cfg(test)]
mod tests;

use arc::{ArcCutter, ArcError, Centre};
pub use arc::Plane;
use homing::{AxisHoming, Homing, HomingConfig, HomingStep};
#[cfg(feature = "arm")]
use kinematics::Arm;
#[cfg(feature = "delta")]
use kinematics::Delta;
use kinematics::{motor_steps, Cartesian, Kinematics, KinematicsError, MachineKinematics, LINEAR_AXES};
use math::{round_to_i32, sqrt};
use planner::{MotorLimits, Planner, PlannerMove, MAX_BLOCK_STEPS};
use prep::Prep;
pub use stepper::{StepFault, StepFeeder, StepGenerator, StepQueues, StepperConfig, StepperStatus, TimerAction, MOTORS};

use crate::settings::Settings;
use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

/// Index of the extruder motor.
pub const E: usize = 3;

/// Soft limits: the box targets must stay in (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftLimits {
    pub min: [f32; LINEAR_AXES],
    pub max: [f32; LINEAR_AXES],
}

/// Where the machine is once homed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HomePosition {
    /// This Cartesian point; each homed motor is set to its share of the
    /// inverse kinematics (Cartesian axes, arm joints, the arm's X).
    Cartesian([f32; LINEAR_AXES]),
    /// Delta: each carriage at its top endstop (`homed_height` + trim).
    DeltaTop,
}

/// A machine's motion configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionConfig {
    pub kinematics: MachineKinematics,
    /// `M92`: steps per mm of X, Y, Z (carriages for a delta; X only for
    /// the arm, whose joints use `Arm::joint_steps_per_degree`) and E.
    pub steps_per_mm: [f32; MOTORS],
    /// `M203`: highest speed of each motor in motor units/s (mm/s; °/s for
    /// arm joints). On a delta this limits each carriage.
    pub max_feed: [f32; MOTORS],
    /// `M201`: highest acceleration of each motor, units/s².
    pub max_accel: [f32; MOTORS],
    /// `M204 P`, `R`, `T`: printing, retract (E only) and travel, mm/s².
    pub print_accel: f32,
    pub retract_accel: f32,
    pub travel_accel: f32,
    /// `M205 J`, mm.
    pub junction_deviation: f32,
    /// `M220` / 100 and `M221` / 100.
    pub feed_factor: f32,
    pub flow_factor: f32,
    /// Chord tolerance of arcs, mm.
    pub arc_tolerance: f32,
    /// The drivers' (or the interrupt's) highest step rate, steps/s.
    pub max_step_rate: f32,
    pub soft_limits: Option<SoftLimits>,
    pub homing: HomingConfig,
    pub home: HomePosition,
    /// Refuse moves until every positioning motor is homed (the arm).
    pub must_home: bool,
    /// Direction inversion for the wiring, direction set-up, hard limits.
    pub stepper: StepperConfig,
}

impl MotionConfig {
    /// SPEC §1: the Prusa i3 (100 steps/mm X/Y, 400 Z, 93 E), homing to the
    /// min endstops, X then Y then Z. The Y motor's direction is inverted:
    /// the belt moves the bed, so the nozzle's +Y is the bed's −Y. The
    /// tunable values are those of [`Settings::prusa_i3`] (a test checks
    /// it); `const`, so a board can keep it in flash.
    pub const fn prusa_i3() -> Self {
        Self {
            kinematics: MachineKinematics::Cartesian(Cartesian),
            steps_per_mm: [100.0, 100.0, 400.0, 93.0],
            max_feed: [300.0, 300.0, 5.0, 25.0],
            max_accel: [3000.0, 3000.0, 100.0, 10_000.0],
            print_accel: 1500.0,
            retract_accel: 1500.0,
            travel_accel: 1500.0,
            junction_deviation: 0.013,
            feed_factor: 1.0,
            flow_factor: 1.0,
            arc_tolerance: 0.002,
            max_step_rate: 50_000.0,
            soft_limits: Some(SoftLimits { min: [0.0, 0.0, 0.0], max: [200.0, 200.0, 180.0] }),
            homing: HomingConfig {
                sequence: [0b001, 0b010, 0b100],
                axes: [
                    AxisHoming::bump(false, 100.0, 50.0, 200.0, 5.0),
                    AxisHoming::bump(false, 100.0, 50.0, 200.0, 5.0),
                    AxisHoming::bump(false, 400.0, 4.0, 180.0, 2.0),
                ],
                acceleration: 100_000.0,
            },
            home: HomePosition::Cartesian([0.0, 0.0, 0.0]),
            must_home: false,
            stepper: StepperConfig { dir_invert: 0b0010, limit_endstops: 0, ..StepperConfig::DEFAULT },
        }
    }

    /// SPEC §2: the delta (80 steps/mm carriages, E 102), homing all
    /// towers up at once; each carriage at most 150 mm/s.
    #[cfg(feature = "delta")]
    pub fn spec_delta(repetier_layout: bool) -> Self {
        let mut config = Self::spec_delta_unplaced(repetier_layout);
        config.place_towers();
        config
    }

    /// [`Self::spec_delta`] before [`Self::place_towers`]: `const`, so a
    /// board can keep it in flash (built field by field in code it cost
    /// 1.1 KB on the AVR).
    #[cfg(feature = "delta")]
    pub const fn spec_delta_unplaced(repetier_layout: bool) -> Self {
        let mut delta = Delta::spec_printer_unplaced(repetier_layout);
        delta.homed_height = 300.0;
        let tower = AxisHoming::bump(true, 80.0, 50.0, 400.0, 5.0);
        Self {
            kinematics: MachineKinematics::Delta(delta),
            steps_per_mm: [80.0, 80.0, 80.0, 102.0],
            max_feed: [150.0, 150.0, 150.0, 25.0],
            max_accel: [3000.0, 3000.0, 3000.0, 10_000.0],
            soft_limits: None,
            homing: HomingConfig { sequence: [0b111, 0, 0], axes: [tower; 3], acceleration: 100_000.0 },
            home: HomePosition::DeltaTop,
            stepper: StepperConfig::DEFAULT,
            max_step_rate: 50_000.0,
            ..Self::prusa_i3()
        }
    }

    /// A delta's tower pivots from its radius and tower angles (after
    /// [`Self::spec_delta_unplaced`]); nothing for other machines.
    #[cfg(feature = "delta")]
    pub fn place_towers(&mut self) {
        if let MachineKinematics::Delta(delta) = &mut self.kinematics {
            delta.place_towers();
        }
    }

    /// SPEC §3: the RR arm with `ppr` driver pulses per turn (200 bench,
    /// 400 machine), X on a 4 mm lead screw, travel X ±100 Y ±110 Z ±40,
    /// homing Z (negative) then Y then X (positive) at 200 steps/s with a
    /// 500 ms pause and a release back-off at 20 steps/s; home (x, y, z) =
    /// (−100, −107, 68), which the soft limits accept although Z 68 is
    /// outside ±40. NC limit switches are hard limits.
    #[cfg(feature = "arm")]
    pub fn spec_arm(ppr: u16) -> Self {
        let arm = Arm::spec_arm(ppr);
        let joint = |towards_max| AxisHoming {
            towards_max,
            fast_rate: 200.0,
            slow_rate: 20.0,
            backoff_steps: (10.0 * arm.joint_steps_per_degree) as u32,
            max_travel_steps: (200.0 * arm.joint_steps_per_degree) as u32,
            release: true,
            pause_ms: 500,
        };
        let screw_per_mm = ppr as f32 / 4.0;
        let screw = AxisHoming {
            backoff_steps: (10.0 * screw_per_mm) as u32,
            max_travel_steps: (250.0 * screw_per_mm) as u32,
            ..joint(true)
        };
        Self {
            kinematics: MachineKinematics::Arm(arm),
            steps_per_mm: [screw_per_mm, 1.0, 1.0, 100.0],
            // Joints in °/s and °/s² (20 kHz TB6600 at 55.6 pulses/°: 360 °/s).
            max_feed: [50.0, 60.0, 60.0, 25.0],
            max_accel: [500.0, 300.0, 300.0, 1000.0],
            print_accel: 500.0,
            retract_accel: 500.0,
            travel_accel: 500.0,
            max_step_rate: if ppr > 200 { 100_000.0 } else { 20_000.0 },
            soft_limits: Some(SoftLimits { min: [-100.0, -110.0, -40.0], max: [100.0, 110.0, 40.0] }),
            homing: HomingConfig {
                sequence: [0b100, 0b010, 0b001],
                axes: [screw, joint(true), joint(false)],
                acceleration: 2000.0,
            },
            home: HomePosition::Cartesian([-100.0, -107.0, 68.0]),
            must_home: true,
            stepper: StepperConfig { limit_endstops: 0b0111_0111, ..StepperConfig::default() },
            ..Self::prusa_i3()
        }
    }

    /// Take the tunable values from the settings (`M92`, `M201`, `M203`,
    /// `M204`, `M205 J`, `M220`, `M221`), milli-units to floats.
    pub fn apply_settings(&mut self, settings: &Settings) {
        #[cfg(feature = "arm")]
        let is_arm = matches!(self.kinematics, MachineKinematics::Arm(_));
        #[cfg(not(feature = "arm"))]
        let is_arm = false;
        for motor in 0..MOTORS {
            // The arm's joints have no steps/mm: pulses per degree come from
            // the gearbox and the driver.
            if !(is_arm && (motor == 1 || motor == 2)) {
                self.steps_per_mm[motor] = milli(settings.steps_per_mm_milli[motor]);
            }
            self.max_feed[motor] = milli(settings.max_feed_um_per_s[motor]);
            self.max_accel[motor] = milli(settings.max_accel_um_per_s2[motor]);
        }
        self.print_accel = milli(settings.print_accel_um_per_s2);
        self.retract_accel = milli(settings.retract_accel_um_per_s2);
        self.travel_accel = milli(settings.travel_accel_um_per_s2);
        self.junction_deviation = milli(settings.junction_deviation_um);
        self.feed_factor = centi(settings.feed_percent);
        self.flow_factor = centi(settings.flow_percent);
        // A delta's saved M665/M666 (none saved yet: zeros, keep the file's).
        #[cfg(feature = "delta")]
        if let MachineKinematics::Delta(delta) = &mut self.kinematics {
            let [rod, radius, height] = settings.delta_geometry_um;
            if rod > radius && radius > 0 && height > 0 {
                delta.set_geometry(milli(rod), milli(radius));
                delta.homed_height = milli(height);
            }
            delta.endstop_trim = settings.delta_trim_um.map(milli);
        }
    }

    /// Steps per motor unit of every motor. Out of line: inlined into its
    /// half-dozen callers it cost 140 bytes more on the AVR.
    #[inline(never)]
    pub fn steps_per_unit(&self) -> [f32; MOTORS] {
        let linear = self.kinematics.motor_steps_per_unit([self.steps_per_mm[0], self.steps_per_mm[1], self.steps_per_mm[2]]);
        [linear[0], linear[1], linear[2], self.steps_per_mm[E]]
    }

    /// The planner's limits in steps, written into `limits` (returned,
    /// the 32 bytes went through a temporary and a copy on the AVR).
    pub fn motor_limits(&self, limits: &mut MotorLimits) {
        let spu = self.steps_per_unit();
        for motor in 0..MOTORS {
            limits.max_rate[motor] = math::min(self.max_feed[motor] * spu[motor], self.max_step_rate);
            limits.max_accel[motor] = self.max_accel[motor] * spu[motor];
        }
    }

    /// What the step interrupt needs ([`StepQueues::split`]).
    pub fn stepper(&self) -> StepperConfig {
        self.stepper
    }
}

/// Why a motion command did nothing (or stopped).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MotionError {
    /// A previous command is still being cut into the planner: retry.
    Busy,
    Unreachable(KinematicsError),
    OutsideSoftLimits,
    /// The machine must be homed first (`G28`).
    NotHomed,
    Arc(ArcError),
    /// These motors' switches did not trigger (or release) in time.
    HomingFailed(u8),
    /// The step interrupt stopped everything; the position is lost.
    Fault(StepFault),
}

/// The centre of an arc: `I`/`J` offsets from the start, or `R`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArcCentre {
    /// µm.
    Offset([i32; 2]),
    /// µm; negative: the arc over half a turn.
    Radius(i32),
}

/// What the board must do to the generator after [`Motion::poll`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepperRequest {
    None,
    /// Call `generator.clear_fault()`: the main loop has flushed.
    ClearFault,
    /// Call `generator.halt(StepFault::Stopped)` (`M410`).
    Halt,
    /// Call `generator.set_config(config)` (`M120`/`M121` changed which
    /// endstops stop a move).
    Configure(StepperConfig),
}

/// A straight line cut into pieces short enough for the kinematics (and
/// for 16-bit step counts); piece ends are computed as they are needed.
#[derive(Clone, Copy, Debug, PartialEq)]
struct LineCut {
    start: [f32; MOTORS],
    delta: [f32; MOTORS],
    target: [f32; MOTORS],
    pieces: u32,
    done: u32,
}

impl LineCut {
    /// A line with no pieces left (an arc's, before its first chord).
    const DONE: Self = Self { start: [0.0; MOTORS], delta: [0.0; MOTORS], target: [0.0; MOTORS], pieces: 0, done: 0 };

    /// Cut the line from `start` to `target`, in place: as a temporary
    /// (56 bytes) it pushed its callers' AVR frames past 63 bytes, where
    /// every stack access costs 12 bytes of code. Points by reference: by
    /// value the AVR copied each first.
    fn init(&mut self, start: &[f32; MOTORS], target: &[f32; MOTORS], config: &MotionConfig) {
        self.start = *start;
        self.target = *target;
        self.done = 0;
        let delta = &mut self.delta;
        for axis in 0..MOTORS {
            delta[axis] = target[axis] - start[axis];
        }
        // Only kinematics that bend straight lines (delta, arm) are cut by
        // length; a Cartesian line needs no square root here (this runs
        // for every G1 of a slicer stream).
        let mut pieces = match config.kinematics.segment_mm() {
            // (`length3`: the same sum, out of line.)
            Some(segment) if segment > 0.0 => match delta.first_chunk::<LINEAR_AXES>() {
                Some(xyz) => kinematics::length3(xyz) / segment,
                None => 0.0,
            },
            _ => 0.0,
        };
        // Keep each motor within a block's 16-bit step count (with room for
        // the delta's up-to-3× carriage travel).
        let spu = config.steps_per_unit();
        const PER_HEADROOM: f32 = 4.0 / MAX_BLOCK_STEPS as f32;
        for axis in 0..LINEAR_AXES {
            pieces = math::max(pieces, math::abs(delta[axis]) * math::max(config.steps_per_mm[axis], spu[axis]) * PER_HEADROOM);
        }
        pieces = math::max(pieces, math::abs(delta[E]) * spu[E] * config.flow_factor * PER_HEADROOM);
        self.pieces = math::to_u32(math::min(pieces, 1.0e7)).saturating_add(1);
    }

    /// The next piece's end into `point`; `false` once the line is done.
    /// (Not an `Iterator`: an `Option<[f32; 4]>` went back through a copy
    /// on the AVR.)
    fn next_into(&mut self, point: &mut [f32; MOTORS]) -> bool {
        if self.done >= self.pieces {
            return false;
        }
        self.done += 1;
        if self.done == self.pieces {
            *point = self.target;
            return true;
        }
        let fraction = self.done as f32 / self.pieces as f32;
        for axis in 0..MOTORS {
            point[axis] = self.start[axis] + self.delta[axis] * fraction;
        }
        true
    }
}

/// Work accepted from the executor and not yet all in the planner.
///
/// `line_to` and `arc_to` only check the move and store it here; `poll`
/// cuts it into the planner. The executor acknowledges the line at once
/// and takes no further command while something is pending
/// ([`Motion::ready`]), so commands still take effect in order and nothing
/// acknowledged is lost, but the planning (kinematics, look-ahead) runs
/// while the host is sending the next line instead of before the `ok`:
/// with ok-per-line hosts this is what lets short segments stream at speed.
#[derive(Clone, Debug, PartialEq)]
enum Pending {
    Nothing,
    Line { cut: LineCut, feed: f32 },
    /// `cut`: the chord being cut (`LineCut::DONE` before the first).
    Arc { arc: ArcCutter, cut: LineCut, feed: f32 },
}

/// The main loop's motion state.
pub struct Motion<'q> {
    pub config: MotionConfig,
    /// `config.motor_limits(..)`, kept up to date by `configure` (computing
    /// it costs a dozen float divisions, too many for every planned piece).
    limits: MotorLimits,
    planner: Planner,
    prep: Prep,
    feeder: StepFeeder<'q>,
    /// Where the queued motion ends: Cartesian X, Y, Z and E, mm.
    position: [f32; MOTORS],
    /// The same in motor steps.
    motor_steps: [i32; MOTORS],
    /// E steps owed (rounding of flow-scaled extrusion), steps.
    e_remainder: f32,
    pending: Pending,
    homing: Homing,
    homing_requested: Option<u8>,
    homing_move: Option<(u16, [i32; MOTORS])>,
    homed: u8,
    error: Option<MotionError>,
    /// The configuration's own hard limits (`M121` goes back to them).
    machine_limits: u8,
    stop_requested: bool,
    /// The stepper configuration changed; the interrupt has the old one.
    stepper_changed: bool,
    fault_seen: bool,
    /// The interrupt still had steps at the last `poll` (only this of its
    /// status is kept: copying the whole status every main-loop pass was a
    /// `memcpy` call a pass).
    stepper_busy: bool,
}

impl<'q> Motion<'q> {
    pub fn new(config: MotionConfig, feeder: StepFeeder<'q>) -> Self {
        let mut slot = MaybeUninit::uninit();
        Self::init_in(&mut slot, config, feeder);
        // SAFETY: `init_in` initialised the slot.
        unsafe { slot.assume_init() }
    }

    /// The motion state built directly in `slot` (inside the board's
    /// `static` machine): the planner ring is never a temporary on the
    /// stack. Inlined into the board's `boot`, whose frame (and so the
    /// temporaries of construction) is gone before the main loop starts.
    pub fn init_in<'s>(slot: &'s mut MaybeUninit<Self>, config: MotionConfig, feeder: StepFeeder<'q>) -> &'s mut Self {
        let p = slot.as_mut_ptr();
        // SAFETY: each write is to a field of the valid slot `p`, every
        // field exactly once (`every_field_is_initialised` lists them), so
        // the slot is initialised afterwards.
        let motion = unsafe {
            addr_of_mut!((*p).config).write(config);
            // `configure` below computes the real limits. All-zero bytes
            // are 0.0 (and 0) for these plain float and integer arrays:
            // a memset, not a zeroed temporary on the stack and a copy.
            core::ptr::write_bytes(addr_of_mut!((*p).limits), 0, 1);
            Planner::init_in(&mut *addr_of_mut!((*p).planner).cast::<MaybeUninit<Planner>>());
            addr_of_mut!((*p).prep).write(Prep::new());
            addr_of_mut!((*p).feeder).write(feeder);
            core::ptr::write_bytes(addr_of_mut!((*p).position), 0, 1);
            core::ptr::write_bytes(addr_of_mut!((*p).motor_steps), 0, 1);
            addr_of_mut!((*p).e_remainder).write(0.0);
            addr_of_mut!((*p).pending).write(Pending::Nothing);
            Homing::init_in(&mut *addr_of_mut!((*p).homing).cast::<MaybeUninit<Homing>>());
            addr_of_mut!((*p).homing_requested).write(None);
            addr_of_mut!((*p).homing_move).write(None);
            addr_of_mut!((*p).homed).write(0);
            addr_of_mut!((*p).error).write(None);
            addr_of_mut!((*p).machine_limits).write(config.stepper.limit_endstops);
            addr_of_mut!((*p).stop_requested).write(false);
            addr_of_mut!((*p).stepper_changed).write(false);
            addr_of_mut!((*p).fault_seen).write(false);
            addr_of_mut!((*p).stepper_busy).write(false);
            slot.assume_init_mut()
        };
        motion.configure();
        // Until homed, the machine believes it is at the origin (reachable
        // on all three machine families).
        // (`position` is the origin already.)
        motion.derive_motor_steps();
        motion
    }

    /// Never called: the compiler checks that this pattern names every
    /// field, so a field added to `Motion` without a write in `init_in`
    /// does not build.
    #[allow(dead_code)]
    fn every_field_is_initialised(&self) {
        let Self {
            config: _,
            limits: _,
            planner: _,
            prep: _,
            feeder: _,
            position: _,
            motor_steps: _,
            e_remainder: _,
            pending: _,
            homing: _,
            homing_requested: _,
            homing_move: _,
            homed: _,
            error: _,
            machine_limits: _,
            stop_requested: _,
            stepper_changed: _,
            fault_seen: _,
            stepper_busy: _,
        } = self;
    }

    fn configure(&mut self) {
        self.config.motor_limits(&mut self.limits);
        self.planner.junction_deviation = self.config.junction_deviation;
        let min_ticks = math::max(stepper::TIMER_HZ as f32 / self.config.max_step_rate, 4.0);
        self.prep.min_interval_q8 = math::to_u32(min_ticks * 256.0);
    }

    /// New settings (`M92`, `M201`, `M203`, `M204`, `M205`, `M220`, `M221`).
    /// Motor positions are re-derived from the Cartesian position, as
    /// Marlin does after `M92`.
    pub fn apply_settings(&mut self, settings: &Settings) {
        self.config.apply_settings(settings);
        self.configure();
        self.derive_motor_steps();
    }

    /// New kinematics (`M665`, `M666`) for the moves that follow.
    #[cfg(feature = "delta")]
    pub fn set_kinematics(&mut self, kinematics: MachineKinematics) {
        self.config.kinematics = kinematics;
        self.configure();
    }

    /// The delta's geometry to change in place (`M665`, `M666`), `None`
    /// for other kinematics; [`Self::kinematics_changed`] must follow
    /// (together what [`Self::set_kinematics`] does with a copy).
    #[cfg(feature = "delta")]
    pub fn delta_mut(&mut self) -> Option<&mut Delta> {
        match &mut self.config.kinematics {
            MachineKinematics::Delta(delta) => Some(delta),
            _ => None,
        }
    }

    /// The kinematics changed in place (see [`Self::delta_mut`]): for the
    /// moves that follow.
    #[cfg(feature = "delta")]
    pub fn kinematics_changed(&mut self) {
        self.configure();
    }

    /// Declare the current position (mm) without moving (after homing, or
    /// for tests). Motor steps follow from the inverse kinematics.
    pub fn set_position_mm(&mut self, position: [f32; MOTORS]) {
        self.position = position;
        self.derive_motor_steps();
    }

    /// The motor steps of the Cartesian position already in `position`
    /// (callers that keep the position pass no copy of it).
    fn derive_motor_steps(&mut self) {
        let position = &self.position;
        let spu = self.config.steps_per_unit();
        if let Ok(motors) = self.config.kinematics.inverse([position[0], position[1], position[2]]) {
            let steps = motor_steps(&motors, &spu);
            self.motor_steps[..LINEAR_AXES].copy_from_slice(&steps);
        }
        self.motor_steps[E] = round_to_i32(self.position[E] * spu[E]);
        self.e_remainder = 0.0;
    }

    /// Declare E's position (µm) without moving it: `G92 E`-like, used
    /// when a cold extrusion is dropped from a move.
    pub fn set_extruder_position_um(&mut self, um: i32) {
        let mm = milli(um);
        self.position[E] = mm;
        // E is linear: its steps per unit are its steps/mm.
        self.motor_steps[E] = round_to_i32(mm * self.config.steps_per_mm[E]);
        self.e_remainder = 0.0;
    }

    /// Can a new motion command be accepted now? (Out of line: inlined in
    /// its half-dozen callers it cost 32 bytes.)
    #[inline(never)]
    pub fn ready(&self) -> bool {
        matches!(self.pending, Pending::Nothing) && !self.homing.is_active() && self.homing_requested.is_none()
    }

    /// Everything accepted has been stepped out.
    pub fn is_idle(&self) -> bool {
        self.ready() && self.planner.is_empty() && !self.prep.is_active() && !self.stepper_busy
    }

    pub fn is_homing(&self) -> bool {
        self.homing.is_active() || self.homing_requested.is_some()
    }

    /// Motors homed since the last fault (bit i: motor i).
    pub fn homed(&self) -> u8 {
        self.homed
    }

    /// The error to report, once.
    pub fn take_error(&mut self) -> Option<MotionError> {
        self.error.take()
    }

    /// Where the queued motion ends, µm (X, Y, Z, E).
    pub fn position_um(&self) -> [i32; MOTORS] {
        // A plain loop: `array::map` compiled to a larger generic helper.
        let mut um = [0; MOTORS];
        for axis in 0..MOTORS {
            um[axis] = round_to_i32(self.position[axis] * 1000.0);
        }
        um
    }

    /// Where the queued motion ends, in motor steps.
    pub fn motor_steps(&self) -> [i32; MOTORS] {
        self.motor_steps
    }

    /// Blocks in the planner (for reports and tests).
    pub fn planner(&self) -> &Planner {
        &self.planner
    }

    /// `M120` (on) / `M121` (off): the homing switches also stop any move
    /// that runs into them, not only homing (Marlin's endstops "enabled
    /// globally"). Off restores the machine's own hard limits (the arm's
    /// NC switches stay on).
    pub fn set_endstops_always(&mut self, on: bool) {
        // `homing::endstop_bit` of each axis, with a running motor bit: a
        // variable shift is a loop on the AVR.
        let (mut homing_switches, mut bit) = (0, 1);
        for axis in &self.config.homing.axes {
            homing_switches |= if axis.towards_max { bit << 4 } else { bit };
            bit <<= 1;
        }
        let limits = if on { self.machine_limits | homing_switches } else { self.machine_limits };
        if limits != self.config.stepper.limit_endstops {
            self.config.stepper.limit_endstops = limits;
            self.stepper_changed = true;
        }
    }

    /// The motors were released (`M18`): every axis must home again.
    pub fn forget_home(&mut self) {
        self.homed = 0;
    }

    /// `M410`: stop now; the position is lost.
    pub fn request_stop(&mut self) {
        self.stop_requested = true;
    }

    /// `G0`/`G1` to a machine position (µm) at a feed rate (µm/s).
    pub fn line_to(&mut self, target_um: &[i32; MOTORS], feed_um_per_s: i32) -> Result<(), MotionError> {
        let target = mm_from_um(target_um);
        self.check_accepting()?;
        self.check_target(target)?;
        let feed = milli(feed_um_per_s) * self.config.feed_factor;
        self.pending = Pending::Line { cut: LineCut::DONE, feed };
        if let Pending::Line { cut, .. } = &mut self.pending {
            cut.init(&self.position, &target, &self.config);
        }
        // Not planned here: the caller acknowledges the line now and the
        // next `poll` plans it, while the host sends the next line (see
        // `Pending`). Planning here put ≈ 25 000 cycles of the AVR between
        // a line's last byte and its `ok`.
        Ok(())
    }

    /// `G2` (clockwise) / `G3` to a machine position (µm) around a centre.
    #[inline(never)]
    pub fn arc_to(&mut self, plane: Plane, target_um: &[i32; MOTORS], centre: ArcCentre, clockwise: bool, feed_um_per_s: i32) -> Result<(), MotionError> {
        let target = mm_from_um(target_um);
        self.check_accepting()?;
        self.check_target(target)?;
        let tolerance = self.config.arc_tolerance;
        let centre = match centre {
            ArcCentre::Offset([i, j]) => Centre::Offset([milli(i), milli(j)]),
            ArcCentre::Radius(r) => Centre::Radius(milli(r)),
        };
        let feed = milli(feed_um_per_s) * self.config.feed_factor;
        // The cutter is built where it is kept, not as a temporary (see
        // `ArcCutter::init`).
        self.pending = Pending::Arc { arc: ArcCutter::EMPTY, cut: LineCut::DONE, feed };
        if let Pending::Arc { arc, .. } = &mut self.pending {
            if let Err(error) = arc.init(plane, &self.position, &target, &centre, clockwise, tolerance) {
                self.pending = Pending::Nothing;
                return Err(MotionError::Arc(error));
            }
        }
        Ok(())
    }

    /// `G28`: home these motors (bit i: motor i; 0: all), once the queued
    /// motion has finished. Watch [`Self::is_homing`].
    pub fn home(&mut self, motors: u8) -> Result<(), MotionError> {
        if !self.ready() {
            return Err(MotionError::Busy);
        }
        let motors = if motors & 0b111 == 0 { 0b111 } else { motors & 0b111 };
        // A delta homes its towers together or not at all.
        #[cfg(feature = "delta")]
        let motors = if matches!(self.config.kinematics, MachineKinematics::Delta(_)) { 0b111 } else { motors };
        self.homing_requested = Some(motors);
        Ok(())
    }

    fn check_accepting(&self) -> Result<(), MotionError> {
        if !self.ready() {
            return Err(MotionError::Busy);
        }
        if self.config.must_home && self.homed & 0b111 != 0b111 {
            return Err(MotionError::NotHomed);
        }
        Ok(())
    }

    fn check_target(&self, target: [f32; MOTORS]) -> Result<(), MotionError> {
        let point = [target[0], target[1], target[2]];
        // The limits and the home by reference: copies cost flash.
        if let Some(limits) = &self.config.soft_limits {
            // Limits bind once an axis knows where it is (Marlin): a machine
            // that must home refuses everything before, see check_accepting.
            let bound = if self.config.must_home { 0b111 } else { self.homed };
            // A running axis bit: a variable shift is a loop on the AVR.
            let mut bit = 1;
            let inside = (0..LINEAR_AXES).all(|axis| {
                let free = bound & bit == 0;
                bit <<= 1;
                free || (point[axis] >= limits.min[axis] - 1e-4 && point[axis] <= limits.max[axis] + 1e-4)
            });
            let at_home = match &self.config.home {
                HomePosition::Cartesian(home) => (0..LINEAR_AXES).all(|axis| math::abs(point[axis] - home[axis]) < 1e-3),
                HomePosition::DeltaTop => false,
            };
            if !inside && !at_home {
                return Err(MotionError::OutsideSoftLimits);
            }
        }
        self.config.kinematics.inverse(point).map_err(MotionError::Unreachable)?;
        Ok(())
    }

    /// Every pass of the main loop: take in the interrupt's status, cut
    /// pending work into the planner, drive homing, and refill the step
    /// queues.
    pub fn poll(&mut self, status: &StepperStatus, now_ms: u32) -> StepperRequest {
        self.stepper_busy = status.busy;
        if let Some(fault) = status.fault {
            if !self.fault_seen {
                self.fault_seen = true;
                self.flush();
                self.homed = 0;
                self.error = Some(MotionError::Fault(fault));
            }
            return StepperRequest::ClearFault;
        }
        self.fault_seen = false;
        if self.stop_requested {
            self.stop_requested = false;
            self.flush();
            self.homed = 0;
            return StepperRequest::Halt;
        }
        if self.stepper_changed {
            self.stepper_changed = false;
            return StepperRequest::Configure(self.config.stepper);
        }
        // A block the interrupt finished before it was fully prepared was
        // abandoned (a homing move stopped by its switches).
        if self.prep.is_active() && status.blocks_done == self.prep.blocks_started() {
            self.prep.reset();
            self.planner.discard_current();
        }
        self.drive_homing(status, now_ms);
        self.feed_planner();
        self.prep.fill(&mut self.planner, &mut self.feeder);
        StepperRequest::None
    }

    /// Forget everything queued (fault, stop). The interrupt drops its
    /// queues itself.
    fn flush(&mut self) {
        self.pending = Pending::Nothing;
        self.planner.clear();
        self.prep.reset();
        self.homing.abort();
        self.homing_requested = None;
        self.homing_move = None;
    }

    /// Cut pending lines and arcs into the planner while it has room.
    fn feed_planner(&mut self) {
        let mut point = [0.0; MOTORS];
        while !self.planner.is_full() {
            let feed = match &mut self.pending {
                Pending::Nothing => return,
                Pending::Line { cut, feed } => {
                    if !cut.next_into(&mut point) {
                        self.pending = Pending::Nothing;
                        return;
                    }
                    *feed
                }
                Pending::Arc { arc, cut, feed } => {
                    if !cut.next_into(&mut point) {
                        // The chord's end in `point`, which the cut's
                        // first piece then replaces.
                        if !arc.next_into(&mut point) {
                            self.pending = Pending::Nothing;
                            return;
                        }
                        cut.init(&self.position, &point, &self.config);
                        // A new cut has at least one piece: this sets `point`.
                        cut.next_into(&mut point);
                    }
                    *feed
                }
            };
            if let Err(error) = self.queue_piece(&point, feed) {
                self.error = Some(error);
                self.pending = Pending::Nothing;
                return;
            }
        }
    }

    /// One straight piece to the planner (the planner has room).
    #[inline(never)]
    fn queue_piece(&mut self, target: &[f32; MOTORS], feed: f32) -> Result<(), MotionError> {
        // Written to keep the AVR frames small (the move built in place,
        // the steps in a function of their own, the motor steps re-derived
        // from the move): beyond 63 bytes of frame every stack access costs
        // 12 bytes of code instead of 2.
        let mut motion = PlannerMove { speed: feed, ..PlannerMove::default() };
        let e_exact = self.piece_steps(target, &mut motion.steps)?;
        let e_steps = motion.steps[E];
        // The X, Y, Z deltas, scaled to the unit vector below.
        for axis in 0..LINEAR_AXES {
            motion.unit[axis] = target[axis] - self.position[axis];
        }
        let delta = &mut motion.unit;
        let xyz = sqrt(delta[0] * delta[0] + delta[1] * delta[1] + delta[2] * delta[2]);
        if xyz > 1.0e-5 {
            let per_mm = 1.0 / xyz;
            for axis in 0..LINEAR_AXES {
                delta[axis] *= per_mm;
            }
            motion.millimetres = xyz;
            motion.acceleration = if e_steps != 0 { self.config.print_accel } else { self.config.travel_accel };
        } else {
            *delta = [0.0; MOTORS];
            motion.millimetres = math::abs(target[E] - self.position[E]);
            motion.acceleration = self.config.retract_accel;
        }
        if self.planner.push(&motion, &self.limits).is_err() {
            // The caller checked for room; never drop a piece silently.
            return Err(MotionError::Busy);
        }
        // motor_steps + (linear − motor_steps): the new motor positions.
        for motor in 0..LINEAR_AXES {
            self.motor_steps[motor] += motion.steps[motor];
        }
        self.motor_steps[E] += e_steps;
        self.e_remainder = e_exact - e_steps as f32;
        self.position = *target;
        Ok(())
    }

    /// The steps of every motor from the queued position to `target`;
    /// returns the exact (unrounded) E steps, owed rounding included.
    fn piece_steps(&self, target: &[f32; MOTORS], steps: &mut [i32; MOTORS]) -> Result<f32, MotionError> {
        let spu = self.config.steps_per_unit();
        let motors = self.config.kinematics.inverse([target[0], target[1], target[2]]).map_err(MotionError::Unreachable)?;
        let linear = motor_steps(&motors, &spu);
        for motor in 0..LINEAR_AXES {
            steps[motor] = linear[motor] - self.motor_steps[motor];
        }
        let e_exact = (target[E] - self.position[E]) * spu[E] * self.config.flow_factor + self.e_remainder;
        steps[E] = round_to_i32(e_exact);
        Ok(e_exact)
    }

    /// Run the homing state machine as far as it goes without waiting.
    fn drive_homing(&mut self, status: &StepperStatus, now_ms: u32) {
        if let Some(motors) = self.homing_requested {
            if !(self.planner.is_empty() && !self.prep.is_active() && !status.busy) {
                return;
            }
            self.homing_requested = None;
            self.homed &= !motors;
            self.homing.start(motors);
        }
        if !self.homing.is_active() {
            return;
        }
        let mut stopped = 0;
        // By reference: a copy of the move's steps cost frame and flash.
        if let Some((expected_done, steps)) = &self.homing_move {
            let finished = status.blocks_done == *expected_done && !status.busy && self.planner.is_empty() && !self.prep.is_active();
            if !finished {
                return;
            }
            stopped = status.stopped;
            self.homing.set_travel(status.stopped_steps);
            // A running motor bit: a variable shift is a loop on the AVR.
            let mut bit = 1;
            for motor in 0..MOTORS {
                let sign = if steps[motor] < 0 { -1 } else { 1 };
                self.motor_steps[motor] += if stopped & bit != 0 { sign * status.stopped_steps[motor] as i32 } else { steps[motor] };
                bit <<= 1;
            }
            self.homing_move = None;
        }
        loop {
            // The steps by reference (`ref`): no copy of them.
            match self.homing.next(&self.config.homing, stopped, now_ms) {
                HomingStep::Move { ref steps, rate, watch, release } => {
                    self.queue_homing_move(steps, rate, watch, release, status.blocks_done);
                    return;
                }
                HomingStep::Wait => return,
                HomingStep::SetHome(motors) => {
                    self.set_home(motors);
                    stopped = 0;
                }
                HomingStep::Done => {
                    self.finish_homing();
                    return;
                }
                HomingStep::Failed(motors) => {
                    self.error = Some(MotionError::HomingFailed(motors));
                    return;
                }
            }
        }
    }

    /// A homing move to the planner (empty: homing waits for it).
    fn queue_homing_move(&mut self, steps: &[i32; MOTORS], rate: f32, watch: u8, release: bool, blocks_done: u16) {
        let dominant = steps.iter().map(|s| s.unsigned_abs()).max().unwrap_or(0);
        let motion = PlannerMove {
            steps: *steps,
            millimetres: dominant as f32,
            unit: [0.0; MOTORS],
            speed: rate,
            acceleration: self.config.homing.acceleration,
            watch,
            watch_release: release,
        };
        if dominant == 0 || self.planner.push(&motion, &self.limits).is_err() {
            self.error = Some(MotionError::HomingFailed(self.homing.group()));
            self.homing.abort();
            return;
        }
        self.homing_move = Some((blocks_done.wrapping_add(1), *steps));
    }

    #[inline(never)]
    fn set_home(&mut self, motors: u8) {
        let spu = self.config.steps_per_unit();
        // By reference: copies of the configuration's parts cost flash.
        let home = match (&self.config.home, &self.config.kinematics) {
            #[cfg(feature = "delta")]
            (HomePosition::DeltaTop, MachineKinematics::Delta(delta)) => Ok(delta.homed_carriage_heights()),
            (HomePosition::Cartesian(point), kinematics) => kinematics.inverse(*point),
            (HomePosition::DeltaTop, kinematics) => kinematics.inverse([0.0; LINEAR_AXES]),
        };
        let Ok(home) = home else {
            self.error = Some(MotionError::HomingFailed(motors));
            return;
        };
        let steps = motor_steps(&home, &spu);
        for motor in 0..LINEAR_AXES {
            if motors & (1 << motor) != 0 {
                self.motor_steps[motor] = steps[motor];
                self.homed |= 1 << motor;
            }
        }
    }

    /// Homing is over: the Cartesian position follows from the motors.
    #[inline(never)]
    fn finish_homing(&mut self) {
        let spu = self.config.steps_per_unit();
        let motors = kinematics::from_steps(
            [self.motor_steps[0], self.motor_steps[1], self.motor_steps[2]],
            [spu[0], spu[1], spu[2]],
        );
        if let Ok(point) = self.config.kinematics.forward(motors) {
            // Keep exact figures where the homed position is a given point.
            let point = match self.config.home {
                HomePosition::Cartesian(home) if self.homed & 0b111 == 0b111 => home,
                _ => point,
            };
            self.position[..LINEAR_AXES].copy_from_slice(&point);
        }
    }
}

/// Thousandths (µm, milli-units) to units as f32. Out of line: a
/// conversion and a division inline at each of a dozen sites cost flash.
#[inline(never)]
pub(crate) fn milli(value: i32) -> f32 {
    value as f32 / 1000.0
}

/// A target in µm to mm. A plain loop: `array::map` compiled to a
/// generic helper larger than this.
#[inline(never)]
fn mm_from_um(um: &[i32; MOTORS]) -> [f32; MOTORS] {
    let mut mm = [0.0; MOTORS];
    for axis in 0..MOTORS {
        mm[axis] = milli(um[axis]);
    }
    mm
}

/// Hundredths (percent) to a factor.
#[inline(never)]
fn centi(value: i32) -> f32 {
    value as f32 / 100.0
}

/// The executor's endstop layout (bit 0 X_MIN, 1 X_MAX, 2 Y_MIN, 3 Y_MAX,
/// 4 Z_MIN, 5 Z_MAX) to the step generator's (bit i: motor i min, 4 + i:
/// max). Polarity must already be applied (1 = triggered).
pub const fn pairs_to_endstop_bits(pairs: u8) -> u8 {
    let mut bits = 0;
    let mut axis = 0;
    while axis < 3 {
        if pairs & (1 << (2 * axis)) != 0 {
            bits |= 1 << axis;
        }
        if pairs & (2 << (2 * axis)) != 0 {
            bits |= 0x10 << axis;
        }
        axis += 1;
    }
    bits
}
