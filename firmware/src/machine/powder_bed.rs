//! The powder-bed retrofit (SPEC §5) as a machine the executor runs: its
//! G-code and its 1 kHz duties. Compiled with the `powder-bed` feature; a
//! board makes its machine the powder bed with
//! [`Machine::become_powder_bed`] at boot (host builds keep every machine,
//! so hal-sim runs this one beside the printers).
//!
//! Once a millisecond the board reads the switches, the carriage's end
//! sensors and its encoder count ([`BedInputs`]), calls
//! [`Machine::powder_bed_tick`], and drives what comes back
//! ([`BedOutputs`]): at most one platform step, the carriage H-bridge's
//! duty, roller and suction. The routines are the core's state machines
//! (`machines::powder_bed`); this module runs the job they belong to:
//!
//! | command | job | reply |
//! |---|---|---|
//! | `G0`/`G1 X Y [F]` | the carriage's X and Y servo axes to a point, on a straight line at the feed (the print pass's moves, Slic3r's G-code: "our one firmware does both", SPEC §5) | |
//! | `M880 [F] [B]` | travel measurement of the feed and/or build platform (none named: both) | `echo:Feed platform travel 40000 steps 200.000 mm` |
//! | `M881 [L<mm>] [N<layers>]` | layer cycles (default 0.1 mm, 1 layer) | `echo:Layer 1 done` per layer |
//! | `M882 S0` / `S1` | carriage to C− / C+ | `echo:Carriage at C+` |
//! | `M821 [P<kp>] [I<ki>] [D<kd>]` | the carriage's servo PID gains (duty per count, per count·s, duty·s per count; derivative on the measurement, filter Td/10); bare: report | `echo:Carriage PID Kp:2.3664 Ki:51.4427 Kd:0.0272` |
//! | `M822` | the carriage's encoder and sensors | `echo:Carriage enc:4020 at:C+ fault:none` |
//! | `M823 E<counts> [T<ms>]` | following-error limit (and how long it may be exceeded); bare: report | `echo:Carriage following error 4000 counts for 1000 ms` |
//! | `M825 [S<d>] [B<band>] [N<cycles>] [A1]` | relay auto-tune of the carriage's servo loop (SPEC §5, Åström–Hägglund, Ziegler–Nichols gains); `A1` applies them | `echo:Carriage relay d:127 a:10.00 Pu:0.200 Ku:16.1701 Kp:9.7021 Ki:97.0209 Kd:0.2426` |
//! | `M3` / `M5` | roller on / off | |
//! | `M10` / `M11` | suction on / off | |
//! | `M104`, `M109`, `M140`, `M190` | none: this machine has no heaters | `echo:M109 ignored: this machine has no heaters` |
//!
//! `M880`–`M882` block like `G28` (busy keep-alives every 2 s) and end
//! with their report and `ok`. A fault ends the job with an `Error:` line
//! (roller and suction off, carriage braked): a switch not found, a
//! carriage stroke whose sensor never trips within its length, a bridge
//! fault or a following error of the carriage's servo loop. `M112` stops
//! everything. `G2`/`G3`, `G28` and `G92` are refused; `Z`/`E` words too
//! (the platforms move only through their jobs).
//!
//! The carriage is a DC servo axis: the closed-loop module's controller
//! (servo PID from the relay rule, in [`crate::num::Native`] arithmetic)
//! follows a reference that runs toward the end at a constant speed; once
//! the end sensor reads active the reference stops a little inside the
//! sensor's zone and the axis settles there.

use super::error::CommandError;
use super::commands::{Listing, Machines};
use super::{Machine, Running};
use crate::closed_loop::control::{AxisController, DriverStatus, FollowingErrorLimit, LoopGains, Reference};
use crate::closed_loop::relay::{RelayAutotune, RelayStep};
use crate::closed_loop::tuning::{relay_ziegler_nichols, RelayGains};
use crate::reply::Fixed;
use crate::gcode::{Code, Command};
use crate::machines::powder_bed::{
    write_no_heaters, write_travel_report, CarriageEnd, LayerCommand, LayerCycle, LayerEvent, Platform, PlatformAction,
    PlatformDriver, PlatformSwitches, TravelLimits, TravelMeasurement, Vertical,
};
use crate::closed_loop::output::ActiveLevel;
use ufmt::uWrite;

/// The platforms' drivers (SPEC §5's M542 at 800 ppr, 200 steps/mm).
pub const PLATFORM: PlatformDriver = PlatformDriver::M542;
/// Reed switches: pull-up, switch to ground.
pub const SWITCH_ACTIVE: ActiveLevel = ActiveLevel::Low;
/// Carriage stroke speed, encoder counts per second (ours).
pub const STROKE_COUNTS_PER_S: i32 = 2_000;
/// A stroke gives up this far from its start without its sensor.
pub const MAX_STROKE_COUNTS: i32 = 4_800;
/// Where the carriage stops past the sensor's edge, counts.
const HOLD_INSIDE_COUNTS: i32 = 20;
/// Ticks the carriage settles at its stop before the stroke counts as done.
const SETTLE_TICKS: u16 = 300;
/// The carriage's loop period (the board's 1 kHz tick).
const CARRIAGE_TICK_S: f32 = 0.001;
/// The relay experiment's time limit, ticks (20 s).
pub const RELAY_TIMEOUT_TICKS: u32 = 20_000;
/// Carriage encoder counts per mm (ours: 200 counts per motor turn, a
/// 10 mm lead): X and Y positions in G-code are mm.
pub const CARRIAGE_COUNTS_PER_MM: i32 = 20;
/// A move counts as arrived within this many counts of its end.
const ARRIVED_COUNTS: i32 = 2;

/// What the board read this millisecond.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BedInputs {
    /// Raw pin levels (true = high) of the reed switches, lower and upper.
    pub feed_switches: (bool, bool),
    pub build_switches: (bool, bool),
    /// The carriage's end sensors, already read with their polarity.
    pub at_minus: bool,
    pub at_plus: bool,
    /// The carriage's quadrature count (X).
    pub carriage_count: i32,
    /// The H-bridge reports a fault (X).
    pub bridge_fault: bool,
    /// The carriage's Y axis: its count and its bridge's fault line.
    pub carriage_y_count: i32,
    pub bridge_y_fault: bool,
}

/// What the board drives this millisecond.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BedOutputs {
    /// One step of one platform (set DIR with `PLATFORM.dir_level`, then
    /// pulse STEP on its active edge).
    pub step: Option<(Platform, Vertical)>,
    /// The carriage H-bridge: signed duty (±255), 0 = brake.
    pub carriage_duty: i32,
    /// The Y axis' H-bridge, the same way.
    pub carriage_y_duty: i32,
    pub roller: bool,
    pub suction: bool,
    /// Platform drivers enabled (ENA at its active level).
    pub platforms_enabled: bool,
}

/// A carriage stroke in progress.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Stroke {
    to: CarriageEnd,
    /// The reference, counts × 1000 (a 1 kHz tick moves it by the speed in
    /// counts/s exactly).
    reference_milli: i32,
    goal: i32,
    /// Set once the sensor tripped: hold here, ticks left to settle.
    hold: Option<(i32, u16)>,
}

enum StrokeResult {
    Running(i32),
    Arrived,
    Failed,
}

/// The job a blocking command runs.
#[derive(Clone, Copy, Debug)]
enum Job {
    Idle,
    /// `M880`: one platform, then maybe the other.
    Travel { platform: Platform, routine: TravelMeasurement, then_build: bool },
    /// `M881`: the cycle's current command, its progress, layers to go.
    Layers { command: LayerCommand, steps_left: u32, layers_left: u16 },
    /// `M882`.
    Carriage,
    /// `G0`/`G1`: X and Y from `from` to `to` (counts) in `ticks`; then
    /// up to `settle` ticks to arrive.
    /// (`per_tick`: counts per tick on each axis, so the reference needs no
    /// 64-bit division: the AVR's is kilobytes of compiler-builtins.)
    Move { from: [i32; 2], to: [i32; 2], per_tick: [f32; 2], ticks: u32, done: u32, settle: u16 },
    /// `M825`: the relay experiment on the carriage; `apply`: `A1`.
    /// `ticks_left`: the experiment gives up after [`RELAY_TIMEOUT_TICKS`]
    /// (a motor that does not move never oscillates).
    RelayTune { tune: RelayAutotune, relay_amplitude: i32, apply: bool, ticks_left: u32 },
}

/// The powder bed's state inside the machine.
#[derive(Clone, Copy, Debug)]
pub struct BedState {
    job: Job,
    cycle: LayerCycle,
    carriage: AxisController,
    /// The carriage's Y axis (same gains as X).
    carriage_y: AxisController,
    stroke: Option<Stroke>,
    roller: bool,
    suction: bool,
    platforms_enabled: bool,
    /// What the board read at the last tick (where the carriage is when a
    /// command starts).
    last: BedInputs,
    /// The carriage loop's PID gains as set (`M821`, `M825 A1`).
    pid: RelayGains,
}

impl BedState {
    fn new() -> Self {
        let pid = relay_ziegler_nichols(127.0, 10.0, 0.05).unwrap_or(RelayGains { ku: 0.0, kp: 0.0, ki: 0.0, kd: 0.0 });
        let gains = LoopGains::servo_pid(&pid, CARRIAGE_TICK_S).unwrap_or(LoopGains::OPEN_LOOP);
        Self {
            job: Job::Idle,
            // The machine's layer settings: suction runs while the roller
            // spreads (config.rs), not only by hand (M10/M11).
            cycle: LayerCycle::new(crate::machines::config::powder_bed().layer),
            carriage: AxisController::new(gains, 255, FollowingErrorLimit { limit: 4_000, hold_ticks: 1_000 }),
            carriage_y: AxisController::new(gains, 255, FollowingErrorLimit { limit: 4_000, hold_ticks: 1_000 }),
            stroke: None,
            roller: false,
            suction: false,
            platforms_enabled: false,
            last: BedInputs { feed_switches: (true, true), build_switches: (true, true), ..BedInputs::default() },
            pid,
        }
    }

    /// Whether a blocking job is under way.
    pub fn is_busy(&self) -> bool {
        !matches!(self.job, Job::Idle)
    }

    fn start_stroke(&mut self, to: CarriageEnd, count: i32) {
        let goal = match to {
            CarriageEnd::Plus => count + MAX_STROKE_COUNTS,
            CarriageEnd::Minus => count - MAX_STROKE_COUNTS,
        };
        self.carriage.reset();
        self.stroke = Some(Stroke { to, reference_milli: count * 1000, goal, hold: None });
    }

    /// One millisecond of the stroke.
    #[inline(never)]
    fn stroke_tick(&mut self, inputs: &BedInputs) -> StrokeResult {
        let Some(mut stroke) = self.stroke else { return StrokeResult::Failed };
        let arrived = match stroke.to {
            CarriageEnd::Minus => inputs.at_minus,
            CarriageEnd::Plus => inputs.at_plus,
        };
        let position = match stroke.hold {
            Some((at, 0)) => {
                let _ = at;
                self.stroke = None;
                return StrokeResult::Arrived;
            }
            Some((at, left)) => {
                stroke.hold = Some((at, left - 1));
                at
            }
            None if arrived => {
                let at = inputs.carriage_count + if stroke.to == CarriageEnd::Plus { HOLD_INSIDE_COUNTS } else { -HOLD_INSIDE_COUNTS };
                stroke.hold = Some((at, SETTLE_TICKS));
                at
            }
            None => {
                let reference = stroke.reference_milli / 1000;
                if reference == stroke.goal {
                    // The whole stroke length and no sensor.
                    self.stroke = None;
                    return StrokeResult::Failed;
                }
                stroke.reference_milli = match stroke.to {
                    CarriageEnd::Plus => (stroke.reference_milli + STROKE_COUNTS_PER_S).min(stroke.goal * 1000),
                    CarriageEnd::Minus => (stroke.reference_milli - STROKE_COUNTS_PER_S).max(stroke.goal * 1000),
                };
                stroke.reference_milli / 1000
            }
        };
        self.stroke = Some(stroke);
        let status = DriverStatus { alarm: false, bridge_fault: inputs.bridge_fault };
        match self.carriage.tick(Reference { position, velocity: 0 }, Ok(inputs.carriage_count), status) {
            Ok(duty) => StrokeResult::Running(duty),
            Err(_) => {
                self.stroke = None;
                StrokeResult::Failed
            }
        }
    }

    /// The 16×2 screen of the powder bed (`drivers::status_screen`): the
    /// job on row 0, the layers done and the roller and suction on row 1.
    /// No temperatures: the machine has no heaters (SPEC §5).
    ///
    /// ```text
    /// Ready           | Layer 3   8 left | Travel feed
    /// Done 0  R:0 S:0 | Done 2  R:1 S:1  | Done 2  R:0 S:0
    /// ```
    pub fn screen(&self, halted: bool) -> [u8; 32] {
        use crate::drivers::status_screen::Row;
        let (mut left, mut right) = (Row::new(), Row::new());
        if halted {
            left.push_str("Halted");
        } else {
            match self.job {
                Job::Idle => left.push_str("Ready"),
                Job::Travel { platform: Platform::Feed, .. } => left.push_str("Travel feed"),
                Job::Travel { platform: Platform::Build, .. } => left.push_str("Travel build"),
                Job::Layers { layers_left, .. } => {
                    right.push_int(i32::from(layers_left) - 1).push_str(" left");
                    left.push_str("Layer ").push_int(i32::from(self.cycle.layers_done()) + 1)
                }
                Job::Carriage => left.push_str("Carriage"),
                Job::Move { .. } => left.push_str("Moving"),
                Job::RelayTune { .. } => left.push_str("Relay tune"),
            };
        }
        let mut screen = [b' '; 32];
        screen[..16].copy_from_slice(left.bytes());
        let start = 16 - right.len();
        screen[start..16].copy_from_slice(&right.bytes()[..right.len()]);
        let mut row = Row::new();
        row.push_str("Done ").push_int(i32::from(self.cycle.layers_done()));
        let flags = [b' ', b' ', b'R', b':', b'0' + u8::from(self.roller), b' ', b'S', b':', b'0' + u8::from(self.suction)];
        row.push_bytes(&flags);
        screen[16..].copy_from_slice(row.bytes());
        screen
    }

    /// Roller, suction and carriage off (a finished or failed job).
    fn all_off(&mut self) {
        self.roller = false;
        self.suction = false;
        self.stroke = None;
    }
}

/// A gain with four decimals.
fn ten_thousandths(value: f32) -> Fixed {
    Fixed { mantissa: crate::motion::math::round_to_i32(value * 10_000.0), digits: 4 }
}

/// The end sensor that reads active now.
fn carriage_at(inputs: &BedInputs) -> Option<CarriageEnd> {
    match (inputs.at_minus, inputs.at_plus) {
        (true, false) => Some(CarriageEnd::Minus),
        (false, true) => Some(CarriageEnd::Plus),
        _ => None,
    }
}

fn switches(inputs: &BedInputs, platform: Platform) -> PlatformSwitches {
    let (lower, upper) = match platform {
        Platform::Feed => inputs.feed_switches,
        Platform::Build => inputs.build_switches,
    };
    PlatformSwitches::from_levels(lower, upper, SWITCH_ACTIVE)
}

/// The powder bed's own codes (dispatched by `Machine::bed_command`; see
/// [`super::commands`]). The printers' codes it runs its own way (`G0`/`G1`,
/// `M3`/`M5`, `M104`…) or refuses (`G2`/`G3`, `G28`, `G92`, `M17`…) are
/// the core's rows. `POWDER_BED` first: `M115` names them in row order.
pub const COMMANDS: &[Listing] = &[
    Listing::m(880).to(882).on(Machines::BED).capability("POWDER_BED"), // jobs
    Listing::m(10).to(11).on(Machines::BED), // suction on / off
    Listing::m(821).on(Machines::BED).capability("CLOSED_LOOP"), // carriage PID
    Listing::m(822).to(823).on(Machines::BED), // carriage report, following error
    Listing::m(825).on(Machines::BED), // relay auto-tune
];

impl Machine<'_> {
    /// Make this machine the powder bed (the board calls it once at boot).
    pub fn become_powder_bed(&mut self) {
        self.powder = Some(BedState::new());
    }

    /// The powder bed's state, if this machine is one.
    pub fn powder_bed(&self) -> Option<&BedState> {
        self.powder.as_ref()
    }

    /// The 1 kHz duties: one tick of the running job. Reports and faults
    /// are printed here; the command's `ok` follows at the next poll.
    #[inline(never)]
    pub fn powder_bed_tick<W: uWrite + ?Sized>(&mut self, inputs: &BedInputs, out: &mut W) -> Result<BedOutputs, W::Error> {
        let halted = self.halted;
        let Some(bed) = self.powder.as_mut() else { return Ok(BedOutputs::default()) };
        if halted {
            bed.job = Job::Idle;
            bed.all_off();
            bed.platforms_enabled = false;
            return Ok(BedOutputs::default());
        }
        bed.last = *inputs;
        let mut outputs = BedOutputs::default();
        match bed.job {
            Job::Idle => {}
            Job::Move { from, to, per_tick, ticks, done, settle } => {
                let done = (done + 1).min(ticks);
                let at = |axis: usize| {
                    if done == ticks {
                        to[axis]
                    } else {
                        from[axis] + crate::motion::math::round_to_i32(per_tick[axis] * done as f32)
                    }
                };
                let x = bed.carriage.tick(Reference { position: at(0), velocity: 0 }, Ok(inputs.carriage_count), DriverStatus { alarm: false, bridge_fault: inputs.bridge_fault });
                let y = bed.carriage_y.tick(Reference { position: at(1), velocity: 0 }, Ok(inputs.carriage_y_count), DriverStatus { alarm: false, bridge_fault: inputs.bridge_y_fault });
                match (x, y) {
                    (Ok(x), Ok(y)) => {
                        outputs.carriage_duty = x;
                        outputs.carriage_y_duty = y;
                        let arrived = (inputs.carriage_count - to[0]).abs() <= ARRIVED_COUNTS && (inputs.carriage_y_count - to[1]).abs() <= ARRIVED_COUNTS;
                        bed.job = if done < ticks {
                            Job::Move { from, to, per_tick, ticks, done, settle }
                        } else if arrived || settle == 0 {
                            Job::Idle
                        } else {
                            Job::Move { from, to, per_tick, ticks, done, settle: settle - 1 }
                        };
                    }
                    _ => {
                        crate::flash_str!("Error:Carriage servo fault (following error or bridge): move stopped\n").write_to(out)?;
                        bed.all_off();
                        bed.job = Job::Idle;
                    }
                }
            }
            Job::Travel { platform, mut routine, then_build } => match routine.tick(&TravelLimits::DEFAULT, switches(inputs, platform)) {
                PlatformAction::Step(direction) => {
                    outputs.step = Some((platform, direction));
                    bed.job = Job::Travel { platform, routine, then_build };
                }
                PlatformAction::Wait => bed.job = Job::Travel { platform, routine, then_build },
                PlatformAction::Finished(_) | PlatformAction::Failed(_) => {
                    if let Some(result) = routine.report(&PLATFORM) {
                        write_travel_report(platform, result, out)?;
                    }
                    bed.job = if then_build {
                        Job::Travel { platform: Platform::Build, routine: TravelMeasurement::new(), then_build: false }
                    } else {
                        Job::Idle
                    };
                }
            },
            Job::RelayTune { mut tune, relay_amplitude, apply, ticks_left } => match tune.tick(inputs.carriage_count) {
                RelayStep::Output(duty) if ticks_left > 0 && !inputs.bridge_fault => {
                    outputs.carriage_duty = duty;
                    bed.job = Job::RelayTune { tune, relay_amplitude, apply, ticks_left: ticks_left - 1 };
                }
                RelayStep::Output(_) => {
                    bed.job = Job::Idle;
                    if inputs.bridge_fault {
                        crate::flash_str!("Error:Carriage relay tune stopped: bridge fault\n").write_to(out)?;
                    } else {
                        crate::flash_str!("Error:Carriage relay tune failed (no steady oscillation)\n").write_to(out)?;
                    }
                }
                RelayStep::Done(result) => {
                    bed.job = Job::Idle;
                    bed.finish_relay(result, apply, out)?;
                }
                RelayStep::Failed => {
                    bed.job = Job::Idle;
                    crate::flash_str!("Error:Carriage relay tune failed (no steady oscillation)\n").write_to(out)?;
                }
            },
            Job::Carriage => match bed.stroke_tick(inputs) {
                StrokeResult::Running(duty) => outputs.carriage_duty = duty,
                StrokeResult::Arrived => {
                    let end = if inputs.at_plus { "+" } else { "-" };
                    crate::flash_str!("echo:Carriage at C").write_to(out)?;
                    out.write_str(end)?;
                    out.write_str("\n")?;
                    bed.job = Job::Idle;
                }
                StrokeResult::Failed => {
                    crate::flash_str!("Error:Carriage stroke failed (sensor not reached or servo fault)\n").write_to(out)?;
                    bed.all_off();
                    bed.job = Job::Idle;
                }
            },
            Job::Layers { command, steps_left, layers_left } => {
                let (next, steps_left) = match command {
                    LayerCommand::Roller(on) => {
                        bed.roller = on;
                        (bed.cycle.on_event(LayerEvent::Done), 0)
                    }
                    LayerCommand::Suction(on) => {
                        bed.suction = on;
                        (bed.cycle.on_event(LayerEvent::Done), 0)
                    }
                    LayerCommand::MoveCarriage { to, .. } => {
                        if bed.stroke.is_none() {
                            bed.start_stroke(to, inputs.carriage_count);
                        }
                        match bed.stroke_tick(inputs) {
                            StrokeResult::Running(duty) => {
                                outputs.carriage_duty = duty;
                                (command, 0)
                            }
                            StrokeResult::Arrived => (bed.cycle.on_event(LayerEvent::CarriageArrived(to)), 0),
                            StrokeResult::Failed => (bed.cycle.on_event(LayerEvent::Failed), 0),
                        }
                    }
                    LayerCommand::StepPlatform { platform, direction, steps } => {
                        // A fresh command starts with its full count.
                        let left = if steps_left == 0 { steps } else { steps_left };
                        if left == 0 {
                            (bed.cycle.on_event(LayerEvent::Done), 0)
                        } else {
                            outputs.step = Some((platform, direction));
                            if left == 1 {
                                (bed.cycle.on_event(LayerEvent::Done), 0)
                            } else {
                                (command, left - 1)
                            }
                        }
                    }
                    LayerCommand::Finished { layer } => {
                        crate::flash_str!("echo:Layer ").write_to(out)?;
                        ufmt::uwrite!(out, "{}", layer)?;
                        crate::flash_str!(" done\n").write_to(out)?;
                        if layers_left > 1 {
                            bed.job = Job::Layers {
                                command: bed.cycle.start(&PLATFORM, &PLATFORM, carriage_at(inputs)),
                                steps_left: 0,
                                layers_left: layers_left - 1,
                            };
                        } else {
                            bed.job = Job::Idle;
                        }
                        return Ok(bed.outputs(outputs));
                    }
                    LayerCommand::Aborted(_) => {
                        crate::flash_str!("Error:Layer cycle aborted\n").write_to(out)?;
                        bed.all_off();
                        bed.job = Job::Idle;
                        return Ok(bed.outputs(outputs));
                    }
                };
                bed.job = Job::Layers { command: next, steps_left, layers_left };
            }
        }
        Ok(bed.outputs(outputs))
    }

    /// The powder bed's commands; `None` for a command it leaves to the
    /// executor (reports, settings, `M112`).
    #[inline(never)]
    pub(super) fn bed_command<W: uWrite + ?Sized>(&mut self, command: &Command, out: &mut W) -> Result<Option<Result<Option<Running>, CommandError>>, W::Error> {
        if self.powder.is_none() {
            return Ok(None);
        }
        if matches!(command.code, Code::G(0 | 1) | Code::Modal) {
            return Ok(Some(self.carriage_move(command)));
        }
        let Some(bed) = self.powder.as_mut() else { return Ok(None) };
        let result = match command.code {
            // No planner moves; the platform drivers are the jobs' own.
            Code::G(2 | 3 | 28 | 92) | Code::M(17 | 18 | 84) => Err(CommandError::NotThisMachine),
            Code::M(code @ (104 | 109 | 140 | 190)) => {
                write_no_heaters(code, out)?;
                Ok(None)
            }
            Code::M(3 | 5) => {
                bed.roller = command.code == Code::M(3);
                Ok(None)
            }
            Code::M(10 | 11) => {
                bed.suction = command.code == Code::M(10);
                Ok(None)
            }
            Code::M(880) => {
                let (feed, build) = match (command.has(b'F'), command.has(b'B')) {
                    (false, false) => (true, true),
                    named => named,
                };
                let platform = if feed { Platform::Feed } else { Platform::Build };
                bed.platforms_enabled = true;
                bed.job = Job::Travel { platform, routine: TravelMeasurement::new(), then_build: feed && build };
                Ok(Some(Running::BedJob))
            }
            Code::M(881) => (|| {
                let mut settings = bed.cycle.settings();
                if let Some(mm) = command.value(b'L')? {
                    settings.thickness_um = mm.to_scaled(3).and_then(|um| u32::try_from(um).ok()).filter(|um| (1..=2_000).contains(um)).ok_or(CommandError::OutOfRange(b'L'))?;
                }
                let layers = match command.value(b'N')? {
                    Some(n) => n.to_int().and_then(|n| u16::try_from(n).ok()).filter(|n| *n >= 1).ok_or(CommandError::OutOfRange(b'N'))?,
                    None => 1,
                };
                bed.cycle.set_settings(settings);
                bed.platforms_enabled = true;
                let command = bed.cycle.start(&PLATFORM, &PLATFORM, carriage_at(&bed.last));
                bed.job = Job::Layers { command, steps_left: 0, layers_left: layers };
                Ok(Some(Running::BedJob))
            })(),
            Code::M(882) => match command.value(b'S').map(|s| s.and_then(|s| s.to_int())) {
                Err(error) => Err(error.into()),
                Ok(Some(end @ (0 | 1))) => {
                    let to = if end == 0 { CarriageEnd::Minus } else { CarriageEnd::Plus };
                    let count = bed.last.carriage_count;
                    bed.start_stroke(to, count);
                    bed.job = Job::Carriage;
                    Ok(Some(Running::BedJob))
                }
                Ok(_) => Err(CommandError::OutOfRange(b'S')),
            },
            Code::M(821) => (|| {
                let read = |letter, now: f32| -> Result<f32, CommandError> {
                    match command.value(letter)? {
                        None => Ok(now),
                        Some(value) => value.to_scaled(4).filter(|v| *v >= 0).map(|v| v as f32 / 10_000.0).ok_or(CommandError::OutOfRange(letter)),
                    }
                };
                if command.has(b'P') || command.has(b'I') || command.has(b'D') {
                    let pid = RelayGains { ku: bed.pid.ku, kp: read(b'P', bed.pid.kp)?, ki: read(b'I', bed.pid.ki)?, kd: read(b'D', bed.pid.kd)? };
                    bed.set_pid(pid)?;
                }
                Ok(None)
            })()
            .inspect(|_| {
                let _ = bed.write_pid(out);
            }),
            Code::M(822) => {
                let last = bed.last;
                crate::flash_str!("echo:Carriage enc:").write_to(out)?;
                ufmt::uwrite!(out, "{}", last.carriage_count)?;
                crate::flash_str!(" at:").write_to(out)?;
                out.write_str(match carriage_at(&last) {
                    Some(CarriageEnd::Minus) => "C-",
                    Some(CarriageEnd::Plus) => "C+",
                    None => "-",
                })?;
                crate::flash_str!(" fault:").write_to(out)?;
                out.write_str(if last.bridge_fault { "bridge\n" } else { "none\n" })?;
                Ok(None)
            }
            Code::M(823) => (|| {
                let mut limit = bed.carriage.following_error();
                if let Some(counts) = command.value(b'E')? {
                    limit.limit = counts.to_int().filter(|c| (1..=1_000_000).contains(c)).ok_or(CommandError::OutOfRange(b'E'))?;
                }
                if let Some(ms) = command.value(b'T')? {
                    limit.hold_ticks = ms.to_int().and_then(|t| u16::try_from(t).ok()).ok_or(CommandError::OutOfRange(b'T'))?;
                }
                bed.carriage.set_following_error(limit);
                Ok(None)
            })()
            .inspect(|_| {
                let limit = bed.carriage.following_error();
                let _ = crate::flash_str!("echo:Carriage following error ").write_to(out);
                let _ = ufmt::uwrite!(out, "{}", limit.limit);
                let _ = crate::flash_str!(" counts for ").write_to(out);
                let _ = ufmt::uwrite!(out, "{} ms\n", limit.hold_ticks);
            }),
            Code::M(825) => (|| {
                let word = |letter, default: i32, range: core::ops::RangeInclusive<i32>| -> Result<i32, CommandError> {
                    match command.value(letter)? {
                        None => Ok(default),
                        Some(value) => value.to_int().filter(|v| range.contains(v)).ok_or(CommandError::OutOfRange(letter)),
                    }
                };
                let relay_amplitude = word(b'S', 127, 10..=255)?;
                let band = word(b'B', 5, 1..=500)?;
                let cycles = word(b'N', 10, 3..=50)?;
                let apply = word(b'A', 0, 0..=1)? == 1;
                let setpoint = bed.last.carriage_count;
                bed.stroke = None;
                let tune = RelayAutotune::new(setpoint, relay_amplitude, 0, band, MAX_STROKE_COUNTS, cycles as u8);
                bed.job = Job::RelayTune { tune, relay_amplitude, apply, ticks_left: RELAY_TIMEOUT_TICKS };
                Ok(Some(Running::BedJob))
            })(),
            _ => return Ok(None),
        };
        Ok(Some(result))
    }

    /// `G0`/`G1 X Y [F]`: the carriage's servo axes on a straight line at
    /// the feed (µm targets from the modal state: units, G90/G91, G92 and
    /// work offsets as for any machine).
    #[inline(never)]
    fn carriage_move(&mut self, command: &Command) -> Result<Option<Running>, CommandError> {
        if command.has(b'Z') || command.has(b'E') {
            return Err(CommandError::NotThisMachine);
        }
        let feed = self.modal.read_feed(command)?;
        let target = self.modal.target(command)?;
        if let Some(feed) = feed {
            self.modal.feed_um_per_s = feed;
        }
        let um_to_counts = |um: i32| (i64::from(um) * i64::from(CARRIAGE_COUNTS_PER_MM) / 1000) as i32;
        let Some(bed) = self.powder.as_mut() else { return Err(CommandError::NotThisMachine) };
        let from = [bed.last.carriage_count, bed.last.carriage_y_count];
        let to = [um_to_counts(target[0]), um_to_counts(target[1])];
        let (dx, dy) = ((to[0] - from[0]) as f32, (to[1] - from[1]) as f32);
        let length_counts = crate::motion::math::sqrt(dx * dx + dy * dy);
        let counts_per_s = self.modal.feed_um_per_s as f32 * CARRIAGE_COUNTS_PER_MM as f32 / 1000.0;
        let ticks = if counts_per_s > 0.0 { (length_counts / counts_per_s * 1000.0) as u32 } else { 0 };
        bed.stroke = None;
        bed.carriage.reset();
        bed.carriage_y.reset();
        let ticks = ticks.max(1);
        let per_tick = [dx / ticks as f32, dy / ticks as f32];
        bed.job = Job::Move { from, to, per_tick, ticks, done: 0, settle: SETTLE_TICKS };
        self.modal.position[0] = target[0];
        self.modal.position[1] = target[1];
        Ok(Some(Running::BedJob))
    }

    /// Whether the powder bed's job is over (for `Running::BedJob`).
    pub(super) fn bed_job_done(&self) -> bool {
        self.powder.as_ref().is_none_or(|bed| !bed.is_busy())
    }
}

impl BedState {
    /// The relay experiment's result: the report, and with `A1` the
    /// carriage loop's new gains (servo PID, derivative on the measurement).
    fn finish_relay<W: uWrite + ?Sized>(&mut self, result: crate::closed_loop::relay::RelayResult, apply: bool, out: &mut W) -> Result<(), W::Error> {
        let period_s = result.period_ticks as f32 * CARRIAGE_TICK_S;
        let Ok(gains) = relay_ziegler_nichols(result.relay_amplitude as f32, result.oscillation_amplitude as f32, period_s) else {
            return crate::flash_str!("Error:Carriage relay tune failed (no oscillation)\n").write_to(out);
        };
        // Label by label from flash: this build's RAM is nearly full.
        crate::flash_str!("echo:Carriage relay d:").write_to(out)?;
        ufmt::uwrite!(out, "{}", result.relay_amplitude)?;
        for (label, value) in [
            (crate::flash_str!(" a:"), Fixed::hundredths(result.oscillation_amplitude * 100)),
            (crate::flash_str!(" Pu:"), Fixed { mantissa: result.period_ticks as i32, digits: 3 }),
            (crate::flash_str!(" Ku:"), ten_thousandths(gains.ku)),
            (crate::flash_str!(" Kp:"), ten_thousandths(gains.kp)),
            (crate::flash_str!(" Ki:"), ten_thousandths(gains.ki)),
            (crate::flash_str!(" Kd:"), ten_thousandths(gains.kd)),
        ] {
            label.write_to(out)?;
            ufmt::uwrite!(out, "{}", value)?;
        }
        out.write_str("\n")?;
        if apply && self.set_pid(gains).is_err() {
            crate::flash_str!("Error:Carriage gains out of range, not applied\n").write_to(out)?;
        }
        Ok(())
    }

    /// New PID gains for the carriage loop (its memory restarts).
    fn set_pid(&mut self, pid: RelayGains) -> Result<(), CommandError> {
        let loop_gains = LoopGains::servo_pid(&pid, CARRIAGE_TICK_S).map_err(|_| CommandError::OutOfRange(b'P'))?;
        self.carriage.set_gains(loop_gains);
        self.pid = pid;
        Ok(())
    }

    /// `echo:Carriage PID Kp:… Ki:… Kd:…`
    fn write_pid<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        crate::flash_str!("echo:Carriage PID").write_to(out)?;
        for (label, value) in [(crate::flash_str!(" Kp:"), self.pid.kp), (crate::flash_str!(" Ki:"), self.pid.ki), (crate::flash_str!(" Kd:"), self.pid.kd)] {
            label.write_to(out)?;
            ufmt::uwrite!(out, "{}", ten_thousandths(value))?;
        }
        out.write_str("\n")
    }

    fn outputs(&self, mut outputs: BedOutputs) -> BedOutputs {
        outputs.roller = self.roller;
        outputs.suction = self.suction;
        outputs.platforms_enabled = self.platforms_enabled;
        outputs
    }
}
