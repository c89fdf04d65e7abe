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
}

impl<'q> HostLink<'q> {
    pub fn new(machine: Machine<'q>) -> Self {
        Self { machine, assembler: LineAssembler::new() }
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
        // waits in the receive ring (hosts wait for `ok` anyway).
        while self.machine.can_accept_line() {
            let Some(byte) = link.pop() else { break };
            if let Some(line) = self.assembler.push(byte) {
                self.machine.receive_line(line, out)?;
            }
        }
        self.machine.poll(now_ms, storage, out)
    }
}
