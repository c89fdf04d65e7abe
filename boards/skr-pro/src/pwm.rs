//! Hardware PWM for the heaters and the part-cooling fan, all at ≈ 1 kHz
//! (MOSFET outputs):
//!
//! | output | pin | timer channel (AF2) |
//! |---|---|---|
//! | hot end HE0 | PB1 | TIM3_CH4 |
//! | fan FAN0 | PC8 | TIM3_CH3 |
//! | bed | PD12 | TIM4_CH1 |
//!
//! TIM3 and TIM4 run from APB1's 84 MHz timer clock: prescaler 330, period
//! 255 counts (ARR 254) → 998 Hz, duty in the core's 0–255 steps directly
//! (255 is above ARR: always on). The compare preload is off, so a new
//! duty, and [`force_off`]'s 0, act at once: with a compare value of 0 the
//! output is low for good (PWM mode 1), which is how the safe state turns
//! these alternate-function pins off.

use stm32f4::stm32f407 as pac;

/// RCC_APB1ENR: TIM3EN, TIM4EN.
const TIM3EN: u32 = 1 << 1;
const TIM4EN: u32 = 1 << 2;
const PRESCALER: u32 = 329;
const TOP: u32 = 254;
/// CCMRx: OCxM = 110 (PWM mode 1), preload off, output; channel 1/3 in
/// the low byte, 2/4 in the high byte.
const PWM1_LOW: u32 = 0b110 << 4;
const PWM1_HIGH: u32 = 0b110 << 12;
/// CCER: CC1E, CC3E, CC4E.
const CC1E: u32 = 1 << 0;
const CC3E: u32 = 1 << 8;
const CC4E: u32 = 1 << 12;
/// CR1: CEN. EGR: UG.
const CEN: u32 = 1;
const UG: u32 = 1;
/// TIM3/TIM4 alternate function number.
const AF_TIM3_4: u32 = 2;

pub fn init(rcc: &pac::RCC, tim3: &pac::TIM3, tim4: &pac::TIM4) {
    // SAFETY (all `bits`): documented field values.
    rcc.apb1enr().modify(|r, w| unsafe { w.bits(r.bits() | TIM3EN | TIM4EN) });
    cortex_m::asm::dsb();
    tim3.psc().write(|w| unsafe { w.bits(PRESCALER) });
    tim3.arr().write(|w| unsafe { w.bits(TOP) });
    tim3.ccr3().write(|w| unsafe { w.bits(0) });
    tim3.ccr4().write(|w| unsafe { w.bits(0) });
    tim3.ccmr2_output().write(|w| unsafe { w.bits(PWM1_LOW | PWM1_HIGH) });
    tim3.ccer().write(|w| unsafe { w.bits(CC3E | CC4E) });
    tim3.egr().write(|w| unsafe { w.bits(UG) });
    tim3.cr1().write(|w| unsafe { w.bits(CEN) });
    tim4.psc().write(|w| unsafe { w.bits(PRESCALER) });
    tim4.arr().write(|w| unsafe { w.bits(TOP) });
    tim4.ccr1().write(|w| unsafe { w.bits(0) });
    tim4.ccmr1_output().write(|w| unsafe { w.bits(PWM1_LOW) });
    tim4.ccer().write(|w| unsafe { w.bits(CC1E) });
    tim4.egr().write(|w| unsafe { w.bits(UG) });
    tim4.cr1().write(|w| unsafe { w.bits(CEN) });
    crate::pins::FAN.make_alternate(AF_TIM3_4, false);
    crate::pins::HOTEND.make_alternate(AF_TIM3_4, false);
    crate::pins::BED.make_alternate(AF_TIM3_4, false);
}

/// Fan duty, 0–255.
pub fn set_fan(duty: u8) {
    // SAFETY: CCR3 of TIM3; one store, any value is valid.
    unsafe { (*pac::TIM3::ptr()).ccr3().write(|w| w.bits(u32::from(duty))) };
}

/// Hot end (HE0) duty, 0–255.
pub fn set_hotend(duty: u8) {
    // SAFETY: CCR4 of TIM3; one store, any value is valid.
    unsafe { (*pac::TIM3::ptr()).ccr4().write(|w| w.bits(u32::from(duty))) };
}

/// Bed duty, 0–255.
pub fn set_bed(duty: u8) {
    // SAFETY: CCR1 of TIM4; one store, any value is valid.
    unsafe { (*pac::TIM4::ptr()).ccr1().write(|w| w.bits(u32::from(duty))) };
}

/// Every PWM output low now (three stores: callable from any interrupt
/// and from the panic handler).
pub fn force_off() {
    set_fan(0);
    set_hotend(0);
    set_bed(0);
}
