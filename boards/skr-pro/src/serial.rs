//! USART1 (PA9/PA10, the TFT header): interrupt-driven receive, polled
//! transmit.
//!
//! QEMU's netduinoplus2 wires its first serial backend (`-serial stdio`)
//! to USART1 as well, so the board and the emulator need no build
//! variant. (The SKR Pro's USB socket is the STM32's own USB device, which
//! needs a USB CDC stack: not implemented yet; see the README.)
//!
//! The receive interrupt does one thing: move the byte (and the UART's own
//! overrun flag) into the core's receive ring. Transmit waits for the data
//! register; the receive interrupt keeps running meanwhile, so waiting to
//! send never loses input.

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicU8, Ordering};
use firmware::emergency::{Emergency, Pending};
use firmware::host_link::SerialLink;
use firmware::rx::{RxConsumer, RxProducer};
use stm32f4::stm32f407 as pac;

use crate::clock::Clocks;
use crate::pins;

/// Baud rate: 115200, our default (Marlin's example configuration uses
/// 250000), or 250000 with `--features baud-250000`.
#[cfg(not(feature = "baud-250000"))]
pub const BAUD: u32 = 115_200;
#[cfg(feature = "baud-250000")]
pub const BAUD: u32 = 250_000;

// USART_SR bits.
const RXNE: u16 = 1 << 5;
const ORE: u16 = 1 << 3;
const TXE: u16 = 1 << 7;
// USART_CR1 bits.
const UE: u16 = 1 << 13;
const TE: u16 = 1 << 3;
const RE: u16 = 1 << 2;
const RXNEIE: u16 = 1 << 5;
/// RCC_APB2ENR: USART1EN.
const USART1EN: u32 = 1 << 4;

/// The interrupt's end of the receive ring. Written once by [`init`]
/// before the USART1 interrupt is enabled; afterwards only that interrupt
/// touches it, except [`Rx::take_dropped`], which masks the interrupt.
struct ProducerCell(UnsafeCell<Option<RxProducer<'static>>>);
// SAFETY: see the comment on the type: accesses never overlap.
unsafe impl Sync for ProducerCell {}
static PRODUCER: ProducerCell = ProducerCell(UnsafeCell::new(None));

/// Emergencies seen by the receive interrupt, for the main loop to act on.
static EMERGENCIES: AtomicU8 = AtomicU8::new(0);

/// The main loop's view of USART1's receive side.
pub struct Rx {
    pub consumer: RxConsumer<'static>,
}

impl SerialLink for Rx {
    fn pop(&mut self) -> Option<u8> {
        self.consumer.pop()
    }

    fn take_dropped(&mut self) -> u8 {
        cortex_m::interrupt::free(|_| {
            // SAFETY: interrupts are masked, so the receive interrupt is not
            // using the producer.
            unsafe { (*PRODUCER.0.get()).as_mut().map_or(0, |p| p.take_dropped()) }
        })
    }

    fn take_emergencies(&mut self) -> Pending {
        Pending(EMERGENCIES.swap(0, Ordering::Relaxed))
    }
}

/// 8N1 at [`BAUD`] with the receive interrupt on (the NVIC line is
/// unmasked by the caller once everything is ready).
pub fn init(rcc: &pac::RCC, usart: &pac::USART1, clocks: &Clocks, producer: RxProducer<'static>) {
    // SAFETY: no interrupt is enabled yet; this is the only writer.
    unsafe { *PRODUCER.0.get() = Some(producer) };
    // SAFETY: setting USART1's clock-enable bit only.
    rcc.apb2enr().modify(|r, w| unsafe { w.bits(r.bits() | USART1EN) });
    cortex_m::asm::dsb();
    pins::USART1_TX.make_alternate(pins::USART1_AF, false);
    pins::USART1_RX.make_alternate(pins::USART1_AF, true);
    // 16× oversampling: BRR = f / baud, rounded (84 MHz: 115200 → 729,
    // 115226 baud, +0.02 %; 250000 → 336, exact).
    let brr = (clocks.apb2_hz + BAUD / 2) / BAUD;
    // SAFETY: every 16-bit divisor is valid; CR1 bits are documented.
    usart.brr().write(|w| unsafe { w.bits(brr as u16) });
    usart.cr2().write(|w| unsafe { w.bits(0) });
    usart.cr3().write(|w| unsafe { w.bits(0) });
    usart.cr1().write(|w| unsafe { w.bits(UE | TE | RE | RXNEIE) });
}

/// The USART1 interrupt's body.
#[inline(always)]
pub fn on_interrupt() {
    // SAFETY: read-only access to USART1's status and data registers; the
    // main loop only ever writes DR on the transmit side.
    let usart = unsafe { &*pac::USART1::ptr() };
    let status = usart.sr().read().bits();
    if status & (RXNE | ORE) == 0 {
        return;
    }
    let overrun = status & ORE != 0;
    // Reading DR after SR clears RXNE and ORE.
    let byte = usart.dr().read().bits() as u8;
    // SAFETY: this interrupt is the producer's only user while it runs
    // (the main loop masks it around `take_dropped`).
    let Some(producer) = (unsafe { (*PRODUCER.0.get()).as_mut() }) else { return };
    let Some(emergency) = producer.push(byte, overrun) else { return };
    if emergency == Emergency::Kill {
        // M112 acts here and now, whatever the main loop is doing.
        pins::all_outputs_safe();
    }
    EMERGENCIES.fetch_or(Pending::NONE.with(emergency).0, Ordering::Relaxed);
}

/// The transmit side, as a `ufmt` writer.
pub struct Tx;

impl Tx {
    pub fn write_byte(byte: u8) {
        // SAFETY: only the main loop (or the panic handler, with interrupts
        // off) transmits; DR and TXE are its own.
        let usart = unsafe { &*pac::USART1::ptr() };
        while usart.sr().read().bits() & TXE == 0 {}
        // SAFETY: any byte may be sent.
        usart.dr().write(|w| unsafe { w.bits(u16::from(byte)) });
    }
}

impl ufmt::uWrite for Tx {
    type Error = core::convert::Infallible;

    fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
        s.bytes().for_each(Self::write_byte);
        Ok(())
    }
}
