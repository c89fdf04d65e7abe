//! The emergency parser: `M112`, `M108` and `M410` recognised byte by byte
//! in the receive interrupt, so they act even when the command queue is full
//! or a command is blocking (Marlin's EMERGENCY_PARSER).
//!
//! A command counts only at the start of a line, optionally after a line
//! number (`N12 M112*..`), and only when its number ends there (`M1120` is
//! not `M112`). The line is still delivered to the normal path afterwards,
//! where it is acknowledged like any other line.
//!
//! The scanner is a handful of states and one byte of digits: bounded, O(1)
//! per byte, safe for an interrupt.

/// What the interrupt must do at once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Emergency {
    /// `M112`: kill. Heaters off, motors off, halt.
    Kill,
    /// `M108`: stop waiting for heaters (and other blocking waits).
    CancelWait,
    /// `M410`: quick stop: abandon all queued motion.
    QuickStop,
}

impl Emergency {
    /// This emergency as a bit of [`Pending`].
    pub const fn bit(self) -> u8 {
        match self {
            Self::Kill => 1,
            Self::CancelWait => 2,
            Self::QuickStop => 4,
        }
    }
}

/// Emergencies seen by the interrupt and not yet handled by the main loop,
/// one bit each (a `u8` so an interrupt can set it in one store).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Pending(pub u8);

impl Pending {
    pub const NONE: Self = Self(0);

    pub fn with(self, emergency: Emergency) -> Self {
        Self(self.0 | emergency.bit())
    }

    pub fn contains(self, emergency: Emergency) -> bool {
        self.0 & emergency.bit() != 0
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// At the start of a line, before any word.
    LineStart,
    /// Inside the `N` line number.
    LineNumber,
    /// After the line number, waiting for `M`.
    AfterLineNumber,
    /// Reading the digits after `M`.
    Code { value: u16, digits: u8 },
    /// Nothing more to see on this line.
    Ignore,
}

/// Byte-by-byte recogniser of the emergency commands.
#[derive(Clone, Copy, Debug)]
pub struct EmergencyScanner {
    state: State,
}

impl Default for EmergencyScanner {
    fn default() -> Self {
        Self::new()
    }
}

impl EmergencyScanner {
    pub const fn new() -> Self {
        Self { state: State::LineStart }
    }

    /// Feed one received byte; returns the emergency it completes, if any.
    pub fn push(&mut self, byte: u8) -> Option<Emergency> {
        let (next, found) = match (self.state, byte) {
            (_, b'\n' | b'\r') => {
                let found = self.finish();
                (State::LineStart, found)
            }
            (State::LineStart, b' ' | b'\t') => (State::LineStart, None),
            (State::LineStart, b'N' | b'n') => (State::LineNumber, None),
            (State::LineStart | State::AfterLineNumber, b'M' | b'm') => (State::Code { value: 0, digits: 0 }, None),
            (State::LineNumber, b'0'..=b'9' | b'-') => (State::LineNumber, None),
            (State::LineNumber, b' ' | b'\t') => (State::AfterLineNumber, None),
            (State::AfterLineNumber, b' ' | b'\t') => (State::AfterLineNumber, None),
            (State::Code { value, digits }, b'0'..=b'9') if digits < 3 => {
                (State::Code { value: value * 10 + u16::from(byte - b'0'), digits: digits + 1 }, None)
            }
            (State::Code { .. }, b' ' | b'\t' | b'*' | b';') => {
                let found = self.finish();
                (State::Ignore, found)
            }
            _ => (State::Ignore, None),
        };
        self.state = next;
        found
    }

    fn finish(&self) -> Option<Emergency> {
        match self.state {
            State::Code { value: 112, digits: 3 } => Some(Emergency::Kill),
            State::Code { value: 108, digits: 3 } => Some(Emergency::CancelWait),
            State::Code { value: 410, digits: 3 } => Some(Emergency::QuickStop),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    fn scan(text: &[u8]) -> Vec<Emergency> {
        let mut scanner = EmergencyScanner::new();
        text.iter().filter_map(|&b| scanner.push(b)).collect()
    }

    #[test]
    fn the_three_commands_are_recognised_at_the_end_of_their_number() {
        assert_eq!(scan(b"M112\n"), [Emergency::Kill]);
        assert_eq!(scan(b"M108\n"), [Emergency::CancelWait]);
        assert_eq!(scan(b"m410\r"), [Emergency::QuickStop]);
    }

    #[test]
    fn numbered_and_checksummed_lines_count() {
        assert_eq!(scan(b"N42 M112*22\n"), [Emergency::Kill]);
        assert_eq!(scan(b"  M112 ; stop\n"), [Emergency::Kill]);
    }

    #[test]
    fn longer_numbers_and_other_positions_do_not_count() {
        assert!(scan(b"M1120\n").is_empty());
        assert!(scan(b"M11\n").is_empty());
        assert!(scan(b"G1 X1 M112\n").is_empty());
        assert!(scan(b"M117 M112\n").is_empty());
        assert!(scan(b"; M112\n").is_empty());
    }

    #[test]
    fn each_line_starts_afresh() {
        assert_eq!(scan(b"G28\nM112\nM105\nM410\n"), [Emergency::Kill, Emergency::QuickStop]);
    }
}
