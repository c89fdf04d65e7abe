//! The RepRapDiscount Smart Controller's 16×2 HD44780 in 4-bit mode (cargo
//! feature `display-hd44780`): the core's driver (`firmware::drivers`) on
//! the RAMPS EXP1 pins, Marlin's pin map: RS D16 (PH1), E D17 (PH0), D4 D23
//! (PA1), D5 D25 (PA3), D6 D27 (PA5), D7 D29 (PA7).
//!
//! The screen (`Machine::status_screen`: state, Z, heaters) is rewritten
//! every 500 ms: 34 transfers of ≈ 45 µs, ≈ 1.6 ms of the main loop.

use avr_device::atmega2560::Peripherals;
use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{ErrorType, OutputPin};
use firmware::drivers::hd44780::Hd44780;

use crate::pins::{self, Pin, Port};

/// How often the screen is rewritten, ms.
pub const REFRESH_MS: u32 = 500;

/// One of the display's pins, driven through the board's port writes
/// (interrupts held off for each read-modify-write: port A also carries
/// E0's STEP and enable pins).
pub struct LcdPin(Pin);

impl ErrorType for LcdPin {
    type Error = core::convert::Infallible;
}

impl OutputPin for LcdPin {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        // SAFETY: `make_output` only changes this pin's PORT and DDR bits.
        pins::make_output(&unsafe { Peripherals::steal() }, self.0, false);
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Self::Error> {
        // SAFETY: as above.
        pins::make_output(&unsafe { Peripherals::steal() }, self.0, true);
        Ok(())
    }
}

/// Busy waiting at 16 MHz (the display needs microseconds between
/// transfers, milliseconds at power-on).
pub struct BusyDelay;

impl DelayNs for BusyDelay {
    fn delay_ns(&mut self, ns: u32) {
        // 16 cycles a microsecond; whole microseconds, rounded up.
        let mut us = ns.div_ceil(1000);
        while us > 0 {
            avr_device::asm::delay_cycles(12);
            us -= 1;
        }
    }
}

pub type Display = Hd44780<LcdPin, LcdPin, LcdPin, LcdPin, LcdPin, LcdPin>;

/// Take the pins and initialise the display (≈ 60 ms, at boot).
pub fn init() -> Display {
    let mut display = Hd44780::new(
        LcdPin(pins::pin(Port::H, 1)),
        LcdPin(pins::pin(Port::H, 0)),
        LcdPin(pins::pin(Port::A, 1)),
        LcdPin(pins::pin(Port::A, 3)),
        LcdPin(pins::pin(Port::A, 5)),
        LcdPin(pins::pin(Port::A, 7)),
    );
    let _ = display.init(&mut BusyDelay);
    display
}
