//! The measurements behind `cargo benchmark`, one function per figure.
//! Each boots a fresh board, so phases cannot disturb one another.

use crate::board::{Board, Endstop, RampsConfig, CPU_HZ, X, Y, Z};
use crate::elf::{ElfInfo, RAM_BYTES};
use crate::host::{with_checksum, HostConfig};
use crate::steps::{judge, MovePlan, Verdict};
use std::path::Path;
use std::time::Duration;

/// Stack budget: 8 KiB of SRAM minus the static data minus a 1 KiB margin.
pub const STACK_MARGIN_BYTES: u32 = 1024;
/// Static RAM budget (`.data` + `.bss`).
pub const STATIC_RAM_BUDGET_BYTES: u32 = 6 * 1024;

/// What a bench phase leaves behind besides its own figure.
#[derive(Clone, Debug, Default)]
pub struct PhaseLog {
    pub name: String,
    pub simulated_s: f64,
    pub wall: Duration,
    pub stack_peak_sp: u32,
    pub stack_peak_paint: u32,
    pub deepest_function: Option<String>,
    pub isr_share: f64,
    pub i_clear_share: f64,
    pub sleep_share: f64,
    pub rx_overruns: u64,
    pub resets: u64,
    pub halted: Option<String>,
    /// Longest main-loop pass (gap between two `wdr`), ms.
    pub main_loop_max_ms: f64,
}

impl PhaseLog {
    pub fn of(name: &str, board: &Board) -> Self {
        let stats = board.stats();
        let cycles = board.cycle().max(1) as f64;
        Self {
            name: name.to_string(),
            simulated_s: board.seconds(),
            wall: board.wall_time(),
            stack_peak_sp: board.stack_peak_sp(),
            stack_peak_paint: board.stack_peak_paint(),
            deepest_function: board.symbol_at(stats.min_sp_pc).map(crate::board::demangle),
            isr_share: stats.isr_cycles as f64 / cycles,
            i_clear_share: stats.i_clear_cycles as f64 / cycles,
            sleep_share: stats.sleep_cycles as f64 / cycles,
            rx_overruns: board.rx_overruns(),
            resets: stats.resets,
            halted: board.halted_reason().map(str::to_string),
            main_loop_max_ms: stats.max_watchdog_gap as f64 * 1000.0 / f64::from(crate::board::CPU_HZ),
        }
    }
}

/// Boot a board and wait for the banner (`echo:… ready`) and the
/// start-up messages after it, as a host does before sending.
pub fn boot(elf: &Path, config: RampsConfig) -> Result<Board, String> {
    let mut board = Board::load(elf, config)?;
    let ready = |board: &Board| {
        board
            .host()
            .replies
            .iter()
            .any(|r| r.text.starts_with("echo:") && r.text.ends_with("ready"))
    };
    let end = board.cycle() + u64::from(CPU_HZ) / 2;
    while board.cycle() < end && !ready(&board) && board.halted_reason().is_none() {
        let next = board.cycle() + u64::from(CPU_HZ) / 1000;
        board.run_until(next);
    }
    if !ready(&board) {
        return Err(format!(
            "no banner within 0.5 s: {:?}",
            board.host().transcript()
        ));
    }
    // Let the start-up messages (stored settings) finish.
    board.run_for_ms(20.0);
    Ok(board)
}

/// The replies to one batch of lines.
pub fn exchange(board: &mut Board, lines: &[&str], timeout_s: f64) -> Result<Vec<String>, String> {
    let before = board.host().replies.len();
    board.send(lines.iter().copied());
    if !board.run_until_host_done(timeout_s) {
        return Err(format!(
            "no ok within {timeout_s} s for {:?}; got {:?}",
            lines,
            board.host().replies[before..]
                .iter()
                .map(|r| r.text.clone())
                .collect::<Vec<_>>()
        ));
    }
    Ok(board.host().replies[before..]
        .iter()
        .map(|r| r.text.clone())
        .collect())
}

/// A typical session for the stack high-water mark: start-up, capability
/// and status reports, settings report and save, motion and arc lines,
/// errors and resends.
pub const COMMAND_TOUR: &[&str] = &[
    "M115",
    "M105",
    "M114",
    "M119",
    "M503",
    "M92 X100 Y100 Z400 E93",
    "M203 X300 Y300 Z5 E25",
    "M201 X3000 Y3000 Z100 E10000",
    "M204 P1500 R1500 T1500",
    "M205 J0.013",
    "M500",
    "M501",
    "G28",
    "G90",
    "G92 X0 Y0 Z0 E0",
    "M83",
    "G1 Z0.3 F720",
    "G1 X103.474 Y98.612 E.02538 F1800",
    "G2 X110 Y110 I5 J5 E0.5",
    "G4 P1",
    "M106 S128",
    "M107",
    "M104 S200",
    "M140 S60",
    "M155 S1",
    "M155 S0",
    "M118 E1 tour done",
];

/// Stack peak and CPU shares over [`COMMAND_TOUR`] (host with printcore
/// numbering at 115200 baud).
pub fn command_tour(elf: &Path) -> Result<PhaseLog, String> {
    let mut board = boot(elf, RampsConfig::stock(115_200))?;
    exchange(&mut board, COMMAND_TOUR, 20.0)?;
    // Errors and protocol paths too (raw lines).
    board.host_mut().config = HostConfig::raw(115_200);
    exchange(
        &mut board,
        &["N1 G28*0", &"X".repeat(120), "G1 X1e99", "M999"],
        5.0,
    )?;
    Ok(PhaseLog::of("command tour", &board))
}

/// A typical slicer G1 line (PrusaSlicer's perimeter output).
pub const TYPICAL_G1: &[&str] = &[
    "G1 X103.474 Y98.612 E.02538",
    "G1 X104.126 Y99.033 E.02071",
    "G1 X104.713 Y99.541 E.02075",
    "G1 X105.224 Y100.124 E.02071",
    "G1 X105.651 Y100.772 E.02074",
    "G1 X105.986 Y101.474 E.02078",
    "G1 X106.222 Y102.215 E.02079",
    "G1 X106.356 Y102.981 E.02078",
];

#[derive(Clone, Debug)]
pub struct ParseResult {
    /// Median main-loop cycles from a G1 line's `\n` to its `ok`, and the
    /// same for the empty numbered line.
    pub g1_median: f64,
    pub baseline_median: f64,
    /// Main-loop cycles a G1 costs after its `ok`: putting it into the
    /// planner (`Motion::queue_piece`), the mean over the G1 lines.
    pub planning_mean: f64,
    pub lines: usize,
    /// Mean length of the G1 lines as sent (with `N…` and `*…`), bytes.
    pub g1_bytes: f64,
    pub first_g1_reply: String,
    pub log: PhaseLog,
}

impl ParseResult {
    pub fn cycles_per_line(&self) -> f64 {
        self.g1_median - self.baseline_median + self.planning_mean
    }
}

/// Cycles the main loop spends on a G1 line beyond an empty line.
///
/// The host sends, one at a time after each `ok`, numbered lines as
/// printcore would: `N<n> <G1 line>*<sum>`, each followed by two empty
/// numbered lines `N<n> *<sum>` (the second one is the baseline: the
/// first arrives while the G1 is still being planned). For each line the window runs from the
/// cycle at which its `\n` is complete in the receiver (RXC) to the cycle
/// at which the firmware writes the first byte of its reply to UDR0;
/// interrupt handler cycles inside the window are subtracted. The figure is
/// median(G1 windows) − median(empty-line windows): checksum over the
/// extra bytes, lexing, parsing and checking the G1 up to its `ok`; plus
/// the planning, which runs after the `ok` (while the host sends the next
/// line): the main-loop cycles in `Motion::queue_piece` (kinematics, step
/// counts, look-ahead) per G1, from the inclusive profile.
pub fn parse_cycles(elf: &Path, repeats: usize) -> Result<ParseResult, String> {
    let mut board = boot(elf, RampsConfig::stock(115_200))?;
    board.host_mut().config = HostConfig::raw(115_200);
    // M302 P1: the hot end is cold on the bench; the G1s extrude.
    exchange(&mut board, &["M110 N0", "G92 X100 Y100 E0", "M83", "M302 P1"], 5.0)?;
    board.inclusive_profile(true);
    board.inclusive_main_loop_only(true);
    let mut lines = Vec::new();
    let mut is_g1 = Vec::new();
    let mut n = 1;
    for r in 0..repeats {
        for g1 in TYPICAL_G1 {
            let _ = r;
            lines.push(with_checksum(&format!("N{n} {g1}")));
            is_g1.push(Some(true));
            n += 1;
            // Two empty lines: the first one arrives while the G1 is being
            // planned (its window holds some of that); the second one is
            // the baseline.
            for baseline in [None, Some(false)] {
                lines.push(with_checksum(&format!("N{n} ")));
                is_g1.push(baseline);
                n += 1;
            }
        }
    }
    let sent_before = board.host().sent.len();
    board.record_isr_intervals(true);
    let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
    exchange(&mut board, &refs, 60.0)?;
    let frame = board.avr_frame_cycles();
    let mut g1 = Vec::new();
    let mut base = Vec::new();
    let mut first_g1_reply = String::new();
    for (i, sent) in board.host().sent[sent_before..].iter().enumerate() {
        let (Some(end), Some(reply)) = (sent.last_byte_start_cycle, sent.first_reply) else {
            return Err(format!("line {:?} has no reply", sent.text));
        };
        let reply = &board.host().replies[reply];
        let rx_complete = end + frame;
        let window = reply.first_byte_cycle.saturating_sub(rx_complete);
        let isr = board.isr_cycles_between(rx_complete, reply.first_byte_cycle);
        let main = (window - isr) as f64;
        let Some(is_a_g1) = is_g1[i] else { continue };
        if is_a_g1 {
            if first_g1_reply.is_empty() {
                first_g1_reply = reply.text.clone();
            }
            if reply.text.starts_with("Error") {
                return Err(format!(
                    "the firmware refused {:?}: {}",
                    sent.text, reply.text
                ));
            }
            g1.push(main);
        } else {
            base.push(main);
        }
    }
    let planning = board
        .inclusive_by_function()
        .into_iter()
        .find(|(name, _)| name.ends_with("Motion>::queue_piece"))
        .map(|(_, cycles)| cycles)
        .ok_or("Motion::queue_piece never ran (or is inlined: the planning is not measured)")?;
    let planning_mean = planning as f64 / g1.len().max(1) as f64;
    let g1_bytes = lines
        .iter()
        .zip(&is_g1)
        .filter(|(_, g)| **g == Some(true))
        .map(|(l, _)| l.len() as f64 + 1.0)
        .sum::<f64>()
        / g1.len().max(1) as f64;
    Ok(ParseResult {
        g1_median: median(&mut g1),
        baseline_median: median(&mut base),
        planning_mean,
        lines: g1.len(),
        g1_bytes,
        first_g1_reply,
        log: PhaseLog::of("parse", &board),
    })
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(|a, b| a.total_cmp(b));
    match values.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => values[n / 2],
        n => (values[n / 2 - 1] + values[n / 2]) / 2.0,
    }
}

/// Endstops that never trip (normally closed, far away): inputs read
/// "open", so a firmware with hard limits lets the bench moves run.
pub fn far_endstops() -> [Option<Endstop>; 6] {
    let mut endstops = [None; 6];
    for (i, slot) in endstops.iter_mut().enumerate() {
        let is_min = i % 2 == 0;
        *slot = Some(Endstop {
            axis: i / 2,
            at_steps: if is_min {
                -1_000_000_000
            } else {
                1_000_000_000
            },
            is_min,
            pressed_level: true,
        });
    }
    endstops
}

/// One step-rate trial's outcome.
#[derive(Clone, Debug)]
pub struct Trial {
    pub rate_hz: f64,
    /// Per moving axis.
    pub verdicts: Vec<Verdict>,
    /// Per moving axis: STEP edges less than 200 ns after a DIR change.
    pub dir_setup_violations: Vec<u64>,
    pub replies: Vec<String>,
}

impl Trial {
    pub fn failure(&self) -> Option<String> {
        self.verdicts
            .iter()
            .zip(["X", "Y", "Z"])
            .find_map(|(v, a)| v.failure.as_ref().map(|f| format!("{a} {f}")))
    }
}

/// Steps per mm the trials configure on every axis (SPEC §1's 100).
pub const TRIAL_STEPS_PER_MM: f64 = 100.0;
/// Steps per axis in a trial move.
pub const TRIAL_STEPS: u64 = 4_000;

/// Move `axes` (X; or X, Y and Z together) by [`TRIAL_STEPS`] with a
/// cruise rate of `rate_hz` steps/s per axis, and judge each axis.
/// Acceleration is chosen so that each ramp takes 20 % of the move.
pub fn step_trial(board: &mut Board, axes: usize, rate_hz: f64) -> Result<Trial, String> {
    let s = TRIAL_STEPS_PER_MM;
    let axis_mm = TRIAL_STEPS as f64 / s;
    let axis_v = rate_hz / s;
    let axis_a = axis_v * axis_v / (2.0 * 0.2 * axis_mm);
    let path_scale = (axes as f64).sqrt();
    let (path_v, path_a) = (axis_v * path_scale, axis_a * path_scale);
    let letters = &["X", "Y", "Z"][..axes];
    let each = |value: f64| {
        letters
            .iter()
            .map(|l| format!("{l}{value:.3}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let setup = [
        format!("M92 {}", each(s)),
        format!("M203 {}", each(axis_v * 1.5)),
        format!("M201 {}", each(axis_a)),
        format!("M204 P{path_a:.3} T{path_a:.3}"),
        "M17".to_string(),
        format!("G92 {}", each(0.0)),
        "G90".to_string(),
    ];
    let setup_refs: Vec<&str> = setup.iter().map(String::as_str).collect();
    let mut replies = exchange(board, &setup_refs, 5.0)?;
    if let Some(error) = replies.iter().find(|r| r.starts_with("Error")) {
        return Err(format!("the firmware refused the trial set-up: {error}"));
    }
    board.clear_step_edges();
    let violations_before: Vec<u64> = [X, Y, Z][..axes]
        .iter()
        .map(|&a| board.dir_setup_violations(a))
        .collect();
    let plan = MovePlan {
        steps: TRIAL_STEPS,
        steps_per_mm: s,
        feed_mm_s: axis_v,
        accel_mm_s2: axis_a,
    };
    let timeout = plan.duration() * 3.0 + 1.0;
    let g1 = format!("G1 {} F{:.1}", each(axis_mm), path_v * 60.0);
    replies.extend(exchange(board, &[g1.as_str(), "M400"], timeout)?);
    let verdicts = [X, Y, Z][..axes]
        .iter()
        .map(|&a| judge(&plan, board.step_edges(a)))
        .collect();
    let dir_setup_violations = [X, Y, Z][..axes]
        .iter()
        .zip(violations_before)
        .map(|(&a, before)| board.dir_setup_violations(a) - before)
        .collect();
    Ok(Trial {
        rate_hz,
        verdicts,
        dir_setup_violations,
        replies,
    })
}

/// Rates tried in order until one fails; then bisected.
pub const TRIAL_RATES_HZ: &[f64] = &[
    2_000.0, 5_000.0, 10_000.0, 15_000.0, 20_000.0, 25_000.0, 30_000.0, 40_000.0, 50_000.0,
    60_000.0, 80_000.0, 100_000.0, 120_000.0, 160_000.0, 200_000.0,
];

#[derive(Clone, Debug)]
pub struct StepRateResult {
    /// Highest on-time rate per axis, steps/s.
    pub per_axis_hz: f64,
    pub axes: usize,
    /// The first failing rate and why.
    pub limit: Option<(f64, String)>,
    pub trials: Vec<(f64, Option<String>)>,
    pub log: PhaseLog,
}

impl StepRateResult {
    pub fn total_hz(&self) -> f64 {
        self.per_axis_hz * self.axes as f64
    }
}

/// The highest sustained step rate with `axes` steppers moving together.
/// Err when the firmware does not step at all (or fails the lowest rate).
pub fn step_rate(elf: &Path, axes: usize) -> Result<StepRateResult, String> {
    let mut config = RampsConfig::stock(115_200);
    config.endstops = far_endstops();
    let mut board = boot(elf, config)?;
    let mut trials = Vec::new();
    let mut best: Option<f64> = None;
    let mut limit = None;
    for &rate in TRIAL_RATES_HZ {
        let trial = step_trial(&mut board, axes, rate)?;
        if trial.verdicts.iter().all(|v| v.steps == 0) {
            let said = trial
                .replies
                .iter()
                .find(|r| !r.starts_with("ok"))
                .cloned()
                .unwrap_or_else(|| "only ok".into());
            return Err(format!(
                "no STEP edges: stepping is not built yet (G1 answered: {said})"
            ));
        }
        let failure = trial.failure();
        trials.push((rate, failure.clone()));
        match failure {
            None => best = Some(rate),
            Some(why) => {
                limit = Some((rate, why));
                break;
            }
        }
    }
    let Some(mut low) = best else {
        let (rate, why) = limit.unwrap_or_default();
        return Err(format!(
            "steps come late already at {rate:.0} steps/s: {why}"
        ));
    };
    if let Some((mut high, _)) = limit.clone() {
        // Three bisections between the last good and the first bad rate.
        for _ in 0..3 {
            let mid = ((low + high) / 2.0 / 100.0).round() * 100.0;
            if mid <= low || mid >= high {
                break;
            }
            let trial = step_trial(&mut board, axes, mid)?;
            let failure = trial.failure();
            trials.push((mid, failure.clone()));
            match failure {
                None => low = mid,
                Some(why) => {
                    high = mid;
                    limit = Some((mid, why));
                }
            }
        }
    }
    Ok(StepRateResult {
        per_axis_hz: low,
        axes,
        limit,
        trials,
        log: PhaseLog::of(&format!("step rate, {axes} axes"), &board),
    })
}

/// Share of cycles in interrupt handlers while X cruises at `rate_hz`.
pub fn isr_share_at(elf: &Path, rate_hz: f64) -> Result<(f64, PhaseLog), String> {
    let mut config = RampsConfig::stock(115_200);
    config.endstops = far_endstops();
    let mut board = boot(elf, config)?;
    let trial = step_trial(&mut board, 1, rate_hz)?;
    let verdict = &trial.verdicts[0];
    if verdict.steps == 0 {
        let said = trial
            .replies
            .iter()
            .find(|r| !r.starts_with("ok"))
            .cloned()
            .unwrap_or_else(|| "only ok".into());
        return Err(format!(
            "no STEP edges: stepping is not built yet (G1 answered: {said})"
        ));
    }
    if let Some(f) = &verdict.failure {
        return Err(format!("X does not hold {rate_hz:.0} steps/s: {f}"));
    }
    let (first, last) = verdict.cruise_span.ok_or("no cruise plateau")?;
    let edges = board.step_edges(X);
    let at = |cycle: u64| {
        edges
            .iter()
            .find(|e| e.rising && e.cycle == cycle)
            .map(|e| e.isr_cycles)
    };
    let (Some(i0), Some(i1)) = (at(first), at(last)) else {
        return Err("cruise edges not found".into());
    };
    Ok((
        (i1 - i0) as f64 / (last - first) as f64,
        PhaseLog::of("ISR share", &board),
    ))
}

/// Short slicer-like segments: a gentle spiral (radius 20 mm) of 1 mm
/// moves with extrusion at 100 mm/s.
pub fn short_segments(count: usize) -> Vec<String> {
    segments_of(count, 1.0)
}

/// The same spiral cut into `length_mm` segments (a turn of the segment
/// direction of `length_mm / 20` rad each: a gentle curve). The position is
/// set to the spiral's first point, so the path is exactly
/// `count × length_mm`: until session 5 it started at the centre, and a
/// 20 mm lead-in move (with a 90° corner into the spiral) was counted as
/// if it were no path at all, which made every ratio look worse (1 mm
/// segments ran at full speed and reported 0.66).
pub fn segments_of(count: usize, length_mm: f64) -> Vec<String> {
    let mut lines = vec![
        "G90".to_string(),
        "M83".to_string(),
        "G92 X120 Y100 E0".to_string(),
        "G1 F6000".to_string(),
        // The hot end is cold on the bench: allow the extrusion (else every
        // line also draws `echo: cold extrusion prevented`).
        "M302 P1".to_string(),
    ];
    let (cx, cy) = (100.0f64, 100.0f64);
    for i in 1..=count {
        let angle = i as f64 * length_mm / 20.0;
        let r = 20.0 + i as f64 * 0.002 * length_mm;
        lines.push(format!(
            "G1 X{:.3} Y{:.3} E.0{:04}",
            cx + r * angle.cos(),
            cy + r * angle.sin(),
            1700 + (i * 37) % 500
        ));
    }
    lines
}

#[derive(Clone, Debug)]
pub struct StreamResult {
    pub lines_per_s: f64,
    pub lines: usize,
    /// The same stream's limit if the firmware answered instantly: the
    /// wire time of each line and its replies, back to back.
    pub wire_bound_lines_per_s: f64,
    pub mean_reply_bytes: f64,
    pub log: PhaseLog,
}

/// Lines per second from a file of short G1 segments at `baud` with
/// printcore numbering and ok flow control: lines acknowledged, divided by
/// the time from the first segment's first byte to the last segment's `ok`
/// arriving at the host. The segments are 0.2 mm at 100 mm/s (500 a
/// second of motion), so the firmware and the wire set the rate, not the
/// moves: with 1 mm segments (until session 8) the planner filled and the
/// figure was the motion's 100 lines/s, whatever the firmware could take.
pub fn stream_rate(elf: &Path, baud: u32, segments: usize) -> Result<StreamResult, String> {
    let mut board = boot(elf, RampsConfig::stock(baud))?;
    let expected_frame = 10 * u64::from(CPU_HZ) / u64::from(baud);
    let frame = board.avr_frame_cycles();
    if frame.abs_diff(expected_frame) * 20 > expected_frame {
        return Err(format!(
            "the ELF runs its UART at {:.0} baud, not {baud} (build it from a machine file with baud = 250000)",
            10.0 * f64::from(CPU_HZ) / frame as f64
        ));
    }
    let job = segments_of(segments, 0.2);
    let header = 5;
    board.send(job.iter());
    let timeout = segments as f64 * 0.05 + 5.0;
    if !board.run_until_host_done(timeout) {
        return Err(format!("the stream did not finish within {timeout} s"));
    }
    let host = board.host();
    let segment_lines: Vec<_> = host
        .sent
        .iter()
        .filter(|s| s.job_index.is_some_and(|i| i >= header))
        .collect();
    if let Some(error) = host.replies.iter().find(|r| r.text.starts_with("Error")) {
        return Err(format!("the firmware answered {:?}", error.text));
    }
    let first = segment_lines.first().ok_or("no segments sent")?;
    let last = segment_lines.last().ok_or("no segments sent")?;
    let ok = &host.replies[last.ok_reply.ok_or("last segment without ok")?];
    let seconds = (ok.arrived_cycle - first.start_cycle) as f64 / f64::from(CPU_HZ);
    // Reply bytes per segment line (everything from its '\n' to its ok).
    let mut reply_bytes = 0usize;
    let mut line_bytes = 0usize;
    for sent in &segment_lines {
        line_bytes += sent.text.len() + 1;
        if let (Some(a), Some(b)) = (sent.first_reply, sent.ok_reply) {
            reply_bytes += host.replies[a..=b]
                .iter()
                .map(|r| r.text.len() + 1)
                .sum::<usize>();
        }
    }
    let n = segment_lines.len() as f64;
    let bytes_per_s = f64::from(baud) / 10.0;
    Ok(StreamResult {
        lines_per_s: n / seconds,
        lines: segment_lines.len(),
        wire_bound_lines_per_s: bytes_per_s / ((line_bytes + reply_bytes) as f64 / n),
        mean_reply_bytes: reply_bytes as f64 / n,
        log: PhaseLog::of(&format!("stream at {baud}"), &board),
    })
}

/// How close a stream of `length_mm` segments at 100 mm/s comes to full
/// speed on the real ELF at `baud`: the path's length over 100 mm/s,
/// divided by the time from the first to the last step pulse of the
/// segments (1.0: never slower than asked; the ramps at the two ends cost a
/// few hundredths). Also the lines per second the host got acknowledged.
pub fn segment_speed(elf: &Path, baud: u32, segments: usize, length_mm: f64) -> Result<(f64, f64, PhaseLog), String> {
    let mut board = boot(elf, RampsConfig::stock(baud))?;
    if std::env::var_os("FERROSTEP_OK_LATENCY").is_some() {
        board.inclusive_profile(true);
        board.sample_pcs(97);
    }
    let job = segments_of(segments, length_mm);
    board.send(job.iter());
    let timeout = segments as f64 * length_mm / 20.0 + 10.0;
    if std::env::var_os("FERROSTEP_RX_TRACE").is_some() {
        board.record_isr_intervals(true);
    }
    if !board.run_until_host_done(timeout) {
        rx_trace(&board);
        let host = board.host();
        let odd: Vec<_> = host.replies.iter().filter(|r| !r.text.starts_with("ok")).take(5).map(|r| r.text.clone()).collect();
        return Err(format!(
            "the stream did not finish within {timeout} s ({} of {} lines acknowledged, {} receive overruns, {} resends, replies besides ok: {odd:?})",
            host.lines_acknowledged(),
            job.len(),
            board.rx_overruns(),
            host.resends.len()
        ));
    }
    board.run_for_ms(500.0);
    rx_trace(&board);
    if let Some(error) = board.host().replies.iter().find(|r| r.text.starts_with("Error")) {
        return Err(format!("the firmware answered {:?}", error.text));
    }
    let edges: Vec<u64> = [X, Y]
        .iter()
        .flat_map(|&axis| board.step_edges(axis).iter().filter(|e| e.rising).map(|e| e.cycle))
        .collect();
    let (first, last) = (edges.iter().min().ok_or("no steps")?, edges.iter().max().ok_or("no steps")?);
    let seconds = (last - first) as f64 / f64::from(CPU_HZ);
    if std::env::var_os("FERROSTEP_SPEED_TRACE").is_some() {
        // Path speed in 20 ms windows (X and Y steps, 100 steps/mm).
        let window = u64::from(CPU_HZ) / 50;
        let mut t = *first;
        let mut trace = String::new();
        while t < *last {
            let count = |axis: usize| board.step_edges(axis).iter().filter(|e| e.rising && e.cycle >= t && e.cycle < t + window).count() as f64;
            let (x, y) = (count(X) / 100.0, count(Y) / 100.0);
            trace.push_str(&format!("{:.0} ", (x * x + y * y).sqrt() * 50.0));
            t += window;
        }
        eprintln!("{length_mm} mm: speed every 20 ms (mm/s, path length from |X|,|Y| steps): {trace}");
    }
    let ideal = segments as f64 * length_mm / 100.0;
    let host = board.host();
    let sent: Vec<_> = host.sent.iter().filter(|s| s.job_index.is_some_and(|i| i >= 5)).collect();
    let (a, b) = (sent.first().ok_or("nothing sent")?, sent.last().ok_or("nothing sent")?);
    let ok = &host.replies[b.ok_reply.ok_or("last segment without ok")?];
    let lines_per_s = sent.len() as f64 / ((ok.arrived_cycle - a.start_cycle) as f64 / f64::from(CPU_HZ));
    if std::env::var_os("FERROSTEP_OK_LATENCY").is_some() {
        let mut latencies = ok_latencies(&board);
        latencies.sort_unstable();
        let at = |q: f64| latencies[((latencies.len() - 1) as f64 * q) as usize] as f64 / 16_000.0;
        eprintln!("{length_mm} mm: last byte -> ok: median {:.2} ms, 90 % {:.2} ms, max {:.2} ms", at(0.5), at(0.9), at(1.0));
        // Where a line's cycle goes on average: its bytes on the wire, the
        // firmware's answer, the ok's bytes, the host's turn-around.
        let host = board.host();
        let (mut wire, mut answer, mut reply, mut turn, mut n) = (0u64, 0u64, 0u64, 0u64, 0u64);
        for pair in host.sent.windows(2) {
            let (s, next) = (&pair[0], &pair[1]);
            let (Some(last), Some(ok)) = (s.last_byte_start_cycle, s.ok_reply) else { continue };
            let ok = &host.replies[ok];
            wire += last - s.start_cycle;
            answer += ok.first_byte_cycle.saturating_sub(last);
            reply += ok.arrived_cycle - ok.first_byte_cycle;
            turn += next.start_cycle.saturating_sub(ok.arrived_cycle);
            n += 1;
        }
        let ms = |c: u64| c as f64 / n.max(1) as f64 / 16_000.0;
        for s in host.sent.iter().skip(20).take(3) {
            eprintln!("{:?}: {} cycles on the wire, frame {}", s.text, s.last_byte_start_cycle.unwrap_or(0) - s.start_cycle, board.avr_frame_cycles());
            let bytes: Vec<_> = board.rx_log().iter().filter(|(c, _)| *c >= s.start_cycle && *c <= s.last_byte_start_cycle.unwrap_or(0)).collect();
            eprintln!("  {} bytes: {:?}", bytes.len(), bytes.windows(2).map(|w| w[1].0 - w[0].0).collect::<Vec<_>>());
        }
        eprintln!("{length_mm} mm: mean per line: line on the wire {:.2} ms, last byte -> ok starts {:.2} ms, ok on the wire {:.2} ms, ok -> next line {:.2} ms", ms(wire), ms(answer), ms(reply), ms(turn));
        // Where the firmware was while lines waited for their ok.
        let mut total: std::collections::BTreeMap<String, usize> = Default::default();
        let host = board.host();
        for s in &host.sent {
            if let (Some(last), Some(ok)) = (s.last_byte_start_cycle, s.ok_reply) {
                for (name, n) in board.stack_samples_between(last, host.replies[ok].first_byte_cycle) {
                    *total.entry(name).or_default() += n;
                }
            }
        }
        let mut total: Vec<_> = total.into_iter().collect();
        total.sort_by(|a, b| b.1.cmp(&a.1));
        let all: usize = host.sent.iter().filter_map(|s| Some((s.last_byte_start_cycle?, host.replies[s.ok_reply?].first_byte_cycle))).map(|(a, b)| board.samples_between(a, b).iter().map(|t| t.1).sum::<usize>()).sum();
        for (name, n) in total.iter().take(25) {
            eprintln!("    {:5.1} %  {name}", *n as f64 * 100.0 / all as f64);
        }
    }
    Ok((ideal / seconds, lines_per_s, PhaseLog::of(&format!("{length_mm} mm segments"), &board)))
}

/// With FERROSTEP_RX_TRACE: the longest interrupt runs by vector, the
/// longest main-loop locks, and what ran before each receive overrun.
fn rx_trace(board: &Board) {
    if std::env::var_os("FERROSTEP_RX_TRACE").is_some() {
            let mut worst: std::collections::BTreeMap<u32, (u64, usize)> = Default::default();
            for (&(a, b), v) in board.isr_intervals().iter().zip(board.isr_vector_numbers()) {
                let e = worst.entry(v).or_default();
                e.0 = e.0.max(b - a);
                e.1 += 1;
            }
            eprintln!("longest interrupt episode by vector (cycles, count): {worst:?}");
            let mut locks = board.main_loop_interrupt_locks().to_vec();
            locks.sort_by_key(|l| std::cmp::Reverse(l.1));
            let named: Vec<_> = locks.iter().take(8).map(|&(pc, n)| (board.symbol_at(pc).map(crate::board::demangle).unwrap_or_default(), n)).collect();
            eprintln!("longest main-loop interrupt locks: {named:?}");
            // The interrupts that ran in the 3 000 cycles before each overrun.
            for &at in board.rx_overrun_cycles().iter().take(4) {
                let around: Vec<_> = board
                    .isr_intervals()
                    .iter()
                    .zip(board.isr_vector_numbers())
                    .filter(|(&(a, b), _)| b + 3000 >= at && a <= at)
                    .map(|(&(a, b), v)| format!("v{v} {}..{}", a as i64 - at as i64, b as i64 - at as i64))
                    .collect();
                let rx: Vec<_> = board.rx_log().iter().filter(|(c, _)| c + 3000 >= at && *c <= at).map(|(c, _)| *c as i64 - at as i64).collect();
                eprintln!("overrun at {at}: interrupts {around:?}; bytes started {rx:?}");
            }
        }
}

/// Flash and static RAM from the ELF.
pub fn sizes(elf: &Path) -> Result<(u32, u32), String> {
    let info = ElfInfo::read(elf)?;
    Ok((info.flash_bytes(), info.ram_static_bytes()))
}

/// The stack budget for a given static RAM use.
pub fn stack_budget(ram_static: u32) -> u32 {
    RAM_BYTES - ram_static - STACK_MARGIN_BYTES
}

/// Samples of the thermal history while the firmware holds the hot end at
/// `target` °C for `seconds` (if it can heat yet): (board, replies).
pub fn heat_run(elf: &Path, target: u32, seconds: f64) -> Result<(Board, Vec<String>), String> {
    let mut board = boot(elf, RampsConfig::stock(115_200))?;
    let mut replies = exchange(&mut board, &[&format!("M104 S{target}"), "M106 S128"], 5.0)?;
    board.run_for_ms(seconds * 1000.0);
    replies.extend(exchange(&mut board, &["M105"], 5.0)?);
    Ok((board, replies))
}

/// `Y`/`Z` re-exported for callers that build trials by hand.
pub const TRIAL_AXES: [usize; 3] = [X, Y, Z];

/// One closed-loop law tick on the ATmega2560 in each arithmetic of
/// `firmware::num`, cycles (mean, min, max over 256 ticks).
#[derive(Clone, Debug)]
pub struct LoopTickCycles {
    pub fixed: (f64, f64, f64),
    pub float: (f64, f64, f64),
}

/// The loop benchmark ELF built beside the firmware (same cargo run).
pub fn loop_bench_elf(firmware_elf: &Path) -> std::path::PathBuf {
    firmware_elf.with_file_name("mega2560-loop-bench.elf")
}

/// Run `mega2560-loop-bench` on simavr and read its figures (see
/// `boards/mega2560-ramps/src/bin/loop_bench.rs`).
pub fn loop_tick_cycles(bench_elf: &Path) -> Result<LoopTickCycles, String> {
    let mut board = Board::load(bench_elf, RampsConfig::stock(115_200))?;
    let done = |board: &Board| board.host().replies.iter().any(|r| r.text == "done" || r.text.starts_with("Error:"));
    let end = board.cycle() + 10 * u64::from(CPU_HZ);
    while board.cycle() < end && !done(&board) && board.halted_reason().is_none() {
        board.run_for_ms(10.0);
    }
    let printed: std::collections::HashMap<String, f64> = board
        .host()
        .replies
        .iter()
        .filter_map(|r| r.text.split_once('='))
        .filter_map(|(k, v)| Some((k.to_string(), v.parse::<f64>().ok()?)))
        .collect();
    let get = |key: &str| {
        printed.get(key).copied().ok_or_else(|| format!("the loop bench printed no {key}: {:?}", board.host().transcript()))
    };
    let triple = |name: &str| -> Result<(f64, f64, f64), String> {
        let key = format!("avr_loop_tick_cycles_{name}");
        Ok((get(&key)?, get(&format!("{key}_min"))?, get(&format!("{key}_max"))?))
    };
    Ok(LoopTickCycles { fixed: triple("fixed")?, float: triple("f32")? })
}

/// Per line of a finished stream: cycles from the start bit of its last
/// byte to the first byte of its `ok` (the firmware's part of the round
/// trip), in job order.
pub fn ok_latencies(board: &Board) -> Vec<u64> {
    let host = board.host();
    host.sent
        .iter()
        .filter_map(|s| {
            let last = s.last_byte_start_cycle?;
            let ok = &host.replies[s.ok_reply?];
            Some(ok.first_byte_cycle.saturating_sub(last))
        })
        .collect()
}

/// Steps per mm of the even-step trials (issue 23's harness: 400).
pub const EVEN_STEPS_PER_MM: f64 = 400.0;
/// The even-step trials' path per axis, mm: one long move that the
/// firmware cuts into pieces (≤ 16 384 steps each: 85 mm at 400 steps/mm
/// is three), then 30 collinear 2 mm moves sent one per `ok`.
pub const EVEN_LONG_MM: f64 = 85.0;
pub const EVEN_SHORT_MM: f64 = 2.0;
pub const EVEN_SHORT_MOVES: usize = 30;
/// Each ramp takes this share of the path (acceleration chosen so).
pub const EVEN_RAMP_SHARE: f64 = 0.10;
/// The judged window: from this share of the steps to 1 − it (the ramps
/// and a margin of 5 % left out).
pub const EVEN_WINDOW_FROM: f64 = 0.15;
/// An interval is even when within this share of the window's median.
pub const EVEN_TOLERANCE: f64 = 0.10;

/// One axis' intervals over the judged window of an even-step trial.
#[derive(Clone, Debug, PartialEq)]
pub struct EvenVerdict {
    pub failure: Option<String>,
    pub steps: u64,
    /// Median interval of the window, cycles.
    pub median_cycles: f64,
    /// Largest |interval − median| / median in the window.
    pub worst_deviation: f64,
    /// The worst interval, cycles, and the step it ends on (1-based).
    pub worst_interval: (u64, u64),
}

/// Judge the rising edges of one axis: `expected` steps in all; every
/// interval between consecutive steps from [`EVEN_WINDOW_FROM`] to
/// 1 − [`EVEN_WINDOW_FROM`] of the steps within [`EVEN_TOLERANCE`] of
/// their median, and the median within 1 % of `rate_hz`.
pub fn judge_even(edges: &[crate::board::StepEdge], expected: u64, rate_hz: f64) -> EvenVerdict {
    let rises: Vec<u64> = edges.iter().filter(|e| e.rising).map(|e| e.cycle).collect();
    let steps = rises.len() as u64;
    let mut verdict = EvenVerdict { failure: None, steps, median_cycles: 0.0, worst_deviation: 0.0, worst_interval: (0, 0) };
    if steps != expected {
        verdict.failure = Some(format!("{steps} steps instead of {expected}"));
        return verdict;
    }
    let first = (expected as f64 * EVEN_WINDOW_FROM) as usize;
    let last = (expected as f64 * (1.0 - EVEN_WINDOW_FROM)) as usize;
    if last <= first + 2 {
        verdict.failure = Some("too few steps to judge".into());
        return verdict;
    }
    let intervals: Vec<u64> = rises[first..=last].windows(2).map(|w| w[1] - w[0]).collect();
    let mut sorted: Vec<f64> = intervals.iter().map(|&i| i as f64).collect();
    let median = median(&mut sorted);
    verdict.median_cycles = median;
    for (i, &interval) in intervals.iter().enumerate() {
        let deviation = (interval as f64 - median).abs() / median;
        if deviation > verdict.worst_deviation {
            verdict.worst_deviation = deviation;
            verdict.worst_interval = (interval, (first + i + 2) as u64);
        }
    }
    let planned = f64::from(CPU_HZ) / rate_hz;
    if ((median - planned) / planned).abs() > 0.01 {
        verdict.failure = Some(format!("cruise at {:.0} steps/s instead of {rate_hz:.0}", f64::from(CPU_HZ) / median));
    } else if verdict.worst_deviation > EVEN_TOLERANCE {
        verdict.failure = Some(format!(
            "uneven: the interval ending on step {} is {} cycles, {:.0} % off the median {median:.0}",
            verdict.worst_interval.1,
            verdict.worst_interval.0,
            verdict.worst_deviation * 100.0
        ));
    }
    verdict
}

/// The G-code of an even-step trial: set-up, then the moves.
pub fn even_job(axes: usize, rate_hz: f64) -> (Vec<String>, Vec<String>, u64) {
    let s = EVEN_STEPS_PER_MM;
    let total_mm = EVEN_LONG_MM + EVEN_SHORT_MM * EVEN_SHORT_MOVES as f64;
    let axis_v = rate_hz / s;
    let axis_a = axis_v * axis_v / (2.0 * EVEN_RAMP_SHARE * total_mm);
    let path_scale = (axes as f64).sqrt();
    let (path_v, path_a) = (axis_v * path_scale, axis_a * path_scale);
    let letters = &["X", "Y", "Z"][..axes];
    let each = |value: f64| letters.iter().map(|l| format!("{l}{value:.3}")).collect::<Vec<_>>().join(" ");
    let setup = vec![
        format!("M92 {}", each(s)),
        format!("M203 {}", each(axis_v * 1.5)),
        format!("M201 {}", each(axis_a)),
        format!("M204 P{path_a:.3} T{path_a:.3}"),
        "M17".to_string(),
        format!("G92 {}", each(0.0)),
        "G90".to_string(),
    ];
    let mut moves = vec![format!("G1 {} F{:.1}", each(EVEN_LONG_MM), path_v * 60.0)];
    for i in 1..=EVEN_SHORT_MOVES {
        moves.push(format!("G1 {}", each(EVEN_LONG_MM + EVEN_SHORT_MM * i as f64)));
    }
    (setup, moves, (total_mm * s).round() as u64)
}

#[derive(Clone, Debug)]
pub struct EvenTrial {
    pub rate_hz: f64,
    pub verdicts: Vec<EvenVerdict>,
    /// Longest run of the step interrupt during the moves, entry to
    /// `reti`, handlers nested in it included, cycles.
    pub longest_step_isr: u64,
    /// Longest run of the step interrupt that began within X's judged
    /// window (the cruise, block boundaries included), cycles: the
    /// interrupt's longest path while cruising.
    pub longest_cruise_step_isr: u64,
}

impl EvenTrial {
    pub fn failure(&self) -> Option<String> {
        self.verdicts.iter().zip(["X", "Y", "Z"]).find_map(|(v, a)| v.failure.as_ref().map(|f| format!("{a} {f}")))
    }
}

/// The step interrupt's vector on the ATmega2560 (TIMER1_COMPA).
pub const STEP_VECTOR: u32 = 17;

/// Longest recorded run of the step interrupt (needs
/// [`Board::record_isr_intervals`]).
pub fn longest_step_isr(board: &Board) -> u64 {
    board
        .isr_intervals()
        .iter()
        .zip(board.isr_vector_numbers())
        .filter(|(_, v)| *v == STEP_VECTOR)
        .map(|(&(a, b), _)| b - a)
        .max()
        .unwrap_or(0)
}

/// One even-step trial on a booted board: the long move and the 30 short
/// ones on `axes` axes at `rate_hz` steps/s each, judged by [`judge_even`].
pub fn even_trial(board: &mut Board, axes: usize, rate_hz: f64) -> Result<EvenTrial, String> {
    let (setup, moves, steps) = even_job(axes, rate_hz);
    let setup_refs: Vec<&str> = setup.iter().map(String::as_str).collect();
    let replies = exchange(board, &setup_refs, 5.0)?;
    if let Some(error) = replies.iter().find(|r| r.starts_with("Error")) {
        return Err(format!("the firmware refused the trial set-up: {error}"));
    }
    board.clear_step_edges();
    board.record_isr_intervals(false);
    board.record_isr_intervals(true);
    let mut lines: Vec<&str> = moves.iter().map(String::as_str).collect();
    lines.push("M400");
    let timeout = steps as f64 / rate_hz * 3.0 + 2.0;
    let replies = exchange(board, &lines, timeout)?;
    if let Some(error) = replies.iter().find(|r| r.starts_with("Error")) {
        return Err(format!("the firmware refused a trial move: {error}"));
    }
    let verdicts = [X, Y, Z][..axes].iter().map(|&a| judge_even(board.step_edges(a), steps, rate_hz)).collect();
    let longest = longest_step_isr(board);
    let rises: Vec<u64> = board.step_edges(X).iter().filter(|e| e.rising).map(|e| e.cycle).collect();
    let window = (rises.get((steps as f64 * EVEN_WINDOW_FROM) as usize), rises.get((steps as f64 * (1.0 - EVEN_WINDOW_FROM)) as usize));
    let longest_cruise = match window {
        (Some(&from), Some(&to)) => board
            .isr_intervals()
            .iter()
            .zip(board.isr_vector_numbers())
            .filter(|&(&(a, _), v)| v == STEP_VECTOR && a >= from && a <= to)
            .map(|(&(a, b), _)| b - a)
            .max()
            .unwrap_or(0),
        _ => 0,
    };
    board.record_isr_intervals(false);
    Ok(EvenTrial { rate_hz, verdicts, longest_step_isr: longest, longest_cruise_step_isr: longest_cruise })
}

/// Rates the even-step search tries in order until one fails; then bisected.
pub const EVEN_RATES_HZ: &[f64] = &[10_000.0, 15_000.0, 20_000.0, 25_000.0, 30_000.0, 33_000.0, 36_000.0, 40_000.0, 45_000.0, 50_000.0];

#[derive(Clone, Debug)]
pub struct EvenRateResult {
    /// Highest rate per axis at which every interval was even.
    pub per_axis_hz: f64,
    pub axes: usize,
    pub limit: Option<(f64, String)>,
    pub trials: Vec<(f64, Option<String>, f64)>,
    /// Longest step-interrupt run over every trial.
    pub longest_step_isr: u64,
    pub log: PhaseLog,
}

impl EvenRateResult {
    pub fn total_hz(&self) -> f64 {
        self.per_axis_hz * self.axes as f64
    }
}

/// The highest per-axis rate whose cruise over block boundaries keeps
/// every interval within ±10 % of the median (see [`even_trial`]).
pub fn even_step_rate(elf: &Path, axes: usize) -> Result<EvenRateResult, String> {
    let mut config = RampsConfig::stock(115_200);
    config.endstops = far_endstops();
    let mut board = boot(elf, config)?;
    let (mut trials, mut best, mut limit, mut longest) = (Vec::new(), None, None, 0u64);
    let mut run = |board: &mut Board, rate: f64, trials: &mut Vec<(f64, Option<String>, f64)>| -> Result<Option<String>, String> {
        let trial = even_trial(board, axes, rate)?;
        longest = longest.max(trial.longest_step_isr);
        let worst = trial.verdicts.iter().map(|v| v.worst_deviation).fold(0.0, f64::max);
        let failure = trial.failure();
        trials.push((rate, failure.clone(), worst));
        Ok(failure)
    };
    for &rate in EVEN_RATES_HZ {
        match run(&mut board, rate, &mut trials)? {
            None => best = Some(rate),
            Some(why) => {
                limit = Some((rate, why));
                break;
            }
        }
    }
    let Some(mut low) = best else {
        let (rate, why) = limit.unwrap_or_default();
        return Err(format!("uneven already at {rate:.0} steps/s: {why}"));
    };
    if let Some((mut high, _)) = limit.clone() {
        for _ in 0..3 {
            let mid = ((low + high) / 2.0 / 250.0).round() * 250.0;
            if mid <= low || mid >= high {
                break;
            }
            match run(&mut board, mid, &mut trials)? {
                None => low = mid,
                Some(why) => {
                    high = mid;
                    limit = Some((mid, why));
                }
            }
        }
    }
    Ok(EvenRateResult { per_axis_hz: low, axes, limit, trials, longest_step_isr: longest, log: PhaseLog::of(&format!("even steps, {axes} axes"), &board) })
}

/// Feed of [`lines_per_s`]' chords, mm/s: 0.5 mm chords at 250 mm/s are
/// 500 a second of motion, more than the firmware takes.
pub const LINES_FEED_MM_S: f64 = 250.0;

/// Unnumbered `length_mm` chords of the bench spiral (see [`segments_of`])
/// sent one per `ok` at `baud`: lines acknowledged per second, from the
/// first chord's first byte to the last chord's `ok`; and the longest run
/// of the step interrupt meanwhile.
pub fn lines_per_s(elf: &Path, baud: u32, segments: usize, length_mm: f64) -> Result<(f64, u64, PhaseLog), String> {
    let mut config = RampsConfig::stock(baud);
    config.host = HostConfig::raw(baud);
    let mut board = boot(elf, config)?;
    board.record_isr_intervals(true);
    let mut job = segments_of(segments, length_mm);
    // The feed high enough that the motion never holds the host back
    // (the planner would fill): the firmware's line rate is measured.
    job[3] = format!("G1 F{:.0}", LINES_FEED_MM_S * 60.0);
    job.insert(0, format!("M203 X{LINES_FEED_MM_S:.0} Y{LINES_FEED_MM_S:.0}"));
    let header = 6;
    board.send(job.iter());
    let timeout = segments as f64 * 0.02 + 10.0;
    if !board.run_until_host_done(timeout) {
        return Err(format!("the stream did not finish within {timeout} s"));
    }
    let host = board.host();
    if let Some(error) = host.replies.iter().find(|r| r.text.starts_with("Error")) {
        return Err(format!("the firmware answered {:?}", error.text));
    }
    let chords: Vec<_> = host.sent.iter().filter(|s| s.job_index.is_some_and(|i| i >= header)).collect();
    let (first, last) = (chords.first().ok_or("nothing sent")?, chords.last().ok_or("nothing sent")?);
    let ok = &host.replies[last.ok_reply.ok_or("last chord without ok")?];
    let seconds = (ok.arrived_cycle - first.start_cycle) as f64 / f64::from(CPU_HZ);
    let rate = chords.len() as f64 / seconds;
    let longest = longest_step_isr(&board);
    Ok((rate, longest, PhaseLog::of(&format!("{length_mm} mm chords at {baud}"), &board)))
}
