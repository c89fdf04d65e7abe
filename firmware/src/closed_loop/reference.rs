//! The reference the loops follow: straight pieces at constant velocity,
//! queued by the main loop, interpolated per tick, with a feedforward
//! preview.
//!
//! Why a preview (ours): the identified axis has a 0.1 s dead time, so a
//! causal loop that learns about a velocity change when it happens is
//! 0.1 s late by construction (at 5 mm/s that is 0.5 mm; on the 5 mm/s
//! circle the start alone costs v²θ³/3 / 12.6 s ≈ 0.0007 mm² of MSE, and
//! the simulated robust PID goes from 0.0039 mm² without preview to
//! 0.00023 mm² with it). The pieces are known
//! in advance (the planner queued them), so the feedforward velocity is
//! taken `preview_ticks` ahead of the reference position: the command
//! reaches the axis when the reference gets there. The loop still compares
//! the measurement with the reference *now*. Zero preview gives the plain
//! ẋd feedforward.
//!
//! A path that starts from rest holds its start position for the preview
//! time while the feedforward already runs. If the main loop lets the queue
//! run dry, the preview shrinks (the look-ahead cursor waits at the end of
//! the queue): keep at least the preview time queued.
//!
//! Cost per tick: per axis two 16/32-bit adds and a compare; the division that
//! turns a piece into per-tick increments happens in [`push`](ReferencePath::push),
//! in the main loop. On the AVR, `push` and `advance` share the path inside
//! a critical section.

use super::control::Reference;
use super::Units;

#[derive(Clone, Copy, Debug)]
struct Piece<const AXES: usize> {
    end: [Units; AXES],
    /// Units per tick: whole part (floor) and 16 fraction bits.
    increment: [i32; AXES],
    increment_fraction: [u16; AXES],
    /// Units per second.
    velocity: [i32; AXES],
    ticks: u16,
}

/// Why a piece was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathError {
    /// The queue is full: try again after a few ticks.
    Full,
    /// A piece needs at least one tick.
    ZeroDuration,
    /// More than 32767 units (16 mm on the printer) per tick.
    TooFast,
}

/// A queue of `N` pieces for `AXES` axes that move together.
#[derive(Clone, Copy, Debug)]
pub struct ReferencePath<const AXES: usize, const N: usize> {
    pieces: [Piece<AXES>; N],
    /// Oldest piece (the one the present cursor is in).
    head: u8,
    len: u8,
    /// End of the last queued piece: the start of the next.
    queued_end: [Units; AXES],
    /// The reference position: whole units (floor) and 16 fraction bits
    /// (two words instead of an i64: the AVR shifts an i64 bit by bit).
    position: [Units; AXES],
    position_fraction: [u16; AXES],
    present_tick: u16,
    /// Ticks the present cursor still waits at the start of a path.
    start_delay: u16,
    /// Look-ahead cursor: piece (counted from head) and tick in it.
    lead_piece: u8,
    lead_tick: u16,
    preview_ticks: u16,
    tick_hz: u16,
}

impl<const AXES: usize, const N: usize> ReferencePath<AXES, N> {
    /// A path at rest at `start`, for a loop ticking at `tick_hz`, with the
    /// feedforward `preview_ticks` ahead.
    pub fn new(start: [Units; AXES], tick_hz: u16, preview_ticks: u16) -> Self {
        Self {
            pieces: [Piece { end: [0; AXES], increment: [0; AXES], increment_fraction: [0; AXES], velocity: [0; AXES], ticks: 0 }; N],
            head: 0,
            len: 0,
            queued_end: start,
            position: start,
            position_fraction: [0; AXES],
            present_tick: 0,
            start_delay: 0,
            lead_piece: 0,
            lead_tick: 0,
            preview_ticks,
            tick_hz,
        }
    }

    /// Queue a straight piece to `end`, taking `ticks` ticks (main loop).
    pub fn push(&mut self, end: [Units; AXES], ticks: u16) -> Result<(), PathError> {
        if ticks == 0 {
            return Err(PathError::ZeroDuration);
        }
        if usize::from(self.len) >= N {
            return Err(PathError::Full);
        }
        let mut piece = Piece { end, increment: [0; AXES], increment_fraction: [0; AXES], velocity: [0; AXES], ticks };
        #[allow(clippy::needless_range_loop)] // four arrays in step
        for axis in 0..AXES {
            let distance = i64::from(end[axis]) - i64::from(self.queued_end[axis]);
            let increment = (distance << 16) / i64::from(ticks);
            if increment.abs() > i64::from(i32::MAX) {
                return Err(PathError::TooFast);
            }
            piece.increment[axis] = (increment >> 16) as i32;
            piece.increment_fraction[axis] = increment as u16;
            piece.velocity[axis] = (distance * i64::from(self.tick_hz) / i64::from(ticks)) as i32;
        }
        if self.len == 0 {
            // From rest: the feedforward starts now, the reference later.
            self.start_delay = self.preview_ticks;
            self.present_tick = 0;
            self.lead_piece = 0;
            self.lead_tick = 0;
        }
        let slot = (usize::from(self.head) + usize::from(self.len)) % N;
        self.pieces[slot] = piece;
        self.len += 1;
        self.queued_end = end;
        Ok(())
    }

    /// One tick: the reference for now (position, and the feedforward
    /// velocity `preview_ticks` ahead), then move on.
    pub fn advance(&mut self) -> [Reference; AXES] {
        let mut references = [Reference::default(); AXES];
        for (reference, position) in references.iter_mut().zip(self.position()) {
            reference.position = position;
        }
        if self.lead_piece < self.len {
            let piece = &self.pieces[(usize::from(self.head) + usize::from(self.lead_piece)) % N];
            for (reference, &velocity) in references.iter_mut().zip(piece.velocity.iter()) {
                reference.velocity = velocity;
            }
            self.lead_tick += 1;
            if self.lead_tick >= piece.ticks {
                self.lead_tick = 0;
                self.lead_piece += 1;
            }
        }
        if self.start_delay > 0 {
            self.start_delay -= 1;
        } else if self.len > 0 {
            let head = usize::from(self.head);
            self.present_tick += 1;
            if self.present_tick >= self.pieces[head].ticks {
                self.position = self.pieces[head].end;
                self.position_fraction = [0; AXES];
                self.present_tick = 0;
                self.head = ((head + 1) % N) as u8;
                self.len -= 1;
                if self.lead_piece > 0 {
                    self.lead_piece -= 1;
                } else {
                    self.lead_tick = 0;
                }
            } else {
                let piece = &self.pieces[head];
                for axis in 0..AXES {
                    let (fraction, carry) = self.position_fraction[axis].overflowing_add(piece.increment_fraction[axis]);
                    self.position_fraction[axis] = fraction;
                    self.position[axis] = self.position[axis].wrapping_add(piece.increment[axis]).wrapping_add(i32::from(carry));
                }
            }
        }
        references
    }

    /// No piece left: the reference is at rest.
    pub fn is_idle(&self) -> bool {
        self.len == 0
    }

    pub fn free_slots(&self) -> usize {
        N - usize::from(self.len)
    }

    /// The reference position now (units).
    pub fn position(&self) -> [Units; AXES] {
        let mut out = self.position;
        for (units, &fraction) in out.iter_mut().zip(self.position_fraction.iter()) {
            if fraction >= 0x8000 {
                *units = units.wrapping_add(1);
            }
        }
        out
    }

    /// Drop every queued piece and stay where the reference is (quick stop,
    /// fault). Also the new start after homing: `restart_at`.
    pub fn clear(&mut self) {
        self.len = 0;
        self.start_delay = 0;
        self.lead_piece = 0;
        self.lead_tick = 0;
        self.queued_end = self.position();
    }

    /// Empty the queue and put the reference at `position` (homing, G92).
    pub fn restart_at(&mut self, position: [Units; AXES]) {
        *self = Self::new(position, self.tick_hz, self.preview_ticks);
    }

    pub fn preview_ticks(&self) -> u16 {
        self.preview_ticks
    }

    /// Change the preview (only while idle: returns false otherwise).
    pub fn set_preview_ticks(&mut self, preview_ticks: u16) -> bool {
        if !self.is_idle() {
            return false;
        }
        self.preview_ticks = preview_ticks;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    #[test]
    fn interpolates_a_piece_and_lands_exactly_on_its_end() {
        let mut path = ReferencePath::<1, 4>::new([0], 1000, 0);
        path.push([1000], 3).unwrap();
        let positions: Vec<i32> = (0..5).map(|_| path.advance()[0].position).collect();
        assert_eq!(positions, [0, 333, 667, 1000, 1000]);
        assert!(path.is_idle());
    }

    #[test]
    fn velocity_is_the_pieces_distance_over_its_duration() {
        let mut path = ReferencePath::<2, 4>::new([0, 0], 1000, 0);
        // 10240 units (5 mm) in 1000 ticks (1 s): 10240 units/s; Y back 1 mm
        path.push([10_240, -2048], 1000).unwrap();
        let r = path.advance();
        assert_eq!((r[0].velocity, r[1].velocity), (10_240, -2048));
    }

    #[test]
    fn the_feedforward_runs_preview_ticks_ahead_of_the_position() {
        let mut path = ReferencePath::<1, 4>::new([0], 1000, 2);
        path.push([400], 4).unwrap();
        path.push([400], 2).unwrap(); // a pause
        let seen: Vec<(i32, i32)> = (0..8).map(|_| path.advance()[0]).map(|r| (r.position, r.velocity)).collect();
        assert_eq!(
            seen,
            [(0, 100_000), (0, 100_000), (0, 100_000), (100, 100_000), (200, 0), (300, 0), (400, 0), (400, 0)]
        );
    }

    #[test]
    fn refuses_a_full_queue_and_zero_duration() {
        let mut path = ReferencePath::<1, 2>::new([0], 1000, 0);
        assert_eq!(path.push([1], 0), Err(PathError::ZeroDuration));
        path.push([1], 1).unwrap();
        path.push([2], 1).unwrap();
        assert_eq!(path.push([3], 1), Err(PathError::Full));
        path.advance();
        assert_eq!(path.free_slots(), 1);
        assert!(path.push([3], 1).is_ok());
    }

    #[test]
    fn no_drift_over_many_pieces_with_remainders() {
        let mut path = ReferencePath::<1, 8>::new([0], 1000, 0);
        let mut target = 0;
        for _ in 0..1000 {
            while path.free_slots() > 0 {
                target += 7;
                path.push([target], 3).unwrap();
            }
            path.advance();
        }
        while !path.is_idle() {
            path.advance();
        }
        assert_eq!(path.position(), [target]);
    }

    #[test]
    fn clear_stops_where_the_reference_is() {
        let mut path = ReferencePath::<1, 4>::new([0], 1000, 0);
        path.push([1000], 10).unwrap();
        path.advance();
        path.advance();
        path.clear();
        assert!(path.is_idle());
        assert_eq!(path.advance()[0], Reference { position: 200, velocity: 0 });
    }

    #[test]
    fn the_path_is_small() {
        // two axes, four pieces
        assert!(core::mem::size_of::<ReferencePath<2, 4>>() <= 176, "{}", core::mem::size_of::<ReferencePath<2, 4>>());
    }
}
