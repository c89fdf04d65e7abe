//! A heater behind a solid-state relay (`control = "ssr-window"` in the
//! machine file): the bed on D8, or the extrusion line's barrel on D9.
//!
//! A zero-crossing SSR switches whole mains half-cycles, so a MOSFET's
//! kilohertz PWM is useless to it: the bed's duty becomes a 200 ms
//! time-proportioning window with on and off slots of at least 10 ms
//! (SPEC §4, `firmware::thermal::SlowPwm`). The window runs in the 1 kHz
//! tick, not in the main loop, so a long main-loop pass (up to tens of
//! milliseconds) can never shorten a slot: the interrupt compares two
//! numbers and writes one pin each millisecond.
//!
//! The main loop hands over the duty ([`set_duty`]); [`stop`] (halt,
//! kill) turns the window off so the tick cannot raise the pin again after
//! `pins::all_outputs_safe` has lowered it.

use avr_device::atmega2560::Peripherals;
use avr_device::interrupt::{CriticalSection, Mutex};
use core::cell::Cell;
use firmware::thermal::{SlowPwm, TimeProportioning};

#[derive(Clone, Copy)]
struct Window {
    pwm: SlowPwm,
    duty: u8,
    running: bool,
}

/// The relay's pin and window (the machine file's `control = "ssr-window"`
/// heater).
const RELAY: (crate::pins::Pin, TimeProportioning) = match crate::pins::RELAY {
    Some(relay) => relay,
    None => panic!("ssr.rs is built only for a machine with a relay-window heater"),
};
const PIN: crate::pins::Pin = RELAY.0;

static BED: Mutex<Cell<Window>> = Mutex::new(Cell::new(Window { pwm: SlowPwm::new(), duty: 0, running: false }));

/// The bed's duty (0–255) from the main loop; takes effect at the next
/// window.
pub fn set_duty(duty: u8) {
    avr_device::interrupt::free(|cs| {
        let cell = BED.borrow(cs);
        cell.set(Window { duty, running: true, ..cell.get() });
    });
}

/// Off at once, and kept off until the next [`set_duty`].
pub fn stop() {
    avr_device::interrupt::free(|cs| BED.borrow(cs).set(Window { pwm: SlowPwm::new(), duty: 0, running: false }));
}

/// One millisecond of the window (from the 1 kHz tick).
pub fn on_tick(dp: &Peripherals, cs: CriticalSection, now_ms: u32) {
    let cell = BED.borrow(cs);
    let mut window = cell.get();
    if !window.running {
        return;
    }
    let level = window.pwm.level(&RELAY.1, now_ms, window.duty);
    cell.set(window);
    crate::pins::make_output_in(dp, cs, PIN, level);
}
