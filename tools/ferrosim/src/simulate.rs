//! A whole G-code file on the simulated board, in virtual time.
//!
//! The file goes through the same firmware core as on the boards (parser,
//! planner, step generator, thermal control), on `hal_sim::SimBoard`: one
//! main-loop pass per virtual millisecond, the step interrupt for every
//! timer tick, heater plants driven by the firmware's duties. The host side
//! behaves like Printrun's printcore: comments and blank lines stripped, one
//! line in flight, the next sent when `ok` comes back.
//!
//! Every `sample_ms` the motor positions are sampled (and every 100 ms the
//! heaters); speeds, accelerations and step rates are derived from those
//! samples, so they are averages over one sample period (10 ms by default:
//! a step rate resolves to 100 steps/s, an acceleration to the difference
//! of two such speeds).

use firmware::motion::kinematics::Kinematics;
use firmware::motion::MotionConfig;
use hal_sim::board::{SimBoard, SimEeprom};

/// The machines the simulator knows (the firmware's machine configurations).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MachineKind {
    /// SPEC §1: Cartesian Prusa i3 (the default machine of the Mega 2560 build).
    Prusa,
    /// SPEC §2: linear delta.
    Delta,
    /// SPEC §3: RR arm with a lead-screw X (400 pulses per turn).
    Arm,
}

impl MachineKind {
    pub fn config(self) -> MotionConfig {
        match self {
            MachineKind::Prusa => MotionConfig::prusa_i3(),
            MachineKind::Delta => MotionConfig::spec_delta(false),
            MachineKind::Arm => MotionConfig::spec_arm(400),
        }
    }

    /// Names of the motors, for reports and plots.
    pub fn motor_names(self) -> [&'static str; 4] {
        match self {
            MachineKind::Prusa => ["X", "Y", "Z", "E"],
            MachineKind::Delta => ["tower A", "tower B", "tower C", "E"],
            MachineKind::Arm => ["X screw", "shoulder", "elbow", "E"],
        }
    }

    /// Where the simulated machine's switches are, as a function of the
    /// motor positions (steps from power-on; bit i: motor i's min switch,
    /// bit 4 + i: its max switch): the Prusa's min switches where the
    /// motors stand at power-on, the delta's max switches 20 mm above, the
    /// arm's X max 1 mm up the screw, shoulder max 300 pulses, elbow min
    /// −300 pulses.
    pub fn endstops(self) -> hal_sim::board::Endstops {
        match self {
            MachineKind::Prusa => Box::new(|p: &[i64; 4]| (0..3).filter(|&m| p[m] <= 0).fold(0, |bits, m| bits | 1 << m)),
            MachineKind::Delta => Box::new(|p: &[i64; 4]| (0..3).filter(|&m| p[m] >= 1600).fold(0, |bits, m| bits | 0x10 << m)),
            MachineKind::Arm => {
                Box::new(|p: &[i64; 4]| u8::from(p[0] >= 400) << 4 | u8::from(p[1] >= 300) << 5 | u8::from(p[2] <= -300) << 2)
            }
        }
    }

    /// Units of the motors (the arm's joints turn in degrees).
    pub fn motor_units(self) -> [&'static str; 4] {
        match self {
            MachineKind::Arm => ["mm", "°", "°", "mm"],
            _ => ["mm"; 4],
        }
    }
}

/// How to run the simulation.
#[derive(Clone, Debug)]
pub struct Options {
    pub machine: MachineKind,
    /// Serial line rate of the simulated host; `None`: 1 Mbaud, so that the
    /// link never limits the machine ("as fast as the machine allows").
    pub baud: Option<u32>,
    /// Motor positions are sampled every this many ms.
    pub sample_ms: u32,
    /// Give up after this much virtual time.
    pub max_hours: f64,
    /// Also record the X and Y motor steps every this many ms
    /// ([`Report::xy_steps`]): the closed-loop reference of
    /// [`crate::tracking`], one per loop tick ([`crate::tracking::sample_ms`]:
    /// 4 ms at 250 Hz). Kept apart from `sample_ms` so that the figures
    /// stay averages over 10 ms (over 4 ms one step of quantisation is
    /// 625 mm/s² of acceleration).
    pub xy_sample_ms: Option<u32>,
}

impl Default for Options {
    fn default() -> Self {
        Self { machine: MachineKind::Prusa, baud: None, sample_ms: 10, max_hours: 48.0, xy_sample_ms: None }
    }
}

/// Motor positions at one moment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub time_s: f64,
    /// Steps from power-on, per motor (distances and rates come from these).
    pub steps: [i64; 4],
    /// What the firmware counts minus `steps` (homing and `G92` set the
    /// firmware's count), as of the last moment the machine was idle.
    pub offset: [i64; 4],
}

/// Heaters at one moment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThermalSample {
    pub time_s: f64,
    pub hotend_c: f64,
    pub bed_c: f64,
    /// 0–1.
    pub hotend_duty: f64,
    pub bed_duty: f64,
}

/// What the simulation found.
#[derive(Clone, Debug)]
pub struct Report {
    pub machine: MachineKind,
    /// From the first line sent to the machine idle with every line
    /// answered, virtual seconds.
    pub print_time_s: f64,
    /// The slicer's estimate, when the file carries one.
    pub slicer_estimate_s: Option<f64>,
    /// Lines sent (comments and blank lines stripped).
    pub lines: usize,
    /// Every `Error:` line the firmware wrote (the first 100).
    pub errors: Vec<String>,
    /// The file did not finish within `max_hours`.
    pub timed_out: bool,
    /// Motor steps per motor unit (mm or °).
    pub steps_per_unit: [f64; 4],
    pub samples: Vec<Sample>,
    /// X and Y motor steps from power-on every `Options::xy_sample_ms`
    /// (empty without it): (time s, [X, Y]).
    pub xy_steps: Vec<(f64, [i64; 2])>,
    pub thermal: Vec<ThermalSample>,
    /// Each `G28`: from the moment the line was sent to the moment its `ok`
    /// was in and the machine idle, virtual seconds.
    pub homing: Vec<(f64, f64)>,
    /// Times the step interrupt ran out of prepared motion mid-block.
    pub underruns: u32,
    /// Wall-clock seconds the simulation took.
    pub wall_s: f64,
}

/// The slicer's own print-time estimate, from PrusaSlicer's
/// `; estimated printing time (normal mode) = 1h 2m 3s` (also `1d …`) or
/// Cura's `;TIME:3723`.
pub fn slicer_estimate_s(gcode: &str) -> Option<f64> {
    for line in gcode.lines() {
        let line = line.trim();
        if let Some(seconds) = line.strip_prefix(";TIME:") {
            if let Ok(s) = seconds.trim().parse::<f64>() {
                return Some(s);
            }
        }
        if line.starts_with(';') && line.contains("estimated printing time") && !line.contains("silent") {
            let value = line.split('=').nth(1)?.trim();
            let mut total = 0.0;
            for part in value.split_whitespace() {
                let (number, unit) = part.split_at(part.len().saturating_sub(1));
                let n: f64 = number.parse().ok()?;
                total += n * match unit {
                    "d" => 86_400.0,
                    "h" => 3_600.0,
                    "m" => 60.0,
                    "s" => 1.0,
                    _ => return None,
                };
            }
            return Some(total);
        }
    }
    None
}

/// The lines a host sends: comments and blank lines stripped.
pub fn host_lines(gcode: &str) -> Vec<&str> {
    gcode
        .lines()
        .map(|line| line.split(';').next().unwrap_or("").trim())
        .filter(|line| !line.is_empty())
        .collect()
}

/// Whether a host line is a `G28` (homing), with or without axis words.
pub fn is_homing(line: &str) -> bool {
    line.split_whitespace().any(|word| word.eq_ignore_ascii_case("G28"))
}

/// Run `gcode` on the simulated machine; `progress(sent, total)` is called
/// every simulated second.
pub fn run(gcode: &str, options: &Options, mut progress: impl FnMut(usize, usize)) -> Report {
    let started = std::time::Instant::now();
    let config = options.machine.config();
    let mut board = SimBoard::with_machine(config, SimEeprom::new());
    board.set_baud(options.baud.unwrap_or(1_000_000));
    board.set_record_steps(false);
    board.set_endstops(options.machine.endstops());
    board.take_output();
    let lines = host_lines(gcode);
    let spu = config.steps_per_unit().map(f64::from);
    let sample_ms = options.sample_ms.max(1);
    let max_ms = (options.max_hours * 3_600_000.0) as u64;
    let mut report = Report {
        machine: options.machine,
        print_time_s: 0.0,
        slicer_estimate_s: slicer_estimate_s(gcode),
        lines: lines.len(),
        errors: Vec::new(),
        timed_out: false,
        steps_per_unit: spu,
        samples: Vec::new(),
        xy_steps: Vec::new(),
        thermal: Vec::new(),
        homing: Vec::new(),
        underruns: 0,
        wall_s: 0.0,
    };
    let start_ms = board.now_ms();
    let mut next = 0;
    let mut in_flight = false;
    let mut last_underruns = board.underruns();
    let mut elapsed: u64 = 0;
    let mut offset = [0i64; 4];
    let mut homing_since: Option<f64> = None;
    report.samples.push(Sample { time_s: 0.0, steps: board.steps.positions(), offset });
    let xy_sample_ms = options.xy_sample_ms.map(|ms| u64::from(ms.max(1)));
    let xy = |positions: [i64; 4]| [positions[0], positions[1]];
    if xy_sample_ms.is_some() {
        report.xy_steps.push((0.0, xy(board.steps.positions())));
    }
    loop {
        if !in_flight {
            if let Some(line) = lines.get(next) {
                if is_homing(line) {
                    homing_since = Some(elapsed as f64 / 1000.0);
                }
                board.receive(line.as_bytes());
                board.receive(b"\n");
                next += 1;
                in_flight = true;
            } else if board.link.machine.motion_idle() {
                break;
            }
        }
        board.advance(1);
        elapsed += 1;
        let output = board.take_output();
        for reply in output.lines() {
            if reply == "ok" || reply.starts_with("ok ") {
                in_flight = false;
            } else if reply.starts_with("Error") && report.errors.len() < 100 {
                report.errors.push(reply.to_string());
            }
        }
        if board.link.machine.motion_idle() {
            let counted = board.link.machine.motor_steps();
            let positions = board.steps.positions();
            offset = [0, 1, 2, 3].map(|m| i64::from(counted[m]) - positions[m]);
            if !in_flight {
                if let Some(since) = homing_since.take() {
                    report.homing.push((since, elapsed as f64 / 1000.0));
                }
            }
        }
        let underruns = board.underruns();
        report.underruns += u32::from(underruns.wrapping_sub(last_underruns));
        last_underruns = underruns;
        let time_s = elapsed as f64 / 1000.0;
        if elapsed.is_multiple_of(u64::from(sample_ms)) {
            report.samples.push(Sample { time_s, steps: board.steps.positions(), offset });
        }
        if xy_sample_ms.is_some_and(|ms| elapsed.is_multiple_of(ms)) {
            report.xy_steps.push((time_s, xy(board.steps.positions())));
        }
        if elapsed.is_multiple_of(100) {
            let (hotend, bed) = board.link.machine.heater_duties();
            report.thermal.push(ThermalSample {
                time_s,
                hotend_c: board.hotend_plant.temperature_c(),
                bed_c: board.bed_plant.temperature_c(),
                hotend_duty: f64::from(hotend) / 255.0,
                bed_duty: f64::from(bed) / 255.0,
            });
        }
        if elapsed.is_multiple_of(1000) {
            progress(next, lines.len());
        }
        if elapsed >= max_ms || board.link.machine.is_halted() && !in_flight && next >= lines.len() {
            report.timed_out = elapsed >= max_ms;
            break;
        }
    }
    // The planner side is idle; the step interrupt may still be emptying
    // its queue: run on until the motors have not moved for 20 ms.
    let mut last_move_ms = elapsed;
    let mut positions = board.steps.positions();
    while !report.timed_out && elapsed - last_move_ms < 20 {
        board.advance(1);
        elapsed += 1;
        if xy_sample_ms.is_some_and(|ms| elapsed.is_multiple_of(ms)) {
            report.xy_steps.push((elapsed as f64 / 1000.0, xy(board.steps.positions())));
        }
        if board.steps.positions() != positions {
            positions = board.steps.positions();
            last_move_ms = elapsed;
        }
    }
    if let Some(since) = homing_since {
        report.homing.push((since, elapsed as f64 / 1000.0));
    }
    let _ = board.take_output();
    let counted = board.link.machine.motor_steps();
    offset = [0, 1, 2, 3].map(|m| i64::from(counted[m]) - positions[m]);
    report.samples.push(Sample { time_s: elapsed as f64 / 1000.0, steps: positions, offset });
    progress(next, lines.len());
    report.print_time_s = last_move_ms.max(u64::from(board.now_ms().wrapping_sub(start_ms)).min(last_move_ms)) as f64 / 1000.0;
    report.wall_s = started.elapsed().as_secs_f64();
    report
}

/// Figures derived from the samples.
#[derive(Clone, Debug, PartialEq)]
pub struct Figures {
    /// Distance each motor travelled, in its units (mm or °).
    pub distance: [f64; 4],
    /// Highest speed of each motor, units/s (over one sample period).
    pub peak_speed: [f64; 4],
    /// Highest acceleration of each motor, units/s².
    pub peak_accel: [f64; 4],
    /// Highest step rate of each motor, steps/s.
    pub max_step_rate: [f64; 4],
}

impl Report {
    /// Distance, peak speed, acceleration and step rate per motor.
    pub fn figures(&self) -> Figures {
        let mut figures = Figures { distance: [0.0; 4], peak_speed: [0.0; 4], peak_accel: [0.0; 4], max_step_rate: [0.0; 4] };
        let mut last_speed: [Option<f64>; 4] = [None; 4];
        for pair in self.samples.windows(2) {
            let dt = pair[1].time_s - pair[0].time_s;
            if dt <= 0.0 {
                continue;
            }
            #[allow(clippy::needless_range_loop)] // six arrays in step
            for motor in 0..4 {
                let steps = (pair[1].steps[motor] - pair[0].steps[motor]) as f64;
                let units = steps / self.steps_per_unit[motor];
                figures.distance[motor] += units.abs();
                let speed = units / dt;
                figures.peak_speed[motor] = figures.peak_speed[motor].max(speed.abs());
                figures.max_step_rate[motor] = figures.max_step_rate[motor].max(steps.abs() / dt);
                if let Some(previous) = last_speed[motor] {
                    figures.peak_accel[motor] = figures.peak_accel[motor].max(((speed - previous) / dt).abs());
                }
                last_speed[motor] = Some(speed);
            }
        }
        figures
    }

    /// The tool position (X, Y, Z mm) and the extruder (mm) at a sample,
    /// through the machine's forward kinematics.
    pub fn tool_position(&self, sample: &Sample) -> Option<([f64; 3], f64)> {
        let config = self.machine.config();
        let units = |m: usize| ((sample.steps[m] + sample.offset[m]) as f64 / self.steps_per_unit[m]) as f32;
        let xyz = config.kinematics.forward([units(0), units(1), units(2)]).ok()?;
        Some((xyz.map(f64::from), f64::from(units(3))))
    }

    /// Tool speed along the path (mm/s) over time: (time s, speed).
    pub fn path_speed(&self) -> Vec<(f64, f64)> {
        let positions: Vec<(f64, [f64; 3])> =
            self.samples.iter().filter_map(|s| self.tool_position(s).map(|(p, _)| (s.time_s, p))).collect();
        positions
            .windows(2)
            .map(|w| {
                let dt = (w[1].0 - w[0].0).max(1e-9);
                let d = (0..3).map(|i| (w[1].1[i] - w[0].1[i]).powi(2)).sum::<f64>().sqrt();
                (w[1].0, d / dt)
            })
            .collect()
    }

    /// The layers: the Z heights (mm, 0.01 mm resolution) at which the
    /// extruder pushed filament, in printing order.
    pub fn layers(&self) -> Vec<f64> {
        let mut layers: Vec<f64> = Vec::new();
        let mut last: Option<(f64, f64)> = None;
        for sample in &self.samples {
            let Some((xyz, e)) = self.tool_position(sample) else { continue };
            // Extruding at a steady height (not while Z moves).
            if let Some((previous_z, previous_e)) = last {
                if e > previous_e + 1e-4 && (xyz[2] - previous_z).abs() < 0.001 {
                    let z = (xyz[2] * 100.0).round() / 100.0;
                    if !layers.iter().any(|l| (l - z).abs() < 0.005) {
                        layers.push(z);
                    }
                }
            }
            last = Some((xyz[2], e));
        }
        layers
    }

    /// The XY path at height `z` with the speed there: (x, y, mm/s).
    pub fn layer_path(&self, z: f64) -> Vec<(f64, f64, f64)> {
        let mut path = Vec::new();
        let mut previous: Option<(f64, [f64; 3])> = None;
        for sample in &self.samples {
            let Some((xyz, _)) = self.tool_position(sample) else { continue };
            if let Some((t, p)) = previous {
                if (xyz[2] - z).abs() < 0.005 {
                    let dt = (sample.time_s - t).max(1e-9);
                    let d = (0..3).map(|i| (xyz[i] - p[i]).powi(2)).sum::<f64>().sqrt();
                    path.push((xyz[0], xyz[1], d / dt));
                }
            }
            previous = Some((sample.time_s, xyz));
        }
        path
    }

    /// Each motor's step rate over time: per motor, (time s, steps/s).
    pub fn step_rates(&self) -> [Vec<(f64, f64)>; 4] {
        let mut rates: [Vec<(f64, f64)>; 4] = Default::default();
        for pair in self.samples.windows(2) {
            let dt = (pair[1].time_s - pair[0].time_s).max(1e-9);
            for (motor, rate) in rates.iter_mut().enumerate() {
                rate.push((pair[1].time_s, (pair[1].steps[motor] - pair[0].steps[motor]).abs() as f64 / dt));
            }
        }
        rates
    }

    /// The text summary the `simulate` command prints.
    pub fn summary(&self) -> String {
        use std::fmt::Write as _;
        let figures = self.figures();
        let names = self.machine.motor_names();
        let units = self.machine.motor_units();
        let mut text = String::new();
        let _ = writeln!(text, "machine: {:?}, {} lines", self.machine, self.lines);
        let _ = write!(text, "print time: {}", clock(self.print_time_s));
        match self.slicer_estimate_s {
            Some(estimate) => {
                let _ = writeln!(
                    text,
                    " (slicer's estimate {}: {:+.1} %)",
                    clock(estimate),
                    (self.print_time_s / estimate - 1.0) * 100.0
                );
            }
            None => text.push('\n'),
        }
        for motor in 0..4 {
            let _ = writeln!(
                text,
                "{:>9}: {:10.2} {:2} travelled, peak {:8.2} {}/s, {:9.1} {}/s², {:7.0} steps/s",
                names[motor],
                figures.distance[motor],
                units[motor],
                figures.peak_speed[motor],
                units[motor],
                figures.peak_accel[motor],
                units[motor],
                figures.max_step_rate[motor]
            );
        }
        let _ = writeln!(text, "planner starvation (step interrupt out of motion mid-block): {} times", self.underruns);
        if let (Some(first), Some(last)) = (self.thermal.first(), self.thermal.last()) {
            let peak_hotend = self.thermal.iter().map(|t| t.hotend_c).fold(f64::MIN, f64::max);
            let peak_bed = self.thermal.iter().map(|t| t.bed_c).fold(f64::MIN, f64::max);
            let _ = writeln!(
                text,
                "hot end: {:.1} → {:.1} °C (peak {:.1}); bed: {:.1} → {:.1} °C (peak {:.1})",
                first.hotend_c, last.hotend_c, peak_hotend, first.bed_c, last.bed_c, peak_bed
            );
        }
        if self.timed_out {
            let _ = writeln!(text, "NOT FINISHED within the time limit");
        }
        for error in &self.errors {
            let _ = writeln!(text, "firmware: {error}");
        }
        let _ = writeln!(
            text,
            "simulated in {:.2} s ({:.2} s per print hour)",
            self.wall_s,
            self.wall_s / (self.print_time_s / 3600.0).max(1e-9)
        );
        text
    }
}

/// `1h 02m 03.4s`.
pub fn clock(seconds: f64) -> String {
    let hours = (seconds / 3600.0).floor();
    let minutes = ((seconds - hours * 3600.0) / 60.0).floor();
    let rest = seconds - hours * 3600.0 - minutes * 60.0;
    if hours > 0.0 {
        format!("{hours:.0}h {minutes:02.0}m {rest:04.1}s")
    } else if minutes > 0.0 {
        format!("{minutes:.0}m {rest:04.1}s")
    } else {
        format!("{rest:.3}s")
    }
}

/// A synthetic print of about `minutes` minutes for benchmarks: a 40 mm
/// square spiral of perimeters and infill lines at 0.2 mm layers, heated
/// first like a slicer's start code.
pub fn synthetic_print(minutes: f64) -> String {
    use std::fmt::Write as _;
    let mut gcode = String::from("; synthetic print\nM140 S60\nM104 S200\nM190 S60\nM109 S200\nG28\nG92 E0\nM83\nG1 Z0.2 F600\n");
    let mut time_s = 0.0;
    let mut layer = 0;
    while time_s < minutes * 60.0 {
        let z = 0.2 * (layer + 1) as f64;
        let _ = writeln!(gcode, ";LAYER:{layer}\nG1 Z{z:.2} F600");
        // Perimeters: squares of 1 mm segments (slicer-like short moves).
        for ring in 0..3 {
            let (lo, hi) = (60.0 + ring as f64 * 0.45, 100.0 - ring as f64 * 0.45);
            let corners = [(lo, lo), (hi, lo), (hi, hi), (lo, hi), (lo, lo)];
            let _ = writeln!(gcode, "G0 X{lo:.3} Y{lo:.3} F9000");
            for pair in corners.windows(2) {
                let ((x0, y0), (x1, y1)) = (pair[0], pair[1]);
                let steps = ((x1 - x0).abs().max((y1 - y0).abs())).ceil() as usize;
                for i in 1..=steps {
                    let f = i as f64 / steps as f64;
                    let _ = writeln!(gcode, "G1 X{:.3} Y{:.3} E0.0332 F2400", x0 + (x1 - x0) * f, y0 + (y1 - y0) * f);
                }
            }
            time_s += 4.0 * (hi - lo) / 40.0;
        }
        // Infill: straight lines 0.45 mm apart.
        let mut y = 62.0;
        let mut forward = true;
        while y < 98.0 {
            let (a, b) = if forward { (62.0, 98.0) } else { (98.0, 62.0) };
            let _ = writeln!(gcode, "G0 X{a:.3} Y{y:.3} F9000\nG1 X{b:.3} Y{y:.3} E1.2 F4800");
            time_s += 36.0 / 80.0 + 0.1;
            y += 0.45;
            forward = !forward;
        }
        layer += 1;
    }
    gcode.push_str("M104 S0\nM140 S0\nM84\n");
    gcode
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slicer_estimates_are_read_from_prusaslicer_and_cura_comments() {
        assert_eq!(slicer_estimate_s("; estimated printing time (normal mode) = 1h 2m 3s\n"), Some(3723.0));
        assert_eq!(slicer_estimate_s("; estimated printing time (silent mode) = 9h\n; estimated printing time (normal mode) = 1d 0h 0m 1s\n"), Some(86_401.0));
        assert_eq!(slicer_estimate_s(";FLAVOR:Marlin\n;TIME:3723\n"), Some(3723.0));
        assert_eq!(slicer_estimate_s("G1 X1\n"), None);
    }

    #[test]
    fn hosts_strip_comments_and_blank_lines() {
        assert_eq!(host_lines("; start\nG28 ; home\n\n  G1 X1  \n"), ["G28", "G1 X1"]);
    }

    #[test]
    fn homing_lines_are_g28_with_or_without_axes() {
        assert!(is_homing("G28") && is_homing("g28 X Y") && is_homing("N3 G28 W"));
        assert!(!is_homing("G280") && !is_homing("G1 X28") && !is_homing("M28"));
    }

    #[test]
    fn clock_formats_hours_minutes_and_seconds() {
        assert_eq!(clock(3723.4), "1h 02m 03.4s");
        assert_eq!(clock(61.0), "1m 01.0s");
        assert_eq!(clock(1.0667), "1.067s");
    }
}
