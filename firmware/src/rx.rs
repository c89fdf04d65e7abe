//! Serial receive ring: the RX interrupt produces, the main loop consumes.
//!
//! The interrupt must never wait and never lose a byte silently. When the
//! ring is full the byte is dropped *and counted*; the main loop turns a
//! non-zero count into an `Error:` reply and discards the damaged line, so the
//! host learns about the loss (and, with line numbers, gets a resend).
//!
//! Built on [`crate::ring`]: lock-free, one byte per index, no interrupt
//! lock on either end.

use crate::emergency::{Emergency, EmergencyScanner};
use crate::ring::{Consumer, Producer, Ring};

/// Bytes the ring holds (one slot of the queue stays empty by design).
pub const RX_RING_SLOTS: usize = 128;

/// The storage behind the ring; boards keep it in a `static`.
pub type RxQueue = Ring<u8, RX_RING_SLOTS>;

/// Interrupt side of the ring.
/// Put into the byte stream where bytes were lost (the ring was full, or
/// the UART overran): the line assembler refuses the line it falls in, so
/// the damage is charged to the line that lost bytes, not to whichever
/// line the main loop happens to be assembling. A NUL that arrives on the
/// wire is stored as [`NUL_ON_THE_WIRE`] instead, so it is refused as the
/// unexpected character it is, not reported as a receive overrun.
pub const LOST_BYTES: u8 = 0;

/// What a NUL received from the host is stored as: a byte no G-code
/// uses (the parser refuses it, a checksum over it fails), and never the
/// loss marker.
pub const NUL_ON_THE_WIRE: u8 = 0xFF;

pub struct RxProducer<'a> {
    queue: Producer<'a, u8, RX_RING_SLOTS>,
    dropped: u8,
    /// Bytes of the line being received were lost and its marker is not in
    /// the ring yet.
    marker_owed: bool,
    /// Lines whose terminator was lost with them, each still owed to the
    /// ring as a marker and a newline: every line the host sent gets its
    /// reply (an error and `ok`), so a host counting `ok`s never waits for
    /// one that cannot come.
    lines_owed: u8,
    /// The last byte seen (stored or lost) ended a line, so a terminator
    /// right after it ends no line (`\r\n`, blank lines: the assembler
    /// skips empty lines, and no reply is owed for them).
    after_terminator: bool,
    emergency: EmergencyScanner,
}

/// Main-loop side of the ring.
pub struct RxConsumer<'a> {
    queue: Consumer<'a, u8, RX_RING_SLOTS>,
}

/// Split a queue into its two ends.
pub fn split(queue: &mut RxQueue) -> (RxProducer<'_>, RxConsumer<'_>) {
    let (producer, consumer) = queue.split();
    let producer = RxProducer {
        queue: producer,
        dropped: 0,
        marker_owed: false,
        lines_owed: 0,
        after_terminator: true,
        emergency: EmergencyScanner::new(),
    };
    (producer, RxConsumer { queue: consumer })
}

fn is_terminator(byte: u8) -> bool {
    byte == b'\n' || byte == b'\r'
}

impl RxProducer<'_> {
    /// Store one received byte; O(1), never blocks. A byte that does not fit
    /// (or that the UART itself lost, `hardware_overrun`) is counted. Returns
    /// the emergency command this byte completes, which the interrupt acts
    /// on at once (it sees every byte, even those the ring has no room for).
    pub fn push(&mut self, byte: u8, hardware_overrun: bool) -> Option<Emergency> {
        if hardware_overrun {
            // The UART lost the byte before this one (what it was is unknown:
            // if it ended a line, that line and this one are refused as one).
            self.dropped = self.dropped.saturating_add(1);
            self.marker_owed = true;
            self.after_terminator = false;
        }
        // What is owed goes in before this byte, in the gap's place; until
        // all of it fits, this byte is lost too.
        let data = if byte == LOST_BYTES { NUL_ON_THE_WIRE } else { byte };
        let stored = self.nothing_owed() && self.queue.enqueue(data).is_ok();
        if !stored {
            self.lose(byte);
        }
        self.after_terminator = is_terminator(byte);
        self.emergency.push(byte)
    }

    /// Account for a byte the ring had no room for.
    #[cold]
    #[inline(never)]
    fn lose(&mut self, byte: u8) {
        self.dropped = self.dropped.saturating_add(1);
        if !is_terminator(byte) {
            self.marker_owed = true;
        } else if !self.after_terminator {
            // A line ended in the gap: it is owed a marker and its end.
            self.lines_owed = self.lines_owed.saturating_add(1);
            self.marker_owed = false;
        }
    }

    /// True when nothing is owed to the ring, after settling what fits.
    /// Inline and two flag tests when nothing is owed: it runs with
    /// interrupts off (the RX interrupt, and the main loop's critical
    /// section), where every cycle delays the next step.
    #[inline(always)]
    fn nothing_owed(&mut self) -> bool {
        if self.lines_owed == 0 && !self.marker_owed {
            return true;
        }
        self.settle_debts()
    }

    /// Put owed markers and line ends into the ring, oldest first, as far
    /// as there is room; true when nothing is owed any more.
    #[cold]
    #[inline(never)]
    fn settle_debts(&mut self) -> bool {
        while self.lines_owed > 0 {
            // A marker and its newline go in together or not at all.
            if self.queue.capacity() - self.queue.len() < 2 {
                return false;
            }
            let _ = self.queue.enqueue(LOST_BYTES);
            let _ = self.queue.enqueue(b'\n');
            self.lines_owed -= 1;
        }
        if self.marker_owed && self.queue.enqueue(LOST_BYTES).is_ok() {
            self.marker_owed = false;
        }
        !self.marker_owed
    }

    /// Bytes lost since the last call (and reset the count). Called by the
    /// main loop inside a critical section. Also settles what the ring is
    /// owed once it has room, so a gap at the end of a burst is marked,
    /// and the line it swallowed answered, even if no byte follows.
    pub fn take_dropped(&mut self) -> u8 {
        self.nothing_owed();
        core::mem::take(&mut self.dropped)
    }

    /// Something for [`Self::take_dropped`] to do: bytes lost, or markers
    /// and line ends still owed to the ring.
    pub fn has_trouble(&self) -> bool {
        self.dropped != 0 || self.marker_owed || self.lines_owed != 0
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

    fn fill_ring(p: &mut RxProducer<'_>) {
        for _ in 0..RX_RING_SLOTS - 1 {
            p.push(b'a', false);
        }
    }

    fn drain(c: &mut RxConsumer<'_>) -> std::vec::Vec<u8> {
        core::iter::from_fn(|| c.pop()).collect()
    }

    /// Lines that vanish whole into a full ring (their newline too) still
    /// come out as one damaged line each, so each gets its reply.
    #[test]
    fn every_line_lost_to_a_full_ring_still_ends_in_the_ring() {
        let mut q = RxQueue::new();
        let (mut p, mut c) = split(&mut q);
        fill_ring(&mut p);
        for b in b"1\nG1 X2\r\nG1 X" {
            p.push(*b, false); // all lost: two line ends and a line's start
        }
        drain(&mut c);
        for b in b"3\nM105\n" {
            p.push(*b, false);
        }
        assert_eq!(drain(&mut c), b"\0\n\0\n\x003\nM105\n");
        assert_eq!(p.take_dropped(), 13);
    }

    /// A gap at the end of a burst is closed by the main loop's call, with
    /// no byte following it.
    #[test]
    fn a_lost_last_newline_is_restored_without_a_following_byte() {
        let mut q = RxQueue::new();
        let (mut p, mut c) = split(&mut q);
        fill_ring(&mut p);
        p.push(b'\n', false);
        drain(&mut c);
        assert_eq!(p.take_dropped(), 1);
        assert_eq!(drain(&mut c), b"\0\n");
    }

    /// A lost terminator that ends no line (blank line, the `\n` of `\r\n`)
    /// owes nothing: the host expects no reply for it.
    #[test]
    fn lost_blank_lines_owe_no_reply() {
        let mut q = RxQueue::new();
        let (mut p, mut c) = split(&mut q);
        for _ in 0..RX_RING_SLOTS - 2 {
            p.push(b'a', false);
        }
        p.push(b'\r', false); // stored: the ring is full after it
        p.push(b'\n', false);
        p.push(b'\n', false);
        drain(&mut c);
        assert_eq!(p.take_dropped(), 2);
        p.push(b'M', false);
        assert_eq!(drain(&mut c), b"M");
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

    /// Issue 22, finding 4: a NUL from the host travelled as the loss
    /// marker and was reported as an overrun.
    #[test]
    fn a_nul_on_the_wire_is_not_the_loss_marker() {
        let mut q = RxQueue::new();
        let (mut p, mut c) = split(&mut q);
        for b in b"G1\0\n" {
            p.push(*b, false);
        }
        assert_eq!(drain(&mut c), b"G1\xff\n");
        assert_eq!(p.take_dropped(), 0);
    }

    #[test]
    fn a_hardware_overrun_is_counted_too() {
        let mut q = RxQueue::new();
        let (mut p, _c) = split(&mut q);
        p.push(b'a', true);
        assert_eq!(p.take_dropped(), 1);
    }
}
