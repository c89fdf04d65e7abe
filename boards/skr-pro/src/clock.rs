//! Clocks: 168 MHz from the board's 8 MHz crystal, and a 1 kHz tick.
//!
//! HSE 8 MHz / PLLM 4 = 2 MHz → ×PLLN 168 = 336 MHz VCO → /PLLP 2 = 168 MHz
//! SYSCLK (/PLLQ 7 = 48 MHz for USB). AHB 168 MHz, APB1 42 MHz (its timers
//! 84 MHz), APB2 84 MHz (its timers 168 MHz). Flash: 5 wait states with
//! prefetch and both caches (the ART accelerator), as RM0090 requires at
//! 168 MHz and 3.3 V.
//!
//! Every wait on a ready bit is bounded: a dead crystal falls back to the
//! internal 16 MHz RC through the PLL (same 168 MHz), a PLL that never
//! locks leaves the chip on the 16 MHz RC, and [`Clocks`] says which, so
//! baud rates and the tick stay right in every case.
//!
//! QEMU's netduinoplus2 has no RCC model: its RCC registers read 0, which
//! no silicon does (HSION and HSIRDY are 1 from reset until software turns
//! the RC off). Then the emulator's fixed 168 MHz is taken as the clock.

use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use stm32f4::stm32f407 as pac;

/// The clock tree the firmware runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Clocks {
    /// Core clock (SysTick, DWT cycle counter).
    pub sysclk_hz: u32,
    /// Peripheral clock of APB2 (USART1, ADC).
    pub apb2_hz: u32,
    /// Timer clock of APB1's timers (TIM2–TIM5).
    pub apb1_timer_hz: u32,
    /// Where the clock came from.
    pub source: ClockSource,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockSource {
    /// The 8 MHz crystal through the PLL (the normal case).
    Crystal,
    /// The crystal did not start: the internal RC through the PLL.
    InternalRcPll,
    /// The PLL did not lock: the internal 16 MHz RC directly.
    InternalRc,
    /// No RCC at all (QEMU): the emulator's fixed 168 MHz.
    Emulated,
}

const SYSCLK_HZ: u32 = 168_000_000;
const HSE_HZ: u32 = 8_000_000;
const HSI_HZ: u32 = 16_000_000;
/// Polls of a ready bit before giving up. HSE start-up is ≤ 2 ms (the
/// crystal's datasheet); a poll is a few cycles at 16 MHz: this is ≥ 20 ms.
const READY_POLLS: u32 = 100_000;

// RCC_CR bits.
const HSERDY: u32 = 1 << 17;
const HSEON: u32 = 1 << 16;
const PLLON: u32 = 1 << 24;
const PLLRDY: u32 = 1 << 25;
// RCC_CFGR fields.
const SW_PLL: u32 = 0b10;
const SWS_MASK: u32 = 0b11 << 2;
const SWS_PLL: u32 = 0b10 << 2;
const HPRE_DIV1: u32 = 0 << 4;
const PPRE1_DIV4: u32 = 0b101 << 10;
const PPRE2_DIV2: u32 = 0b100 << 13;
// FLASH_ACR: LATENCY 5, PRFTEN, ICEN, DCEN.
const FLASH_ACR_168MHZ: u32 = 5 | (1 << 8) | (1 << 9) | (1 << 10);

fn wait_for(mut ready: impl FnMut() -> bool) -> bool {
    (0..READY_POLLS).any(|_| ready())
}

/// Switch to 168 MHz (or the best fallback) and report the result.
pub fn init(rcc: &pac::RCC, flash: &pac::FLASH) -> Clocks {
    let emulated = Clocks {
        sysclk_hz: SYSCLK_HZ,
        apb2_hz: SYSCLK_HZ / 2,
        apb1_timer_hz: SYSCLK_HZ / 2,
        source: ClockSource::Emulated,
    };
    if rcc.cr().read().bits() == 0 {
        return emulated;
    }
    let on_rc = Clocks { sysclk_hz: HSI_HZ, apb2_hz: HSI_HZ, apb1_timer_hz: HSI_HZ, source: ClockSource::InternalRc };

    // SAFETY (every `bits` below): documented RCC/FLASH field values.
    rcc.cr().modify(|r, w| unsafe { w.bits(r.bits() | HSEON) });
    let crystal = wait_for(|| rcc.cr().read().bits() & HSERDY != 0);
    let (pll_input_hz, pllsrc_hse) = if crystal { (HSE_HZ, 1) } else { (HSI_HZ, 0) };
    if !crystal {
        rcc.cr().modify(|r, w| unsafe { w.bits(r.bits() & !HSEON) });
    }
    // VCO input 2 MHz: PLLM = input / 2 MHz.
    let pllm = pll_input_hz / 2_000_000;
    let plln = 168;
    let pllp_div2 = 0b00;
    let pllq = 7;
    rcc.pllcfgr()
        .write(|w| unsafe { w.bits(pllm | (plln << 6) | (pllp_div2 << 16) | (pllsrc_hse << 22) | (pllq << 24)) });
    rcc.cr().modify(|r, w| unsafe { w.bits(r.bits() | PLLON) });
    if !wait_for(|| rcc.cr().read().bits() & PLLRDY != 0) {
        return on_rc;
    }
    // Slow the flash down before the clock goes up.
    flash.acr().write(|w| unsafe { w.bits(FLASH_ACR_168MHZ) });
    // RM0090 §3.5.1: the new latency must read back before the switch.
    if !wait_for(|| flash.acr().read().bits() & 0b111 == FLASH_ACR_168MHZ & 0b111) {
        return on_rc;
    }
    rcc.cfgr().write(|w| unsafe { w.bits(HPRE_DIV1 | PPRE1_DIV4 | PPRE2_DIV2) });
    rcc.cfgr().modify(|r, w| unsafe { w.bits(r.bits() | SW_PLL) });
    if !wait_for(|| rcc.cfgr().read().bits() & SWS_MASK == SWS_PLL) {
        return on_rc;
    }
    Clocks {
        sysclk_hz: SYSCLK_HZ,
        apb2_hz: SYSCLK_HZ / 2,
        apb1_timer_hz: SYSCLK_HZ / 2,
        source: if crystal { ClockSource::Crystal } else { ClockSource::InternalRcPll },
    }
}

static MILLIS: AtomicU32 = AtomicU32::new(0);

/// SysTick at 1 kHz from the core clock.
pub fn start_tick(syst: &mut SYST, clocks: &Clocks) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(clocks.sysclk_hz / 1000 - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Milliseconds since boot (wraps after 49 days).
pub fn millis() -> u32 {
    MILLIS.load(Ordering::Relaxed)
}

/// The SysTick exception's body: one more millisecond. Only this handler
/// writes the count, so a load and a store are enough.
#[inline(always)]
pub fn on_tick() {
    MILLIS.store(MILLIS.load(Ordering::Relaxed).wrapping_add(1), Ordering::Relaxed);
}
