//! Segment preparation: turns the planner's oldest block into timed
//! [`Segment`]s for the step interrupt, a little ahead of it (main loop).
//!
//! # Algorithm
//!
//! The block is measured in *events* (steps of its dominant motor). From the
//! current speed v₀, the events left D, the nominal speed V, the exit speed
//! vₓ (the next block's entry, re-read every segment because look-ahead may
//! raise it) and the acceleration A (all in events and seconds), the rest of
//! the block is a trapezoid: accelerate to V (or to the peak of a triangle),
//! cruise, decelerate to vₓ. Event e (counted from now) happens at the exact
//! time t(e) of that profile.
//!
//! The profile is cut into segments of k events. Within a segment the
//! interrupt's wait grows linearly (`interval`, `add`); the two are chosen
//! so that the first wait is exact and the segment's total time is exact:
//! add = 2·(T − k·I₀)/(k·(k − 1)). Segments are short where the speed
//! changes fast relative to itself (at most [`SPEED_RATIO`] apart) and at
//! most [`MAX_SEGMENT_S`] long, so the linear wait is a close fit and the
//! queued work (≤ 15 segments) stays re-plannable.
//!
//! Times are converted to 1/256 timer ticks; what rounding leaves over
//! (`time_debt_q8`) is taken off the next segment, so the step times never
//! drift from the profile by more than a fraction of a tick.
//!
//! Why not AVR446's ramp (c₀ = f·√(2/α)·0.676, cₙ = cₙ₋₁ − 2cₙ₋₁/(4n+1)),
//! which SPEC §3 mentions for the arm: its recurrence needs a division per
//! step in the interrupt, and the 0.676 fudge only corrects the
//! recurrence's own error. Here every machine gets the exact trapezoid: the
//! first step from rest comes after exactly √(2/A) (AVR446's c₀ without
//! the fudge), short moves become triangles, and the interrupt only adds.
//!
//! As it goes it writes the block's current speed and remaining length back
//! into the planner (`entry_speed_sqr`, `millimetres`), which is what lets
//! the look-ahead raise the exit speed of a block already under way.

use super::math::{clamp, max, min, speed_sqr_after, sqrt, to_i32, to_u32};
use super::planner::{Planner, SpeedSqr};
use super::stepper::{Segment, StepBlock, StepFeeder, TIMER_HZ};

/// Longest segment, seconds: bounds the queued (committed) motion to
/// ≈ 15 × 5 ms, so look-ahead can still change what follows.
pub const MAX_SEGMENT_S: f32 = 0.005;
/// Longest segment while cruising, seconds: the speed is constant, so a
/// longer segment is still exact, and the main loop prepares half as many.
pub const MAX_CRUISE_SEGMENT_S: f32 = 0.010;
/// Largest ratio of speeds at the two ends of an accelerating segment.
pub const SPEED_RATIO: f32 = 1.5;
/// Most segments [`Prep::fill`] queues per call when the interrupt is
/// about to run dry. Two: each costs the AVR ≈ 0.5–1 ms, and a line that
/// arrives meanwhile waits for them (with 16, lines of a starved stream
/// waited up to 30 ms for their `ok`); the main loop comes straight back
/// when it has nothing else to do.
const SEGMENTS_PER_FILL: usize = 2;
/// Step time [`Prep::fill`] keeps queued for the interrupt, in
/// [`QUEUED_UNIT_TICKS`], while the running block's exit speed may still
/// change: 25 ms. Enough to cover a main-loop pass of a print (a line
/// parsed and planned, a report written: a few ms), and no more: what is
/// queued is committed, and the look-ahead can only raise the speed of
/// blocks not yet cut into segments. Queuing the whole segment queue
/// (15 × 5–10 ms) committed the deceleration of the newest block before
/// the host's next line could arrive, and a stream of short lines slowed
/// itself down. Once the exit is final (`Planner::exit_is_final`) the
/// whole queue fills, so a long pass (`M500` writing the EEPROM) does not
/// stop the steps.
const QUEUED_TARGET: u16 = 25_000 / 32;
/// Below this much queued (10 ms), or with fewer than two segments,
/// [`Prep::fill`] queues up to [`SEGMENTS_PER_FILL`] at once; above it one
/// per call, so the main loop gets back to the serial port within one
/// segment's preparation.
const QUEUED_LOW: u16 = 10_000 / 32;
/// The unit of queued time: 64 timer ticks (32 µs).
const QUEUED_UNIT_TICKS: f32 = 64.0;
/// Q24.8 ticks per second.
const Q8_PER_S: f32 = TIMER_HZ as f32 * 256.0;
/// Slots of the queued-time mirror (the interrupt's segment queue).
const MIRROR_SLOTS: usize = super::stepper::SEGMENT_SLOTS;

/// The preparation state.
pub struct Prep {
    /// A block is under way (its `StepBlock` is queued).
    active: bool,
    events_left: u16,
    events_per_mm: f32,
    /// 1 / `events_per_mm`.
    mm_per_event: f32,
    /// The running block's nominal speed (events/s) and acceleration
    /// (events/s²), fixed for the block: computed once, not per segment,
    /// with their reciprocals (a float division costs the AVR three
    /// multiplications: the per-segment work multiplies instead).
    nominal: f32,
    inv_nominal: f32,
    accel: f32,
    inv_accel: f32,
    /// Speed at the end of the last queued segment, events/s.
    speed: f32,
    /// The exit speed² last read from the planner and its speed in
    /// events/s: the square root is taken only when look-ahead changed it,
    /// not for every segment.
    exit_sqr_seen: Option<SpeedSqr>,
    exit_speed: f32,
    /// The cruise's wait per event, 1/256 ticks (Q8_PER_S / `nominal`),
    /// and its events per segment.
    cruise_q8: f32,
    cruise_events: u16,
    /// The last cruise segment's event count and its reciprocal (a cruise
    /// repeats the same count, so the division is done once).
    cruise_k: u16,
    cruise_inv_k: f32,
    /// Queued time minus ideal time, 1/256 ticks.
    time_debt_q8: f32,
    /// Shortest wait the interrupt may be given, 1/256 ticks.
    pub min_interval_q8: u32,
    /// Blocks handed to the interrupt so far (wrapping; compare with
    /// `StepperStatus::blocks_done`).
    blocks_started: u16,
    /// The durations of the segments still in the interrupt's queue
    /// (units of [`QUEUED_UNIT_TICKS`]), a ring that mirrors it: `mirror_len`
    /// entries ending before `mirror_next`, summing to `queued_time`. The
    /// interrupt takes segments oldest first, so the mirror drops from its
    /// front as many as the queue lost.
    mirror: [u16; MIRROR_SLOTS],
    mirror_next: u8,
    mirror_len: u8,
    queued_time: u16,
}

impl Default for Prep {
    fn default() -> Self {
        Self::new()
    }
}

/// Where the rest of a block is in its trapezoid (events, events/s).
#[derive(Clone, Copy, Debug)]
struct Profile {
    start_speed: f32,
    accel: f32,
    /// 1 / `accel`, 1 / `peak`.
    inv_accel: f32,
    inv_peak: f32,
    peak: f32,
    /// Events from now where acceleration ends and deceleration begins.
    accel_end: f32,
    decel_start: f32,
}

impl Profile {
    /// `inv_accel` and `inv_nominal` are 1/`accel` and 1/`nominal`.
    fn new(start_speed: f32, distance: f32, nominal: f32, exit: f32, accel: f32, inv_accel: f32, inv_nominal: f32) -> Self {
        let v0_sqr = start_speed * start_speed;
        let peak_sqr_nominal = nominal * nominal;
        let exit_sqr = exit * exit;
        let half_inv_a = 0.5 * inv_accel;
        let accel_distance = (peak_sqr_nominal - v0_sqr) * half_inv_a;
        let decel_distance = (peak_sqr_nominal - exit_sqr) * half_inv_a;
        if start_speed <= nominal && accel_distance + decel_distance <= distance {
            return Self {
                start_speed,
                accel,
                inv_accel,
                inv_peak: inv_nominal,
                peak: nominal,
                accel_end: accel_distance,
                decel_start: distance - decel_distance,
            };
        }
        // A triangle: the peak where the two ramps meet. If the exit cannot
        // be reached (it always can, by the planner's passes, but rounding
        // happens) accelerate throughout; if the speed is too high to slow
        // to the exit (likewise), decelerate throughout.
        // (2·a·d + v0², as speed_sqr_after: addition commutes exactly.)
        let peak_sqr = max((speed_sqr_after(v0_sqr, accel, distance) + exit_sqr) * 0.5, v0_sqr);
        let peak = max(sqrt(peak_sqr), start_speed);
        let accel_end = clamp((peak_sqr - v0_sqr) * half_inv_a, 0.0, distance);
        let inv_peak = inverse(peak);
        Self { start_speed, accel, inv_accel, inv_peak, peak, accel_end, decel_start: accel_end }
    }

    /// Speed after `e` events.
    fn speed_at(&self, e: f32) -> f32 {
        if e <= self.accel_end {
            sqrt(speed_sqr_after(self.start_speed * self.start_speed, self.accel, e))
        } else if e <= self.decel_start {
            self.peak
        } else {
            // peak² − 2·a·(e − d) as peak² + 2·a·(d − e): the same bits
            // (d − e is −(e − d) exactly, and peak² is never −0).
            sqrt(max(speed_sqr_after(self.peak * self.peak, self.accel, self.decel_start - e), 0.0))
        }
    }

    /// Time from now to event `e`, seconds.
    fn time_at(&self, e: f32) -> f32 {
        self.time_at_speed(e, self.speed_at(e))
    }

    /// [`Self::time_at`] when the speed at `e` is known already (one
    /// square root fewer: each is hundreds of cycles on the AVR).
    fn time_at_speed(&self, e: f32, speed: f32) -> f32 {
        if e <= self.accel_end {
            return (speed - self.start_speed) * self.inv_accel;
        }
        let accel_time = (self.peak - self.start_speed) * self.inv_accel;
        if e <= self.decel_start {
            return accel_time + (e - self.accel_end) * self.inv_peak;
        }
        let cruise_time = (self.decel_start - self.accel_end) * self.inv_peak;
        accel_time + cruise_time + (self.peak - speed) * self.inv_accel
    }

    /// Events in the next segment (≥ 1, ≤ `left`).
    fn segment_events(&self, left: u16) -> u16 {
        let v = self.start_speed;
        let (mut target, boundary) = if self.accel_end >= 0.5 {
            let faster = min(v * SPEED_RATIO, self.peak);
            ((faster * faster - v * v) * 0.5 * self.inv_accel, self.accel_end)
        } else if self.decel_start >= 0.5 {
            // Cruising: constant speed up to the deceleration.
            (v * MAX_CRUISE_SEGMENT_S, self.decel_start)
        } else {
            let slower = v / SPEED_RATIO;
            ((v * v - slower * slower) * 0.5 * self.inv_accel, left as f32)
        };
        let within_time = v * MAX_SEGMENT_S + 0.5 * self.accel * MAX_SEGMENT_S * MAX_SEGMENT_S;
        if self.accel_end >= 0.5 || self.decel_start < 0.5 {
            target = min(target, within_time);
        }
        // End near the phase boundary rather than just past it.
        if target > boundary {
            target = boundary + 0.5;
        }
        // Below `left` here, so within u16 (NaN and negatives give 0, as
        // `as u16` would).
        let events = if target >= left as f32 { left } else { to_u32(target) as u16 };
        events.clamp(1, left.max(1))
    }
}

impl Prep {
    pub const fn new() -> Self {
        Self {
            active: false,
            events_left: 0,
            events_per_mm: 0.0,
            mm_per_event: 0.0,
            nominal: 0.0,
            inv_nominal: 0.0,
            accel: 0.0,
            inv_accel: 0.0,
            speed: 0.0,
            exit_sqr_seen: None,
            exit_speed: 0.0,
            cruise_q8: 0.0,
            cruise_events: 1,
            cruise_k: 0,
            cruise_inv_k: 0.0,
            time_debt_q8: 0.0,
            min_interval_q8: 8 << 8,
            blocks_started: 0,
            mirror: [0; MIRROR_SLOTS],
            mirror_next: 0,
            mirror_len: 0,
            queued_time: 0,
        }
    }

    /// A block is under way.
    pub fn is_active(&self) -> bool {
        self.active
    }

    /// Blocks handed to the interrupt so far (wrapping).
    pub fn blocks_started(&self) -> u16 {
        self.blocks_started
    }

    /// Forget the block under way (after a fault or an abandoned homing
    /// move; the interrupt drops what was queued).
    // Out of line: it has several callers (24 bytes).
    #[inline(never)]
    pub fn reset(&mut self) {
        self.active = false;
        self.events_left = 0;
        self.time_debt_q8 = 0.0;
        self.mirror_len = 0;
        self.queued_time = 0;
    }

    /// Drop from the mirror the segments the interrupt has taken since the
    /// last call (`queued`: what is left in its queue).
    fn forget_taken(&mut self, queued: usize) {
        while self.mirror_len as usize > queued {
            let oldest = (self.mirror_next as usize + MIRROR_SLOTS - self.mirror_len as usize) % MIRROR_SLOTS;
            self.queued_time = self.queued_time.saturating_sub(self.mirror[oldest]);
            self.mirror_len -= 1;
        }
    }

    /// A segment lasting `ticks_q8` went into the interrupt's queue.
    fn remember_queued(&mut self, ticks_q8: f32) {
        let units = to_u32(ticks_q8 * (1.0 / (256.0 * QUEUED_UNIT_TICKS))).min(u16::MAX as u32) as u16;
        if let Some(slot) = self.mirror.get_mut(self.mirror_next as usize) {
            *slot = units;
        }
        self.mirror_next = ((self.mirror_next as usize + 1) % MIRROR_SLOTS) as u8;
        self.mirror_len = (self.mirror_len + 1).min(MIRROR_SLOTS as u8);
        self.queued_time = self.queued_time.saturating_add(units);
    }

    /// Queue segments while there is room and something to prepare.
    /// Returns the number of segments queued.
    pub fn fill(&mut self, planner: &mut Planner, feeder: &mut StepFeeder<'_>) -> usize {
        let mut queued = 0;
        self.forget_taken(feeder.queued_segments());
        // Up to QUEUED_LOW as fast as possible (at most a queue's worth per
        // call: the main loop must come back to its other duties, and the
        // watchdog, even if the interrupt drains the queue as fast as this
        // fills it); from there to QUEUED_TARGET one segment per pass, so a
        // line that arrived waits for one segment's preparation at most.
        while queued < SEGMENTS_PER_FILL {
            let enough_segments = feeder.queued_segments() >= 2;
            if enough_segments && queued > 0 && self.queued_time >= QUEUED_LOW {
                break;
            }
            if enough_segments && self.queued_time >= QUEUED_TARGET && !planner.exit_is_final() {
                break;
            }
            let starts_block = !self.active;
            if starts_block {
                let Some(block) = planner.current() else { break };
                if !feeder.block_room() {
                    break;
                }
                let step_block = StepBlock {
                    steps: block.steps,
                    events: block.events,
                    direction: block.direction,
                    watch: block.watch,
                    watch_release: block.watch_release,
                };
                self.events_per_mm = block.events as f32 / block.millimetres;
                self.mm_per_event = block.millimetres / block.events as f32;
                self.speed = sqrt(block.entry.mm2_s2()) * self.events_per_mm;
                self.nominal = sqrt(block.nominal_speed_sqr) * self.events_per_mm;
                self.inv_nominal = inverse(self.nominal);
                self.accel = block.acceleration * self.events_per_mm;
                self.inv_accel = inverse(self.accel);
                self.cruise_q8 = Q8_PER_S * self.inv_nominal;
                // (≥ 1: a block of few events at a slow feed.)
                self.cruise_events = to_u32(max(self.nominal * MAX_CRUISE_SEGMENT_S, 1.0)).min(u16::MAX as u32) as u16;
                self.exit_sqr_seen = None;
                self.events_left = block.events;
                self.active = true;
                feeder.push_block(step_block);
                self.blocks_started = self.blocks_started.wrapping_add(1);
            } else if !feeder.segment_room() {
                break;
            }
            let exit_sqr = planner.exit_speed_sqr();
            let Some(block) = planner.current_mut() else { break };
            let segment = self.next_segment(exit_sqr, starts_block);
            feeder.push_segment(segment);
            queued += 1;
            block.millimetres = self.events_left as f32 * self.mm_per_event;
            block.ramp = SpeedSqr::from_mm2_s2(2.0 * block.acceleration * block.millimetres);
            let speed_mm = self.speed * self.mm_per_event;
            block.entry = SpeedSqr::from_mm2_s2(speed_mm * speed_mm);
            if self.events_left == 0 {
                self.active = false;
                planner.discard_current();
            }
        }
        queued
    }

    // Out of line: inlined into `fill` (and so into `Motion::poll`) the
    // float code spilled more registers, 172 bytes more on the AVR.
    #[inline(never)]
    fn next_segment(&mut self, exit_speed_sqr: SpeedSqr, starts_block: bool) -> Segment {
        if self.exit_sqr_seen != Some(exit_speed_sqr) {
            self.exit_sqr_seen = Some(exit_speed_sqr);
            self.exit_speed = sqrt(exit_speed_sqr.mm2_s2()) * self.events_per_mm;
        }
        if self.speed >= self.nominal && self.exit_speed >= self.nominal {
            return self.cruise_segment(starts_block);
        }
        let profile = Profile::new(
            self.speed,
            self.events_left as f32,
            self.nominal,
            self.exit_speed,
            self.accel,
            self.inv_accel,
            self.inv_nominal,
        );
        let events = profile.segment_events(self.events_left);
        let end_speed = profile.speed_at(events as f32);
        let duration = profile.time_at_speed(events as f32, end_speed);
        let first = if events == 1 { duration } else { profile.time_at(1.0) };
        let (interval, add, actual_q8) = self.fit(events, duration * Q8_PER_S - self.time_debt_q8, first * Q8_PER_S);
        self.time_debt_q8 += actual_q8 - duration * Q8_PER_S;
        self.remember_queued(actual_q8);
        self.speed = end_speed;
        self.events_left -= events;
        Segment { interval, add, events, starts_block }
    }

    /// The rest of the block runs at the nominal speed (the steady state of
    /// a slicer stream): equal waits, so neither square roots nor the
    /// trapezoid are needed. The wait is rounded to 1/256 tick with this
    /// segment's share of the time debt folded in, exactly as [`Self::fit`]
    /// does for `add` = 0.
    fn cruise_segment(&mut self, starts_block: bool) -> Segment {
        let events = self.cruise_events.min(self.events_left);
        if events != self.cruise_k {
            self.cruise_k = events;
            self.cruise_inv_k = 1.0 / events as f32;
        }
        let k = events as f32;
        let ideal_q8 = k * self.cruise_q8;
        let wait = max(round_f32((ideal_q8 - self.time_debt_q8) * self.cruise_inv_k), self.min_interval_q8 as f32);
        self.time_debt_q8 += k * wait - ideal_q8;
        self.remember_queued(k * wait);
        self.speed = self.nominal;
        self.events_left -= events;
        Segment { interval: to_u32(wait), add: 0, events, starts_block }
    }

    /// Interval and add (Q24.8) for `events` events lasting `total_q8`,
    /// the first `first_q8`; also the total the interrupt will really take.
    fn fit(&self, events: u16, total_q8: f32, first_q8: f32) -> (u32, i32, f32) {
        let k = events as f32;
        let min = self.min_interval_q8 as f32;
        let total_q8 = max(total_q8, min * k);
        if events == 1 {
            let interval = total_q8 + 0.5;
            let interval = to_u32(interval);
            return (interval, 0, interval as f32);
        }
        let pairs = k * (k - 1.0) * 0.5;
        // One division: 1/k = ((k − 1)/2) · (1/pairs).
        let inv_pairs = 1.0 / pairs;
        let inv_k = (k - 1.0) * 0.5 * inv_pairs;
        let mut add = round_f32((total_q8 - k * first_q8) * inv_pairs);
        // Keep every wait above the minimum: the last one is I₀ + (k−1)·add.
        let mut interval = round_f32((total_q8 - add * pairs) * inv_k);
        if interval < min || interval + add * (k - 1.0) < min {
            add = 0.0;
            interval = max(round_f32(total_q8 * inv_k), min);
        }
        let actual = k * interval + add * pairs;
        (to_u32(interval), to_i32(add), actual)
    }
}

/// 1/`value`, or 0 for a speed or acceleration that is not positive.
/// Out of line: three sites.
#[inline(never)]
fn inverse(value: f32) -> f32 {
    if value > 0.0 {
        1.0 / value
    } else {
        0.0
    }
}

fn round_f32(value: f32) -> f32 {
    super::math::round_to_i32(value) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_times_match_the_analytic_trapezoid() {
        // 1000 events, 0 → 10 000 ev/s at 100 000 ev/s²: 500 to accelerate,
        // 500 to stop: a triangle peaking at 10 000 after 0.1 s.
        let p = Profile::new(0.0, 1000.0, 20_000.0, 0.0, 100_000.0, 1.0 / 100_000.0, 1.0 / 20_000.0);
        assert!((p.peak - 10_000.0).abs() < 1.0);
        assert!((p.time_at(500.0) - 0.1).abs() < 1e-5);
        assert!((p.time_at(1000.0) - 0.2).abs() < 1e-5);
        // Trapezoid: cruise at 5000.
        let p = Profile::new(0.0, 1000.0, 5_000.0, 0.0, 100_000.0, 1.0 / 100_000.0, 1.0 / 5_000.0);
        assert!((p.accel_end - 125.0).abs() < 1e-3 && (p.decel_start - 875.0).abs() < 1e-3);
        assert!((p.time_at(1000.0) - (0.05 + 0.15 + 0.05)).abs() < 1e-5);
    }

    /// A long cruise: `fill` queues 10 ms segments until 25 ms are
    /// queued, then nothing more until the interrupt takes some; the
    /// rest of the block stays in the planner, where look-ahead can still
    /// change it.
    #[test]
    fn fill_keeps_a_bounded_time_queued_and_refills_as_segments_go() {
        use super::super::planner::{MotorLimits, PlannerMove};
        use super::super::stepper::{StepQueues, MOTORS};
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(Default::default());
        let mut planner = Planner::new();
        let limits = MotorLimits { max_rate: [100_000.0; MOTORS], max_accel: [1.0e6; MOTORS] };
        // 100 mm at 50 mm/s, 100 steps/mm: 5 000 events a second.
        let steps = [10_000, 0, 0, 0];
        let motion = PlannerMove { steps, millimetres: 100.0, unit: [1.0, 0.0, 0.0, 0.0], speed: 50.0, acceleration: 1.0e6, watch: 0, watch_release: false };
        planner.push(&motion, &limits).unwrap();
        let mut prep = Prep::new();
        let mut calls = 0;
        while prep.fill(&mut planner, &mut feeder) > 0 {
            calls += 1;
            assert!(calls < 20);
        }
        // The ramp's short segments, then 10 ms cruise segments: 25 ms
        // (to within the last segment) and not a whole queue's worth.
        let queued = feeder.queued_segments();
        let ms = prep.queued_time as f32 * QUEUED_UNIT_TICKS / 2000.0;
        assert!(prep.queued_time >= QUEUED_TARGET && ms < 35.0 && queued >= 2 && queued < 15, "{queued} segments, {ms} ms");
        assert_eq!(prep.fill(&mut planner, &mut feeder), 0);
        // The interrupt runs through the first segment: room for more.
        while feeder.queued_segments() == queued {
            generator.on_timer();
        }
        assert!(prep.fill(&mut planner, &mut feeder) >= 1);
        assert!(planner.current().is_some_and(|block| block.millimetres > 90.0));
    }

    /// Once the running block's exit can no longer change (the next block
    /// is planned for good), the whole segment queue fills: a long main-loop
    /// pass then does not stop the steps.
    #[test]
    fn fill_queues_further_once_the_exit_is_final() {
        use super::super::planner::{MotorLimits, PlannerMove};
        use super::super::stepper::{StepQueues, MOTORS, SEGMENT_SLOTS};
        let mut queues = StepQueues::new();
        let (mut feeder, _generator) = queues.split(Default::default());
        let mut planner = Planner::new();
        let limits = MotorLimits { max_rate: [100_000.0; MOTORS], max_accel: [1.0e6; MOTORS] };
        let motion = PlannerMove { steps: [10_000, 0, 0, 0], millimetres: 100.0, unit: [1.0, 0.0, 0.0, 0.0], speed: 50.0, acceleration: 1.0e6, watch: 0, watch_release: false };
        planner.push(&motion, &limits).unwrap();
        assert!(!planner.exit_is_final());
        planner.push(&motion, &limits).unwrap();
        // Straight on at the same feed: the second block enters at full
        // speed, its best, and is planned for good.
        assert!(planner.exit_is_final());
        let mut prep = Prep::new();
        for _ in 0..40 {
            prep.fill(&mut planner, &mut feeder);
        }
        assert_eq!(feeder.queued_segments(), SEGMENT_SLOTS - 1);
    }

    #[test]
    fn segments_cover_the_block_exactly() {
        let p = Profile::new(3000.0, 700.0, 8000.0, 1000.0, 200_000.0, 1.0 / 200_000.0, 1.0 / 8000.0);
        let mut left = 700_u16;
        let mut chunks = 0;
        while left > 0 {
            let k = Profile::new(p.speed_at((700 - left) as f32), left as f32, 8000.0, 1000.0, 200_000.0, 1.0 / 200_000.0, 1.0 / 8000.0).segment_events(left);
            assert!(k >= 1 && k <= left);
            left -= k;
            chunks += 1;
        }
        assert!(chunks < 40, "{chunks}");
    }
}
