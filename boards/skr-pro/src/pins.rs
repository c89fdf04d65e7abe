//! BigTreeTech SKR Pro 1.2 pin map (STM32F407ZGT6), as in Marlin's
//! `pins_BTT_SKR_PRO_common.h` (checked against it) and BTT's schematic.
//!
//! | role       | X    | Y    | Z    | E0   | E1   | E2   |
//! |------------|------|------|------|------|------|------|
//! | STEP       | PE9  | PE11 | PE13 | PE14 | PD15 | PD13 |
//! | DIR        | PF1  | PE8  | PC2  | PA0  | PE7  | PG9  |
//! | EN (low)   | PF2  | PD7  | PC0  | PC3  | PA3  | PF0  |
//!
//! Heaters: HE0 PB1, HE1 PD14, HE2 PB0, bed PD12 (high = on). Fans: FAN0
//! PC8 (TIM3_CH3, hardware PWM here), FAN1 PE5, FAN2 PE6. Thermistors:
//! T0 PF4 = ADC3_IN14 (hot end 0), T1 PF5 = ADC3_IN15, T2 PF6 = ADC3_IN4,
//! bed PF3 = ADC3_IN9 (4.7 kΩ pull-ups to 3.3 V = the ADC reference, so the
//! ratio, and the core's 10-bit tables, are the same as on RAMPS).
//! Endstops: X- PB10, X+ PE15 (E0 socket), Y- PE12, Y+ PE10 (E1), Z- PG8,
//! Z+ PG5 (E2). Serial: USART1 on PA9 (TX) / PA10 (RX), the TFT header.
//!
//! The core drives four motors (X, Y, Z, E0); E1 and E2 are held disabled.
//! Every pin here is configuration: a machine that wires things otherwise
//! changes this file only.
//!
//! GPIO is reached through raw register addresses rather than the PAC's
//! per-port types (GPIOA, GPIOB and the rest are three different types
//! there): every port has the same layout, and a pin is (port, bit).
//! After [`init`] every change of level is one store to BSRR, which is
//! atomic: the interrupts and the main loop never race on a port.

use core::ptr::{read_volatile, write_volatile};

/// A GPIO port, by its register block's base address.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Port(usize);

impl Port {
    pub const A: Port = Port(0x4002_0000);
    pub const B: Port = Port(0x4002_0400);
    pub const C: Port = Port(0x4002_0800);
    pub const D: Port = Port(0x4002_0C00);
    pub const E: Port = Port(0x4002_1000);
    pub const F: Port = Port(0x4002_1400);
    pub const G: Port = Port(0x4002_1800);

    const MODER: usize = 0x00;
    const PUPDR: usize = 0x0C;
    const IDR: usize = 0x10;
    const BSRR: usize = 0x18;
    const AFRL: usize = 0x20;

    /// RCC_AHB1ENR bit of this port (GPIOA = bit 0, …).
    const fn clock_bit(self) -> u32 {
        ((self.0 - 0x4002_0000) / 0x400) as u32
    }

    fn register(self, offset: usize) -> *mut u32 {
        (self.0 + offset) as *mut u32
    }

    /// Input levels of all 16 pins.
    #[inline(always)]
    pub fn input(self) -> u32 {
        // SAFETY: IDR of an existing GPIO port; reading has no side effect.
        unsafe { read_volatile(self.register(Self::IDR)) }
    }

    /// One atomic store: bits 0–15 set pins, bits 16–31 reset them.
    #[inline(always)]
    pub fn bsrr(self, value: u32) {
        // SAFETY: BSRR of an existing GPIO port; the store is atomic.
        unsafe { write_volatile(self.register(Self::BSRR), value) }
    }

    /// Read-modify-write of a 2-bit-per-pin register. Only called during
    /// set-up, before any interrupt that touches this port is enabled.
    fn modify_field(self, offset: usize, bits_per_pin: u32, pin: u8, value: u32) {
        let shift = u32::from(pin % (32 / bits_per_pin as u8)) * bits_per_pin;
        let mask = ((1u32 << bits_per_pin) - 1) << shift;
        let register = self.register(offset + if bits_per_pin == 4 && pin >= 8 { 4 } else { 0 });
        // SAFETY: MODER/PUPDR/AFRx of an existing GPIO port; every value of
        // the field is defined.
        unsafe { write_volatile(register, (read_volatile(register) & !mask) | ((value << shift) & mask)) }
    }
}

/// One pin: port and bit (0–15).
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Pin {
    pub port: Port,
    pub bit: u8,
}

const fn pin(port: Port, bit: u8) -> Pin {
    Pin { port, bit }
}

impl Pin {
    #[inline(always)]
    pub fn set(self, high: bool) {
        self.port.bsrr(if high { 1 << self.bit } else { 1 << (self.bit + 16) });
    }

    pub fn is_high(self) -> bool {
        self.port.input() & (1 << self.bit) != 0
    }

    /// Push-pull output at `high`: the level is written before the mode so
    /// the pin never glitches to the other level.
    pub fn make_output(self, high: bool) {
        self.set(high);
        self.port.modify_field(Port::MODER, 2, self.bit, 0b01);
    }

    /// Input with the internal pull-up (endstops switch to ground; an open
    /// wire reads high).
    pub fn make_input_pulled_up(self) {
        self.port.modify_field(Port::MODER, 2, self.bit, 0b00);
        self.port.modify_field(Port::PUPDR, 2, self.bit, 0b01);
    }

    /// Analog mode (ADC input; the digital input is switched off).
    pub fn make_analog(self) {
        self.port.modify_field(Port::PUPDR, 2, self.bit, 0b00);
        self.port.modify_field(Port::MODER, 2, self.bit, 0b11);
    }

    /// Alternate function `af` (0–15), optionally with the pull-up.
    pub fn make_alternate(self, af: u32, pull_up: bool) {
        self.port.modify_field(Port::AFRL, 4, self.bit, af);
        self.port.modify_field(Port::PUPDR, 2, self.bit, if pull_up { 0b01 } else { 0b00 });
        self.port.modify_field(Port::MODER, 2, self.bit, 0b10);
    }
}

// --- steppers ---------------------------------------------------------------

/// STEP pins of the core's motors 0–3 (X, Y, Z, E0): all on port E, so one
/// BSRR store steps any set of them.
pub const STEP_PORT: Port = Port::E;
pub const STEP_BITS: [u8; 4] = [9, 11, 13, 14];
/// DIR pins of motors 0–3 (X, Y, Z, E0).
pub const DIRS: [Pin; 4] = [pin(Port::F, 1), pin(Port::E, 8), pin(Port::C, 2), pin(Port::A, 0)];
/// STEP pins of the sockets the core does not drive yet (E1, E2): held low.
pub const SPARE_STEPS: [Pin; 2] = [pin(Port::D, 15), pin(Port::D, 13)];
/// DIR pins of E1, E2.
pub const SPARE_DIRS: [Pin; 2] = [pin(Port::E, 7), pin(Port::G, 9)];
/// Driver enables of X, Y, Z, E0, E1, E2 (active low: high = disabled).
pub const STEPPER_ENABLES: [Pin; 6] =
    [pin(Port::F, 2), pin(Port::D, 7), pin(Port::C, 0), pin(Port::C, 3), pin(Port::A, 3), pin(Port::F, 0)];
/// E1 and E2 stay disabled: the core drives four motors.
const DRIVEN_ENABLES: usize = 4;

/// BSRR value that raises the STEP pins of `mask` (bit i: motor i), for
/// every mask: the step interrupt does one table load and one store.
pub const STEP_SET: [u32; 16] = {
    let mut table = [0u32; 16];
    let mut mask = 0;
    while mask < 16 {
        let mut motor = 0;
        while motor < 4 {
            if mask & (1 << motor) != 0 {
                table[mask] |= 1 << STEP_BITS[motor];
            }
            motor += 1;
        }
        mask += 1;
    }
    table
};
/// BSRR value that lowers every STEP pin of port E.
pub const STEP_RESET_ALL: u32 = STEP_SET[15] << 16;

// --- heaters, fans ------------------------------------------------------------

/// Hot end 0 (HE0).
pub const HOTEND: Pin = pin(Port::B, 1);
/// Heated bed (the board's MOSFET on PD12).
pub const BED: Pin = pin(Port::D, 12);
/// Part-cooling fan FAN0 (TIM3_CH3 on AF2 while the PWM runs).
pub const FAN: Pin = pin(Port::C, 8);
/// Every heater and fan gate (high = on): HE0, HE1, HE2, bed, FAN0–2.
pub const HEATER_OUTPUTS: [Pin; 7] =
    [HOTEND, pin(Port::D, 14), pin(Port::B, 0), BED, FAN, pin(Port::E, 5), pin(Port::E, 6)];

// --- sensors ------------------------------------------------------------------

/// ADC3 channel of the hot-end thermistor (T0 = PF4).
pub const HOTEND_THERMISTOR_CHANNEL: u8 = 14;
/// ADC3 channel of the bed thermistor (PF3).
pub const BED_THERMISTOR_CHANNEL: u8 = 9;
/// Thermistor inputs: PF3 (bed), PF4 (T0), PF5 (T1), PF6 (T2).
pub const THERMISTOR_PINS: [Pin; 4] = [pin(Port::F, 3), pin(Port::F, 4), pin(Port::F, 5), pin(Port::F, 6)];

/// Endstops in the core's bit order: X_MIN, X_MAX, Y_MIN, Y_MAX, Z_MIN, Z_MAX.
pub const ENDSTOPS: [Pin; 6] =
    [pin(Port::B, 10), pin(Port::E, 15), pin(Port::E, 12), pin(Port::E, 10), pin(Port::G, 8), pin(Port::G, 5)];

// --- serial ---------------------------------------------------------------------

pub const USART1_TX: Pin = pin(Port::A, 9);
pub const USART1_RX: Pin = pin(Port::A, 10);
/// USART1's alternate function number on PA9/PA10.
pub const USART1_AF: u32 = 7;

// --- set-up -------------------------------------------------------------------------

/// RCC_AHB1ENR: the GPIO ports' clocks must run before their registers
/// can be written.
const RCC_AHB1ENR: *mut u32 = 0x4002_3830 as *mut u32;

fn enable_port_clocks() {
    let ports = [Port::A, Port::B, Port::C, Port::D, Port::E, Port::F, Port::G];
    let bits = ports.iter().fold(0, |bits, port| bits | (1 << port.clock_bit()));
    // SAFETY: RCC_AHB1ENR; setting GPIO clock-enable bits only. Runs before
    // any interrupt is enabled (boot, panic with interrupts off).
    unsafe { write_volatile(RCC_AHB1ENR, read_volatile(RCC_AHB1ENR) | bits) };
    // The clock needs two AHB cycles before the port answers.
    cortex_m::asm::dsb();
}

/// Every output in its safe state and mode, every input configured.
/// The first thing the firmware does at boot.
pub fn init() {
    all_outputs_safe();
    for motor in 0..4 {
        STEP_PORT.bsrr(1 << (STEP_BITS[motor] + 16));
        pin(STEP_PORT, STEP_BITS[motor]).make_output(false);
        DIRS[motor].make_output(false);
    }
    for spare in SPARE_STEPS.iter().chain(SPARE_DIRS.iter()) {
        spare.make_output(false);
    }
    for endstop in ENDSTOPS {
        endstop.make_input_pulled_up();
    }
    for thermistor in THERMISTOR_PINS {
        thermistor.make_analog();
    }
}

/// The safe state: every heater and fan off, every stepper driver disabled.
/// Runs first at boot, from the receive interrupt on `M112`, and from the
/// panic handler. Safe to call from any context: after the first call it
/// changes levels with BSRR stores only (and mode bits that already hold
/// these values are rewritten with the same values at boot only).
pub fn all_outputs_safe() {
    // The fan and the heaters run on timer channels: a pin in
    // alternate-function mode ignores BSRR, so their compare values go to
    // 0 first, which holds each output low though it stays on the timer.
    crate::pwm::force_off();
    static CONFIGURED: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);
    if !CONFIGURED.swap(true, core::sync::atomic::Ordering::Relaxed) {
        enable_port_clocks();
        for heater in HEATER_OUTPUTS {
            heater.make_output(false);
        }
        for enable in STEPPER_ENABLES {
            enable.make_output(true);
        }
        return;
    }
    for heater in HEATER_OUTPUTS {
        if heater != FAN {
            heater.set(false);
        }
    }
    for enable in STEPPER_ENABLES {
        enable.set(true);
    }
}

/// Drive the enables of the motors the core drives (active low).
pub fn set_steppers_enabled(enabled: bool) {
    for enable in &STEPPER_ENABLES[..DRIVEN_ENABLES] {
        enable.set(!enabled);
    }
}

/// Endstop levels packed in the core's bit order.
pub fn endstop_levels() -> u8 {
    ENDSTOPS.iter().enumerate().fold(0, |bits, (i, pin)| bits | (u8::from(pin.is_high()) << i))
}
