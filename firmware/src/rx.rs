//! Serial receive ring: the RX interrupt produces, the main loop consumes.
//!
//! The interrupt must never wait and never lose a byte silently. When the
//! ring is full the byte is dropped *and counted*; the main loop turns a
//! non-zero count into an `Error:` reply and discards the damaged line, so the
//! host learns about the loss (and, with line numbers, gets a resend).
//!
//! Built on `heapless::spsc`, which is lock-free (single producer, single
//! consumer). On the AVR it needs heapless' `portable-atomic` feature.

use crate::emergency::{Emergency, EmergencyScanner};
use heapless::spsc::{Consumer, Producer, Queue};

/// Bytes the ring holds (one slot of the queue stays empty by design).
pub const RX_RING_SLOTS: usize = 128;

/// The storage behind the ring; boards keep it in a `static`.
pub type RxQueue = Queue<u8, RX_RING_SLOTS>;

/// Interrupt side of the ring.
/// Put into the byte stream where bytes were lost (the ring was full, or
/// the UART overran): the line assembler refuses the line it falls in, so
/// the damage is charged to the line that lost bytes, not to whichever
/// line the main loop happens to be assembling. NUL never belongs in
/// G-code, so a NUL that arrives on the wire is refused the same way.
pub const LOST_BYTES: u8 = 0;

pub struct RxProducer<'a> {
    queue: Producer<'a, u8, RX_RING_SLOTS>,
    dropped: u8,
    /// Bytes were lost and the marker is not in the ring yet.
    marker_owed: bool,
    emergency: EmergencyScanner,
}

/// Main-loop side of the ring.
pub struct RxConsumer<'a> {
    queue: Consumer<'a, u8, RX_RING_SLOTS>,
}

/// Split a queue into its two ends.
pub fn split(queue: &mut RxQueue) -> (RxProducer<'_>, RxConsumer<'_>) {
    let (producer, consumer) = queue.split();
    (RxProducer { queue: producer, dropped: 0, marker_owed: false, emergency: EmergencyScanner::new() }, RxConsumer { queue: consumer })
}

impl RxProducer<'_> {
    /// Store one received byte; O(1), never blocks. A byte that does not fit
    /// (or that the UART itself lost, `hardware_overrun`) is counted. Returns
    /// the emergency command this byte completes, which the interrupt acts
    /// on at once (it sees every byte, even those the ring has no room for).
    pub fn push(&mut self, byte: u8, hardware_overrun: bool) -> Option<Emergency> {
        if hardware_overrun {
            // The UART lost the byte before this one.
            self.dropped = self.dropped.saturating_add(1);
            self.marker_owed = true;
        }
        // The marker goes in before the first byte after the gap (it needs
        // a slot of its own; until there is one, that byte is lost too).
        if self.marker_owed && self.queue.enqueue(LOST_BYTES).is_ok() {
            self.marker_owed = false;
        }
        if self.marker_owed || self.queue.enqueue(byte).is_err() {
            self.dropped = self.dropped.saturating_add(1);
            self.marker_owed = true;
        }
        self.emergency.push(byte)
    }

    /// Take (and reset) the count of bytes lost since the last call.
    /// Called by the main loop inside a critical section.
    /// Bytes lost since the last call. Also puts an owed marker into the
    /// ring once it has room, so a gap at the end of a burst is marked
    /// even if no byte follows it for a while.
    pub fn take_dropped(&mut self) -> u8 {
        if self.marker_owed && self.queue.enqueue(LOST_BYTES).is_ok() {
            self.marker_owed = false;
        }
        core::mem::take(&mut self.dropped)
    }
}

impl RxConsumer<'_> {
    /// Next received byte, if any.
    pub fn pop(&mut self) -> Option<u8> {
        self.queue.dequeue()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_come_out_in_order() {
        let mut q = RxQueue::new();
        let (mut p, mut c) = split(&mut q);
        for b in b"M105\n" {
            p.push(*b, false);
        }
        let mut got = [0u8; 5];
        for slot in got.iter_mut() {
            *slot = c.pop().unwrap();
        }
        assert_eq!(&got, b"M105\n");
        assert_eq!(c.pop(), None);
    }

    /// After a gap the marker comes first, in the byte's place: the
    /// consumer sees exactly where the stream is broken.
    #[test]
    fn bytes_lost_to_a_full_ring_leave_a_marker_where_they_were() {
        let mut q = RxQueue::new();
        let (mut p, mut c) = split(&mut q);
        for _ in 0..RX_RING_SLOTS - 1 {
            p.push(b'a', false);
        }
        p.push(b'L', false); // lost: the ring holds 127
        for _ in 0..3 {
            c.pop();
        }
        p.push(b'b', false); // the marker takes the first free slot
        p.push(b'c', false);
        let tail: std::vec::Vec<u8> = core::iter::from_fn(|| c.pop()).collect();
        assert_eq!(&tail[tail.len() - 3..], &[LOST_BYTES, b'b', b'c']);
        assert_eq!(p.take_dropped(), 1);
    }

    #[test]
    fn a_full_ring_counts_every_dropped_byte() {
        let mut q = RxQueue::new();
        let (mut p, _c) = split(&mut q);
        for _ in 0..RX_RING_SLOTS + 9 {
            p.push(b'x', false);
        }
        // heapless keeps one slot free: capacity is SLOTS - 1.
        assert_eq!(p.take_dropped(), 10);
        assert_eq!(p.take_dropped(), 0);
    }

    #[test]
    fn an_emergency_command_is_reported_even_when_the_ring_is_full() {
        let mut q = RxQueue::new();
        let (mut p, _c) = split(&mut q);
        for _ in 0..RX_RING_SLOTS {
            p.push(b'\n', false);
        }
        let found: std::vec::Vec<_> = b"M112\n".iter().filter_map(|&b| p.push(b, false)).collect();
        assert_eq!(found, [Emergency::Kill]);
    }

    #[test]
    fn a_hardware_overrun_is_counted_too() {
        let mut q = RxQueue::new();
        let (mut p, _c) = split(&mut q);
        p.push(b'a', true);
        assert_eq!(p.take_dropped(), 1);
    }
}
