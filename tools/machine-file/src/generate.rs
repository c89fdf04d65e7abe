//! A checked [`Machine`] as Rust source: the constants the firmware core
//! builds its machine from ([`core_source`]), the board's pins and serial
//! rate ([`board_source`]), and which parts of the firmware are linked in
//! ([`features`]).

use crate::check::{Control, HeaterRole, HomeEnd, Kind, Kinematics, Machine};
use crate::pins::{self, Pin};
use crate::thermistor::{self, Divider};
use std::fmt::Write as _;

/// An `f32` literal that reads back as the same `f32`.
fn f(value: f64) -> String {
    format!("{:?}", value as f32)
}

fn fs(values: &[f64]) -> String {
    values.iter().map(|&v| f(v)).collect::<Vec<_>>().join(", ")
}

/// FNV-1a of what makes two machine files different machines (name, kind,
/// kinematics): settings saved by `M500` carry it, and a build for another
/// machine refuses them at boot.
pub fn fingerprint(machine: &Machine) -> u32 {
    let kinematics = match machine.kinematics {
        Kinematics::Cartesian => "cartesian",
        Kinematics::Delta { .. } => "delta",
        Kinematics::Arm { .. } => "arm",
    };
    let text = format!("{}\0{:?}\0{kinematics}", machine.name, machine.kind);
    text.bytes().fold(0x811c_9dc5u32, |hash, byte| (hash ^ u32::from(byte)).wrapping_mul(0x0100_0193))
}

/// Cargo features of the firmware core this machine needs linked in.
pub fn features(machine: &Machine) -> Vec<&'static str> {
    let mut features = Vec::new();
    match machine.kind {
        Kind::Printer => features.push("printer"),
        Kind::ExtrusionLine => features.push("extrusion-line"),
        Kind::PowderBed => features.push("powder-bed"),
    }
    if !machine.heaters.is_empty() {
        features.push("heaters");
    }
    match machine.kinematics {
        Kinematics::Delta { .. } => features.push("delta"),
        Kinematics::Arm { .. } => features.push("arm"),
        Kinematics::Cartesian => {}
    }
    if machine.encoders {
        features.push("encoders");
    }
    features
}

/// The board's own configuration switches (`cfg(feature = "…")` in
/// `boards/mega2560-ramps`), derived from the file.
pub fn board_features(machine: &Machine) -> Vec<&'static str> {
    let mut features = Vec::new();
    if machine.kind == Kind::Printer {
        features.push("motion");
        if !machine.heaters.is_empty() {
            features.push("printer");
        }
    }
    if !machine.heaters.is_empty() {
        features.push("heaters");
    }
    match machine.kinematics {
        Kinematics::Delta { .. } => features.push("machine-delta"),
        Kinematics::Arm { .. } => features.push("machine-arm"),
        Kinematics::Cartesian => {}
    }
    match machine.kind {
        Kind::ExtrusionLine => features.push("machine-extrusion-line"),
        Kind::PowderBed => features.push("machine-powder-bed"),
        Kind::Printer => {}
    }
    if machine.encoders {
        features.push("encoders");
    }
    if machine.display {
        features.push("display-hd44780");
    }
    match machine.heaters.iter().find(|h| h.role == HeaterRole::Bed).map(|h| h.control) {
        Some(Control::SsrWindow { .. }) => features.push("bed-ssr"),
        Some(Control::BangBang { .. }) => features.push("bed-bang-bang"),
        _ => {}
    }
    features
}

/// Every board feature [`board_features`] may name (for `check-cfg`).
pub const ALL_BOARD_FEATURES: [&str; 11] = [
    "motion",
    "printer",
    "heaters",
    "machine-delta",
    "machine-arm",
    "machine-extrusion-line",
    "machine-powder-bed",
    "encoders",
    "display-hd44780",
    "bed-ssr",
    "bed-bang-bang",
];

/// Gains × 10⁴ as the core keeps them (`thermal::Gains`).
fn gains_scaled(pid: [f64; 3]) -> [u32; 3] {
    pid.map(|g| (g * 10_000.0).round() as u32)
}

/// The core's constants for this machine, as items of a module; `p` is
/// the path of the firmware crate from there (`crate` or `firmware`).
pub fn core_source(machine: &Machine, p: &str) -> String {
    let mut out = String::new();
    let w = &mut out;
    writeln!(w, "// Generated from {} by tools/machine-file: edit the machine file, not this.", machine.path).unwrap();
    writeln!(w, "/// `M115`'s `MACHINE_TYPE`: the machine file's `machine.name`.").unwrap();
    writeln!(w, "pub const NAME: &str = {:?};", machine.name).unwrap();
    writeln!(w, "/// Identifies the machine file in saved settings (`storage`).").unwrap();
    writeln!(w, "pub const FINGERPRINT: u32 = {:#010x};", fingerprint(machine)).unwrap();
    writeln!(w, "/// Serial rate, baud.").unwrap();
    writeln!(w, "pub const BAUD: u32 = {};", machine.baud).unwrap();
    motion_source(machine, p, w);
    let mut trigger = 0u8;
    if let Some(axes) = &machine.axes {
        for (motor, axis) in axes.iter().take(3).enumerate() {
            if axis.endstop_high {
                trigger |= 0b11 << (2 * motor);
            }
        }
    } else {
        trigger = 0b11_1111;
    }
    writeln!(w, "/// Endstop levels that mean triggered, `M119`'s order (X_MIN, X_MAX, Y_MIN, …; bit set: high).").unwrap();
    writeln!(w, "pub const ENDSTOP_TRIGGER_LEVELS: u8 = {trigger:#010b};").unwrap();
    for heater in &machine.heaters {
        heater_source(heater, p, w);
    }
    let slot = |roles: &[HeaterRole]| match machine.heaters.iter().find(|h| roles.contains(&h.role)).map(|h| h.role) {
        Some(HeaterRole::Hotend) => "Some((&HOTEND, HOTEND_GAINS))",
        Some(HeaterRole::Barrel) => "Some((&BARREL, BARREL_GAINS))",
        Some(HeaterRole::Bed) => "Some((&BED, BED_GAINS))",
        None => "None",
    };
    writeln!(
        w,
        "/// The heaters: the hot end (or the extrusion line's barrel) and the bed, each with its default gains.\n\
         pub fn heaters() -> [Option<(&'static {p}::progmem::Flash<{p}::thermal::HeaterConfig>, {p}::thermal::Gains)>; 2] {{\n    [{}, {}]\n}}",
        slot(&[HeaterRole::Hotend, HeaterRole::Barrel]),
        slot(&[HeaterRole::Bed])
    )
    .unwrap();
    out
}

fn motion_source(machine: &Machine, p: &str, w: &mut String) {
    let (Some(motion), Some(axes)) = (&machine.motion, &machine.axes) else {
        writeln!(w, "/// This machine does not plan moves: the motion core is built with a placeholder.").unwrap();
        writeln!(w, "pub const MOTION: {p}::motion::MotionConfig = {p}::motion::MotionConfig::prusa_i3();").unwrap();
        return;
    };
    let is_arm = matches!(machine.kinematics, Kinematics::Arm { .. });
    let joint_spd = match machine.kinematics {
        Kinematics::Arm { joint_steps_per_degree, .. } => joint_steps_per_degree,
        _ => 0.0,
    };
    let kinematics = match &machine.kinematics {
        Kinematics::Cartesian => format!("{p}::motion::kinematics::MachineKinematics::Cartesian({p}::motion::kinematics::Cartesian)"),
        Kinematics::Delta { rod_length, radius, nozzle_offset, tower_angles, homed_height, printable_radius, segment_length } => format!(
            "{p}::motion::kinematics::MachineKinematics::Delta({{\n        \
             let mut delta = {p}::motion::kinematics::Delta::unplaced({}, {}, {}, [{}]);\n        \
             delta.homed_height = {};\n        delta.printable_radius = {};\n        delta.segment_length = {};\n        delta\n    }})",
            f(*rod_length),
            f(*radius),
            f(*nozzle_offset),
            fs(tower_angles),
            f(*homed_height),
            f(*printable_radius),
            f(*segment_length)
        ),
        Kinematics::Arm { upper_arm, forearm, origin, joint_steps_per_degree, segment_length, .. } => format!(
            "{p}::motion::kinematics::MachineKinematics::Arm({p}::motion::kinematics::Arm {{ l1: {}, l2: {}, origin_py: {}, origin_pz: {}, joint_steps_per_degree: {}, segment_length: {} }})",
            f(*upper_arm),
            f(*forearm),
            f(origin[0]),
            f(origin[1]),
            f(*joint_steps_per_degree),
            f(*segment_length)
        ),
    };
    let steps: Vec<f64> = axes.iter().map(|a| a.steps_per_mm).collect();
    let feeds: Vec<f64> = axes.iter().map(|a| a.max_feed).collect();
    let accels: Vec<f64> = axes.iter().map(|a| a.max_acceleration).collect();
    let soft_limits = match machine.kinematics {
        Kinematics::Delta { .. } => "None".to_string(),
        _ => format!(
            "Some({p}::motion::SoftLimits {{ min: [{}], max: [{}] }})",
            fs(&axes[..3].iter().map(|a| a.min).collect::<Vec<_>>()),
            fs(&axes[..3].iter().map(|a| a.max).collect::<Vec<_>>())
        ),
    };
    let mut homing_axes = Vec::new();
    for (motor, axis) in axes.iter().take(3).enumerate() {
        let units = if is_arm && motor > 0 { joint_spd } else { axis.steps_per_mm };
        let fast = axis.homing_feed * units;
        // The arm homes as its thesis did: a pause on the switch, then a
        // slow release at a tenth of the speed; the others bump twice.
        let (slow, release, pause) = if is_arm { (fast / 10.0, true, 500) } else { (fast / 2.0, false, 0) };
        homing_axes.push(format!(
            "{p}::motion::homing::AxisHoming {{ towards_max: {}, fast_rate: {}, slow_rate: {}, backoff_steps: {}, max_travel_steps: {}, release: {release}, pause_ms: {pause} }}",
            axis.home == HomeEnd::Max,
            f(fast),
            f(slow),
            (axis.homing_backoff * units) as u32,
            (axis.homing_travel * units) as u32,
        ));
    }
    let mut sequence = motion.homing_groups.clone();
    sequence.resize(3, 0);
    let home = match &machine.kinematics {
        Kinematics::Delta { .. } => format!("{p}::motion::HomePosition::DeltaTop"),
        Kinematics::Arm { home_position, .. } => format!("{p}::motion::HomePosition::Cartesian([{}])", fs(home_position)),
        Kinematics::Cartesian => format!(
            "{p}::motion::HomePosition::Cartesian([{}])",
            fs(&axes[..3]
                .iter()
                .map(|a| match a.home {
                    HomeEnd::Max => a.max,
                    HomeEnd::Min => a.min,
                    HomeEnd::None => 0.0f64.clamp(a.min, a.max),
                })
                .collect::<Vec<_>>())
        ),
    };
    let dir_invert = axes.iter().enumerate().fold(0u8, |bits, (m, a)| bits | (u8::from(a.invert_direction) << m));
    let limits = axes.iter().take(3).enumerate().fold(0u8, |bits, (m, a)| {
        if !a.hard_limits {
            return bits;
        }
        bits | if a.min_endstop.is_some() { 1 << m } else { 0 } | if a.max_endstop.is_some() { 0x10 << m } else { 0 }
    });
    writeln!(w, "/// The motion configuration (`MotionConfig`): kinematics, per-motor limits, homing, directions.").unwrap();
    writeln!(
        w,
        "pub const MOTION: {p}::motion::MotionConfig = {p}::motion::MotionConfig {{\n    \
         kinematics: {kinematics},\n    \
         steps_per_mm: [{}],\n    max_feed: [{}],\n    max_accel: [{}],\n    \
         print_accel: {},\n    retract_accel: {},\n    travel_accel: {},\n    junction_deviation: {},\n    \
         feed_factor: 1.0,\n    flow_factor: 1.0,\n    arc_tolerance: {},\n    max_step_rate: {},\n    \
         soft_limits: {soft_limits},\n    \
         homing: {p}::motion::homing::HomingConfig {{\n        sequence: [{:#05b}, {:#05b}, {:#05b}],\n        axes: [\n            {},\n        ],\n        acceleration: {},\n    }},\n    \
         home: {home},\n    must_home: {},\n    \
         stepper: {p}::motion::StepperConfig {{ dir_invert: {dir_invert:#06b}, limit_endstops: {limits:#010b}, ..{p}::motion::StepperConfig::DEFAULT }},\n}};",
        fs(&steps),
        fs(&feeds),
        fs(&accels),
        f(motion.print_acceleration),
        f(motion.retract_acceleration),
        f(motion.travel_acceleration),
        f(motion.junction_deviation),
        f(motion.arc_tolerance),
        f(motion.max_step_rate),
        sequence[0],
        sequence[1],
        sequence[2],
        homing_axes.join(",\n            "),
        f(motion.homing_acceleration),
        motion.must_home || is_arm,
    )
    .unwrap();
}

fn heater_source(heater: &crate::check::Heater, p: &str, w: &mut String) {
    let name = match heater.role {
        HeaterRole::Hotend => "HOTEND",
        HeaterRole::Bed => "BED",
        HeaterRole::Barrel => "BARREL",
    };
    let divider = Divider { curve: heater.thermistor.curve, pullup_ohms: heater.pullup_ohms };
    let table = divider.table().expect("checked in check::heater");
    let description = format!("{} (Marlin thermistor {})", heater.thermistor.description, heater.thermistor.marlin_type);
    w.push_str(&thermistor::table_source(&format!("{name}_THERMISTOR"), &description, &divider, &table, p));
    let (base, guard) = match heater.role {
        HeaterRole::Hotend => ("hotend(0)", "HOTEND"),
        HeaterRole::Bed => ("bed()", "BED"),
        HeaterRole::Barrel => ("barrel()", "BARREL"),
    };
    let (control, output, gains) = match heater.control {
        Control::Pid(pid) => {
            let law = if heater.role == HeaterRole::Barrel { "PLAIN_PID" } else { "PID" };
            (format!("{p}::thermal::pid::Control::{law}"), format!("{p}::thermal::output::OutputMode::HardwarePwm"), pid)
        }
        Control::BangBang { hysteresis } => (
            format!("{p}::thermal::pid::Control::BangBang {{ hysteresis_tenths: {} }}", (hysteresis * 10.0).round() as u32),
            format!("{p}::thermal::output::OutputMode::HardwarePwm"),
            [0.0; 3],
        ),
        Control::SsrWindow { pid, window_ms, min_slot_ms } => {
            let law = if heater.role == HeaterRole::Barrel { "PLAIN_PID" } else { "PID" };
            (
                format!("{p}::thermal::pid::Control::{law}"),
                format!(
                    "{p}::thermal::output::OutputMode::TimeProportioning({p}::thermal::output::TimeProportioning {{ period_ms: {window_ms}, min_slot_ms: {min_slot_ms} }})"
                ),
                pid,
            )
        }
    };
    let mut guard_fields = format!("max_c: {}", heater.max_temp.round() as i64);
    for (field, value) in [
        ("runaway_period_s", heater.runaway_period.map(u32::from)),
        ("runaway_hysteresis_c", heater.runaway_hysteresis.map(u32::from)),
        ("watch_period_s", heater.watch_period.map(u32::from)),
        ("watch_increase_c", heater.watch_increase.map(u32::from)),
    ] {
        if let Some(value) = value {
            write!(guard_fields, ", {field}: {value}").unwrap();
        }
    }
    writeln!(w, "/// The {} heater: thermistor, control, output and protections, in flash.", name.to_lowercase()).unwrap();
    writeln!(w, "#[cfg_attr(target_arch = \"avr\", link_section = \".progmem.data\")]").unwrap();
    writeln!(
        w,
        "pub static {name}: {p}::progmem::Flash<{p}::thermal::HeaterConfig> = {p}::progmem::Flash::new({p}::thermal::HeaterConfig {{\n    \
         sensor: {p}::thermal::thermistor::Thermistor::new(&{name}_THERMISTOR),\n    control: {control},\n    output: {output},\n    \
         guard: {p}::thermal::guard::GuardConfig {{ {guard_fields}, ..{p}::thermal::guard::GuardConfig::{guard} }},\n    \
         ..{p}::thermal::HeaterConfig::{base}\n}});"
    )
    .unwrap();
    let [kp, ki, kd] = gains_scaled(gains);
    writeln!(w, "/// Its default gains (`M301`/`M304`, `M502`), Marlin's units × 10⁴.").unwrap();
    writeln!(w, "pub const {name}_GAINS: {p}::thermal::Gains = {p}::thermal::Gains {{ kp: {kp}, ki: {ki}, kd: {kd} }};").unwrap();
}

fn pin_literal(pin: Pin) -> String {
    format!("pin(Port::{}, {})", pin.port, pin.bit)
}

fn channel_of(pin: Pin) -> Option<&'static str> {
    let d = pin.arduino()?;
    pins::PWM_CHANNELS.iter().find(|&&(p, _)| p == d).map(|&(_, name)| name)
}

/// The board's pins, PWM channels, thermistor channels and endstop
/// polarity, as items of `boards/mega2560-ramps/src/pins.rs` (which
/// defines `Pin`, `Port` and `pin`).
pub fn board_source(machine: &Machine) -> String {
    let mut out = String::new();
    let w = &mut out;
    writeln!(w, "// Generated from {} by tools/machine-file: edit the machine file, not this.", machine.path).unwrap();
    if let Some(axes) = &machine.axes {
        let list = |get: &dyn Fn(&crate::check::Axis) -> Pin| axes.iter().map(|a| pin_literal(get(a))).collect::<Vec<_>>().join(", ");
        writeln!(w, "/// STEP pins of X, Y, Z, E0.\npub const STEP: [Pin; 4] = [{}];", list(&|a| a.step)).unwrap();
        writeln!(w, "/// DIR pins of X, Y, Z, E0.\npub const DIR: [Pin; 4] = [{}];", list(&|a| a.dir)).unwrap();
        writeln!(w, "/// ENABLE pins (active low) of X, Y, Z, E0.\npub const ENABLE: [Pin; 4] = [{}];", list(&|a| a.enable)).unwrap();
        let mut endstops = Vec::new();
        let (mut pullups, mut invert) = (0u8, 0u8);
        for (motor, axis) in axes.iter().take(3).enumerate() {
            for (end, pin) in [axis.min_endstop, axis.max_endstop].into_iter().enumerate() {
                endstops.push(pin.map_or("None".to_string(), |p| format!("Some({})", pin_literal(p))));
                if pin.is_some() && axis.endstop_pullup {
                    pullups |= 1 << (2 * motor + end);
                }
            }
            if !axis.endstop_high {
                invert |= (1 << motor) | (0x10 << motor);
            }
        }
        writeln!(w, "/// Endstops in `M119`'s order: X_MIN, X_MAX, Y_MIN, Y_MAX, Z_MIN, Z_MAX.\npub const ENDSTOPS: [Option<Pin>; 6] = [{}];", endstops.join(", ")).unwrap();
        writeln!(w, "/// Endstops whose pull-up is on (bit i: `ENDSTOPS[i]`).\npub const ENDSTOP_PULLUPS: u8 = {pullups:#010b};").unwrap();
        writeln!(w, "/// Endstops that read low when triggered, in the step generator's layout (bit m: motor m's min, 4 + m: its max).\npub const ENDSTOP_ACTIVE_LOW: u8 = {invert:#010b};").unwrap();
    } else {
        // The machines that are not printers drive their own motors
        // (line.rs, bed.rs); the planner's pins stay RAMPS's, disabled.
        writeln!(w, "/// STEP pins of X, Y, Z, E0 (RAMPS; this machine drives its motors itself).\npub const STEP: [Pin; 4] = [pin(Port::F, 0), pin(Port::F, 6), pin(Port::L, 3), pin(Port::A, 4)];").unwrap();
        writeln!(w, "/// DIR pins of X, Y, Z, E0.\npub const DIR: [Pin; 4] = [pin(Port::F, 1), pin(Port::F, 7), pin(Port::L, 1), pin(Port::A, 6)];").unwrap();
        writeln!(w, "/// ENABLE pins (active low) of X, Y, Z, E0.\npub const ENABLE: [Pin; 4] = [pin(Port::D, 7), pin(Port::F, 2), pin(Port::K, 0), pin(Port::A, 2)];").unwrap();
        writeln!(w, "/// Endstops in `M119`'s order (none: this machine reads its own switches).\npub const ENDSTOPS: [Option<Pin>; 6] = [None; 6];").unwrap();
        writeln!(w, "pub const ENDSTOP_PULLUPS: u8 = 0;\npub const ENDSTOP_ACTIVE_LOW: u8 = 0;").unwrap();
    }
    for (role, name) in [(HeaterRole::Hotend, "HOTEND"), (HeaterRole::Bed, "BED"), (HeaterRole::Barrel, "BARREL")] {
        match machine.heaters.iter().find(|h| h.role == role) {
            Some(h) => {
                writeln!(w, "/// The {} heater's output.\npub const {name}: Option<Pin> = Some({});", name.to_lowercase(), pin_literal(h.output)).unwrap();
                writeln!(
                    w,
                    "/// Its hardware PWM channel (None: switched in software).\npub const {name}_PWM: Option<crate::pwm::Channel> = {};",
                    match (h.control, channel_of(h.output)) {
                        (Control::SsrWindow { .. }, _) | (_, None) => "None".to_string(),
                        (_, Some(c)) => format!("Some(crate::pwm::Channel::{c})"),
                    }
                )
                .unwrap();
                writeln!(w, "/// Its thermistor's ADC channel.\npub const {name}_ADC: u8 = {};", h.adc_channel).unwrap();
            }
            None => {
                writeln!(w, "pub const {name}: Option<Pin> = None;\npub const {name}_PWM: Option<crate::pwm::Channel> = None;\npub const {name}_ADC: u8 = 0;").unwrap();
            }
        }
    }
    match machine.heaters.iter().find_map(|h| match h.control {
        Control::SsrWindow { window_ms, min_slot_ms, .. } => Some((h.output, window_ms, min_slot_ms)),
        _ => None,
    }) {
        Some((pin, period, slot)) => writeln!(
            w,
            "/// The heater behind a solid-state relay: its pin and window.\npub const RELAY: Option<(Pin, firmware::thermal::TimeProportioning)> = Some(({}, firmware::thermal::TimeProportioning {{ period_ms: {period}, min_slot_ms: {slot} }}));",
            pin_literal(pin)
        )
        .unwrap(),
        None => writeln!(w, "pub const RELAY: Option<(Pin, firmware::thermal::TimeProportioning)> = None;").unwrap(),
    }
    match machine.fan {
        Some(pin) => writeln!(
            w,
            "/// The part-cooling fan.\npub const FAN: Option<Pin> = Some({});\npub const FAN_PWM: Option<crate::pwm::Channel> = Some(crate::pwm::Channel::{});",
            pin_literal(pin),
            channel_of(pin).expect("checked: the fan is on a PWM pin")
        )
        .unwrap(),
        None => writeln!(w, "pub const FAN: Option<Pin> = None;\npub const FAN_PWM: Option<crate::pwm::Channel> = None;").unwrap(),
    }
    out
}
