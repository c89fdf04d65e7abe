//! Recorded encoder traces: format, recording from the simulated axis, and
//! a replayer that feeds a trace into the firmware's own NSE-5310 tracker
//! and following-error check.
//!
//! # Format (`hal-sim/traces/*.csv`, see `traces/README.md`)
//!
//! CSV, one header line `time_s,raw,index,commanded_mm`, then one row per
//! encoder read:
//! - `time_s`: seconds since the start of the trace (decimal);
//! - `raw`: the NSE-5310's 12-bit count as read (0–4095), or empty when the
//!   read failed;
//! - `index`: Index edges seen (by the external interrupt, debounced) since
//!   the previous row (0, 1, 2, …);
//! - `commanded_mm`: where the firmware wanted the axis at that read (the
//!   loop's reference), mm; may be empty when unknown.
//!
//! Lines starting with `#` are comments. The first row is the homing read:
//! its position is `commanded_mm` (or 0).

use crate::axis_plant::{AxisPlant, PlantConfig};
use firmware::closed_loop::control::{AxisController, DriverStatus, FollowingErrorLimit, LoopGains, Reference};
use firmware::closed_loop::nse5310::{EncoderFault, LinearTracker, TrackerConfig, TrackerCounters, UNITS_PER_MM};
use firmware::closed_loop::output::StepperScale;
use firmware::closed_loop::reference::ReferencePath;
use firmware::closed_loop::tuning::Strategy;
use firmware::closed_loop::{AxisFault, EncoderAxis, Reading};
use std::fmt::Write as _;

pub const HEADER: &str = "time_s,raw,index,commanded_mm";

/// One encoder read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceRow {
    pub time_s: f64,
    /// `None`: the read failed.
    pub raw: Option<u16>,
    pub index: u8,
    pub commanded_mm: Option<f64>,
}

/// A line that is not a trace row.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TraceError {
    /// 1-based line number.
    pub line: usize,
    pub message: String,
}

/// Parse a trace.
pub fn parse(text: &str) -> Result<Vec<TraceRow>, TraceError> {
    let mut rows = Vec::new();
    let mut header_seen = false;
    for (number, line) in text.lines().enumerate() {
        let line_number = number + 1;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let error = |message: &str| TraceError { line: line_number, message: message.into() };
        if !header_seen {
            if line != HEADER {
                return Err(error("expected the header time_s,raw,index,commanded_mm"));
            }
            header_seen = true;
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != 4 {
            return Err(error("expected 4 fields"));
        }
        let time_s: f64 = fields[0].parse().map_err(|_| error("bad time_s"))?;
        let raw = if fields[1].is_empty() {
            None
        } else {
            let raw: u16 = fields[1].parse().map_err(|_| error("bad raw"))?;
            if raw > 4095 {
                return Err(error("raw is 12 bits (0-4095)"));
            }
            Some(raw)
        };
        let index: u8 = fields[2].parse().map_err(|_| error("bad index"))?;
        let commanded_mm =
            if fields[3].is_empty() { None } else { Some(fields[3].parse().map_err(|_| error("bad commanded_mm"))?) };
        rows.push(TraceRow { time_s, raw, index, commanded_mm });
    }
    if !header_seen {
        return Err(TraceError { line: 0, message: "empty trace".into() });
    }
    Ok(rows)
}

/// Write a trace (with `comment` lines first).
pub fn write(comment: &str, rows: &[TraceRow]) -> String {
    let mut out = String::new();
    for line in comment.lines() {
        let _ = writeln!(out, "# {line}");
    }
    let _ = writeln!(out, "{HEADER}");
    for row in rows {
        let raw = row.raw.map(|r| r.to_string()).unwrap_or_default();
        let commanded = row.commanded_mm.map(|c| format!("{c:.5}")).unwrap_or_default();
        let _ = writeln!(out, "{:.4},{raw},{},{commanded}", row.time_s, row.index);
    }
    out
}

/// A capture streamed by the firmware's `M828` (the `TR:` lines of a
/// host's log; `firmware::closed_loop::trace` documents the format), as
/// one trace per axis.
#[derive(Clone, Debug, PartialEq)]
pub struct Capture {
    pub loop_hz: u16,
    /// X's and Y's steps/mm, from the start line.
    pub steps_per_mm: [f64; 2],
    /// X's and Y's rows, one per sample received (`time_s` from the sample
    /// numbers, so a dropped sample leaves a gap in time).
    pub axes: [Vec<TraceRow>; 2],
    /// Samples the firmware recorded and dropped (from the end line, if the
    /// log has one).
    pub totals: Option<(u32, u32)>,
    /// Samples missing between received ones (from the numbering).
    pub gaps: u32,
}

/// Read the `TR:` lines out of a host log (anything else, `ok` and other
/// replies, is skipped). The first `TR:start` begins the capture.
pub fn parse_capture(text: &str) -> Result<Capture, TraceError> {
    let mut capture: Option<Capture> = None;
    let mut last_number: Option<u8> = None;
    let mut sample_index: u64 = 0;
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        let Some(body) = line.strip_prefix("TR:") else { continue };
        let error = |message: &str| TraceError { line: number + 1, message: message.into() };
        if let Some(rest) = body.strip_prefix("start ") {
            if capture.is_some() {
                break;
            }
            let fields: Vec<&str> = rest.split_whitespace().collect();
            let [hz, x, y] = fields[..] else { return Err(error("expected TR:start <hz> <x steps/mm x1000> <y steps/mm x1000>")) };
            let loop_hz: u16 = hz.parse().ok().filter(|hz| *hz > 0).ok_or_else(|| error("bad loop rate"))?;
            let milli = |field: &str| field.parse::<i64>().ok().filter(|m| *m > 0).map(|m| m as f64 / 1000.0).ok_or_else(|| error("bad steps/mm"));
            capture = Some(Capture { loop_hz, steps_per_mm: [milli(x)?, milli(y)?], axes: [Vec::new(), Vec::new()], totals: None, gaps: 0 });
            continue;
        }
        let Some(capture) = capture.as_mut() else { continue };
        if let Some(rest) = body.strip_prefix("end ") {
            let fields: Vec<u32> = rest.split_whitespace().filter_map(|f| f.parse().ok()).collect();
            let [recorded, dropped] = fields[..] else { return Err(error("expected TR:end <recorded> <dropped>")) };
            capture.totals = Some((recorded, dropped));
            break;
        }
        let bytes = body.as_bytes();
        if bytes.len() != 22 {
            return Err(error("a sample line has 22 characters after TR:"));
        }
        let hex = |range: std::ops::Range<usize>| u32::from_str_radix(&body[range], 16).map_err(|_| error("bad hexadecimal"));
        let sample_number = hex(0..2)? as u8;
        if let Some(last) = last_number {
            let step = sample_number.wrapping_sub(last);
            capture.gaps += u32::from(step.max(1) - 1);
            sample_index += u64::from(step.max(1));
        }
        last_number = Some(sample_number);
        let time_s = sample_index as f64 / f64::from(capture.loop_hz);
        for axis in 0..2 {
            let at = 2 + axis * 10;
            let raw = if &body[at..at + 3] == "---" { None } else { Some(hex(at..at + 3)? as u16) };
            let index = hex(at + 3..at + 4)? as u8;
            // 24-bit two's complement.
            let steps = ((hex(at + 4..at + 10)? << 8) as i32) >> 8;
            let commanded_mm = Some(f64::from(steps) / capture.steps_per_mm[axis]);
            capture.axes[axis].push(TraceRow { time_s, raw, index, commanded_mm });
        }
    }
    capture.ok_or(TraceError { line: 0, message: "no TR:start line (M828 S1 starts a capture)".into() })
}

/// What the firmware made of a trace.
#[derive(Clone, Debug)]
pub struct ReplayReport {
    /// The tracker's position after each row, mm (the last good one after a
    /// fault).
    pub positions_mm: Vec<f64>,
    pub counters: TrackerCounters,
    /// The first fault and the row (0-based, among data rows) that raised it.
    pub fault: Option<(usize, AxisFault)>,
    /// Largest |commanded − position| before any fault, mm.
    pub max_error_mm: f64,
}

/// Replay `rows` through the firmware's [`LinearTracker`] and the loop's
/// following-error check (an [`AxisController`] with open-loop gains used
/// only as the monitor), one row per tick.
pub fn replay(rows: &[TraceRow], tracker: TrackerConfig, following: FollowingErrorLimit) -> ReplayReport {
    let mut report = ReplayReport { positions_mm: Vec::new(), counters: TrackerCounters::default(), fault: None, max_error_mm: 0.0 };
    let mut encoder = LinearTracker::new(tracker);
    let mut monitor: AxisController = AxisController::new(LoopGains::OPEN_LOOP, i32::MAX, following);
    let to_units = |mm: f64| (mm * f64::from(UNITS_PER_MM)).round() as i32;
    let mut homed = false;
    for (number, row) in rows.iter().enumerate() {
        let commanded = row.commanded_mm.map(to_units);
        let measured = match row.raw {
            Some(raw) if !homed => {
                let _ = encoder.update(raw, 0, 0);
                let home = commanded.unwrap_or(0);
                encoder.set_position(home, home);
                homed = true;
                Ok(home)
            }
            Some(raw) => encoder.update(raw, row.index, commanded.unwrap_or_else(|| encoder.position())),
            None => encoder.read_failed().map(|()| encoder.position()),
        };
        let position = encoder.position();
        report.positions_mm.push(f64::from(position) / f64::from(UNITS_PER_MM));
        let reference = Reference { position: commanded.unwrap_or(position), velocity: 0 };
        let result = monitor.tick(reference, measured, DriverStatus::default());
        if report.fault.is_none() {
            match result {
                Err(fault) => report.fault = Some((number, fault)),
                Ok(_) => {
                    let error = f64::from(reference.position - position).abs() / f64::from(UNITS_PER_MM);
                    report.max_error_mm = report.max_error_mm.max(error);
                }
            }
        }
    }
    report.counters = encoder.counters();
    report
}

/// Something that happens to the axis during a recording.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// The belt jumps by this many mm.
    Slip(f64),
    /// The sensor freezes.
    Stick,
    /// Index glitch edges, one per plant substep.
    GlitchBurst(u32),
}

/// A recording: an axis, a strategy, straight moves, events.
#[derive(Clone, Debug)]
pub struct Scenario {
    pub description: &'static str,
    pub plant: PlantConfig,
    pub strategy: Strategy,
    pub loop_hz: u16,
    pub start_mm: f64,
    /// (end mm, duration s), one after the other.
    pub moves: Vec<(f64, f64)>,
    /// Extra time at the end, s.
    pub hold_s: f64,
    /// (time s, event).
    pub events: Vec<(f64, Event)>,
}

/// The loop rate of the shipped traces: 250 Hz (one read per 1 mm up to
/// 250 mm/s), so the files stay small.
pub const TRACE_LOOP_HZ: u16 = 250;

/// Run a scenario on the simulated axis with the firmware's loop and
/// record every encoder read.
pub fn record(scenario: &Scenario) -> Vec<TraceRow> {
    let period = 1.0 / f64::from(scenario.loop_hz);
    let substeps = 4;
    let mut plant = AxisPlant::new(scenario.plant.clone(), scenario.start_mm, period / f64::from(substeps));
    let gains = scenario.strategy.loop_gains(0.1, period as f32).expect("gains");
    // The recorder never stops on a following error: it records what the
    // sensor said (the replayer decides). Encoder faults do stop the loop;
    // the motor then follows the reference open loop, as a naive firmware would.
    let following = FollowingErrorLimit { limit: i32::MAX / 8, hold_ticks: u16::MAX };
    let mut axis = EncoderAxis::new(
        LinearTracker::new(TrackerConfig::for_read_rate(200, scenario.loop_hz).expect("fast enough to unwrap")),
        AxisController::new(gains, 200 * UNITS_PER_MM, following),
        StepperScale::new(100.0, UNITS_PER_MM as f32).expect("scale"),
    );
    let to_units = |mm: f64| (mm * f64::from(UNITS_PER_MM)).round() as i32;
    let first = plant.read_raw();
    let _ = axis.tracker.update(first, 0, 0);
    axis.rehome(to_units(scenario.start_mm));
    plant.take_index_edges();
    let mut rows = vec![TraceRow { time_s: 0.0, raw: Some(first), index: 0, commanded_mm: Some(scenario.start_mm) }];
    let preview = (0.1 * f64::from(scenario.loop_hz)).round() as u16;
    let mut path = ReferencePath::<1, 8>::new([to_units(scenario.start_mm)], scenario.loop_hz, preview);
    let mut next_move = 0;
    let mut queued_s = 0.0;
    let mut queued_ticks: i64 = 0;
    let total_s = scenario.moves.iter().map(|m| m.1).sum::<f64>() + 0.1 + scenario.hold_s;
    let ticks = (total_s * f64::from(scenario.loop_hz)).round() as usize;
    let mut events = scenario.events.clone();
    let scale = StepperScale::new(100.0, UNITS_PER_MM as f32).expect("scale");
    for tick in 1..=ticks {
        while next_move < scenario.moves.len() && path.free_slots() > 0 {
            let (end_mm, duration_s) = scenario.moves[next_move];
            queued_s += duration_s;
            let end_tick = (queued_s * f64::from(scenario.loop_hz)).round() as i64;
            path.push([to_units(end_mm)], (end_tick - queued_ticks).max(1) as u16).expect("room");
            queued_ticks = end_tick;
            next_move += 1;
        }
        plant.advance(period);
        let time_s = tick as f64 * period;
        events.retain(|&(at, event)| {
            if time_s + 1e-9 < at {
                return true;
            }
            match event {
                Event::Slip(mm) => plant.slip(mm, crate::axis_plant::SLIP_DURATION_S),
                Event::Stick => plant.stick_sensor(),
                Event::GlitchBurst(edges) => plant.glitch_burst(edges),
            }
            false
        });
        let reference = path.advance()[0];
        let raw = plant.read_raw();
        let index = plant.take_index_edges();
        let rate = match axis.tick(reference, Reading::Raw(raw), index, DriverStatus::default()) {
            Ok(rate) => rate,
            // Encoder gone: the stepper keeps following the reference.
            Err(_) => scale.step_rate(reference.velocity),
        };
        plant.set_step_rate(rate);
        rows.push(TraceRow {
            time_s,
            raw: Some(raw),
            index,
            commanded_mm: Some(f64::from(reference.position) / f64::from(UNITS_PER_MM)),
        });
    }
    rows
}

/// The traces shipped in `hal-sim/traces/`, by file name.
pub fn shipped_scenarios() -> Vec<(&'static str, Scenario)> {
    let circle_x: Vec<(f64, f64)> = {
        let pieces = crate::axis_plant::circle_pieces(10.0);
        let mut previous_s = 0.0;
        pieces
            .iter()
            .map(|&((x, _), end_s)| {
                let duration = end_s - previous_s;
                previous_s = end_s;
                (x, duration)
            })
            .collect()
    };
    let noisy_x = PlantConfig { glitch_rate_hz: 0.0, ..PlantConfig::printer_x() };
    vec![
        (
            "clean_circle.csv",
            Scenario {
                description: "X axis of SPEC §1's circle at 10 mm/s, robust PID gamma 0.5, 250 Hz, encoder noise 1 count, no glitches",
                plant: noisy_x.clone(),
                strategy: Strategy::RobustPid { gamma_milli: 500 },
                loop_hz: TRACE_LOOP_HZ,
                start_mm: 60.0,
                moves: circle_x,
                hold_s: 1.0,
                events: vec![],
            },
        ),
        (
            "belt_slip.csv",
            Scenario {
                description: "open loop: X moves 0 -> 5 mm at 10 mm/s and holds; at 1.0 s the belt jumps a 2 mm tooth",
                plant: noisy_x.clone(),
                strategy: Strategy::OpenLoop,
                loop_hz: TRACE_LOOP_HZ,
                start_mm: 0.0,
                moves: vec![(5.0, 0.5)],
                hold_s: 1.5,
                events: vec![(1.0, Event::Slip(2.0))],
            },
        ),
        (
            "index_glitch_burst.csv",
            Scenario {
                description: "robust PID gamma 0.5: X moves 0 -> 10 mm at 10 mm/s; at 0.45 s a burst of 160 Index glitch edges (40 reads)",
                plant: noisy_x.clone(),
                strategy: Strategy::RobustPid { gamma_milli: 500 },
                loop_hz: TRACE_LOOP_HZ,
                start_mm: 0.0,
                moves: vec![(10.0, 1.0)],
                hold_s: 1.0,
                events: vec![(0.45, Event::GlitchBurst(160))],
            },
        ),
        (
            "stuck_sensor.csv",
            Scenario {
                description: "X moves 0 -> 10 mm at 10 mm/s; at 0.4 s the sensor's reading freezes (the recorder's stepper keeps following the reference)",
                plant: noisy_x,
                strategy: Strategy::RobustPid { gamma_milli: 500 },
                loop_hz: TRACE_LOOP_HZ,
                start_mm: 0.0,
                moves: vec![(10.0, 1.0)],
                hold_s: 1.0,
                events: vec![(0.4, Event::Stick)],
            },
        ),
    ]
}

/// A shipped trace as text, exactly as in `hal-sim/traces/`.
pub fn render_shipped(name: &str) -> Option<String> {
    shipped_scenarios().into_iter().find(|(n, _)| *n == name).map(|(_, scenario)| {
        let comment = format!("{}\ngenerated by hal_sim::encoder_trace::record (PlantConfig seed {})", scenario.description, scenario.plant.seed);
        write(&comment, &record(&scenario))
    })
}

/// Encoder faults are [`AxisFault::Encoder`]; a helper for tests.
pub fn is_encoder_fault(fault: AxisFault, kind: EncoderFault) -> bool {
    fault == AxisFault::Encoder(kind)
}

#[cfg(test)]
mod capture_tests {
    use super::*;

    #[test]
    fn a_host_log_with_tr_lines_becomes_one_trace_per_axis() {
        let log = "ok\nTR:start 250 100000 80000\nok\nTR:00ABC10007D0---FFFFFFF\necho:busy: processing\nTR:0200010007D10002FFFFFF\nTR:end 4 1\n";
        let capture = parse_capture(log).unwrap();
        assert_eq!(capture.loop_hz, 250);
        assert_eq!(capture.steps_per_mm, [100.0, 80.0]);
        assert_eq!(capture.totals, Some((4, 1)));
        assert_eq!(capture.gaps, 1);
        let [x, y] = &capture.axes;
        assert_eq!(x[0], TraceRow { time_s: 0.0, raw: Some(0xABC), index: 1, commanded_mm: Some(20.0) });
        assert_eq!(y[0], TraceRow { time_s: 0.0, raw: None, index: 15, commanded_mm: Some(-1.0 / 80.0) });
        assert_eq!(x[1].time_s, 2.0 / 250.0);
        assert_eq!((x[1].raw, x[1].commanded_mm), (Some(0), Some(20.01)));
        assert_eq!((y[1].raw, y[1].index, y[1].commanded_mm), (Some(0), 2, Some(-1.0 / 80.0)));
    }

    #[test]
    fn a_log_without_a_start_line_is_refused() {
        assert!(parse_capture("ok\nTR:00ABC10007D0---FFFFFFF\n").is_err());
    }
}
