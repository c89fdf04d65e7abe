//! The G-code lexer and parser: one line of text → one [`Command`].
//!
//! Grammar (RS274/NGC as RepRap firmware speaks it):
//! - a word is a letter and a number: `X-1.25`; letters may be lower case;
//!   whitespace may stand anywhere between words (`G1X10 Y 5` is fine);
//! - `;` starts a comment that runs to the end of the line; `( … )` is a
//!   comment inside the line and must be closed;
//! - the first word names the command (`G`, `M` or `T` and a whole number);
//!   a line that starts with an axis word repeats the modal motion (Grbl);
//! - a letter with no number is a flag (`G28 X`); commands that need a value
//!   report [`ParseError::WordWithoutValue`] when they read it;
//! - `M117`/`M118` take the rest of the line as text;
//! - CAM output puts several codes on one line (`G17 G90`, `G91 G0 Z5`,
//!   `S10000 M3`, Grbl's "block"): the codes that only set a mode
//!   ([`is_mode_setting`]: plane, units, distance, feed mode, work
//!   coordinates, cancels, spindle and coolant) go into
//!   [`Command::settings`], applied before the command; the one code that
//!   acts (a motion, `G28`, `G92`, `M2`, …) is the command. A line of only
//!   `%` (a CAM program's start/end marker) is empty. `G53` (this line's
//!   move in machine coordinates) travels the same way, though it holds for
//!   its own line only.
//!
//! Line numbers (`N`) and checksums (`*`) belong to the host protocol and are
//! removed by [`crate::protocol`] before this parser sees the line.
//!
//! Nothing here allocates, and no float is used (see [`number`]).

pub mod number;

pub use number::{Decimal, NumberError};

/// Most parameter words one command may carry (`G1 X Y Z E F` is 5).
pub const MAX_WORDS: usize = 12;
/// Most mode-setting codes one line may carry besides its command.
pub const MAX_SETTINGS: usize = 6;

/// Why a line is not valid G-code. `repr(u8)`: the variant's number is
/// its first byte, which the error messages index by (`machine::error`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum ParseError {
    /// A number that cannot be read (`X1.2.3`, `X-`, `x1e30`).
    BadNumber(u8),
    /// A number whose integer part does not fit (`X99999999999`).
    NumberOutOfRange(u8),
    /// A parameter without the value its command needs (`G1 X`).
    WordWithoutValue(u8),
    /// A `(` comment that is never closed.
    UnterminatedComment,
    /// A byte that is neither a letter, a number, a space nor a comment
    /// (NUL, non-ASCII, `#`, ...).
    UnexpectedByte(u8),
    /// The same letter twice (`G1 X1 X2`).
    DuplicateWord(u8),
    /// More than [`MAX_WORDS`] parameters.
    TooManyWords,
    /// The command number is not a whole number in range (`G1.5`, `M-3`).
    BadCommandNumber,
    /// Only comments and spaces: nothing to execute.
    Empty,
    /// More mode-setting codes on one line than [`MAX_SETTINGS`].
    TooManyCodes,
}

/// Codes that only set a mode (Grbl's non-motion modal groups, and spindle
/// and coolant): several may share a line with one command. Out of line:
/// the parser and the executor share one copy of the range checks.
#[inline(never)]
pub fn is_mode_setting(code: Code) -> bool {
    // One bit per code, G0–G95 then M0–M15, in flash: the range compares
    // came to 124 bytes.
    let bit = match code {
        Code::G(n) if n < 96 => n,
        Code::M(n) if n < 16 => 96 + n,
        _ => return false,
    };
    MODE_SETTING_MAP.get(usize::from(bit >> 3)).is_some_and(|byte| byte >> (bit & 7) & 1 != 0)
}

/// G17–G21, G40, G49, G53–G59, G61, G64, G80, G90, G91, G93, G94; M3–M5,
/// M7–M9 (see [`is_mode_setting`]).
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
static MODE_SETTING_MAP: crate::progmem::Flash<[u8; 14]> = crate::progmem::Flash::new({
    let g: [(u16, u16); 11] =
        [(17, 21), (40, 40), (49, 49), (53, 59), (61, 61), (64, 64), (80, 80), (90, 91), (93, 94), (96 + 3, 96 + 5), (96 + 7, 96 + 9)];
    let mut map = [0u8; 14];
    let mut i = 0;
    while i < g.len() {
        let mut n = g[i].0;
        while n <= g[i].1 {
            map[(n >> 3) as usize] |= 1 << (n & 7);
            n += 1;
        }
        i += 1;
    }
    map
});

/// A parameter word; `value` is `None` for a bare flag (`G28 X`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Word {
    pub letter: u8,
    pub value: Option<Decimal>,
}

/// What the line asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Code {
    G(u16),
    M(u16),
    T(u16),
    /// Axis words with no command: repeat the modal motion (`G0`/`G1`).
    Modal,
    /// A G or M code with a subcode or a negative number (`M862.3`):
    /// no command of ours; answered as an unknown command.
    Other,
}

/// One parsed line.
///
/// `repr(C)`, the words last: the code and the settings, read where the
/// line is executed, stay within the first 63 bytes of a frame holding
/// the command, which the AVR reaches in one instruction.
#[derive(Clone, Debug, PartialEq, Eq)]
#[repr(C)]
pub struct Command {
    pub code: Code,
    /// Mode-setting codes that came on the same line, in line order; they
    /// apply before `code` (see the module docs).
    pub settings: heapless::Vec<Code, MAX_SETTINGS>,
    words: heapless::Vec<Word, MAX_WORDS>,
}

impl ParseError {
    /// The variant's number, in declaration order.
    pub fn number(self) -> u8 {
        // SAFETY: a `repr(u8)` enum begins with its `u8` discriminant,
        // whatever the variant (RFC 2195), so the first byte is initialised.
        unsafe { *(&self as *const Self).cast::<u8>() }
    }
}

impl Command {
    pub fn new(code: Code) -> Self {
        Self { code, words: heapless::Vec::new(), settings: heapless::Vec::new() }
    }

    /// On the AVR, an empty command in the one `static` the main loop
    /// parses into (the executor's line, the protocol's `M110` check):
    /// on the stack, the command made the frames that held it larger than
    /// the 63 bytes the AVR reaches in one instruction, and every access
    /// beyond several instructions longer. Static RAM grows by a command,
    /// the deepest stack (the executor's) shrinks by one.
    ///
    /// # Safety
    /// Main loop only, and the command returned by the previous call must
    /// no longer be in use (the executor's and the protocol's uses never
    /// overlap: lines are received and executed one after the other).
    #[cfg(target_arch = "avr")]
    pub(crate) unsafe fn scratch() -> &'static mut Self {
        static mut SCRATCH: core::mem::MaybeUninit<Command> = core::mem::MaybeUninit::uninit();
        // SAFETY: see above.
        unsafe { (*core::ptr::addr_of_mut!(SCRATCH)).write(Self::new(Code::Other)) }
    }

    /// Add a word (tests and generated commands).
    pub fn with(mut self, letter: u8, value: Decimal) -> Self {
        let _ = self.words.push(Word { letter, value: Some(value) });
        self
    }

    /// Whether `letter` appears, with or without a value.
    #[inline(never)]
    pub fn has(&self, letter: u8) -> bool {
        self.words.iter().any(|w| w.letter == letter)
    }

    /// The value of `letter`: `Ok(None)` if absent, an error if it is a flag.
    #[inline(never)]
    pub fn value(&self, letter: u8) -> Result<Option<Decimal>, ParseError> {
        match self.words.iter().find(|w| w.letter == letter) {
            None => Ok(None),
            Some(Word { value: Some(v), .. }) => Ok(Some(*v)),
            Some(Word { value: None, .. }) => Err(ParseError::WordWithoutValue(letter)),
        }
    }

    pub fn words(&self) -> &[Word] {
        &self.words
    }
}

/// Parse one line (without `N` and `*checksum`) into a command.
pub fn parse(text: &[u8]) -> Result<Command, ParseError> {
    let mut command = Command::new(Code::Other);
    parse_into(text, &mut command).map(|()| command)
}

/// [`parse`] into `command` (whatever it held is replaced; after an error
/// it holds part of the line). The executor parses into its own frame:
/// returning the command by value built it in this function's frame and
/// copied it out, and on the AVR a frame that large made most accesses
/// to it several instructions longer.
#[inline(never)]
pub fn parse_into(text: &[u8], command: &mut Command) -> Result<(), ParseError> {
    command.words.clear();
    command.settings.clear();
    if text.iter().filter(|b| **b != b' ' && **b != b'\t').eq(b"%".iter()) {
        return Err(ParseError::Empty);
    }
    let mut lexer = Lexer { text, index: 0 };
    let first = lexer.next_word()?.ok_or(ParseError::Empty)?;
    let code = match first.letter {
        b'G' | b'M' | b'T' => {
            let value = first.value.ok_or(ParseError::WordWithoutValue(first.letter))?;
            let number = code_number(value).ok_or(ParseError::BadCommandNumber)?;
            match first.letter {
                b'G' => Code::G(number),
                b'M' => Code::M(number),
                _ => Code::T(number),
            }
        }
        _ => Code::Modal,
    };
    command.code = code;
    if matches!(code, Code::M(117) | Code::M(118)) {
        return Ok(()); // the rest is free text
    }
    if code == Code::Modal {
        command.words.push(first).map_err(|_| ParseError::TooManyWords)?;
    }
    while let Some(word) = lexer.next_word()? {
        if let Some(extra) = command_code(word) {
            take_code(command, extra)?;
            continue;
        }
        if command.has(word.letter) {
            return Err(ParseError::DuplicateWord(word.letter));
        }
        command.words.push(word).map_err(|_| ParseError::TooManyWords)?;
    }
    Ok(())
}

/// A code's number: whole, non-negative and within `u16`.
fn code_number(value: Decimal) -> Option<u16> {
    if value.fraction_digits() != 0 || value.is_negative() {
        return None;
    }
    u16::try_from(value.mantissa()).ok()
}

/// A `G`/`M` word that names a code (whole, non-negative).
fn command_code(word: Word) -> Option<Code> {
    let number = code_number(word.value?)?;
    match word.letter {
        b'G' => Some(Code::G(number)),
        b'M' => Some(Code::M(number)),
        _ => None,
    }
}

/// A second code on the line: a mode setting joins `settings` (`S10000 M3`
/// is the modal line `S10000` with `M3` applied first); a code that acts
/// becomes the command when the line had none and no axis word (`F300
/// G28`), or when the first code only set a mode (`G91 G0 Z5`). Two codes
/// that both act (`G28 G92`) keep Marlin's reading: the second is an
/// ignored word.
fn take_code(command: &mut Command, extra: Code) -> Result<(), ParseError> {
    if is_mode_setting(extra) {
        return command.settings.push(extra).map_err(|_| ParseError::TooManyCodes);
    }
    if command.code == Code::Modal && !command.words.iter().any(|w| matches!(w.letter, b'X' | b'Y' | b'Z' | b'E' | b'A' | b'B' | b'C')) {
        command.code = extra;
    } else if is_mode_setting(command.code) {
        command.settings.push(command.code).map_err(|_| ParseError::TooManyCodes)?;
        command.code = extra;
    } else {
        let letter = if matches!(extra, Code::G(_)) { b'G' } else { b'M' };
        if !command.has(letter) {
            let number = match extra {
                Code::G(n) | Code::M(n) => n,
                _ => 0,
            };
            command.words.push(Word { letter, value: Some(Decimal::from_int(i32::from(number))) }).map_err(|_| ParseError::TooManyWords)?;
        }
    }
    Ok(())
}

/// Only the command code of a line (its first word), for lines whose
/// arguments do not parse: `M115 U3.13.0` is still an `M115`, and
/// `M862.3 P "MK3S"` is [`Code::Other`]. `None` for an empty line or one
/// that does not start with a word.
pub fn code_of(text: &[u8]) -> Option<Code> {
    let mut lexer = Lexer { text, index: 0 };
    let first = match lexer.next_word() {
        Ok(Some(word)) => word,
        Ok(None) => return None,
        Err(_) => return match text.iter().find(|b| **b != b' ') {
            Some(b'G' | b'g' | b'M' | b'm') => Some(Code::Other),
            _ => None,
        },
    };
    let number = first.value.filter(|v| v.fraction_digits() == 0 && !v.is_negative()).and_then(|v| u16::try_from(v.mantissa()).ok());
    Some(match (first.letter, number) {
        (b'G', Some(n)) => Code::G(n),
        (b'M', Some(n)) => Code::M(n),
        (b'T', Some(n)) => Code::T(n),
        (b'G' | b'M' | b'T', None) => Code::Other,
        _ => Code::Modal,
    })
}

/// The free text of an `M117`/`M118` line: everything after the code.
pub fn text_argument(text: &[u8]) -> &[u8] {
    let mut index = 0;
    // Skip spaces, the letter, and the code's digits, then one space.
    while index < text.len() && text[index] == b' ' {
        index += 1;
    }
    index += 1;
    while index < text.len() && text[index].is_ascii_digit() {
        index += 1;
    }
    if index < text.len() && text[index] == b' ' {
        index += 1;
    }
    let rest = &text[index.min(text.len())..];
    match rest.iter().position(|&b| b == b';') {
        Some(end) => &rest[..end],
        None => rest,
    }
}

struct Lexer<'a> {
    text: &'a [u8],
    index: usize,
}

impl Lexer<'_> {
    /// Skip spaces and comments; `Ok(None)` at the end of the line.
    fn skip_blank(&mut self) -> Result<Option<u8>, ParseError> {
        loop {
            let Some(&byte) = self.text.get(self.index) else { return Ok(None) };
            match byte {
                b' ' | b'\t' => self.index += 1,
                b';' => {
                    self.index = self.text.len();
                    return Ok(None);
                }
                b'(' => {
                    let rest = &self.text[self.index..];
                    let close = rest.iter().position(|&b| b == b')').ok_or(ParseError::UnterminatedComment)?;
                    self.index += close + 1;
                }
                _ => return Ok(Some(byte)),
            }
        }
    }

    fn next_word(&mut self) -> Result<Option<Word>, ParseError> {
        let Some(byte) = self.skip_blank()? else { return Ok(None) };
        if !byte.is_ascii_alphabetic() {
            return Err(ParseError::UnexpectedByte(byte));
        }
        let letter = byte.to_ascii_uppercase();
        self.index += 1;
        // Spaces may separate a letter from its number (`X 10`).
        while matches!(self.text.get(self.index), Some(b' ' | b'\t')) {
            self.index += 1;
        }
        let starts_number = matches!(self.text.get(self.index), Some(b'0'..=b'9' | b'-' | b'+' | b'.'));
        if !starts_number {
            return Ok(Some(Word { letter, value: None }));
        }
        match Decimal::parse(&self.text[self.index..]) {
            Ok((value, used)) => {
                self.index += used;
                Ok(Some(Word { letter, value: Some(value) }))
            }
            Err(NumberError::Malformed) => Err(ParseError::BadNumber(letter)),
            Err(NumberError::OutOfRange) => Err(ParseError::NumberOutOfRange(letter)),
        }
    }
}

#[cfg(test)]
mod tests;
