//! A recorded encoder trace through the firmware's own NSE-5310 tracker and
//! following-error check: a CSV trace of one axis (the format of
//! `hal-sim/traces/README.md`), or a host's log of an `M828` capture from
//! a board (its `TR:` lines: X and Y).

use firmware::closed_loop::control::FollowingErrorLimit;
use firmware::closed_loop::nse5310::TrackerConfig;
use hal_sim::encoder_trace::{self, Capture, ReplayReport, TraceRow};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::plots::{line_chart, Series};

/// The shipped traces are read at 200 Hz and replayed one row per 250 Hz
/// loop tick (see the traces' README).
pub const READ_RATE_HZ: u16 = 200;

/// A replayed trace.
pub struct Replay {
    pub rows: Vec<TraceRow>,
    pub report: ReplayReport,
}

/// Parse and replay a trace file's text.
pub fn replay_text(text: &str) -> Result<Replay, String> {
    let rows = encoder_trace::parse(text).map_err(|e| format!("line {}: {}", e.line, e.message))?;
    let tracker = TrackerConfig::for_read_rate(READ_RATE_HZ, encoder_trace::TRACE_LOOP_HZ).ok_or("no tracker configuration for this read rate")?;
    let report = encoder_trace::replay(&rows, tracker, FollowingErrorLimit::printer_default(encoder_trace::TRACE_LOOP_HZ));
    Ok(Replay { rows, report })
}

/// An `M828` capture, both axes replayed.
pub struct CaptureReplay {
    pub capture: Capture,
    /// X's and Y's replays.
    pub axes: [Replay; 2],
}

/// Whether `text` is a host log with an `M828` capture (rather than CSV).
pub fn is_capture(text: &str) -> bool {
    text.lines().any(|line| line.trim().starts_with("TR:start "))
}

/// Parse an `M828` capture out of a host log and replay X and Y.
pub fn replay_capture_text(text: &str) -> Result<CaptureReplay, String> {
    let capture = encoder_trace::parse_capture(text).map_err(|e| format!("line {}: {}", e.line, e.message))?;
    let tracker = TrackerConfig::for_read_rate(READ_RATE_HZ, capture.loop_hz).ok_or("no tracker configuration for this loop rate")?;
    let following = FollowingErrorLimit::printer_default(capture.loop_hz);
    let axes = capture.axes.clone().map(|rows| {
        let report = encoder_trace::replay(&rows, tracker, following);
        Replay { rows, report }
    });
    Ok(CaptureReplay { capture, axes })
}

impl CaptureReplay {
    /// The capture's own figures, then each axis' summary.
    pub fn summary(&self) -> String {
        let mut text = String::new();
        let c = &self.capture;
        let _ = write!(
            text,
            "M828 capture: {} samples at {} Hz, steps/mm X {} Y {}",
            c.axes[0].len(),
            c.loop_hz,
            c.steps_per_mm[0],
            c.steps_per_mm[1]
        );
        match c.totals {
            Some((recorded, dropped)) => {
                let _ = writeln!(text, "; the board recorded {recorded}, dropped {dropped}; {} missing here", c.gaps);
            }
            None => {
                let _ = writeln!(text, "; no end line (capture still running?); {} missing", c.gaps);
            }
        }
        for (letter, axis) in ["X", "Y"].iter().zip(&self.axes) {
            for line in axis.summary().lines() {
                let _ = writeln!(text, "{letter}: {line}");
            }
        }
        text
    }
}

impl Replay {
    /// (time s, commanded − measured mm) for every row with a command.
    pub fn errors(&self) -> Vec<(f64, f64)> {
        self.rows
            .iter()
            .zip(&self.report.positions_mm)
            .filter_map(|(row, position)| row.commanded_mm.map(|c| (row.time_s, c - position)))
            .collect()
    }

    /// The printed summary: rows, largest error, counters, the alarm.
    pub fn summary(&self) -> String {
        let mut text = String::new();
        let c = &self.report.counters;
        let _ = writeln!(text, "{} rows, {:.3} s", self.rows.len(), self.rows.last().map_or(0.0, |r| r.time_s));
        let _ = writeln!(text, "largest following error before any alarm: {:.4} mm", self.report.max_error_mm);
        let _ = writeln!(
            text,
            "index edges accepted {}, glitches rejected {}, bounces {}, missed {}; bad reads {}",
            c.index_accepted, c.index_glitches, c.index_bounces, c.index_missed, c.bad_reads
        );
        match self.report.fault {
            Some((row, fault)) => {
                let time = self.rows.get(row).map_or(0.0, |r| r.time_s);
                let _ = writeln!(text, "ALARM at row {row} ({time:.3} s): {fault:?}");
            }
            None => {
                let _ = writeln!(text, "no alarm");
            }
        }
        text
    }

    /// The tracking error over time, as PNG and SVG.
    pub fn plot(&self, stem: &Path) -> Result<[PathBuf; 2], String> {
        line_chart(stem, "Encoder trace: commanded − measured", "time (s)", "mm", &[Series { name: "error", points: self.errors() }])
    }
}
