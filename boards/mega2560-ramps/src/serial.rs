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

/// Baud rate: 115200, our default (Marlin's example configuration uses
/// 250000), or 250000 with `--features baud-250000`.
#[cfg(not(feature = "baud-250000"))]
pub const BAUD: u32 = 115_200;
#[cfg(feature = "baud-250000")]
pub const BAUD: u32 = 250_000;

const CPU_HZ: u32 = 16_000_000;
/// Double-speed mode divisor (U2X0 = 1): UBRR = f/(8·baud) − 1, rounded.
/// 115200 → 16 (117647 baud, +2.1 %, as on every Arduino); 250000 → 7 (exact).
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
    // SAFETY: U2X0 (bit 1) only; the other bits are flags or zero.
    usart.ucsr0a.write(|w| unsafe { w.bits(1 << 1) });
    // 8 data bits, no parity, one stop bit: UCSZ01 | UCSZ00.
    // SAFETY: a valid frame format.
    usart.ucsr0c.write(|w| unsafe { w.bits(0b0000_0110) });
    usart.ucsr0b.write(|w| w.rxen0().set_bit().txen0().set_bit().rxcie0().set_bit());
}

/// Bytes taken from the UART and not yet through [`receive`]: the
/// handler's first, interrupts-off part fills it; the run of the handler
/// that is draining it (`DRAINING`) empties it with interrupts on.
const RAW_SLOTS: usize = 16;
static mut RAW: [(u8, bool); RAW_SLOTS] = [(0, false); RAW_SLOTS];
static mut RAW_HEAD: u8 = 0;
static mut RAW_LEN: u8 = 0;
static mut DRAINING: bool = false;

/// USART0 receive complete, in two parts.
///
/// 1. Interrupts off, a few dozen cycles: every byte the UART holds goes
///    into `RAW` with its overrun flag.
/// 2. Unless an outer run of this handler is already at it, the bytes go
///    through the ring and the emergency scanner (~250 cycles each) with
///    interrupts on: a step is held up only by part 1.
///
/// The receive interrupt stays enabled, so a byte that arrives while part 2
/// runs, or while another handler runs on top of it (the step interrupt's
/// new block: up to ≈ 1 600 cycles), is taken at once by a nested part 1.
/// At 250 000 baud a byte comes every 640 cycles and the UART holds two:
/// when this handler switched its own source off for part 2, a step
/// interrupt on top of it lost bytes. Only when `RAW` is full (a burst
/// faster than the wire, as QEMU delivers them) does part 1 switch the
/// source off and leave the bytes in the UART; part 2 switches it back on
/// as soon as it has taken one.
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
            let overrun = usart.ucsr0a.read().dor0().bit_is_set();
            let byte = usart.udr0.read().bits();
            let slot = (RAW_HEAD as usize + RAW_LEN as usize) % RAW_SLOTS;
            (*addr_of_mut!(RAW))[slot] = (byte, overrun);
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
    // With the encoder loops the tick runs ≈ 0.5 ms with interrupts on: it
    // must not sit on top of part 2 (found on simavr). Its mask is put
    // back as it was (the main loop masks it too).
    #[cfg(feature = "encoders")]
    let tick = crate::clock::hold_tick();
    loop {
        // SAFETY: interrupts are off here (on entry, and after each byte).
        let next = unsafe {
            if RAW_LEN == 0 {
                None
            } else {
                let taken = (*addr_of_mut!(RAW))[RAW_HEAD as usize % RAW_SLOTS];
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
