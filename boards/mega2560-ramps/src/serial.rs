//! USART0 (the USB bridge): interrupt-driven receive, polled transmit.
//!
//! The receive interrupt does one thing: move the byte (and the UART's own
//! overrun flag) into the core's receive ring, through a small buffer of
//! its own so that it never leaves the UART's two-byte FIFO waiting
//! (see `USART0_RX`). Transmit waits for the data
//! register; the receive interrupt keeps running meanwhile, so waiting to
//! send never loses input.

use avr_device::atmega2560::{Peripherals, USART0};
use avr_device::interrupt::{CriticalSection, Mutex};
use core::cell::Cell;
use core::ptr::addr_of_mut;
use firmware::emergency::{Emergency, Pending};
use firmware::host_link::SerialLink;
use firmware::rx::{RxConsumer, RxProducer};

/// Baud rate: the machine file's `machine.baud` (115200 in the shipped
/// files but one, 250000 for hosts that want it).
pub const BAUD: u32 = firmware::machine_file::BAUD;

const CPU_HZ: u32 = 16_000_000;

/// Double-speed mode divisor (U2X0 = 1): UBRR = f/(8·baud) − 1, rounded.
/// 115200 → 16 (117647 baud, +2.1 %, as on every Arduino); 250000 → 7 (exact).
/// The machine file's checker refuses rates this makes more than 2.5 % off.
const UBRR: u16 = ((CPU_HZ + 4 * BAUD) / (8 * BAUD) - 1) as u16;

/// The interrupt's end of the receive ring, installed once by [`init`]
/// (before interrupts are on). Used by the receive interrupt, and by the
/// main loop only inside critical sections ([`with_producer`]). A plain
/// static, not a `RefCell`: the borrow flag cost a call inside every lock.
static mut RX_PRODUCER: Option<RxProducer<'static>> = None;

/// The producer, for the main loop (inside a critical section) or for the
/// receive interrupt's draining run (the only one, see `USART0_RX`).
fn with_producer<R>(_cs: CriticalSection<'_>, f: impl FnOnce(&mut RxProducer<'static>) -> R) -> Option<R> {
    // SAFETY: the token (a critical section, or the receive interrupt's
    // draining run, which nothing else that touches the producer can
    // interrupt) gives exclusive access.
    unsafe { (*addr_of_mut!(RX_PRODUCER)).as_mut().map(f) }
}

/// Non-zero: the receive ring's producer has lost bytes or owes markers
/// (`RxProducer::has_trouble`), set by the receive interrupt; the main
/// loop's `take_dropped` takes its lock only then.
static mut RX_TROUBLE: u8 = 0;

/// Emergencies seen by the receive interrupt, for the main loop to act on.
static EMERGENCIES: Mutex<Cell<Pending>> = Mutex::new(Cell::new(Pending::NONE));

/// The main loop's view of USART0's receive side.
pub struct Rx {
    pub consumer: RxConsumer<'static>,
}

impl SerialLink for Rx {
    fn pop(&mut self) -> Option<u8> {
        self.consumer.pop()
    }

    fn take_dropped(&mut self) -> u8 {
        // The lock only when the receive side reported trouble: the main
        // loop asks on every pass, and every interrupt lock there may make
        // a step late at high rates (a byte is read atomically on the AVR;
        // the flag is set by the receive interrupt and cleared here under
        // the lock, so a report between the read and the lock waits one
        // pass).
        // SAFETY: a one-byte volatile read of a flag only the receive
        // interrupt sets.
        if unsafe { core::ptr::read_volatile(addr_of_mut!(RX_TROUBLE)) } == 0 {
            return 0;
        }
        avr_device::interrupt::free(|cs| {
            with_producer(cs, |p| {
                let dropped = p.take_dropped();
                // SAFETY: interrupts are off.
                unsafe { *addr_of_mut!(RX_TROUBLE) = p.has_trouble() as u8 };
                dropped
            })
        })
        .unwrap_or(0)
    }

    fn take_emergencies(&mut self) -> Pending {
        avr_device::interrupt::free(|cs| EMERGENCIES.borrow(cs).replace(Pending::NONE))
    }
}

/// Set up 8N1 at [`BAUD`] with the receive interrupt on.
pub fn init(dp: &Peripherals, producer: RxProducer<'static>) {
    // SAFETY: interrupts are not enabled yet: nothing else uses it.
    unsafe { *addr_of_mut!(RX_PRODUCER) = Some(producer) };
    let usart = &dp.USART0;
    usart.ubrr0.write(|w| w.bits(UBRR));
    // Double speed; the other bits are flags or zero.
    usart.ucsr0a.write(|w| w.u2x0().set_bit());
    // 8N1, asynchronous.
    usart.ucsr0c.write(|w| w.umsel0().usart_async().upm0().disabled().usbs0().stop1().ucsz0().chr8());
    usart.ucsr0b.write(|w| w.rxen0().set_bit().txen0().set_bit().rxcie0().set_bit());
}

/// Bytes taken from the UART and not yet through [`receive`]: the
/// handler's first, interrupts-off part fills it; the run of the handler
/// that is draining it (`DRAINING`) empties it with interrupts on.
const RAW_SLOTS: usize = 16;
static mut RAW: RawSlots = RawSlots([RawByte { byte: 0, status: 0 }; RAW_SLOTS]);

/// `RAW`'s 32 bytes aligned to 32, so that part 1 finds a slot's address
/// with an 8-bit addition (no carry into the high byte).
#[repr(C, align(32))]
struct RawSlots([RawByte; RAW_SLOTS]);

/// One received byte and UCSR0A as read just before it, whose DOR0 bit
/// (3) is the UART's overrun flag for it (C layout: part 1 writes it from
/// assembly; the register whole, so that part 1 does not spend
/// interrupts-off cycles on extracting the bit).
#[repr(C)]
#[derive(Clone, Copy)]
struct RawByte {
    byte: u8,
    status: u8,
}

/// UCSR0A's data-overrun bit.
const DOR0: u8 = 1 << 3;
static mut RAW_HEAD: u8 = 0;
static mut RAW_LEN: u8 = 0;
static mut DRAINING: bool = false;

// USART0 receive complete, in two parts.
//
// 1. Interrupts off, ≈ 43 cycles from the vector to its `sei` (≈ 70
//    while the test-and-set of `DRAINING` and part 2's entry came before
//    it): the byte goes into `RAW` with its
//    overrun flag (a second byte waiting is left to a nested run).
//    Hand-written (`__vector_25` below): the compiler's
//    handler saved 15 registers first and took ≈ 110–150 cycles to its
//    `sei`, and that much was a step's lateness when a byte arrived just
//    before a step (11 % of the interval at 13 000 steps/s: the even-step
//    rate's limit once block changes became cheap).
// 2. Unless an outer run of this handler is already at it, the bytes go
//    through the ring and the emergency scanner (~250 cycles each) with
//    interrupts on ([`drain`]): a step is held up only by part 1.
//
// Nesting and masking with the other handlers: see `interrupts.rs`. The
// receive interrupt stays enabled (a nested part 1 takes each byte at
// once) because at 250 000 baud a byte comes every 640 cycles and the
// UART holds two: when this handler switched its own source off for part
// 2, a step interrupt on top of it lost bytes. Only when `RAW` is full (a
// burst faster than the wire, as QEMU delivers them) does part 1 switch
// the source off and leave the bytes in the UART; part 2 switches it back
// on as soon as it has taken one.
//
// Registers: part 1 uses r24, r25, r30, r31, saved
// here. Part 2 is Rust: before calling it, r0 and r1 are saved and r1
// cleared (the interrupted code may hold anything in them), and
// `ferrostep_rx_drain` saves the other call-clobbered registers. UCSR0A
// 0xC0 (RXC0 bit 7, DOR0 bit 3), UCSR0B 0xC1 (RXCIE0 bit 7), UDR0 0xC6.
#[cfg(not(feature = "encoders"))]
core::arch::global_asm!(
    ".section .text.__vector_25,\"ax\",@progbits",
    ".global __vector_25",
    "__vector_25:",
    "push r24",
    "in r24, 0x3f",
    "push r24",
    "push r25",
    "push r30",
    "push r31",
    // Part 1: one byte, interrupts off.
    "lds r24, {len}",
    "cpi r24, {slots}",
    "breq 3f",
    "lds r25, {head}",
    "add r25, r24",
    "andi r25, {slots} - 1",
    "lsl r25",
    // (RAW is aligned to its 32 bytes: no carry into r31.)
    "ldi r30, lo8({raw})",
    "ldi r31, hi8({raw})",
    "add r30, r25",
    // The overrun flag belongs to the byte at the head: read the status
    // first, and keep it whole.
    "lds r25, 0xc0",
    "std Z+1, r25",
    "lds r25, 0xc6",
    "st Z, r25",
    "inc r24",
    "sts {len}, r24",
    // Interrupts on at once: a step due meanwhile goes first, and another
    // byte waiting in the UART (it came while interrupts were off) is
    // taken by a nested run of this handler, which also drains if no run
    // is at it yet. The test-and-set of DRAINING below may be interrupted:
    // a nested run that finds it clear drains everything and clears it
    // again before this run goes on, so one run drains at a time and the
    // bytes keep their order.
    "sei",
    "rjmp 4f",
    // RAW is full: leave the bytes in the UART, the source off.
    "3:",
    "lds r25, 0xc1",
    "andi r25, 0x7f",
    "sts 0xc1, r25",
    // Part 2 unless an outer run is at it.
    "4:",
    "lds r25, {draining}",
    "tst r25",
    "brne 5f",
    "ldi r25, 1",
    "sts {draining}, r25",
    "push r0",
    "push r1",
    "clr r1",
    "call ferrostep_rx_drain",
    "pop r1",
    "pop r0",
    "5:",
    "pop r31",
    "pop r30",
    "pop r25",
    "pop r24",
    "out 0x3f, r24",
    "pop r24",
    "reti",
    len = sym RAW_LEN,
    head = sym RAW_HEAD,
    raw = sym RAW,
    draining = sym DRAINING,
    slots = const RAW_SLOTS,
);

/// The compiler's handler (encoder builds: part 2 must hold the encoder
/// tick off before interrupts go on, see [`drain`]).
#[cfg(feature = "encoders")]
#[avr_device::interrupt(atmega2560)]
fn USART0_RX() {
    // SAFETY: USART0's status and data registers are read only here; the
    // main loop only writes the transmit side. RAW and its indices are
    // written with interrupts off only.
    let usart = unsafe { &*USART0::ptr() };
    unsafe {
        loop {
            if RAW_LEN as usize == RAW_SLOTS {
                usart.ucsr0b.modify(|_, w| w.rxcie0().clear_bit());
                break;
            }
            // The overrun flag belongs to the byte at the head: read it first.
            let status = usart.ucsr0a.read().bits();
            let byte = usart.udr0.read().bits();
            let slot = (RAW_HEAD as usize + RAW_LEN as usize) % RAW_SLOTS;
            (*addr_of_mut!(RAW)).0[slot] = RawByte { byte, status };
            RAW_LEN += 1;
            if usart.ucsr0a.read().rxc0().bit_is_clear() {
                break;
            }
        }
        if DRAINING {
            return;
        }
        DRAINING = true;
    }
    // SAFETY: the routine preserves every register (it saves the
    // call-clobbered ones itself) and returns with interrupts off;
    // DRAINING is set, so a nested run of this handler only does part 1.
    unsafe { core::arch::asm!("call ferrostep_rx_drain") };
}

// Part 2's way in: the call-clobbered registers of avr-gcc's convention
// (r18–r27, r30, r31) saved around an ordinary call to `drain`. Without
// the encoder loops interrupts go on first and stay on through the
// restores (`drain` returns with them on), so neither delays a step; with
// them `drain` returns with interrupts off.
#[cfg(not(feature = "encoders"))]
core::arch::global_asm!(
    ".section .text.ferrostep_rx_drain,\"ax\",@progbits",
    "ferrostep_rx_drain:",
    "sei",
    "push r18", "push r19", "push r20", "push r21", "push r22", "push r23",
    "push r24", "push r25", "push r26", "push r27", "push r30", "push r31",
    "call {f}",
    "pop r31", "pop r30", "pop r27", "pop r26", "pop r25", "pop r24",
    "pop r23", "pop r22", "pop r21", "pop r20", "pop r19", "pop r18",
    "ret",
    f = sym drain,
);
#[cfg(feature = "encoders")]
core::arch::global_asm!(
    ".section .text.ferrostep_rx_drain,\"ax\",@progbits",
    "ferrostep_rx_drain:",
    "push r18", "push r19", "push r20", "push r21", "push r22", "push r23",
    "push r24", "push r25", "push r26", "push r27", "push r30", "push r31",
    "call {f}",
    "pop r31", "pop r30", "pop r27", "pop r26", "pop r25", "pop r24",
    "pop r23", "pop r22", "pop r21", "pop r20", "pop r19", "pop r18",
    "ret",
    f = sym drain,
);

/// The receive handler's part 2: the bytes of `RAW` through [`receive`]
/// with interrupts on; returns with `DRAINING` clear, and interrupts on
/// (off in encoder builds).
extern "C" fn drain() {
    // Encoder builds: the tick is masked for part 2 (see `interrupts.rs`;
    // its long run on top of part 2 was found on simavr). Interrupts are
    // still off here in those builds.
    #[cfg(feature = "encoders")]
    let tick = crate::clock::hold_tick();
    avr_device::interrupt::disable();
    // SAFETY: USART0's control register, as in the handler.
    let usart = unsafe { &*USART0::ptr() };
    loop {
        // SAFETY: interrupts are off here (on entry, and after each byte).
        let next = unsafe {
            if RAW_LEN == 0 {
                None
            } else {
                let RawByte { byte, status } = (*addr_of_mut!(RAW)).0[RAW_HEAD as usize % RAW_SLOTS];
                let taken = (byte, status & DOR0 != 0);
                RAW_HEAD = ((RAW_HEAD as usize + 1) % RAW_SLOTS) as u8;
                RAW_LEN -= 1;
                // Room again: the source back on (part 1 may have switched
                // it off on a full buffer).
                usart.ucsr0b.modify(|_, w| w.rxcie0().set_bit());
                Some(taken)
            }
        };
        let Some((byte, overrun)) = next else { break };
        // SAFETY: only this run of the handler drains; a nested run only
        // adds to RAW (with interrupts off) and returns.
        unsafe { avr_device::interrupt::enable() };
        receive(byte, overrun);
        avr_device::interrupt::disable();
    }
    #[cfg(feature = "encoders")]
    crate::clock::release_tick(tick);
    // SAFETY: interrupts are off.
    unsafe { DRAINING = false };
    // Without the encoder loops, interrupts go back on now, not at the
    // `reti`: the register restores of part 2's way out and of part 1
    // (≈ 50 cycles) held a step up by that much when it fell due meanwhile
    // (8–12 % of the interval from 20 000 steps/s on the bench). A byte
    // arriving now starts a run that finds DRAINING clear and drains it
    // itself.
    #[cfg(not(feature = "encoders"))]
    // SAFETY: RAW is empty and DRAINING clear: nothing of this run is left
    // that a nested run could disturb.
    unsafe {
        avr_device::interrupt::enable()
    };
}

#[inline(never)]
fn receive(byte: u8, overrun: bool) {
    // SAFETY: see the handler: only its draining run calls this, the main
    // loop is interrupted, and no other interrupt uses the producer.
    let cs = unsafe { CriticalSection::new() };
    let Some((emergency, trouble)) = with_producer(cs, |p| {
        let emergency = p.push(byte, overrun);
        (emergency, p.has_trouble())
    }) else {
        return;
    };
    if trouble {
        // SAFETY: as above (only this run of the handler writes it with
        // interrupts on; the main loop clears it with interrupts off).
        unsafe { *addr_of_mut!(RX_TROUBLE) = 1 };
    }
    let Some(emergency) = emergency else { return };
    avr_device::interrupt::free(|cs| {
        if emergency == Emergency::Kill {
            // M112 acts here and now, whatever the main loop is doing; with
            // interrupts off, so the step interrupt cannot step in between.
            // SAFETY: single read-modify-writes of port registers.
            let dp = unsafe { avr_device::atmega2560::Peripherals::steal() };
            crate::stepping::stop_timer(&dp);
            #[cfg(feature = "machine-extrusion-line")]
            crate::line::stop(&dp);
            #[cfg(feature = "machine-powder-bed")]
            crate::bed::stop(&dp);
            crate::pins::all_outputs_safe(&dp);
        }
        let pending = EMERGENCIES.borrow(cs);
        pending.set(pending.get().with(emergency));
    });
}

/// The transmit side, as a `ufmt` writer.
pub struct Tx;

impl Tx {
    fn write_byte(byte: u8) {
        // SAFETY: only the main loop transmits; UDR0 and UDRE0 are its own.
        let usart = unsafe { &*USART0::ptr() };
        while usart.ucsr0a.read().udre0().bit_is_clear() {}
        usart.udr0.write(|w| w.bits(byte));
    }
}

impl ufmt::uWrite for Tx {
    type Error = core::convert::Infallible;

    fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
        s.bytes().for_each(Self::write_byte);
        Ok(())
    }

    /// The character's UTF-8 bytes, as the default (`encode_utf8` and
    /// `write_str`) sends them, straight to the UART: the default's
    /// buffer, its checks and panic path cost the AVR more code.
    fn write_char(&mut self, c: char) -> Result<(), Self::Error> {
        firmware::reply::utf8_bytes(c, Self::write_byte);
        Ok(())
    }
}
