//! A quadrature (A/B, optional index) decoder for the DC servo axes of
//! SPEC §5, as an edge-driven state machine.
//!
//! The board calls [`QuadratureDecoder::on_edge`] from the pin-change (or
//! external) interrupt of A and B with both pin levels read in that
//! interrupt; each legal transition moves the count by one (×4 decoding).
//! A transition where both A and B changed means at least one edge was
//! missed (the interrupt came too late): the count cannot know which way,
//! so it stays and the [`illegal_transitions`](QuadratureDecoder::illegal_transitions)
//! counter goes up. A steadily growing counter means the encoder outruns
//! the interrupt; the position is then suspect.
//!
//! With an index channel, [`on_index`](QuadratureDecoder::on_index) checks
//! that the count at each index pulse is the same modulo the counts per
//! revolution: a difference is a missed edge that the A/B state could not
//! see (two edges missed), counted in
//! [`index_mismatches`](QuadratureDecoder::index_mismatches).
//!
//! Cost: a table lookup and an add (~30 cycles on the AVR in the interrupt).
//! The tick reads [`count`](QuadratureDecoder::count) inside a critical
//! section on the AVR (an `i32` is four byte loads).

/// Count change for (previous AB << 2 | new AB); 2 marks an illegal jump.
const TRANSITIONS: [i8; 16] = [
    0, -1, 1, 2, // from 00: to 00, 01, 10, 11
    1, 0, 2, -1, // from 01
    -1, 2, 0, 1, // from 10
    2, 1, -1, 0, // from 11
];

#[derive(Clone, Copy, Debug)]
pub struct QuadratureDecoder {
    state: u8,
    count: i32,
    illegal: u16,
    /// Counts per revolution for the index check (0: no check).
    counts_per_rev: u16,
    /// Count at the first index pulse, modulo `counts_per_rev`.
    index_reference: Option<u16>,
    index_mismatches: u16,
}

impl QuadratureDecoder {
    /// `a`, `b`: the pin levels at start-up. `counts_per_rev`: counts (×4)
    /// between index pulses, or 0 without an index channel.
    pub const fn new(a: bool, b: bool, counts_per_rev: u16) -> Self {
        Self {
            state: ((a as u8) << 1) | b as u8,
            count: 0,
            illegal: 0,
            counts_per_rev,
            index_reference: None,
            index_mismatches: 0,
        }
    }

    /// A or B changed: both levels as read now. A call without a change
    /// (a glitch shorter than the interrupt latency) does nothing.
    pub fn on_edge(&mut self, a: bool, b: bool) {
        let new = ((a as u8) << 1) | b as u8;
        let change = TRANSITIONS[usize::from((self.state << 2) | new)];
        if change == 2 {
            self.illegal = self.illegal.saturating_add(1);
        } else {
            self.count = self.count.wrapping_add(i32::from(change));
        }
        self.state = new;
    }

    /// The index pulse (rising edge).
    pub fn on_index(&mut self) {
        if self.counts_per_rev == 0 {
            return;
        }
        let phase = self.count.rem_euclid(i32::from(self.counts_per_rev)) as u16;
        match self.index_reference {
            None => self.index_reference = Some(phase),
            Some(reference) if reference != phase => {
                self.index_mismatches = self.index_mismatches.saturating_add(1);
                // Re-anchor so one slip is counted once.
                self.index_reference = Some(phase);
            }
            Some(_) => {}
        }
    }

    pub fn count(&self) -> i32 {
        self.count
    }

    /// Homing: the current position becomes `count`.
    pub fn set_count(&mut self, count: i32) {
        self.count = count;
        self.index_reference = None;
    }

    pub fn illegal_transitions(&self) -> u16 {
        self.illegal
    }

    pub fn index_mismatches(&self) -> u16 {
        self.index_mismatches
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gray sequence forward: 00 → 10 → 11 → 01 → 00 (A leads B).
    const FORWARD: [(bool, bool); 4] = [(true, false), (true, true), (false, true), (false, false)];

    #[test]
    fn counts_four_per_cycle_forward_and_back() {
        let mut q = QuadratureDecoder::new(false, false, 0);
        for _ in 0..10 {
            for (a, b) in FORWARD {
                q.on_edge(a, b);
            }
        }
        assert_eq!(q.count(), 40);
        for _ in 0..3 {
            for (a, b) in FORWARD.iter().rev().skip(1).chain(core::iter::once(&(false, false))) {
                q.on_edge(*a, *b);
            }
        }
        assert_eq!(q.count(), 28);
        assert_eq!(q.illegal_transitions(), 0);
    }

    #[test]
    fn both_channels_changing_at_once_is_a_missed_edge_counted_not_moved() {
        let mut q = QuadratureDecoder::new(false, false, 0);
        q.on_edge(true, false); // +1
        q.on_edge(false, true); // 10 → 01: both changed
        assert_eq!(q.count(), 1);
        assert_eq!(q.illegal_transitions(), 1);
    }

    #[test]
    fn a_call_without_change_does_nothing() {
        let mut q = QuadratureDecoder::new(true, true, 0);
        q.on_edge(true, true);
        assert_eq!((q.count(), q.illegal_transitions()), (0, 0));
    }

    #[test]
    fn index_pulses_at_the_same_phase_agree_and_a_slip_is_counted() {
        let mut q = QuadratureDecoder::new(false, false, 200);
        let step = |q: &mut QuadratureDecoder, n: usize| {
            for _ in 0..n {
                for (a, b) in FORWARD {
                    q.on_edge(a, b);
                }
            }
        };
        q.on_index();
        step(&mut q, 50); // one revolution: 200 counts
        q.on_index();
        assert_eq!(q.index_mismatches(), 0);
        step(&mut q, 49);
        q.on_edge(true, false);
        q.on_edge(false, true); // two edges lost: illegal, count 2 short
        q.on_edge(false, false);
        q.on_index();
        assert_eq!(q.index_mismatches(), 1);
        assert_eq!(q.illegal_transitions(), 1);
    }

    #[test]
    fn homing_sets_the_count() {
        let mut q = QuadratureDecoder::new(false, false, 0);
        q.on_edge(true, false);
        q.set_count(-100);
        q.on_edge(true, true);
        assert_eq!(q.count(), -99);
    }
}
