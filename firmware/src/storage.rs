//! Persistent settings: `M500` saves, `M501` loads, at boot they load.
//!
//! The image is kept twice, in two slots, and a save always writes the slot
//! that does not hold the newest image: payload first, then the header
//! whose CRC covers both. A power loss during a save leaves a slot whose
//! CRC does not match, and the other slot still holds the previous
//! settings: after any interruption the next boot loads either the old or
//! the new settings, never a mix.
//!
//! Slot layout (little endian):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 2 | magic `0xF5E7` |
//! | 2 | 1 | layout version ([`LAYOUT_VERSION`]) |
//! | 3 | 2 | sequence number (the newer slot has the higher, wrapping) |
//! | 5 | 2 | payload length |
//! | 7 | 2 | CRC-16/CCITT of bytes 0–6, 9–12 and the payload |
//! | 9 | 4 | the machine file's fingerprint ([`crate::machine_file::FINGERPRINT`]) |
//! | 13 | n | payload ([`Settings`]' slots in declaration order, `i32` each) |
//!
//! An image with another magic, version or length, or a wrong CRC, is
//! refused whole and reported; the defaults stay in force. So is an image
//! saved by a firmware built for another machine file (its steps/mm and
//! gains would be another machine's): never half-loaded.
//!
//! EEPROM wears out (≈100 000 writes per cell): only bytes that differ are
//! written.

use crate::settings::Settings;

/// Bump whenever the payload layout changes: older images are then refused.
pub const LAYOUT_VERSION: u8 = 3;
const MAGIC: u16 = 0xF5E7;
const HEADER_LEN: usize = 13;
/// Payload: the `i32` slots of [`Settings`] (33 in layout 3).
pub const PAYLOAD_LEN: usize = crate::settings::SLOTS * 4;
/// Bytes one slot occupies.
pub const SLOT_LEN: usize = HEADER_LEN + PAYLOAD_LEN;
/// Storage the two slots need.
pub const STORAGE_NEEDED: usize = 2 * SLOT_LEN;

/// Byte-addressed non-volatile memory (the Mega 2560's EEPROM, or RAM in
/// hal-sim).
pub trait NonVolatile {
    /// Size in bytes.
    fn capacity(&self) -> usize;
    fn read(&mut self, address: usize) -> u8;
    /// Write one byte (may take milliseconds on EEPROM).
    fn write(&mut self, address: usize, value: u8);
    /// Make every write so far durable; false if the medium failed. EEPROM
    /// is durable byte by byte (nothing to do); a flash store writes its
    /// page here ([`crate::flash_pages`]).
    fn commit(&mut self) -> bool {
        true
    }
}

/// Why settings were not saved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SaveError {
    /// The storage is smaller than two slots.
    TooSmall,
    /// The medium refused the write (flash that does not program).
    WriteFailed,
}

/// Why stored settings were not loaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LoadError {
    /// No slot holds an image of this firmware (blank, or another layout).
    NoImage,
    /// An image is there but its CRC does not match: corrupt.
    Corrupt { stored: u16, computed: u16 },
    /// The image was written by a firmware with another layout version.
    OldVersion(u8),
    /// The storage is smaller than two slots.
    TooSmall,
    /// The image was saved by a firmware built for another machine file.
    OtherMachine,
}

/// What a successful save or load reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stored {
    pub bytes: usize,
    pub crc: u16,
}

/// Save `settings` into the slot not holding the newest image.
pub fn save(storage: &mut (impl NonVolatile + ?Sized), settings: &Settings) -> Result<Stored, SaveError> {
    if storage.capacity() < STORAGE_NEEDED {
        return Err(SaveError::TooSmall);
    }
    let (newest_slot, sequence) = match newest(storage) {
        Ok((slot, sequence)) => (Some(slot), sequence.wrapping_add(1)),
        Err(_) => (None, 0),
    };
    let slot = match newest_slot {
        Some(0) => 1,
        _ => 0,
    };
    let mut image = [0u8; SLOT_LEN];
    encode(settings, sequence, &mut image);
    let base = slot * SLOT_LEN;
    // Payload first, header last: the CRC in the header makes it valid.
    // One range, rotated by the header's length (a chain of two ranges
    // cost more code), and `get` rather than an index with its panic.
    for step in 0..SLOT_LEN {
        let index = if step < PAYLOAD_LEN { HEADER_LEN + step } else { step - PAYLOAD_LEN };
        let Some(&byte) = image.get(index) else { continue };
        if storage.read(base + index) != byte {
            storage.write(base + index, byte);
        }
    }
    if !storage.commit() {
        return Err(SaveError::WriteFailed);
    }
    Ok(Stored { bytes: SLOT_LEN, crc: u16::from_le_bytes([image[7], image[8]]) })
}

/// Load the newest valid image.
pub fn load(storage: &mut (impl NonVolatile + ?Sized)) -> Result<(Settings, Stored), LoadError> {
    let mut settings = Settings::default();
    load_into(storage, &mut settings).map(|stored| (settings, stored))
}

/// [`load`] into `settings`, which changes only when an image loads: the
/// payload goes from the storage straight into the settings (checked
/// first by [`newest`]), with no image and no `Settings` in this frame
/// nor the caller's (on the AVR they made the loader's frame 245 bytes,
/// and every access beyond 63 bytes several instructions longer).
pub fn load_into(storage: &mut (impl NonVolatile + ?Sized), settings: &mut Settings) -> Result<Stored, LoadError> {
    if storage.capacity() < STORAGE_NEEDED {
        return Err(LoadError::TooSmall);
    }
    let (slot, _) = newest(storage)?;
    let base = slot * SLOT_LEN;
    for slot in 0..crate::settings::SLOTS {
        let at = base + HEADER_LEN + 4 * slot;
        let bytes = [storage.read(at), storage.read(at + 1), storage.read(at + 2), storage.read(at + 3)];
        settings.set_slot(slot, i32::from_le_bytes(bytes));
    }
    Ok(Stored { bytes: SLOT_LEN, crc: u16::from_le_bytes([storage.read(base + 7), storage.read(base + 8)]) })
}

/// The valid slot with the newest sequence number; with none, why the
/// first slot is refused (as good a reason as any).
#[inline(never)]
fn newest(storage: &mut (impl NonVolatile + ?Sized)) -> Result<(usize, u16), LoadError> {
    let mut best: Option<(usize, u16)> = None;
    let mut first_error = LoadError::NoImage;
    let mut image = [0u8; SLOT_LEN];
    for slot in 0..2 {
        read_slot_into(storage, slot, &mut image);
        match check(&image) {
            Ok(sequence) => {
                best = match best {
                    // Sequence numbers wrap: newer means "ahead by less than half".
                    Some((_, other)) if sequence.wrapping_sub(other) > u16::MAX / 2 => best,
                    _ => Some((slot, sequence)),
                };
            }
            Err(error) if slot == 0 || error == LoadError::OtherMachine => first_error = error,
            Err(_) => {}
        }
    }
    best.ok_or(first_error)
}

#[cfg(test)]
fn read_slot(storage: &mut (impl NonVolatile + ?Sized), slot: usize) -> [u8; SLOT_LEN] {
    let mut image = [0u8; SLOT_LEN];
    read_slot_into(storage, slot, &mut image);
    image
}

/// Slot `slot`'s bytes into `image` (by reference: an array returned by
/// value is a stack copy on the AVR).
#[inline(never)]
fn read_slot_into(storage: &mut (impl NonVolatile + ?Sized), slot: usize, image: &mut [u8; SLOT_LEN]) {
    for (index, byte) in image.iter_mut().enumerate() {
        *byte = storage.read(slot * SLOT_LEN + index);
    }
}

/// The sequence number of a valid image.
#[inline(never)]
fn check(image: &[u8; SLOT_LEN]) -> Result<u16, LoadError> {
    if u16::from_le_bytes([image[0], image[1]]) != MAGIC {
        return Err(LoadError::NoImage);
    }
    if image[2] != LAYOUT_VERSION {
        return Err(LoadError::OldVersion(image[2]));
    }
    if usize::from(u16::from_le_bytes([image[5], image[6]])) != PAYLOAD_LEN {
        return Err(LoadError::NoImage);
    }
    let stored = u16::from_le_bytes([image[7], image[8]]);
    let computed = image_crc(image);
    if stored != computed {
        return Err(LoadError::Corrupt { stored, computed });
    }
    if u32::from_le_bytes([image[9], image[10], image[11], image[12]]) != crate::machine_file::FINGERPRINT {
        return Err(LoadError::OtherMachine);
    }
    Ok(u16::from_le_bytes([image[3], image[4]]))
}

#[inline(never)]
fn image_crc(image: &[u8; SLOT_LEN]) -> u16 {
    let crc = crc16(0xFFFF, &image[..7]);
    crc16(crc, &image[9..])
}

/// CRC-16/CCITT-FALSE, bitwise: 30 bytes of code instead of a 512-byte
/// table, and the image is only checked at boot and on `M500`/`M501`.
/// The polynomial goes through `black_box`: from `opt-level=2` LLVM turns a
/// bitwise CRC with a constant polynomial into a 512-byte table, which the
/// AVR keeps in RAM (`.data`).
#[inline(never)]
fn crc16(mut crc: u16, bytes: &[u8]) -> u16 {
    let polynomial = core::hint::black_box(0x1021u16);
    for &byte in bytes {
        crc ^= u16::from(byte) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ polynomial } else { crc << 1 };
        }
    }
    crc
}


fn encode(settings: &Settings, sequence: u16, image: &mut [u8; SLOT_LEN]) {
    image[0..2].copy_from_slice(&MAGIC.to_le_bytes());
    image[2] = LAYOUT_VERSION;
    image[3..5].copy_from_slice(&sequence.to_le_bytes());
    image[5..7].copy_from_slice(&(PAYLOAD_LEN as u16).to_le_bytes());
    image[9..13].copy_from_slice(&crate::machine_file::FINGERPRINT.to_le_bytes());
    for (slot, bytes) in image[HEADER_LEN..].chunks_exact_mut(4).enumerate() {
        bytes.copy_from_slice(&settings.slot(slot).to_le_bytes());
    }
    let crc = image_crc(image);
    image[7..9].copy_from_slice(&crc.to_le_bytes());
}

/// Storage in RAM, with the faults a test wants (hal-sim and unit tests).
pub struct MemoryStorage<const N: usize> {
    pub bytes: [u8; N],
    /// Writes still allowed before the "power" fails (None: unlimited).
    pub writes_before_power_loss: Option<usize>,
    pub writes: usize,
}

impl<const N: usize> Default for MemoryStorage<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> MemoryStorage<N> {
    /// Blank, like an erased EEPROM (all 0xFF).
    pub const fn new() -> Self {
        Self { bytes: [0xFF; N], writes_before_power_loss: None, writes: 0 }
    }
}

impl<const N: usize> NonVolatile for MemoryStorage<N> {
    fn capacity(&self) -> usize {
        N
    }
    fn read(&mut self, address: usize) -> u8 {
        self.bytes.get(address).copied().unwrap_or(0xFF)
    }
    fn write(&mut self, address: usize, value: u8) {
        if let Some(left) = self.writes_before_power_loss {
            if left == 0 {
                return;
            }
            self.writes_before_power_loss = Some(left - 1);
        }
        if let Some(byte) = self.bytes.get_mut(address) {
            *byte = value;
            self.writes += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type Eeprom = MemoryStorage<4096>;

    fn custom() -> Settings {
        let mut settings = Settings::default();
        settings.steps_per_mm_milli[3] = 415_500;
        settings.junction_deviation_um = 20;
        settings
    }

    /// Layout 3, byte by byte as an earlier firmware wrote it (the
    /// header, then each slot's `i32` little endian): EEPROMs in the
    /// field keep loading.
    #[test]
    fn a_layout_3_image_written_byte_by_byte_loads() {
        let mut slots: std::vec::Vec<i32> = (1..=33).collect();
        slots[0] = 80_125; // M92 X80.125
        let mut image = std::vec![0xE7, 0xF5, 3, 7, 0, 132, 0, 0, 0];
        image.extend_from_slice(&crate::machine_file::FINGERPRINT.to_le_bytes());
        for value in &slots {
            image.extend_from_slice(&value.to_le_bytes());
        }
        let crc = crc16(crc16(0xFFFF, &image[..7]), &image[9..]);
        image[7..9].copy_from_slice(&crc.to_le_bytes());
        let mut eeprom = MemoryStorage::<512>::new();
        eeprom.bytes[..image.len()].copy_from_slice(&image);
        let (settings, stored) = load(&mut eeprom).unwrap();
        assert_eq!(stored.bytes, 145);
        assert_eq!(settings.steps_per_mm_milli, [80_125, 2, 3, 4]);
        assert_eq!(settings.flow_percent, 21);
        assert_eq!(settings.delta_trim_um, [31, 32, 33]);
        // And saved back, the same bytes (sequence 8 in the other slot).
        save(&mut eeprom, &settings).unwrap();
        let mut again = read_slot(&mut eeprom, 1);
        again[3] = 7;
        assert_eq!(&again[13..], &image[13..]);
    }

    #[test]
    fn a_blank_eeprom_has_no_image() {
        assert_eq!(load(&mut Eeprom::new()), Err(LoadError::NoImage));
    }

    #[test]
    fn saved_settings_load_back_unchanged() {
        let mut eeprom = Eeprom::new();
        let stored = save(&mut eeprom, &custom()).unwrap();
        let (settings, loaded) = load(&mut eeprom).unwrap();
        assert_eq!(settings, custom());
        assert_eq!(stored, loaded);
        assert_eq!(stored.bytes, 145);
    }

    #[test]
    fn saves_alternate_slots_and_the_newest_wins() {
        let mut eeprom = Eeprom::new();
        save(&mut eeprom, &Settings::default()).unwrap();
        save(&mut eeprom, &custom()).unwrap();
        assert_eq!(load(&mut eeprom).unwrap().0, custom());
        // Slot 0 still holds the first image, slot 1 the second.
        assert_eq!(&eeprom.bytes[0..2], &MAGIC.to_le_bytes());
        assert_eq!(&eeprom.bytes[SLOT_LEN..SLOT_LEN + 2], &MAGIC.to_le_bytes());
    }

    #[test]
    fn every_single_bit_flip_is_detected() {
        let mut reference = Eeprom::new();
        save(&mut reference, &custom()).unwrap();
        for byte in 0..SLOT_LEN {
            for bit in 0..8 {
                let mut eeprom = Eeprom { bytes: reference.bytes, writes_before_power_loss: None, writes: 0 };
                eeprom.bytes[byte] ^= 1 << bit;
                match load(&mut eeprom) {
                    Err(_) => {}
                    Ok((settings, _)) => panic!("flip of byte {byte} bit {bit} loaded {settings:?}"),
                }
            }
        }
    }

    #[test]
    fn a_truncated_image_is_refused() {
        let mut eeprom = Eeprom::new();
        save(&mut eeprom, &custom()).unwrap();
        for byte in &mut eeprom.bytes[SLOT_LEN / 2..SLOT_LEN] {
            *byte = 0xFF;
        }
        assert!(matches!(load(&mut eeprom), Err(LoadError::Corrupt { .. })));
    }

    #[test]
    fn settings_saved_for_another_machine_file_are_refused_whole() {
        let mut storage = MemoryStorage::<512>::new();
        save(&mut storage, &custom()).unwrap();
        // Another machine's build writes its own fingerprint (and a CRC
        // that covers it: the image is intact, only not ours).
        let mut image = read_slot(&mut storage, 0);
        let other = crate::machine_file::FINGERPRINT ^ 1;
        image[9..13].copy_from_slice(&other.to_le_bytes());
        let crc = image_crc(&image);
        image[7..9].copy_from_slice(&crc.to_le_bytes());
        for (i, &b) in image.iter().enumerate() {
            storage.write(i, b);
        }
        assert_eq!(load(&mut storage).map(|(s, _)| s), Err(LoadError::OtherMachine));
    }

    #[test]
    fn another_layout_version_is_refused() {
        let mut eeprom = Eeprom::new();
        save(&mut eeprom, &custom()).unwrap();
        eeprom.bytes[2] = LAYOUT_VERSION + 1;
        assert_eq!(load(&mut eeprom), Err(LoadError::OldVersion(LAYOUT_VERSION + 1)));
    }

    #[test]
    fn a_power_loss_at_any_byte_of_a_save_leaves_old_or_new_never_a_mix() {
        let old = Settings::default();
        let new = custom();
        for cut in 0..=SLOT_LEN {
            let mut eeprom = Eeprom::new();
            save(&mut eeprom, &old).unwrap();
            eeprom.writes_before_power_loss = Some(cut);
            save(&mut eeprom, &new).unwrap();
            eeprom.writes_before_power_loss = None;
            let (loaded, _) = load(&mut eeprom).unwrap();
            assert!(loaded == old || loaded == new, "cut after {cut} writes: {loaded:?}");
        }
    }

    #[test]
    fn unchanged_bytes_are_not_rewritten() {
        let mut eeprom = Eeprom::new();
        save(&mut eeprom, &custom()).unwrap();
        save(&mut eeprom, &custom()).unwrap();
        let writes = eeprom.writes;
        // A third save goes to slot 0 again, which holds the same payload:
        // only the sequence number and CRC change.
        save(&mut eeprom, &custom()).unwrap();
        assert!(eeprom.writes - writes <= 4, "{} writes", eeprom.writes - writes);
    }

    #[test]
    fn sequence_numbers_wrap() {
        let mut eeprom = Eeprom::new();
        save(&mut eeprom, &Settings::default()).unwrap();
        // Force slot 0's sequence to the top, then save twice across the wrap.
        let mut image = read_slot(&mut eeprom, 0);
        encode(&Settings::default(), u16::MAX, &mut image);
        eeprom.bytes[..SLOT_LEN].copy_from_slice(&image);
        save(&mut eeprom, &custom()).unwrap();
        assert_eq!(load(&mut eeprom).unwrap().0, custom());
    }
}
