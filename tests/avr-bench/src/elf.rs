//! What the bench needs from the ELF itself: section sizes (flash and static
//! RAM use) and a few linker symbols (`__bss_end`, `__stack`). A 32-bit
//! little-endian ELF reader of ~100 lines, so the bench needs no ELF crate.

use std::path::Path;

/// Where the GNU AVR linker puts data-space addresses.
pub const DATA_OFFSET: u32 = 0x0080_0000;
/// First SRAM address of the ATmega2560 (below are registers and I/O).
pub const RAM_START: u16 = 0x0200;
/// Last SRAM address of the ATmega2560 (8 KiB of SRAM).
pub const RAM_END: u16 = 0x21FF;
/// SRAM size of the ATmega2560.
pub const RAM_BYTES: u32 = 8 * 1024;
/// Flash size of the ATmega2560.
pub const FLASH_BYTES: u32 = 256 * 1024;

#[derive(Clone, Debug)]
pub struct Section {
    pub name: String,
    pub addr: u32,
    pub size: u32,
    /// SHF_ALLOC: the section occupies memory on the chip.
    pub alloc: bool,
    /// SHT_NOBITS (.bss): no bytes in the file, hence none in flash.
    pub nobits: bool,
}

#[derive(Clone, Debug)]
pub struct Symbol {
    pub name: String,
    pub value: u32,
    pub size: u32,
}

/// The parts of the firmware ELF the bench reads.
#[derive(Clone, Debug)]
pub struct ElfInfo {
    pub sections: Vec<Section>,
    pub symbols: Vec<Symbol>,
}

impl ElfInfo {
    pub fn read(path: &Path) -> Result<Self, String> {
        let bytes =
            std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        Self::parse(&bytes).map_err(|e| format!("{}: {e}", path.display()))
    }

    pub fn parse(b: &[u8]) -> Result<Self, String> {
        if b.len() < 52 || &b[..4] != b"\x7fELF" {
            return Err("not an ELF file".into());
        }
        if b[4] != 1 || b[5] != 1 {
            return Err("not a 32-bit little-endian ELF (AVR ELFs are)".into());
        }
        let u16_at = |o: usize| -> Result<u16, String> {
            b.get(o..o + 2)
                .map(|s| u16::from_le_bytes([s[0], s[1]]))
                .ok_or_else(|| "truncated ELF".to_string())
        };
        let u32_at = |o: usize| -> Result<u32, String> {
            b.get(o..o + 4)
                .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
                .ok_or_else(|| "truncated ELF".to_string())
        };
        let shoff = u32_at(0x20)? as usize;
        let shentsize = u16_at(0x2E)? as usize;
        let shnum = u16_at(0x30)? as usize;
        let shstrndx = u16_at(0x32)? as usize;
        struct Raw {
            name: u32,
            kind: u32,
            flags: u32,
            addr: u32,
            offset: u32,
            size: u32,
            link: u32,
            entsize: u32,
        }
        let mut raw = Vec::with_capacity(shnum);
        for i in 0..shnum {
            let o = shoff + i * shentsize;
            raw.push(Raw {
                name: u32_at(o)?,
                kind: u32_at(o + 4)?,
                flags: u32_at(o + 8)?,
                addr: u32_at(o + 12)?,
                offset: u32_at(o + 16)?,
                size: u32_at(o + 20)?,
                link: u32_at(o + 24)?,
                entsize: u32_at(o + 36)?,
            });
        }
        let c_str = |table: &Raw, index: u32| -> String {
            let start = (table.offset + index) as usize;
            let end = b[start.min(b.len())..]
                .iter()
                .position(|&c| c == 0)
                .map_or(b.len(), |n| start + n);
            String::from_utf8_lossy(&b[start.min(b.len())..end]).into_owned()
        };
        let names = raw.get(shstrndx).ok_or("no section name table")?;
        let sections = raw
            .iter()
            .map(|s| Section {
                name: c_str(names, s.name),
                addr: s.addr,
                size: s.size,
                alloc: s.flags & 0x2 != 0,
                nobits: s.kind == 8,
            })
            .collect();
        let mut symbols = Vec::new();
        for table in raw.iter().filter(|s| s.kind == 2) {
            let strings = raw
                .get(table.link as usize)
                .ok_or("symbol table without strings")?;
            let entsize = if table.entsize == 0 {
                16
            } else {
                table.entsize as usize
            };
            for i in 0..table.size as usize / entsize {
                let o = table.offset as usize + i * entsize;
                symbols.push(Symbol {
                    name: c_str(strings, u32_at(o)?),
                    value: u32_at(o + 4)?,
                    size: u32_at(o + 8)?,
                });
            }
        }
        Ok(Self { sections, symbols })
    }

    pub fn section(&self, name: &str) -> Option<&Section> {
        self.sections.iter().find(|s| s.name == name)
    }

    pub fn symbol(&self, name: &str) -> Option<u32> {
        self.symbols
            .iter()
            .find(|s| s.name == name)
            .map(|s| s.value)
    }

    /// Bytes programmed into flash: every allocated section with contents
    /// (`.text`, and `.data`'s initial values, which the start-up code copies
    /// to RAM), as avr-size counts them.
    pub fn flash_bytes(&self) -> u32 {
        self.sections
            .iter()
            .filter(|s| s.alloc && !s.nobits && s.addr < DATA_OFFSET)
            .map(|s| s.size)
            .sum::<u32>()
            + self
                .sections
                .iter()
                .filter(|s| s.alloc && !s.nobits && is_data(s.addr))
                .map(|s| s.size)
                .sum::<u32>()
    }

    /// Statically allocated RAM: `.data` + `.bss` (+ `.noinit`).
    pub fn ram_static_bytes(&self) -> u32 {
        self.sections
            .iter()
            .filter(|s| s.alloc && is_data(s.addr))
            .map(|s| s.size)
            .sum()
    }

    /// First RAM address past the static data (`__bss_end` / `_end`), as a
    /// data-space address (0x200..=0x21FF).
    pub fn static_end(&self) -> u16 {
        let end = self
            .symbol("__bss_end")
            .or_else(|| self.symbol("_end"))
            .unwrap_or(DATA_OFFSET + u32::from(RAM_START) + self.ram_static_bytes());
        (end - DATA_OFFSET) as u16
    }

    /// The initial stack pointer (`__stack`, RAMEND unless relocated).
    pub fn initial_sp(&self) -> u16 {
        self.symbol("__stack")
            .map_or(RAM_END, |s| (s & 0xFFFF) as u16)
    }
}

fn is_data(addr: u32) -> bool {
    (DATA_OFFSET..DATA_OFFSET + 0x1_0000).contains(&addr)
}
