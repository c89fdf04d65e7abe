//! The main loop's serial duties, shared by every board and the simulator:
//! act on emergencies from the receive interrupt, turn received bytes into
//! lines (only while the command queue has room), and run the executor.
//!
//! A board implements [`SerialLink`] over its receive ring and calls
//! [`HostLink::service`] once per pass of its main loop.

use crate::emergency::{Emergency, Pending};
use crate::line::LineAssembler;
use crate::machine::Machine;
use crate::storage::NonVolatile;
use ufmt::uWrite;

/// The receive side of a board's serial port, as the main loop sees it.
pub trait SerialLink {
    /// The next received byte, if any.
    fn pop(&mut self) -> Option<u8>;
    /// Bytes lost since the last call (ring full, UART overrun).
    fn take_dropped(&mut self) -> u8;
    /// Emergencies recognised by the receive interrupt since the last call.
    fn take_emergencies(&mut self) -> Pending;
}

/// The executor and the line being received.
pub struct HostLink<'q> {
    pub machine: Machine<'q>,
    assembler: LineAssembler,
    /// When the last byte was taken from the receive ring.
    last_byte_ms: u32,
}

impl<'q> HostLink<'q> {
    pub fn new(machine: Machine<'q>) -> Self {
        Self { machine, assembler: LineAssembler::new(), last_byte_ms: 0 }
    }

    /// The link and its machine built directly in `slot` (a `static` on the
    /// boards), without kilobyte-sized temporaries on the stack; see
    /// [`Machine::init_in`].
    pub fn init_in<'s>(
        slot: &'s mut core::mem::MaybeUninit<Self>,
        config: crate::motion::MotionConfig,
        feeder: crate::motion::StepFeeder<'q>,
    ) -> &'s mut Self {
        let p = slot.as_mut_ptr();
        // SAFETY: both fields of the valid slot are written once, `machine`
        // in place by `Machine::init_in`; the slot is then initialised.
        unsafe {
            Machine::init_in(&mut *core::ptr::addr_of_mut!((*p).machine).cast(), config, feeder);
            core::ptr::addr_of_mut!((*p).assembler).write(LineAssembler::new());
            core::ptr::addr_of_mut!((*p).last_byte_ms).write(0);
            slot.assume_init_mut()
        }
    }

    /// One pass: emergencies first, then input, then execution.
    #[inline(never)]
    pub fn service<W: uWrite + ?Sized>(
        &mut self,
        link: &mut impl SerialLink,
        storage: &mut dyn NonVolatile,
        now_ms: u32,
        out: &mut W,
    ) -> Result<(), W::Error> {
        let emergencies = link.take_emergencies();
        if emergencies.contains(Emergency::Kill) {
            self.machine.kill(out)?;
        }
        if emergencies.contains(Emergency::CancelWait) {
            self.machine.cancel_wait();
        }
        if emergencies.contains(Emergency::QuickStop) {
            self.machine.quick_stop();
        }
        // Lost bytes are marked in the byte stream itself (`rx::LOST_BYTES`),
        // so the line that lost them is refused when it is complete; the
        // count only feeds statistics.
        let _ = link.take_dropped();
        // Take bytes only while the queue has room for a line; the rest
        // waits in the receive ring (hosts wait for `ok` anyway). A refused
        // line ends the pass: its reply is longer than the line, so a host
        // that sends on every reply could otherwise keep this loop busy for
        // ever (accepted lines are bounded by the queue), and the watchdog,
        // fed once a pass, reset the board (issue 22: a noisy line ended in
        // a reset).
        while self.machine.can_accept_line() {
            let Some(byte) = link.pop() else {
                // A numbered line whose end was lost to noise: refuse it
                // (and ask for it again) rather than wait for ever, as
                // both the host and this side would.
                if self.assembler.holds_protocol_line() && now_ms.wrapping_sub(self.last_byte_ms) >= crate::line::LINE_END_TIMEOUT_MS {
                    let line = self.assembler.abandon();
                    let assembler = &mut self.assembler;
                    self.machine.receive_line_then(line, out, || discard_in_flight(assembler, link))?;
                }
                break;
            };
            self.last_byte_ms = now_ms;
            if let Some(line) = self.assembler.push(byte) {
                let queued = self.machine.queued_lines();
                // The line borrows the assembler's buffer: the discard
                // works on the ring and a flag (`discard_to_line_end`
                // after the line is handed back).
                let mut cut = false;
                self.machine.receive_line_then(line, out, || cut = discard_ring(link))?;
                if cut {
                    self.assembler.discard_to_line_end();
                }
                if self.machine.queued_lines() == queued {
                    break;
                }
            }
        }
        self.machine.poll(now_ms, storage, out)
    }

}

/// After a resend request, as Marlin: throw away what the receive ring
/// holds. The host sent those lines before it saw the request; each would
/// be refused as out of order, each refusal would carry an `ok` and a
/// `Resend:`, and a host that sends a line on each (printcore does) would
/// keep the errors going. Returns whether the discard cut a line in two
/// (its rest is then skipped up to its end). Bounded by the ring's size.
fn discard_ring(link: &mut impl SerialLink) -> bool {
    let mut last = b'\n';
    for _ in 0..crate::rx::RX_RING_SLOTS {
        let Some(byte) = link.pop() else { break };
        last = byte;
    }
    last != b'\n' && last != b'\r'
}

/// [`discard_ring`], and the assembler skips the rest of a cut line.
fn discard_in_flight(assembler: &mut LineAssembler, link: &mut impl SerialLink) {
    if discard_ring(link) {
        assembler.discard_to_line_end();
    }
}
