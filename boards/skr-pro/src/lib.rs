//! Board support for the BigTreeTech SKR Pro 1.2 (STM32F407ZGT6,
//! Cortex-M4F at 168 MHz): pins, clocks, serial, ADC, PWM, watchdog, the
//! step timer and settings storage, each implementing what the `firmware`
//! core asks of a board. The binaries (`src/main.rs`, the firmware, and
//! `src/bin/step_bench.rs`) own the interrupt vectors and call the
//! handlers' bodies here, so every decision stays in the core.
//!
//! The same ELF also boots on QEMU's `netduinoplus2` (an STM32F405: the same
//! die without Ethernet/DCMI): see `clock` for how the missing RCC model is
//! recognised.
#![no_std]
#![deny(unsafe_op_in_unsafe_fn)]

pub mod adc;
pub mod clock;
pub mod pins;
pub mod pwm;
pub mod serial;
pub mod stepper;
pub mod storage;
pub mod watchdog;

pub use stm32f4::stm32f407 as pac;

/// Interrupt priorities (the F407 has 4 priority bits, in the top nibble;
/// lower is more urgent): steps are never delayed by serial input, and
/// the millisecond tick can wait a few microseconds.
pub mod priority {
    pub const STEP_TIMER: u8 = 0x00;
    pub const SERIAL: u8 = 0x40;
    pub const TICK: u8 = 0x80;
}
