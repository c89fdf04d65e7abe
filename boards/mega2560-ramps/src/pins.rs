//! The Mega 2560's pins as the machine file wires them; the defaults a
//! machine file starts from are RAMPS 1.4's (Marlin's pin map):
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
#[allow(dead_code)] // every port is listed; a machine uses some
pub enum Port {
    A = 0x20,
    B = 0x23,
    C = 0x26,
    D = 0x29,
    E = 0x2C,
    F = 0x2F,
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
    pub fn pin_register(self) -> *mut u8 {
        let low = self as u8;
        let address = if low < 0x20 { 0x100 + u16::from(low) } else { u16::from(low) };
        address as usize as *mut u8
    }
}

impl Port {
    #[cfg_attr(not(feature = "motion"), allow(dead_code))]
    /// The I/O-space address of the port's PORTx register (what `sbi` and
    /// `cbi` take), for ports A–G; `None` for H–L, which lie beyond it.
    pub const fn port_io_address(self) -> Option<u8> {
        let low = self as u8;
        if low < 0x20 {
            None
        } else {
            Some(low + 2 - 0x20)
        }
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

// The machine's pins, generated from its machine file (build.rs): `STEP`,
// `DIR`, `ENABLE` (X, Y, Z, E0), `ENDSTOPS` (M119's order) with
// `ENDSTOP_PULLUPS` and `ENDSTOP_ACTIVE_LOW`, the heaters' outputs, PWM
// channels and thermistor channels (`HOTEND`, `BED`, `BARREL`, `*_PWM`,
// `*_ADC`), `RELAY` and `FAN`. Everything below, the step interrupt
// included, reads them from here.
// (Not every machine uses every item: the extrusion line has no bed, …)
#[allow(dead_code)]
mod generated {
    use super::{pin, Pin, Port};
    include!(concat!(env!("OUT_DIR"), "/pins.rs"));
}
pub use generated::*;

/// RAMPS's second extruder driver (unused): its enable is held off.
pub const E1_ENABLE: Pin = pin(Port::C, 7);
/// The RAMPS 1.4 MOSFET gates (D10, D9, D8): whatever the machine file
/// puts on them, they are driven low at boot and on every halt.
pub const HEATER_OUTPUTS: [Pin; 3] = [pin(Port::B, 4), pin(Port::H, 6), pin(Port::H, 5)];

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

/// SPEC §3's safety inputs (the arm build), on RAMPS AUX-2 beside the
/// ALARMs, each pulled up: the safety relay of the light curtain on D40 =
/// PG1, the emergency stop on D42 = PL7, the re-arm button on D44 = PL5.
/// The trips are fail-safe: the relay's safety contact and the e-stop's
/// NC contact hold their line low while all is well, so a trip, a pressed
/// button or an open wire reads high. Re-arm is a normally-open button to
/// ground (pressed = low). The machine file cannot use these pins
/// (machine-file's check reserves them).
#[cfg(feature = "machine-arm")]
pub const SAFETY_RELAY: Pin = pin(Port::G, 1);
#[cfg(feature = "machine-arm")]
pub const EMERGENCY_STOP: Pin = pin(Port::L, 7);
#[cfg(feature = "machine-arm")]
pub const REARM: Pin = pin(Port::L, 5);
/// The level of each input when active (tripped, pressed, pressed).
#[cfg(feature = "machine-arm")]
pub const SAFETY_RELAY_TRIPPED_HIGH: bool = true;
#[cfg(feature = "machine-arm")]
pub const EMERGENCY_STOP_PRESSED_HIGH: bool = true;
#[cfg(feature = "machine-arm")]
pub const REARM_PRESSED_HIGH: bool = false;

/// The inputs that stop the machine (the core's bits).
#[cfg(feature = "machine-arm")]
pub const SAFETY_TRIPS: u8 = firmware::machine::safety::RELAY_TRIPPED | firmware::machine::safety::EMERGENCY_STOP;

/// The safety inputs in the core's bits (`firmware::machine::safety`).
#[cfg(feature = "machine-arm")]
pub fn safety_inputs(dp: &Peripherals) -> u8 {
    use firmware::machine::safety::{EMERGENCY_STOP as STOP, REARM as ARM, RELAY_TRIPPED};
    [(SAFETY_RELAY, SAFETY_RELAY_TRIPPED_HIGH, RELAY_TRIPPED), (EMERGENCY_STOP, EMERGENCY_STOP_PRESSED_HIGH, STOP), (REARM, REARM_PRESSED_HIGH, ARM)]
        .iter()
        .fold(0, |inputs, &(input, active_high, bit)| if read(dp, input) == active_high { inputs | bit } else { inputs })
}

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
#[allow(dead_code)]
pub fn make_input_pulled_up(dp: &Peripherals, pin: Pin) {
    make_input(dp, pin, true);
}

/// Make `pin` an input, its pull-up on or off.
pub fn make_input(_dp: &Peripherals, pin: Pin, pull_up: bool) {
    let mask = 1u8 << pin.bit;
    let base = pin.port.pin_register();
    // SAFETY: as in `make_output_unguarded`: DDRx, then PORTx; interrupts
    // are held off (the step interrupt writes other bits of some ports).
    avr_device::interrupt::free(|_| unsafe {
        let ddr = base.add(DDR);
        ddr.write_volatile(ddr.read_volatile() & !mask);
        let out = base.add(PORT);
        out.write_volatile(if pull_up { out.read_volatile() | mask } else { out.read_volatile() & !mask });
    });
}

/// The endstops as inputs, each with its pull-up as the machine file says.
pub fn init_endstops(dp: &Peripherals) {
    for (index, endstop) in ENDSTOPS.iter().enumerate() {
        if let Some(pin) = *endstop {
            make_input(dp, pin, ENDSTOP_PULLUPS & (1 << index) != 0);
        }
    }
}

/// The level of an input pin.
#[inline(always)]
pub fn read(_dp: &Peripherals, pin: Pin) -> bool {
    // SAFETY: `pin_register` is the port's PINx, readable at any time.
    let bits = unsafe { pin.port.pin_register().read_volatile() };
    bits & (1 << pin.bit) != 0
}

/// Drive every stepper driver's enable (active low); E1's stays off.
#[cfg_attr(any(feature = "machine-extrusion-line", feature = "machine-powder-bed"), allow(dead_code))]
pub fn set_steppers_enabled(dp: &Peripherals, enabled: bool) {
    for &enable in &ENABLE {
        make_output(dp, enable, !enabled);
    }
}

/// Endstop levels packed in the core's bit order (X_MIN, X_MAX, Y_MIN, …);
/// a switch that is not fitted reads as not triggered.
pub fn endstop_levels(dp: &Peripherals) -> u8 {
    ENDSTOPS.iter().enumerate().fold(0, |bits, (i, endstop)| {
        let motor = i / 2;
        let active_low = ENDSTOP_ACTIVE_LOW & (1 << motor) != 0;
        let level = match *endstop {
            Some(pin) => read(dp, pin),
            None => active_low,
        };
        bits | (u8::from(level) << i)
    })
}

/// Endstops in the step generator's layout (bit m: motor m's min switch,
/// 4 + m: its max), 1 = triggered, polarity applied; switches not fitted
/// read as not triggered. The pins are constants: this compiles to a few
/// port reads and bit tests.
#[inline(always)]
#[cfg_attr(not(feature = "motion"), allow(dead_code))]
pub fn endstops_triggered(dp: &Peripherals) -> u8 {
    let mut levels = 0u8;
    let mut index = 0;
    while index < 6 {
        let bit = if index % 2 == 0 { 1 << (index / 2) } else { 0x10 << (index / 2) };
        let high = match ENDSTOPS[index] {
            Some(pin) => read(dp, pin),
            None => ENDSTOP_ACTIVE_LOW & bit != 0,
        };
        if high {
            levels |= bit;
        }
        index += 1;
    }
    levels ^ ENDSTOP_ACTIVE_LOW
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
    for &enable in &ENABLE {
        make_output(dp, enable, true);
    }
    make_output(dp, E1_ENABLE, true);
}
