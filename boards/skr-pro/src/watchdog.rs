//! The independent watchdog (IWDG): resets a firmware that stops running
//! its main loop. It runs from the ≈32 kHz LSI, which nothing can stop;
//! once started it cannot be stopped either (the panic handler feeds it
//! while it waits with every output off, as the Mega 2560 stops its own).
//! QEMU's netduinoplus2 does not model the IWDG: there it never bites.

use stm32f4::stm32f407 as pac;

/// Prescaler /64 (PR = 4): 500 Hz at the nominal 32 kHz LSI; reload 1000:
/// 2 s nominal (1.4–3.8 s over the LSI's 17–47 kHz spread).
const PRESCALER_DIV64: u16 = 4;
const RELOAD: u16 = 1000;

const KEY_UNLOCK: u16 = 0x5555;
const KEY_FEED: u16 = 0xAAAA;
const KEY_START: u16 = 0xCCCC;

pub fn start(iwdg: &pac::IWDG) {
    // SAFETY (all `bits`): documented keys and field values.
    iwdg.kr().write(|w| unsafe { w.bits(KEY_UNLOCK) });
    iwdg.pr().write(|w| unsafe { w.bits(PRESCALER_DIV64) });
    iwdg.rlr().write(|w| unsafe { w.bits(RELOAD) });
    iwdg.kr().write(|w| unsafe { w.bits(KEY_START) });
    iwdg.kr().write(|w| unsafe { w.bits(KEY_FEED) });
}

/// Reset the watchdog's count; called once per main-loop pass.
pub fn feed() {
    // SAFETY: KR is write-only; the feed key has no other effect.
    unsafe { (*pac::IWDG::ptr()).kr().write(|w| w.bits(KEY_FEED)) };
}
