//! Constant tables in flash on the AVR.
//!
//! The ATmega2560 is a Harvard machine: a `static` is copied into the 8 KiB
//! of SRAM at boot unless it is placed in program memory and read with the
//! `lpm` instruction. Tables (thermistors, lookup tables) therefore live in
//! [`Flash`], which puts them in `.progmem.data` on the AVR and reads them
//! byte by byte with `elpm`; on every other target it is an ordinary static.
//!
//! Only `Copy` data without pointers belongs in here (integers and arrays of
//! them): a pointer stored in flash would be read back as a RAM address.

/// A value of type `T` that lives in flash on the AVR.
#[repr(transparent)]
pub struct Flash<T: Copy>(T);

impl<T: Copy> Flash<T> {
    /// Wrap a value; use in a `static` marked with
    /// `#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]`.
    pub const fn new(value: T) -> Self {
        Self(value)
    }

    /// A copy of the whole value.
    pub fn load(&self) -> T {
        load(&self.0)
    }
}

impl<T: Copy, const N: usize> Flash<[T; N]> {
    /// Number of elements.
    pub const fn len(&self) -> usize {
        N
    }

    pub const fn is_empty(&self) -> bool {
        N == 0
    }

    /// A copy of element `index`; `None` past the end.
    pub fn get(&self, index: usize) -> Option<T> {
        self.0.get(index).map(load)
    }
}

/// Copy `*source` out of flash (AVR) or memory (elsewhere).
#[cfg(not(target_arch = "avr"))]
fn load<T: Copy>(source: &T) -> T {
    *source
}

#[cfg(target_arch = "avr")]
fn load<T: Copy>(source: &T) -> T {
    let mut value = core::mem::MaybeUninit::<T>::uninit();
    let destination = value.as_mut_ptr().cast::<u8>();
    let address = (source as *const T).cast::<u8>() as u16;
    for offset in 0..core::mem::size_of::<T>() {
        // SAFETY: `source` is a `Flash` static in `.progmem.data`, so its
        // bytes are in program memory at the same address (below 64 KiB:
        // avr-gcc's linker script puts `.progmem*` first in `.text`).
        let byte = unsafe { read_flash_byte(address.wrapping_add(offset as u16)) };
        // SAFETY: `offset` is within the size of `T`.
        unsafe { destination.add(offset).write(byte) };
    }
    // SAFETY: every byte of the `Copy` value has been copied.
    unsafe { value.assume_init() }
}

/// Read one byte of program memory with `lpm`.
///
/// # Safety
/// `address` must be inside the first 64 KiB of flash.
#[cfg(target_arch = "avr")]
unsafe fn read_flash_byte(address: u16) -> u8 {
    let byte: u8;
    // SAFETY: `lpm` only reads program memory; Z is the address.
    unsafe {
        core::arch::asm!(
            "lpm {byte}, Z",
            byte = out(reg) byte,
            in("Z") address,
            options(pure, readonly, nostack, preserves_flags),
        );
    }
    byte
}

#[cfg(test)]
mod tests {
    use super::*;

    static ROWS: Flash<[(u16, i32); 3]> = Flash::new([(1, -1), (2, -2), (3, -3)]);

    #[test]
    fn elements_read_back_unchanged() {
        assert_eq!(ROWS.len(), 3);
        assert_eq!(ROWS.get(1), Some((2, -2)));
        assert_eq!(ROWS.get(3), None);
        assert_eq!(ROWS.load()[2], (3, -3));
    }
}

/// A string kept in flash on the AVR (see [`flash_str!`]). ASCII only,
/// ended by a NUL: one pointer, not a pointer and a length, so that every
/// call that writes one loads two registers fewer (4 bytes of code each on
/// the AVR, for one byte of flash per string).
#[derive(Clone, Copy)]
pub struct FlashStr {
    /// The first byte of a NUL-terminated array in `.progmem.data`.
    start: *const u8,
}

impl FlashStr {
    /// Wrap a NUL-terminated array that lives in `.progmem.data` (use
    /// [`flash_str!`]).
    /// ([`nul_terminated`] checked the array when it was made.)
    #[doc(hidden)]
    #[inline(always)]
    pub const fn from_static(bytes: &'static [u8]) -> Self {
        Self { start: bytes.as_ptr() }
    }

    /// The number of bytes before the NUL.
    pub fn len(&self) -> usize {
        let mut len = 0;
        self.for_each_piece(|text| {
            len += text.len();
            Ok::<(), ()>(())
        })
        .ok();
        len
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Write the string to `out`, copying it out of flash in small pieces.
    pub fn write_to<W: ufmt::uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        self.for_each_piece(|text| out.write_str(text))
    }

    /// Call `write` with the text, 16 bytes at a time.
    fn for_each_piece<E>(&self, mut write: impl FnMut(&str) -> Result<(), E>) -> Result<(), E> {
        let mut chunk = [0u8; 16];
        let mut at = self.start;
        loop {
            let mut len = 0;
            while len < chunk.len() {
                // SAFETY: `at` stays within the array `from_static` took:
                // it stops at the NUL that ends it. ASCII by construction
                // (`flash_str!` checks it at compile time); the mask makes
                // it so whatever flash returns.
                let byte = unsafe { load(&*at) } & 0x7F;
                if byte == 0 {
                    break;
                }
                chunk[len] = byte;
                len += 1;
                // SAFETY: as above; at most one past this byte, the NUL.
                at = unsafe { at.add(1) };
            }
            if len > 0 {
                // SAFETY: every byte is below 0x80, and ASCII is valid
                // UTF-8. (`from_utf8` would pull in a 256-byte table.)
                write(unsafe { core::str::from_utf8_unchecked(&chunk[..len]) })?;
            }
            if len < chunk.len() {
                return Ok(());
            }
        }
    }
}

impl ufmt::uDisplay for FlashStr {
    fn fmt<W: ufmt::uWrite + ?Sized>(&self, f: &mut ufmt::Formatter<'_, W>) -> Result<(), W::Error> {
        self.for_each_piece(|text| f.write_str(text))
    }
}

/// `parts` one after the other and a NUL, in a byte array (const
/// context, for [`flash_str!`] and [`flash_concat!`]): ASCII without NUL.
#[doc(hidden)]
pub const fn nul_terminated<const N: usize>(parts: &[&str]) -> [u8; N] {
    let (array, at) = joined::<N>(parts, false);
    assert!(at + 1 == N);
    array
}

/// The total length of `parts` (const context, for [`flash_concat!`]).
#[doc(hidden)]
pub const fn total_len(parts: &[&str]) -> usize {
    let mut len = 0;
    let mut i = 0;
    while i < parts.len() {
        len += parts[i].len();
        i += 1;
    }
    len
}

/// `parts` one after the other in a byte array (const context); NULs may
/// separate the strings of a table.
#[doc(hidden)]
pub const fn concat_ascii<const N: usize>(parts: &[&str]) -> [u8; N] {
    let (array, at) = joined::<N>(parts, true);
    assert!(at == N);
    array
}

/// `parts` copied one after the other to the start of an `N`-byte array
/// (ASCII, NUL only if `nul_allowed`), and how many bytes that took.
const fn joined<const N: usize>(parts: &[&str], nul_allowed: bool) -> ([u8; N], usize) {
    let mut array = [0u8; N];
    let mut at = 0;
    let mut i = 0;
    while i < parts.len() {
        let bytes = parts[i].as_bytes();
        let mut j = 0;
        while j < bytes.len() {
            assert!(bytes[j] < 0x80 && (nul_allowed || bytes[j] > 0), "flash strings are ASCII (without NUL unless a table)");
            array[at] = bytes[j];
            at += 1;
            j += 1;
        }
        i += 1;
    }
    (array, at)
}

/// Several `&str` constants joined into one string in flash, as a
/// [`FlashStr`]: a reply built from constants (the firmware's name and
/// version) is written with one call and costs no RAM.
#[macro_export]
macro_rules! flash_concat {
    ($($part:expr),+ $(,)?) => {{
        const PARTS: &[&str] = &[$($part),+];
        #[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
        static BYTES: [u8; $crate::progmem::total_len(PARTS) + 1] = $crate::progmem::nul_terminated(PARTS);
        $crate::progmem::FlashStr::from_static(&BYTES)
    }};
}

/// A string literal stored in flash on the AVR (in RAM on other targets),
/// as a [`FlashStr`]: `out.write_flash(flash_str!("echo:busy"))`.
#[macro_export]
macro_rules! flash_str {
    ($text:expr) => {{
        const TEXT: &str = $text;
        #[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
        static BYTES: [u8; TEXT.len() + 1] = $crate::progmem::nul_terminated(&[TEXT]);
        $crate::progmem::FlashStr::from_static(&BYTES)
    }};
}

#[cfg(test)]
mod flash_str_tests {
    use crate::reply::test_support::Text;

    #[test]
    fn a_flash_string_writes_its_text_in_any_length() {
        let mut out = Text::default();
        crate::flash_str!("").write_to(&mut out).unwrap();
        crate::flash_str!("Cap:EEPROM:").write_to(&mut out).unwrap();
        crate::flash_str!("0123456789abcdefXYZ").write_to(&mut out).unwrap();
        ufmt::uwrite!(out, "[{}]", crate::flash_str!("mid")).unwrap();
        crate::flash_concat!("a", "", "bc", crate::FIRMWARE_NAME).write_to(&mut out).unwrap();
        assert_eq!(out.0, "Cap:EEPROM:0123456789abcdefXYZ[mid]abcFerrostep");
        // A piece's worth exactly, and two: no empty piece, nothing lost.
        let mut pieces = std::vec::Vec::new();
        crate::flash_str!("0123456789abcdef").for_each_piece(|text| Ok::<(), ()>(pieces.push(text.len()))).unwrap();
        crate::flash_str!("0123456789abcdef0123456789abcdef!").for_each_piece(|text| Ok::<(), ()>(pieces.push(text.len()))).unwrap();
        assert_eq!(pieces, [16, 16, 16, 1]);
        assert_eq!(crate::flash_str!("").len(), 0);
        assert!(crate::flash_str!("").is_empty());
        assert_eq!(crate::flash_concat!("ab", "cde").len(), 5);
    }
}
