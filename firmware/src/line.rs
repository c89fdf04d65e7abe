//! Assembling received bytes into lines.
//!
//! A line ends at `\n` or `\r` (so `\r\n` works; the empty line between them
//! is skipped, as Marlin does). The buffer is fixed; a line that does not fit
//! is not truncated and executed (a truncated `G1 X100` could be `G1 X1`) but
//! reported as [`Line::TooLong`] once its end arrives. A line during which the
//! receive ring lost bytes is reported as [`Line::Damaged`]: it must never be
//! executed, because what is left of it may be a different, valid command.

/// Longest line accepted, in bytes, without its terminator (Marlin: 96).
pub const MAX_LINE: usize = 96;

/// One complete line, as handed to the protocol layer.
#[derive(Debug, PartialEq, Eq)]
pub enum Line<'a> {
    /// A line that arrived intact (may still be malformed G-code).
    Text(&'a [u8]),
    /// The line was longer than [`MAX_LINE`]; its bytes are gone.
    TooLong,
    /// Bytes of this line were lost in reception (ring or UART overrun).
    Damaged,
}

/// Collects bytes until a line terminator.
pub struct LineAssembler {
    buffer: heapless::Vec<u8, MAX_LINE>,
    /// The buffer holds a line already handed out; clear it on the next byte.
    handed_out: bool,
    overflowed: bool,
    damaged: bool,
}

impl Default for LineAssembler {
    fn default() -> Self {
        Self::new()
    }
}

impl LineAssembler {
    pub const fn new() -> Self {
        Self { buffer: heapless::Vec::new(), handed_out: false, overflowed: false, damaged: false }
    }

    /// Mark the line being received as damaged (bytes were lost).
    pub fn mark_damaged(&mut self) {
        self.damaged = true;
    }

    /// Feed one byte; returns a line when `byte` terminates one.
    pub fn push(&mut self, byte: u8) -> Option<Line<'_>> {
        if core::mem::take(&mut self.handed_out) {
            self.buffer.clear();
        }
        if byte == crate::rx::LOST_BYTES {
            // Bytes were lost right here (see `rx::LOST_BYTES`).
            self.damaged = true;
            return None;
        }
        if byte != b'\n' && byte != b'\r' {
            if self.buffer.push(byte).is_err() {
                self.overflowed = true;
            }
            return None;
        }
        let overflowed = core::mem::take(&mut self.overflowed);
        let damaged = core::mem::take(&mut self.damaged);
        if damaged || overflowed || self.buffer.is_empty() {
            self.buffer.clear();
            return if damaged {
                Some(Line::Damaged)
            } else if overflowed {
                Some(Line::TooLong)
            } else {
                None
            };
        }
        self.handed_out = true;
        Some(Line::Text(&self.buffer))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed<'a>(assembler: &'a mut LineAssembler, bytes: &[u8]) -> Option<Line<'a>> {
        let (last, head) = bytes.split_last().unwrap();
        for b in head {
            assert_eq!(assembler.push(*b), None);
        }
        assembler.push(*last)
    }

    #[test]
    fn a_newline_completes_a_line() {
        let mut a = LineAssembler::new();
        assert_eq!(feed(&mut a, b"M105\n"), Some(Line::Text(b"M105")));
        assert_eq!(feed(&mut a, b"M114\r"), Some(Line::Text(b"M114")));
    }

    #[test]
    fn crlf_gives_one_line_and_empty_lines_are_skipped() {
        let mut a = LineAssembler::new();
        assert_eq!(feed(&mut a, b"G28\r"), Some(Line::Text(b"G28")));
        assert_eq!(a.push(b'\n'), None);
        assert_eq!(a.push(b'\n'), None);
    }

    #[test]
    fn a_line_longer_than_the_buffer_is_reported_not_truncated() {
        let mut a = LineAssembler::new();
        let mut long = [b'X'; MAX_LINE + 200];
        *long.last_mut().unwrap() = b'\n';
        assert_eq!(feed(&mut a, &long), Some(Line::TooLong));
        // The next line is received normally.
        assert_eq!(feed(&mut a, b"M115\n"), Some(Line::Text(b"M115")));
    }

    #[test]
    fn a_line_of_exactly_the_buffer_size_is_accepted() {
        let mut a = LineAssembler::new();
        let mut line = [b'1'; MAX_LINE + 1];
        line[MAX_LINE] = b'\n';
        assert_eq!(feed(&mut a, &line), Some(Line::Text(&[b'1'; MAX_LINE])));
    }

    /// The receive ring's marker damages the line it falls in, and only
    /// that one: the lines before and after are intact.
    #[test]
    fn the_lost_bytes_marker_damages_exactly_the_line_it_falls_in() {
        let mut a = LineAssembler::new();
        assert_eq!(feed(&mut a, b"G1 X1\n"), Some(Line::Text(b"G1 X1")));
        assert_eq!(feed(&mut a, b"G1 X\x002\n"), Some(Line::Damaged));
        assert_eq!(feed(&mut a, b"G1 X3\n"), Some(Line::Text(b"G1 X3")));
    }

    #[test]
    fn a_line_that_lost_bytes_is_damaged() {
        let mut a = LineAssembler::new();
        a.push(b'G');
        a.mark_damaged();
        assert_eq!(feed(&mut a, b"1 X10\n"), Some(Line::Damaged));
        assert_eq!(feed(&mut a, b"M105\n"), Some(Line::Text(b"M105")));
    }
}
