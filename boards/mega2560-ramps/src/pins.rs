//! RAMPS 1.4 on the Mega 2560 (Marlin's pin map).
//!
//! | role      | X    | Y    | Z    | E0   | E1   |
//! |-----------|------|------|------|------|------|
//! | STEP      | PF0  | PF6  | PL3  | PA4  | PC1  |
//! | DIR       | PF1  | PF7  | PL1  | PA6  | PC3  |
//! | EN (low)  | PD7  | PF2  | PK0  | PA2  | PC7  |
//!
//! Heaters: hot end D10 = PB4 (OC2A), bed D8 = PH5 (OC4C), fan D9 = PH6
//! (OC2B). Thermistors: T0 = ADC13, bed = ADC14, T1 = ADC15.
//! Endstops: X_MIN PE5, X_MAX PE4, Y_MIN PJ1, Y_MAX PJ0, Z_MIN PD3, Z_MAX PD2.

use avr_device::atmega2560::Peripherals;

/// One bit of an I/O port, named by its register addresses' owner.
#[derive(Clone, Copy)]
pub enum Port {
    A,
    B,
    C,
    D,
    F,
    H,
    K,
}

#[derive(Clone, Copy)]
pub struct Pin {
    pub port: Port,
    pub bit: u8,
}

const fn pin(port: Port, bit: u8) -> Pin {
    Pin { port, bit }
}

/// Stepper driver enables (active low: high = disabled).
pub const STEPPER_ENABLES: [Pin; 5] =
    [pin(Port::D, 7), pin(Port::F, 2), pin(Port::K, 0), pin(Port::A, 2), pin(Port::C, 7)];
/// Heater and fan MOSFET gates (high = on).
pub const HEATER_OUTPUTS: [Pin; 3] = [pin(Port::B, 4), pin(Port::H, 5), pin(Port::H, 6)];

/// The ADC channel of the hot-end thermistor (T0).
pub const HOTEND_THERMISTOR_CHANNEL: u8 = 13;
/// The ADC channel of the bed thermistor.
pub const BED_THERMISTOR_CHANNEL: u8 = 14;

/// Drive `pin` as an output at `high`. The level is written before the
/// direction so that the pin never glitches to the other level.
pub fn make_output(dp: &Peripherals, pin: Pin, high: bool) {
    let mask = 1u8 << pin.bit;
    macro_rules! drive {
        ($port:ident, $out:ident, $ddr:ident) => {{
            // SAFETY: every bit pattern is valid for PORTx and DDRx.
            dp.$port.$out.modify(|r, w| unsafe { w.bits(if high { r.bits() | mask } else { r.bits() & !mask }) });
            dp.$port.$ddr.modify(|r, w| unsafe { w.bits(r.bits() | mask) });
        }};
    }
    match pin.port {
        Port::A => drive!(PORTA, porta, ddra),
        Port::B => drive!(PORTB, portb, ddrb),
        Port::C => drive!(PORTC, portc, ddrc),
        Port::D => drive!(PORTD, portd, ddrd),
        Port::F => drive!(PORTF, portf, ddrf),
        Port::H => drive!(PORTH, porth, ddrh),
        Port::K => drive!(PORTK, portk, ddrk),
    }
}

/// The safe state: every heater and fan off, every stepper driver disabled.
/// Runs first at boot and from the panic handler.
pub fn all_outputs_safe(dp: &Peripherals) {
    for heater in HEATER_OUTPUTS {
        make_output(dp, heater, false);
    }
    for enable in STEPPER_ENABLES {
        make_output(dp, enable, true);
    }
}
