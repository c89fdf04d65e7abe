//! USART0 (the USB bridge): interrupt-driven receive, polled transmit.
//!
//! The receive interrupt does one thing: move the byte (and the UART's own
//! overrun flag) into the core's receive ring. Transmit waits for the data
//! register; the receive interrupt keeps running meanwhile, so waiting to
//! send never loses input.

use avr_device::atmega2560::{Peripherals, USART0};
use avr_device::interrupt::{CriticalSection, Mutex};
use core::cell::Cell;
use core::ptr::addr_of_mut;
use firmware::emergency::{Emergency, Pending};
use firmware::host_link::SerialLink;
use firmware::rx::{RxConsumer, RxProducer};

/// Baud rate: Marlin's default 115200, or 250000 with `--features baud-250000`.
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
/// receive interrupt (its RX source is off while it runs, see below).
fn with_producer<R>(_cs: CriticalSection<'_>, f: impl FnOnce(&mut RxProducer<'static>) -> R) -> Option<R> {
    // SAFETY: the token (a critical section, or the receive interrupt with
    // its own source disabled and nothing else touching the producer)
    // gives exclusive access.
    unsafe { (*addr_of_mut!(RX_PRODUCER)).as_mut().map(f) }
}

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
        avr_device::interrupt::free(|cs| with_producer(cs, |p| p.take_dropped())).unwrap_or(0)
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

/// USART0 receive complete. The handler switches its own source off, then
/// for each byte the UART holds takes it and its overrun flag and lets
/// every other interrupt in while it runs the ring and the emergency
/// scanner (~250 cycles): a step is held up only by the entry and these
/// few register reads, not by the whole handler. The source comes back on
/// (with interrupts off) just before returning, so a byte that arrived
/// after the last check is handled next.
#[avr_device::interrupt(atmega2560)]
fn USART0_RX() {
    // SAFETY: USART0's status and data registers are read only here; the
    // main loop only writes the transmit side; UCSR0B's receive-interrupt
    // bit is written only here, with interrupts off.
    let usart = unsafe { &*USART0::ptr() };
    usart.ucsr0b.modify(|_, w| w.rxcie0().clear_bit());
    // With the encoder loops the tick runs ≈ 0.5 ms with interrupts on: it
    // must not sit on top of this handler while its source is off (two
    // more bytes and the UART overruns; found on simavr). Its mask is put
    // back as it was (the main loop masks it too).
    #[cfg(feature = "encoders")]
    let tick = crate::clock::hold_tick();
    // Every byte the UART holds, in one entry: at 250 000 baud a byte comes
    // every 640 cycles, and bytes that piled up while other handlers ran
    // on top of this one are taken without leaving and re-entering (the
    // UART holds two; a third one arriving meanwhile is lost).
    loop {
        // The overrun flag belongs to the byte at the head: read it first.
        let overrun = usart.ucsr0a.read().dor0().bit_is_set();
        let byte = usart.udr0.read().bits();
        // SAFETY: only this handler's own source is off; the producer is
        // touched by nothing that can interrupt it.
        unsafe { avr_device::interrupt::enable() };
        receive(byte, overrun);
        avr_device::interrupt::disable();
        if usart.ucsr0a.read().rxc0().bit_is_clear() {
            break;
        }
    }
    #[cfg(feature = "encoders")]
    crate::clock::release_tick(tick);
    usart.ucsr0b.modify(|_, w| w.rxcie0().set_bit());
}

#[inline(never)]
fn receive(byte: u8, overrun: bool) {
    // SAFETY: see the handler: its source is off, the main loop is
    // interrupted, and no other interrupt uses the producer.
    let cs = unsafe { CriticalSection::new() };
    let Some(Some(emergency)) = with_producer(cs, |p| p.push(byte, overrun)) else { return };
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
}
