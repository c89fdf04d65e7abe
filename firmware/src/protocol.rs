//! Marlin's host protocol: line numbers, checksums and resend requests.
//!
//! A host may prefix a line with `N<n>` and suffix it with `*<checksum>`,
//! the XOR of every byte before the `*`. A numbered line is accepted only if
//! its checksum matches and `n` is one more than the last accepted number
//! (or the line is an `M110`, which sets the numbering). Anything else is
//! answered with Marlin's error, `Resend: <last+1>` and `ok`, so Printrun,
//! OctoPrint and Repetier-Host resend from the right line. An unnumbered
//! line is accepted as is (plain terminals), and a numbered line without a
//! checksum is refused (a number without a checksum protects nothing).
//!
//! A line with a checksum but no `N` (its `N` was hit by line noise) is
//! evidence of numbering: once the host has numbered its lines it is
//! answered with `Resend:` for the next expected line, so a numbering host
//! converges whichever byte a flip hits.
//!
//! A line that lost bytes in reception is refused the same way when it was
//! numbered (or, when its start was lost, once the host has used line
//! numbers); an unnumbered line is never answered with `Resend:` (the host
//! has no number to resend), and the error alone tells the user that a line
//! was lost. The overrun's text says "checksum": OctoPrint treats an
//! `Error:` as fatal unless it names "line number", "checksum", "format
//! error" or "expected line".

use crate::line::Line;
use ufmt::uWrite;

/// Why a received line was refused before any G-code was parsed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineRejection {
    ChecksumMismatch,
    LineNumberOutOfOrder,
    NoChecksum,
    NoLineNumberWithChecksum,
    /// `N` not followed by a valid number, or `*` by a valid checksum.
    MalformedHeader,
    TooLong,
    /// Bytes of the line were lost in reception.
    Damaged,
    /// A numbered line's end never came ([`crate::line::LINE_END_TIMEOUT_MS`]).
    Unterminated,
}

impl LineRejection {
    /// Marlin's text for the rejection (the part after `Error:`).
    pub fn message(self) -> crate::progmem::FlashStr {
        match self {
            Self::ChecksumMismatch => crate::flash_str!("checksum mismatch"),
            Self::LineNumberOutOfOrder => crate::flash_str!("Line Number is not Last Line Number+1"),
            Self::NoChecksum => crate::flash_str!("No Checksum with line number"),
            Self::NoLineNumberWithChecksum => crate::flash_str!("No Line Number with checksum"),
            Self::MalformedHeader => crate::flash_str!("Malformed line number or checksum"),
            Self::TooLong => crate::flash_str!("Line too long"),
            Self::Damaged => crate::flash_str!("Serial receive overrun, line lost (checksum not verified)"),
            Self::Unterminated => crate::flash_str!("Line without its end, dropped (checksum not verified)"),
        }
    }
}

/// Line-numbering state of the host connection.
pub struct HostProtocol {
    last_line: i32,
    /// The host has sent numbered lines: lost lines can be resent.
    numbered: bool,
    /// The line refused last was numbered: its reply asks for a resend.
    resend: bool,
}

impl Default for HostProtocol {
    fn default() -> Self {
        Self::new()
    }
}

impl HostProtocol {
    pub const fn new() -> Self {
        Self { last_line: 0, numbered: false, resend: false }
    }

    pub fn last_line(&self) -> i32 {
        self.last_line
    }

    /// Set the last line number (`M110 N<n>`): the next line is `n + 1`.
    pub fn set_last_line(&mut self, number: i32) {
        self.last_line = number;
    }

    /// Check a received line; returns the G-code body (without `N` and
    /// `*checksum`) or why it was refused.
    pub fn accept<'a>(&mut self, line: Line<'a>) -> Result<&'a [u8], LineRejection> {
        let text = match line {
            Line::Text(text) => text,
            Line::TooLong { numbered } => {
                self.resend = numbered;
                return Err(LineRejection::TooLong);
            }
            Line::Damaged { numbered } => {
                self.resend = numbered.unwrap_or(self.numbered);
                return Err(LineRejection::Damaged);
            }
            Line::Unterminated { numbered } => {
                self.resend = numbered;
                return Err(LineRejection::Unterminated);
            }
        };
        let star = text.iter().position(|&b| b == b'*');
        let start = text.iter().position(|&b| b != b' ').unwrap_or(text.len());
        let numbered = matches!(text.get(start), Some(b'N' | b'n'));
        self.resend = numbered;
        // The body and its line number (`None`: an unnumbered line).
        let (body, number) = if numbered {
            self.numbered = true;
            let star = star.ok_or(LineRejection::NoChecksum)?;
            let expected = parse_checksum(&text[star + 1..]).ok_or(LineRejection::MalformedHeader)?;
            let actual = text[..star].iter().fold(0u8, |sum, &b| sum ^ b);
            if actual != expected {
                return Err(LineRejection::ChecksumMismatch);
            }
            let (number, used) = parse_line_number(&text[start + 1..star]).ok_or(LineRejection::MalformedHeader)?;
            (&text[start + 1 + used..star], Some(number))
        } else if let Some(star) = star {
            // A checksum field without an `N`: the host numbered this line
            // and the line lost its number on the way (a flipped bit
            // turned the `N` into another byte). If the host numbers its
            // lines, ask for the next expected line as Marlin does, or the
            // host never learns the line was lost. A lone `*` or one
            // followed by anything but a checksum is no evidence of
            // numbering: no resend (a terminal user typed it).
            self.resend = self.numbered && parse_checksum(&text[star + 1..]).is_some();
            return Err(LineRejection::NoLineNumberWithChecksum);
        } else {
            (text, None)
        };
        // One call for both kinds of line.
        match (m110_argument(body), number) {
            // `N<n> M110 N<m>` and `M110 N<m>` number from m; `N<n> M110`
            // from n; a bare `M110` keeps the numbering.
            (Some(argument), _) => {
                if let Some(next) = argument.or(number) {
                    self.last_line = next;
                }
            }
            (None, Some(number)) if Some(number) != self.last_line.checked_add(1) => {
                return Err(LineRejection::LineNumberOutOfOrder);
            }
            (None, Some(number)) => self.last_line = number,
            (None, None) => {}
        }
        Ok(body)
    }

    /// Write the reply to a refused line: the error, a resend request when
    /// the line was numbered, and `ok` (Marlin's order).
    pub fn write_rejection<W: uWrite + ?Sized>(&mut self, rejection: LineRejection, out: &mut W) -> Result<(), W::Error> {
        self.write_rejection_then(rejection, out, || ())
    }

    /// [`Self::write_rejection`], calling `before_resend` between the error
    /// line and the `Resend:` when there is one. The receive side discards
    /// the lines in flight there, as Marlin: after the request the host
    /// sends the line asked for at once (printcore on `Resend:` itself),
    /// and a discard after the reply would throw that line away too (seen
    /// on the bench: the same resend for ever).
    pub fn write_rejection_then<W: uWrite + ?Sized>(
        &mut self,
        rejection: LineRejection,
        out: &mut W,
        before_resend: impl FnOnce(),
    ) -> Result<(), W::Error> {
        out.write_str("Error:")?;
        rejection.message().write_to(out)?;
        // The `ok` joined to the last piece: one call fewer.
        if self.resend {
            ufmt::uwrite!(out, ", Last Line: {}\n", crate::reply::Fixed::whole(self.last_line))?;
            before_resend();
            ufmt::uwrite!(out, "Resend: {}\nok\n", crate::reply::Fixed::whole(self.last_line.wrapping_add(1)))
        } else {
            out.write_str("\nok\n")
        }
    }
}

fn parse_line_number(text: &[u8]) -> Option<(i32, usize)> {
    match crate::gcode::Decimal::parse(text) {
        Ok((value, used)) if value.fraction_digits() == 0 => Some((value.mantissa(), used)),
        _ => None,
    }
}

fn parse_checksum(text: &[u8]) -> Option<u8> {
    let digits = text.iter().take_while(|b| b.is_ascii_digit()).count();
    // `split_at_checked`: no panic path (`digits` never exceeds the length).
    let (number, rest) = text.split_at_checked(digits)?;
    if digits == 0 || digits > 3 || rest.iter().any(|&b| b != b' ') {
        return None;
    }
    number.iter().try_fold(0u8, |sum, &b| sum.checked_mul(10)?.checked_add(b - b'0'))
}

/// `Some(N argument)` when the body's command is `M110` (the numbering
/// reset, which exempts its line from the order check, as in Marlin).
///
/// Every line passes here, and the executor parses it again later, so the
/// full parse runs only for a line that can be an `M110`: one whose first
/// word is `M110`, or one that starts with a comment (which the parser
/// skips). A `G1 …` line costs a look at its first byte.
fn m110_argument(body: &[u8]) -> Option<Option<i32>> {
    if !may_be_m110(body) {
        return None;
    }
    // SAFETY: the main loop, receiving a line: no command is executing.
    #[cfg(target_arch = "avr")]
    let command = unsafe { crate::gcode::Command::scratch() };
    #[cfg(not(target_arch = "avr"))]
    let command = &mut crate::gcode::Command::new(crate::gcode::Code::Other);
    crate::gcode::parse_into(body, command).ok()?;
    if command.code != crate::gcode::Code::M(110) {
        return None;
    }
    Some(command.value(b'N').ok().flatten().and_then(|n| n.to_int()))
}

/// `false` only when the line's first word is certainly not `M110`: the
/// answer [`crate::gcode::parse`] would give is then "not M110" too.
fn may_be_m110(body: &[u8]) -> bool {
    let blank = |b: &u8| matches!(b, b' ' | b'\t');
    let start = body.iter().position(|b| !blank(b)).unwrap_or(body.len());
    match body.get(start) {
        Some(b'M' | b'm') => {}
        // A comment first: let the parser find the first word.
        Some(b'(' | b';') => return true,
        // Another letter, another byte, or nothing: not an M110 line.
        _ => return false,
    }
    let rest = &body[start + 1..];
    let digits = rest.iter().position(|b| !blank(b)).unwrap_or(rest.len());
    matches!(
        crate::gcode::Decimal::parse(&rest[digits..]),
        Ok((number, _)) if number == crate::gcode::Decimal::from_int(110)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reply::test_support::Text;
    use std::format;
    use std::string::String;

    fn with_checksum(line: &str) -> String {
        let sum = line.bytes().fold(0u8, |s, b| s ^ b);
        format!("{line}*{sum}")
    }

    fn accept(protocol: &mut HostProtocol, line: &str) -> Result<String, LineRejection> {
        protocol.accept(Line::Text(line.as_bytes())).map(|body| String::from_utf8(body.to_vec()).unwrap())
    }

    #[test]
    fn numbered_lines_in_order_are_accepted_and_stripped() {
        let mut p = HostProtocol::new();
        assert_eq!(accept(&mut p, &with_checksum("N1 G1 X5")), Ok(" G1 X5".into()));
        assert_eq!(accept(&mut p, &with_checksum("N2 M105")), Ok(" M105".into()));
        assert_eq!(p.last_line(), 2);
    }

    #[test]
    fn printcore_starts_with_m110_at_minus_one() {
        let mut p = HostProtocol::new();
        p.set_last_line(41);
        assert!(accept(&mut p, &with_checksum("N-1 M110")).is_ok());
        assert_eq!(p.last_line(), -1);
        assert!(accept(&mut p, &with_checksum("N0 G28")).is_ok());
    }

    #[test]
    fn m110_with_an_argument_sets_the_numbering_numbered_or_not() {
        let mut p = HostProtocol::new();
        assert!(accept(&mut p, &with_checksum("N7 M110 N100")).is_ok());
        assert_eq!(p.last_line(), 100);
        assert!(accept(&mut p, "M110 N5").is_ok());
        assert_eq!(p.last_line(), 5);
        assert!(accept(&mut p, &with_checksum("N6 G28")).is_ok());
    }

    #[test]
    fn a_wrong_checksum_is_refused_and_resent() {
        let mut p = HostProtocol::new();
        accept(&mut p, &with_checksum("N1 G28")).unwrap();
        let err = accept(&mut p, "N2 G1 X5*0").unwrap_err();
        assert_eq!(err, LineRejection::ChecksumMismatch);
        let mut out = Text::default();
        p.write_rejection(err, &mut out).unwrap();
        assert_eq!(out.0, "Error:checksum mismatch, Last Line: 1\nResend: 2\nok\n");
    }

    #[test]
    fn a_skipped_line_number_is_refused() {
        let mut p = HostProtocol::new();
        accept(&mut p, &with_checksum("N1 G28")).unwrap();
        assert_eq!(accept(&mut p, &with_checksum("N3 G28")), Err(LineRejection::LineNumberOutOfOrder));
        let mut out = Text::default();
        p.write_rejection(LineRejection::LineNumberOutOfOrder, &mut out).unwrap();
        assert_eq!(out.0, "Error:Line Number is not Last Line Number+1, Last Line: 1\nResend: 2\nok\n");
    }

    #[test]
    fn a_number_without_checksum_and_a_checksum_without_number_are_refused() {
        let mut p = HostProtocol::new();
        assert_eq!(accept(&mut p, "N1 G28"), Err(LineRejection::NoChecksum));
        let mut out = Text::default();
        p.write_rejection(LineRejection::NoChecksum, &mut out).unwrap();
        assert_eq!(out.0, "Error:No Checksum with line number, Last Line: 0\nResend: 1\nok\n");
        assert_eq!(accept(&mut p, "G28*18"), Err(LineRejection::NoLineNumberWithChecksum));
    }

    #[test]
    fn unnumbered_lines_pass_and_errors_have_no_resend() {
        let mut p = HostProtocol::new();
        assert_eq!(accept(&mut p, "M105"), Ok("M105".into()));
        let mut out = Text::default();
        p.write_rejection(LineRejection::TooLong, &mut out).unwrap();
        assert_eq!(out.0, "Error:Line too long\nok\n");
    }

    /// Finding 4 of issue 22: after numbered lines, an unnumbered line that
    /// is too long, or a lone `*`, was answered with `Resend:`.
    #[test]
    fn unnumbered_refusals_never_ask_for_a_resend_even_after_numbered_lines() {
        let mut p = HostProtocol::new();
        accept(&mut p, &with_checksum("N1 G28")).unwrap();
        let cases: [(Line<'_>, LineRejection); 4] = [
            (Line::TooLong { numbered: false }, LineRejection::TooLong),
            (Line::Text(b"*"), LineRejection::NoLineNumberWithChecksum),
            (Line::Text(b"M118 JOB5*M118 JOB6"), LineRejection::NoLineNumberWithChecksum),
            (Line::Damaged { numbered: Some(false) }, LineRejection::Damaged),
        ];
        for (line, expected) in cases {
            let rejection = p.accept(line).unwrap_err();
            assert_eq!(rejection, expected);
            let mut out = Text::default();
            p.write_rejection(rejection, &mut out).unwrap();
            assert!(!out.0.contains("Resend"), "{}", out.0);
        }
        // Numbered ones do, and a damaged line whose start was lost counts
        // as numbered once the host numbers its lines.
        for line in [Line::TooLong { numbered: true }, Line::Damaged { numbered: None }, Line::Damaged { numbered: Some(true) }] {
            let rejection = p.accept(line).unwrap_err();
            let mut out = Text::default();
            p.write_rejection(rejection, &mut out).unwrap();
            assert!(out.0.contains("Resend: 2"), "{}", out.0);
        }
    }

    /// Issue 22: a flip that destroys the `N` of a numbered line left
    /// `Error:No Line Number with checksum` without `Resend:`, and the host
    /// never resent the line. Now the next expected line is asked for.
    #[test]
    fn a_numbered_line_that_lost_its_n_is_resent() {
        let mut p = HostProtocol::new();
        accept(&mut p, &with_checksum("N1 G28")).unwrap();
        // `N` (0x4E) with bit 0 flipped is `O`.
        let line = with_checksum("N2 G1 X5").replacen('N', "O", 1);
        let rejection = accept(&mut p, &line).unwrap_err();
        assert_eq!(rejection, LineRejection::NoLineNumberWithChecksum);
        let mut out = Text::default();
        p.write_rejection(rejection, &mut out).unwrap();
        assert_eq!(out.0, "Error:No Line Number with checksum, Last Line: 1\nResend: 2\nok\n");
        assert_eq!(accept(&mut p, &with_checksum("N2 G1 X5")), Ok(" G1 X5".into()));
    }

    /// Before any numbered line, a checksum alone is no evidence of
    /// numbering: the error, no `Resend:`.
    #[test]
    fn a_checksum_without_number_from_a_host_that_never_numbered_is_not_resent() {
        let mut p = HostProtocol::new();
        let rejection = accept(&mut p, "G28*18").unwrap_err();
        let mut out = Text::default();
        p.write_rejection(rejection, &mut out).unwrap();
        assert_eq!(out.0, "Error:No Line Number with checksum\nok\n");
    }

    #[test]
    fn only_lines_whose_first_word_can_be_m110_are_parsed_for_it() {
        for body in ["M110", " m110 N5", "M 110", "M110.", "(reset) M110 N3", "; M110"] {
            assert!(may_be_m110(body.as_bytes()), "{body}");
        }
        for body in ["G1 X5", "M1100", "M11", "M111 N5", "M110.5", "N5 M110", "", "  ", "T0"] {
            assert!(!may_be_m110(body.as_bytes()), "{body}");
        }
    }

    #[test]
    fn m110_after_a_comment_still_sets_the_numbering() {
        let mut p = HostProtocol::new();
        assert!(accept(&mut p, "(restart) M110 N20").is_ok());
        assert_eq!(p.last_line(), 20);
        assert!(accept(&mut p, &with_checksum("N21 M110 N40 ; again")).is_ok());
        assert_eq!(p.last_line(), 40);
    }

    #[test]
    fn a_garbled_checksum_field_is_refused() {
        let mut p = HostProtocol::new();
        assert_eq!(accept(&mut p, "N1 G28*1x"), Err(LineRejection::MalformedHeader));
        assert_eq!(accept(&mut p, "N1 G28*999"), Err(LineRejection::MalformedHeader));
    }
}
