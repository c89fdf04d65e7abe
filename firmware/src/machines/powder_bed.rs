//! The powder-bed retrofit (SPEC §5): two platforms on M542-driven
//! steppers with reed switches, a carriage on a DC servo axis with end
//! sensors C− and C+, a roller and a suction unit.
//!
//! Two routines, each a state machine that emits commands and consumes
//! what happened, so that they are tested without hardware:
//!
//! - [`TravelMeasurement`]: ticked at the platform step rate (1 kHz in the
//!   thesis, no ramp), it answers each tick with one [`PlatformAction`]
//!   (step up, step down, wait) and finally reports the travel between the
//!   lower (A) and upper (B) switch in steps and mm;
//! - [`LayerCycle`]: one layer (roller on, spread C− → C+, print pass on
//!   the way back, feed platform up one layer, build platform down one
//!   layer) as a list of [`LayerCommand`]s, each answered by a
//!   [`LayerEvent`] when done.
//!
//! This machine has no heaters: [`write_no_heaters`] is the reply to
//! `M104`/`M109`/`M140`/`M190` (never blocking).

pub use crate::closed_loop::output::ActiveLevel;

/// Which way a platform moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Vertical {
    Up,
    Down,
}

/// The two platforms.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Platform {
    /// Holds the fresh powder: rises to offer one layer.
    Feed,
    /// Holds the part: sinks by one layer after each print pass.
    Build,
}

impl Platform {
    pub fn name(self) -> &'static str {
        match self {
            Platform::Feed => "Feed",
            Platform::Build => "Build",
        }
    }
}

/// The signals of an M542 platform driver (SPEC §5): active-low enable,
/// pulse on the falling edge, DIR high = down. The board reads these to
/// drive its pins; the routines only speak of up and down.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PlatformDriver {
    /// ENA level that enables the driver.
    pub enable_active: ActiveLevel,
    /// The STEP edge that makes a step. `Low`: idle high, a step is a
    /// high → low edge (then back high after the pulse width).
    pub step_active: ActiveLevel,
    /// DIR level that moves the platform down.
    pub dir_down: ActiveLevel,
    /// Pulses per motor revolution set on the driver's switches (800).
    pub pulses_per_rev: u16,
    /// Platform steps per metre of travel (steps/mm × 1000: fractional
    /// leads are exact to 1/1000 step/mm).
    pub steps_per_m: u32,
}

impl PlatformDriver {
    /// SPEC §5's M542 at 800 ppr. The lead-screw pitch is not in the
    /// thesis: 4 mm per turn (200 steps/mm) is ours, configuration.
    pub const M542: PlatformDriver = PlatformDriver {
        enable_active: ActiveLevel::Low,
        step_active: ActiveLevel::Low,
        dir_down: ActiveLevel::High,
        pulses_per_rev: 800,
        steps_per_m: 200_000,
    };

    /// The DIR pin level for a direction (true = high).
    pub fn dir_level(&self, direction: Vertical) -> bool {
        let down_high = self.dir_down == ActiveLevel::High;
        match direction {
            Vertical::Down => down_high,
            Vertical::Up => !down_high,
        }
    }

    /// The STEP pin's idle level (true = high); a step drives it to the
    /// other level for the pulse width, then back.
    pub fn step_idle_level(&self) -> bool {
        self.step_active == ActiveLevel::Low
    }

    /// The ENA level for enabled / disabled.
    pub fn enable_level(&self, enabled: bool) -> bool {
        (self.enable_active == ActiveLevel::High) == enabled
    }

    /// Steps → µm (rounded), 32-bit only: `steps ≤ 4 294 967` and
    /// `steps_per_m ≤ 4 294 967` (4294 steps/mm) keep every product in range.
    pub fn steps_to_um(&self, steps: u32) -> u32 {
        let per_m = self.steps_per_m.clamp(1, 4_294_967);
        let steps = steps.min(4_294_967);
        let whole_mm = steps * 1000 / per_m;
        let remainder = steps * 1000 % per_m;
        whole_mm * 1000 + (remainder * 1000 + per_m / 2) / per_m
    }
}

/// The two reed switches of one platform, already read with their polarity
/// (true = the magnet is at the switch).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PlatformSwitches {
    /// A, the lower switch.
    pub lower: bool,
    /// B, the upper switch.
    pub upper: bool,
}

impl PlatformSwitches {
    /// From the raw pin levels (true = high) and the configured polarity
    /// (the Hamlin 59085 wiring of the thesis contradicts itself).
    pub fn from_levels(lower_high: bool, upper_high: bool, active: ActiveLevel) -> Self {
        Self { lower: active.is_asserted(lower_high), upper: active.is_asserted(upper_high) }
    }
}

/// Limits of the travel measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TravelLimits {
    /// Most steps toward a switch before it counts as missing (a bit more
    /// than the longest travel the machine has).
    pub max_steps: u32,
    /// Most steps up to get off the lower switch when starting on it.
    pub max_backoff_steps: u32,
    /// Ticks to stand still at the zero (the thesis paused there).
    pub pause_ticks: u16,
    /// Consecutive equal readings before a switch change counts (reed
    /// contacts bounce); the platform does not step while one is pending.
    pub debounce_ticks: u8,
}

impl TravelLimits {
    /// 300 mm at 200 steps/mm, 10 mm of back-off, the thesis' 2 s pause at
    /// the zero (2 000 ticks at 1 kHz: the platform settles on its lower
    /// switch before the count starts), three readings (ours).
    pub const DEFAULT: TravelLimits = TravelLimits { max_steps: 60_000, max_backoff_steps: 2_000, pause_ticks: 2_000, debounce_ticks: 3 };
}

/// What the board does this tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlatformAction {
    /// One step (set DIR first, then one STEP pulse).
    Step(Vertical),
    /// Stand still this tick (pausing, or confirming a switch).
    Wait,
    /// The routine is over; ticking again repeats this.
    Finished(TravelReport),
    /// The routine stopped; disable nothing else, report the fault.
    Failed(TravelFault),
}

/// The measured travel between the lower switch (zero, as reached from
/// above) and the upper switch (as reached from below).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TravelReport {
    pub steps: u32,
    pub um: u32,
}

/// Why the travel measurement stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TravelFault {
    /// `max_steps` down without reaching A: switch missing, unplugged or
    /// wrong polarity.
    LowerSwitchNotFound,
    /// `max_steps` up from the zero without reaching B.
    UpperSwitchNotFound,
    /// Started on A and `max_backoff_steps` up did not release it: the
    /// switch reads active everywhere (polarity, short).
    LowerSwitchStuck,
    /// A and B both active: polarity or wiring.
    BothSwitchesActive,
}

impl TravelFault {
    pub fn message(self) -> &'static str {
        match self {
            TravelFault::LowerSwitchNotFound => "lower switch (A) not found",
            TravelFault::UpperSwitchNotFound => "upper switch (B) not found",
            TravelFault::LowerSwitchStuck => "lower switch (A) never releases",
            TravelFault::BothSwitchesActive => "both switches active (check polarity)",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TravelPhase {
    /// Starting on A: step up until A releases.
    BackOff,
    /// Step down until A.
    SeekLower,
    /// Zeroed on A: stand still.
    Pause,
    /// Step up until B, counting.
    SeekUpper,
    Finished(TravelReport),
    Failed(TravelFault),
}

/// The travel measurement of one platform (SPEC §5), ≈ 16 bytes: step down
/// to A (starting on A, first step up until it releases, so that the zero
/// is always A's edge as approached from above), zero, pause, step up to B
/// counting steps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TravelMeasurement {
    phase: TravelPhase,
    /// Steps (or pause ticks) in this phase.
    count: u32,
    /// Consecutive readings that differ from the phase's expectation.
    confirm: u8,
    started: bool,
}

impl Default for TravelMeasurement {
    fn default() -> Self {
        Self::new()
    }
}

impl TravelMeasurement {
    pub const fn new() -> Self {
        Self { phase: TravelPhase::SeekLower, count: 0, confirm: 0, started: false }
    }

    /// One tick at the step rate, with the switches as read now.
    pub fn tick(&mut self, limits: &TravelLimits, switches: PlatformSwitches) -> PlatformAction {
        if let TravelPhase::Finished(report) = self.phase {
            return PlatformAction::Finished(report);
        }
        if let TravelPhase::Failed(fault) = self.phase {
            return PlatformAction::Failed(fault);
        }
        if switches.lower && switches.upper {
            return self.fail(TravelFault::BothSwitchesActive);
        }
        if !self.started {
            self.started = true;
            if switches.lower {
                self.enter(TravelPhase::BackOff);
            }
        }
        match self.phase {
            TravelPhase::BackOff => {
                // Step up until A reads released `debounce` times in a row.
                if !switches.lower {
                    if self.confirmed(limits) {
                        self.enter(TravelPhase::SeekLower);
                        return PlatformAction::Wait;
                    }
                    return PlatformAction::Wait;
                }
                self.confirm = 0;
                if self.count >= limits.max_backoff_steps {
                    return self.fail(TravelFault::LowerSwitchStuck);
                }
                self.count += 1;
                PlatformAction::Step(Vertical::Up)
            }
            TravelPhase::SeekLower => {
                if switches.lower {
                    if self.confirmed(limits) {
                        self.enter(TravelPhase::Pause);
                    }
                    return PlatformAction::Wait;
                }
                self.confirm = 0;
                if self.count >= limits.max_steps {
                    return self.fail(TravelFault::LowerSwitchNotFound);
                }
                self.count += 1;
                PlatformAction::Step(Vertical::Down)
            }
            TravelPhase::Pause => {
                if self.count >= u32::from(limits.pause_ticks) {
                    self.enter(TravelPhase::SeekUpper);
                } else {
                    self.count += 1;
                    return PlatformAction::Wait;
                }
                self.tick(limits, switches)
            }
            TravelPhase::SeekUpper => {
                if switches.upper {
                    if self.confirmed(limits) {
                        let steps = self.count;
                        self.phase = TravelPhase::Finished(TravelReport { steps, um: 0 });
                        return PlatformAction::Wait;
                    }
                    return PlatformAction::Wait;
                }
                self.confirm = 0;
                if self.count >= limits.max_steps {
                    return self.fail(TravelFault::UpperSwitchNotFound);
                }
                self.count += 1;
                PlatformAction::Step(Vertical::Up)
            }
            TravelPhase::Finished(_) | TravelPhase::Failed(_) => PlatformAction::Wait,
        }
    }

    /// The result, with the mm figure from the driver's steps/m.
    pub fn report(&self, driver: &PlatformDriver) -> Option<Result<TravelReport, TravelFault>> {
        match self.phase {
            TravelPhase::Finished(report) => Some(Ok(TravelReport { steps: report.steps, um: driver.steps_to_um(report.steps) })),
            TravelPhase::Failed(fault) => Some(Err(fault)),
            _ => None,
        }
    }

    /// Steps counted in the current phase (up from zero while seeking B).
    pub fn steps_in_phase(&self) -> u32 {
        self.count
    }

    fn confirmed(&mut self, limits: &TravelLimits) -> bool {
        self.confirm = self.confirm.saturating_add(1);
        self.confirm >= limits.debounce_ticks.max(1)
    }

    fn enter(&mut self, phase: TravelPhase) {
        self.phase = phase;
        self.count = 0;
        self.confirm = 0;
    }

    fn fail(&mut self, fault: TravelFault) -> PlatformAction {
        self.phase = TravelPhase::Failed(fault);
        PlatformAction::Failed(fault)
    }
}

/// `echo:Feed platform travel 40000 steps 200.000 mm` (or the fault as
/// `Error:Feed platform travel: lower switch (A) not found`).
pub fn write_travel_report<W: ufmt::uWrite + ?Sized>(
    platform: Platform,
    result: Result<TravelReport, TravelFault>,
    out: &mut W,
) -> Result<(), W::Error> {
    match result {
        Ok(report) => {
            ufmt::uwrite!(out, "echo:{}", platform.name())?;
            crate::flash_str!(" platform travel ").write_to(out)?;
            ufmt::uwrite!(out, "{}", report.steps)?;
            crate::flash_str!(" steps ").write_to(out)?;
            write_um_as_mm(report.um as i32, out)?;
            out.write_str(" mm\n")
        }
        Err(fault) => {
            ufmt::uwrite!(out, "Error:{}", platform.name())?;
            crate::flash_str!(" platform travel: ").write_to(out)?;
            out.write_str(fault.message())?;
            out.write_str("\n")
        }
    }
}

/// µm as mm with three decimals.
pub fn write_um_as_mm<W: ufmt::uWrite + ?Sized>(um: i32, out: &mut W) -> Result<(), W::Error> {
    if um < 0 {
        out.write_str("-")?;
    }
    let magnitude = um.unsigned_abs();
    let fraction = magnitude % 1000;
    ufmt::uwrite!(out, "{}.", magnitude / 1000)?;
    if fraction < 100 {
        out.write_str("0")?;
    }
    if fraction < 10 {
        out.write_str("0")?;
    }
    ufmt::uwrite!(out, "{}", fraction)
}

// ------------------------------------------------------------------ layers

/// The carriage's two ends, each with a sensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CarriageEnd {
    /// C−: the parking end, where a layer starts.
    Minus,
    /// C+: the far end of the spreading stroke.
    Plus,
}

/// One thing for the executor to do; answer with a [`LayerEvent`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerCommand {
    /// Roller motor on/off. Answer [`LayerEvent::Done`].
    Roller(bool),
    /// Suction unit on/off. Answer [`LayerEvent::Done`].
    Suction(bool),
    /// Drive the carriage (DC servo axis) toward `to` until its end sensor
    /// trips. `print_pass`: this stroke is the print pass (the print head,
    /// outside the thesis, may act during it). Answer
    /// [`LayerEvent::CarriageArrived`].
    MoveCarriage { to: CarriageEnd, print_pass: bool },
    /// Step one platform (see [`PlatformDriver`]). Answer [`LayerEvent::Done`].
    StepPlatform { platform: Platform, direction: Vertical, steps: u32 },
    /// The layer is done: nothing more to do.
    Finished { layer: u16 },
    /// The cycle stopped: turn the roller and the suction off and stop the
    /// carriage and the platforms. Nothing more follows.
    Aborted(LayerFault),
}

/// What the executor reports back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerEvent {
    /// The last output or platform command is complete.
    Done,
    /// The carriage reached an end sensor.
    CarriageArrived(CarriageEnd),
    /// The last command failed (bridge fault, following error, timeout,
    /// `M112`/`M410`).
    Failed,
}

/// Why a layer cycle stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerFault {
    /// The executor reported [`LayerEvent::Failed`] while this step ran.
    StepFailed(LayerStep),
    /// An event that does not answer the command (e.g. the carriage
    /// arrived at the wrong end).
    Unexpected(LayerStep),
}

/// The steps of a layer, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerStep {
    /// The carriage was not at C−: return there first (no roller).
    ReturnToStart,
    RollerOn,
    SuctionOn,
    /// C− → C+ with the roller turning.
    Spread,
    RollerOff,
    SuctionOff,
    /// C+ → C−: the print pass.
    PrintPass,
    FeedUp,
    BuildDown,
    Finished,
    Aborted,
}

/// Layer cycle settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayerSettings {
    /// Layer thickness, µm (a parameter of each cycle: `M852 L`).
    pub thickness_um: u32,
    /// Run the suction unit while spreading (ours: the thesis has it
    /// on/off only).
    pub suction_while_spreading: bool,
}

/// One layer after another (SPEC §5): roller on, spread C− → C+, roller
/// off, print pass C+ → C−, feed platform up one layer, build platform
/// down one layer. ≈ 20 bytes.
///
/// Platform steps per layer are `thickness · steps/mm`, truncated; the
/// fraction of a step is carried to the next layer per platform, so after
/// n layers each platform has moved exactly ⌊n · thickness · steps/mm⌋
/// steps (no drift).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayerCycle {
    step: LayerStep,
    settings: LayerSettings,
    layer: u16,
    feed_steps: u32,
    build_steps: u32,
    /// Carried fractions of a step, in steps/m × µm units (see [`steps_for_layer`]).
    feed_remainder: u32,
    build_remainder: u32,
}

/// Steps for one layer of `thickness_um` at `steps_per_m`, with the carried
/// remainder (in 1/10⁶ step): returns (steps, new remainder). 32-bit: the
/// product is computed as whole mm and µm parts.
pub fn steps_for_layer(thickness_um: u32, steps_per_m: u32, remainder: u32) -> (u32, u32) {
    // thickness_um · steps_per_m / 10⁶, split so no product exceeds 2^32
    // for layers ≤ 4.29 mm and ≤ 4294 steps/mm.
    let thickness_um = thickness_um.min(4_294);
    let steps_per_m = steps_per_m.min(4_294_967);
    let whole_per_m = steps_per_m / 1000; // steps/mm
    let milli = steps_per_m % 1000; // thousandths of a step per mm
    // thickness_um · whole_per_m: ≤ 4294 · 4294 < 2^25, in 1/1000 step
    let from_whole = thickness_um * whole_per_m;
    // thickness_um · milli ≤ 4294 · 999 < 2^23, in 1/10⁶ step
    let from_milli = thickness_um * milli + remainder;
    let millionths_from_milli = from_milli % 1_000_000;
    let thousandths = from_whole + from_milli / 1_000_000 * 1000;
    let steps = thousandths / 1000;
    let millionths = (thousandths % 1000) * 1000 + millionths_from_milli;
    (steps + millionths / 1_000_000, millionths % 1_000_000)
}

impl LayerCycle {
    pub const fn new(settings: LayerSettings) -> Self {
        Self { step: LayerStep::Finished, settings, layer: 0, feed_steps: 0, build_steps: 0, feed_remainder: 0, build_remainder: 0 }
    }

    /// Change the thickness (between layers).
    pub fn set_settings(&mut self, settings: LayerSettings) {
        self.settings = settings;
    }

    pub fn settings(&self) -> LayerSettings {
        self.settings
    }

    /// Start one layer. `carriage_at`: the end sensor that reads active now
    /// (`None`: somewhere between). Returns the first command.
    pub fn start(&mut self, feed: &PlatformDriver, build: &PlatformDriver, carriage_at: Option<CarriageEnd>) -> LayerCommand {
        let (feed_steps, feed_remainder) = steps_for_layer(self.settings.thickness_um, feed.steps_per_m, self.feed_remainder);
        let (build_steps, build_remainder) = steps_for_layer(self.settings.thickness_um, build.steps_per_m, self.build_remainder);
        self.feed_steps = feed_steps;
        self.build_steps = build_steps;
        self.feed_remainder = feed_remainder;
        self.build_remainder = build_remainder;
        self.step = if carriage_at == Some(CarriageEnd::Minus) { LayerStep::RollerOn } else { LayerStep::ReturnToStart };
        self.command()
    }

    /// What the current step asks for (again).
    pub fn command(&self) -> LayerCommand {
        match self.step {
            LayerStep::ReturnToStart => LayerCommand::MoveCarriage { to: CarriageEnd::Minus, print_pass: false },
            LayerStep::RollerOn => LayerCommand::Roller(true),
            LayerStep::SuctionOn => LayerCommand::Suction(true),
            LayerStep::Spread => LayerCommand::MoveCarriage { to: CarriageEnd::Plus, print_pass: false },
            LayerStep::RollerOff => LayerCommand::Roller(false),
            LayerStep::SuctionOff => LayerCommand::Suction(false),
            LayerStep::PrintPass => LayerCommand::MoveCarriage { to: CarriageEnd::Minus, print_pass: true },
            LayerStep::FeedUp => LayerCommand::StepPlatform { platform: Platform::Feed, direction: Vertical::Up, steps: self.feed_steps },
            LayerStep::BuildDown => LayerCommand::StepPlatform { platform: Platform::Build, direction: Vertical::Down, steps: self.build_steps },
            LayerStep::Finished => LayerCommand::Finished { layer: self.layer },
            LayerStep::Aborted => LayerCommand::Aborted(LayerFault::Unexpected(LayerStep::Aborted)),
        }
    }

    /// The executor's answer to the last command; returns the next one.
    pub fn on_event(&mut self, event: LayerEvent) -> LayerCommand {
        let step = self.step;
        if matches!(step, LayerStep::Finished | LayerStep::Aborted) {
            return self.command();
        }
        if event == LayerEvent::Failed {
            return self.abort(LayerFault::StepFailed(step));
        }
        let expected = match step {
            LayerStep::ReturnToStart | LayerStep::PrintPass => LayerEvent::CarriageArrived(CarriageEnd::Minus),
            LayerStep::Spread => LayerEvent::CarriageArrived(CarriageEnd::Plus),
            _ => LayerEvent::Done,
        };
        if event != expected {
            return self.abort(LayerFault::Unexpected(step));
        }
        let suction = self.settings.suction_while_spreading;
        self.step = match step {
            LayerStep::ReturnToStart => LayerStep::RollerOn,
            LayerStep::RollerOn if suction => LayerStep::SuctionOn,
            LayerStep::RollerOn | LayerStep::SuctionOn => LayerStep::Spread,
            LayerStep::Spread => LayerStep::RollerOff,
            LayerStep::RollerOff if suction => LayerStep::SuctionOff,
            LayerStep::RollerOff | LayerStep::SuctionOff => LayerStep::PrintPass,
            LayerStep::PrintPass => LayerStep::FeedUp,
            LayerStep::FeedUp => LayerStep::BuildDown,
            LayerStep::BuildDown => {
                self.layer = self.layer.wrapping_add(1);
                LayerStep::Finished
            }
            LayerStep::Finished | LayerStep::Aborted => step,
        };
        self.command()
    }

    fn abort(&mut self, fault: LayerFault) -> LayerCommand {
        self.step = LayerStep::Aborted;
        LayerCommand::Aborted(fault)
    }

    /// The step running now.
    pub fn step(&self) -> LayerStep {
        self.step
    }

    /// Layers completed.
    pub fn layers_done(&self) -> u16 {
        self.layer
    }

    /// Whether a layer is under way.
    pub fn is_busy(&self) -> bool {
        !matches!(self.step, LayerStep::Finished | LayerStep::Aborted)
    }
}

/// The reply to a heater command on a machine with none (SPEC §5):
/// `echo:M109 ignored: this machine has no heaters` (then `ok`, at once).
pub fn write_no_heaters<W: ufmt::uWrite + ?Sized>(code: u16, out: &mut W) -> Result<(), W::Error> {
    ufmt::uwrite!(out, "echo:M{}", code)?;
    crate::flash_str!(" ignored: this machine has no heaters\n").write_to(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::string::String;
    use std::vec::Vec;

    struct Out(String);
    impl ufmt::uWrite for Out {
        type Error = ();
        fn write_str(&mut self, s: &str) -> Result<(), ()> {
            self.0.push_str(s);
            Ok(())
        }
    }

    #[test]
    fn m542_signals_enable_low_step_on_the_falling_edge_dir_high_is_down() {
        let d = PlatformDriver::M542;
        assert!(!d.enable_level(true));
        assert!(d.enable_level(false));
        assert!(d.step_idle_level(), "idle high, the step is the falling edge");
        assert!(d.dir_level(Vertical::Down));
        assert!(!d.dir_level(Vertical::Up));
    }

    #[test]
    fn reed_switch_polarity_is_configuration() {
        assert_eq!(PlatformSwitches::from_levels(false, true, ActiveLevel::Low), PlatformSwitches { lower: true, upper: false });
        assert_eq!(PlatformSwitches::from_levels(false, true, ActiveLevel::High), PlatformSwitches { lower: false, upper: true });
    }

    #[test]
    fn steps_to_um_rounds_to_nearest() {
        let d = PlatformDriver::M542;
        assert_eq!(d.steps_to_um(40_000), 200_000);
        assert_eq!(d.steps_to_um(1), 5);
        let odd = PlatformDriver { steps_per_m: 266_667, ..d };
        assert_eq!(odd.steps_to_um(800), 3000);
    }

    /// A platform between two switch zones, in steps: A reads active at or
    /// below `lower`, B at or above `upper`.
    fn run(start: i32, lower: i32, upper: Option<i32>, limits: &TravelLimits) -> (Result<TravelReport, TravelFault>, i32) {
        let mut position = start;
        let mut m = TravelMeasurement::new();
        for _ in 0..1_000_000 {
            let switches = PlatformSwitches { lower: position <= lower, upper: upper.is_some_and(|u| position >= u) };
            match m.tick(limits, switches) {
                PlatformAction::Step(Vertical::Up) => position += 1,
                PlatformAction::Step(Vertical::Down) => position -= 1,
                PlatformAction::Wait => {}
                PlatformAction::Finished(_) | PlatformAction::Failed(_) => {
                    return (m.report(&PlatformDriver::M542).unwrap(), position);
                }
            }
        }
        panic!("never finished");
    }

    #[test]
    fn travel_is_counted_from_the_lower_to_the_upper_switch() {
        let (result, end) = run(5_000, 100, Some(40_100), &TravelLimits::DEFAULT);
        assert_eq!(result, Ok(TravelReport { steps: 40_000, um: 200_000 }));
        assert_eq!(end, 40_100);
    }

    #[test]
    fn starting_on_the_lower_switch_gives_the_same_travel() {
        let (result, _) = run(-50, 100, Some(40_100), &TravelLimits::DEFAULT);
        assert_eq!(result, Ok(TravelReport { steps: 40_000, um: 200_000 }));
    }

    #[test]
    fn a_missing_switch_is_a_fault_after_the_step_limit() {
        let limits = TravelLimits { max_steps: 50_000, ..TravelLimits::DEFAULT };
        assert_eq!(run(5_000, 100, None, &limits).0, Err(TravelFault::UpperSwitchNotFound));
        assert_eq!(run(5_000, -100_000, Some(40_000), &limits).0, Err(TravelFault::LowerSwitchNotFound));
        assert_eq!(run(5_000, 1_000_000, Some(2_000_000), &limits).0, Err(TravelFault::LowerSwitchStuck));
    }

    #[test]
    fn both_switches_active_is_a_fault() {
        assert_eq!(run(5_000, 10_000, Some(0), &TravelLimits::DEFAULT).0, Err(TravelFault::BothSwitchesActive));
    }

    #[test]
    fn a_bouncing_switch_is_confirmed_before_it_counts() {
        let limits = TravelLimits::DEFAULT;
        let mut m = TravelMeasurement::new();
        let off = PlatformSwitches::default();
        let on = PlatformSwitches { lower: true, upper: false };
        assert_eq!(m.tick(&limits, off), PlatformAction::Step(Vertical::Down));
        // one glitch: no step while it is pending, then stepping resumes
        assert_eq!(m.tick(&limits, on), PlatformAction::Wait);
        assert_eq!(m.tick(&limits, off), PlatformAction::Step(Vertical::Down));
        for _ in 0..3 {
            assert_eq!(m.tick(&limits, on), PlatformAction::Wait);
        }
        // zeroed: the pause runs (no steps) before seeking B
        for _ in 0..limits.pause_ticks {
            assert_eq!(m.tick(&limits, on), PlatformAction::Wait);
        }
        assert_eq!(m.tick(&limits, on), PlatformAction::Step(Vertical::Up));
    }

    #[test]
    fn travel_reports_print_in_steps_and_mm() {
        let mut out = Out(String::new());
        write_travel_report(Platform::Feed, Ok(TravelReport { steps: 40_000, um: 200_000 }), &mut out).unwrap();
        write_travel_report(Platform::Build, Ok(TravelReport { steps: 7, um: 35 }), &mut out).unwrap();
        write_travel_report(Platform::Build, Err(TravelFault::UpperSwitchNotFound), &mut out).unwrap();
        assert_eq!(
            out.0,
            "echo:Feed platform travel 40000 steps 200.000 mm\n\
             echo:Build platform travel 7 steps 0.035 mm\n\
             Error:Build platform travel: upper switch (B) not found\n"
        );
    }

    #[test]
    fn layer_steps_carry_the_fraction_so_n_layers_are_exact() {
        assert_eq!(steps_for_layer(100, 200_000, 0), (20, 0));
        // 266.667 steps/mm, 50 µm: 13.33335 steps per layer
        let mut remainder = 0;
        let mut total = 0;
        for _ in 0..300 {
            let (steps, r) = steps_for_layer(50, 266_667, remainder);
            assert!(steps == 13 || steps == 14);
            remainder = r;
            total += steps;
        }
        // 300 · 13.33335 = 4000.005
        assert_eq!(total, 4000);
    }

    fn settings(suction: bool) -> LayerSettings {
        LayerSettings { thickness_um: 100, suction_while_spreading: suction }
    }

    fn answer(command: LayerCommand) -> LayerEvent {
        match command {
            LayerCommand::MoveCarriage { to, .. } => LayerEvent::CarriageArrived(to),
            _ => LayerEvent::Done,
        }
    }

    #[test]
    fn a_layer_runs_spread_print_feed_up_build_down_in_order() {
        let d = PlatformDriver::M542;
        let mut cycle = LayerCycle::new(settings(true));
        let mut commands = Vec::new();
        let mut command = cycle.start(&d, &d, Some(CarriageEnd::Minus));
        while cycle.is_busy() {
            commands.push(command);
            command = cycle.on_event(answer(command));
        }
        assert_eq!(
            commands,
            [
                LayerCommand::Roller(true),
                LayerCommand::Suction(true),
                LayerCommand::MoveCarriage { to: CarriageEnd::Plus, print_pass: false },
                LayerCommand::Roller(false),
                LayerCommand::Suction(false),
                LayerCommand::MoveCarriage { to: CarriageEnd::Minus, print_pass: true },
                LayerCommand::StepPlatform { platform: Platform::Feed, direction: Vertical::Up, steps: 20 },
                LayerCommand::StepPlatform { platform: Platform::Build, direction: Vertical::Down, steps: 20 },
            ]
        );
        assert_eq!(command, LayerCommand::Finished { layer: 1 });
    }

    #[test]
    fn a_carriage_away_from_c_minus_returns_there_first_without_the_roller() {
        let d = PlatformDriver::M542;
        let mut cycle = LayerCycle::new(settings(false));
        let first = cycle.start(&d, &d, None);
        assert_eq!(first, LayerCommand::MoveCarriage { to: CarriageEnd::Minus, print_pass: false });
        assert_eq!(cycle.on_event(LayerEvent::CarriageArrived(CarriageEnd::Minus)), LayerCommand::Roller(true));
        assert_eq!(cycle.on_event(LayerEvent::Done), LayerCommand::MoveCarriage { to: CarriageEnd::Plus, print_pass: false });
    }

    #[test]
    fn a_failure_or_a_wrong_answer_aborts_the_layer() {
        let d = PlatformDriver::M542;
        let mut cycle = LayerCycle::new(settings(false));
        cycle.start(&d, &d, Some(CarriageEnd::Minus));
        cycle.on_event(LayerEvent::Done);
        assert_eq!(cycle.on_event(LayerEvent::Failed), LayerCommand::Aborted(LayerFault::StepFailed(LayerStep::Spread)));
        assert!(!cycle.is_busy());
        let mut cycle = LayerCycle::new(settings(false));
        cycle.start(&d, &d, Some(CarriageEnd::Minus));
        cycle.on_event(LayerEvent::Done);
        assert_eq!(
            cycle.on_event(LayerEvent::CarriageArrived(CarriageEnd::Minus)),
            LayerCommand::Aborted(LayerFault::Unexpected(LayerStep::Spread))
        );
    }

    #[test]
    fn heater_commands_get_a_clear_reply() {
        let mut out = Out(String::new());
        write_no_heaters(109, &mut out).unwrap();
        assert_eq!(out.0, "echo:M109 ignored: this machine has no heaters\n");
    }

    #[test]
    fn state_is_small() {
        assert!(core::mem::size_of::<TravelMeasurement>() <= 24);
        assert!(core::mem::size_of::<LayerCycle>() <= 32);
    }
}
