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
}

impl From<ParseError> for CommandError {
    fn from(error: ParseError) -> Self {
        Self::Parse(error)
    }
}

impl CommandError {
    /// Write the `Error:` line for this error.
    pub fn write<W: uWrite + ?Sized>(self, out: &mut W) -> Result<(), W::Error> {
        out.write_str("Error:")?;
        match self {
            Self::Parse(error) => write_parse_error(error, out),
            Self::InvalidFeedRate => crate::flash_str!("Invalid feed rate (F must be > 0)").write_to(out),
            Self::OutOfRange(letter) => ufmt::uwrite!(out, "Value out of range for {}", char::from(letter)),
            Self::Missing(letter) => ufmt::uwrite!(out, "Missing {} word", char::from(letter)),
            Self::Halted => crate::flash_str!("Printer halted. kill() called!").write_to(out),
            Self::Motion(error) => write_motion_error(error, out),
            Self::PositionLost => crate::flash_str!("Position unknown after a motion stop: home with G28 first").write_to(out),
            Self::NotThisMachine => crate::flash_str!("Not available on this machine").write_to(out),
            Self::UnsupportedMode(code) => write_unsupported_mode(code, out),
            Self::MachineFrameArc => crate::flash_str!("G53 moves with G0 or G1 only").write_to(out),
            Self::DiameterGainSign => crate::flash_str!("Diameter gains must be <= 0 (reverse acting)").write_to(out),
            Self::DriverAlarm => crate::flash_str!("A driver ALARM is active: clear it before homing").write_to(out),
        }?;
        out.write_str("\n")
    }
}

fn write_motion_error<W: uWrite + ?Sized>(error: MotionError, out: &mut W) -> Result<(), W::Error> {
    let text = match error {
        MotionError::Busy => crate::flash_str!("Motion busy, command refused"),
        MotionError::Unreachable(KinematicsError::OutsidePrintable) => crate::flash_str!("Move outside the printable radius"),
        MotionError::Unreachable(KinematicsError::TooTilted) => crate::flash_str!("Move tilts a rod too far"),
        MotionError::Unreachable(_) => crate::flash_str!("Move out of reach"),
        MotionError::OutsideSoftLimits => crate::flash_str!("Move outside the soft limits"),
        MotionError::NotHomed => crate::flash_str!("Home XYZ first (G28)"),
        MotionError::Arc(ArcError::ZeroRadius) => crate::flash_str!("Arc with zero radius"),
        MotionError::Arc(ArcError::RadiusMismatch) => crate::flash_str!("Arc end is not on the circle"),
        MotionError::Arc(ArcError::RadiusTooSmall) => crate::flash_str!("Arc radius too small for its end point"),
        MotionError::HomingFailed(_) => crate::flash_str!("Homing Failed"),
        MotionError::Fault(_) => crate::flash_str!("Motion stopped"),
    };
    text.write_to(out)
}

fn write_unsupported_mode<W: uWrite + ?Sized>(code: Code, out: &mut W) -> Result<(), W::Error> {
    // G93 (inverse-time feed) is the only one today.
    let (number, back) = match code {
        Code::G(n) => (n, 94),
        _ => (0, 94),
    };
    ufmt::uwrite!(out, "G{} is not supported: moves are refused until G{}", number, back)
}

fn write_parse_error<W: uWrite + ?Sized>(error: ParseError, out: &mut W) -> Result<(), W::Error> {
    match error {
        ParseError::BadNumber(letter) => ufmt::uwrite!(out, "Bad number after {}", char::from(letter)),
        ParseError::NumberOutOfRange(letter) => ufmt::uwrite!(out, "Number out of range after {}", char::from(letter)),
        ParseError::WordWithoutValue(letter) => ufmt::uwrite!(out, "Missing value after {}", char::from(letter)),
        ParseError::UnterminatedComment => crate::flash_str!("Unterminated comment").write_to(out),
        ParseError::UnexpectedByte(byte) => ufmt::uwrite!(out, "Unexpected character (byte {})", byte),
        ParseError::DuplicateWord(letter) => ufmt::uwrite!(out, "Repeated word {}", char::from(letter)),
        ParseError::TooManyWords => out.write_str("Too many words"),
        ParseError::BadCommandNumber => out.write_str("Bad command number"),
        ParseError::Empty => out.write_str("Empty command"),
        ParseError::TooManyCodes => out.write_str("Too many codes on one line"),
    }
}
