//! The extrusion line's two velocity-mode steppers (cargo feature
//! `machine-extrusion-line`, SPEC §4): the screw on E0's driver, the puller
//! on X's, each on its own compare channel of Timer5 (16 MHz / 8 = the
//! core's 2 MHz step clock).
//!
//! Klipper's shape: each compare interrupt flips its STEP pin and moves its
//! compare on by the next half period, both prepared by the core
//! (`VelocityStepper::on_timer`: a toggle, an add and a shift). The
//! interrupt runs on its own copy of the stepper; the main loop, after the
//! core's ramp update (every 20 ms), lets that copy follow the model
//! ([`apply`]) inside a critical section, and starts or stops the channel.
//!
//! | motor | STEP | DIR | EN (low = on) | timer |
//! |---|---|---|---|---|
//! | screw | D26 = PA4 | D28 = PA6 | D24 = PA2 | OCR5A |
//! | puller | A0 = PF0 | A1 = PF1 | D38 = PD7 | OCR5B |

use crate::pins::{self, Pin, Port};
use avr_device::atmega2560::Peripherals;
use avr_device::interrupt::{CriticalSection, Mutex};
use core::cell::RefCell;
use firmware::machine::line::{LineTimers, LINE_CONFIG};
use firmware::machines::extrusion_line::ExtrusionLine;
use firmware::machines::velocity::{TimerChange, VelocityConfig, VelocityStepper};

struct Motor {
    step: Pin,
    dir: Pin,
    enable: Pin,
    /// OCIE5A / OCIE5B and OCF5A / OCF5B.
    bit: u8,
}

const SCREW: Motor = Motor { step: pins::pin(Port::A, 4), dir: pins::pin(Port::A, 6), enable: pins::pin(Port::A, 2), bit: 1 };
const PULLER: Motor = Motor { step: pins::pin(Port::F, 0), dir: pins::pin(Port::F, 1), enable: pins::pin(Port::D, 7), bit: 2 };

/// The least lead, in timer ticks (0.5 µs), a compare is armed with: the
/// compare write and the return from the interrupt take about 4 µs.
const LATE_MARGIN_TICKS: i16 = 8;

/// The interrupts' copies: [screw, puller].
static STEPPERS: Mutex<RefCell<[VelocityStepper; 2]>> = Mutex::new(RefCell::new([VelocityStepper::new(); 2]));

/// Timer5 free-running at 2 MHz, both channels off; drivers disabled.
pub fn init(dp: &Peripherals) {
    // Normal mode (WGM53:50 = 0), clk/8, no interrupt yet.
    dp.TC5.tccr5a.write(|w| w.wgm5().bits(0b00));
    dp.TC5.tccr5b.write(|w| w.wgm5().bits(0b00).cs5().prescale_8());
    dp.TC5.timsk5.write(|w| w.ocie5a().clear_bit().ocie5b().clear_bit());
    for motor in [&SCREW, &PULLER] {
        pins::make_output(dp, motor.step, false);
        pins::make_output(dp, motor.enable, true);
    }
}

/// Both channels off at once (halt, kill, panic): from any context.
pub fn stop(dp: &Peripherals) {
    dp.TC5.timsk5.write(|w| w.ocie5a().clear_bit().ocie5b().clear_bit());
}

/// After `Machine::poll_line`: the copies follow the models; a start arms
/// the channel (driver on, direction set, first edge `first_ticks` away),
/// a stop disarms it (STEP low; the driver keeps holding).
pub fn apply(dp: &Peripherals, timers: LineTimers, line: Option<&ExtrusionLine<firmware::machines::diameter::ClosedLoopPi>>) {
    let Some(line) = line.filter(|_| timers.changed) else { return };
    avr_device::interrupt::free(|cs| {
        let mut steppers = STEPPERS.borrow(cs).borrow_mut();
        for (index, (motor, change, model, config)) in [
            (&SCREW, timers.screw, &line.extruder, &LINE_CONFIG.extruder),
            (&PULLER, timers.puller, &line.puller, &LINE_CONFIG.puller),
        ]
        .into_iter()
        .enumerate()
        {
            steppers[index].follow(model);
            match change {
                TimerChange::Start { first_ticks } => start(dp, cs, motor, config, first_ticks),
                TimerChange::Stop => {
                    // SAFETY: clearing this channel's interrupt enable only.
                    dp.TC5.timsk5.modify(|r, w| unsafe { w.bits(r.bits() & !(1 << motor.bit)) });
                    pins::make_output_in(dp, cs, motor.step, false);
                }
                TimerChange::None => {}
            }
        }
    });
}

fn start(dp: &Peripherals, cs: CriticalSection, motor: &Motor, config: &VelocityConfig, first_ticks: u16) {
    pins::make_output_in(dp, cs, motor.enable, false);
    pins::make_output_in(dp, cs, motor.dir, config.invert_direction);
    let at = dp.TC5.tcnt5.read().bits().wrapping_add(first_ticks);
    if motor.bit == 1 {
        dp.TC5.ocr5a.write(|w| w.bits(at));
    } else {
        dp.TC5.ocr5b.write(|w| w.bits(at));
    }
    // SAFETY: writing 1 clears this channel's pending flag; then its
    // interrupt is enabled.
    dp.TC5.tifr5.write(|w| unsafe { w.bits(1 << motor.bit) });
    dp.TC5.timsk5.modify(|r, w| unsafe { w.bits(r.bits() | (1 << motor.bit)) });
}

/// One compare of `index`'s channel: the next STEP level and compare time.
#[inline(always)]
fn on_compare(index: usize, motor: &Motor) {
    // SAFETY: Timer5 and the two motors' pins belong to this module; the
    // interrupt runs with interrupts off.
    let dp = unsafe { Peripherals::steal() };
    avr_device::interrupt::free(|cs| {
        let edge = STEPPERS.borrow(cs).borrow_mut()[index].on_timer();
        match edge {
            Some(edge) => {
                pins::make_output_in(&dp, cs, motor.step, edge.step_high);
                let previous = if index == 0 { dp.TC5.ocr5a.read().bits() } else { dp.TC5.ocr5b.read().bits() };
                let mut next = previous.wrapping_add(edge.next_ticks);
                // Held off past the next edge's time (by other interrupts
                // and critical sections): that compare would only match
                // after the counter wraps, 32.8 ms away. Take the edge a
                // few ticks from now instead: late, never lost.
                let now = dp.TC5.tcnt5.read().bits();
                if next.wrapping_sub(now) as i16 <= LATE_MARGIN_TICKS {
                    next = now.wrapping_add(LATE_MARGIN_TICKS as u16);
                }
                if index == 0 {
                    dp.TC5.ocr5a.write(|w| w.bits(next));
                } else {
                    dp.TC5.ocr5b.write(|w| w.bits(next));
                }
            }
            // SAFETY: clearing this channel's interrupt enable only.
            None => dp.TC5.timsk5.modify(|r, w| unsafe { w.bits(r.bits() & !(1 << motor.bit)) }),
        }
    });
}

#[avr_device::interrupt(atmega2560)]
fn TIMER5_COMPA() {
    on_compare(0, &SCREW);
}

#[avr_device::interrupt(atmega2560)]
fn TIMER5_COMPB() {
    on_compare(1, &PULLER);
}
