//! Control-law benchmark for the Mega 2560: what one tick of the
//! closed-loop position law costs the ATmega2560 in each arithmetic of
//! `firmware::num` (Q16.16 fixed point and soft-float f32), measured, so
//! the choice of [`firmware::num::Native`] for this board rests on figures.
//!
//! Timer1 counts CPU cycles (clk/1). Each sample times one
//! `AxisController::tick` of the robust PID (γ 0.5, 1 kHz) on a 5 mm/s
//! ramp with a following error that wanders over ±0.05 mm:
//!
//! ```text
//! t0 = TCNT1; tick; t1 = TCNT1;  cost = (t1 − t0) − (the same with no tick)
//! ```
//!
//! Nothing else runs (no interrupts are enabled). Output on USART0 at
//! 115200 baud, one `key=value` per line, then `done`; `avr-bench` reads it
//! on simavr (`cargo benchmark`, keys `avr_loop_tick_cycles_*`). On a real
//! board the same lines appear in a serial terminal.
#![no_std]
#![no_main]
#![deny(unsafe_op_in_unsafe_fn)]

use avr_device::atmega2560::{Peripherals, TC1, USART0};
use core::hint::black_box;
use firmware::closed_loop::control::{AxisController, DriverStatus, FollowingErrorLimit, LoopGains, Reference};
use firmware::closed_loop::tuning::Strategy;
use firmware::num::{FixedPoint, Float, LoopArithmetic};
use ufmt::uwrite;

const CPU_HZ: u32 = 16_000_000;
const BAUD: u32 = 115_200;
/// Double-speed mode divisor (U2X0 = 1), as the firmware's serial.
const UBRR: u16 = ((CPU_HZ + 4 * BAUD) / (8 * BAUD) - 1) as u16;
const SAMPLES: u16 = 256;
const NO_FAULT: DriverStatus = DriverStatus { alarm: false, bridge_fault: false };

struct Tx;

impl ufmt::uWrite for Tx {
    type Error = core::convert::Infallible;

    fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
        // SAFETY: this program is the only user of USART0.
        let usart = unsafe { &*USART0::ptr() };
        for byte in s.bytes() {
            while usart.ucsr0a.read().udre0().bit_is_clear() {}
            usart.udr0.write(|w| w.bits(byte));
        }
        Ok(())
    }
}

#[inline(always)]
fn now(timer: &TC1) -> u16 {
    timer.tcnt1.read().bits()
}

/// Cycles of the measurement itself (two counter reads).
fn bare(timer: &TC1) -> u16 {
    let mut least = u16::MAX;
    for _ in 0..SAMPLES {
        let start = now(timer);
        let end = black_box(now(timer));
        least = least.min(end.wrapping_sub(start));
    }
    least
}

struct Cost {
    min: u16,
    max: u16,
    sum: u32,
}

/// One robust-PID tick per sample, in arithmetic `A`.
#[inline(never)]
fn law_cost<A: LoopArithmetic>(timer: &TC1, overhead: u16) -> Cost {
    let gains: LoopGains<A> =
        Strategy::RobustPid { gamma_milli: 500 }.loop_gains::<A>(0.1, 0.001).unwrap_or(LoopGains::OPEN_LOOP);
    let mut controller = AxisController::<A>::new(gains, 200 * 2048, FollowingErrorLimit::printer_default(1000));
    let mut cost = Cost { min: u16::MAX, max: 0, sum: 0 };
    for k in 0..SAMPLES {
        let position = i32::from(k) * 10;
        let reference = black_box(Reference { position, velocity: 10_240 });
        let measured = black_box(Ok(position - (i32::from(k % 64) * 3 - 96)));
        let start = now(timer);
        let output = controller.tick(reference, measured, NO_FAULT);
        let end = now(timer);
        let _ = black_box(output);
        let cycles = end.wrapping_sub(start).saturating_sub(overhead);
        cost.min = cost.min.min(cycles);
        cost.max = cost.max.max(cycles);
        cost.sum += u32::from(cycles);
    }
    cost
}

fn report(tx: &mut Tx, name: &str, cost: &Cost) {
    let _ = uwrite!(tx, "avr_loop_tick_cycles_{}={}\n", name, cost.sum / u32::from(SAMPLES));
    let _ = uwrite!(tx, "avr_loop_tick_cycles_{}_min={}\navr_loop_tick_cycles_{}_max={}\n", name, cost.min, name, cost.max);
}

#[avr_device::entry]
fn main() -> ! {
    // SAFETY: the only call.
    let dp = unsafe { Peripherals::steal() };
    dp.USART0.ubrr0.write(|w| w.bits(UBRR));
    // SAFETY: U2X0 only; 8N1 (UCSZ01 | UCSZ00).
    dp.USART0.ucsr0a.write(|w| unsafe { w.bits(1 << 1) });
    // SAFETY: as above.
    dp.USART0.ucsr0c.write(|w| unsafe { w.bits(0b0000_0110) });
    dp.USART0.ucsr0b.write(|w| w.txen0().set_bit());
    // Timer1, normal mode, clk/1: TCNT1 counts CPU cycles.
    // SAFETY: documented field values.
    dp.TC1.tccr1a.write(|w| unsafe { w.bits(0) });
    // SAFETY: CS10 = 1: no prescaler.
    dp.TC1.tccr1b.write(|w| unsafe { w.bits(1) });

    let overhead = bare(&dp.TC1);
    let fixed = law_cost::<FixedPoint>(&dp.TC1, overhead);
    let float = law_cost::<Float>(&dp.TC1, overhead);
    let mut tx = Tx;
    let _ = uwrite!(tx, "bench:loop\nsamples={}\noverhead_cycles={}\n", SAMPLES, overhead);
    report(&mut tx, "fixed", &fixed);
    report(&mut tx, "f32", &float);
    let _ = uwrite!(tx, "done\n");
    loop {
        avr_device::asm::sleep();
    }
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    let _ = uwrite!(Tx, "Error:bench panic\n");
    loop {}
}
