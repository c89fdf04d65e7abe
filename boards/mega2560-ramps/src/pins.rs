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

/// One bit of an I/O port, named by its register addresses' owner. The
/// discriminant is the low byte of the port's PINx address (DDRx and PORTx
/// follow it): ports A–G sit at 0x20–0x34, H–L at 0x100–0x10B
/// (avr-device's `PORTx::PTR`). One address computation instead of a match
/// with eleven arms per access.
#[derive(Clone, Copy)]
#[repr(u8)]
pub enum Port {
    A = 0x20,
    B = 0x23,
    C = 0x26,
    D = 0x29,
    E = 0x2C,
    F = 0x2F,
    #[cfg_attr(not(feature = "machine-powder-bed"), allow(dead_code))]
    G = 0x32,
    H = 0x00,
    J = 0x03,
    K = 0x06,
    L = 0x09,
}

impl Port {
    /// The data-space address of the port's PINx register; DDRx is at
    /// +1 and PORTx at +2.
    #[inline(always)]
    fn pin_register(self) -> *mut u8 {
        let low = self as u8;
        let address = if low < 0x20 { 0x100 + u16::from(low) } else { u16::from(low) };
        address as usize as *mut u8
    }
}

const DDR: usize = 1;
const PORT: usize = 2;

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

fn make_output_unguarded(_dp: &Peripherals, pin: Pin, high: bool) {
    let mask = 1u8 << pin.bit;
    let base = pin.port.pin_register();
    // SAFETY: `base` is a port's PINx; PORTx and DDRx follow it, and every
    // bit pattern is valid for them (the same accesses as the PAC's
    // `modify`).
    unsafe {
        let out = base.add(PORT);
        let value = out.read_volatile();
        out.write_volatile(if high { value | mask } else { value & !mask });
        let ddr = base.add(DDR);
        ddr.write_volatile(ddr.read_volatile() | mask);
    }
}

/// Make `pin` an input with its pull-up on (endstops switch to ground or
/// are open-collector; an open wire then reads high).
pub fn make_input_pulled_up(_dp: &Peripherals, pin: Pin) {
    let mask = 1u8 << pin.bit;
    let base = pin.port.pin_register();
    // SAFETY: as in `make_output_unguarded`: DDRx, then PORTx.
    unsafe {
        let ddr = base.add(DDR);
        ddr.write_volatile(ddr.read_volatile() & !mask);
        let out = base.add(PORT);
        out.write_volatile(out.read_volatile() | mask);
    }
}

/// The level of an input pin.
pub fn read(_dp: &Peripherals, pin: Pin) -> bool {
    // SAFETY: `pin_register` is the port's PINx, readable at any time.
    let bits = unsafe { pin.port.pin_register().read_volatile() };
    bits & (1 << pin.bit) != 0
}

/// Drive every stepper driver's enable (active low).
#[cfg_attr(any(feature = "machine-extrusion-line", feature = "machine-powder-bed"), allow(dead_code))]
pub fn set_steppers_enabled(dp: &Peripherals, enabled: bool) {
    for &enable in &STEPPER_ENABLES {
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
    for &heater in &HEATER_OUTPUTS {
        make_output(dp, heater, false);
    }
    for &enable in &STEPPER_ENABLES {
        make_output(dp, enable, true);
    }
}
