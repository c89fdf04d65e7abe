//! Why a well-formed line could not be executed.

use crate::gcode::{Code, ParseError};
use crate::motion::arc::ArcError;
use crate::motion::kinematics::KinematicsError;
use crate::motion::MotionError;
use ufmt::uWrite;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CommandError {
    /// The line is not valid G-code.
    Parse(ParseError),
    /// `F` is zero, negative or absurdly large.
    InvalidFeedRate,
    /// A value outside what the named word accepts.
    OutOfRange(u8),
    /// A required word is missing.
    Missing(u8),
    /// The firmware is halted (`M112`, or a safety fault): nothing runs
    /// until the board is reset.
    Halted,
    /// Motion refused the move (nothing moved).
    Motion(MotionError),
    /// A motion fault lost the position: moves wait for `G28`.
    PositionLost,
    /// The command belongs to another kind of machine (`M665` on a
    /// Cartesian printer).
    NotThisMachine,
    /// A mode this firmware does not run (`G93`); moves wait until the
    /// supported one is back.
    UnsupportedMode(Code),
    /// `G53` with an arc (Grbl: machine coordinates for `G0`/`G1` only).
    MachineFrameArc,
    /// A diameter PI gain above zero (the loop is reverse acting).
    DiameterGainSign,
    /// `G28` while a driver's ALARM input is active.
    DriverAlarm,
    /// A move or `G28` after a safety trip that was not re-armed: which
    /// input ([`super::safety::RELAY_TRIPPED`] or
    /// [`super::safety::EMERGENCY_STOP`]).
    SafetyStop(u8),
}

impl From<ParseError> for CommandError {
    fn from(error: ParseError) -> Self {
        Self::Parse(error)
    }
}

impl CommandError {
    /// Write the `Error:` line for this error.
    pub fn write<W: uWrite + ?Sized>(self, out: &mut W) -> Result<(), W::Error> {
        let (index, argument) = self.message();
        write_message(index, argument, out)
    }

    /// Which of [`MESSAGES`] says this, and its argument (a letter or a
    /// number, as the message's marker asks).
    fn message(self) -> (u8, u16) {
        let index = match self {
            Self::Parse(error) => return parse_message(error),
            Self::InvalidFeedRate => 0,
            Self::OutOfRange(letter) => return (1, letter.into()),
            Self::Missing(letter) => return (2, letter.into()),
            Self::Halted => 3,
            Self::Motion(error) => motion_message(error),
            Self::PositionLost => 4,
            Self::NotThisMachine => 5,
            // G93 (inverse-time feed) is the only one today.
            Self::UnsupportedMode(code) => return (6, if let Code::G(n) = code { n } else { 0 }),
            Self::MachineFrameArc => 7,
            Self::DiameterGainSign => 8,
            Self::DriverAlarm => 9,
            Self::SafetyStop(super::safety::EMERGENCY_STOP) => SAFETY_MESSAGES + 1,
            Self::SafetyStop(_) => SAFETY_MESSAGES,
        };
        (index, 0)
    }
}

fn motion_message(error: MotionError) -> u8 {
    match error {
        MotionError::Busy => 10,
        MotionError::Unreachable(KinematicsError::OutsidePrintable) => 11,
        MotionError::Unreachable(KinematicsError::TooTilted) => 12,
        MotionError::Unreachable(_) => 13,
        MotionError::OutsideSoftLimits => 14,
        MotionError::NotHomed => 15,
        MotionError::Arc(ArcError::ZeroRadius) => 16,
        MotionError::Arc(ArcError::RadiusMismatch) => 17,
        MotionError::Arc(ArcError::RadiusTooSmall) => 18,
        MotionError::HomingFailed(_) => 19,
        MotionError::Fault(_) => 20,
    }
}

fn parse_message(error: ParseError) -> (u8, u16) {
    // The messages follow the variants' order: the index is arithmetic.
    let argument = match error {
        ParseError::BadNumber(byte)
        | ParseError::NumberOutOfRange(byte)
        | ParseError::WordWithoutValue(byte)
        | ParseError::UnexpectedByte(byte)
        | ParseError::DuplicateWord(byte) => byte,
        _ => 0,
    };
    (FIRST_PARSE_MESSAGE + error.number(), argument.into())
}

/// Index of [`ParseError::BadNumber`]'s message; the other parse errors'
/// follow in declaration order.
const FIRST_PARSE_MESSAGE: u8 = 21;
/// The safety trips' refusals follow the ten parse errors' messages:
/// the relay's, then the emergency stop's.
const SAFETY_MESSAGES: u8 = FIRST_PARSE_MESSAGE + 10;

/// In a message: the argument as a letter.
const LETTER: &str = "\x01";
/// In a message: the argument as a decimal number.
const NUMBER: &str = "\x02";

/// Every error message, numbered from 0 in this order, each followed by
/// a NUL. One table and one writer instead of a `write_str` or `uwrite!`
/// per message, each with its own call sequence.
const MESSAGE_PARTS: &[&str] = &[
    "Invalid feed rate (F must be > 0)\0",
    "Value out of range for ", LETTER, "\0",
    "Missing ", LETTER, " word\0",
    "Printer halted. kill() called!\0",
    "Position unknown after a motion stop: home with G28 first\0",
    "Not available on this machine\0",
    "G", NUMBER, " is not supported: moves are refused until G94\0",
    "G53 moves with G0 or G1 only\0",
    "Diameter gains must be <= 0 (reverse acting)\0",
    "A driver ALARM is active: clear it before homing\0",
    // 10: motion.
    "Motion busy, command refused\0",
    "Move outside the printable radius\0",
    "Move tilts a rod too far\0",
    "Move out of reach\0",
    "Move outside the soft limits\0",
    "Home XYZ first (G28)\0",
    "Arc with zero radius\0",
    "Arc end is not on the circle\0",
    "Arc radius too small for its end point\0",
    "Homing Failed\0",
    "Motion stopped\0",
    // 21: parsing.
    "Bad number after ", LETTER, "\0",
    "Number out of range after ", LETTER, "\0",
    "Missing value after ", LETTER, "\0",
    "Unterminated comment\0",
    "Unexpected character (byte ", NUMBER, ")\0",
    "Repeated word ", LETTER, "\0",
    "Too many words\0",
    "Bad command number\0",
    "Empty command\0",
    "Too many codes on one line\0",
    // 31: safety trips (SPEC §3), refused until re-armed.
    "Safety relay tripped: clear the light curtain, press re-arm, then G28\0",
    "Emergency stop pressed: release it, press re-arm, then G28\0",
];

#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
static MESSAGES: crate::progmem::Flash<[u8; crate::progmem::total_len(MESSAGE_PARTS)]> =
    crate::progmem::Flash::new(crate::progmem::concat_ascii(MESSAGE_PARTS));

/// `Error:`, message `index` of [`MESSAGES`] with `argument` in place of
/// its marker, and the end of the line.
#[inline(never)]
fn write_message<W: uWrite + ?Sized>(index: u8, argument: u16, out: &mut W) -> Result<(), W::Error> {
    out.write_str("Error:")?;
    let mut at = 0;
    let mut skip = index;
    while skip > 0 {
        match MESSAGES.get(at) {
            Some(0) => skip -= 1,
            Some(_) => {}
            None => break,
        }
        at += 1;
    }
    while let Some(byte) = MESSAGES.get(at) {
        match byte {
            0 => break,
            1 => out.write_char(char::from(argument as u8))?,
            2 => ufmt::uwrite!(out, "{}", crate::reply::Whole(argument.into()))?,
            _ => out.write_char(char::from(byte))?,
        }
        at += 1;
    }
    out.write_str("\n")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::StepFault;
    use crate::reply::test_support::Text;

    fn line(error: CommandError) -> std::string::String {
        let mut out = Text::default();
        error.write(&mut out).unwrap();
        out.0
    }

    #[test]
    fn every_error_has_its_exact_line() {
        use CommandError as E;
        use ParseError as P;
        let cases = [
            (E::Parse(P::BadNumber(b'X')), "Bad number after X"),
            (E::Parse(P::NumberOutOfRange(b'Y')), "Number out of range after Y"),
            (E::Parse(P::WordWithoutValue(b'F')), "Missing value after F"),
            (E::Parse(P::UnterminatedComment), "Unterminated comment"),
            (E::Parse(P::UnexpectedByte(255)), "Unexpected character (byte 255)"),
            (E::Parse(P::UnexpectedByte(0)), "Unexpected character (byte 0)"),
            (E::Parse(P::DuplicateWord(b'Z')), "Repeated word Z"),
            (E::Parse(P::TooManyWords), "Too many words"),
            (E::Parse(P::BadCommandNumber), "Bad command number"),
            (E::Parse(P::Empty), "Empty command"),
            (E::Parse(P::TooManyCodes), "Too many codes on one line"),
            (E::InvalidFeedRate, "Invalid feed rate (F must be > 0)"),
            (E::OutOfRange(b'S'), "Value out of range for S"),
            (E::Missing(b'R'), "Missing R word"),
            (E::Halted, "Printer halted. kill() called!"),
            (E::Motion(MotionError::Busy), "Motion busy, command refused"),
            (E::Motion(MotionError::Unreachable(KinematicsError::OutsidePrintable)), "Move outside the printable radius"),
            (E::Motion(MotionError::Unreachable(KinematicsError::TooTilted)), "Move tilts a rod too far"),
            (E::Motion(MotionError::Unreachable(KinematicsError::OutOfReach)), "Move out of reach"),
            (E::Motion(MotionError::Unreachable(KinematicsError::NoSolution)), "Move out of reach"),
            (E::Motion(MotionError::OutsideSoftLimits), "Move outside the soft limits"),
            (E::Motion(MotionError::NotHomed), "Home XYZ first (G28)"),
            (E::Motion(MotionError::Arc(ArcError::ZeroRadius)), "Arc with zero radius"),
            (E::Motion(MotionError::Arc(ArcError::RadiusMismatch)), "Arc end is not on the circle"),
            (E::Motion(MotionError::Arc(ArcError::RadiusTooSmall)), "Arc radius too small for its end point"),
            (E::Motion(MotionError::HomingFailed(3)), "Homing Failed"),
            (E::Motion(MotionError::Fault(StepFault::Stopped)), "Motion stopped"),
            (E::PositionLost, "Position unknown after a motion stop: home with G28 first"),
            (E::NotThisMachine, "Not available on this machine"),
            (E::UnsupportedMode(Code::G(93)), "G93 is not supported: moves are refused until G94"),
            (E::UnsupportedMode(Code::M(7)), "G0 is not supported: moves are refused until G94"),
            (E::MachineFrameArc, "G53 moves with G0 or G1 only"),
            (E::DiameterGainSign, "Diameter gains must be <= 0 (reverse acting)"),
            (E::DriverAlarm, "A driver ALARM is active: clear it before homing"),
            (E::SafetyStop(crate::machine::safety::RELAY_TRIPPED), "Safety relay tripped: clear the light curtain, press re-arm, then G28"),
            (E::SafetyStop(crate::machine::safety::EMERGENCY_STOP), "Emergency stop pressed: release it, press re-arm, then G28"),
        ];
        for (error, text) in cases {
            assert_eq!(line(error), std::format!("Error:{text}\n"), "{error:?}");
        }
    }
}
