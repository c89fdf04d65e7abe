//! The command table: which G/M codes each machine runs, what a halted
//! machine does with them, and what `M115` says about them.
//!
//! Every feature module declares its codes in a `COMMANDS` slice of
//! [`Listing`]s beside the `match` that runs them: the executor's own
//! ([`CORE`], below), the printer's encoder loops (`encoders::COMMANDS`),
//! the extrusion line (`line::COMMANDS`) and the powder bed
//! (`powder_bed::COMMANDS`). A row names a code (or a run of codes), the
//! machines that have it, whether it runs while halted, and the `M115`
//! capability it stands for. From these rows, at compile time:
//!
//! - **listed or unknown** ([`listing`]): the executor answers a code not
//!   listed for the running machine with `echo:Unknown command: "…"`, as
//!   Marlin does, whatever its arguments; a listed one with malformed
//!   arguments gets an `Error:` line. The check comes before the `match`,
//!   so a code the `match` would run but no row lists is unknown: the
//!   table, not the `match`, decides.
//! - **halted** ([`Halted`]): after `M112` (or a safety fault) a listed
//!   code either still runs (reports, waits, the protocol's own codes:
//!   hosts keep polling `M105`) or is refused with the halt's `Error:`.
//! - **`M115`** ([`capabilities`]): Marlin's capability lines, in Marlin's
//!   order ([`MARLIN_CAPABILITIES`]), each `1` when a listed row (or the
//!   parser, [`PARSER_CAPABILITIES`]) claims it, then this firmware's own
//!   (`CLOSED_LOOP`, `EXTRUSION_LINE`, `POWDER_BED`) in table order, each
//!   once.
//!
//! "The machines that have it" is two things: the cargo features select
//! which tables are built at all (a module compiled out lists nothing),
//! and [`Machines`] says which kind of machine — printer, extrusion line,
//! powder bed, chosen at boot by `become_…` — answers the code. A row
//! that depends on a feature inside a table says so with
//! [`Machines::when`]. A code listed in two tables for the same machine
//! must have one halted policy (checked at compile time); the first
//! module in dispatch order that handles it runs it.
//!
//! The tables are `const`: they exist only while compiling. What is left
//! in the image is two bitmaps per machine kind built (listed, runs
//! while halted: a bit test per command; 138 bytes each) and one `M115`
//! string per kind built, all in flash.
//!
//! A test walks every code for every machine kind
//! (`machine::tests::every_listed_code_is_dispatched_and_every_other_is_unknown`):
//! a listed code never answers "Unknown command", an unlisted one always
//! does, and the halted policy and `M115` follow the rows.

use crate::gcode::Code;

/// What a halted machine does with a listed code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Halted {
    /// It runs as always: it only reports, waits or talks protocol.
    Runs,
    /// It is refused with `Error:Printer halted. kill() called!`.
    Refused,
}

/// The kind of machine the executor is (the board picks it at boot).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A printer (Cartesian, delta or arm): the default.
    Printer = 0,
    /// SPEC §4's extrusion line (`Machine::become_extrusion_line`).
    Line = 1,
    /// SPEC §5's powder bed (`Machine::become_powder_bed`).
    Bed = 2,
}

/// Every kind, in index order.
pub const KINDS: [Kind; 3] = [Kind::Printer, Kind::Line, Kind::Bed];

/// A set of machine kinds, one bit per [`Kind`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Machines(u8);

impl Machines {
    pub const NONE: Machines = Machines(0);
    pub const PRINTER: Machines = Machines(1 << Kind::Printer as u8);
    pub const LINE: Machines = Machines(1 << Kind::Line as u8);
    pub const BED: Machines = Machines(1 << Kind::Bed as u8);
    pub const ALL: Machines = Machines(0b111);

    /// These machines if `built` (a `cfg!(feature = …)`), else none.
    pub const fn when(self, built: bool) -> Machines {
        if built {
            self
        } else {
            Machines::NONE
        }
    }

    pub const fn has(self, kind: Kind) -> bool {
        self.0 >> kind as u8 & 1 != 0
    }
}

/// The letter of a row's codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Letter {
    G,
    M,
    /// `T<n>`, every `n` (the handler decides which tools exist).
    T,
    /// Axis words without a code: the modal motion (`G0`/`G1`).
    Modal,
}

/// One row of a command table: `letter` `first`..=`last`.
#[derive(Clone, Copy, Debug)]
pub struct Listing {
    pub letter: Letter,
    pub first: u16,
    pub last: u16,
    pub machines: Machines,
    pub halted: Halted,
    /// The `M115` capability this code stands for (`Cap:<name>:1`), or "".
    pub capability: &'static str,
}

impl Listing {
    /// `Gn`, refused while halted, on every machine, no capability: the
    /// common case; change one column with the `const fn`s below.
    pub const fn g(n: u16) -> Listing {
        Listing { letter: Letter::G, first: n, last: n, machines: Machines::ALL, halted: Halted::Refused, capability: "" }
    }

    /// `Mn`, as [`Listing::g`].
    pub const fn m(n: u16) -> Listing {
        Listing { letter: Letter::M, ..Listing::g(n) }
    }

    /// `T<n>` for every `n`.
    pub const fn t() -> Listing {
        Listing { letter: Letter::T, ..Listing::g(0) }
    }

    /// Axis words alone.
    pub const fn modal() -> Listing {
        Listing { letter: Letter::Modal, ..Listing::g(0) }
    }

    /// The codes from this one's number up to `last`.
    pub const fn to(self, last: u16) -> Listing {
        Listing { last, ..self }
    }

    /// Runs while halted.
    pub const fn runs_halted(self) -> Listing {
        Listing { halted: Halted::Runs, ..self }
    }

    pub const fn on(self, machines: Machines) -> Listing {
        Listing { machines, ..self }
    }

    pub const fn capability(self, name: &'static str) -> Listing {
        Listing { capability: name, ..self }
    }
}

/// The executor's own codes (`Machine::dispatch` in `machine/mod.rs`; the
/// mode-setting codes in `Machine::apply_setting`). Machines without
/// printer axes or heaters still list the printers' codes: they refuse
/// them (or, for reports, say they ignore them) rather than call them
/// unknown, and the extrusion line and the powder bed handle some of
/// them first (their own tables list only their own codes).
pub const CORE: &[Listing] = &[
    // Moves: linear_move (or, without printer axes, refused).
    Listing::g(0).to(1),
    Listing::modal(),
    Listing::g(2).to(3).capability("ARCS"),
    Listing::g(4).runs_halted(), // dwell
    // G10 L2/L20: work offsets; G10/G11 otherwise: not yet available.
    Listing::g(10).to(11),
    // Mode settings (`gcode::is_mode_setting`; apply_setting).
    Listing::g(17).to(21),
    Listing::g(40),
    Listing::g(49),
    Listing::g(53).to(59),
    Listing::g(61),
    Listing::g(64),
    Listing::g(80),
    Listing::g(90).to(91),
    Listing::g(93).to(94),
    Listing::m(3).to(5), // spindle: "ignored" echo (the line's screw, the bed's roller)
    Listing::m(7).to(9), // coolant: "ignored" echo
    Listing::g(28),      // home
    Listing::g(92),      // set position
    Listing::m(2),       // end of program
    Listing::m(30),
    Listing::m(17).to(18), // drivers on / off
    Listing::m(84),
    Listing::m(73), // progress: accepted silently
    Listing::m(82).to(83),
    Listing::m(92), // settings words (change_settings)
    Listing::m(104).capability("THERMAL_PROTECTION"), // heaters
    Listing::m(109),
    Listing::m(140),
    Listing::m(190),
    Listing::m(301).to(304),
    Listing::m(105).runs_halted(), // temperatures
    Listing::m(106).to(107),       // fan
    // Emergency parser: they act from the receive interrupt.
    Listing::m(108).runs_halted().capability("EMERGENCY_PARSER"),
    Listing::m(112).runs_halted().capability("EMERGENCY_PARSER"),
    Listing::m(410).runs_halted().capability("EMERGENCY_PARSER"),
    Listing::m(110).runs_halted(), // line number: the protocol's
    Listing::m(113).to(115).runs_halted(), // keep-alive, position, capabilities
    Listing::m(117).to(119).runs_halted(), // message, echo, endstops
    Listing::m(120).to(121),               // endstops always / homing only
    Listing::m(155).capability("AUTOREPORT_TEMP"),
    Listing::m(201),
    Listing::m(203).to(205),
    Listing::m(220).to(221),
    Listing::m(400), // wait for moves
    Listing::m(500).capability("EEPROM"),
    Listing::m(501).to(502),
    Listing::m(503).runs_halted(),
    // The delta's geometry and endstop trim (refused unless the kinematics are a delta).
    Listing::m(665).to(666).on(Machines::ALL.when(cfg!(feature = "delta"))),
    Listing::t(),
];

/// Capabilities of the parser rather than of a code.
pub const PARSER_CAPABILITIES: &[&str] = &["PAREN_COMMENTS"];

/// The capabilities `M115` always names, in Marlin's order: `1` when
/// claimed, `0` otherwise (hosts read both).
pub const MARLIN_CAPABILITIES: &[&str] = &[
    "SERIAL_XON_XOFF",
    "BINARY_FILE_TRANSFER",
    "EEPROM",
    "VOLUMETRIC",
    "AUTOREPORT_TEMP",
    "AUTOREPORT_POS",
    "PROGRESS",
    "PRINT_JOB",
    "AUTOLEVEL",
    "Z_PROBE",
    "LEVELING_DATA",
    "SOFTWARE_POWER",
    "TOGGLE_LIGHTS",
    "EMERGENCY_PARSER",
    "HOST_ACTION_COMMANDS",
    "PROMPT_SUPPORT",
    "SDCARD",
    "AUTOREPORT_SD_STATUS",
    "THERMAL_PROTECTION",
    "MOTION_MODES",
    "ARCS",
    "BABYSTEPPING",
    "CHAMBER_TEMPERATURE",
    "PAREN_COMMENTS",
];

#[cfg(feature = "encoders")]
const ENCODERS: &[Listing] = super::encoders::COMMANDS;
#[cfg(not(feature = "encoders"))]
const ENCODERS: &[Listing] = &[];
#[cfg(feature = "extrusion-line")]
const LINE: &[Listing] = super::line::COMMANDS;
#[cfg(not(feature = "extrusion-line"))]
const LINE: &[Listing] = &[];
#[cfg(feature = "powder-bed")]
const BED: &[Listing] = super::powder_bed::COMMANDS;
#[cfg(not(feature = "powder-bed"))]
const BED: &[Listing] = &[];

/// Every table built, in the order `M115` names their capabilities.
pub const TABLES: [&[Listing]; 4] = [CORE, ENCODERS, LINE, BED];

// --- derived at compile time -------------------------------------------------

/// Bit of `Modal` is 0, of any `T` 1, of `G0` [`G_BASE`], of `M0` [`M_BASE`].
const G_BASE: u16 = 2;
/// G codes G0–G99.
const M_BASE: u16 = G_BASE + 100;
/// M codes M0–M999.
const BITS: u16 = M_BASE + 1000;
const BYTES: usize = BITS.div_ceil(8) as usize;

/// The bit of `letter` `n`, if a table can list it.
const fn bit(letter: Letter, n: u16) -> Option<u16> {
    match letter {
        Letter::Modal => Some(0),
        Letter::T => Some(1),
        Letter::G if n < M_BASE - G_BASE => Some(G_BASE + n),
        Letter::M if n < BITS - M_BASE => Some(M_BASE + n),
        _ => None,
    }
}

/// For each kind (`BYTES` each, in [`Kind`] order): the codes listed
/// (`halted` false), or the codes that run while halted (`halted` true).
const fn bitmaps(halted: bool) -> [u8; 3 * BYTES] {
    let mut map = [0u8; 3 * BYTES];
    let mut k = 0;
    while k < KINDS.len() {
        let kind = KINDS[k];
        let mut t = 0;
        while t < TABLES.len() {
            let mut r = 0;
            while r < TABLES[t].len() {
                let row = TABLES[t][r];
                if row.machines.has(kind) && (!halted || matches!(row.halted, Halted::Runs)) {
                    let mut n = row.first;
                    while n <= row.last {
                        let Some(b) = bit(row.letter, n) else { panic!("a listed code past G99 or M999: widen the bitmap") };
                        map[k * BYTES + (b >> 3) as usize] |= 1 << (b & 7);
                        n += 1;
                    }
                }
                r += 1;
            }
            t += 1;
        }
        k += 1;
    }
    map
}

/// Two rows that list one code for one machine agree on its halted policy.
const fn check_halted_policies() {
    let listed = bitmaps(false);
    let runs = bitmaps(true);
    let mut k = 0;
    while k < KINDS.len() {
        let mut t = 0;
        while t < TABLES.len() {
            let mut r = 0;
            while r < TABLES[t].len() {
                let row = TABLES[t][r];
                if row.machines.has(KINDS[k]) && matches!(row.halted, Halted::Refused) {
                    let mut n = row.first;
                    while n <= row.last {
                        if let Some(b) = bit(row.letter, n) {
                            let i = k * BYTES + (b >> 3) as usize;
                            assert!(listed[i] >> (b & 7) & 1 == 1);
                            assert!(runs[i] >> (b & 7) & 1 == 0, "a code listed twice for one machine, runs while halted in one row only");
                        }
                        n += 1;
                    }
                }
                r += 1;
            }
            t += 1;
        }
        k += 1;
    }
}

const _: () = check_halted_policies();

type Bitmap = crate::progmem::Flash<[u8; BYTES]>;

/// Kind `kind`'s part of [`bitmaps`].
const fn part(all: [u8; 3 * BYTES], kind: Kind) -> [u8; BYTES] {
    let mut map = [0u8; BYTES];
    let mut i = 0;
    while i < BYTES {
        map[i] = all[kind as usize * BYTES + i];
        i += 1;
    }
    map
}

/// The two bitmaps of a `kind` machine, (listed, runs while halted), as
/// statics in flash: only the kinds built take room.
macro_rules! bitmaps_of {
    ($kind:expr) => {{
        #[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
        static LISTED: Bitmap = Bitmap::new(part(bitmaps(false), $kind));
        #[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
        static RUNS_HALTED: Bitmap = Bitmap::new(part(bitmaps(true), $kind));
        (&LISTED, &RUNS_HALTED)
    }};
}

/// Whether `code` is listed for a `kind` machine, and then its halted
/// policy. Out of line: one copy for the parse-error path and the
/// dispatch.
#[inline(never)]
pub fn listing(code: Code, kind: Kind) -> Option<Halted> {
    let (letter, n) = match code {
        Code::G(n) => (Letter::G, n),
        Code::M(n) => (Letter::M, n),
        Code::T(_) => (Letter::T, 0),
        Code::Modal => (Letter::Modal, 0),
        Code::Other => return None,
    };
    let b = bit(letter, n)?;
    let (listed, runs_halted): (&Bitmap, &Bitmap) = match kind {
        #[cfg(feature = "extrusion-line")]
        Kind::Line => bitmaps_of!(Kind::Line),
        #[cfg(feature = "powder-bed")]
        Kind::Bed => bitmaps_of!(Kind::Bed),
        _ => bitmaps_of!(Kind::Printer),
    };
    let is_set = |map: &Bitmap| map.get(usize::from(b >> 3)).is_some_and(|byte| byte >> (b & 7) & 1 != 0);
    if !is_set(listed) {
        return None;
    }
    Some(if is_set(runs_halted) { Halted::Runs } else { Halted::Refused })
}

// --- M115 ----------------------------------------------------------------------

/// Whether a row listed for `kind` (or the parser) claims `name`.
const fn claimed(kind: Kind, name: &str) -> bool {
    let mut p = 0;
    while p < PARSER_CAPABILITIES.len() {
        if same(PARSER_CAPABILITIES[p], name) {
            return true;
        }
        p += 1;
    }
    first_claim(kind, name, TABLES.len(), 0)
}

/// Whether a row listed for `kind` before table `t_end`, row `r_end`
/// claims `name` (`t_end` = all tables: anywhere).
const fn first_claim(kind: Kind, name: &str, t_end: usize, r_end: usize) -> bool {
    let mut t = 0;
    while t < TABLES.len() {
        let mut r = 0;
        while r < TABLES[t].len() {
            if t > t_end || (t == t_end && r >= r_end) {
                return false;
            }
            let row = TABLES[t][r];
            if row.machines.has(kind) && same(row.capability, name) {
                return true;
            }
            r += 1;
        }
        t += 1;
    }
    false
}

const fn same(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

const fn is_marlins(name: &str) -> bool {
    let mut i = 0;
    while i < MARLIN_CAPABILITIES.len() {
        if same(MARLIN_CAPABILITIES[i], name) {
            return true;
        }
        i += 1;
    }
    false
}

/// The firmware line of `M115`.
const FIRMWARE_LINE: [&str; 7] = [
    "FIRMWARE_NAME:",
    crate::FIRMWARE_NAME,
    " ",
    crate::FIRMWARE_VERSION,
    " (Rust) SOURCE_CODE_URL:local PROTOCOL_VERSION:1.0 MACHINE_TYPE:",
    crate::machine_file::NAME,
    " EXTRUDER_COUNT:",
];

/// `M115`'s reply for `kind` into `text` (when given), and its length.
const fn write_reply(kind: Kind, text: &mut [u8]) -> usize {
    let mut at = 0;
    let mut i = 0;
    while i < FIRMWARE_LINE.len() {
        at = put(text, at, FIRMWARE_LINE[i]);
        i += 1;
    }
    at = put(text, at, super::EXTRUDERS_TEXT);
    at = put(text, at, "\n");
    let mut i = 0;
    while i < MARLIN_CAPABILITIES.len() {
        let name = MARLIN_CAPABILITIES[i];
        at = put(text, at, "Cap:");
        at = put(text, at, name);
        at = put(text, at, if claimed(kind, name) { ":1\n" } else { ":0\n" });
        i += 1;
    }
    let mut t = 0;
    while t < TABLES.len() {
        let mut r = 0;
        while r < TABLES[t].len() {
            let row = TABLES[t][r];
            let name = row.capability;
            if row.machines.has(kind) && !name.is_empty() && !is_marlins(name) && !first_claim(kind, name, t, r) {
                at = put(text, at, "Cap:");
                at = put(text, at, name);
                at = put(text, at, ":1\n");
            }
            r += 1;
        }
        t += 1;
    }
    at
}

/// `part` into `text` at `at` (if `text` is long enough: the sizing pass
/// passes an empty one); the new end.
const fn put(text: &mut [u8], at: usize, part: &str) -> usize {
    let bytes = part.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        if at + i < text.len() {
            text[at + i] = bytes[i];
        }
        i += 1;
    }
    at + bytes.len()
}

/// `M115`'s reply for `kind`, NUL-terminated (for [`crate::progmem::FlashStr`]).
const fn reply<const N: usize>(kind: Kind) -> [u8; N] {
    let mut text = [0u8; N];
    let len = write_reply(kind, &mut text);
    assert!(len + 1 == N);
    let mut i = 0;
    while i < len {
        assert!(text[i] > 0 && text[i] < 0x80, "M115 is ASCII");
        i += 1;
    }
    text
}

const fn reply_len(kind: Kind) -> usize {
    write_reply(kind, &mut []) + 1
}

macro_rules! reply_for {
    ($kind:expr) => {{
        #[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
        static TEXT: [u8; reply_len($kind)] = reply($kind);
        crate::progmem::FlashStr::from_static(&TEXT)
    }};
}

/// `M115`: the firmware line and the `Cap:` lines hosts read to decide
/// what to send (OctoPrint enables auto-reporting and the emergency parser
/// from these), for a `kind` machine. One string in flash per kind built.
pub fn capabilities(kind: Kind) -> crate::progmem::FlashStr {
    match kind {
        #[cfg(feature = "extrusion-line")]
        Kind::Line => reply_for!(Kind::Line),
        #[cfg(feature = "powder-bed")]
        Kind::Bed => reply_for!(Kind::Bed),
        _ => reply_for!(Kind::Printer),
    }
}
