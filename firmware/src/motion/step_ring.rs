//! The queues between the main loop and the step interrupt: one producer
//! (the main loop), one consumer (the interrupt), `N` slots (a power of
//! two), of which `N − 1` hold items.
//!
//! Why not `heapless::spsc` (which the rest of the firmware uses): the step
//! interrupt takes a segment every few milliseconds and, at 30 000
//! steps/s, has 533 CPU cycles per event on the ATmega2560, of which the
//! ordinary event already needs ~390. heapless indexes with `usize` atomics,
//! which a chip without 16-bit atomic loads emulates with an interrupt
//! lock per access, and hands items out by value through a stack copy: the
//! segment change cost ~200 cycles on top of the event and made one
//! stepper's steps late above 25 000 steps/s on the bench. Here the indices
//! are single bytes (one load or store, atomic on any chip) and the
//! consumer reads the front item in place ([`Consumer::front`]) before
//! releasing its slot ([`Consumer::release`]).
//!
//! Ordering, for one core whose consumer is an interrupt handler (the
//! Mega 2560, the STM32F4; hal-sim runs both ends on one thread): the
//! producer writes the slot and then publishes it by storing `tail`, both
//! as volatile writes, which the compiler keeps in program order; the
//! consumer runs with the producer stopped (interrupts do not nest into
//! the step handler), so its reads need no order, and it gives a slot back
//! with a volatile store of `head`. Indices are single bytes: one load or
//! store on any chip.
//!
//! Not `core::sync::atomic::AtomicU8`: on `avr-none` (nightly 2025) the
//! ring built on it produced no steps at all on the real ELF while the
//! host tests passed; `portable_atomic::AtomicU8` worked but called an
//! out-of-line function with the ordering as an argument for every access
//! (~40 cycles each). See the README's toolchain traps.

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;
use core::ptr::{read_volatile, write_volatile};

pub struct StepRing<T, const N: usize> {
    slots: [UnsafeCell<MaybeUninit<T>>; N],
    /// Next slot the consumer reads; written by the consumer only.
    head: UnsafeCell<u8>,
    /// Next slot the producer writes; written by the producer only.
    tail: UnsafeCell<u8>,
}

impl<T: Copy, const N: usize> Default for StepRing<T, N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Copy, const N: usize> StepRing<T, N> {
    const MASK: u8 = {
        assert!(N.is_power_of_two() && N >= 2 && N <= 128, "N: a power of two from 2 to 128");
        (N - 1) as u8
    };

    pub const fn new() -> Self {
        Self { slots: [const { UnsafeCell::new(MaybeUninit::uninit()) }; N], head: UnsafeCell::new(0), tail: UnsafeCell::new(0) }
    }

    /// The two ends; the borrow keeps the ring from being split twice.
    pub fn split(&mut self) -> (Producer<'_, T, N>, Consumer<'_, T, N>) {
        let ring: &Self = self;
        (Producer { ring }, Consumer { ring })
    }

    fn slot(&self, index: u8) -> *mut MaybeUninit<T> {
        self.slots[usize::from(index & Self::MASK)].get()
    }

    #[inline(always)]
    fn head(&self) -> u8 {
        // SAFETY: a byte that only the consumer writes (see the module docs).
        unsafe { read_volatile(self.head.get()) }
    }

    #[inline(always)]
    fn tail(&self) -> u8 {
        // SAFETY: a byte that only the producer writes.
        unsafe { read_volatile(self.tail.get()) }
    }
}

/// The main loop's end.
pub struct Producer<'a, T, const N: usize> {
    ring: &'a StepRing<T, N>,
}

impl<T: Copy, const N: usize> Producer<'_, T, N> {
    /// Room for one more item.
    pub fn ready(&self) -> bool {
        self.ring.tail().wrapping_sub(self.ring.head()) & StepRing::<T, N>::MASK != StepRing::<T, N>::MASK
    }

    /// Queue `item`, or hand it back when the ring is full.
    pub fn enqueue(&mut self, item: T) -> Result<(), T> {
        if !self.ready() {
            return Err(item);
        }
        let tail = self.ring.tail();
        // SAFETY: the slot at `tail` is outside head..tail: the consumer
        // does not touch it until the volatile store below (after this
        // volatile write) publishes it; `tail` is this end's own byte.
        unsafe {
            write_volatile(self.ring.slot(tail), MaybeUninit::new(item));
            write_volatile(self.ring.tail.get(), tail.wrapping_add(1) & StepRing::<T, N>::MASK);
        }
        Ok(())
    }

    /// Items waiting for the consumer.
    pub fn len(&self) -> usize {
        usize::from(self.ring.tail().wrapping_sub(self.ring.head()) & StepRing::<T, N>::MASK)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The interrupt's end.
pub struct Consumer<'a, T, const N: usize> {
    ring: &'a StepRing<T, N>,
}

impl<T: Copy, const N: usize> Consumer<'_, T, N> {
    /// An item is waiting.
    #[inline(always)]
    pub fn ready(&self) -> bool {
        self.ring.head() != self.ring.tail()
    }

    /// The oldest item, read in place; [`Self::release`] frees its slot.
    #[inline(always)]
    pub fn front(&self) -> Option<&T> {
        let head = self.ring.head();
        if head == self.ring.tail() {
            return None;
        }
        // SAFETY: head != tail: the producer wrote and published this slot
        // and will not reuse it before `release` moves `head` past it.
        Some(unsafe { (*self.ring.slot(head)).assume_init_ref() })
    }

    /// Free the oldest item's slot (after [`Self::front`] returned it).
    #[inline(always)]
    pub fn release(&mut self) {
        let head = self.ring.head();
        if head != self.ring.tail() {
            // SAFETY: `head` is this end's own byte.
            unsafe { write_volatile(self.ring.head.get(), head.wrapping_add(1) & StepRing::<T, N>::MASK) };
        }
    }

    /// Take the oldest item.
    pub fn dequeue(&mut self) -> Option<T> {
        let item = *self.front()?;
        self.release();
        Some(item)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ring_of_four_slots_holds_three_items_in_order() {
        let mut ring = StepRing::<u16, 4>::new();
        let (mut producer, mut consumer) = ring.split();
        assert_eq!(consumer.front(), None);
        assert_eq!((producer.enqueue(1), producer.enqueue(2), producer.enqueue(3)), (Ok(()), Ok(()), Ok(())));
        assert!(!producer.ready());
        assert_eq!(producer.enqueue(4), Err(4));
        assert_eq!(producer.len(), 3);
        assert_eq!(consumer.front(), Some(&1));
        consumer.release();
        assert_eq!(producer.enqueue(4), Ok(()));
        assert_eq!([consumer.dequeue(), consumer.dequeue(), consumer.dequeue(), consumer.dequeue()], [Some(2), Some(3), Some(4), None]);
        assert!(producer.is_empty() && !consumer.ready());
    }

    #[test]
    fn indices_wrap_around_the_ring_many_times() {
        let mut ring = StepRing::<u32, 16>::new();
        let (mut producer, mut consumer) = ring.split();
        let mut next_out = 0;
        for item in 0..10_000u32 {
            if producer.enqueue(item).is_err() {
                while let Some(out) = consumer.dequeue() {
                    assert_eq!(out, next_out);
                    next_out += 1;
                }
                producer.enqueue(item).unwrap();
            }
        }
        while let Some(out) = consumer.dequeue() {
            assert_eq!(out, next_out);
            next_out += 1;
        }
        assert_eq!(next_out, 10_000);
    }

    #[test]
    fn release_on_an_empty_ring_does_nothing() {
        let mut ring = StepRing::<u8, 2>::new();
        let (mut producer, mut consumer) = ring.split();
        consumer.release();
        assert_eq!(producer.enqueue(7), Ok(()));
        assert_eq!(producer.enqueue(8), Err(8));
        assert_eq!(consumer.dequeue(), Some(7));
    }
}
