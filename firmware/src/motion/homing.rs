//! Homing (`G28`): the per-axis sequence as a state machine that the motion
//! layer drives one move at a time.
//!
//! For each group of motors homed together (one axis at a time on a
//! Cartesian printer or the arm, all three towers at once on a delta):
//!
//! 1. *approach* towards the endstop at the fast rate, up to the axis'
//!    travel; each motor stops on its own switch (the step interrupt does it,
//!    so the stop comes within one step);
//! 2. optionally *pause* (the arm: 500 ms);
//! 3. either *back off* a fixed distance and *re-approach* slowly (the
//!    RepRap way), or back off slowly until the switch *releases* (the
//!    arm's thesis: that release point is home);
//! 4. *set* the motors of the group to their home position.
//!
//! A switch that never triggers (or never releases) within the allowed
//! travel fails homing for that group: the machine stays unhomed.
//!
//! Rates and distances are in steps, so one description fits carriages,
//! lead screws and joints alike; the presets convert from mm.

use super::stepper::MOTORS;

/// How one motor homes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisHoming {
    /// Home at the max endstop (else the min endstop).
    pub towards_max: bool,
    /// Approach rate, steps/s.
    pub fast_rate: f32,
    /// Re-approach (or release) rate, steps/s.
    pub slow_rate: f32,
    /// Back-off distance (or the most to back off looking for the release).
    pub backoff_steps: u32,
    /// The longest approach before giving up (the axis' travel and some).
    pub max_travel_steps: u32,
    /// Back off slowly until the switch releases, instead of bump homing.
    pub release: bool,
    /// Pause after the approach, ms.
    pub pause_ms: u16,
}

impl AxisHoming {
    /// Marlin-like bump homing from mm figures.
    pub const fn bump(towards_max: bool, steps_per_mm: f32, feed_mm_s: f32, travel_mm: f32, backoff_mm: f32) -> Self {
        Self {
            towards_max,
            fast_rate: feed_mm_s * steps_per_mm,
            slow_rate: feed_mm_s * steps_per_mm / 2.0,
            backoff_steps: (backoff_mm * steps_per_mm) as u32,
            max_travel_steps: (travel_mm * 1.5 * steps_per_mm) as u32,
            release: false,
            pause_ms: 0,
        }
    }
}

/// The order of homing and each motor's way.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HomingConfig {
    /// Motor masks homed together, in order (0: unused slot).
    pub sequence: [u8; 3],
    pub axes: [AxisHoming; 3],
    /// Acceleration of homing moves, steps/s².
    pub acceleration: f32,
}

/// The endstop bit of a motor's homing switch (`StepBlock::watch` layout).
pub fn endstop_bit(motor: usize, towards_max: bool) -> u8 {
    if towards_max {
        0x10 << motor
    } else {
        1 << motor
    }
}

/// Endstop pin levels → triggered bits (`StepBlock::watch` layout), with
/// the polarity of each switch: a bit of `active_high` set means that
/// switch reads high when triggered (a normally-closed switch with a
/// pull-up, so an open wire reads as triggered, as SPEC §3 wants); clear
/// means active low (a normally-open switch to ground). Switches not in
/// `present` never trigger.
pub const fn endstops_triggered(levels: u8, active_high: u8, present: u8) -> u8 {
    !(levels ^ active_high) & present
}

/// What the motion layer should do next.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HomingStep {
    /// Queue this motor-space move, then call again once it has finished.
    Move { steps: [i32; MOTORS], rate: f32, watch: u8, release: bool },
    /// Nothing yet (pausing); call again later.
    Wait,
    /// Set these motors to their home position, then call again.
    SetHome(u8),
    /// Every requested motor is homed.
    Done,
    /// These motors' switches did not trigger (or release) in time.
    Failed(u8),
}

/// `repr(u8)`: `NextGroup` is the tag 0, so an all-zero `Homing` is
/// [`Homing::new`] (see [`Homing::init_in`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
enum Phase {
    NextGroup,
    AfterApproach,
    Pausing { until_ms: u32 },
    AfterBackoff,
    AfterReapproach,
    AfterRelease,
}

/// The kinds of homing move.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stage {
    /// Fast, towards the switch, up to the travel, watching it.
    Approach,
    /// Fast, away from the switch, not watching (bump homing).
    BackOff,
    /// Slow, towards the switch, twice the back-off, watching it.
    Reapproach,
    /// Slow, away from the switch until it releases (the arm).
    Release,
}

/// The state machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Homing {
    requested: u8,
    group_index: u8,
    group: u8,
    phase: Phase,
    active: bool,
    /// Steps each motor made in the last move before its switch stopped it.
    travel: [u16; MOTORS],
}

impl Default for Homing {
    fn default() -> Self {
        Self::new()
    }
}

impl Homing {
    pub const fn new() -> Self {
        Self { requested: 0, group_index: 0, group: 0, phase: Phase::NextGroup, active: false, travel: [0; MOTORS] }
    }

    /// [`Self::new`] built in `slot` with a memset: all-zero bytes are
    /// `new()` (zero integers, `false`, `Phase::NextGroup` as tag 0 of a
    /// `repr(u8)` enum; a test compares), where the constant was written
    /// byte by byte to absolute addresses of the board's `static` machine.
    pub fn init_in(slot: &mut core::mem::MaybeUninit<Self>) {
        // SAFETY: zero bytes are a valid `Homing`, see above.
        unsafe { core::ptr::write_bytes(slot.as_mut_ptr(), 0, 1) };
    }

    /// Begin homing these motors (a mask of motors 0–2).
    pub fn start(&mut self, motors: u8) {
        // `new()` by a memset, as `init_in`.
        // SAFETY: zero bytes are a valid `Homing` (see `init_in`).
        unsafe { core::ptr::write_bytes(self as *mut Self, 0, 1) };
        self.requested = motors & 0b111;
        self.active = true;
    }

    pub fn is_active(&self) -> bool {
        self.active
    }

    pub fn abort(&mut self) {
        self.active = false;
    }

    /// How far each stopped motor went in the last move (the generator's
    /// `stopped_steps`), before [`Self::next`].
    pub fn set_travel(&mut self, travel: [u16; MOTORS]) {
        self.travel = travel;
    }

    /// The motors being homed right now.
    pub fn group(&self) -> u8 {
        self.group
    }

    /// The next step. `stopped`: the motors that their endstop stopped in
    /// the move that just finished (ignored when no move was asked for).
    pub fn next(&mut self, config: &HomingConfig, stopped: u8, now_ms: u32) -> HomingStep {
        if !self.active {
            return HomingStep::Done;
        }
        let group = self.group;
        let lead = self.lead(config);
        match self.phase {
            Phase::NextGroup => self.start_next_group(config),
            Phase::AfterApproach => {
                if stopped & group != group {
                    return self.fail(group & !stopped);
                }
                if lead.pause_ms > 0 {
                    self.phase = Phase::Pausing { until_ms: now_ms.wrapping_add(lead.pause_ms as u32) };
                    return HomingStep::Wait;
                }
                self.back_off(config)
            }
            Phase::Pausing { until_ms } => {
                if (now_ms.wrapping_sub(until_ms) as i32) < 0 {
                    return HomingStep::Wait;
                }
                self.back_off(config)
            }
            Phase::AfterBackoff => {
                self.phase = Phase::AfterReapproach;
                self.group_move(config, Stage::Reapproach)
            }
            Phase::AfterReapproach | Phase::AfterRelease => {
                if stopped & group != group {
                    return self.fail(group & !stopped);
                }
                if self.phase == Phase::AfterReapproach {
                    // The back-off must have released the switch: a
                    // re-approach that stops within half of it means the
                    // switch never let go (stuck, or shorted wiring; Marlin's
                    // "Bad endstop"), and the home found would be wrong.
                    // (A running bit over zipped arrays: no variable shifts
                    // or bounds checks on the AVR.)
                    let mut stuck = 0;
                    let mut bit = 1;
                    for (travel, axis) in self.travel.iter().zip(&config.axes) {
                        if group & bit != 0 && u32::from(*travel) * 2 < axis.backoff_steps {
                            stuck |= bit;
                        }
                        bit <<= 1;
                    }
                    if stuck != 0 {
                        return self.fail(stuck);
                    }
                }
                self.phase = Phase::NextGroup;
                HomingStep::SetHome(group)
            }
        }
    }

    fn start_next_group(&mut self, config: &HomingConfig) -> HomingStep {
        while (self.group_index as usize) < config.sequence.len() {
            let group = config.sequence[self.group_index as usize] & self.requested;
            self.group_index += 1;
            if group != 0 {
                self.group = group;
                self.phase = Phase::AfterApproach;
                return self.group_move(config, Stage::Approach);
            }
        }
        self.active = false;
        self.group = 0;
        HomingStep::Done
    }

    // Inline in both its callers: out of line, its result went through
    // memory once more (24 bytes).
    #[inline(always)]
    fn back_off(&mut self, config: &HomingConfig) -> HomingStep {
        let lead = self.lead(config);
        if lead.release {
            self.phase = Phase::AfterRelease;
            self.group_move(config, Stage::Release)
        } else {
            self.phase = Phase::AfterBackoff;
            self.group_move(config, Stage::BackOff)
        }
    }

    /// The settings of the group's first motor, which lead its pause and
    /// kind of back-off. Out of line: two callers.
    #[inline(never)]
    fn lead<'c>(&self, config: &'c HomingConfig) -> &'c AxisHoming {
        &config.axes[self.group.trailing_zeros().min(2) as usize]
    }

    /// A move of every motor of the group, towards (or away from) its
    /// switch, watching it or not. One function for the four kinds of move
    /// (not generic over a closure, which compiled to four copies).
    #[inline(never)]
    fn group_move(&self, config: &HomingConfig, stage: Stage) -> HomingStep {
        let towards = matches!(stage, Stage::Approach | Stage::Reapproach);
        let watch = !matches!(stage, Stage::BackOff);
        let mut steps = [0_i32; MOTORS];
        let mut rate = f32::MAX;
        let mut watch_bits = 0;
        // A running motor bit and zipped arrays: no variable shifts (a loop
        // each on the AVR) and no bounds checks.
        let mut bit = 1_u8;
        for (step, axis) in steps.iter_mut().zip(&config.axes) {
            let motor_bit = bit;
            bit <<= 1;
            if self.group & motor_bit == 0 {
                continue;
            }
            let (distance, axis_rate) = match stage {
                Stage::Approach => (axis.max_travel_steps, axis.fast_rate),
                Stage::BackOff => (axis.backoff_steps, axis.fast_rate),
                Stage::Reapproach => (axis.backoff_steps.saturating_mul(2), axis.slow_rate),
                Stage::Release => (axis.backoff_steps, axis.slow_rate),
            };
            let distance = distance.min(i32::MAX as u32) as i32;
            let positive = axis.towards_max == towards;
            *step = if positive { distance } else { -distance };
            rate = super::math::min(rate, axis_rate);
            if watch {
                // `endstop_bit`: bit i (min) or 4 + i (max).
                watch_bits |= if axis.towards_max { motor_bit << 4 } else { motor_bit };
            }
        }
        HomingStep::Move { steps, rate, watch: watch_bits, release: matches!(stage, Stage::Release) }
    }

    fn fail(&mut self, motors: u8) -> HomingStep {
        self.active = false;
        HomingStep::Failed(motors)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn arm_config() -> HomingConfig {
        let joint = |towards_max| AxisHoming {
            towards_max,
            fast_rate: 200.0,
            slow_rate: 20.0,
            backoff_steps: 2000,
            max_travel_steps: 20_000,
            release: true,
            pause_ms: 500,
        };
        HomingConfig { sequence: [0b100, 0b010, 0b001], axes: [joint(true), joint(true), joint(false)], acceleration: 1000.0 }
    }

    #[test]
    fn arm_sequence_is_z_then_y_then_x_with_pause_and_release() {
        let config = arm_config();
        let mut homing = Homing::new();
        homing.start(0b111);
        let mut now = 0;
        for (motor, sign) in [(2_usize, -1), (1, 1), (0, 1)] {
            let bit = 1 << motor;
            let HomingStep::Move { steps, rate, watch, release } = homing.next(&config, 0, now) else { panic!() };
            assert_eq!(steps[motor], sign * 20_000, "approach of motor {motor}");
            assert_eq!((rate, release), (200.0, false));
            assert_eq!(watch, endstop_bit(motor, sign > 0));
            // Switch hit: pause 500 ms.
            assert_eq!(homing.next(&config, bit, now), HomingStep::Wait);
            now += 499;
            assert_eq!(homing.next(&config, bit, now), HomingStep::Wait);
            now += 1;
            let HomingStep::Move { steps, rate, release, .. } = homing.next(&config, bit, now) else { panic!() };
            assert_eq!((steps[motor], rate, release), (-sign * 2000, 20.0, true));
            assert_eq!(homing.next(&config, bit, now), HomingStep::SetHome(bit));
        }
        assert_eq!(homing.next(&config, 0, now), HomingStep::Done);
        assert!(!homing.is_active());
    }

    #[test]
    fn a_zeroed_homing_is_new() {
        let mut slot = core::mem::MaybeUninit::<Homing>::uninit();
        Homing::init_in(&mut slot);
        // SAFETY: `init_in` initialised it.
        assert_eq!(unsafe { slot.assume_init() }, Homing::new());
    }

    #[test]
    fn endstop_polarity() {
        // X min NC (active high), Y min NO (active low), nothing else fitted.
        let (active_high, present) = (0b0000_0001, 0b0000_0011);
        assert_eq!(endstops_triggered(0b0000_0010, active_high, present), 0);
        assert_eq!(endstops_triggered(0b0000_0001, active_high, present), 0b11);
        assert_eq!(endstops_triggered(0b1111_0011, active_high, present), 0b01);
    }

    #[test]
    fn bump_homing_and_failure() {
        let axis = AxisHoming::bump(false, 100.0, 50.0, 200.0, 5.0);
        let config = HomingConfig { sequence: [0b001, 0b010, 0b100], axes: [axis; 3], acceleration: 100_000.0 };
        let mut homing = Homing::new();
        homing.start(0b001);
        let HomingStep::Move { steps, .. } = homing.next(&config, 0, 0) else { panic!() };
        assert_eq!(steps[0], -30_000);
        let HomingStep::Move { steps, watch, .. } = homing.next(&config, 1, 0) else { panic!() };
        assert_eq!((steps[0], watch), (500, 0));
        let HomingStep::Move { steps, rate, watch, .. } = homing.next(&config, 0, 0) else { panic!() };
        assert_eq!((steps[0], rate, watch), (-1000, 2500.0, 1));
        // The switch came back after 498 of the 500 steps backed off.
        homing.set_travel([498, 0, 0, 0]);
        assert_eq!(homing.next(&config, 1, 0), HomingStep::SetHome(1));
        assert_eq!(homing.next(&config, 0, 0), HomingStep::Done);
        // A switch stuck triggered: the re-approach stops at once.
        homing.start(0b001);
        homing.next(&config, 0, 0);
        homing.next(&config, 1, 0);
        homing.next(&config, 0, 0);
        homing.set_travel([3, 0, 0, 0]);
        assert_eq!(homing.next(&config, 1, 0), HomingStep::Failed(0b001));
        // A switch that never triggers.
        homing.start(0b010);
        homing.next(&config, 0, 0);
        assert_eq!(homing.next(&config, 0, 0), HomingStep::Failed(0b010));
    }
}
