//! The ATmega2560's 4 KiB EEPROM as the core's non-volatile storage.
//!
//! A byte write takes ≈3.4 ms (the core writes only bytes that changed);
//! reads are immediate. QEMU's AVR machine has no EEPROM: there the image
//! reads back blank and the defaults apply, as on a new board.

use avr_device::atmega2560::EEPROM;
use firmware::storage::NonVolatile;

/// Bounded wait for a previous write (a write needs ≈ 54 000 cycles; each
/// poll is a few cycles, so this is several times the worst case).
const MAX_POLLS: u32 = 200_000;

pub struct Eeprom {
    registers: EEPROM,
}

impl Eeprom {
    pub fn new(registers: EEPROM) -> Self {
        Self { registers }
    }

    /// Wait until no write is in progress (bounded: a missing EEPROM
    /// must not hang the firmware).
    fn wait_ready(&self) {
        for _ in 0..MAX_POLLS {
            if self.registers.eecr.read().eepe().bit_is_clear() {
                return;
            }
        }
    }
}

impl NonVolatile for Eeprom {
    fn capacity(&self) -> usize {
        4096
    }

    fn read(&mut self, address: usize) -> u8 {
        self.wait_ready();
        self.registers.eear.write(|w| w.bits(address as u16));
        self.registers.eecr.write(|w| w.eere().set_bit());
        self.registers.eedr.read().bits()
    }

    fn write(&mut self, address: usize, value: u8) {
        self.wait_ready();
        self.registers.eear.write(|w| w.bits(address as u16));
        self.registers.eedr.write(|w| w.bits(value));
        // EEMPE then EEPE within four cycles, with no interrupt between.
        avr_device::interrupt::free(|_| {
            self.registers.eecr.write(|w| w.eempe().set_bit());
            self.registers.eecr.write(|w| w.eempe().set_bit().eepe().set_bit());
        });
        super::watchdog::feed();
    }
}
