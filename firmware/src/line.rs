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
    /// `numbered`: its first non-blank byte was `N` (only then may the
    /// reply ask for a resend: a host never resends what it did not number).
    TooLong { numbered: bool },
    /// Bytes of this line were lost in reception (ring or UART overrun).
    /// `numbered`: whether its first non-blank byte was `N`; `None` when
    /// the loss came before any byte of it survived.
    Damaged { numbered: Option<bool> },
    /// A numbered (or checksummed) line whose end never came: no byte for
    /// [`LINE_END_TIMEOUT_MS`] (see [`LineAssembler::abandon`]).
    Unterminated { numbered: bool },
}

/// How long a started line that carries a line number or a checksum may
/// wait for its next byte before it is refused: a host sends such a line
/// in one go (8 ms for the longest at 115200 baud) and then waits for its
/// `ok`, so a line end lost to noise would otherwise hang both sides (a
/// person typing in a terminal types no `N…*…` lines; their lines wait).
pub const LINE_END_TIMEOUT_MS: u32 = 250;

/// Collects bytes until a line terminator.
pub struct LineAssembler {
    buffer: heapless::Vec<u8, MAX_LINE>,
    /// The buffer holds a line already handed out; clear it on the next byte.
    handed_out: bool,
    overflowed: bool,
    damaged: bool,
    /// First non-blank byte of the line being received (0: none yet).
    first: u8,
    /// The line being received reached a `;` comment outside `( … )`: what
    /// follows it is never executed, so bytes that do not fit are dropped
    /// instead of refusing the line (Marlin ignores comments whatever
    /// their length).
    in_comment: bool,
    /// Inside a `( … )` comment (a `;` there starts nothing).
    in_paren: bool,
    /// Drop bytes up to the next line end: the start of this line was
    /// discarded (see [`LineAssembler::discard_to_line_end`]).
    discarding: bool,
}

impl Default for LineAssembler {
    fn default() -> Self {
        Self::new()
    }
}

impl LineAssembler {
    pub const fn new() -> Self {
        Self {
            buffer: heapless::Vec::new(),
            handed_out: false,
            overflowed: false,
            damaged: false,
            first: 0,
            in_comment: false,
            in_paren: false,
            discarding: false,
        }
    }

    /// Whether the line being received carries a number or a checksum, so
    /// it may be given up when its end does not come.
    pub fn holds_protocol_line(&self) -> bool {
        !self.handed_out && !self.discarding && (matches!(self.first, b'N' | b'n') || self.buffer.contains(&b'*'))
    }

    /// Give up the line being received (its end never came): the bytes
    /// are dropped, and the line is reported so that it gets its reply.
    pub fn abandon(&mut self) -> Line<'static> {
        let numbered = matches!(self.first, b'N' | b'n');
        self.buffer.clear();
        self.overflowed = false;
        self.damaged = false;
        self.first = 0;
        self.in_comment = false;
        self.in_paren = false;
        Line::Unterminated { numbered }
    }

    /// Drop everything up to and including the next line end, silently:
    /// the caller threw away the start of the line being received (after a
    /// resend request, the rest of a line the host sent before it saw the
    /// request is not a line of its own).
    pub fn discard_to_line_end(&mut self) {
        self.discarding = true;
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
        let terminator = byte == b'\n' || byte == b'\r';
        if self.discarding {
            self.discarding = !terminator;
            return None;
        }
        if byte == crate::rx::LOST_BYTES {
            // Bytes were lost right here (see `rx::LOST_BYTES`).
            self.damaged = true;
            return None;
        }
        if !terminator {
            if self.first == 0 && byte != b' ' && byte != b'\t' {
                // `first` stays 0 after a loss, so a line whose start was
                // lost does not claim to be unnumbered.
                self.first = if self.damaged { 1 } else { byte };
            }
            match byte {
                b'(' if !self.in_comment => self.in_paren = true,
                b')' => self.in_paren = false,
                b';' if !self.in_paren => self.in_comment = true,
                _ => {}
            }
            if self.buffer.push(byte).is_err() && !self.in_comment {
                self.overflowed = true;
            }
            return None;
        }
        let overflowed = core::mem::take(&mut self.overflowed);
        let damaged = core::mem::take(&mut self.damaged);
        let first = core::mem::take(&mut self.first);
        self.in_comment = false;
        self.in_paren = false;
        let numbered = matches!(first, b'N' | b'n');
        if damaged || overflowed || self.buffer.is_empty() {
            self.buffer.clear();
            return if damaged {
                Some(Line::Damaged { numbered: if first == 0 || first == 1 { None } else { Some(numbered) } })
            } else if overflowed {
                Some(Line::TooLong { numbered })
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
    use std::format;

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
        assert_eq!(feed(&mut a, &long), Some(Line::TooLong { numbered: false }));
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
        assert_eq!(feed(&mut a, b"G1 X\x002\n"), Some(Line::Damaged { numbered: Some(false) }));
        assert_eq!(feed(&mut a, b"G1 X3\n"), Some(Line::Text(b"G1 X3")));
    }

    #[test]
    fn a_line_that_lost_bytes_is_damaged() {
        let mut a = LineAssembler::new();
        a.push(b'G');
        a.mark_damaged();
        assert_eq!(feed(&mut a, b"1 X10\n"), Some(Line::Damaged { numbered: Some(false) }));
        assert_eq!(feed(&mut a, b"M105\n"), Some(Line::Text(b"M105")));
    }

    /// Marlin ignores a `;` comment whatever its length: only the part
    /// before it must fit. A `;` inside `( … )` starts no comment.
    #[test]
    fn an_overlong_semicolon_comment_is_dropped_not_refused() {
        let mut a = LineAssembler::new();
        let line = format!("G1 X5 ;{}\n", "c".repeat(300));
        match feed(&mut a, line.as_bytes()) {
            Some(Line::Text(text)) => assert!(text.starts_with(b"G1 X5 ;")),
            other => panic!("{other:?}"),
        }
        let line = format!("G1 X5 (a;b) {}\n", "9".repeat(300));
        assert_eq!(feed(&mut a, line.as_bytes()), Some(Line::TooLong { numbered: false }));
        let line = format!("N7 G1 X{}*3\n", "9".repeat(300));
        assert_eq!(feed(&mut a, line.as_bytes()), Some(Line::TooLong { numbered: true }));
    }

    /// A line whose start was lost does not say whether it was numbered.
    #[test]
    fn a_line_damaged_before_its_first_byte_has_no_numbering_hint() {
        let mut a = LineAssembler::new();
        assert_eq!(feed(&mut a, b"\x00 G1 X5\n"), Some(Line::Damaged { numbered: None }));
        assert_eq!(feed(&mut a, b" N5 G1\x00 X5\n"), Some(Line::Damaged { numbered: Some(true) }));
    }

    #[test]
    fn discarding_drops_the_rest_of_the_line_only() {
        let mut a = LineAssembler::new();
        a.discard_to_line_end();
        assert_eq!(feed(&mut a, b"5 G1 X5*77\n"), None);
        assert_eq!(feed(&mut a, b"M105\n"), Some(Line::Text(b"M105")));
    }
}
