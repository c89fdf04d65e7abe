//! The queues between the main loop and the interrupts: the step
//! interrupt's segments and blocks (`motion::stepper`) and the serial
//! receive ring (`rx`). One producer, one consumer, `N` slots (a power of
//! two up to 128), of which `N − 1` hold items.
//!
//! Why not `heapless::spsc` (which these queues used before): it indexes
//! with `usize` atomics, which a chip without 16-bit atomic loads emulates
//! with an interrupt lock per access, and hands items out by value through
//! a stack copy. On the ATmega2560 the step interrupt has 533 cycles per
//! event at 30 000 steps/s, of which the ordinary event already needs
//! ~390; heapless' segment change cost ~200 more and made one stepper's
//! steps late above 25 000 steps/s on the bench. Here the indices are
//! single bytes (one load or store on any chip) and the consumer reads the
//! front item in place ([`Consumer::front`]) before releasing its slot
//! ([`Consumer::release`]).
//!
//! Ordering: the producer writes the slot and then publishes it by storing
//! `tail` (Release); the consumer loads `tail` (Acquire) before reading a
//! slot and frees it by storing `head` (Release); the producer loads `head`
//! (Acquire) before reusing a slot. Those are `AtomicU8` operations except
//! on the AVR, which runs the firmware on one core with the other end in an
//! interrupt handler: there both indices and the slot writes are volatile,
//! which the compiler keeps in program order; the
//! consumer runs with the producer stopped (an interrupt handler is not
//! interrupted by the main loop), so its reads need no order, and it gives a
//! slot back with a volatile store of `head`. When the producer is the
//! interrupt (serial receive) the same holds the other way round: the main
//! loop's reads of a published slot happen after its volatile read of
//! `tail`, and the handler writes only slots outside head..tail.
//!
//! Not `core::sync::atomic::AtomicU8`: on `avr-none` (nightly 2025) the
//! step ring built on it produced no steps at all on the real ELF while
//! the host tests passed; `portable_atomic::AtomicU8` worked but called an
//! out-of-line function with the ordering as an argument for every access
//! (~40 cycles each). See the README's toolchain traps.

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;
use core::ptr::write_volatile;

/// One index byte, written by one end only.
#[cfg(not(target_arch = "avr"))]
struct Index(core::sync::atomic::AtomicU8);

#[cfg(not(target_arch = "avr"))]
impl Index {
    const fn new() -> Self {
        Self(core::sync::atomic::AtomicU8::new(0))
    }

    #[inline(always)]
    fn load(&self) -> u8 {
        self.0.load(core::sync::atomic::Ordering::Acquire)
    }

    #[inline(always)]
    fn store(&self, value: u8) {
        self.0.store(value, core::sync::atomic::Ordering::Release)
    }
}

/// One index byte, written by one end only (volatile: see the module docs).
#[cfg(target_arch = "avr")]
struct Index(UnsafeCell<u8>);

#[cfg(target_arch = "avr")]
impl Index {
    const fn new() -> Self {
        Self(UnsafeCell::new(0))
    }

    #[inline(always)]
    fn load(&self) -> u8 {
        // SAFETY: a byte: one load, never torn; the other end only reads it.
        unsafe { core::ptr::read_volatile(self.0.get()) }
    }

    #[inline(always)]
    fn store(&self, value: u8) {
        // SAFETY: only this index's own end writes it.
        unsafe { write_volatile(self.0.get(), value) }
    }
}

/// The indices come first (`repr(C)`): the AVR reaches them and the slots
/// from one pointer register (the step interrupt's segment change kept a
/// second pointer, and saved it, when they came after 176 bytes of slots).
#[repr(C)]
pub struct Ring<T, const N: usize> {
    /// Next slot the consumer reads; written by the consumer only.
    head: Index,
    /// Next slot the producer writes; written by the producer only.
    tail: Index,
    slots: [UnsafeCell<MaybeUninit<T>>; N],
}

// SAFETY: each index is written by one end only and published with
// Release/Acquire (volatile in program order on the single-core AVR); a
// slot is written by the producer only while outside head..tail and read by
// the consumer only while inside, so the two ends never touch one slot at
// once. `split` borrows the ring mutably, so there is one pair of ends.
unsafe impl<T: Send, const N: usize> Sync for Ring<T, N> {}

impl<T: Copy, const N: usize> Default for Ring<T, N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Copy, const N: usize> Ring<T, N> {
    const MASK: u8 = {
        assert!(N.is_power_of_two() && N >= 2 && N <= 128, "N: a power of two from 2 to 128");
        (N - 1) as u8
    };

    pub const fn new() -> Self {
        Self { slots: [const { UnsafeCell::new(MaybeUninit::uninit()) }; N], head: Index::new(), tail: Index::new() }
    }

    /// The two ends; the borrow keeps the ring from being split twice.
    pub fn split(&mut self) -> (Producer<'_, T, N>, Consumer<'_, T, N>) {
        let ring: &Self = self;
        (Producer { ring }, Consumer { ring })
    }

    #[inline(always)]
    fn slot(&self, index: u8) -> *mut MaybeUninit<T> {
        let index = index & Self::MASK;
        if N * size_of::<T>() <= 256 {
            // The byte offset fits a byte: one 8-bit multiply on the AVR
            // instead of a 16-bit one (the step interrupt's segment change
            // spent ~14 cycles on it).
            let offset = index.wrapping_mul(size_of::<T>() as u8);
            // SAFETY: index < N, so the offset lies inside `slots`, at the
            // start of slot `index` (the slots are contiguous, no padding
            // between array elements).
            UnsafeCell::raw_get(unsafe { self.slots.as_ptr().cast::<u8>().add(usize::from(offset)) }.cast())
        } else {
            self.slots[usize::from(index)].get()
        }
    }

    #[inline(always)]
    fn head(&self) -> u8 {
        self.head.load()
    }

    #[inline(always)]
    fn tail(&self) -> u8 {
        self.tail.load()
    }
}

/// The main loop's end.
pub struct Producer<'a, T, const N: usize> {
    ring: &'a Ring<T, N>,
}

impl<T: Copy, const N: usize> Producer<'_, T, N> {
    /// Room for one more item.
    pub fn ready(&self) -> bool {
        self.ring.tail().wrapping_sub(self.ring.head()) & Ring::<T, N>::MASK != Ring::<T, N>::MASK
    }

    /// Queue `item`, or hand it back when the ring is full.
    pub fn enqueue(&mut self, item: T) -> Result<(), T> {
        if !self.ready() {
            return Err(item);
        }
        let tail = self.ring.tail();
        // SAFETY: the slot at `tail` is outside head..tail: the consumer
        // does not touch it until the store below publishes it.
        unsafe { write_volatile(self.ring.slot(tail), MaybeUninit::new(item)) };
        self.ring.tail.store(tail.wrapping_add(1) & Ring::<T, N>::MASK);
        Ok(())
    }

    /// Items the ring holds when full.
    pub const fn capacity(&self) -> usize {
        N - 1
    }

    /// Items waiting for the consumer.
    pub fn len(&self) -> usize {
        usize::from(self.ring.tail().wrapping_sub(self.ring.head()) & Ring::<T, N>::MASK)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The interrupt's end.
pub struct Consumer<'a, T, const N: usize> {
    ring: &'a Ring<T, N>,
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

    /// The item after the oldest, read in place (the step generator keeps
    /// its running block at the front and looks at the next one).
    #[inline(always)]
    pub fn second(&self) -> Option<&T> {
        let head = self.ring.head();
        let tail = self.ring.tail();
        let next = head.wrapping_add(1) & Ring::<T, N>::MASK;
        if head == tail || next == tail {
            return None;
        }
        // SAFETY: next lies in head..tail: published, and not reused before
        // `head` moves past it.
        Some(unsafe { (*self.ring.slot(next)).assume_init_ref() })
    }

    /// Free the oldest item's slot (after [`Self::front`] returned it).
    #[inline(always)]
    pub fn release(&mut self) {
        let head = self.ring.head();
        if head != self.ring.tail() {
            self.ring.head.store(head.wrapping_add(1) & Ring::<T, N>::MASK);
        }
    }

    /// Let `take` look at the oldest item in place; if it returns true,
    /// free the slot. `false` if the ring is empty or `take` declined. One
    /// read of the indices (`front` then `release` read them twice).
    #[inline(always)]
    pub fn take_front_if(&mut self, take: impl FnOnce(&T) -> bool) -> bool {
        let head = self.ring.head();
        if head == self.ring.tail() {
            return false;
        }
        // SAFETY: as in `front`: the slot is published and stays ours until
        // `head` moves past it, below.
        if !take(unsafe { (*self.ring.slot(head)).assume_init_ref() }) {
            return false;
        }
        self.ring.head.store(head.wrapping_add(1) & Ring::<T, N>::MASK);
        true
    }

    /// Take the oldest item.
    pub fn dequeue(&mut self) -> Option<T> {
        let head = self.ring.head();
        if head == self.ring.tail() {
            return None;
        }
        // SAFETY: as in `front`: head != tail, so the slot holds a published
        // item, copied out straight into the result before `head` moves
        // past it (only the consumer moves `head`, so `release`'s second
        // check would be redundant).
        let item = Some(unsafe { *(*self.ring.slot(head)).assume_init_ref() });
        self.ring.head.store(head.wrapping_add(1) & Ring::<T, N>::MASK);
        item
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ring_of_four_slots_holds_three_items_in_order() {
        let mut ring = Ring::<u16, 4>::new();
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
        let mut ring = Ring::<u32, 16>::new();
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
    fn take_front_if_frees_only_what_it_takes() {
        let mut ring = Ring::<u8, 4>::new();
        let (mut producer, mut consumer) = ring.split();
        assert!(!consumer.take_front_if(|_| true));
        assert_eq!(producer.enqueue(7), Ok(()));
        assert_eq!(producer.enqueue(8), Ok(()));
        let mut seen = 0;
        assert!(!consumer.take_front_if(|&v| {
            seen = v;
            false
        }));
        assert_eq!(seen, 7);
        assert!(consumer.take_front_if(|&v| v == 7));
        assert_eq!(consumer.dequeue(), Some(8));
        assert_eq!(consumer.dequeue(), None);
    }

    #[test]
    fn release_on_an_empty_ring_does_nothing() {
        let mut ring = Ring::<u8, 2>::new();
        let (mut producer, mut consumer) = ring.split();
        consumer.release();
        assert_eq!(producer.enqueue(7), Ok(()));
        assert_eq!(producer.enqueue(8), Err(8));
        assert_eq!(consumer.dequeue(), Some(7));
    }
}
