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
    E,
    F,
    #[cfg_attr(not(feature = "machine-powder-bed"), allow(dead_code))]
    G,
    H,
    J,
    K,
    L,
}

#[derive(Clone, Copy)]
pub struct Pin {
    pub port: Port,
    pub bit: u8,
}

pub const fn pin(port: Port, bit: u8) -> Pin {
    Pin { port, bit }
}

/// Stepper driver enables (active low: high = disabled).
pub const STEPPER_ENABLES: [Pin; 5] =
    [pin(Port::D, 7), pin(Port::F, 2), pin(Port::K, 0), pin(Port::A, 2), pin(Port::C, 7)];
/// Heater and fan MOSFET gates (high = on).
pub const HEATER_OUTPUTS: [Pin; 3] = [HOTEND, BED, FAN];
/// The hot-end heater (D10, OC2A).
pub const HOTEND: Pin = pin(Port::B, 4);
/// The heated bed (D8, OC4C).
pub const BED: Pin = pin(Port::H, 5);
/// The part-cooling fan (D9, OC2B).
pub const FAN: Pin = pin(Port::H, 6);
/// Endstops in the core's bit order: X_MIN, X_MAX, Y_MIN, Y_MAX, Z_MIN, Z_MAX.
pub const ENDSTOPS: [Pin; 6] =
    [pin(Port::E, 5), pin(Port::E, 4), pin(Port::J, 1), pin(Port::J, 0), pin(Port::D, 3), pin(Port::D, 2)];

/// The ADC channel of the hot-end thermistor (T0).
pub const HOTEND_THERMISTOR_CHANNEL: u8 = 13;
/// The ADC channel of the bed thermistor.
pub const BED_THERMISTOR_CHANNEL: u8 = 14;

/// SPEC §3's driver ALARM inputs (the arm build), motors X Y Z E0 in
/// order: A9–A12 = PK1–PK4 on RAMPS AUX-2, pulled up.
#[cfg(feature = "machine-arm")]
pub const DRIVER_ALARMS: [Pin; 4] = [pin(Port::K, 1), pin(Port::K, 2), pin(Port::K, 3), pin(Port::K, 4)];
/// The level of an active ALARM (polarity is configuration): the drivers'
/// open-collector outputs pull the line low on an alarm.
#[cfg(feature = "machine-arm")]
pub const DRIVER_ALARM_ACTIVE_HIGH: bool = false;

/// The active driver ALARMs, bit i = motor i.
#[cfg(feature = "machine-arm")]
pub fn driver_alarms(dp: &Peripherals) -> u8 {
    DRIVER_ALARMS
        .iter()
        .enumerate()
        .fold(0, |alarms, (motor, &alarm)| if read(dp, alarm) == DRIVER_ALARM_ACTIVE_HIGH { alarms | 1 << motor } else { alarms })
}

/// STEP and DIR pins of X, Y, Z and E0 (driven by [`crate::stepping`]).
pub const STEP_DIR: [Pin; 8] = [
    pin(Port::F, 0),
    pin(Port::F, 1),
    pin(Port::F, 6),
    pin(Port::F, 7),
    pin(Port::L, 3),
    pin(Port::L, 1),
    pin(Port::A, 4),
    pin(Port::A, 6),
];

/// Drive `pin` as an output at `high`. The level is written before the
/// direction so that the pin never glitches to the other level. Interrupts
/// are held off during the read-modify-write: the step interrupt writes
/// STEP/DIR bits of the same ports (F, L, A).
pub fn make_output(dp: &Peripherals, pin: Pin, high: bool) {
    avr_device::interrupt::free(|_| make_output_unguarded(dp, pin, high));
}

/// [`make_output`] from code that already holds interrupts off (an
/// interrupt handler).
#[cfg_attr(not(any(feature = "bed-ssr", feature = "machine-extrusion-line", feature = "machine-powder-bed")), allow(dead_code))]
pub fn make_output_in(dp: &Peripherals, _cs: avr_device::interrupt::CriticalSection, pin: Pin, high: bool) {
    make_output_unguarded(dp, pin, high);
}

fn make_output_unguarded(dp: &Peripherals, pin: Pin, high: bool) {
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
        Port::E => drive!(PORTE, porte, ddre),
        Port::F => drive!(PORTF, portf, ddrf),
        Port::G => drive!(PORTG, portg, ddrg),
        Port::H => drive!(PORTH, porth, ddrh),
        Port::J => drive!(PORTJ, portj, ddrj),
        Port::K => drive!(PORTK, portk, ddrk),
        Port::L => drive!(PORTL, portl, ddrl),
    }
}

/// Make `pin` an input with its pull-up on (endstops switch to ground or
/// are open-collector; an open wire then reads high).
pub fn make_input_pulled_up(dp: &Peripherals, pin: Pin) {
    let mask = 1u8 << pin.bit;
    macro_rules! input {
        ($port:ident, $out:ident, $ddr:ident) => {{
            // SAFETY: every bit pattern is valid for DDRx and PORTx.
            dp.$port.$ddr.modify(|r, w| unsafe { w.bits(r.bits() & !mask) });
            dp.$port.$out.modify(|r, w| unsafe { w.bits(r.bits() | mask) });
        }};
    }
    match pin.port {
        Port::A => input!(PORTA, porta, ddra),
        Port::B => input!(PORTB, portb, ddrb),
        Port::C => input!(PORTC, portc, ddrc),
        Port::D => input!(PORTD, portd, ddrd),
        Port::E => input!(PORTE, porte, ddre),
        Port::F => input!(PORTF, portf, ddrf),
        Port::G => input!(PORTG, portg, ddrg),
        Port::H => input!(PORTH, porth, ddrh),
        Port::J => input!(PORTJ, portj, ddrj),
        Port::K => input!(PORTK, portk, ddrk),
        Port::L => input!(PORTL, portl, ddrl),
    }
}

/// The level of an input pin.
pub fn read(dp: &Peripherals, pin: Pin) -> bool {
    let bits = match pin.port {
        Port::A => dp.PORTA.pina.read().bits(),
        Port::B => dp.PORTB.pinb.read().bits(),
        Port::C => dp.PORTC.pinc.read().bits(),
        Port::D => dp.PORTD.pind.read().bits(),
        Port::E => dp.PORTE.pine.read().bits(),
        Port::F => dp.PORTF.pinf.read().bits(),
        Port::G => dp.PORTG.ping.read().bits(),
        Port::H => dp.PORTH.pinh.read().bits(),
        Port::J => dp.PORTJ.pinj.read().bits(),
        Port::K => dp.PORTK.pink.read().bits(),
        Port::L => dp.PORTL.pinl.read().bits(),
    };
    bits & (1 << pin.bit) != 0
}

/// Drive every stepper driver's enable (active low).
#[cfg_attr(any(feature = "machine-extrusion-line", feature = "machine-powder-bed"), allow(dead_code))]
pub fn set_steppers_enabled(dp: &Peripherals, enabled: bool) {
    for enable in STEPPER_ENABLES {
        make_output(dp, enable, !enabled);
    }
}

/// Endstop levels packed in the core's bit order.
pub fn endstop_levels(dp: &Peripherals) -> u8 {
    ENDSTOPS.iter().enumerate().fold(0, |bits, (i, &pin)| bits | (u8::from(read(dp, pin)) << i))
}

/// The safe state: every heater and fan off, every stepper driver disabled.
/// Runs first at boot and from the panic handler.
pub fn all_outputs_safe(dp: &Peripherals) {
    // A pin driven by a PWM compare unit ignores its PORT bit: cut the
    // timers loose first.
    crate::pwm::disconnect_all(dp);
    for heater in HEATER_OUTPUTS {
        make_output(dp, heater, false);
    }
    for enable in STEPPER_ENABLES {
        make_output(dp, enable, true);
    }
}
