//! From the file as written ([`crate::schema`]) to a checked
//! [`Machine`]: every value in range, every pin a Mega 2560 pin used once,
//! every option one the board and the kinematics can carry. All problems
//! are collected, each as `key: problem`, so one build names them all.

use crate::pins::{self, Pin};
use crate::schema::{self, AxisSection, HeaterSection, PinValue};
use crate::thermistor::{self, Divider};
use std::collections::BTreeMap;

/// What the machine is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Moves through the planner: Cartesian, delta or arm.
    Printer,
    /// SPEC's filament extrusion line: velocity steppers and a barrel.
    ExtrusionLine,
    /// SPEC's powder-bed retrofit: platforms, a DC-servo carriage.
    PowderBed,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Kinematics {
    Cartesian,
    Delta {
        rod_length: f64,
        radius: f64,
        nozzle_offset: f64,
        tower_angles: [f64; 3],
        homed_height: f64,
        printable_radius: f64,
        segment_length: f64,
    },
    Arm {
        upper_arm: f64,
        forearm: f64,
        origin: [f64; 2],
        joint_steps_per_degree: f64,
        segment_length: f64,
        home_position: [f64; 3],
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HomeEnd {
    Min,
    Max,
    None,
}

/// One motor (X, Y, Z or E).
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    pub steps_per_mm: f64,
    pub max_feed: f64,
    pub max_acceleration: f64,
    pub invert_direction: bool,
    pub min: f64,
    pub max: f64,
    pub home: HomeEnd,
    pub homing_feed: f64,
    pub homing_backoff: f64,
    /// Farthest the axis seeks its switch before homing fails (mm, ° for
    /// arm joints).
    pub homing_travel: f64,
    /// Endstops read high when triggered.
    pub endstop_high: bool,
    pub endstop_pullup: bool,
    pub hard_limits: bool,
    pub step: Pin,
    pub dir: Pin,
    pub enable: Pin,
    pub min_endstop: Option<Pin>,
    pub max_endstop: Option<Pin>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeaterRole {
    Hotend,
    Bed,
    Barrel,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Control {
    /// Kp, Ki, Kd in Marlin's units (duty counts 0–255 per °C, per °C·s,
    /// per °C/s).
    Pid([f64; 3]),
    /// On below target − hysteresis, off above target + hysteresis (°C).
    BangBang { hysteresis: f64 },
    /// PID whose duty is a slow on/off window (solid-state relays).
    SsrWindow { pid: [f64; 3], window_ms: u16, min_slot_ms: u16 },
}

#[derive(Clone, Debug)]
pub struct Heater {
    pub role: HeaterRole,
    pub thermistor: &'static thermistor::Kind,
    pub pullup_ohms: f64,
    pub adc_channel: u8,
    pub sensor_pin: Pin,
    pub output: Pin,
    pub max_temp: f64,
    pub control: Control,
    pub runaway_period: Option<u16>,
    pub runaway_hysteresis: Option<u8>,
    pub watch_period: Option<u16>,
    pub watch_increase: Option<u8>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Motion {
    pub print_acceleration: f64,
    pub retract_acceleration: f64,
    pub travel_acceleration: f64,
    pub junction_deviation: f64,
    pub arc_tolerance: f64,
    pub max_step_rate: f64,
    /// Motor masks homed one group after another (bit 0 X, 1 Y, 2 Z).
    pub homing_groups: Vec<u8>,
    pub homing_acceleration: f64,
    pub must_home: bool,
}

/// A checked machine file.
#[derive(Clone, Debug)]
pub struct Machine {
    pub path: String,
    pub name: String,
    pub kind: Kind,
    pub baud: u32,
    pub kinematics: Kinematics,
    pub motion: Option<Motion>,
    /// X, Y, Z, E (printers only).
    pub axes: Option<[Axis; 4]>,
    pub heaters: Vec<Heater>,
    pub fan: Option<Pin>,
    pub display: bool,
    pub encoders: bool,
}

/// USART0's divisor for `baud` at 16 MHz in double-speed mode (U2X0):
/// UBRR = 16 MHz / (8 · baud) − 1, rounded; and the rate it really makes.
pub fn usart_divisor(baud: u32) -> (u16, f64) {
    let cpu_hz = 16_000_000u64;
    let ubrr = ((cpu_hz + 4 * u64::from(baud)) / (8 * u64::from(baud))).saturating_sub(1).min(4095) as u16;
    (ubrr, cpu_hz as f64 / (8.0 * (f64::from(ubrr) + 1.0)))
}

const AXIS_NAMES: [&str; 4] = ["x", "y", "z", "e"];

/// Problems found, each `key: what is wrong`.
#[derive(Default)]
struct Problems(Vec<String>);

impl Problems {
    fn add(&mut self, key: &str, problem: impl Into<String>) {
        self.0.push(format!("{key}: {}", problem.into()));
    }
}

/// Check a parsed file; `Err` lists every problem.
pub fn check(path: &str, file: schema::File, all_options: bool) -> Result<Machine, Vec<String>> {
    // An option written with `enabled = false` is described (and checked)
    // but left out, unless the build asks for every option (CI's size
    // check).
    let display_wanted = file.display.as_ref().is_some_and(|d| d.enabled || all_options);
    let encoders_wanted = file.encoders.as_ref().is_some_and(|e| e.enabled || all_options);
    let mut problems = Problems::default();
    let mut pins_used: BTreeMap<Pin, String> = BTreeMap::new();
    let mut use_pin = |problems: &mut Problems, key: String, pin: Pin| {
        if let Some(other) = pins_used.get(&pin) {
            problems.add(&key, format!("pin {pin} is already used by {other}"));
        } else {
            pins_used.insert(pin, key);
        }
    };

    let m = &file.machine;
    if m.name.trim().is_empty() || m.name.len() > 40 || !m.name.chars().all(|c| c.is_ascii_graphic() || c == ' ') {
        problems.add("machine.name", "must be 1–40 printable ASCII characters (hosts show it from M115)");
    }
    if m.board != "mega2560-ramps" {
        problems.add("machine.board", format!("\"{}\" is not a board machine files can build for (known: \"mega2560-ramps\")", m.board));
    }
    let (_, real_baud) = usart_divisor(m.baud.max(1));
    if !(2_400..=1_000_000).contains(&m.baud) || (real_baud / f64::from(m.baud) - 1.0).abs() > 0.025 {
        problems.add(
            "machine.baud",
            format!("{} baud is not a rate USART0 makes within 2.5 % at 16 MHz (115200, 250000, 500000, 57600 … are)", m.baud),
        );
    }
    let kind = match m.kind.as_str() {
        "printer" => Kind::Printer,
        "extrusion-line" => Kind::ExtrusionLine,
        "powder-bed" => Kind::PowderBed,
        other => {
            problems.add("machine.kind", format!("\"{other}\" is not a kind (\"printer\", \"extrusion-line\" or \"powder-bed\")"));
            Kind::Printer
        }
    };

    let kinematics = match (kind, &file.kinematics) {
        (Kind::Printer, None) => {
            problems.add("kinematics", "a printer needs a [kinematics] table");
            Kinematics::Cartesian
        }
        (Kind::Printer, Some(k)) => kinematics(k, &mut problems),
        (_, Some(_)) => {
            problems.add("kinematics", "only printers have kinematics (this machine drives its motors itself)");
            Kinematics::Cartesian
        }
        (_, None) => Kinematics::Cartesian,
    };

    let motion = match (kind, &file.motion) {
        (Kind::Printer, Some(section)) => Some(motion(section, &kinematics, &mut problems)),
        (Kind::Printer, None) => {
            problems.add("motion", "a printer needs a [motion] table");
            None
        }
        (_, Some(_)) => {
            problems.add("motion", "only printers plan moves: remove [motion]");
            None
        }
        (_, None) => None,
    };

    let axes: Option<[Axis; 4]> = if kind == Kind::Printer {
        let mut checked = Vec::new();
        for (index, name) in AXIS_NAMES.iter().enumerate() {
            match file.axes.get(*name) {
                Some(section) => checked.push(axis(name, index, section, &kinematics, &mut problems, &mut use_pin)),
                None => problems.add(&format!("axes.{name}"), "missing: a printer needs [axes.x], [axes.y], [axes.z] and [axes.e]"),
            }
        }
        checked.try_into().ok()
    } else {
        if !file.axes.is_empty() {
            problems.add("axes", "only printers have [axes.*]: this machine's motors are its own");
        }
        None
    };
    for name in file.axes.keys() {
        if !AXIS_NAMES.contains(&name.as_str()) {
            problems.add(&format!("axes.{name}"), "not an axis (x, y, z or e)");
        }
    }
    if let (Some(motion), Some(axes)) = (&motion, &axes) {
        for (bit, axis) in axes.iter().take(3).enumerate() {
            let homed = motion.homing_groups.iter().any(|g| g & (1 << bit) != 0);
            if homed && axis.home == HomeEnd::None {
                problems.add(&format!("axes.{}.home", AXIS_NAMES[bit]), "is \"none\" but motion.homing_order homes this axis");
            }
            if !homed && axis.home != HomeEnd::None {
                problems.add("motion.homing_order", format!("does not home {} although axes.{}.home names an end", AXIS_NAMES[bit], AXIS_NAMES[bit]));
            }
        }
    }

    let mut heaters = Vec::new();
    for (name, section) in &file.heaters {
        let role = match (kind, name.as_str()) {
            (Kind::Printer, "hotend") => HeaterRole::Hotend,
            (Kind::Printer, "bed") => HeaterRole::Bed,
            (Kind::ExtrusionLine, "barrel") => HeaterRole::Barrel,
            (Kind::PowderBed, _) => {
                problems.add(&format!("heaters.{name}"), "the powder bed has no heaters");
                continue;
            }
            _ => {
                let known = if kind == Kind::Printer { "\"hotend\" and \"bed\"" } else { "\"barrel\"" };
                problems.add(&format!("heaters.{name}"), format!("not a heater of this machine (it has {known})"));
                continue;
            }
        };
        if let Some(h) = heater(name, role, section, &mut problems, &mut use_pin) {
            heaters.push(h);
        }
    }
    heaters.sort_by_key(|h| h.role as u8);
    if kind == Kind::ExtrusionLine && !heaters.iter().any(|h| h.role == HeaterRole::Barrel) {
        problems.add("heaters.barrel", "missing: the extrusion line needs its barrel heater");
    }

    let fan = match &file.fan {
        Some(section) => match Pin::parse(&section.pin) {
            Ok(pin) => {
                if kind == Kind::PowderBed {
                    problems.add("fan", "the powder bed has no fan output (D8 and D10 are its suction and roller)");
                } else if !pwm_capable(pin) {
                    problems.add("fan.pin", format!("{pin} has no PWM channel this board drives (use D8, D9 or D10)"));
                }
                use_pin(&mut problems, "fan.pin".into(), pin);
                Some(pin)
            }
            Err(e) => {
                problems.add("fan.pin", e);
                None
            }
        },
        None => None,
    };

    let display = match &file.display {
        Some(d) if d.kind == "hd44780" => true,
        Some(d) => {
            problems.add("display.type", format!("\"{}\" is not a display this board drives (\"hd44780\": the RepRapDiscount Smart Controller's 16x2 on EXP1)", d.kind));
            false
        }
        None => false,
    };
    if display && kind == Kind::ExtrusionLine {
        problems.add("display", "the extrusion line's board has no display driver (only printers and the powder bed)");
    }
    let encoders = match &file.encoders {
        Some(e) if e.kind == "nse5310" => true,
        Some(e) => {
            problems.add("encoders.type", format!("\"{}\" is not an encoder the firmware reads (\"nse5310\")", e.kind));
            false
        }
        None => false,
    };
    if encoders && !(kind == Kind::Printer && kinematics == Kinematics::Cartesian) {
        problems.add("encoders", "the NSE-5310 loops close X and Y of a Cartesian printer only");
    }
    if kind == Kind::Printer {
        // RAMPS's second extruder driver is not used: its enable is held off.
        use_pin(&mut problems, "the unused E1 driver's enable".into(), Pin::digital(30).unwrap());
    }
    if matches!(kinematics, Kinematics::Arm { .. }) {
        for (n, motor) in ["x", "y", "z", "e"].iter().enumerate() {
            use_pin(&mut problems, format!("the {motor} driver's ALARM input"), Pin::digital(63 + n as u8).unwrap());
        }
        // The safety inputs (boards/mega2560-ramps/src/pins.rs).
        for (what, pin) in [("the safety relay input", 40), ("the emergency stop input", 42), ("the re-arm input", 44)] {
            use_pin(&mut problems, what.into(), Pin::digital(pin).unwrap());
        }
    }
    if encoders && encoders_wanted {
        // I²C on D20/D21 and the Index inputs on A9/A10.
        for (key, pin) in [("encoders (SDA)", 20), ("encoders (SCL)", 21), ("encoders (X index)", 63), ("encoders (Y index)", 64)] {
            use_pin(&mut problems, key.into(), Pin::digital(pin).unwrap());
        }
    }
    if display && display_wanted {
        // EXP1 of the RepRapDiscount Smart Controller: RS D16, E D17, D4–D7 on D23/D25/D27/D29.
        for (key, pin) in [("display (RS)", 16), ("display (E)", 17), ("display (D4)", 23), ("display (D5)", 25), ("display (D6)", 27), ("display (D7)", 29)] {
            use_pin(&mut problems, key.into(), Pin::digital(pin).unwrap());
        }
    }

    if problems.0.is_empty() {
        Ok(Machine {
            path: path.into(),
            name: m.name.clone(),
            kind,
            baud: m.baud,
            kinematics,
            motion,
            axes,
            heaters,
            fan,
            display: display && display_wanted,
            encoders: encoders && encoders_wanted,
        })
    } else {
        Err(problems.0)
    }
}

fn pwm_capable(pin: Pin) -> bool {
    pin.arduino().is_some_and(|d| pins::PWM_CHANNELS.iter().any(|&(p, _)| p == d))
}

fn positive(problems: &mut Problems, key: &str, value: f64, unit: &str) -> f64 {
    if !(value > 0.0) || !value.is_finite() {
        problems.add(key, format!("must be above 0 {unit} (is {value})"));
    }
    value
}

fn required<T: Copy>(problems: &mut Problems, key: &str, value: Option<T>, why: &str) -> Option<T> {
    if value.is_none() {
        problems.add(key, format!("missing: {why}"));
    }
    value
}

/// A required, positive geometry figure of `kinematics.<key>` (1 when
/// missing: the problem is recorded, checking goes on).
fn geometry(problems: &mut Problems, key: &str, value: Option<f64>, unit: &str, machine: &str) -> f64 {
    let key = format!("kinematics.{key}");
    let value = required(problems, &key, value, &format!("{machine} needs it")).unwrap_or(1.0);
    positive(problems, &key, value, unit)
}

fn kinematics(k: &schema::KinematicsSection, problems: &mut Problems) -> Kinematics {
    let delta_keys = [k.rod_length, k.radius, k.nozzle_offset, k.homed_height, k.printable_radius];
    let arm_keys = [k.upper_arm, k.forearm, k.joint_gear_ratio, k.joint_pulses_per_rev];
    let foreign = |problems: &mut Problems, keys: &[Option<f64>], extra: bool, what: &str| {
        if keys.iter().any(Option::is_some) || extra {
            problems.add("kinematics", format!("has {what} keys that do not belong to type \"{}\"", k.kind));
        }
    };
    match k.kind.as_str() {
        "cartesian" => {
            foreign(problems, &delta_keys, k.tower_angles.is_some() || k.segment_length.is_some(), "delta");
            foreign(problems, &arm_keys, k.origin.is_some() || k.home_position.is_some(), "arm");
            Kinematics::Cartesian
        }
        "delta" => {
            foreign(problems, &arm_keys, k.origin.is_some() || k.home_position.is_some(), "arm");
            let need = |problems: &mut Problems, key: &str, v: Option<f64>, unit: &str| geometry(problems, key, v, unit, "a delta");
            let rod_length = need(problems, "rod_length", k.rod_length, "mm");
            let radius = need(problems, "radius", k.radius, "mm");
            let nozzle_offset = need(problems, "nozzle_offset", k.nozzle_offset, "mm");
            let homed_height = need(problems, "homed_height", k.homed_height, "mm");
            let printable_radius = need(problems, "printable_radius", k.printable_radius, "mm");
            let segment_length = positive(problems, "kinematics.segment_length", k.segment_length.unwrap_or(1.0), "mm");
            let tower_angles = required(problems, "kinematics.tower_angles", k.tower_angles, "a delta needs its three tower angles").unwrap_or([0.0, 120.0, 240.0]);
            if rod_length <= radius {
                problems.add("kinematics.rod_length", format!("must be longer than kinematics.radius ({rod_length} ≤ {radius}): the nozzle could not reach the centre"));
            } else if printable_radius > rod_length - radius {
                problems.add(
                    "kinematics.printable_radius",
                    format!("{printable_radius} mm is beyond the reach rod_length − radius = {} mm", rod_length - radius),
                );
            }
            Kinematics::Delta { rod_length, radius, nozzle_offset, tower_angles, homed_height, printable_radius, segment_length }
        }
        "arm" => {
            foreign(problems, &delta_keys, k.tower_angles.is_some(), "delta");
            let need = |problems: &mut Problems, key: &str, v: Option<f64>, unit: &str| geometry(problems, key, v, unit, "an arm");
            let upper_arm = need(problems, "upper_arm", k.upper_arm, "mm");
            let forearm = need(problems, "forearm", k.forearm, "mm");
            let ratio = need(problems, "joint_gear_ratio", k.joint_gear_ratio, "");
            let ppr = need(problems, "joint_pulses_per_rev", k.joint_pulses_per_rev, "pulses");
            let segment_length = positive(problems, "kinematics.segment_length", k.segment_length.unwrap_or(0.35), "mm");
            let origin = required(problems, "kinematics.origin", k.origin, "the work origin's (py, pz) from the shoulder").unwrap_or([0.0; 2]);
            let home_position = required(problems, "kinematics.home_position", k.home_position, "where X, Y, Z are once homed").unwrap_or([0.0; 3]);
            Kinematics::Arm { upper_arm, forearm, origin, joint_steps_per_degree: ratio * ppr / 360.0, segment_length, home_position }
        }
        other => {
            problems.add("kinematics.type", format!("\"{other}\" is not a kinematics (\"cartesian\", \"delta\" or \"arm\")"));
            Kinematics::Cartesian
        }
    }
}

fn motion(section: &schema::MotionSection, kinematics: &Kinematics, problems: &mut Problems) -> Motion {
    let p = |problems: &mut Problems, key: &str, v: f64, unit: &str| positive(problems, &format!("motion.{key}"), v, unit);
    let mut groups = Vec::new();
    let mut homed = 0u8;
    for group in &section.homing_order {
        let mut mask = 0u8;
        for letter in group.chars() {
            let bit = match letter.to_ascii_lowercase() {
                'x' => 1,
                'y' => 2,
                'z' => 4,
                _ => {
                    problems.add("motion.homing_order", format!("\"{group}\": only x, y and z are homed"));
                    0
                }
            };
            if homed & bit != 0 || mask & bit != 0 {
                problems.add("motion.homing_order", format!("\"{group}\": {letter} is homed twice"));
            }
            mask |= bit;
        }
        homed |= mask;
        if mask != 0 {
            groups.push(mask);
        }
    }
    if groups.len() > 3 {
        problems.add("motion.homing_order", "at most three groups");
    }
    if matches!(kinematics, Kinematics::Delta { .. }) && groups != [0b111] {
        problems.add("motion.homing_order", "a delta homes its three towers together: [\"xyz\"]");
    }
    let max_step_rate = p(problems, "max_step_rate", section.max_step_rate, "steps/s");
    if max_step_rate > 100_000.0 {
        problems.add("motion.max_step_rate", format!("{max_step_rate} steps/s is more than the step interrupt makes (100 000)"));
    }
    Motion {
        print_acceleration: p(problems, "print_acceleration", section.print_acceleration, "mm/s²"),
        retract_acceleration: p(problems, "retract_acceleration", section.retract_acceleration, "mm/s²"),
        travel_acceleration: p(problems, "travel_acceleration", section.travel_acceleration, "mm/s²"),
        junction_deviation: p(problems, "junction_deviation", section.junction_deviation, "mm"),
        arc_tolerance: p(problems, "arc_tolerance", section.arc_tolerance, "mm"),
        max_step_rate,
        homing_groups: groups,
        homing_acceleration: p(problems, "homing_acceleration", section.homing_acceleration, "steps/s²"),
        must_home: section.must_home,
    }
}

fn parse_pin(problems: &mut Problems, key: &str, value: &Option<PinValue>, default: Option<u8>) -> Option<Pin> {
    match value {
        Some(PinValue::Name(name)) if name == "none" => None,
        Some(value) => match Pin::parse(value) {
            Ok(pin) => Some(pin),
            Err(e) => {
                problems.add(key, e);
                None
            }
        },
        None => default.and_then(Pin::digital),
    }
}

fn axis(
    name: &str,
    index: usize,
    s: &AxisSection,
    kinematics: &Kinematics,
    problems: &mut Problems,
    use_pin: &mut impl FnMut(&mut Problems, String, Pin),
) -> Axis {
    let key = |k: &str| format!("axes.{name}.{k}");
    let is_e = index == 3;
    let arm_joint = matches!(kinematics, Kinematics::Arm { .. }) && (index == 1 || index == 2);
    let steps_per_mm = if arm_joint {
        if s.steps_per_mm.is_some() {
            problems.add(&key("steps_per_mm"), "an arm joint's pulses per degree come from kinematics.joint_gear_ratio and joint_pulses_per_rev");
        }
        1.0
    } else {
        let v = required(problems, &key("steps_per_mm"), s.steps_per_mm, "how many steps make one mm").unwrap_or(1.0);
        positive(problems, &key("steps_per_mm"), v, "steps/mm")
    };
    let unit = if arm_joint { "°/s" } else { "mm/s" };
    let max_feed = positive(problems, &key("max_feed"), s.max_feed, unit);
    let max_acceleration = positive(problems, &key("max_acceleration"), s.max_acceleration, "mm/s²");
    let home = match s.home.as_deref() {
        Some("min") => HomeEnd::Min,
        Some("max") => HomeEnd::Max,
        Some("none") | None if is_e => HomeEnd::None,
        Some("none") => HomeEnd::None,
        Some(other) => {
            problems.add(&key("home"), format!("\"{other}\" is not an end (\"min\", \"max\" or \"none\")"));
            HomeEnd::None
        }
        None => {
            problems.add(&key("home"), "missing: say which end the axis homes to (\"min\", \"max\" or \"none\")");
            HomeEnd::None
        }
    };
    if is_e {
        for (k, present) in [
            ("min", s.min.is_some()),
            ("max", s.max.is_some()),
            ("homing_feed", s.homing_feed.is_some()),
            ("endstop_triggered", s.endstop_triggered.is_some()),
            ("min_endstop_pin", s.min_endstop_pin.is_some()),
            ("max_endstop_pin", s.max_endstop_pin.is_some()),
        ] {
            if present {
                problems.add(&key(k), "the extruder has no travel, homing or endstops");
            }
        }
        if home != HomeEnd::None {
            problems.add(&key("home"), "the extruder does not home");
        }
    }
    let (min, max) = if is_e {
        (0.0, 0.0)
    } else {
        let min = required(problems, &key("min"), s.min, "the travel's lower end (mm)").unwrap_or(0.0);
        let max = required(problems, &key("max"), s.max, "the travel's upper end (mm)").unwrap_or(1.0);
        if min >= max {
            problems.add(&key("min"), format!("travel min must be below max ({min} ≥ {max})"));
        }
        (min, max)
    };
    let homing_feed = if home == HomeEnd::None {
        s.homing_feed.unwrap_or(1.0)
    } else {
        let v = required(problems, &key("homing_feed"), s.homing_feed, "how fast the axis seeks its endstop").unwrap_or(1.0);
        positive(problems, &key("homing_feed"), v, unit)
    };
    let homing_backoff = s.homing_backoff.unwrap_or(5.0);
    if home != HomeEnd::None {
        positive(problems, &key("homing_backoff"), homing_backoff, "mm");
    }
    let homing_travel = s.homing_travel.unwrap_or(1.5 * (max - min).abs());
    if home != HomeEnd::None {
        positive(problems, &key("homing_travel"), homing_travel, unit);
    }
    let endstop_high = match s.endstop_triggered.as_deref() {
        None | Some("high") => true,
        Some("low") => false,
        Some(other) => {
            problems.add(&key("endstop_triggered"), format!("\"{other}\" is not a level (\"high\" or \"low\")"));
            true
        }
    };
    let ramps = pins::ramps_axis(name).unwrap_or([None; 5]);
    let step = parse_pin(problems, &key("step_pin"), &s.step_pin, ramps[0]);
    let dir = parse_pin(problems, &key("dir_pin"), &s.dir_pin, ramps[1]);
    let enable = parse_pin(problems, &key("enable_pin"), &s.enable_pin, ramps[2]);
    let min_default = if home == HomeEnd::Min { ramps[3] } else { None };
    let max_default = if home == HomeEnd::Max { ramps[4] } else { None };
    let min_endstop = parse_pin(problems, &key("min_endstop_pin"), &s.min_endstop_pin, min_default);
    let max_endstop = parse_pin(problems, &key("max_endstop_pin"), &s.max_endstop_pin, max_default);
    if home == HomeEnd::Min && min_endstop.is_none() {
        problems.add(&key("min_endstop_pin"), "the axis homes to min but has no min endstop");
    }
    if home == HomeEnd::Max && max_endstop.is_none() {
        problems.add(&key("max_endstop_pin"), "the axis homes to max but has no max endstop");
    }
    if s.hard_limits && min_endstop.is_none() && max_endstop.is_none() {
        problems.add(&key("hard_limits"), "needs an endstop to stop on");
    }
    for (k, pin) in [("step_pin", step), ("dir_pin", dir), ("enable_pin", enable)] {
        if pin.is_none() && !matches!((k, &s.step_pin), (_, Some(_))) {
            problems.add(&key(k), "missing: every motor needs STEP, DIR and ENABLE pins");
        }
    }
    for (k, pin) in [("step_pin", step), ("dir_pin", dir), ("enable_pin", enable), ("min_endstop_pin", min_endstop), ("max_endstop_pin", max_endstop)] {
        if let Some(pin) = pin {
            use_pin(problems, key(k), pin);
        }
    }
    let fallback = Pin::digital(0).unwrap();
    Axis {
        steps_per_mm,
        max_feed,
        max_acceleration,
        invert_direction: s.invert_direction,
        min,
        max,
        home,
        homing_feed,
        homing_backoff,
        homing_travel,
        endstop_high,
        endstop_pullup: s.endstop_pullup.unwrap_or(true),
        hard_limits: s.hard_limits,
        step: step.unwrap_or(fallback),
        dir: dir.unwrap_or(fallback),
        enable: enable.unwrap_or(fallback),
        min_endstop,
        max_endstop,
    }
}

fn heater(
    name: &str,
    role: HeaterRole,
    s: &HeaterSection,
    problems: &mut Problems,
    use_pin: &mut impl FnMut(&mut Problems, String, Pin),
) -> Option<Heater> {
    let key = |k: &str| format!("heaters.{name}.{k}");
    let Some(thermistor_name) = &s.thermistor else {
        problems.add(&format!("heaters.{name}"), "has no thermistor: a heater is only safe with a sensor (set heaters.NAME.thermistor)");
        return None;
    };
    let Some(kind) = thermistor::find(thermistor_name) else {
        problems.add(&key("thermistor"), format!("\"{thermistor_name}\" is not a thermistor the firmware has a table for (known: {})", thermistor::known_names()));
        return None;
    };
    let pullup_ohms = positive(problems, &key("pullup_ohms"), s.pullup_ohms.unwrap_or(4_700.0), "Ω");
    if let Err(e) = (Divider { curve: kind.curve, pullup_ohms }).table() {
        problems.add(&key("pullup_ohms"), e);
    }
    let max_temp = positive(problems, &key("max_temp"), s.max_temp, "°C");
    if max_temp > kind.rated_max_c {
        problems.add(&key("max_temp"), format!("{max_temp} °C is above what the {} is rated and tabled for ({} °C)", kind.description, kind.rated_max_c));
    }
    if max_temp < 40.0 {
        problems.add(&key("max_temp"), format!("{max_temp} °C leaves no room to heat (the safety margin below it is 10–15 °C)"));
    }
    let (default_output, default_sensor) = pins::ramps_heater(match role {
        HeaterRole::Hotend => "hotend",
        HeaterRole::Bed => "bed",
        HeaterRole::Barrel => "barrel",
    })
    .unwrap();
    let sensor_pin = parse_pin(problems, &key("sensor_pin"), &s.sensor_pin, Some(default_sensor))?;
    let Some(adc_channel) = sensor_pin.adc_channel() else {
        problems.add(&key("sensor_pin"), format!("{sensor_pin} is not an analog input (A0–A15)"));
        return None;
    };
    let output = parse_pin(problems, &key("output_pin"), &s.output_pin, Some(default_output))?;
    let pid = |problems: &mut Problems| match s.pid {
        Some(g) if g.iter().all(|v| v.is_finite() && *v >= 0.0 && *v <= 10_000.0) => g,
        Some(_) => {
            problems.add(&key("pid"), "gains must be between 0 and 10 000 (Marlin's units: [Kp, Ki, Kd])");
            [0.0; 3]
        }
        None => {
            problems.add(&key("pid"), "missing: PID control needs [Kp, Ki, Kd] (Marlin's units)");
            [0.0; 3]
        }
    };
    let control = match s.control.as_str() {
        "pid" => Control::Pid(pid(problems)),
        "bang-bang" => {
            let hysteresis = s.hysteresis.unwrap_or(2.0);
            if !(0.1..=20.0).contains(&hysteresis) {
                problems.add(&key("hysteresis"), "must be 0.1–20 °C");
            }
            Control::BangBang { hysteresis }
        }
        "ssr-window" => {
            let window_ms = s.window_ms.unwrap_or(200);
            let min_slot_ms = s.min_slot_ms.unwrap_or(10);
            if !(20..=10_000).contains(&window_ms) || min_slot_ms == 0 || min_slot_ms > window_ms / 2 {
                problems.add(&key("window_ms"), "the window must be 20–10 000 ms and min_slot_ms 1 ms to half of it");
            }
            Control::SsrWindow { pid: pid(problems), window_ms, min_slot_ms }
        }
        other => {
            problems.add(&key("control"), format!("\"{other}\" is not a control (\"pid\", \"bang-bang\" or \"ssr-window\")"));
            Control::Pid([0.0; 3])
        }
    };
    if !matches!(control, Control::Pid(_) | Control::SsrWindow { .. }) && s.pid.is_some() {
        problems.add(&key("pid"), "only \"pid\" and \"ssr-window\" control use gains");
    }
    let windowed = matches!(control, Control::SsrWindow { .. });
    if !windowed && !pwm_capable(output) {
        problems.add(&key("output_pin"), format!("{output} has no PWM channel this board drives (use D8, D9 or D10, or control = \"ssr-window\")"));
    }
    if windowed && role == HeaterRole::Hotend {
        problems.add(&key("control"), "a hot end reacts in seconds: a 200 ms relay window is for beds and barrels");
    }
    if windowed && output != Pin::digital(if role == HeaterRole::Barrel { 9 } else { 8 }).unwrap() {
        problems.add(&key("output_pin"), "the relay window drives D8 (bed) or D9 (barrel) only on this board");
    }
    use_pin(problems, key("sensor_pin"), sensor_pin);
    use_pin(problems, key("output_pin"), output);
    Some(Heater {
        role,
        thermistor: kind,
        pullup_ohms,
        adc_channel,
        sensor_pin,
        output,
        max_temp,
        control,
        runaway_period: s.runaway_period,
        runaway_hysteresis: s.runaway_hysteresis,
        watch_period: s.watch_period,
        watch_increase: s.watch_increase,
    })
}
