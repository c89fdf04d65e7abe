//! The ams NSE-5310 linear magnetic encoder (SPEC §1).
//!
//! The chip reports an absolute 12-bit angle inside one 2 mm pole PAIR of the
//! magnetic strip: 4096 counts per 2 mm, so one count is 1/2048 mm
//! (0.48828 µm), which is exactly one [`Units`](super::Units) of the loop.
//! Across pole pairs it knows nothing: the firmware unwraps. Between two reads
//! the strip moves less than half a pole pair (1 mm) when the encoder is read
//! often enough, so a jump of more than 2048 counts means a pole-pair
//! boundary was crossed, in the direction of the jump ([`LinearTracker`]).
//!
//! The Index line pulses once per pole pair and says nothing about direction.
//! It is noisy (the thesis debounced it and still saw error spikes), so it is
//! never used to count: [`IndexDebouncer`] (in the external interrupt) keeps
//! edges that are at least a minimum time apart, and the tracker accepts an
//! edge only when the unwrapped reading agrees that the index position was
//! crossed (or is within a window of it). Edges that disagree are rejected
//! and counted.
//!
//! The I²C side ([`Nse5310`]) only turns a bus transfer into a raw count; it
//! works with any embedded-hal 1 [`I2c`]. Both chips answer at 0x40 by
//! default, so two of them need two buses (or chip-select gating, or OTP
//! addresses): that is board configuration, and each [`Nse5310`] owns the
//! bus it is given (`&mut bus` works too).

use embedded_hal::i2c::I2c;

/// Counts per pole pair (12 bits).
pub const COUNTS_PER_POLE_PAIR: i32 = 4096;
/// A jump of more than this between two reads crossed a pole-pair boundary.
pub const HALF_POLE_PAIR: i32 = COUNTS_PER_POLE_PAIR / 2;
/// Loop units (counts) per millimetre: 4096 counts over a 2 mm pole pair.
pub const UNITS_PER_MM: i32 = 2048;
/// The chip's factory I²C address (7 bits).
pub const DEFAULT_ADDRESS: u8 = 0x40;

// Status bits in the second byte of a read, after D3..D0 (the layout the
// Aus3D module firmware and the thesis read: OCF, COF, LIN, magnitude).
const OCF: u8 = 1 << 3;
const COF: u8 = 1 << 2;
const LIN: u8 = 1 << 1;

/// Why one read gave no usable count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReadError<E> {
    /// The bus transfer failed (NACK, arbitration, timeout).
    Bus(E),
    /// Offset compensation has not finished (OCF = 0): the chip is starting.
    NotReady,
    /// The CORDIC overflowed (COF = 1): the count is garbage.
    Overflow,
    /// Linearity alarm (LIN = 1): the magnet is too far or too close.
    FieldOutOfRange,
}

/// Decode the first two bytes of a read: D11..D4, then D3..D0 + status.
pub fn decode_frame(frame: [u8; 2]) -> Result<u16, ReadError<core::convert::Infallible>> {
    let status = frame[1];
    if status & OCF == 0 {
        return Err(ReadError::NotReady);
    }
    if status & COF != 0 {
        return Err(ReadError::Overflow);
    }
    if status & LIN != 0 {
        return Err(ReadError::FieldOutOfRange);
    }
    Ok((u16::from(frame[0]) << 4) | u16::from(frame[1] >> 4))
}

/// One NSE-5310 on its own I²C bus.
pub struct Nse5310<I2C> {
    i2c: I2C,
    address: u8,
}

impl<I2C: I2c> Nse5310<I2C> {
    /// `address` is the chip's 7-bit address ([`DEFAULT_ADDRESS`] unless
    /// programmed otherwise).
    pub fn new(i2c: I2C, address: u8) -> Self {
        Self { i2c, address }
    }

    /// Read the raw 12-bit count (one 2-byte read transfer, ≈ 60 µs at 400 kHz).
    pub fn read_raw(&mut self) -> Result<u16, ReadError<I2C::Error>> {
        let mut frame = [0u8; 2];
        self.i2c.read(self.address, &mut frame).map_err(ReadError::Bus)?;
        decode_frame(frame).map_err(|error| match error {
            ReadError::Bus(never) => match never {},
            ReadError::NotReady => ReadError::NotReady,
            ReadError::Overflow => ReadError::Overflow,
            ReadError::FieldOutOfRange => ReadError::FieldOutOfRange,
        })
    }

    pub fn address(&self) -> u8 {
        self.address
    }

    /// Give the bus back.
    pub fn release(self) -> I2C {
        self.i2c
    }
}

/// Debounces the Index line inside its external interrupt: an edge closer
/// than `min_spacing_us` to the previous one is a bounce.
///
/// On the AVR the tick reads it inside a critical section (`take`).
#[derive(Clone, Copy, Debug)]
pub struct IndexDebouncer {
    min_spacing_us: u32,
    last_edge_us: u32,
    seen_edge: bool,
    pending: u8,
    bounces: u16,
}

impl IndexDebouncer {
    pub const fn new(min_spacing_us: u32) -> Self {
        Self { min_spacing_us, last_edge_us: 0, seen_edge: false, pending: 0, bounces: 0 }
    }

    /// Call from the Index pin's external interrupt (rising edge), with a
    /// microsecond clock that may wrap.
    pub fn on_edge(&mut self, now_us: u32) {
        if self.seen_edge && now_us.wrapping_sub(self.last_edge_us) < self.min_spacing_us {
            self.bounces = self.bounces.saturating_add(1);
        } else {
            self.pending = self.pending.saturating_add(1);
        }
        self.seen_edge = true;
        self.last_edge_us = now_us;
    }

    /// Debounced edges since the last call (hand them to [`LinearTracker::update`]).
    pub fn take(&mut self) -> u8 {
        core::mem::take(&mut self.pending)
    }

    /// Edges dropped as bounces since start.
    pub fn bounces(&self) -> u16 {
        self.bounces
    }
}

/// Why the encoder can no longer be trusted. The loop turns these into an
/// [`AxisFault`](super::AxisFault) and the job stops.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EncoderFault {
    /// The reading did not change while the commanded position moved by
    /// more than the configured travel: sensor (or axis) stuck.
    Stuck,
    /// Too many consecutive reads failed or were implausible.
    NoReading,
}

/// Tuning of the tracker; see [`TrackerConfig::default_for_printer`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TrackerConfig {
    /// Raw count at which the Index pulse fires (its phase in the pole pair).
    pub index_phase: u16,
    /// An index edge is accepted when the unwrapped reading crossed the
    /// index phase, or is within this many counts of it.
    pub index_window: u16,
    /// A larger jump between reads (counts, after unwrapping) is rejected as
    /// implausible: the axis cannot move that far in one read period.
    pub max_jump: u16,
    /// Consecutive failed or rejected reads before [`EncoderFault::NoReading`].
    pub max_bad_reads: u8,
    /// Commanded travel (units) with a bit-identical reading before
    /// [`EncoderFault::Stuck`]...
    pub stuck_travel: i32,
    /// ...over at least this many consecutive identical reads. One repeat
    /// is not evidence: above 62.5 mm/s at a 250 Hz read rate one read
    /// period is already 0.25 mm of command, and a carriage that pauses (a
    /// reversal, the dead time after a start) with a quiet sensor repeats
    /// a reading now and then; the simulated 60-minute print raised a false
    /// "encoder stuck" that way with one repeat allowed.
    pub stuck_reads: u8,
}

impl TrackerConfig {
    /// Defaults for SPEC §1's printer: index at count 0, ±256 counts
    /// (0.125 mm) window, jumps up to 1024 counts (0.5 mm) per read (500 mm/s
    /// at a 1 kHz read rate, 100 mm/s at 200 Hz), 5 bad reads, stuck after
    /// 0.25 mm of commanded travel over 4 identical reads.
    pub const fn default_for_printer() -> Self {
        Self { index_phase: 0, index_window: 256, max_jump: 1024, max_bad_reads: 5, stuck_travel: UNITS_PER_MM / 4, stuck_reads: 4 }
    }

    /// The printer defaults with `max_jump` sized for an axis that moves at
    /// most `max_speed_mm_s` and is read `read_hz` times a second: 1.5 × the
    /// travel per read + 64 counts of noise margin. `None` when the axis
    /// could move 0.9 mm or more between reads: the unwrapping would be
    /// ambiguous (SPEC §1: read at least once per 1 mm).
    pub fn for_read_rate(max_speed_mm_s: u16, read_hz: u16) -> Option<Self> {
        if read_hz == 0 {
            return None;
        }
        let per_read = u32::from(max_speed_mm_s) * UNITS_PER_MM as u32 / u32::from(read_hz);
        if per_read * 10 >= 9 * UNITS_PER_MM as u32 {
            return None;
        }
        let max_jump = (per_read * 3 / 2 + 64).min(HALF_POLE_PAIR as u32 - 1) as u16;
        Some(Self { max_jump, ..Self::default_for_printer() })
    }
}

/// Counters a host can ask for (`M822`): how healthy the encoder is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TrackerCounters {
    /// Index edges that agreed with the unwrapped count.
    pub index_accepted: u16,
    /// Index edges rejected: the reading was nowhere near the index phase.
    pub index_glitches: u16,
    /// Extra edges in one read period (beyond the one accepted).
    pub index_bounces: u16,
    /// Index-phase crossings seen in the count with no index edge.
    pub index_missed: u16,
    /// Reads rejected as implausible jumps, or failed on the bus.
    pub bad_reads: u16,
}

/// Unwraps NSE-5310 readings into a position relative to the homing zero,
/// cross-checks the Index line and watches for a stuck sensor.
///
/// Pure state machine, integer only, bounded: call [`update`](Self::update)
/// once per read (at least once per 1 mm of travel).
#[derive(Clone, Copy, Debug)]
pub struct LinearTracker {
    config: TrackerConfig,
    /// Unwrapped count since the first read (units).
    unwrapped: i32,
    /// Unwrapped count that is position zero (set by homing).
    zero: i32,
    last_raw: u16,
    primed: bool,
    consecutive_bad: u8,
    /// Commanded position when the raw reading last changed.
    commanded_at_change: i32,
    /// Commanded position at the last accepted read: the unwrapping
    /// expects the strip to have moved by the command since then.
    commanded_at_read: i32,
    /// Consecutive reads equal to the one before.
    same_reads: u8,
    /// The last read crossed the index phase without an edge: it may
    /// still come with the next read.
    edge_owed: bool,
    fault: Option<EncoderFault>,
    counters: TrackerCounters,
}

impl LinearTracker {
    pub const fn new(config: TrackerConfig) -> Self {
        Self {
            config,
            unwrapped: 0,
            zero: 0,
            last_raw: 0,
            primed: false,
            consecutive_bad: 0,
            commanded_at_change: 0,
            commanded_at_read: 0,
            same_reads: 0,
            edge_owed: false,
            fault: None,
            counters: TrackerCounters {
                index_accepted: 0,
                index_glitches: 0,
                index_bounces: 0,
                index_missed: 0,
                bad_reads: 0,
            },
        }
    }

    /// Feed one reading. `index_edges`: debounced Index edges since the last
    /// read; `commanded`: where the firmware has commanded the axis (units,
    /// same zero), for the stuck-sensor check. Returns the position (units
    /// from the homing zero) or the latched fault.
    pub fn update(&mut self, raw: u16, index_edges: u8, commanded: i32) -> Result<i32, EncoderFault> {
        if let Some(fault) = self.fault {
            return Err(fault);
        }
        let raw = raw & 0x0FFF;
        if !self.primed {
            self.primed = true;
            self.last_raw = raw;
            self.unwrapped = i32::from(raw);
            self.zero = self.unwrapped;
            self.commanded_at_change = commanded;
            self.commanded_at_read = commanded;
            return Ok(0);
        }
        // Unwrap around what the command predicts: the reading may be
        // anywhere in the pole pair, but it can only differ from
        // "last reading + commanded travel" by the change of the following
        // error, which stays far below half a pole pair. So the axis may
        // travel more than 1 mm between reads (SPEC §1's "one read per mm"
        // holds for an unwrapping without a prediction; the printer's
        // 300 mm/s at 250 Hz is 1.2 mm a read), and a command that stands
        // still unwraps as before.
        let predicted = commanded.wrapping_sub(self.commanded_at_read);
        let mut deviation = (i32::from(raw) - i32::from(self.last_raw) - predicted).rem_euclid(COUNTS_PER_POLE_PAIR);
        if deviation > HALF_POLE_PAIR {
            deviation -= COUNTS_PER_POLE_PAIR;
        }
        let jump = predicted.wrapping_add(deviation);
        if deviation.unsigned_abs() > u32::from(self.config.max_jump) {
            // Implausible: keep the last good reading and wait for the next.
            self.reject_read()?;
            return Ok(self.position());
        }
        self.consecutive_bad = 0;
        self.commanded_at_read = commanded;
        self.cross_check_index(jump, raw, index_edges);
        self.unwrapped = self.unwrapped.wrapping_add(jump);
        if raw != self.last_raw {
            self.commanded_at_change = commanded;
            self.same_reads = 0;
        } else {
            self.same_reads = self.same_reads.saturating_add(1);
            if self.same_reads >= self.config.stuck_reads
                && (commanded.wrapping_sub(self.commanded_at_change)).unsigned_abs() > self.config.stuck_travel.unsigned_abs()
            {
                self.fault = Some(EncoderFault::Stuck);
                return Err(EncoderFault::Stuck);
            }
        }
        self.last_raw = raw;
        Ok(self.position())
    }

    /// A read failed (bus error, status flags): counts towards
    /// [`EncoderFault::NoReading`].
    pub fn read_failed(&mut self) -> Result<(), EncoderFault> {
        if let Some(fault) = self.fault {
            return Err(fault);
        }
        self.reject_read()
    }

    fn reject_read(&mut self) -> Result<(), EncoderFault> {
        self.counters.bad_reads = self.counters.bad_reads.saturating_add(1);
        self.consecutive_bad = self.consecutive_bad.saturating_add(1);
        if self.consecutive_bad >= self.config.max_bad_reads {
            self.fault = Some(EncoderFault::NoReading);
            return Err(EncoderFault::NoReading);
        }
        Ok(())
    }

    fn cross_check_index(&mut self, jump: i32, raw: u16, index_edges: u8) {
        // Reading relative to the index phase, before and after the jump.
        let phase = i32::from(self.config.index_phase);
        let before = (i32::from(self.last_raw) - phase).rem_euclid(COUNTS_PER_POLE_PAIR);
        let after = before + jump;
        let crossed = !(1..COUNTS_PER_POLE_PAIR).contains(&after) && jump != 0;
        // The edges are collected apart from the read (the board takes
        // them just after its I²C reads): an edge may reach the read after
        // the one that saw its crossing. One read of grace, then missed.
        let owed = core::mem::replace(&mut self.edge_owed, false);
        if index_edges == 0 {
            if owed {
                self.counters.index_missed = self.counters.index_missed.saturating_add(1);
            }
            self.edge_owed = crossed;
            return;
        }
        let relative = (i32::from(raw) - phase).rem_euclid(COUNTS_PER_POLE_PAIR);
        let distance = relative.min(COUNTS_PER_POLE_PAIR - relative);
        if crossed || owed || distance <= i32::from(self.config.index_window) {
            if crossed && owed && index_edges < 2 {
                // Two crossings, one edge.
                self.counters.index_missed = self.counters.index_missed.saturating_add(1);
            }
            self.counters.index_accepted = self.counters.index_accepted.saturating_add(1);
            self.counters.index_bounces = self.counters.index_bounces.saturating_add(u16::from(index_edges - 1));
        } else {
            self.counters.index_glitches = self.counters.index_glitches.saturating_add(u16::from(index_edges));
        }
    }

    /// Position in units from the homing zero (the last good reading).
    pub fn position(&self) -> i32 {
        self.unwrapped.wrapping_sub(self.zero)
    }

    /// Homing: the current reading becomes `position` (usually 0). Also
    /// clears a latched fault (the axis was re-homed).
    pub fn set_position(&mut self, position: i32, commanded: i32) {
        self.zero = self.unwrapped.wrapping_sub(position);
        self.commanded_at_change = commanded;
        self.commanded_at_read = commanded;
        self.same_reads = 0;
        self.consecutive_bad = 0;
        self.fault = None;
    }

    /// Start over: the next reading primes the tracker at position 0 (a
    /// re-homing after the axis moved unwatched, e.g. while its loop was
    /// stopped by a fault). Clears the fault; the counters stay.
    pub fn restart(&mut self) {
        self.primed = false;
        self.consecutive_bad = 0;
        self.same_reads = 0;
        self.fault = None;
    }

    pub fn fault(&self) -> Option<EncoderFault> {
        self.fault
    }

    pub fn counters(&self) -> TrackerCounters {
        self.counters
    }

    /// Whether a first reading has been taken.
    pub fn is_primed(&self) -> bool {
        self.primed
    }

    pub fn config(&self) -> TrackerConfig {
        self.config
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tracker() -> LinearTracker {
        LinearTracker::new(TrackerConfig::default_for_printer())
    }

    #[test]
    fn first_read_is_position_zero() {
        let mut t = tracker();
        assert_eq!(t.update(1234, 0, 0), Ok(0));
        assert_eq!(t.update(1240, 0, 0), Ok(6));
    }

    #[test]
    fn one_count_is_one_2048th_of_a_millimetre() {
        assert_eq!(COUNTS_PER_POLE_PAIR, 4096);
        assert_eq!(UNITS_PER_MM, 2048);
        // 2 mm / 4096 = 0.48828125 µm
        assert_eq!(2_000_000_000 / COUNTS_PER_POLE_PAIR as i64, 488_281);
    }

    #[test]
    fn a_jump_of_more_than_2048_counts_crosses_a_pole_pair_in_the_jumps_direction() {
        let mut t = tracker();
        t.update(4000, 0, 0).unwrap();
        // 4000 → 100: raw jumped −3900, i.e. +196 counts across the boundary.
        assert_eq!(t.update(100, 1, 0), Ok(196));
        // back: 100 → 4000 is −196
        assert_eq!(t.update(4000, 1, 0), Ok(0));
    }

    #[test]
    fn unwraps_many_pole_pairs_forward_and_back() {
        let mut t = tracker();
        let mut raw: i32 = 3000;
        t.update(raw as u16, 0, 0).unwrap();
        // 25 mm forward in steps of 900 counts, then back.
        for _ in 0..(25 * 2048 / 900) {
            raw = (raw + 900).rem_euclid(4096);
            t.update(raw as u16, 0, 0).unwrap();
        }
        assert_eq!(t.position(), (25 * 2048 / 900) * 900);
        for _ in 0..(25 * 2048 / 900) {
            raw = (raw - 900).rem_euclid(4096);
            t.update(raw as u16, 0, 0).unwrap();
        }
        assert_eq!(t.position(), 0);
    }

    #[test]
    fn an_index_edge_at_the_pole_boundary_is_accepted() {
        let mut t = tracker();
        t.update(4090, 0, 0).unwrap();
        t.update(10, 1, 16).unwrap();
        assert_eq!(t.counters().index_accepted, 1);
        assert_eq!(t.counters().index_glitches, 0);
    }

    #[test]
    fn an_index_edge_mid_pole_is_a_glitch_rejected_and_counted() {
        let mut t = tracker();
        t.update(2000, 0, 0).unwrap();
        assert_eq!(t.update(2010, 3, 10), Ok(10));
        assert_eq!(t.counters().index_glitches, 3);
        assert_eq!(t.counters().index_accepted, 0);
        // the position never moved because of the glitch
        assert_eq!(t.position(), 10);
    }

    #[test]
    fn extra_edges_in_one_read_at_the_boundary_count_as_bounces() {
        let mut t = tracker();
        t.update(4095, 0, 0).unwrap();
        t.update(3, 3, 0).unwrap();
        assert_eq!(t.counters().index_accepted, 1);
        assert_eq!(t.counters().index_bounces, 2);
    }

    #[test]
    fn a_boundary_crossing_without_index_edge_counts_as_missed_index() {
        let mut t = tracker();
        t.update(4000, 0, 0).unwrap();
        t.update(50, 0, 0).unwrap();
        // One read of grace for an edge that comes late...
        assert_eq!(t.counters().index_missed, 0);
        t.update(60, 0, 0).unwrap();
        assert_eq!(t.counters().index_missed, 1);
    }

    #[test]
    fn an_index_edge_one_read_after_its_crossing_is_accepted_not_missed() {
        let mut t = tracker();
        t.update(4000, 0, 0).unwrap();
        t.update(1000, 0, 1096).unwrap();
        // 1000 counts past the phase: not near it, but the edge was owed.
        t.update(1300, 1, 1396).unwrap();
        assert_eq!(t.counters().index_accepted, 1);
        assert_eq!((t.counters().index_missed, t.counters().index_glitches), (0, 0));
    }

    #[test]
    fn the_index_phase_is_configurable() {
        let mut t = LinearTracker::new(TrackerConfig { index_phase: 1000, ..TrackerConfig::default_for_printer() });
        t.update(990, 0, 0).unwrap();
        t.update(1010, 1, 20).unwrap();
        assert_eq!(t.counters().index_accepted, 1);
        t.update(1900, 0, 0).unwrap();
        t.update(1910, 1, 0).unwrap();
        assert_eq!(t.counters().index_glitches, 1);
    }

    #[test]
    fn homing_sets_the_zero_and_position_is_relative() {
        let mut t = tracker();
        t.update(100, 0, 0).unwrap();
        t.update(600, 0, 500).unwrap();
        assert_eq!(t.position(), 500);
        t.set_position(0, 0);
        assert_eq!(t.position(), 0);
        assert_eq!(t.update(700, 0, 100), Ok(100));
        t.set_position(-2048, 0);
        assert_eq!(t.position(), -2048);
    }

    #[test]
    fn an_implausible_jump_is_rejected_and_the_last_position_kept() {
        let mut t = tracker();
        t.update(0, 0, 0).unwrap();
        t.update(100, 0, 0).unwrap();
        // +1900 counts (0.93 mm) in one read is more than max_jump (1024)
        assert_eq!(t.update(2000, 0, 0), Ok(100));
        assert_eq!(t.counters().bad_reads, 1);
        assert_eq!(t.update(110, 0, 0), Ok(110));
    }

    #[test]
    fn the_unwrapping_follows_the_command_beyond_half_a_pole_pair_per_read() {
        // 300 mm/s read at 250 Hz: 1.2 mm (2458 counts) a read, more than
        // half a pole pair; the carriage lags the command by 40 counts.
        let mut t = tracker();
        t.update(0, 0, 0).unwrap();
        for read in 1..=50i32 {
            let commanded = read * 2458;
            let carriage = commanded - 40;
            assert_eq!(t.update(carriage.rem_euclid(4096) as u16, 0, commanded), Ok(carriage), "read {read}");
        }
        assert_eq!(t.counters().bad_reads, 0);
        // A reading 0.6 mm off the prediction is rejected, not misread.
        let commanded: i32 = 51 * 2458;
        assert_eq!(t.update((commanded + 1229).rem_euclid(4096) as u16, 0, commanded), Ok(50 * 2458 - 40));
        assert_eq!(t.counters().bad_reads, 1);
    }

    #[test]
    fn a_restart_primes_on_the_next_reading_wherever_the_strip_is() {
        let mut t = tracker();
        t.update(0, 0, 0).unwrap();
        for _ in 0..5 {
            let _ = t.read_failed();
        }
        assert_eq!(t.fault(), Some(EncoderFault::NoReading));
        t.restart();
        assert_eq!(t.update(3000, 0, 777), Ok(0));
        assert_eq!(t.update(3010, 0, 787), Ok(10));
    }

    #[test]
    fn five_consecutive_bad_reads_latch_no_reading() {
        let mut t = tracker();
        t.update(0, 0, 0).unwrap();
        for _ in 0..4 {
            assert_eq!(t.read_failed(), Ok(()));
        }
        assert_eq!(t.read_failed(), Err(EncoderFault::NoReading));
        assert_eq!(t.update(0, 0, 0), Err(EncoderFault::NoReading));
        t.set_position(0, 0);
        assert_eq!(t.update(1, 0, 0), Ok(1));
    }

    #[test]
    fn a_bit_identical_reading_while_commanded_travel_exceeds_a_quarter_mm_is_stuck() {
        let mut t = tracker();
        t.update(777, 0, 0).unwrap();
        // Four identical reads over 0.25 mm = 512 units of commanded
        // travel are still fine...
        for commanded in [128, 256, 384, 512] {
            assert!(t.update(777, 0, commanded).is_ok());
        }
        // ...one unit more is not.
        assert_eq!(t.update(777, 0, 513), Err(EncoderFault::Stuck));
        assert_eq!(t.fault(), Some(EncoderFault::Stuck));
    }

    #[test]
    fn one_repeated_reading_during_fast_travel_is_not_stuck() {
        // 100 mm/s read at 250 Hz: 0.4 mm = 819 units of command per read.
        let mut t = tracker();
        t.update(100, 0, 0).unwrap();
        assert!(t.update(100, 0, 819).is_ok());
        assert!(t.update(100, 0, 1638).is_ok());
        assert!(t.update(100, 0, 2457).is_ok());
        // The reading moves again: the count starts over.
        assert!(t.update(900, 0, 3276).is_ok());
        assert!(t.update(900, 0, 4095).is_ok());
        // A fourth identical read with the command 0.25 mm on is stuck.
        assert!(t.update(900, 0, 4914).is_ok());
        assert!(t.update(900, 0, 5733).is_ok());
        assert_eq!(t.update(900, 0, 6552), Err(EncoderFault::Stuck));
    }

    #[test]
    fn a_noisy_sensor_at_rest_is_not_stuck() {
        let mut t = tracker();
        for i in 0..1000u16 {
            assert!(t.update(777 + (i % 2), 0, 0).is_ok());
        }
    }

    #[test]
    fn max_jump_follows_speed_and_read_rate_and_refuses_ambiguous_rates() {
        // 200 mm/s at 500 Hz: 0.4 mm = 819 counts per read → 1292
        assert_eq!(TrackerConfig::for_read_rate(200, 500).map(|c| c.max_jump), Some(1292));
        // 200 mm/s at 200 Hz is 1 mm per read: refused
        assert_eq!(TrackerConfig::for_read_rate(200, 200), None);
        assert_eq!(TrackerConfig::for_read_rate(200, 0), None);
    }

    #[test]
    fn debouncer_drops_edges_closer_than_the_minimum_spacing() {
        let mut d = IndexDebouncer::new(200);
        d.on_edge(1_000);
        d.on_edge(1_050);
        d.on_edge(1_150);
        d.on_edge(5_000);
        assert_eq!(d.take(), 2);
        assert_eq!(d.bounces(), 2);
        assert_eq!(d.take(), 0);
        // the clock may wrap
        d.on_edge(u32::MAX - 10);
        d.on_edge(100);
        assert_eq!(d.take(), 1);
    }

    #[test]
    fn decodes_the_12_bit_count_and_status_flags() {
        // D11..D4 = 0xAB, D3..D0 = 0xC, OCF set
        assert_eq!(decode_frame([0xAB, 0xC8]), Ok(0xABC));
        assert_eq!(decode_frame([0xAB, 0xC0]), Err(ReadError::NotReady));
        assert_eq!(decode_frame([0xAB, 0xCC]), Err(ReadError::Overflow));
        assert_eq!(decode_frame([0xAB, 0xCA]), Err(ReadError::FieldOutOfRange));
    }

    struct FakeBus {
        address_seen: u8,
        frame: [u8; 2],
        fail: bool,
    }

    impl embedded_hal::i2c::ErrorType for FakeBus {
        type Error = embedded_hal::i2c::ErrorKind;
    }

    impl I2c for FakeBus {
        fn transaction(&mut self, address: u8, operations: &mut [embedded_hal::i2c::Operation<'_>]) -> Result<(), Self::Error> {
            self.address_seen = address;
            if self.fail {
                return Err(embedded_hal::i2c::ErrorKind::NoAcknowledge(embedded_hal::i2c::NoAcknowledgeSource::Address));
            }
            for operation in operations {
                if let embedded_hal::i2c::Operation::Read(buffer) = operation {
                    buffer.copy_from_slice(&self.frame[..buffer.len()]);
                }
            }
            Ok(())
        }
    }

    #[test]
    fn reads_through_embedded_hal_i2c_at_the_configured_address() {
        let mut chip = Nse5310::new(FakeBus { address_seen: 0, frame: [0x12, 0x38], fail: false }, DEFAULT_ADDRESS);
        assert_eq!(chip.read_raw(), Ok(0x123));
        assert_eq!(chip.release().address_seen, 0x40);
        let mut chip = Nse5310::new(FakeBus { address_seen: 0, frame: [0, 0], fail: true }, 0x41);
        assert!(matches!(chip.read_raw(), Err(ReadError::Bus(_))));
        assert_eq!(chip.address(), 0x41);
    }
}
