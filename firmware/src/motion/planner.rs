//! The look-ahead planner: a ring of blocks whose entry speeds are raised as
//! high as the cornering and acceleration limits allow, while every block can
//! still stop within the buffer.
//!
//! # Algorithm (Grbl's, re-derived)
//!
//! A block is one straight move of all motors. For each block the planner
//! knows its length L (mm, along the Cartesian path, or |E| for an
//! extruder-only move), its nominal speed v (mm/s), its acceleration a
//! (mm/s²) and the largest speed it may be entered with, `max_entry`:
//!
//! - the junction speed with the previous block by *junction deviation*:
//!   the corner is taken as if it were a circular arc that stays within δ of
//!   the corner point, at the centripetal acceleration a. With
//!   cos θ = −u_prev·u (u: unit vectors) and sin(θ/2) = √((1 − cos θ)/2),
//!   v² = a·δ·sin(θ/2)/(1 − sin(θ/2)). Straight on: unlimited; reversal: 0.
//!   No trigonometry, one square root.
//! - and the nominal speeds of both blocks.
//!
//! Entry speeds (squared, so that a·d terms add: v₁² = v₀² + 2·a·d) are then
//! set by two passes each time a block is added:
//!
//! 1. *Backward*, newest to oldest: the newest block must stop at its end;
//!    each block's entry is the lower of its `max_entry` and what it can
//!    decelerate from to reach its successor's entry.
//! 2. *Forward*, oldest to newest: a block cannot be entered faster than its
//!    predecessor can accelerate to.
//!
//! # Invariants
//!
//! - The newest block always exits at 0: whatever the host sends next, the
//!   machine can stop within the buffer.
//! - Entry speeds only ever rise as blocks are added (more room to stop), so
//!   the segment preparation, which works ahead of the planner, is never
//!   asked to have gone slower than it did.
//! - `planned`: every block up to it is optimal (at its `max_entry`, or
//!   accelerating at full rate from an optimal block) and never changes
//!   again; the passes only run over the blocks after it. This keeps the
//!   cost per new block at a few blocks instead of the whole buffer.
//! - The oldest block (`tail`) belongs to the segment preparation, which
//!   rewrites its `entry_speed_sqr` and `millimetres` to its current speed
//!   and remaining length as it goes; it is never changed by the passes.
//!
//! Lengths, nominal speeds and accelerations are `f32` (main loop only, as
//! in Marlin on the AVR; the step interrupt never reads a block). The
//! entry speeds that the passes move are integers ([`SpeedSqr`]) and each
//! block carries its `ramp`, 2·a·L, so that a pass step is an add and a
//! compare: the passes visit every block of the final deceleration (≈ 8
//! for 0.5 mm lines at 100 mm/s) for every line, and in soft float that
//! was ≈ 10 000 of the AVR's cycles a line.

use super::stepper::MOTORS;
use super::math::{min, sqrt, to_u32};

/// A speed squared in 1/256 (mm/s)², saturating at ≈ 4 096 mm/s: the
/// look-ahead only adds and compares these. (From `f32`: NaN and negatives
/// give 0.)
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub struct SpeedSqr(u32);

impl SpeedSqr {
    pub const ZERO: Self = Self(0);
    const PER_MM2_S2: f32 = 256.0;

    /// From (mm/s)² (`to_u32` saturates: no bound needed).
    pub fn from_mm2_s2(value: f32) -> Self {
        Self(to_u32(value * Self::PER_MM2_S2))
    }

    /// In (mm/s)².
    pub fn mm2_s2(self) -> f32 {
        self.0 as f32 * (1.0 / Self::PER_MM2_S2)
    }

    /// The speed² after gaining `ramp` (2·a·d) on top of this one.
    fn after(self, ramp: Self) -> Self {
        Self(self.0.saturating_add(ramp.0))
    }
}

/// Blocks in the ring (one stays empty: 23 usable). Look-ahead must hold
/// the distance to stop from full speed, v²/(2a): 3.3 mm at 100 mm/s and
/// 1500 mm/s², which 0.2 mm slicer segments fill only with ≥ 17 blocks.
/// 24 × 33 bytes on the AVR.
pub const PLANNER_SLOTS: usize = 24;
/// Largest step count of one motor in one block (16-bit Bresenham).
pub const MAX_BLOCK_STEPS: u32 = u16::MAX as u32;

/// One straight move, ready for look-ahead and stepping.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Block {
    /// Steps of every motor.
    pub steps: [u16; MOTORS],
    /// The largest of `steps`.
    pub events: u16,
    /// Bit i set: motor i moves positive.
    pub direction: u8,
    /// Endstops watched while this block runs (homing), see `StepBlock`.
    pub watch: u8,
    pub watch_release: bool,
    /// Remaining path length (mm); shrinks while the block is prepared.
    pub millimetres: f32,
    /// Entry speed²; the current speed² once preparation began.
    pub entry: SpeedSqr,
    pub max_entry: SpeedSqr,
    /// 2·a·`millimetres`: the speed² gained (or shed) over the rest of the
    /// block at full acceleration.
    pub ramp: SpeedSqr,
    /// (mm/s)².
    pub nominal_speed_sqr: f32,
    /// mm/s², within every motor's limit.
    pub acceleration: f32,
}

/// A move as the motion layer hands it over.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlannerMove {
    /// Signed steps of every motor (each |·| ≤ [`MAX_BLOCK_STEPS`]).
    pub steps: [i32; MOTORS],
    /// Path length, mm (> 0).
    pub millimetres: f32,
    /// Unit vector of the move in (X, Y, Z, E) for cornering; all zero:
    /// the move starts and ends at rest (homing, changes of kind).
    pub unit: [f32; MOTORS],
    /// Requested speed, mm/s.
    pub speed: f32,
    /// Requested acceleration, mm/s².
    pub acceleration: f32,
    pub watch: u8,
    pub watch_release: bool,
}

/// [`Planner::push`] found the ring full.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Full;

/// Per-motor limits in steps: rate (steps/s) and acceleration (steps/s²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotorLimits {
    pub max_rate: [f32; MOTORS],
    pub max_accel: [f32; MOTORS],
}

/// The ring of blocks.
pub struct Planner {
    blocks: [Block; PLANNER_SLOTS],
    head: u8,
    tail: u8,
    planned: u8,
    previous_unit: [f32; MOTORS],
    previous_nominal_speed_sqr: f32,
    /// `M205 J`, mm.
    pub junction_deviation: f32,
}

impl Default for Planner {
    fn default() -> Self {
        Self::new()
    }
}

/// Keep in `lowest` the (limit, steps) of the smallest limit/steps seen,
/// by cross-multiplying; steps 0: none seen yet. Out of line: the rate
/// and the acceleration share it.
#[inline(never)]
fn lower_ratio(lowest: &mut (f32, f32), limit: f32, steps: f32) {
    if lowest.1 == 0.0 || limit * lowest.1 < lowest.0 * steps {
        *lowest = (limit, steps);
    }
}

/// A move's unit vector is either of length 1 or all zero (no direction:
/// homing, extruder-only moves). Told apart by the bits, ±0.0 being the
/// only floats whose bits are zero but for the sign: the two squared
/// lengths this replaced were 8 soft-float multiplications and additions,
/// ≈ 2 000 AVR cycles for every line.
fn has_direction(unit: &[f32; MOTORS]) -> bool {
    unit.iter().any(|component| component.to_bits() << 1 != 0)
}

const fn next(index: u8) -> u8 {
    if index as usize + 1 == PLANNER_SLOTS {
        0
    } else {
        index + 1
    }
}

const fn prev(index: u8) -> u8 {
    if index == 0 {
        PLANNER_SLOTS as u8 - 1
    } else {
        index - 1
    }
}

impl Planner {
    /// The planner built directly in `slot` (inside the board's `static`
    /// machine), block by block: `new()` would build the whole ring as a
    /// temporary, 1.6 KB of the AVR's stack at boot.
    pub fn init_in(slot: &mut core::mem::MaybeUninit<Self>) -> &mut Self {
        let p = slot.as_mut_ptr();
        // SAFETY: every field of the valid slot is written once; the slot
        // is initialised afterwards. The ring and the previous unit vector
        // are zeroed with one memset each: all-zero bytes are a valid
        // `Block` (integers, a bool, floats: `new_empty_block`, which a
        // test compares) and 0.0.
        unsafe {
            core::ptr::write_bytes(core::ptr::addr_of_mut!((*p).blocks), 0, 1);
            core::ptr::addr_of_mut!((*p).head).write(0);
            core::ptr::addr_of_mut!((*p).tail).write(0);
            core::ptr::addr_of_mut!((*p).planned).write(0);
            core::ptr::write_bytes(core::ptr::addr_of_mut!((*p).previous_unit), 0, 1);
            core::ptr::addr_of_mut!((*p).previous_nominal_speed_sqr).write(0.0);
            core::ptr::addr_of_mut!((*p).junction_deviation).write(0.013);
            slot.assume_init_mut()
        }
    }

    /// Never called: the compiler checks that this pattern names every
    /// field, so a field added without a write in `init_in` does not build.
    #[allow(dead_code)]
    fn every_field_is_initialised(&self) {
        let Self { blocks: _, head: _, tail: _, planned: _, previous_unit: _, previous_nominal_speed_sqr: _, junction_deviation: _ } = self;
    }

    const fn new_empty_block() -> Block {
        Block {
            steps: [0; MOTORS],
            events: 0,
            direction: 0,
            watch: 0,
            watch_release: false,
            millimetres: 0.0,
            entry: SpeedSqr::ZERO,
            max_entry: SpeedSqr::ZERO,
            ramp: SpeedSqr::ZERO,
            nominal_speed_sqr: 0.0,
            acceleration: 0.0,
        }
    }

    pub const fn new() -> Self {
        const EMPTY: Block = Planner::new_empty_block();
        Self {
            blocks: [EMPTY; PLANNER_SLOTS],
            head: 0,
            tail: 0,
            planned: 0,
            previous_unit: [0.0; MOTORS],
            previous_nominal_speed_sqr: 0.0,
            junction_deviation: 0.013,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.head == self.tail
    }

    pub fn is_full(&self) -> bool {
        next(self.head) == self.tail
    }

    /// Blocks queued (the one being prepared included).
    pub fn len(&self) -> usize {
        (self.head as usize + PLANNER_SLOTS - self.tail as usize) % PLANNER_SLOTS
    }

    /// The oldest block: the one the segment preparation works on.
    pub fn current(&self) -> Option<&Block> {
        // `get`: no bounds check (and panic path) for the ring index.
        if self.is_empty() {
            None
        } else {
            self.blocks.get(self.tail as usize)
        }
    }

    pub fn current_mut(&mut self) -> Option<&mut Block> {
        if self.is_empty() {
            None
        } else {
            self.blocks.get_mut(self.tail as usize)
        }
    }

    /// Speed² the oldest block must end with: the next block's entry, or 0.
    pub fn exit_speed_sqr(&self) -> SpeedSqr {
        let following = next(self.tail);
        if self.is_empty() || following == self.head {
            SpeedSqr::ZERO
        } else {
            self.blocks.get(following as usize).map_or(SpeedSqr::ZERO, |block| block.entry)
        }
    }

    /// The oldest block's exit speed can no longer change: the next block
    /// exists and is at or before `planned`, which the passes never touch
    /// again (see the module comment). Its segments may then be queued as
    /// far ahead as the interrupt's queue allows.
    pub fn exit_is_final(&self) -> bool {
        // `planned` lies from `tail` to the newest block (it is `head` only
        // when the ring is empty): past `tail`, it has the next block at or
        // before it.
        self.planned != self.tail && self.planned != self.head
    }

    /// The oldest block is fully prepared: drop it.
    pub fn discard_current(&mut self) {
        if self.is_empty() {
            return;
        }
        if self.planned == self.tail {
            self.planned = next(self.tail);
        }
        self.tail = next(self.tail);
        if self.is_empty() {
            self.planned = self.tail;
        }
    }

    /// Drop every block (after a fault or an abandoned homing move).
    pub fn clear(&mut self) {
        self.tail = self.head;
        self.planned = self.head;
        self.previous_unit = [0.0; MOTORS];
        self.previous_nominal_speed_sqr = 0.0;
    }

    /// The blocks after the one being prepared, oldest first (for tests and
    /// reports).
    pub fn blocks(&self) -> impl Iterator<Item = &Block> {
        let mut index = self.tail;
        core::iter::from_fn(move || {
            if index == self.head {
                return None;
            }
            let block = &self.blocks[index as usize];
            index = next(index);
            Some(block)
        })
    }

    /// Add a move. `Err` when the ring is full (the caller still has the
    /// move: handing it back was a 40-byte copy on the AVR); a move without
    /// steps is accepted and dropped.
    pub fn push(&mut self, motion: &PlannerMove, limits: &MotorLimits) -> Result<(), Full> {
        if self.is_full() {
            return Err(Full);
        }
        let was_empty = self.is_empty();
        let head = self.head as usize;
        // Built in its slot (free: the ring is not full, and the head is
        // not published until the end), not as a temporary: the copy was a
        // memcpy and the temporary pushed the AVR frame past 63 bytes.
        // (`get_mut`: the head is always in the ring; no bounds check.)
        let Some(block) = self.blocks.get_mut(head) else {
            return Err(Full);
        };
        *block = Block { watch: motion.watch, watch_release: motion.watch_release, ..Block::default() };
        // A motor covers steps/L steps per mm of path: the path's speed and
        // acceleration are capped so that each motor stays within its own
        // limits, i.e. by the smallest limit·L/steps. The smallest ratio is
        // found by cross-multiplying (a/b < c/d ⇔ a·d < c·b), so there is
        // one division per limit instead of two per motor (each costs the
        // AVR hundreds of cycles, for every line of a slicer stream).
        // (limit, steps); steps 0: no motor seen yet (a moving motor has ≥ 1).
        let mut rate = (0.0, 0.0);
        let mut accel = (0.0, 0.0);
        // A running motor bit: a variable shift is a loop on the AVR.
        let mut bit = 1;
        for motor in 0..MOTORS {
            let motor_bit = bit;
            bit <<= 1;
            let steps = motion.steps[motor].unsigned_abs().min(MAX_BLOCK_STEPS);
            if steps == 0 {
                continue;
            }
            block.steps[motor] = steps as u16;
            block.events = block.events.max(steps as u16);
            if motion.steps[motor] > 0 {
                block.direction |= motor_bit;
            }
            let steps = steps as f32;
            let (motor_rate, motor_accel) = (limits.max_rate[motor], limits.max_accel[motor]);
            lower_ratio(&mut rate, motor_rate, steps);
            lower_ratio(&mut accel, motor_accel, steps);
        }
        // No motor moves: nothing to plan (both limits are set by the first
        // moving motor).
        if block.events == 0 {
            return Ok(());
        }
        let speed = min(motion.speed, rate.0 * motion.millimetres / rate.1);
        let acceleration = min(motion.acceleration, accel.0 * motion.millimetres / accel.1);
        if !(motion.millimetres > 0.0) || !(speed > 0.0) || !(acceleration > 0.0) {
            return Ok(());
        }
        block.millimetres = motion.millimetres;
        block.acceleration = acceleration;
        block.ramp = SpeedSqr::from_mm2_s2(2.0 * acceleration * motion.millimetres);
        let nominal_speed_sqr = speed * speed;
        block.nominal_speed_sqr = nominal_speed_sqr;
        block.entry = SpeedSqr::ZERO;
        let max_entry_speed_sqr = if was_empty {
            0.0
        } else {
            min(min(self.junction_speed_sqr(&motion.unit, acceleration), nominal_speed_sqr), self.previous_nominal_speed_sqr)
        };
        if let Some(block) = self.blocks.get_mut(head) {
            block.max_entry = SpeedSqr::from_mm2_s2(max_entry_speed_sqr);
        }
        self.previous_unit = motion.unit;
        self.previous_nominal_speed_sqr = nominal_speed_sqr;
        self.head = next(self.head);
        self.recalculate();
        Ok(())
    }

    /// Junction deviation (see the module comment).
    fn junction_speed_sqr(&self, unit: &[f32; MOTORS], acceleration: f32) -> f32 {
        if !has_direction(&self.previous_unit) || !has_direction(unit) {
            // No direction (homing, a change between printing and
            // extruder-only moves): start from rest.
            return 0.0;
        }
        let mut cos_theta = 0.0;
        for motor in 0..MOTORS {
            cos_theta -= self.previous_unit[motor] * unit[motor];
        }
        if cos_theta > 0.999_999 {
            return 0.0;
        }
        if cos_theta < -0.999_999 {
            return f32::MAX;
        }
        let sin_half = sqrt(0.5 * (1.0 - cos_theta));
        acceleration * self.junction_deviation * sin_half / (1.0 - sin_half)
    }

    fn recalculate(&mut self) {
        let newest = prev(self.head);
        // Backward pass over the blocks after `planned`.
        let mut index = newest;
        let mut next_entry = SpeedSqr::ZERO;
        while index != self.planned {
            // (`get`: ring indices, no bounds checks; never `None`.)
            let Some(block) = self.blocks.get_mut(index as usize) else { break };
            if block.entry != block.max_entry {
                block.entry = block.max_entry.min(next_entry.after(block.ramp));
            }
            next_entry = block.entry;
            index = prev(index);
        }
        // Forward pass from `planned`.
        let mut index = self.planned;
        while index != newest {
            let following = next(index);
            // Two fields, not a copy of the whole block (a memcpy on the AVR).
            let Some(current) = self.blocks.get(index as usize) else { break };
            let (current_entry, current_ramp) = (current.entry, current.ramp);
            let Some(block) = self.blocks.get_mut(following as usize) else { break };
            if current_entry < block.entry {
                let reachable = current_entry.after(current_ramp);
                if reachable < block.entry {
                    // Full acceleration through `current`: nothing before
                    // `block` can improve any more.
                    block.entry = reachable;
                    self.planned = following;
                }
            }
            if block.entry == block.max_entry {
                self.planned = following;
            }
            index = following;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ring_built_in_place_holds_empty_blocks() {
        // `init_in` zeroes the ring with a memset: zero bytes must be the
        // empty block.
        let mut slot = core::mem::MaybeUninit::<Planner>::uninit();
        let planner = Planner::init_in(&mut slot);
        assert!(planner.blocks.iter().all(|block| *block == Planner::new_empty_block()));
        assert_eq!(planner.previous_unit, [0.0; MOTORS]);
        assert!(planner.is_empty() && planner.junction_deviation == 0.013);
    }

    const LIMITS: MotorLimits = MotorLimits { max_rate: [30_000.0; MOTORS], max_accel: [300_000.0; MOTORS] };

    fn line(dx: f32, dy: f32, speed: f32) -> PlannerMove {
        let length = sqrt(dx * dx + dy * dy);
        PlannerMove {
            steps: [(dx * 100.0) as i32, (dy * 100.0) as i32, 0, 0],
            millimetres: length,
            unit: [dx / length, dy / length, 0.0, 0.0],
            speed,
            acceleration: 1000.0,
            watch: 0,
            watch_release: false,
        }
    }

    #[test]
    fn newest_block_always_stops_and_straight_lines_keep_speed() {
        let mut planner = Planner::new();
        for _ in 0..10 {
            planner.push(&line(10.0, 0.0, 100.0), &LIMITS).unwrap();
        }
        let blocks: std::vec::Vec<_> = planner.blocks().copied().collect();
        assert_eq!(blocks[0].entry, SpeedSqr::ZERO);
        // 10 mm at 1000 mm/s² from rest reaches √(2·1000·10) = 141 > 100.
        for block in &blocks[1..] {
            assert_eq!(block.entry.mm2_s2(), 100.0 * 100.0);
        }
        let last = blocks.last().unwrap();
        // It can still stop: entry² ≤ 2·a·L.
        assert!(last.entry <= last.ramp && last.ramp.mm2_s2() == 2.0 * last.acceleration * last.millimetres);
    }

    #[test]
    fn junction_deviation_matches_grbl_formula() {
        let mut planner = Planner::new();
        planner.push(&line(10.0, 0.0, 200.0), &LIMITS).unwrap();
        planner.push(&line(0.0, 10.0, 200.0), &LIMITS).unwrap();
        planner.push(&line(10.0, 0.0, 200.0), &LIMITS).unwrap();
        // 90°: sin(45°) = 0.7071; v² = a·δ·s/(1 − s) = 1000·0.013·2.4142.
        let expected = 1000.0 * 0.013 * (0.707_106_77 / (1.0 - 0.707_106_77));
        let second = planner.blocks().nth(1).unwrap();
        // Within the integer speed²'s resolution, 1/256 (mm/s)².
        assert!((second.max_entry.mm2_s2() - expected).abs() < 1.0 / 256.0, "{:?}", second.max_entry);
        assert_eq!(second.entry, second.max_entry);
        // A reversal stops.
        let mut planner = Planner::new();
        planner.push(&line(10.0, 0.0, 100.0), &LIMITS).unwrap();
        planner.push(&line(-10.0, 0.0, 100.0), &LIMITS).unwrap();
        assert_eq!(planner.blocks().nth(1).unwrap().max_entry, SpeedSqr::ZERO);
    }

    #[test]
    fn a_move_without_direction_is_entered_and_left_at_rest() {
        let mut planner = Planner::new();
        planner.push(&line(10.0, 0.0, 100.0), &LIMITS).unwrap();
        // An extruder-only move: no unit vector (both signs of zero).
        let retract = PlannerMove { steps: [0, 0, 0, -300], millimetres: 3.0, unit: [-0.0, 0.0, -0.0, 0.0], speed: 40.0, acceleration: 1000.0, watch: 0, watch_release: false };
        planner.push(&retract, &LIMITS).unwrap();
        planner.push(&line(10.0, 0.0, 100.0), &LIMITS).unwrap();
        let max_entries: std::vec::Vec<_> = planner.blocks().map(|block| block.max_entry).collect();
        assert_eq!(max_entries, [SpeedSqr::ZERO; 3]);
        // Two lines in the same direction: no corner limit, the nominal speed.
        planner.push(&line(10.0, 0.0, 100.0), &LIMITS).unwrap();
        assert_eq!(planner.blocks().nth(3).unwrap().max_entry.mm2_s2(), 100.0 * 100.0);
    }

    #[test]
    fn per_motor_limits_cap_speed_and_acceleration() {
        let limits = MotorLimits { max_rate: [5_000.0, 30_000.0, 30_000.0, 30_000.0], max_accel: [50_000.0, 300_000.0, 300_000.0, 300_000.0] };
        let mut planner = Planner::new();
        planner.push(&line(10.0, 0.0, 100.0), &limits).unwrap();
        let block = planner.current().unwrap();
        // 100 steps/mm: 5000 steps/s = 50 mm/s, 50 000 steps/s² = 500 mm/s².
        assert_eq!(block.nominal_speed_sqr, 2500.0);
        assert_eq!(block.acceleration, 500.0);
    }

    /// `exit_is_final` (two index compares) agrees with its definition:
    /// the block after the oldest exists and is at or before `planned`.
    #[test]
    fn the_oldest_exit_is_final_exactly_when_its_successor_is_planned() {
        let mut planner = Planner::new();
        let moves = [line(1.0, 0.0, 50.0), line(0.0, 1.0, 50.0), line(1.0, 0.0, 80.0), line(-1.0, 0.0, 50.0), line(0.5, 0.5, 50.0)];
        let mut seen = [false; 2];
        for round in 0..200 {
            if round % 3 == 2 {
                planner.discard_current();
            } else {
                let _ = planner.push(&moves[round % moves.len()], &LIMITS);
            }
            let slots = PLANNER_SLOTS as u8;
            let to_planned = (planner.planned + slots - planner.tail) % slots;
            let defined = planner.len() >= 2 && to_planned >= 1 && (to_planned as usize) < planner.len();
            assert_eq!(planner.exit_is_final(), defined, "round {round}");
            seen[defined as usize] = true;
        }
        assert_eq!(seen, [true, true]);
    }

    #[test]
    fn ring_fills_and_drains() {
        let mut planner = Planner::new();
        let mut accepted = 0;
        while planner.push(&line(1.0, 0.0, 50.0), &LIMITS).is_ok() {
            accepted += 1;
        }
        assert_eq!(accepted, PLANNER_SLOTS - 1);
        assert!(planner.is_full());
        planner.discard_current();
        assert!(!planner.is_full());
        assert_eq!(planner.len(), PLANNER_SLOTS - 2);
        planner.clear();
        assert!(planner.is_empty());
    }
}
