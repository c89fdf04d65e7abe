//! Settings storage for boards whose only non-volatile memory is flash
//! (the SKR Pro's STM32F407): a [`NonVolatile`] of `N` bytes kept in RAM
//! and written, on [`commit`](NonVolatile::commit), to the next blank page
//! of one flash sector.
//!
//! # Why pages, and the invariants
//!
//! Flash programs only 1 → 0 and erases a whole sector at once (128 KiB
//! on the F407, ≈ 1–2 s during which the CPU cannot fetch from flash). So a
//! save never rewrites a page: it appends. The sector is cut into pages of
//! `N` bytes plus a 4-byte commit word:
//!
//! ```text
//! page k at k·(N + 4):  [ N bytes of image ][ COMMITTED ]
//! ```
//!
//! - A page is *committed* when its commit word reads [`COMMITTED`]; the
//!   word is programmed last, so a page cut short by a power loss is never
//!   taken for the image (its word still reads erased, or garbage).
//! - Pages are used in order: the newest image is the committed page with
//!   the highest index; the next save goes to the first page after the last
//!   one that is not blank (a torn page is skipped, never reused).
//! - Only when no blank page is left is the sector erased (once every
//!   `SIZE / (N + 4)` saves: 334 in the F407's 128 KiB sector with `N` = 384), and the image
//!   written to page 0 at once. A power loss in that window loses the
//!   stored settings (the board then boots with its defaults and says so);
//!   the core's two-slot image (`storage`) still guards every other moment.
//! - After programming, the page is read back: flash that did not take the
//!   write (worn, or an emulator without a flash controller) is reported
//!   (`commit` → false, `M500` answers `Error:`), and that page is skipped.

use crate::storage::NonVolatile;

/// The commit word: mixed bits, so neither erased flash (all ones) nor a
/// zeroed region reads as committed.
pub const COMMITTED: u32 = 0x5AFE_C0DE;

/// One erasable flash sector, byte-addressed from its start.
pub trait FlashSector {
    /// Bytes in the sector.
    fn size(&self) -> usize;
    fn read(&self, offset: usize) -> u8;
    /// Program `bytes` at `offset` (4-aligned, a multiple of 4 long) into
    /// erased flash. True when the hardware reported no error.
    fn program(&mut self, offset: usize, bytes: &[u8]) -> bool;
    /// Erase the whole sector to 0xFF. True when the hardware reported no
    /// error.
    fn erase(&mut self) -> bool;
}

/// `N` bytes of settings storage over a flash sector (`N` a multiple of 4).
pub struct PagedStore<F: FlashSector, const N: usize> {
    flash: F,
    mirror: [u8; N],
    /// Where the next save goes (page index).
    next_page: usize,
    dirty: bool,
}

impl<F: FlashSector, const N: usize> PagedStore<F, N> {
    const PAGE: usize = N + 4;

    /// Read the newest committed image into RAM (blank if none).
    pub fn open(flash: F) -> Self {
        assert!(N.is_multiple_of(4), "the image is programmed in words");
        let mut store = Self { flash, mirror: [0xFF; N], next_page: 0, dirty: false };
        let pages = store.pages();
        let mut newest = None;
        for page in 0..pages {
            if store.committed(page) {
                newest = Some(page);
            }
            if !store.blank(page) {
                store.next_page = page + 1;
            }
        }
        if let Some(page) = newest {
            let base = page * Self::PAGE;
            for (index, byte) in store.mirror.iter_mut().enumerate() {
                *byte = store.flash.read(base + index);
            }
        }
        store
    }

    fn pages(&self) -> usize {
        self.flash.size() / Self::PAGE
    }

    fn commit_word(&self, page: usize) -> u32 {
        let at = page * Self::PAGE + N;
        u32::from_le_bytes([self.flash.read(at), self.flash.read(at + 1), self.flash.read(at + 2), self.flash.read(at + 3)])
    }

    fn committed(&self, page: usize) -> bool {
        self.commit_word(page) == COMMITTED
    }

    fn blank(&self, page: usize) -> bool {
        let base = page * Self::PAGE;
        (base..base + Self::PAGE).all(|at| self.flash.read(at) == 0xFF)
    }

    /// The page the next commit writes (for reports and tests).
    pub fn next_page(&self) -> usize {
        self.next_page
    }

    /// The flash underneath (tests inspect it).
    pub fn flash(&self) -> &F {
        &self.flash
    }

    /// Program the mirror and then the commit word into `page`; read back.
    fn write_page(&mut self, page: usize) -> bool {
        let base = page * Self::PAGE;
        let programmed = self.flash.program(base, &self.mirror) && self.flash.program(base + N, &COMMITTED.to_le_bytes());
        programmed && self.committed(page) && (0..N).all(|index| self.flash.read(base + index) == self.mirror[index])
    }
}

impl<F: FlashSector, const N: usize> NonVolatile for PagedStore<F, N> {
    fn capacity(&self) -> usize {
        N
    }

    fn read(&mut self, address: usize) -> u8 {
        self.mirror.get(address).copied().unwrap_or(0xFF)
    }

    fn write(&mut self, address: usize, value: u8) {
        if let Some(byte) = self.mirror.get_mut(address) {
            if *byte != value {
                *byte = value;
                self.dirty = true;
            }
        }
    }

    fn commit(&mut self) -> bool {
        if !self.dirty {
            return true;
        }
        if self.next_page >= self.pages() {
            if !self.flash.erase() {
                return false;
            }
            self.next_page = 0;
        }
        let page = self.next_page;
        // Used whether or not it took the write: a page is never reused.
        self.next_page += 1;
        let written = self.write_page(page);
        self.dirty = !written;
        written
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::Settings;
    use crate::storage::{self, SaveError};

    /// Flash as the hardware behaves: programming only clears bits, an
    /// erase sets the whole sector; counts erases. `broken`: programming
    /// does nothing (QEMU's ROM).
    struct FakeFlash {
        bytes: std::vec::Vec<u8>,
        erases: usize,
        broken: bool,
    }

    impl FakeFlash {
        fn new(size: usize) -> Self {
            Self { bytes: std::vec![0xFF; size], erases: 0, broken: false }
        }
    }

    impl FlashSector for FakeFlash {
        fn size(&self) -> usize {
            self.bytes.len()
        }
        fn read(&self, offset: usize) -> u8 {
            self.bytes[offset]
        }
        fn program(&mut self, offset: usize, bytes: &[u8]) -> bool {
            assert!(offset.is_multiple_of(4) && bytes.len().is_multiple_of(4), "word programming");
            if !self.broken {
                for (cell, byte) in self.bytes[offset..offset + bytes.len()].iter_mut().zip(bytes) {
                    *cell &= *byte;
                }
            }
            true
        }
        fn erase(&mut self) -> bool {
            self.bytes.fill(0xFF);
            self.erases += 1;
            true
        }
    }

    type Store = PagedStore<FakeFlash, 384>;

    fn custom_settings(x: i32) -> Settings {
        let mut settings = Settings::default();
        settings.steps_per_mm_milli[0] = x;
        settings
    }

    #[test]
    fn saved_settings_survive_a_reopen_of_the_sector() {
        let mut store = Store::open(FakeFlash::new(16 * 388));
        storage::save(&mut store, &custom_settings(12_345)).unwrap();
        let mut reopened = Store::open(store.flash);
        let (loaded, _) = storage::load(&mut reopened).unwrap();
        assert_eq!(loaded, custom_settings(12_345));
        assert_eq!(reopened.next_page(), 1);
    }

    #[test]
    fn each_save_appends_a_page_and_the_newest_wins() {
        let mut store = Store::open(FakeFlash::new(16 * 388));
        for x in 1..=3 {
            storage::save(&mut store, &custom_settings(x * 1000)).unwrap();
        }
        assert_eq!(store.next_page(), 3);
        let mut reopened = Store::open(store.flash);
        assert_eq!(storage::load(&mut reopened).unwrap().0, custom_settings(3000));
    }

    #[test]
    fn a_save_with_nothing_changed_writes_no_page() {
        let mut store = Store::open(FakeFlash::new(16 * 388));
        storage::save(&mut store, &custom_settings(7)).unwrap();
        let page = store.next_page();
        assert!(store.commit());
        assert_eq!(store.next_page(), page);
    }

    #[test]
    fn a_full_sector_is_erased_once_and_writing_starts_over() {
        let mut store = Store::open(FakeFlash::new(4 * 388));
        for x in 1..=5 {
            storage::save(&mut store, &custom_settings(x)).unwrap();
        }
        assert_eq!(store.flash().erases, 1);
        assert_eq!(store.next_page(), 1);
        let mut reopened = Store::open(store.flash);
        assert_eq!(storage::load(&mut reopened).unwrap().0, custom_settings(5));
    }

    /// Power lost after the image but before its commit word: the page is
    /// not taken, the previous image loads, and the next save goes after it.
    #[test]
    fn a_torn_page_is_skipped_and_the_previous_image_loads() {
        let mut store = Store::open(FakeFlash::new(16 * 388));
        storage::save(&mut store, &custom_settings(1)).unwrap();
        let mut flash = store.flash;
        // Page 1 got half an image and no commit word.
        for byte in &mut flash.bytes[388..388 + 100] {
            *byte = 0x12;
        }
        let mut reopened = Store::open(flash);
        assert_eq!(storage::load(&mut reopened).unwrap().0, custom_settings(1));
        assert_eq!(reopened.next_page(), 2);
        storage::save(&mut reopened, &custom_settings(2)).unwrap();
        let mut again = Store::open(reopened.flash);
        assert_eq!(storage::load(&mut again).unwrap().0, custom_settings(2));
    }

    /// Zeroed flash (an emulator's ROM) holds no image and is not taken
    /// for one.
    #[test]
    fn zeroed_flash_holds_no_image() {
        let mut flash = FakeFlash::new(4 * 388);
        flash.bytes.fill(0);
        let mut store = Store::open(flash);
        assert_eq!(storage::load(&mut store).map(|_| ()), Err(storage::LoadError::NoImage));
    }

    /// Flash that does not take the write is reported, not believed.
    #[test]
    fn flash_that_does_not_program_fails_the_save() {
        let mut flash = FakeFlash::new(4 * 388);
        flash.broken = true;
        let mut store = Store::open(flash);
        assert_eq!(storage::save(&mut store, &custom_settings(3)).map(|_| ()), Err(SaveError::WriteFailed));
    }
}
