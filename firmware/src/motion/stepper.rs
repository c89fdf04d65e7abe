//! The step generator: the only motion code that runs in the step-timer
//! interrupt.
//!
//! # What the interrupt does, and why it is cheap
//!
//! Everything that needs a multiplication, a division or a float (planning,
//! the trapezoid, the timing of every step) happens in the main loop, which
//! hands two kinds of ready-made work to the interrupt through lock-free
//! single-producer/single-consumer queues ([`StepQueues`]):
//!
//! - a [`StepBlock`] per planner block: the step count of every motor, the
//!   number of *events* (the largest step count: one event per step of the
//!   dominant motor), the direction bits and, for homing, the endstops to
//!   watch;
//! - [`Segment`]s: runs of events with a linearly changing wait, Klipper's
//!   `interval`/`add`/`count`. Each block is cut into one or more of them.
//!
//! Per event the interrupt does only
//!
//! ```text
//! wait   = frac + interval          (Q24.8 timer ticks; frac keeps the 1/256s)
//! interval += add ; events_left -= 1
//! mask = motors that step on every event
//!      | Bresenham of the others (16-bit compare, then add or subtract)
//! ```
//!
//! which is a handful of 8/16/32-bit additions on the AVR and no
//! multiplication. A single-motor move or a 45° diagonal skips the
//! Bresenham loop altogether. Taking the next segment is inline too, and
//! so is a new block in the same directions (see "The hand-over"); a
//! direction change, a homing block, a long wait, a start from idle and
//! the end of the queue are out of line
//! ([`StepGenerator::on_timer_general`]).
//!
//! # The hand-over: a block change as cheap as a segment change
//!
//! As in Grbl's segment buffer, everything a block change needs is
//! prepared in the main loop, and the interrupt only moves along:
//!
//! - [`StepFeeder::push_block`] turns the [`StepBlock`] into a
//!   `PreparedBlock` (Bresenham thresholds, the motors that step on every
//!   event and those that step on some, the endstops ahead) in the block
//!   queue, and keeps its head;
//! - [`StepFeeder::push_segment`] copies that head (a start marker, the
//!   direction bits, the two motor classes, the endstops ahead: 5 bytes)
//!   into the block's first segment;
//! - the interrupt's segment change (inline, interrupts off) sees the
//!   marker, checks that the block keeps the directions on the pins and
//!   that no homing stop is pending, takes the head from the segment with
//!   the segment's own fields, releases the finished block's slot (the
//!   next block is already in place behind it: the running block is
//!   always the front of the block queue) and, only for motors that run
//!   the Bresenham, copies their steps and thresholds from the record.
//!
//! Invariants of the hand-over: a block is pushed before its first
//! segment, so the record is there when its segment is; the running block
//! is the front slot of the block queue from its first event to its last,
//! and only the interrupt releases it; the segments of a block sum to its
//! events (`prep` cuts them so), so at its end every Bresenham counter is
//! 0 again (invariant 1) and the next block starts from there without a
//! reset; a block that changes a direction, or a homing block, takes the
//! general path, which gives the direction its set-up lead and resets
//! the homing stops.
//!
//! On the ATmega2560 (simavr, the bench's `even_steps` example) an
//! ordinary event costs the step interrupt ≈ 240 cycles from entry to
//! `reti`, one that takes the block's next segment ≈ 340, one that takes
//! the next block ≈ 400–420 (≈ 620 when it ran in the cold path). The
//! board splits `on_timer` into [`StepGenerator::ordinary_ready`]
//! and [`StepGenerator::ordinary_event`], inline, and
//! `on_timer_general`, which it reaches through a call that saves
//! registers on that path only: a call the compiler can see anywhere in an
//! AVR interrupt handler makes it save every call-clobbered register on
//! every run (see the board's `stepping` module).
//!
//! # Invariants
//!
//! 1. All motors of a block start and end together: the multi-motor DDA is
//!    Bresenham in its truncating form, motor i steps at event
//!    e = ⌈j·n/sᵢ⌉ (j = 1..sᵢ), so every motor's last step falls on the
//!    block's last event, and a motor is never ahead of the ideal line and at
//!    most one step behind it. Counters are 16 bit: blocks have at most
//!    65 535 events (the planner splits longer moves).
//! 2. Timing never drifts: waits are summed in 1/256 ticks and only the whole
//!    ticks leave ([`TimerAction::next_interval_ticks`]), so the step times
//!    are exactly the running sum of the segments' intervals, which the main
//!    loop computes with the same integer arithmetic (see `prep`).
//! 3. A direction change is never presented with a step: when a block turns a
//!    motor round, the new direction bits come in an action without steps at
//!    least `dir_setup_ticks` before the first step of the block.
//! 4. The interrupt never blocks and never fails: with no work queued it
//!    returns an idle poll interval; a block whose segments have not arrived
//!    in time (an underrun, which the main loop must prevent) simply waits.
//!
//! # How the board uses it
//!
//! On every compare interrupt of the step timer (2 MHz on the Mega 2560):
//!
//! ```text
//! if gen.endstop_mask() != 0 { gen.on_endstops(read_endstop_bits()) }
//! let (steps, dirs) = gen.pins_now();          (the event computed last time)
//! write DIR pins  = dirs                       (bit i: motor i)
//! raise STEP pins of steps
//! let ticks = gen.on_timer().next_interval_ticks
//!     (or: if gen.ordinary_ready() { gen.ordinary_event() }
//!          else { match gen.on_timer_general() { 0 => gen.ordinary_event(), t => t } })
//! OCR += ticks                                 (relative to the last compare)
//! lower STEP pins once the configured pulse width has passed
//! ```
//!
//! Directions are already inverted for the wiring ([`StepperConfig`]).

use crate::ring::{Consumer, Producer, Ring};

/// Motors the core drives: X/A/X-screw, Y/B/elbow, Z/C/shoulder, E.
pub const MOTORS: usize = 4;
/// Step timer frequency (16 MHz / 8 on the Mega 2560).
pub const TIMER_HZ: u32 = 2_000_000;
/// Fractional bits of [`Segment::interval`] and [`Segment::add`].
pub const INTERVAL_FRACTION_BITS: u32 = 8;
/// Slots of the segment queue (one stays empty: 15 usable).
pub const SEGMENT_SLOTS: usize = 16;
/// Slots of the block queue (15 usable).
pub const BLOCK_SLOTS: usize = 16;
/// Interval of the interrupt when there is nothing to do: 1 ms.
pub const IDLE_POLL_TICKS: u16 = 2000;
/// Waits longer than 16 bits are cut into pieces of this many ticks.
const LONG_WAIT_PIECE: u32 = 0x8000;

/// A run of events with a linearly changing wait.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Segment {
    /// Wait before this segment's first event, in 1/256 timer ticks.
    pub interval: u32,
    /// Added to the wait after each event, 1/256 ticks (negative: faster).
    pub add: i32,
    /// Events in this segment (≥ 1).
    pub events: u16,
    /// The first segment of the next [`StepBlock`].
    pub starts_block: bool,
}

/// What the interrupt needs to know about one planner block.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepBlock {
    /// Steps of every motor (≤ `events`).
    pub steps: [u16; MOTORS],
    /// Events: the largest entry of `steps`.
    pub events: u16,
    /// Bit i set: motor i moves in its positive direction.
    pub direction: u8,
    /// Endstop bits that stop their motor during this block (homing):
    /// bit i is motor i's min endstop, bit 4 + i its max endstop.
    pub watch: u8,
    /// Stop a watched motor when its endstop *releases* instead.
    pub watch_release: bool,
}

/// A [`StepBlock`] as the interrupt consumes it, prepared by the main loop
/// ([`StepFeeder::push_block`]): the Bresenham thresholds, which motors
/// step on every event and which on some, the endstops ahead. The
/// interrupt never copies it whole: the running block stays in its queue
/// slot (the front of the block queue) until its last event, and the
/// interrupt reads it there, as Grbl's segments point at their block's
/// data (see "The hand-over" in the module comment).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct PreparedBlock {
    /// Steps of every motor (≤ `events`).
    steps: [u16; MOTORS],
    /// events − steps: a motor steps when its counter reaches this.
    thresholds: [u16; MOTORS],
    events: u16,
    /// Motors with as many steps as events (no Bresenham), and the others
    /// that move (Bresenham).
    always: u8,
    minor: u8,
    /// `always | minor`.
    moving: u8,
    /// Direction bits of the moving motors (the others 0).
    direction: u8,
    /// Endstops the block moves towards (bit i: motor i's min, 4 + i: max).
    ahead: u8,
    watch: u8,
    watch_release: bool,
}

impl PreparedBlock {
    /// The main loop's part of a block change.
    fn prepare(block: &StepBlock) -> Self {
        let mut prepared = Self { events: block.events, watch: block.watch, watch_release: block.watch_release, ..Self::default() };
        for motor in 0..MOTORS {
            let steps = block.steps[motor].min(block.events);
            prepared.steps[motor] = steps;
            prepared.thresholds[motor] = block.events - steps;
            if steps == block.events && steps != 0 {
                prepared.always |= 1 << motor;
            } else if steps != 0 {
                prepared.minor |= 1 << motor;
            }
        }
        prepared.moving = prepared.always | prepared.minor;
        prepared.direction = block.direction & prepared.moving;
        let negative = prepared.moving & !prepared.direction;
        prepared.ahead = negative | (prepared.direction << 4);
        prepared
    }
}

/// A [`Segment`] as it waits in the queue: the main loop's description,
/// and for the first segment of a block the little the interrupt needs to
/// change blocks without reading the block record first (copied in by
/// [`StepFeeder::push_segment`] from the block pushed last). 15 bytes: 16
/// slots stay within 256 bytes, so the AVR finds a slot with one 8-bit
/// multiply.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct QueuedSegment {
    interval: u32,
    add: i32,
    events: u16,
    /// [`NOT_A_START`], [`CHEAP_START`] or [`GENERAL_START`].
    start: u8,
    /// The new block's direction bits, motor classes and endstops ahead
    /// ([`PreparedBlock`]'s fields of the same names).
    direction: u8,
    always: u8,
    minor: u8,
    ahead: u8,
}

/// [`QueuedSegment::start`]: the segment continues the running block.
const NOT_A_START: u8 = 0;
/// It starts a block the interrupt may take inline (if its directions
/// match the pins: the interrupt checks).
const CHEAP_START: u8 = 1;
/// It starts a block that needs the general path: a homing block (its
/// endstops to watch and its stops to reset).
const GENERAL_START: u8 = 2;

/// The head of the block pushed last, kept by the feeder for its first
/// segment.
#[derive(Clone, Copy, Debug, Default)]
struct BlockHead {
    start: u8,
    direction: u8,
    always: u8,
    minor: u8,
    ahead: u8,
}

/// The interrupt's answer: what to do now and when to come back.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TimerAction {
    /// Motors to step now (bit i: motor i).
    pub step_mask: u8,
    /// Direction pin levels to hold from now on (before stepping).
    pub dir_mask: u8,
    /// Ticks from this interrupt's compare time to the next one (≥ 1).
    pub next_interval_ticks: u16,
}

/// Why the generator stopped everything.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepFault {
    /// An endstop configured as a hard limit was hit while moving towards
    /// it (the bits of the endstops that were hit).
    LimitHit(u8),
    /// The main loop or an emergency stopped motion (`M410`, `M112`).
    Stopped,
}

/// Board and driver facts the interrupt needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepperConfig {
    /// Direction bits to invert for the wiring (bit i: motor i).
    pub dir_invert: u8,
    /// Least time from a direction change to the next step, ticks.
    pub dir_setup_ticks: u16,
    /// Endstops that stop all motion when hit outside homing, if the move
    /// goes towards them (same bit layout as [`StepBlock::watch`]).
    pub limit_endstops: u8,
}

impl StepperConfig {
    /// 5 µs direction set-up covers the TB6600 and the CL86T;
    /// A4988/DRV8825 need 0.2/0.65.
    pub const DEFAULT: Self = Self { dir_invert: 0, dir_setup_ticks: 10, limit_endstops: 0 };
}

impl Default for StepperConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What the main loop learns from the interrupt (read in a critical
/// section on the board: [`StepGenerator::status`] only copies fields).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepperStatus {
    /// Blocks finished or abandoned so far (wrapping).
    pub blocks_done: u16,
    /// Steps still queued or running.
    pub busy: bool,
    /// Set until [`StepGenerator::clear_fault`].
    pub fault: Option<StepFault>,
    /// Motors that a watched endstop stopped in the last homing block.
    pub stopped: u8,
    /// Steps each stopped motor made in that block before it stopped.
    pub stopped_steps: [u16; MOTORS],
    /// Times a block ran out of segments (the main loop was late).
    pub underruns: u16,
}

/// The storage of both queues; the board keeps it in a `static`.
pub struct StepQueues {
    segments: Ring<QueuedSegment, SEGMENT_SLOTS>,
    blocks: Ring<PreparedBlock, BLOCK_SLOTS>,
}

impl Default for StepQueues {
    fn default() -> Self {
        Self::new()
    }
}

impl StepQueues {
    pub const fn new() -> Self {
        Self { segments: Ring::new(), blocks: Ring::new() }
    }

    /// The main loop's end and the interrupt's end.
    pub fn split(&mut self, config: StepperConfig) -> (StepFeeder<'_>, StepGenerator<'_>) {
        let (segment_in, segment_out) = self.segments.split();
        let (block_in, block_out) = self.blocks.split();
        (StepFeeder { segments: segment_in, blocks: block_in, head: BlockHead::default() }, StepGenerator::new(segment_out, block_out, config))
    }
}

/// The main loop's end of the queues.
pub struct StepFeeder<'a> {
    segments: Producer<'a, QueuedSegment, SEGMENT_SLOTS>,
    blocks: Producer<'a, PreparedBlock, BLOCK_SLOTS>,
    /// The block pushed last, for its first segment.
    head: BlockHead,
}

impl StepFeeder<'_> {
    /// Room for one more segment.
    pub fn segment_room(&self) -> bool {
        self.segments.ready()
    }

    /// Room for a new block and its first segment.
    pub fn block_room(&self) -> bool {
        self.segments.ready() && self.blocks.ready()
    }

    /// Queue a segment (`false` if full).
    pub fn push_segment(&mut self, segment: Segment) -> bool {
        let mut queued = QueuedSegment { interval: segment.interval, add: segment.add, events: segment.events, ..QueuedSegment::default() };
        if segment.starts_block {
            let head = self.head;
            queued.start = head.start;
            queued.direction = head.direction;
            queued.always = head.always;
            queued.minor = head.minor;
            queued.ahead = head.ahead;
        }
        self.segments.enqueue(queued).is_ok()
    }

    /// Queue a block; its first segment must follow with `starts_block`.
    /// The block's set-up for the interrupt (Bresenham thresholds, motor
    /// classes, endstops ahead) is computed here, in the main loop.
    pub fn push_block(&mut self, block: StepBlock) -> bool {
        let prepared = PreparedBlock::prepare(&block);
        if !self.blocks.ready() || self.blocks.enqueue(prepared).is_err() {
            return false;
        }
        self.head = BlockHead {
            start: if prepared.watch == 0 { CHEAP_START } else { GENERAL_START },
            direction: prepared.direction,
            always: prepared.always,
            minor: prepared.minor,
            ahead: prepared.ahead,
        };
        true
    }

    /// Segments waiting for the interrupt.
    pub fn queued_segments(&self) -> usize {
        self.segments.len()
    }
}

/// The interrupt's end: a pure state machine driven by [`Self::on_timer`].
pub struct StepGenerator<'a> {
    segments: Consumer<'a, QueuedSegment, SEGMENT_SLOTS>,
    /// The running block stays in place at the front of this queue (while
    /// `in_block`: its slot is released when the block finishes).
    blocks: Consumer<'a, PreparedBlock, BLOCK_SLOTS>,
    config: StepperConfig,

    // The running segment.
    interval: u32,
    add: i32,
    events_left: u16,
    frac: u8,

    // The running block's Bresenham state: its steps and thresholds copied
    // at the block change (read through the block pointer, the per-event
    // path kept two more registers, 8 cycles an event: the one-stepper
    // rate that stays on time fell from 50 000 to 47 500 steps/s).
    steps: [u16; MOTORS],
    thresholds: [u16; MOTORS],
    counters: [u16; MOTORS],
    /// Motors that step on every event (as many steps as events): no
    /// Bresenham needed. The others (`minor`) run the counters.
    always: u8,
    minor: u8,
    /// Events of the segments of this block taken so far: the events done
    /// are `events_started - events_left` ([`Self::events_done`]), so the
    /// per-event path counts only `events_left`.
    events_started: u16,
    direction: u8,
    /// [`Self::endstop_mask`].
    endstops_to_read: u8,
    in_block: bool,
    discarding: bool,
    /// `in_block && !discarding && fault.is_none()`, kept as one byte for
    /// the ordinary segment change ([`Self::refresh_continuable`] after
    /// every change of the three).
    continuable: bool,

    // The event computed ahead, fired by the next call.
    pending_mask: u8,
    pending_dir: u8,
    /// Ticks still to wait before the pending event fires.
    long_wait: u32,
    /// `long_wait != 0`, kept as one byte: the interrupt tests it twice an
    /// event, and a 32-bit test costs the AVR four loads.
    long_waiting: bool,

    stopped: u8,
    stopped_steps: [u16; MOTORS],
    fault: Option<StepFault>,
    blocks_done: u16,
    underruns: u16,
    /// X's and Y's step positions at the start of the running block, for
    /// the encoder loops (SPEC §1): counted from boot, not from any homing
    /// zero, and kept at block granularity so that the per-event path pays
    /// nothing for them (see [`AxisProgress`]).
    #[cfg(feature = "encoders")]
    origin: [i32; ENCODED_MOTORS],
}

/// X and Y: the motors an encoder watches (SPEC §1).
#[cfg(feature = "encoders")]
pub const ENCODED_MOTORS: usize = 2;

/// A copy of what the interrupt knows about X's and Y's progress, taken
/// with interrupts off (a few bytes); [`Self::positions`] does the
/// arithmetic afterwards, outside the lock.
#[cfg(feature = "encoders")]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AxisProgress {
    origin: [i32; ENCODED_MOTORS],
    steps: [u16; ENCODED_MOTORS],
    events: u16,
    fired: u16,
    direction: u8,
    stopped: u8,
    stopped_steps: [u16; ENCODED_MOTORS],
}

#[cfg(feature = "encoders")]
impl AxisProgress {
    /// X's and Y's step positions now (since boot), within one step: the
    /// steps of a block are spread evenly over its events (Bresenham), so
    /// after `fired` of `events` a motor has made `fired·steps/events`.
    pub fn positions(&self) -> [i32; ENCODED_MOTORS] {
        let mut positions = self.origin;
        for motor in 0..ENCODED_MOTORS {
            let done = block_steps_done(self, motor);
            positions[motor] = if self.direction & (1 << motor) != 0 {
                positions[motor].wrapping_add(done)
            } else {
                positions[motor].wrapping_sub(done)
            };
        }
        positions
    }
}

/// Steps `motor` has made in the block `progress` describes.
#[cfg(feature = "encoders")]
fn block_steps_done(progress: &AxisProgress, motor: usize) -> i32 {
    if progress.stopped & (1 << motor) != 0 {
        return i32::from(progress.stopped_steps[motor]);
    }
    let steps = u32::from(progress.steps[motor]);
    if progress.events == 0 || progress.fired >= progress.events {
        return steps as i32;
    }
    (u32::from(progress.fired) * steps / u32::from(progress.events)) as i32
}

impl<'a> StepGenerator<'a> {
    fn new(
        segments: Consumer<'a, QueuedSegment, SEGMENT_SLOTS>,
        blocks: Consumer<'a, PreparedBlock, BLOCK_SLOTS>,
        config: StepperConfig,
    ) -> Self {
        Self {
            segments,
            blocks,
            config,
            interval: 0,
            add: 0,
            events_left: 0,
            frac: 0,
            steps: [0; MOTORS],
            thresholds: [0; MOTORS],
            counters: [0; MOTORS],
            always: 0,
            minor: 0,
            events_started: 0,
            direction: 0,
            endstops_to_read: 0,
            in_block: false,
            discarding: false,
            continuable: false,
            pending_mask: 0,
            pending_dir: 0,
            long_wait: 0,
            long_waiting: false,
            stopped: 0,
            stopped_steps: [0; MOTORS],
            fault: None,
            blocks_done: 0,
            underruns: 0,
            #[cfg(feature = "encoders")]
            origin: [0; ENCODED_MOTORS],
        }
    }

    /// X's and Y's progress for the encoder loops (copy it with the step
    /// interrupt held off, then call [`AxisProgress::positions`]).
    #[cfg(feature = "encoders")]
    pub fn axis_progress(&self) -> AxisProgress {
        let mut progress = AxisProgress { origin: self.origin, ..AxisProgress::default() };
        if self.in_block {
            let block = self.running_block();
            progress.steps = [block.steps[0], block.steps[1]];
            progress.events = block.events;
            // The pending event has not fired yet.
            progress.fired = self.events_done() - (self.pending_mask != 0) as u16;
            progress.direction = self.direction;
            progress.stopped = self.stopped;
            progress.stopped_steps = [self.stopped_steps[0], self.stopped_steps[1]];
        }
        progress
    }

    /// What the next [`Self::on_timer`] call fires (STEP mask, DIR levels),
    /// without computing anything: the board puts these on the pins first
    /// and only then calls `on_timer`, so the step edges keep their times
    /// whatever the computation of the next event costs.
    #[inline(always)]
    pub fn pins_now(&self) -> (u8, u8) {
        let dir_mask = self.pending_dir ^ self.config.dir_invert;
        if self.long_waiting {
            (0, dir_mask)
        } else {
            (self.pending_mask & !self.stopped, dir_mask)
        }
    }

    /// The step-timer interrupt: fire the event computed last time, compute
    /// the next one.
    #[inline(always)]
    pub fn on_timer(&mut self) -> TimerAction {
        let (step_mask, dir_mask) = self.pins_now();
        let mut next_interval_ticks = if self.ordinary_ready() { 0 } else { self.on_timer_general() };
        if next_interval_ticks == 0 {
            next_interval_ticks = self.ordinary_event();
        }
        TimerAction { step_mask, dir_mask, next_interval_ticks }
    }

    /// The next call is an ordinary event: no long wait under way and
    /// events left in the running segment, or the next queued segment
    /// continues the running block and has just been taken (the common
    /// segment change, done here so that it stays cheap). Then
    /// [`Self::ordinary_event`] is all `on_timer` does after the pins;
    /// otherwise [`Self::on_timer_general`]. A board whose interrupt pays
    /// for every register a call could clobber (the AVR) calls this inline
    /// and reaches `on_timer_general` through a call that saves registers
    /// on that path alone.
    #[inline(always)]
    pub fn ordinary_ready(&mut self) -> bool {
        !self.long_waiting && (self.events_left != 0 || self.take_next_segment_of_block())
    }

    /// STEP mask of the pending event when [`Self::ordinary_ready`]
    /// (`pins_now().0` without the long-wait test).
    #[inline(always)]
    pub fn ordinary_step_mask(&self) -> u8 {
        self.pending_mask & !self.stopped
    }

    /// What `on_timer` does after the pins when [`Self::ordinary_ready`]
    /// is false: a piece of a long wait, or a segment change that the
    /// ordinary path does not cover (new block, direction change, end of
    /// the queue, discarding, fault). Returns the ticks to the next call,
    /// or 0: "events are left in the running segment: compute the next
    /// with [`Self::ordinary_event`]" (every wait this returns is ≥ 1).
    /// Out of line: the per-event path keeps few registers.
    #[inline(never)]
    pub fn on_timer_general(&mut self) -> u16 {
        if self.long_waiting {
            return self.wait_longer();
        }
        if self.events_left != 0 {
            return 0;
        }
        self.next_segment()
    }

    /// The ordinary event: one more event of the running segment (call
    /// only when [`Self::ordinary_ready`], or after
    /// [`Self::on_timer_general`] returned 0). Returns the ticks to the
    /// next call.
    #[inline(always)]
    pub fn ordinary_event(&mut self) -> u16 {
        self.next_event()
    }

    /// The hot path: one more event of the running segment. Always
    /// inline: out of line (as `opt-level = "z"` chose) it cost the AVR's
    /// step interrupt a call and six register saves, ~33 cycles an event.
    /// The Bresenham step comes first, so that nothing is held in registers
    /// across it; `sum >> 24 != 0` is `ticks > 0xFFFF` as one byte test.
    #[inline(always)]
    fn next_event(&mut self) -> u16 {
        self.pending_mask = self.bresenham();
        self.events_left -= 1;
        let sum = self.frac as u32 + self.interval;
        self.frac = sum as u8;
        self.interval = self.interval.wrapping_add(self.add as u32);
        if sum >> 24 != 0 {
            self.set_long_wait((sum >> INTERVAL_FRACTION_BITS) - LONG_WAIT_PIECE);
            return LONG_WAIT_PIECE as u16;
        }
        (sum >> INTERVAL_FRACTION_BITS) as u16
    }

    #[inline(always)]
    fn bresenham(&mut self) -> u8 {
        if self.minor == 0 {
            // One motor, or a 45° diagonal: nothing to decide.
            return self.always;
        }
        self.minor_steps() | self.always
    }

    /// Bresenham for the motors that step on some events only.
    #[inline(always)]
    fn minor_steps(&mut self) -> u8 {
        let mut mask = 0;
        let mut bit = 1;
        for motor in 0..MOTORS {
            if self.minor & bit != 0 {
                let counter = self.counters[motor];
                let threshold = self.thresholds[motor];
                if counter >= threshold {
                    self.counters[motor] = counter - threshold;
                    mask |= bit;
                } else {
                    self.counters[motor] = counter + self.steps[motor];
                }
            }
            bit <<= 1;
        }
        mask
    }

    /// A wait too long for 16 bits, or the lead of a direction change: an
    /// action without steps that presents the coming event's directions.
    #[cold]
    fn wait_longer(&mut self) -> u16 {
        let piece = if self.long_wait > 0xFFFF { LONG_WAIT_PIECE } else { self.long_wait };
        self.set_long_wait(self.long_wait - piece);
        piece as u16
    }

    /// The segment change, kept cheap, and the block change with it: the
    /// next segment continues the running block, or starts the next block
    /// in the same directions (no fault, not discarding, no homing). Copies
    /// the segment's fields straight from the queue slot and frees it; at a
    /// block change the block's head comes with the segment and the block
    /// record is only reached for its Bresenham figures, after the segment
    /// is done with (see the module comment, "The hand-over"). `false`
    /// leaves everything to [`Self::next_segment`]. Inline in the ordinary
    /// path (see [`Self::ordinary_ready`]): behind a call it would cost the
    /// AVR's interrupt its register saves on every event.
    #[inline(always)]
    fn take_next_segment_of_block(&mut self) -> bool {
        debug_assert_eq!(self.continuable, self.in_block && !self.discarding && self.fault.is_none());
        if !self.continuable {
            return false;
        }
        self.segments.take_front_if(|segment| {
            if segment.events == 0 {
                return false;
            }
            let start = segment.start;
            if start != NOT_A_START {
                // The running block must have run to its end (then every
                // Bresenham counter is back at 0: invariant 1), and the new
                // one must keep the directions (else the general path gives
                // the direction change its lead).
                // (That the segments covered the block exactly is the main
                // loop's promise: `prep` cuts every block into segments
                // that sum to its events.)
                if start != CHEAP_START || self.stopped != 0 {
                    return false;
                }
                if (segment.direction ^ self.pending_dir) & (segment.always | segment.minor) != 0 {
                    return false;
                }
                self.always = segment.always;
                self.minor = segment.minor;
                self.endstops_to_read = self.config.limit_endstops & segment.ahead;
                self.events_started = 0;
            }
            // Events first: then no register holds them during the copy.
            self.events_left = segment.events;
            self.events_started = self.events_started.wrapping_add(segment.events);
            self.interval = segment.interval;
            self.add = segment.add;
            if start == NOT_A_START {
                return true;
            }
            // The encoder loops' origin moves by the whole block: two
            // additions, no division (the block ran to its end).
            #[cfg(feature = "encoders")]
            if let Some(done) = self.blocks.front() {
                for motor in 0..ENCODED_MOTORS {
                    let steps = i32::from(done.steps[motor]);
                    self.origin[motor] = if self.direction & (1 << motor) != 0 {
                        self.origin[motor].wrapping_add(steps)
                    } else {
                        self.origin[motor].wrapping_sub(steps)
                    };
                }
            }
            // The running block's slot goes back to the main loop; the next
            // one, in place behind it (the feeder pushes a block before its
            // first segment), is the running block from now on.
            self.blocks.release();
            self.blocks_done = self.blocks_done.wrapping_add(1);
            if self.minor == 0 {
                return true;
            }
            // The block record is needed only for the Bresenham's figures,
            // and only after the segment is done with: the steps and
            // thresholds of the motors that step on some events.
            let Some(next) = self.blocks.front() else {
                // If it is missing the queues are corrupt: stop rather than
                // guess (the general path then drops everything).
                // (`continuable` by hand: a call here would make the AVR's
                // handler save more registers on every event.)
                self.fault = Some(StepFault::Stopped);
                self.continuable = false;
                return false;
            };
            // A motor at a time, unrolled: every destination a fixed address
            // and only the record's pointer held (a bulk copy holds 16
            // registers or calls `memcpy`, a loop two more pointers: either
            // makes the AVR's handler save more registers on every event).
            macro_rules! copy_bresenham {
                ($($motor:literal)*) => {$(
                    if next.minor & (1 << $motor) != 0 {
                        self.steps[$motor] = next.steps[$motor];
                        self.thresholds[$motor] = next.thresholds[$motor];
                    }
                )*};
            }
            const _: () = assert!(MOTORS == 4);
            copy_bresenham!(0 1 2 3);
            true
        })
    }

    fn set_long_wait(&mut self, ticks: u32) {
        self.long_wait = ticks;
        self.long_waiting = ticks != 0;
    }

    /// The running segment is used up: take the next one (and its block).
    /// Out of line, so that the per-event path keeps few registers.
    #[inline(never)]
    fn next_segment(&mut self) -> u16 {
        self.pending_mask = 0;
        if self.fault.is_some() {
            self.drain();
            return IDLE_POLL_TICKS;
        }
        loop {
            let Some(segment) = self.segments.dequeue() else {
                if self.in_block && self.events_done() != self.running_block().events {
                    if !self.discarding {
                        self.underruns = self.underruns.wrapping_add(1);
                    }
                } else if self.in_block {
                    self.finish_block();
                }
                return IDLE_POLL_TICKS;
            };
            if segment.start != NOT_A_START {
                if self.in_block {
                    self.finish_block();
                }
                if self.blocks.front().is_none() {
                    // The feeder pushes the block first; if it is missing
                    // the queues are corrupt: stop rather than guess.
                    self.fault = Some(StepFault::Stopped);
                    self.refresh_continuable();
                    return IDLE_POLL_TICKS;
                }
                self.start_block();
            } else if self.discarding || !self.in_block {
                continue;
            }
            self.interval = segment.interval;
            self.add = segment.add;
            self.events_left = segment.events;
            self.events_started = self.events_started.wrapping_add(segment.events);
            if self.events_left == 0 {
                continue;
            }
            break;
        }
        let dir_changes = self.direction != self.pending_dir;
        let ticks = self.next_event_ticks();
        self.pending_dir = self.direction;
        if !dir_changes {
            return self.split_wait(ticks);
        }
        // Present the new directions at least `dir_setup_ticks` before the
        // step: an empty action first, the step after the rest of the wait.
        let setup = self.config.dir_setup_ticks.max(1) as u32;
        let lead = if ticks > setup + 1 { ticks - setup } else { 1 };
        let lead = lead.min(LONG_WAIT_PIECE);
        self.set_long_wait((ticks - lead.min(ticks)).max(setup));
        lead as u16
    }

    /// Like [`Self::next_event`], returning the whole wait.
    fn next_event_ticks(&mut self) -> u32 {
        self.pending_mask = self.bresenham();
        self.events_left -= 1;
        let sum = self.frac as u32 + self.interval;
        self.frac = sum as u8;
        self.interval = self.interval.wrapping_add(self.add as u32);
        (sum >> INTERVAL_FRACTION_BITS).max(1)
    }

    fn split_wait(&mut self, ticks: u32) -> u16 {
        if ticks > 0xFFFF {
            self.set_long_wait(ticks - LONG_WAIT_PIECE);
            LONG_WAIT_PIECE as u16
        } else {
            ticks as u16
        }
    }

    /// Start the block at the front of the block queue (it stays there
    /// until [`Self::finish_block`]; the caller checked that it is there).
    fn start_block(&mut self) {
        let Some(&block) = self.blocks.front() else { return };
        self.in_block = true;
        self.discarding = false;
        self.refresh_continuable();
        self.events_started = 0;
        self.stopped = 0;
        self.stopped_steps = [0; MOTORS];
        self.always = block.always;
        self.minor = block.minor;
        self.counters = [0; MOTORS];
        self.steps = block.steps;
        self.thresholds = block.thresholds;
        // Motors that stay still keep their direction pins: no needless
        // direction change (and its set-up lead) when another motor turns.
        self.direction = block.direction | (self.pending_dir & !block.moving & 0x0F);
        self.update_endstop_mask();
    }

    /// The running block (only while `in_block`).
    #[inline(always)]
    fn running_block(&self) -> PreparedBlock {
        debug_assert!(self.in_block);
        // While `in_block` the front slot of the block queue is the running
        // block: the producer does not reuse it before `finish_block`
        // releases it.
        self.blocks.front().copied().unwrap_or_default()
    }

    fn finish_block(&mut self) {
        #[cfg(feature = "encoders")]
        {
            // Whole blocks need no division; an abandoned or halted one
            // (cold) takes the proportional count.
            self.origin = self.axis_progress().positions();
        }
        self.in_block = false;
        self.refresh_continuable();
        self.endstops_to_read = 0;
        self.always = 0;
        self.minor = 0;
        // The block's slot goes back to the main loop.
        self.blocks.release();
        self.blocks_done = self.blocks_done.wrapping_add(1);
    }

    fn refresh_continuable(&mut self) {
        self.continuable = self.in_block && !self.discarding && self.fault.is_none();
    }

    /// Events of the running block done so far (the pending one counted).
    fn events_done(&self) -> u16 {
        self.events_started.wrapping_sub(self.events_left)
    }

    /// Endstop bits worth reading now (0: the board may skip the reads).
    /// Kept up to date at block start and end and on a new configuration:
    /// computing it on every step cost the interrupt ~20 cycles.
    #[inline(always)]
    pub fn endstop_mask(&self) -> u8 {
        self.endstops_to_read
    }

    fn update_endstop_mask(&mut self) {
        self.endstops_to_read = if self.in_block { self.running_block().watch | (self.config.limit_endstops & self.endstops_ahead()) } else { 0 };
    }

    /// Endstops that the running block moves towards.
    fn endstops_ahead(&self) -> u8 {
        if self.in_block {
            self.running_block().ahead
        } else {
            0
        }
    }

    /// The board's endstop reading (bit layout of [`StepBlock::watch`],
    /// 1 = triggered after the configured polarity). Call before
    /// [`Self::on_timer`] whenever [`Self::endstop_mask`] is non-zero.
    pub fn on_endstops(&mut self, triggered: u8) {
        if !self.in_block || self.discarding {
            return;
        }
        let (watch, watch_release) = (self.running_block().watch, self.running_block().watch_release);
        if watch != 0 {
            let level = if watch_release { !triggered } else { triggered };
            let hit = level & watch;
            let motors = (hit | (hit >> 4)) & 0x0F & !self.stopped;
            if motors != 0 {
                self.stop_motors(motors);
                if !self.in_block {
                    return;
                }
            }
        }
        let limits = triggered & self.config.limit_endstops & self.endstops_ahead() & !watch;
        if limits != 0 {
            self.halt(StepFault::LimitHit(limits));
        }
    }

    /// Stop some motors of a homing block; abandon the block once every
    /// watched motor has stopped. Cold path (a division per motor).
    #[cold]
    #[inline(never)]
    fn stop_motors(&mut self, motors: u8) {
        // The pending event has not fired: it is not counted.
        let fired = self.events_done() - (self.pending_mask != 0) as u16;
        let block = self.running_block();
        for motor in 0..MOTORS {
            if motors & (1 << motor) != 0 && block.events != 0 {
                let steps = (fired as u32 * block.steps[motor] as u32) / block.events as u32;
                self.stopped_steps[motor] = steps as u16;
            }
        }
        self.stopped |= motors;
        let watched = (block.watch | (block.watch >> 4)) & 0x0F & block.moving;
        if watched & !self.stopped == 0 {
            self.abandon_block();
        }
    }

    /// Drop the rest of the running block: its queued segments, and the
    /// ones still coming, up to the next block. The block counts as done
    /// at once: the main loop learns it from `blocks_done` and stops
    /// preparing it. (Counting it only when its segments ran out let a main
    /// loop that refills faster than this drains keep the block alive.)
    fn abandon_block(&mut self) {
        self.events_left = 0;
        self.pending_mask = 0;
        self.set_long_wait(0);
        self.discarding = true;
        self.refresh_continuable();
        self.events_started = self.running_block().events;
        while let Some(segment) = self.segments.front() {
            if segment.start != NOT_A_START {
                break;
            }
            self.segments.release();
        }
        self.finish_block();
    }

    /// Stop all motion at once (hard limit, `M410`, `M112`). Every queued
    /// step is dropped, and so is everything queued until
    /// [`Self::clear_fault`]. Positions are lost: the main loop re-homes.
    pub fn halt(&mut self, fault: StepFault) {
        self.fault = Some(fault);
        self.refresh_continuable();
        // The events of the running segment not computed yet are not done:
        // keep `events_done` as it was (the encoder loops' positions).
        self.events_started = self.events_done();
        self.events_left = 0;
        self.pending_mask = 0;
        self.set_long_wait(0);
        self.drain();
    }

    fn drain(&mut self) {
        if self.in_block {
            self.finish_block();
        }
        while self.segments.dequeue().is_some() {}
        while self.blocks.dequeue().is_some() {}
    }

    /// Accept work again after a fault; the main loop calls this once it
    /// has flushed its planner (everything queued before is dropped).
    pub fn clear_fault(&mut self) {
        self.drain();
        self.fault = None;
        self.discarding = false;
        self.refresh_continuable();
    }

    /// A copy of what the main loop needs (cheap: no arithmetic). A board
    /// that must keep its interrupt locks short reads it a field at a time
    /// instead (the Mega 2560's `stepping::status`, with the accessors
    /// below).
    pub fn status(&self) -> StepperStatus {
        let mut status = StepperStatus {
            blocks_done: self.blocks_done,
            busy: self.is_busy(),
            fault: self.fault,
            stopped: 0,
            stopped_steps: [0; MOTORS],
            underruns: self.underruns,
        };
        self.homing_stops(&mut status);
        status
    }

    /// Blocks finished or abandoned so far (wrapping).
    pub fn blocks_done(&self) -> u16 {
        self.blocks_done
    }

    /// Steps still queued or running.
    pub fn is_busy(&self) -> bool {
        self.has_queued_segments() || self.is_running()
    }

    /// Segments wait in the queue. (A board that reads [`Self::is_busy`]
    /// in two interrupt locks reads this first: only the main loop adds
    /// segments, so once this is false nothing can start before
    /// [`Self::is_running`] is read.)
    pub fn has_queued_segments(&self) -> bool {
        self.segments.ready()
    }

    /// A block or a step is under way.
    pub fn is_running(&self) -> bool {
        // Bitwise, not short-circuit: fewer branches, and the board reads
        // this under an interrupt lock.
        (u8::from(self.in_block) | self.pending_mask | u8::from(self.long_waiting)) != 0
    }

    pub fn fault(&self) -> Option<StepFault> {
        self.fault
    }

    /// Times a block ran out of segments (wrapping).
    pub fn underruns(&self) -> u16 {
        self.underruns
    }

    /// Fill in which motors the last homing block's endstops stopped, and
    /// their steps. Only meaningful once the generator is idle (`busy`
    /// false): the next block resets them.
    pub fn homing_stops(&self, status: &mut StepperStatus) {
        status.stopped = self.stopped;
        status.stopped_steps = self.stopped_steps;
    }

    pub fn config(&self) -> StepperConfig {
        self.config
    }

    pub fn set_config(&mut self, config: StepperConfig) {
        self.config = config;
        self.update_endstop_mask();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    /// Run the generator for `ticks` of virtual time; (time, mask, dir) of
    /// every action with steps.
    fn run(generator: &mut StepGenerator<'_>, ticks: u64) -> Vec<(u64, u8, u8)> {
        let mut now = 0_u64;
        let mut out = Vec::new();
        let mut last_dir = 0;
        while now < ticks {
            let pins = generator.pins_now();
            let action = generator.on_timer();
            // What the board wrote before computing is what was fired.
            assert_eq!(pins, (action.step_mask, action.dir_mask));
            if action.step_mask != 0 {
                // Invariant 3: directions never change in an action with steps.
                assert_eq!(action.dir_mask, last_dir, "direction changed with a step at {now}");
                out.push((now, action.step_mask, action.dir_mask));
            }
            last_dir = action.dir_mask;
            assert!(action.next_interval_ticks >= 1);
            now += action.next_interval_ticks as u64;
        }
        out
    }

    fn block(steps: [u16; MOTORS], direction: u8) -> StepBlock {
        StepBlock { steps, events: *steps.iter().max().unwrap(), direction, watch: 0, watch_release: false }
    }

    #[test]
    fn constant_rate_block_steps_exactly() {
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        assert!(feeder.push_block(block([1000, 500, 0, 3], 0b0011)));
        assert!(feeder.push_segment(Segment { interval: 200 << 8, add: 0, events: 1000, starts_block: true }));
        let events = run(&mut generator, 400_000);
        let count = |motor: u8| events.iter().filter(|e| e.1 & (1 << motor) != 0).count();
        assert_eq!((count(0), count(1), count(2), count(3)), (1000, 500, 0, 3));
        // Every 200 ticks, and all motors' last steps together.
        let first = events[0].0;
        assert!(events.windows(2).all(|w| w[1].0 - w[0].0 == 200));
        let last = events.last().unwrap();
        assert_eq!(last.1, 0b1011);
        assert_eq!(last.0 - first, 999 * 200);
        assert_eq!(generator.status().blocks_done, 1);
        assert!(!generator.status().busy);
    }

    #[cfg(feature = "encoders")]
    #[test]
    fn x_and_y_positions_follow_the_steps_within_one_step_and_exactly_at_block_ends() {
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        // X +1000, Y +500; then X −300, Y −700.
        assert!(feeder.push_block(block([1000, 500, 0, 0], 0b0011)));
        assert!(feeder.push_segment(Segment { interval: 200 << 8, add: 0, events: 1000, starts_block: true }));
        assert!(feeder.push_block(block([300, 700, 0, 0], 0b0000)));
        assert!(feeder.push_segment(Segment { interval: 200 << 8, add: 0, events: 700, starts_block: true }));
        assert_eq!(generator.axis_progress().positions(), [0, 0]);
        // Part of the way through the first block: count the STEP pulses.
        let events = run(&mut generator, 100_000);
        let count = |motor: u8| events.iter().filter(|e| e.1 & (1 << motor) != 0).count() as i32;
        let [x, y] = generator.axis_progress().positions();
        assert!((x - count(0)).abs() <= 1 && (y - count(1)).abs() <= 1, "{x} {y} vs {} {}", count(0), count(1));
        for _ in 0..5_000 {
            generator.on_timer();
        }
        assert_eq!(generator.status().blocks_done, 2);
        assert_eq!(generator.axis_progress().positions(), [700, -200]);
    }

    /// A halt in the middle of a segment: X's and Y's positions count the
    /// steps that were made (within the one pending), not the rest of the
    /// segment.
    #[cfg(feature = "encoders")]
    #[test]
    fn a_halt_keeps_the_positions_of_the_steps_made() {
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        assert!(feeder.push_block(block([1000, 500, 0, 0], 0b0011)));
        assert!(feeder.push_segment(Segment { interval: 200 << 8, add: 0, events: 1000, starts_block: true }));
        let events = run(&mut generator, 40_000);
        let count = |motor: u8| events.iter().filter(|e| e.1 & (1 << motor) != 0).count() as i32;
        generator.halt(StepFault::Stopped);
        let [x, y] = generator.axis_progress().positions();
        assert!((x - count(0)).abs() <= 1 && (y - count(1)).abs() <= 1, "{x} {y} vs {} {}", count(0), count(1));
    }

    /// Blocks in the same direction follow one another through the
    /// interrupt's cheap block change (the next block read in place): every
    /// motor makes exactly its steps in every block, the rhythm holds across
    /// the boundaries, the block count follows, and a block that turns a
    /// motor round still gets its direction lead.
    #[test]
    fn block_changes_keep_every_count_and_the_rhythm() {
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        let blocks = [[40, 13, 0, 7], [25, 25, 0, 0], [30, 0, 29, 1], [12, 5, 0, 0]];
        let mut expected = [0usize; MOTORS];
        for (i, steps) in blocks.iter().enumerate() {
            assert!(feeder.push_block(block(*steps, 0b1111)));
            let events = *steps.iter().max().unwrap();
            // Two segments each: a block change and a segment change.
            let first = events / 2;
            assert!(feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: first, starts_block: true }));
            assert!(feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: events - first, starts_block: false }));
            for motor in 0..MOTORS {
                expected[motor] += usize::from(steps[motor]);
            }
            assert_eq!(generator.status().blocks_done, 0, "block {i} queued");
        }
        let events = run(&mut generator, 20_000);
        let count = |motor: u8| events.iter().filter(|e| e.1 & (1 << motor) != 0).count();
        assert_eq!([count(0), count(1), count(2), count(3)], expected);
        assert!(events.windows(2).all(|w| w[1].0 - w[0].0 == 100), "{events:?}");
        assert_eq!(generator.status().blocks_done, blocks.len() as u16);
        assert!(!generator.status().busy);
        // The encoder loops' origin followed the cheap block changes.
        #[cfg(feature = "encoders")]
        assert_eq!(generator.axis_progress().positions(), [expected[0] as i32, expected[1] as i32]);
        // Now one that reverses X: the general path, with its lead.
        assert!(feeder.push_block(block([5, 0, 0, 0], 0b1111)));
        assert!(feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 5, starts_block: true }));
        assert!(feeder.push_block(block([5, 0, 0, 0], 0b1110)));
        assert!(feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 5, starts_block: true }));
        let events = run(&mut generator, 5_000);
        assert_eq!(events.len(), 10);
        assert_eq!(events[4].2 & 1, 1);
        assert_eq!(events[5].2 & 1, 0);
        assert_eq!(generator.status().blocks_done, blocks.len() as u16 + 2);
    }

    /// The inline block change resets no Bresenham counter (they are back
    /// at 0 at every block's end): a block taken that way steps each motor
    /// on exactly the events it would step on when started from idle.
    #[test]
    fn a_block_taken_inline_steps_on_the_same_events_as_from_idle() {
        let second = [23, 31, 0, 9];
        let pattern = |events: &[(u64, u8, u8)]| events.iter().map(|e| e.1).collect::<Vec<u8>>();
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        assert!(feeder.push_block(block(second, 0b1011)));
        assert!(feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 31, starts_block: true }));
        let alone = run(&mut generator, 10_000);
        assert_eq!(alone.len(), 31);

        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        assert!(feeder.push_block(block([17, 40, 0, 3], 0b1011)));
        assert!(feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 40, starts_block: true }));
        assert!(feeder.push_block(block(second, 0b1011)));
        assert!(feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 31, starts_block: true }));
        let both = run(&mut generator, 20_000);
        assert_eq!(both.len(), 71);
        // Same rhythm straight through the boundary, and the second block's
        // events exactly as alone.
        assert!(both.windows(2).all(|w| w[1].0 - w[0].0 == 100));
        assert_eq!(pattern(&both[40..]), pattern(&alone));
        assert_eq!(generator.status().blocks_done, 2);
    }

    /// A homing block after an ordinary one takes the general path (its
    /// endstops to watch), and an ordinary block after a homing block
    /// whose motor stopped also does (the stops to reset): the counts stay
    /// exact either way.
    #[test]
    fn homing_blocks_are_never_taken_inline() {
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        assert!(feeder.push_block(block([10, 0, 0, 0], 0b0001)));
        assert!(feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 10, starts_block: true }));
        let mut homing = block([50, 0, 0, 0], 0b0001);
        homing.watch = 0b0001_0000;
        assert!(feeder.push_block(homing));
        assert!(feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 50, starts_block: true }));
        assert!(feeder.push_block(block([7, 0, 0, 0], 0b0001)));
        assert!(feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 7, starts_block: true }));
        let mut fired = 0;
        for _ in 0..500 {
            if generator.endstop_mask() != 0 {
                // The switch is 20 steps into the homing block.
                generator.on_endstops(if fired >= 30 { 0b0001_0000 } else { 0 });
            }
            fired += generator.on_timer().step_mask.count_ones();
        }
        assert_eq!(fired, 10 + 20 + 7);
        assert_eq!(generator.status().blocks_done, 3);
    }

    #[test]
    fn direction_change_comes_before_the_step() {
        let mut queues = StepQueues::new();
        let config = StepperConfig { dir_invert: 0b0010, dir_setup_ticks: 10, limit_endstops: 0 };
        let (mut feeder, mut generator) = queues.split(config);
        feeder.push_block(block([3, 0, 0, 0], 0b0001));
        feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 3, starts_block: true });
        feeder.push_block(block([2, 0, 0, 0], 0b0000));
        feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 2, starts_block: true });
        let mut now = 0_u64;
        let mut trace = Vec::new();
        for _ in 0..12 {
            let action = generator.on_timer();
            trace.push((now, action.step_mask, action.dir_mask));
            now += action.next_interval_ticks as u64;
        }
        let steps: Vec<_> = trace.iter().filter(|t| t.1 != 0).collect();
        assert_eq!(steps.len(), 5);
        // Motor 1 is inverted: its pin reads 1 for "negative".
        assert!(steps[..3].iter().all(|s| s.2 == 0b0011));
        assert!(steps[3..].iter().all(|s| s.2 == 0b0010));
        // The reversal keeps the 100-tick rhythm and shows the new direction
        // 10 ticks ahead, in an action without steps.
        assert_eq!(steps[3].0 - steps[2].0, 100);
        let change = trace.iter().position(|t| t.2 == 0b0010 && t.0 > steps[2].0).unwrap();
        assert_eq!(trace[change].1, 0);
        assert_eq!(steps[3].0 - trace[change].0, 10);
    }

    #[test]
    fn long_waits_are_cut_into_pieces() {
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        feeder.push_block(block([3, 0, 0, 0], 1));
        // 200 000 ticks = 0.1 s between steps: 10 steps/s.
        feeder.push_segment(Segment { interval: 200_000 << 8, add: 0, events: 3, starts_block: true });
        let events = run(&mut generator, 1_000_000);
        assert_eq!(events.len(), 3);
        assert_eq!(events[1].0 - events[0].0, 200_000);
        assert_eq!(events[2].0 - events[1].0, 200_000);
    }

    #[test]
    fn fractional_intervals_do_not_drift() {
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        feeder.push_block(block([1000, 0, 0, 0], 1));
        // 33.3 ticks (8525/256): 1000 events take 33 300.78 ticks.
        feeder.push_segment(Segment { interval: 8525, add: 0, events: 1000, starts_block: true });
        let events = run(&mut generator, 100_000);
        let span = events.last().unwrap().0 - events[0].0;
        assert_eq!(span, (999 * 8525 + (8525 & 0xFF)) as u64 >> 8);
    }

    #[test]
    fn homing_block_stops_each_motor_at_its_endstop() {
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        // Three towers up towards their max endstops (bits 4, 5, 6).
        let mut homing = block([1000, 1000, 1000, 0], 0b0111);
        homing.watch = 0b0111_0000;
        feeder.push_block(homing);
        feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 600, starts_block: true });
        feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 400, starts_block: false });
        feeder.push_block(block([5, 0, 0, 0], 0));
        feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 5, starts_block: true });
        let mut fired = [0_u32; MOTORS];
        let mut triggered = 0_u8;
        for _ in 0..5000 {
            if generator.endstop_mask() != 0 {
                generator.on_endstops(triggered);
            }
            let action = generator.on_timer();
            for motor in 0..MOTORS {
                if action.step_mask & (1 << motor) != 0 {
                    fired[motor] += 1;
                }
            }
            // Endstops sit at 100, 250 and 700 steps up.
            for (motor, at) in [(0, 100), (1, 250), (2, 700)] {
                if fired[motor] >= at {
                    triggered |= 0x10 << motor;
                }
            }
        }
        // Each stopped on its switch; the rest of the block was dropped and
        // the next block ran (five steps back down on motor 0).
        assert_eq!(fired, [105, 250, 700, 0]);
        let status = generator.status();
        assert_eq!(status.blocks_done, 2);
        assert!(!status.busy);
    }

    /// The main loop learns that a stopped homing block is over at once,
    /// even while it keeps queueing that block's segments: otherwise a main
    /// loop that refills as fast as the interrupt discards (the real board)
    /// would prepare the abandoned block forever.
    #[test]
    fn an_abandoned_homing_block_counts_as_done_at_once() {
        let mut queues = StepQueues::new();
        let (mut feeder, mut generator) = queues.split(StepperConfig::default());
        let mut homing = block([1000, 0, 0, 0], 0);
        homing.watch = 0b0000_0001;
        feeder.push_block(homing);
        feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 10, starts_block: true });
        for _ in 0..5 {
            generator.on_timer();
        }
        generator.on_endstops(0b0000_0001);
        assert_eq!(generator.status().blocks_done, 1);
        // More of the dropped block keeps coming; it is skipped, and the
        // count does not move again.
        for _ in 0..50 {
            feeder.push_segment(Segment { interval: 100 << 8, add: 0, events: 10, starts_block: false });
            assert_eq!(generator.on_timer().step_mask, 0);
        }
        assert_eq!(generator.status().blocks_done, 1);
        assert!(!generator.status().busy || feeder.queued_segments() > 0);
    }

    #[test]
    fn hard_limit_halts_everything_until_cleared() {
        let mut queues = StepQueues::new();
        let config = StepperConfig { limit_endstops: 0b0000_0001, ..StepperConfig::default() };
        let (mut feeder, mut generator) = queues.split(config);
        feeder.push_block(block([100, 0, 0, 0], 0)); // towards X min
        feeder.push_segment(Segment { interval: 50 << 8, add: 0, events: 100, starts_block: true });
        let mut fired = 0;
        for _ in 0..20 {
            let action = generator.on_timer();
            fired += action.step_mask.count_ones();
        }
        assert_eq!(generator.endstop_mask(), 0b0000_0001);
        generator.on_endstops(0b0000_0001);
        for _ in 0..200 {
            fired += generator.on_timer().step_mask.count_ones();
        }
        assert!(fired < 25, "{fired}");
        assert_eq!(generator.status().fault, Some(StepFault::LimitHit(1)));
        // Moving away from the same switch is allowed once cleared.
        generator.clear_fault();
        feeder.push_block(block([10, 0, 0, 0], 1));
        feeder.push_segment(Segment { interval: 50 << 8, add: 0, events: 10, starts_block: true });
        let events = run(&mut generator, 10_000);
        assert_eq!(events.len(), 10);
    }
}
