//! Settings storage: RAM for now (documented in the README).
//!
//! The F407 has no EEPROM. The durable choice is a flash sector (Marlin
//! uses the last 128 KiB sector, 0x080E0000): programming bytes is quick,
//! but erasing the sector takes 1–2 s during which the single flash bank
//! stalls every instruction fetch, interrupts included. Doing that
//! safely (step timer and serial reception stopped, watchdog window) is
//! its own piece of work; until then settings live in RAM: `M500` keeps
//! them until the next reset, and every boot reports "No stored settings"
//! and starts from the defaults, like a new board.

use firmware::storage::NonVolatile;

/// Bytes kept: as much as the Mega 2560's EEPROM.
pub const CAPACITY: usize = 4096;

pub struct RamStorage {
    bytes: [u8; CAPACITY],
}

impl RamStorage {
    /// Blank, as erased memory reads (0xFF).
    pub const fn new() -> Self {
        Self { bytes: [0xFF; CAPACITY] }
    }
}

impl Default for RamStorage {
    fn default() -> Self {
        Self::new()
    }
}

impl NonVolatile for RamStorage {
    fn capacity(&self) -> usize {
        CAPACITY
    }

    fn read(&mut self, address: usize) -> u8 {
        self.bytes.get(address).copied().unwrap_or(0xFF)
    }

    fn write(&mut self, address: usize, value: u8) {
        if let Some(byte) = self.bytes.get_mut(address) {
            *byte = value;
        }
    }
}
