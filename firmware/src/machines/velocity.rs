//! Steppers run at a set speed, not to a position (SPEC §4: the extruder
//! screw and the puller of the filament line).
//!
//! The thesis toggled the STEP pin from a timer interrupt every
//!
//! ```text
//! half-period [µs] = 60 / RPM / steps_per_rev / microsteps · 10⁶ / 2
//! ```
//!
//! where `steps_per_rev` counts the motor's full steps per turn of the
//! *output* shaft, gearbox included: the extruder's NEMA 23 with its 15:1
//! box is 200·15 = 3000 steps/rev at 1/16 (625/RPM µs), the puller's NEMA 17
//! with 6:1 is 1200 steps/rev at 1/32 (781.25/RPM µs). The puller's ratio is
//! 6:1 in the thesis' code and 4:1 in its table, so the ratio is
//! configuration ([`DriveTrain::gear`]).
//!
//! # Whole timer ticks, and how they are rounded
//!
//! A compare timer counts whole ticks: on the Mega 2560 a 16-bit timer at
//! 16 MHz / 8 = 2 MHz, 0.5 µs per tick ([`MEGA_STEP_TIMER_HZ`]). The half
//! period is kept in Q24.8 ticks (1/256 tick), computed from the RPM in the
//! main loop whenever the speed changes; the interrupt adds it to a
//! fractional phase and waits the whole part, carrying the fraction to the
//! next edge (error diffusion). So every edge is within one tick of the
//! ideal, and the long-run speed is exact to 1/256 tick per edge (the
//! puller at 1 rpm, 1562.5 ticks, alternates 1562 and 1563). The Q8 value
//! itself is rounded to nearest.
//!
//! The speed is held in milli-RPM of the output shaft (`10_000` = 10 rpm).
//!
//! # Acceleration
//!
//! A new set speed is never applied at once: [`VelocityStepper::update`],
//! called at a fixed rate ([`VelocityConfig::updates_per_s`], e.g. from the
//! 1 kHz tick every 20 ms), moves the running speed toward the target by at
//! most [`VelocityConfig::slew_mrpm_per_update`]. From standstill the motor
//! starts at the slew step (or the slowest speed the 16-bit timer can time,
//! whichever is higher), as any stepper can start without a ramp at a low
//! enough speed.
//!
//! # Cost
//!
//! [`VelocityStepper::on_timer`] (the interrupt): one add, one shift, a
//! compare, no division. [`VelocityStepper::update`] (main loop or tick):
//! two 32-bit divisions when the speed changes, none when it does not.

/// The Mega 2560's step timer: 16 MHz / 8.
pub const MEGA_STEP_TIMER_HZ: u32 = 2_000_000;

/// The longest half period a 16-bit compare register can time.
pub const MAX_HALF_PERIOD_TICKS: u32 = 0xFFFF;

/// Motor turns per output-shaft turn, as a fraction (15:1 is `{15, 1}`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GearRatio {
    pub motor_turns: u16,
    pub output_turns: u16,
}

impl GearRatio {
    pub const DIRECT: GearRatio = GearRatio { motor_turns: 1, output_turns: 1 };

    pub const fn new(motor_turns: u16, output_turns: u16) -> Self {
        Self { motor_turns, output_turns }
    }
}

/// Motor, gearbox and driver of one velocity-mode axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DriveTrain {
    /// Full steps per motor turn (200 for a 1.8° motor).
    pub motor_full_steps: u16,
    pub gear: GearRatio,
    /// Driver microstepping (16 for 1/16).
    pub microsteps: u16,
}

impl DriveTrain {
    /// SPEC §4's extruder: NEMA 23, 15:1, DRV8825 at 1/16 (3000 steps/rev).
    pub const EXTRUDER_SCREW: DriveTrain = DriveTrain { motor_full_steps: 200, gear: GearRatio::new(15, 1), microsteps: 16 };
    /// SPEC §4's puller as in the thesis' code: NEMA 17, 6:1, 1/32 (1200 steps/rev).
    pub const PULLER_6_TO_1: DriveTrain = DriveTrain { motor_full_steps: 200, gear: GearRatio::new(6, 1), microsteps: 32 };
    /// The puller as in the thesis' table: 4:1 (800 steps/rev).
    pub const PULLER_4_TO_1: DriveTrain = DriveTrain { motor_full_steps: 200, gear: GearRatio::new(4, 1), microsteps: 32 };

    /// Microsteps per output-shaft turn, as a fraction (numerator, denominator).
    const fn microsteps_per_rev(&self) -> (u64, u64) {
        (
            self.motor_full_steps as u64 * self.gear.motor_turns as u64 * self.microsteps as u64,
            if self.gear.output_turns == 0 { 1 } else { self.gear.output_turns as u64 },
        )
    }

    /// Full steps per output turn (the thesis' `steps_per_rev`): 3000 for
    /// the extruder. Truncated for a ratio that does not divide evenly.
    pub const fn steps_per_rev(&self) -> u32 {
        let (numerator, denominator) = self.microsteps_per_rev();
        (numerator / self.microsteps as u64 / denominator) as u32
    }
}

/// The ideal half period in nanoseconds at `mrpm` (milli-RPM of the output
/// shaft), rounded to nearest: SPEC §4's formula. `None` at 0 rpm or for a
/// drive with no steps. (Main loop and tests: 64-bit.)
pub fn half_period_ns(drive: &DriveTrain, mrpm: u32) -> Option<u32> {
    let (numerator, denominator) = drive.microsteps_per_rev();
    // 60 s · 10⁹ ns · 1000 mrpm/rpm / 2 edges per step
    let top = 30_000_000_000_000u64 * denominator;
    let bottom = u64::from(mrpm) * numerator;
    if bottom == 0 {
        return None;
    }
    u32::try_from((top + bottom / 2) / bottom).ok()
}

/// Timer ticks × milli-RPM per edge: the half period in ticks is this
/// divided by the speed in milli-RPM. Rounded to nearest (relative error
/// below 10⁻⁶ for the SPEC §4 drives, where it is exact). 0 for a drive
/// with no steps or a constant beyond 32 bits.
pub const fn edge_constant(drive: &DriveTrain, timer_hz: u32) -> u32 {
    let (numerator, denominator) = drive.microsteps_per_rev();
    if numerator == 0 {
        return 0;
    }
    // 60 s · 1000 mrpm/rpm / 2 edges = 30 000
    let top = 30_000u64 * timer_hz as u64 * denominator;
    let value = (top + numerator / 2) / numerator;
    if value > u32::MAX as u64 {
        0
    } else {
        value as u32
    }
}

/// The half period in Q24.8 ticks at `mrpm`, rounded to nearest: two 32-bit
/// divisions (no 64-bit arithmetic on the AVR). 0 at 0 rpm.
pub fn half_period_q8(edge_constant: u32, mrpm: u32) -> u32 {
    if mrpm == 0 {
        return 0;
    }
    let whole = edge_constant / mrpm;
    let remainder = edge_constant % mrpm;
    if whole >= 1 << 24 {
        return u32::MAX;
    }
    // remainder < mrpm; a speed under 2^23 mrpm keeps (remainder << 8) in 32 bits.
    let mrpm = mrpm.min(1 << 23);
    let remainder = remainder.min(mrpm - 1);
    let fraction = ((remainder << 8) + mrpm / 2) / mrpm; // 0..=256, 256 carries
    (whole << 8) + fraction
}

/// The constants of one velocity-mode axis (configuration: RAM or flash).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VelocityConfig {
    pub drive: DriveTrain,
    /// See [`edge_constant`].
    pub edge_constant: u32,
    /// The slowest speed whose half period fits the 16-bit timer.
    pub min_mrpm: u32,
    /// Set speeds above this are refused.
    pub max_mrpm: u32,
    /// Acceleration: the most the speed changes per [`VelocityStepper::update`].
    pub slew_mrpm_per_update: u32,
    pub updates_per_s: u16,
    /// Drive DIR the other way (motor wired or mounted reversed).
    pub invert_direction: bool,
}

/// Why a velocity configuration was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VelocityConfigError {
    /// No steps per turn, or a timer too fast for 32-bit constants.
    Drive,
    /// The top speed needs a half period under [`MIN_HALF_PERIOD_TICKS`].
    TooFast,
    /// No acceleration, or no update rate.
    Ramp,
}

/// Shortest half period accepted (20 µs at 2 MHz: the interrupt needs time
/// for the other axes and the serial line).
pub const MIN_HALF_PERIOD_TICKS: u32 = 40;

impl VelocityConfig {
    /// `max_rpm`: top speed (rpm of the output); `accel_rpm_per_s`: ramp;
    /// `updates_per_s`: how often [`VelocityStepper::update`] runs.
    pub const fn new(
        drive: DriveTrain,
        timer_hz: u32,
        max_rpm: u16,
        accel_rpm_per_s: u16,
        updates_per_s: u16,
    ) -> Result<Self, VelocityConfigError> {
        let edge_constant = edge_constant(&drive, timer_hz);
        if edge_constant == 0 {
            return Err(VelocityConfigError::Drive);
        }
        let max_mrpm = max_rpm as u32 * 1000;
        if max_mrpm == 0 || edge_constant / max_mrpm < MIN_HALF_PERIOD_TICKS {
            return Err(VelocityConfigError::TooFast);
        }
        if updates_per_s == 0 || accel_rpm_per_s == 0 {
            return Err(VelocityConfigError::Ramp);
        }
        let slew = accel_rpm_per_s as u32 * 1000 / updates_per_s as u32;
        if slew == 0 {
            return Err(VelocityConfigError::Ramp);
        }
        let min_mrpm = edge_constant.div_ceil(MAX_HALF_PERIOD_TICKS);
        Ok(Self {
            drive,
            edge_constant,
            min_mrpm,
            max_mrpm,
            slew_mrpm_per_update: slew,
            updates_per_s,
            invert_direction: false,
        })
    }
}

/// What the board does with the step timer after an [`update`](VelocityStepper::update).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimerChange {
    /// Nothing: running on (the interrupt picks up the new period) or still stopped.
    None,
    /// The axis was stopped: enable the driver, set DIR, arm the compare
    /// `first_ticks` from now and enable the interrupt.
    Start { first_ticks: u16 },
    /// The ramp reached zero: stop the interrupt (STEP is left low).
    Stop,
}

/// One edge from the interrupt: drive STEP to `step_high`, and arm the
/// next compare `next_ticks` after this one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Edge {
    pub step_high: bool,
    pub next_ticks: u16,
}

/// Why a set speed was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpeedError {
    /// Above [`VelocityConfig::max_mrpm`].
    TooFast { max_mrpm: u32 },
}

/// The running state of one velocity-mode axis (18 bytes).
///
/// On the AVR the main loop's [`update`](Self::update) and the interrupt's
/// [`on_timer`](Self::on_timer) share it: call `update` inside a critical
/// section (it writes the 32-bit period the interrupt reads).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VelocityStepper {
    target_mrpm: u32,
    current_mrpm: u32,
    /// Half period in Q24.8 ticks; 0 while stopped.
    half_period_q8: u32,
    /// Whole steps made since start-up (rising edges), wraps.
    steps: u32,
    phase_q8: u8,
    step_high: bool,
}

impl VelocityStepper {
    pub const fn new() -> Self {
        Self { target_mrpm: 0, current_mrpm: 0, half_period_q8: 0, steps: 0, phase_q8: 0, step_high: false }
    }

    /// Ask for a speed (the ramp gets there). 0 stops with a ramp; a speed
    /// between 0 and the slowest the timer can time runs at that slowest.
    pub fn set_target(&mut self, config: &VelocityConfig, mrpm: u32) -> Result<(), SpeedError> {
        if mrpm > config.max_mrpm {
            return Err(SpeedError::TooFast { max_mrpm: config.max_mrpm });
        }
        self.target_mrpm = if mrpm == 0 { 0 } else { mrpm.max(config.min_mrpm) };
        Ok(())
    }

    /// Stop now, without a ramp (emergency, interlock, driver fault).
    pub fn halt(&mut self) -> TimerChange {
        let was_running = self.half_period_q8 != 0;
        *self = Self { steps: self.steps, ..Self::new() };
        if was_running {
            TimerChange::Stop
        } else {
            TimerChange::None
        }
    }

    /// One ramp update (at [`VelocityConfig::updates_per_s`]).
    pub fn update(&mut self, config: &VelocityConfig) -> TimerChange {
        let target = self.target_mrpm;
        let current = self.current_mrpm;
        let slew = config.slew_mrpm_per_update;
        let next = if target > current {
            let raised = current.saturating_add(slew).max(config.min_mrpm);
            raised.min(target)
        } else if current > target {
            let lowered = current.saturating_sub(slew);
            if lowered < config.min_mrpm && target < config.min_mrpm {
                target
            } else {
                lowered.max(target)
            }
        } else {
            return TimerChange::None;
        };
        let was_running = self.half_period_q8 != 0;
        self.current_mrpm = next;
        self.half_period_q8 = half_period_q8(config.edge_constant, next).min(MAX_HALF_PERIOD_TICKS << 8);
        match (was_running, self.half_period_q8 != 0) {
            (false, true) => {
                self.phase_q8 = 0;
                self.step_high = false;
                TimerChange::Start { first_ticks: self.next_ticks() }
            }
            (true, false) => {
                self.step_high = false;
                TimerChange::Stop
            }
            _ => TimerChange::None,
        }
    }

    fn next_ticks(&mut self) -> u16 {
        let total = self.half_period_q8 + u32::from(self.phase_q8);
        self.phase_q8 = total as u8;
        (total >> 8).clamp(1, MAX_HALF_PERIOD_TICKS) as u16
    }

    /// The interrupt's own copy of a stepper takes the speed of the main
    /// loop's `model` after an [`update`](Self::update) (inside a critical
    /// section): speed and period always; the edge phase too when it
    /// starts, so its first edge is the model's `TimerChange::Start`. The
    /// step count and STEP level stay the interrupt's, so no edge is lost
    /// or doubled.
    pub fn follow(&mut self, model: &VelocityStepper) {
        if self.half_period_q8 == 0 && model.half_period_q8 != 0 {
            self.phase_q8 = model.phase_q8;
            self.step_high = model.step_high;
        }
        self.target_mrpm = model.target_mrpm;
        self.current_mrpm = model.current_mrpm;
        self.half_period_q8 = model.half_period_q8;
    }

    /// The compare fired (interrupt): the new STEP level and the time to
    /// the next edge; `None` once stopped (disable the interrupt).
    pub fn on_timer(&mut self) -> Option<Edge> {
        if self.half_period_q8 == 0 {
            return None;
        }
        self.step_high = !self.step_high;
        if self.step_high {
            self.steps = self.steps.wrapping_add(1);
        }
        Some(Edge { step_high: self.step_high, next_ticks: self.next_ticks() })
    }

    /// The speed the motor runs at now (milli-RPM).
    pub fn current_mrpm(&self) -> u32 {
        self.current_mrpm
    }

    pub fn target_mrpm(&self) -> u32 {
        self.target_mrpm
    }

    /// Whether the ramp has reached the set speed.
    pub fn at_speed(&self) -> bool {
        self.current_mrpm == self.target_mrpm
    }

    pub fn is_running(&self) -> bool {
        self.half_period_q8 != 0
    }

    /// The half period now, Q24.8 ticks (0 stopped).
    pub fn half_period_q8(&self) -> u32 {
        self.half_period_q8
    }

    /// Whole steps made (rising STEP edges) since start-up, wrapping.
    pub fn steps(&self) -> u32 {
        self.steps
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RAMP_HZ: u16 = 50;

    fn extruder() -> VelocityConfig {
        VelocityConfig::new(DriveTrain::EXTRUDER_SCREW, MEGA_STEP_TIMER_HZ, 20, 5, RAMP_HZ).unwrap()
    }

    fn puller() -> VelocityConfig {
        VelocityConfig::new(DriveTrain::PULLER_6_TO_1, MEGA_STEP_TIMER_HZ, 15, 5, RAMP_HZ).unwrap()
    }

    #[test]
    fn the_thesis_drives_have_3000_and_1200_steps_per_rev() {
        assert_eq!(DriveTrain::EXTRUDER_SCREW.steps_per_rev(), 3000);
        assert_eq!(DriveTrain::PULLER_6_TO_1.steps_per_rev(), 1200);
        assert_eq!(DriveTrain::PULLER_4_TO_1.steps_per_rev(), 800);
    }

    #[test]
    fn spec_half_periods_625_and_781_25_us_per_rpm() {
        // extruder: 625/RPM µs
        assert_eq!(half_period_ns(&DriveTrain::EXTRUDER_SCREW, 1_000), Some(625_000));
        assert_eq!(half_period_ns(&DriveTrain::EXTRUDER_SCREW, 10_000), Some(62_500));
        // puller (6:1): 781.25/RPM µs
        assert_eq!(half_period_ns(&DriveTrain::PULLER_6_TO_1, 1_000), Some(781_250));
        assert_eq!(half_period_ns(&DriveTrain::PULLER_6_TO_1, 5_000), Some(156_250));
        // puller (4:1): 1171.875/RPM µs
        assert_eq!(half_period_ns(&DriveTrain::PULLER_4_TO_1, 1_000), Some(1_171_875));
        assert_eq!(half_period_ns(&DriveTrain::EXTRUDER_SCREW, 0), None);
    }

    #[test]
    fn extruder_at_10_rpm_is_62_5_us_or_125_ticks_at_2_mhz() {
        let k = edge_constant(&DriveTrain::EXTRUDER_SCREW, MEGA_STEP_TIMER_HZ);
        assert_eq!(k, 1_250_000);
        assert_eq!(half_period_q8(k, 10_000), 125 << 8);
        let config = extruder();
        let mut stepper = VelocityStepper::new();
        stepper.set_target(&config, 10_000).unwrap();
        while !stepper.at_speed() {
            stepper.update(&config);
        }
        for _ in 0..100 {
            assert_eq!(stepper.on_timer().unwrap().next_ticks, 125);
        }
    }

    #[test]
    fn a_fractional_half_period_alternates_whole_ticks_with_the_exact_mean() {
        // Puller at 1 rpm: 781.25 µs = 1562.5 ticks.
        let k = edge_constant(&DriveTrain::PULLER_6_TO_1, MEGA_STEP_TIMER_HZ);
        assert_eq!(half_period_q8(k, 1_000), 1562 * 256 + 128);
        let mut stepper = VelocityStepper { target_mrpm: 1_000, current_mrpm: 1_000, half_period_q8: half_period_q8(k, 1_000), ..VelocityStepper::new() };
        let ticks: std::vec::Vec<u16> = (0..4).map(|_| stepper.on_timer().unwrap().next_ticks).collect();
        assert_eq!(ticks, [1562, 1563, 1562, 1563]);
        // 4:1 puller at 1 rpm: 2343.75 ticks; four edges take exactly 9375.
        let k = edge_constant(&DriveTrain::PULLER_4_TO_1, MEGA_STEP_TIMER_HZ);
        let mut stepper = VelocityStepper { half_period_q8: half_period_q8(k, 1_000), ..VelocityStepper::new() };
        let sum: u32 = (0..400).map(|_| u32::from(stepper.on_timer().unwrap().next_ticks)).sum();
        assert_eq!(sum, 937_500);
    }

    #[test]
    fn no_edge_is_off_by_more_than_one_tick_and_the_mean_speed_is_exact() {
        let k = edge_constant(&DriveTrain::PULLER_6_TO_1, MEGA_STEP_TIMER_HZ);
        for mrpm in [1_000, 1_234, 3_878, 7_000, 15_000] {
            let period = half_period_q8(k, mrpm);
            let mut stepper = VelocityStepper { half_period_q8: period, ..VelocityStepper::new() };
            let mut total = 0u64;
            for _ in 0..10_000 {
                let ticks = u32::from(stepper.on_timer().unwrap().next_ticks);
                assert!(ticks == period >> 8 || ticks == (period >> 8) + 1);
                total += u64::from(ticks);
            }
            let ideal = 10_000.0 * k as f64 / mrpm as f64;
            assert!((total as f64 - ideal).abs() < 10_000.0 / 256.0 + 1.0, "{mrpm}: {total} vs {ideal}");
        }
    }

    #[test]
    fn step_pin_toggles_and_counts_a_step_per_rising_edge() {
        let config = extruder();
        let mut stepper = VelocityStepper::new();
        stepper.set_target(&config, 10_000).unwrap();
        assert!(matches!(stepper.update(&config), TimerChange::Start { .. }));
        let levels: std::vec::Vec<bool> = (0..4).map(|_| stepper.on_timer().unwrap().step_high).collect();
        assert_eq!(levels, [true, false, true, false]);
        assert_eq!(stepper.steps(), 2);
    }

    #[test]
    fn speed_ramps_by_the_slew_limit_instead_of_jumping() {
        // 5 rpm/s at 50 updates/s: 100 mrpm per update; 0 → 10 rpm in 2 s.
        let config = extruder();
        assert_eq!(config.slew_mrpm_per_update, 100);
        let mut stepper = VelocityStepper::new();
        stepper.set_target(&config, 10_000).unwrap();
        let change = stepper.update(&config);
        assert_eq!(stepper.current_mrpm(), 100);
        assert_eq!(change, TimerChange::Start { first_ticks: 12_500 });
        let mut updates = 1;
        let mut previous = stepper.current_mrpm();
        while !stepper.at_speed() {
            assert_eq!(stepper.update(&config), TimerChange::None);
            assert!(stepper.current_mrpm() - previous <= 100);
            previous = stepper.current_mrpm();
            updates += 1;
        }
        assert_eq!(updates, 100);
        // Down to a stop with the same ramp, then the timer stops.
        stepper.set_target(&config, 0).unwrap();
        let mut last = TimerChange::None;
        for _ in 0..100 {
            last = stepper.update(&config);
        }
        assert_eq!(last, TimerChange::Stop);
        assert!(!stepper.is_running());
        assert_eq!(stepper.on_timer(), None);
    }

    #[test]
    fn speeds_below_what_the_16_bit_timer_can_time_run_at_the_slowest_it_can() {
        let config = puller();
        // 1 562 500 / 65 535 → 24 mrpm
        assert_eq!(config.min_mrpm, 24);
        let mut stepper = VelocityStepper::new();
        stepper.set_target(&config, 5).unwrap();
        assert_eq!(stepper.target_mrpm(), 24);
        stepper.update(&config);
        assert!(stepper.half_period_q8() >> 8 <= MAX_HALF_PERIOD_TICKS);
    }

    #[test]
    fn set_speeds_above_the_configured_top_are_refused() {
        let config = puller();
        let mut stepper = VelocityStepper::new();
        assert_eq!(stepper.set_target(&config, 15_001), Err(SpeedError::TooFast { max_mrpm: 15_000 }));
        assert_eq!(stepper.target_mrpm(), 0);
    }

    #[test]
    fn configurations_that_the_timer_cannot_run_are_refused() {
        // 1 000 rpm at 1/16 with 15:1 would need 0.6 µs half periods.
        assert_eq!(VelocityConfig::new(DriveTrain::EXTRUDER_SCREW, MEGA_STEP_TIMER_HZ, 1000, 5, 50), Err(VelocityConfigError::TooFast));
        assert_eq!(VelocityConfig::new(DriveTrain::EXTRUDER_SCREW, MEGA_STEP_TIMER_HZ, 10, 0, 50), Err(VelocityConfigError::Ramp));
    }

    #[test]
    fn halt_stops_at_once() {
        let config = extruder();
        let mut stepper = VelocityStepper::new();
        stepper.set_target(&config, 10_000).unwrap();
        stepper.update(&config);
        assert_eq!(stepper.halt(), TimerChange::Stop);
        assert_eq!((stepper.current_mrpm(), stepper.target_mrpm(), stepper.on_timer()), (0, 0, None));
    }

    #[test]
    fn state_is_small() {
        assert!(core::mem::size_of::<VelocityStepper>() <= 20);
    }
}
