//! Settings storage in the F407's last flash sector (sector 11, 128 KiB at
//! 0x080E0000, where Marlin keeps its emulated EEPROM too). `memory.x` ends
//! the program's flash before it.
//!
//! The core's [`PagedStore`] does the bookkeeping (an image in RAM, each
//! `M500` appended to the next blank page, the sector erased only when it
//! is full: once every 504 saves); this file is the register work:
//! unlock, program words (PSIZE ×32, 2.7–3.6 V), erase, lock, and the
//! data cache flushed so a read-back sees the flash, not the cache.
//!
//! While the flash programs or erases, every instruction fetch from it
//! stalls, interrupt handlers included: ≈ 16 µs per word (≈ 1 ms for a
//! page), ≈ 1–2 s for the erase. The watchdog (≈ 2 s) is fed right before
//! the erase. Heater PWM keeps its last duty through the stall (timers run
//! on), the step interrupt is late: save settings while the machine is
//! idle, as with Marlin.
//!
//! QEMU's netduinoplus2 has no flash controller (its flash is ROM, the
//! registers read 0): the read-back finds nothing written, so `M500`
//! answers `Error:Settings not stored: …` there, and every boot loads the
//! defaults.

use crate::watchdog;
use firmware::flash_pages::{FlashSector, PagedStore};
use stm32f4::stm32f407 as pac;

/// Bytes of settings image (the core's two slots need 290).
pub const CAPACITY: usize = 384;

/// The settings store the main loop hands to the core.
pub type SettingsStore = PagedStore<Sector11, CAPACITY>;

/// Open the store: reads the newest saved image.
pub fn open() -> SettingsStore {
    PagedStore::open(Sector11)
}

const SECTOR_START: usize = 0x080E_0000;
const SECTOR_SIZE: usize = 128 * 1024;
const SECTOR_NUMBER: u32 = 11;

const KEY1: u32 = 0x4567_0123;
const KEY2: u32 = 0xCDEF_89AB;
// FLASH_SR
const SR_BSY: u32 = 1 << 16;
/// EOP, OPERR, WRPERR, PGAERR, PGPERR, PGSERR (write 1 to clear).
const SR_FLAGS: u32 = 0b1111_0011;
const SR_ERRORS: u32 = 0b1111_0010;
// FLASH_CR
const CR_PG: u32 = 1 << 0;
const CR_SER: u32 = 1 << 1;
const CR_SNB_SHIFT: u32 = 3;
const CR_PSIZE_X32: u32 = 0b10 << 8;
const CR_STRT: u32 = 1 << 16;
const CR_LOCK: u32 = 1 << 31;
// FLASH_ACR
const ACR_DCEN: u32 = 1 << 10;
const ACR_DCRST: u32 = 1 << 12;

/// The F407's sector 11.
pub struct Sector11;

fn flash() -> &'static pac::flash::RegisterBlock {
    // SAFETY: the flash interface is used by this driver only (the clock
    // set-up wrote ACR's latency once, before).
    unsafe { &*pac::FLASH::ptr() }
}

fn wait_idle(flash: &pac::flash::RegisterBlock) {
    while flash.sr().read().bits() & SR_BSY != 0 {}
}

/// Unlock, run `operation` with CR set to `cr`, lock; true without errors.
fn with_unlocked(cr: u32, operation: impl FnOnce()) -> bool {
    let flash = flash();
    wait_idle(flash);
    if flash.cr().read().bits() & CR_LOCK != 0 {
        // SAFETY (all `bits` below): the documented key sequence and field
        // values of RM0090 §3.6.
        flash.keyr().write(|w| unsafe { w.bits(KEY1) });
        flash.keyr().write(|w| unsafe { w.bits(KEY2) });
    }
    flash.sr().write(|w| unsafe { w.bits(SR_FLAGS) });
    flash.cr().write(|w| unsafe { w.bits(cr) });
    operation();
    wait_idle(flash);
    let errors = flash.sr().read().bits() & SR_ERRORS;
    flash.cr().write(|w| unsafe { w.bits(CR_LOCK) });
    flush_data_cache(flash);
    errors == 0
}

/// Reset the ART data cache so reads see the flash as it now is.
fn flush_data_cache(flash: &pac::flash::RegisterBlock) {
    let acr = flash.acr().read().bits();
    // SAFETY: DCEN/DCRST only; latency and the other enables kept.
    flash.acr().write(|w| unsafe { w.bits(acr & !ACR_DCEN) });
    flash.acr().write(|w| unsafe { w.bits((acr & !ACR_DCEN) | ACR_DCRST) });
    flash.acr().write(|w| unsafe { w.bits(acr & !ACR_DCRST) });
}

impl FlashSector for Sector11 {
    fn size(&self) -> usize {
        SECTOR_SIZE
    }

    fn read(&self, offset: usize) -> u8 {
        if offset >= SECTOR_SIZE {
            return 0xFF;
        }
        // SAFETY: inside sector 11, which the program never occupies.
        unsafe { core::ptr::read_volatile((SECTOR_START + offset) as *const u8) }
    }

    fn program(&mut self, offset: usize, bytes: &[u8]) -> bool {
        if offset % 4 != 0 || bytes.len() % 4 != 0 || offset + bytes.len() > SECTOR_SIZE {
            return false;
        }
        with_unlocked(CR_PSIZE_X32 | CR_PG, || {
            for (index, word) in bytes.chunks_exact(4).enumerate() {
                let word = u32::from_le_bytes([word[0], word[1], word[2], word[3]]);
                let address = (SECTOR_START + offset + 4 * index) as *mut u32;
                // SAFETY: a word-aligned address in sector 11 with PG set:
                // the write programs it (RM0090 §3.6.4).
                unsafe { core::ptr::write_volatile(address, word) };
                wait_idle(flash());
            }
        })
    }

    fn erase(&mut self) -> bool {
        watchdog::feed();
        let cr = CR_PSIZE_X32 | CR_SER | (SECTOR_NUMBER << CR_SNB_SHIFT);
        let erased = with_unlocked(cr, || {
            // SAFETY: STRT starts the sector erase set up above.
            flash().cr().write(|w| unsafe { w.bits(cr | CR_STRT) });
            wait_idle(flash());
        });
        watchdog::feed();
        erased
    }
}
