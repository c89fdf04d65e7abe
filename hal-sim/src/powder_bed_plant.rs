//! The powder-bed retrofit (SPEC §5) in simulation: two platforms on
//! M542-driven steppers with reed switches, a carriage on a DC motor with a
//! quadrature encoder and end sensors C−/C+, a roller and a suction unit;
//! and [`PowderBed::execute`], which carries out the firmware's
//! [`LayerCommand`]s the way the executor will (for the tests).
//!
//! # Platforms ([`PlatformPlant`])
//!
//! Driven through their pins, with the driver's polarities: the platform
//! moves one step on each *active* STEP edge (falling for the M542) while
//! ENA is at its enabling level (low), down when DIR is at its down level
//! (high). Hard stops bound the travel (steps beyond them are lost, as a
//! stalled motor's are). Each reed switch is closed while the platform's
//! magnet is within its zone (a range of positions), and its pin reads at
//! the configured active level then (pull-up, switch to ground: low).
//! A switch can be missing (never closes).
//!
//! # Carriage ([`Carriage`])
//!
//! The closed-loop module's [`DcServoPlant`] (duty → speed with a lag and
//! a small dead time → quadrature edges) read by the firmware's
//! [`QuadratureDecoder`] and driven by its servo PID ([`AxisController`]).
//! C− reads active at or below `c_minus_counts`, C+ at or above
//! `c_plus_counts`.

use crate::axis_plant::DcServoPlant;
use firmware::closed_loop::control::{AxisController, DriverStatus, FollowingErrorLimit, Reference};
use firmware::closed_loop::output::ActiveLevel;
use firmware::closed_loop::quadrature::QuadratureDecoder;
use firmware::closed_loop::tuning::relay_ziegler_nichols;
use firmware::closed_loop::LoopGains;
use firmware::machines::powder_bed::{
    CarriageEnd, LayerCommand, LayerEvent, Platform, PlatformAction, PlatformDriver, PlatformSwitches, TravelFault, TravelLimits,
    TravelMeasurement, TravelReport, Vertical,
};

/// One platform and its two reed switches.
#[derive(Clone, Debug)]
pub struct PlatformPlant {
    pub driver: PlatformDriver,
    /// Position in steps, up positive.
    pub position: i64,
    /// Hard stops (steps).
    pub bottom: i64,
    pub top: i64,
    /// Closed-switch zones (inclusive), `None`: the switch is missing.
    pub lower_zone: Option<(i64, i64)>,
    pub upper_zone: Option<(i64, i64)>,
    /// The level a closed switch reads (pull-up to 5 V, switch to ground: `Low`).
    pub switch_active: ActiveLevel,
    enable_level: bool,
    dir_level: bool,
    step_level: bool,
    /// Steps taken on active edges while enabled.
    pub steps_taken: u64,
    /// Active edges while disabled (a fault in the firmware's sequencing).
    pub edges_while_disabled: u64,
}

impl PlatformPlant {
    /// A platform with `travel` steps between the lower switch's top edge
    /// and the upper switch's bottom edge; zones 60 steps long (0.3 mm of a
    /// reed's pull-in at 200 steps/mm), hard stops 400 steps beyond them.
    pub fn new(driver: PlatformDriver, travel: i64, start: i64) -> Self {
        let lower_top = 0;
        let upper_bottom = travel;
        Self {
            driver,
            position: start,
            bottom: lower_top - 460,
            top: upper_bottom + 460,
            lower_zone: Some((lower_top - 60, lower_top)),
            upper_zone: Some((upper_bottom, upper_bottom + 60)),
            switch_active: ActiveLevel::Low,
            enable_level: !driver.enable_level(true),
            dir_level: false,
            step_level: driver.step_idle_level(),
            steps_taken: 0,
            edges_while_disabled: 0,
        }
    }

    pub fn set_enable(&mut self, high: bool) {
        self.enable_level = high;
    }

    pub fn set_dir(&mut self, high: bool) {
        self.dir_level = high;
    }

    /// Drive STEP; the active edge moves the platform.
    pub fn set_step(&mut self, high: bool) {
        let previous = self.step_level;
        self.step_level = high;
        let active_edge = match self.driver.step_active {
            ActiveLevel::Low => previous && !high,
            ActiveLevel::High => !previous && high,
        };
        if !active_edge {
            return;
        }
        if self.enable_level != self.driver.enable_level(true) {
            self.edges_while_disabled += 1;
            return;
        }
        let down = self.dir_level == (self.driver.dir_down == ActiveLevel::High);
        let next = if down { self.position - 1 } else { self.position + 1 };
        self.position = next.clamp(self.bottom, self.top);
        self.steps_taken += 1;
    }

    fn in_zone(&self, zone: Option<(i64, i64)>) -> bool {
        zone.is_some_and(|(low, high)| self.position >= low && self.position <= high)
    }

    /// Pin levels (true = high) of the lower and upper switch.
    pub fn switch_levels(&self) -> (bool, bool) {
        let level = |closed: bool| match self.switch_active {
            ActiveLevel::High => closed,
            ActiveLevel::Low => !closed,
        };
        (level(self.in_zone(self.lower_zone)), level(self.in_zone(self.upper_zone)))
    }

    /// One step as the board does it: DIR first, then a pulse (active
    /// edge, back to idle).
    pub fn pulse(&mut self, direction: Vertical) {
        let dir = self.driver.dir_level(direction);
        self.set_dir(dir);
        let idle = self.driver.step_idle_level();
        self.set_step(!idle);
        self.set_step(idle);
    }
}

/// The carriage: DC motor, encoder, servo PID, end sensors.
pub struct Carriage {
    pub plant: DcServoPlant,
    pub decoder: QuadratureDecoder,
    pub controller: AxisController,
    pub c_minus_counts: i32,
    pub c_plus_counts: i32,
    /// Reference speed of a stroke, counts/s.
    pub speed_counts_per_s: i32,
    /// The executor gives up on a stroke this long without its sensor.
    pub max_stroke_counts: i32,
    /// Time simulated, s.
    pub time_s: f64,
}

/// A carriage stroke that failed: the servo loop faulted, or the end
/// sensor did not trip within the stroke length.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StrokeFailed;

/// The loop period of the carriage servo (1 kHz).
pub const CARRIAGE_TICK_S: f64 = 0.001;

impl Carriage {
    /// SPEC §5's Pittman carriage as in the closed-loop tests (40 counts/s
    /// per duty unit, 30 ms lag, 4 ms dead time), relay-tuned gains, ±255
    /// duty; C− at 0, C+ at 4000 counts (20 revolutions), strokes at 2000
    /// counts/s.
    pub fn standard() -> Self {
        let gains = relay_ziegler_nichols(127.0, 10.0, 0.05).expect("relay gains");
        let fixed: LoopGains = LoopGains::servo_pid(&gains, CARRIAGE_TICK_S as f32).expect("servo gains");
        Self {
            plant: DcServoPlant::new(40.0, 0.03, 0.004, 0.0001),
            decoder: QuadratureDecoder::new(false, false, 0),
            controller: AxisController::new(fixed, 255, FollowingErrorLimit { limit: 4000, hold_ticks: 1000 }),
            c_minus_counts: 0,
            c_plus_counts: 4000,
            speed_counts_per_s: 2000,
            max_stroke_counts: 4800,
            time_s: 0.0,
        }
    }

    pub fn at(&self) -> Option<CarriageEnd> {
        let count = self.decoder.count();
        if count <= self.c_minus_counts {
            Some(CarriageEnd::Minus)
        } else if count >= self.c_plus_counts {
            Some(CarriageEnd::Plus)
        } else {
            None
        }
    }

    /// Move toward `to` until its sensor reads active, then stop 20
    /// counts into the sensor's zone and hold. `Err(StrokeFailed)` on a loop fault or
    /// when the sensor has not tripped within `max_stroke_counts`.
    pub fn stroke(&mut self, to: CarriageEnd) -> Result<(), StrokeFailed> {
        let start = self.decoder.count();
        let (goal, step) = match to {
            CarriageEnd::Plus => (start + self.max_stroke_counts, self.speed_counts_per_s),
            CarriageEnd::Minus => (start - self.max_stroke_counts, -self.speed_counts_per_s),
        };
        let per_tick = f64::from(step) * CARRIAGE_TICK_S;
        let mut reference = f64::from(start);
        let ticks = ((f64::from(goal - start) / per_tick).abs() as usize) + 2000;
        for _ in 0..ticks {
            if self.at() == Some(to) {
                // stop just inside the sensor's zone and settle
                let hold = self.decoder.count() + if step > 0 { 20 } else { -20 };
                for _ in 0..300 {
                    self.tick(hold)?;
                }
                return Ok(());
            }
            let goal = f64::from(goal);
            reference = if step > 0 { (reference + per_tick).min(goal) } else { (reference + per_tick).max(goal) };
            self.tick(reference.round() as i32)?;
        }
        Err(StrokeFailed)
    }

    /// One millisecond with the firmware's duty on the H-bridge (the
    /// board's 1 kHz tick, when the firmware runs the loop itself).
    pub fn drive(&mut self, duty: i32) {
        self.plant.set_duty(duty);
        let decoder = &mut self.decoder;
        self.plant.advance(CARRIAGE_TICK_S, |a, b| decoder.on_edge(a, b));
        self.time_s += CARRIAGE_TICK_S;
    }

    fn tick(&mut self, position: i32) -> Result<(), StrokeFailed> {
        let duty = self.controller.tick(Reference { position, velocity: 0 }, Ok(self.decoder.count()), DriverStatus::default()).map_err(|_| StrokeFailed)?;
        self.plant.set_duty(duty);
        let decoder = &mut self.decoder;
        self.plant.advance(CARRIAGE_TICK_S, |a, b| decoder.on_edge(a, b));
        self.time_s += CARRIAGE_TICK_S;
        Ok(())
    }
}

/// The whole machine.
pub struct PowderBed {
    pub feed: PlatformPlant,
    pub build: PlatformPlant,
    pub carriage: Carriage,
    /// The carriage's Y axis (no end sensors).
    pub carriage_y: Carriage,
    pub roller_on: bool,
    pub suction_on: bool,
    /// Every command executed, in order, with what was true at that moment.
    pub log: Vec<LogEntry>,
}

/// What [`PowderBed::execute`] saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogEntry {
    pub command: LayerCommand,
    pub roller_on: bool,
    pub carriage_at: Option<CarriageEnd>,
    pub feed_position: i64,
    pub build_position: i64,
}

impl PowderBed {
    /// Both platforms with `travel` steps between their switches, the
    /// feed platform near its top, the build platform near its top (a new
    /// job), the carriage at C−.
    pub fn new(driver: PlatformDriver, travel: i64) -> Self {
        Self {
            feed: PlatformPlant::new(driver, travel, travel / 2),
            build: PlatformPlant::new(driver, travel, travel - 100),
            carriage: Carriage::standard(),
            carriage_y: Carriage::standard(),
            roller_on: false,
            suction_on: false,
            log: Vec::new(),
        }
    }

    pub fn platform(&mut self, platform: Platform) -> &mut PlatformPlant {
        match platform {
            Platform::Feed => &mut self.feed,
            Platform::Build => &mut self.build,
        }
    }

    /// Carry out one layer command as the executor would and answer it.
    /// `Finished`/`Aborted` answer `Done` (nothing to do but stop).
    pub fn execute(&mut self, command: LayerCommand) -> LayerEvent {
        self.log.push(LogEntry {
            command,
            roller_on: self.roller_on,
            carriage_at: self.carriage.at(),
            feed_position: self.feed.position,
            build_position: self.build.position,
        });
        match command {
            LayerCommand::Roller(on) => {
                self.roller_on = on;
                LayerEvent::Done
            }
            LayerCommand::Suction(on) => {
                self.suction_on = on;
                LayerEvent::Done
            }
            LayerCommand::MoveCarriage { to, .. } => match self.carriage.stroke(to) {
                Ok(()) => LayerEvent::CarriageArrived(to),
                Err(StrokeFailed) => LayerEvent::Failed,
            },
            LayerCommand::StepPlatform { platform, direction, steps } => {
                let plant = self.platform(platform);
                let enable = plant.driver.enable_level(true);
                plant.set_enable(enable);
                for _ in 0..steps {
                    plant.pulse(direction);
                }
                LayerEvent::Done
            }
            LayerCommand::Finished { .. } => LayerEvent::Done,
            LayerCommand::Aborted(_) => {
                self.roller_on = false;
                self.suction_on = false;
                LayerEvent::Done
            }
        }
    }
}

/// Run the firmware's travel measurement on `plant` at 1 kHz (the
/// thesis' rate), driving the pins as the board does and reading the
/// switches through the configured polarity. Returns the result and the
/// seconds it took.
pub fn measure_travel(plant: &mut PlatformPlant, limits: &TravelLimits, polarity: ActiveLevel) -> (Result<TravelReport, TravelFault>, f64) {
    let mut routine = TravelMeasurement::new();
    let enable = plant.driver.enable_level(true);
    plant.set_enable(enable);
    for tick in 0..10_000_000u64 {
        let (lower, upper) = plant.switch_levels();
        match routine.tick(limits, PlatformSwitches::from_levels(lower, upper, polarity)) {
            PlatformAction::Step(direction) => plant.pulse(direction),
            PlatformAction::Wait => {}
            PlatformAction::Finished(_) | PlatformAction::Failed(_) => {
                return (routine.report(&plant.driver).expect("finished"), tick as f64 / 1000.0);
            }
        }
    }
    panic!("the travel measurement never finished");
}
