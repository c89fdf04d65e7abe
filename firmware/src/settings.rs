//! The machine's tunable settings: what `M92`, `M201`, `M203`, `M204`,
//! `M205`, `M220`, `M221`, `M301`/`M304` and `M665`/`M666` change, `M503`
//! prints and `M500`/`M501` save and load (`storage`).
//!
//! Values are fixed point with three decimals ("milli" units) so that they
//! print back exactly as typed and need no float: steps/mm × 1000, mm/s ×
//! 1000 (= µm/s), mm/s² × 1000 (= µm/s²). Units are Marlin's.

use crate::reply::Fixed;
use ufmt::uWrite;

/// The axes with per-axis settings, X Y Z E (the executor's axes,
/// `machine::modal::AXIS_LETTERS`, are these). Declared here, the lowest
/// of the modules that use it: settings sit below the motion core and the
/// executor, and import neither.
pub const AXES: usize = 4;

/// What one row of the settings declaration holds: one `i32` (a slot of
/// the saved image) or an array of them, one slot each.
pub trait Slots {
    /// Slots this field takes in the saved image.
    const LEN: usize;
    fn slot(&self, index: usize) -> i32;
    fn set_slot(&mut self, index: usize, value: i32);
}

impl Slots for i32 {
    const LEN: usize = 1;
    fn slot(&self, _: usize) -> i32 {
        *self
    }
    fn set_slot(&mut self, _: usize, value: i32) {
        *self = value;
    }
}

impl<const N: usize> Slots for [i32; N] {
    const LEN: usize = N;
    fn slot(&self, index: usize) -> i32 {
        self.get(index).copied().unwrap_or(0)
    }
    fn set_slot(&mut self, index: usize, value: i32) {
        if let Some(slot) = self.get_mut(index) {
            *slot = value;
        }
    }
}

/// The settings, declared once: each row is a field of [`Settings`] (its
/// reader is the field itself), its place in the saved image (rows in
/// order, slots in order: [`field`] numbers the first slot of each, which
/// `M503` and the storage use) and, for the generic setting commands, the
/// command, letters, decimals and range that set it ([`words`]). A new
/// setting is a new row here (last, so stored images keep their layout;
/// bump `storage::LAYOUT_VERSION`), its default in [`Settings::prusa_i3`]
/// (or from the machine file, `machine::init_defaults`) and its line in
/// [`M503_PARTS`].
macro_rules! declare_settings {
    ($($(#[$doc:meta])* $name:ident / $number:ident: $ty:ty $(=> $code:literal $letters:literal $digits:literal $range:ident)?,)*) => {
        /// Every tunable value, as the setting commands change them and
        /// the storage keeps them (see [`declare_settings`]).
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        pub struct Settings {
            $($(#[$doc])* pub $name: $ty,)*
        }

        /// The first slot of each field in the saved image (the per-axis
        /// arrays take four each, X Y Z E).
        pub mod field {
            #![allow(unused)]
            use super::{Slots, AXES};
            declare_settings!(@numbers 0; $($number: $ty,)*);
        }

        /// Slots in the saved image.
        pub const SLOTS: usize = 0 $(+ <$ty as Slots>::LEN)*;

        /// The rows set by the generic setting commands: code, letters
        /// (one per slot), decimals, range, first slot.
        const WORD_ROWS: &[(u16, &[u8], u8, u8, usize)] =
            &[$($(($code, $letters, $digits, range::$range, field::$number),)?)*];

        impl Settings {
            /// Slot `index` of the saved image (0 past the last).
            pub fn slot(&self, index: usize) -> i32 {
                $(
                    if let Some(i) = index.checked_sub(field::$number).filter(|i| *i < <$ty as Slots>::LEN) {
                        return self.$name.slot(i);
                    }
                )*
                0
            }

            /// Set slot `index` (nothing past the last).
            pub fn set_slot(&mut self, index: usize, value: i32) {
                $(
                    if let Some(i) = index.checked_sub(field::$number).filter(|i| *i < <$ty as Slots>::LEN) {
                        return self.$name.set_slot(i, value);
                    }
                )*
            }
        }
    };
    (@numbers $at:expr; $number:ident: $ty:ty, $($rest:tt)*) => {
        pub const $number: usize = $at;
        declare_settings!(@numbers $number + <$ty as Slots>::LEN; $($rest)*);
    };
    (@numbers $at:expr;) => {};
}

// A row: `name / SLOT_NUMBER: type`, and for a setting the generic
// setting commands change, `=> code letters decimals range`: `M<code>`
// with one letter per slot sets it, the value in units of 10^-decimals,
// which must lie in the [`range`] named (values in milli-units, decimals
// 3, unless counted in whole units). Within a command, the words are read
// in row order (the first refused one is the error reported).
declare_settings! {
    /// `M92`: steps per mm × 1000, per axis X Y Z E.
    steps_per_mm_milli / STEPS_PER_MM: [i32; AXES] => 92 b"XYZE" 3 POSITIVE,
    /// `M203`: maximum feed rate per axis, µm/s.
    max_feed_um_per_s / MAX_FEED: [i32; AXES] => 203 b"XYZE" 3 POSITIVE,
    /// `M201`: maximum acceleration per axis, µm/s².
    max_accel_um_per_s2 / MAX_ACCEL: [i32; AXES] => 201 b"XYZE" 3 POSITIVE,
    /// `M204 P`: acceleration of printing moves, µm/s² (`M204 S` sets it
    /// and the travel acceleration: `machine::SETTING_WORDS`).
    print_accel_um_per_s2 / PRINT_ACCEL: i32 => 204 b"P" 3 POSITIVE,
    /// `M204 R`: acceleration of retracts (E-only moves), µm/s².
    retract_accel_um_per_s2 / RETRACT_ACCEL: i32 => 204 b"R" 3 POSITIVE,
    /// `M204 T`: acceleration of travel (non-extruding) moves, µm/s².
    travel_accel_um_per_s2 / TRAVEL_ACCEL: i32 => 204 b"T" 3 POSITIVE,
    /// `M205 J`: junction deviation, µm (Marlin's default 0.013 mm).
    junction_deviation_um / JUNCTION_DEVIATION: i32 => 205 b"J" 3 JUNCTION_DEVIATION,
    /// `M205 S`: minimum feed rate of printing moves, µm/s.
    min_feed_um_per_s / MIN_FEED: i32 => 205 b"S" 3 NOT_NEGATIVE,
    /// `M205 T`: minimum feed rate of travel moves, µm/s.
    min_travel_feed_um_per_s / MIN_TRAVEL_FEED: i32 => 205 b"T" 3 NOT_NEGATIVE,
    /// `M205 B`: minimum segment time, µs.
    min_segment_time_us / MIN_SEGMENT_TIME: i32 => 205 b"B" 0 SEGMENT_TIME,
    /// `M220 S`: feed-rate override, percent.
    feed_percent / FEED_PERCENT: i32 => 220 b"S" 0 PERCENT,
    /// `M221 S`: flow (extrusion) override, percent.
    flow_percent / FLOW_PERCENT: i32 => 221 b"S" 0 PERCENT,
    /// `M301 P I D` (hot end), Marlin's units × 10⁴ (see
    /// `thermal::Gains`); `M303 U1` sets them too. Default: the machine
    /// file's.
    hotend_pid / HOTEND_PID: [i32; 3],
    /// `M304 P I D`: the bed's gains, the same way.
    bed_pid / BED_PID: [i32; 3],
    /// `M665 L R H` (a delta): rod length, radius and homed height, µm
    /// (zeros on other machines). Default: the machine file's.
    delta_geometry_um / DELTA_GEOMETRY: [i32; 3],
    /// `M666 X Y Z` (a delta): each tower's endstop trim, µm.
    delta_trim_um / DELTA_TRIM: [i32; 3],
}

/// The value ranges of the setting words, by number in [`RANGES`].
pub mod range {
    /// Strictly positive (steps/mm, feed rates, accelerations).
    pub const POSITIVE: u8 = 0;
    /// Not negative (minimum feed rates).
    pub const NOT_NEGATIVE: u8 = 1;
    /// Junction deviation, µm: 0.001–0.3 mm.
    pub const JUNCTION_DEVIATION: u8 = 2;
    /// Minimum segment time, µs: up to 1 s.
    pub const SEGMENT_TIME: u8 = 3;
    /// Feed and flow percent, 10–999 as Marlin clamps.
    pub const PERCENT: u8 = 4;
}

/// The ranges [`range`] numbers, (min, max). By number rather than in
/// each [`Word`]: a word is copied into the executor's frame, which must
/// not grow (the Prusa i3's stack margin).
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
pub static RANGES: crate::progmem::Flash<[(i32, i32); 5]> =
    crate::progmem::Flash::new([(1, i32::MAX), (0, i32::MAX), (1, 300), (0, 1_000_000), (10, 999)]);

/// One word of a setting command: `M<code> <letter><value>` sets slot
/// `slot` to the value in units of 10^-`digits`, which must lie in
/// [`RANGES`]`[range]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Word {
    pub code: u16,
    pub letter: u8,
    pub digits: u8,
    pub range: u8,
    pub slot: u8,
}

/// Number of [`words`].
pub const WORDS: usize = {
    let mut n = 0;
    let mut r = 0;
    while r < WORD_ROWS.len() {
        n += WORD_ROWS[r].1.len();
        r += 1;
    }
    n
};

/// Every word of the setting commands, in row order, from the declaration.
pub const fn words() -> [Word; WORDS] {
    let mut words = [Word { code: 0, letter: 0, digits: 0, range: 0, slot: 0 }; WORDS];
    let (mut at, mut r) = (0, 0);
    while r < WORD_ROWS.len() {
        let (code, letters, digits, range, first) = WORD_ROWS[r];
        let mut k = 0;
        while k < letters.len() {
            assert!(first + k < u8::MAX as usize);
            words[at] = Word { code, letter: letters[k], digits, range, slot: (first + k) as u8 };
            at += 1;
            k += 1;
        }
        r += 1;
    }
    words
}

impl Default for Settings {
    fn default() -> Self {
        Self::prusa_i3()
    }
}

/// [`Settings::prusa_i3`] in flash: the defaults of everything the
/// machine file does not set.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
pub static PRUSA_I3: crate::progmem::Flash<Settings> = crate::progmem::Flash::new(Settings::prusa_i3());

impl Settings {
    /// SPEC §1: the Cartesian Prusa i3 on RAMPS (A4988 at 1/16, GT2 16-tooth
    /// pulleys: 100 steps/mm on X and Y; M8 Z rods: 400 steps/mm; E 93).
    pub const fn prusa_i3() -> Self {
        Self {
            steps_per_mm_milli: [100_000, 100_000, 400_000, 93_000],
            max_feed_um_per_s: [300_000, 300_000, 5_000, 25_000],
            max_accel_um_per_s2: [3_000_000, 3_000_000, 100_000, 10_000_000],
            print_accel_um_per_s2: 1_500_000,
            retract_accel_um_per_s2: 1_500_000,
            travel_accel_um_per_s2: 1_500_000,
            junction_deviation_um: 13,
            min_feed_um_per_s: 0,
            min_travel_feed_um_per_s: 0,
            min_segment_time_us: 20_000,
            feed_percent: 100,
            flow_percent: 100,
            // Marlin's DEFAULT_Kp/Ki/Kd and DEFAULT_bedKp/Ki/Kd.
            hotend_pid: [222_000, 10_800, 1_140_000],
            bed_pid: [100_000, 230, 3_054_000],
            delta_geometry_um: [0; 3],
            delta_trim_um: [0; 3],
        }
    }

    /// `M503`: the settings as the commands that would set them, in
    /// Marlin's layout: [`M503_SCRIPT`] read out, then each heater's gains.
    pub fn report<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        let mut at = 0;
        for (&[kp, ki, kd], code) in [(&self.hotend_pid, 301), (&self.bed_pid, 304)] {
            at = self.write_script(at, out)?;
            if let Some(gains) = crate::thermal::Gains::new(kp, ki, kd) {
                gains.write_as(code, out)?;
            }
        }
        out.write_str("\n")?;
        // A delta's geometry and trims (zeros on other machines).
        if self.delta_geometry_um[0] > 0 {
            for (title, code, letters, values) in [
                ("echo:; Delta settings (L<diagonal rod> R<radius> H<height>):\n", 665u16, b"LRH", &self.delta_geometry_um),
                ("echo:; Endstop adjustment:\n", 666, b"XYZ", &self.delta_trim_um),
            ] {
                out.write_str(title)?;
                ufmt::uwrite!(out, "echo:  M{}", crate::reply::Whole(code))?;
                for (&letter, &um) in letters.iter().zip(values) {
                    let hundredths = if um >= 0 { (um + 5) / 10 } else { (um - 5) / 10 };
                    ufmt::uwrite!(out, " {}{}", char::from(letter), Fixed { mantissa: hundredths, digits: 2 })?;
                }
                out.write_str("\n")?;
            }
        }
        Ok(())
    }

    /// [`M503_SCRIPT`] from byte `at` to the next NUL, with every field
    /// marker replaced by its value; returns where the next part starts.
    #[inline(never)]
    fn write_script<W: uWrite + ?Sized>(
        &self,
        mut at: usize,
        out: &mut W,
    ) -> Result<usize, W::Error> {
        while let Some(byte) = M503_SCRIPT.get(at) {
            at += 1;
            match byte {
                0 => break,
                // Stored without the `echo:` that follows it.
                b'\n' => {
                    out.write_char('\n')?;
                    crate::flash_str!(LINE_START).write_to(out)?;
                }
                1..=0x7F => out.write_char(char::from(byte))?,
                _ => {
                    let value = self.slot(usize::from(byte & FIELD_MASK));
                    let (mantissa, digits) = match byte & !FIELD_MASK {
                        // Marlin prints two decimals, rounded.
                        MILLI => (
                            if value >= 0 {
                                (value + 5) / 10
                            } else {
                                (value - 5) / 10
                            },
                            2,
                        ),
                        WHOLE => (value, 0),
                        // THOUSANDTHS
                        _ => (value, 3),
                    };
                    ufmt::uwrite!(out, "{}", Fixed { mantissa, digits })?;
                }
            }
        }
        Ok(at)
    }
}

/// In [`M503_SCRIPT`]: a byte with the top bit set stands for field
/// `byte & FIELD_MASK`, printed as `byte & !FIELD_MASK` says.
const FIELD_MASK: u8 = 0x1F;
/// A milli-unit value, shown with two decimals.
const MILLI: u8 = 0x80;
/// A whole number.
const WHOLE: u8 = 0xA0;
/// Thousandths, with three decimals.
const THOUSANDTHS: u8 = 0xC0;

/// `M503`'s text ([`M503_PARTS`]) with markers for the values (see
/// [`FIELD_MASK`]), in two parts ended by NUL: up to the hot end's gains, up to the bed's. Every
/// line after the first starts with `echo:`: stored without it, and
/// [`Settings::write_script`] writes it after each newline.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
static M503_SCRIPT: crate::progmem::Flash<[u8; SCRIPT_LEN]> = crate::progmem::Flash::new(script_bytes());

/// What every newline of [`M503_TEXT`] is followed by.
const LINE_START: &str = "echo:";

/// [`M503_TEXT`]'s length without the `echo:` after each newline.
const SCRIPT_LEN: usize = {
    let mut newlines = 0;
    let mut i = 0;
    while i < M503_TEXT.len() {
        if M503_TEXT[i] == b'\n' {
            newlines += 1;
        }
        i += 1;
    }
    M503_TEXT.len() - newlines * LINE_START.len()
};

const fn script_bytes() -> [u8; SCRIPT_LEN] {
    let mut bytes = [0; SCRIPT_LEN];
    let (mut from, mut to) = (0, 0);
    while from < M503_TEXT.len() {
        bytes[to] = M503_TEXT[from];
        to += 1;
        if M503_TEXT[from] == b'\n' {
            // Each newline is followed by `echo:` (checked here).
            let mut k = 0;
            while k < LINE_START.len() {
                assert!(M503_TEXT[from + 1 + k] == LINE_START.as_bytes()[k]);
                k += 1;
            }
            from += LINE_START.len();
        }
        from += 1;
    }
    bytes
}

/// `M503`'s text, a piece at a time: text, or a slot's value and how
/// it prints.
#[derive(Clone, Copy)]
enum Part {
    Text(&'static str),
    /// A milli-unit value, with two decimals (Marlin's, rounded).
    Milli(usize),
    /// A whole number.
    Whole(usize),
    /// A value in thousandths, with three decimals.
    Thousandths(usize),
    /// The end of a part of the script (a heater's gains follow).
    End,
}

const M503_PARTS: &[Part] = {
    use field::*;
    use Part::{End, Milli, Text, Thousandths, Whole};
    &[
        Text("echo:; Steps per unit:\necho:  M92 X"),
        Milli(STEPS_PER_MM),
        Text(" Y"),
        Milli(STEPS_PER_MM + 1),
        Text(" Z"),
        Milli(STEPS_PER_MM + 2),
        Text(" E"),
        Milli(STEPS_PER_MM + 3),
        Text("\necho:; Max feedrates (units/s):\necho:  M203 X"),
        Milli(MAX_FEED),
        Text(" Y"),
        Milli(MAX_FEED + 1),
        Text(" Z"),
        Milli(MAX_FEED + 2),
        Text(" E"),
        Milli(MAX_FEED + 3),
        Text("\necho:; Max Acceleration (units/s2):\necho:  M201 X"),
        Milli(MAX_ACCEL),
        Text(" Y"),
        Milli(MAX_ACCEL + 1),
        Text(" Z"),
        Milli(MAX_ACCEL + 2),
        Text(" E"),
        Milli(MAX_ACCEL + 3),
        Text("\necho:; Acceleration (units/s2) (P<print-accel> R<retract-accel> T<travel-accel>):\necho:  M204 P"),
        Milli(PRINT_ACCEL),
        Text(" R"),
        Milli(RETRACT_ACCEL),
        Text(" T"),
        Milli(TRAVEL_ACCEL),
        Text("\necho:; Advanced (B<min_segment_time_us> S<min_feedrate> T<min_travel_feedrate> J<junc_dev>):\necho:  M205 B"),
        Whole(MIN_SEGMENT_TIME),
        Text(" S"),
        Milli(MIN_FEED),
        Text(" T"),
        Milli(MIN_TRAVEL_FEED),
        Text(" J"),
        Thousandths(JUNCTION_DEVIATION),
        Text("\necho:; Feedrate and flow:\necho:  M220 S"),
        Whole(FEED_PERCENT),
        Text("\necho:  M221 S"),
        Whole(FLOW_PERCENT),
        Text("\necho:; Hotend PID:\necho:  "),
        End,
        Text("\necho:; Bed PID:\necho:  "),
        End,
    ]
};

/// [`M503_PARTS`] as bytes (`bytes` long enough, or empty to measure);
/// the length.
const fn m503_bytes(bytes: &mut [u8]) -> usize {
    let mut at = 0;
    let mut i = 0;
    while i < M503_PARTS.len() {
        let marker = match M503_PARTS[i] {
            Part::Text(text) => {
                let text = text.as_bytes();
                let mut k = 0;
                while k < text.len() {
                    assert!(text[k] > 0 && text[k] < 0x80);
                    if at + k < bytes.len() {
                        bytes[at + k] = text[k];
                    }
                    k += 1;
                }
                at += text.len();
                i += 1;
                continue;
            }
            Part::Milli(slot) => MILLI | marker_slot(slot),
            Part::Whole(slot) => WHOLE | marker_slot(slot),
            Part::Thousandths(slot) => THOUSANDTHS | marker_slot(slot),
            Part::End => 0,
        };
        if at < bytes.len() {
            bytes[at] = marker;
        }
        at += 1;
        i += 1;
    }
    at
}

const fn marker_slot(slot: usize) -> u8 {
    assert!(slot <= FIELD_MASK as usize, "a slot past the M503 script's markers");
    slot as u8
}

const M503_LEN: usize = m503_bytes(&mut []);
const M503_BYTES: [u8; M503_LEN] = {
    let mut bytes = [0; M503_LEN];
    m503_bytes(&mut bytes);
    bytes
};
const M503_TEXT: &[u8] = &M503_BYTES;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slot_numbers_reach_their_fields_in_declaration_order() {
        let mut settings = Settings::prusa_i3();
        for index in 0..SLOTS {
            settings.set_slot(index, -1 - index as i32);
        }
        settings.set_slot(SLOTS, 99);
        assert_eq!(settings.steps_per_mm_milli, [-1, -2, -3, -4]);
        assert_eq!(settings.max_feed_um_per_s, [-5, -6, -7, -8]);
        assert_eq!(settings.max_accel_um_per_s2, [-9, -10, -11, -12]);
        assert_eq!(settings.print_accel_um_per_s2, -13);
        assert_eq!(settings.retract_accel_um_per_s2, -14);
        assert_eq!(settings.travel_accel_um_per_s2, -15);
        assert_eq!(settings.junction_deviation_um, -16);
        assert_eq!(settings.min_feed_um_per_s, -17);
        assert_eq!(settings.min_travel_feed_um_per_s, -18);
        assert_eq!(settings.min_segment_time_us, -19);
        assert_eq!(settings.feed_percent, -20);
        assert_eq!(settings.flow_percent, -21);
        assert_eq!(settings.hotend_pid, [-22, -23, -24]);
        assert_eq!(settings.bed_pid, [-25, -26, -27]);
        assert_eq!(settings.delta_geometry_um, [-28, -29, -30]);
        assert_eq!(settings.delta_trim_um, [-31, -32, -33]);
        assert_eq!((0..SLOTS).map(|i| settings.slot(i)).collect::<std::vec::Vec<_>>(), (1..=33).map(|i| -i).collect::<std::vec::Vec<_>>());
        assert_eq!(settings.slot(SLOTS), 0);
    }

    #[test]
    fn the_saved_image_holds_thirty_three_slots() {
        // storage::LAYOUT_VERSION 3: a change here is a new layout.
        assert_eq!(SLOTS, 33);
        assert_eq!((field::HOTEND_PID, field::BED_PID, field::DELTA_GEOMETRY, field::DELTA_TRIM), (21, 24, 27, 30));
    }
}
