//! Hardware PWM for the part-cooling fan: TIM3 channel 3 on PC8 (AF2).
//!
//! TIM3 runs from APB1's 84 MHz timer clock: prescaler 330, period 255
//! counts (ARR 254) → 998 Hz, duty in the core's 0–255 steps directly
//! (255 is above ARR: always on). The compare preload is off, so a new duty,
//! and [`force_off`]'s 0, act at once.

use stm32f4::stm32f407 as pac;

/// RCC_APB1ENR: TIM3EN.
const TIM3EN: u32 = 1 << 1;
const PRESCALER: u32 = 329;
const TOP: u32 = 254;
/// CCMR2: OC3M = 110 (PWM mode 1), OC3PE = 0, CC3S = 00 (output).
const OC3_PWM1: u32 = 0b110 << 4;
/// CCER: CC3E.
const CC3E: u32 = 1 << 8;
/// CR1: CEN. EGR: UG.
const CEN: u32 = 1;
const UG: u32 = 1;
/// TIM3's alternate function number on PC8.
const TIM3_AF: u32 = 2;

pub fn init(rcc: &pac::RCC, timer: &pac::TIM3) {
    // SAFETY (all `bits`): documented field values.
    rcc.apb1enr().modify(|r, w| unsafe { w.bits(r.bits() | TIM3EN) });
    cortex_m::asm::dsb();
    timer.psc().write(|w| unsafe { w.bits(PRESCALER) });
    timer.arr().write(|w| unsafe { w.bits(TOP) });
    timer.ccr3().write(|w| unsafe { w.bits(0) });
    timer.ccmr2_output().write(|w| unsafe { w.bits(OC3_PWM1) });
    timer.ccer().write(|w| unsafe { w.bits(CC3E) });
    timer.egr().write(|w| unsafe { w.bits(UG) });
    timer.cr1().write(|w| unsafe { w.bits(CEN) });
    crate::pins::FAN.make_alternate(TIM3_AF, false);
}

/// Fan duty, 0–255.
pub fn set_fan(duty: u8) {
    // SAFETY: CCR3 of TIM3; one store, any value is valid.
    unsafe { (*pac::TIM3::ptr()).ccr3().write(|w| w.bits(u32::from(duty))) };
}

/// Fan output low now (one store: callable from any interrupt).
pub fn force_off() {
    set_fan(0);
}
