//! The command executor and the machine's modal state.
//!
//! The board's main loop feeds every complete line to
//! [`Machine::handle_line`]. A line goes through the host protocol (line
//! numbers, checksums), the G-code parser, and then the command it names;
//! every line gets exactly one final `ok` (after its error or report, as in
//! Marlin), so a host that waits for `ok` never stalls.

use crate::gcode::{self, Code, Command, ParseError};
use crate::line::Line;
use crate::protocol::HostProtocol;
use crate::reply::{Fixed, Printable};
use crate::thermal::{Celsius, Heater};
use ufmt::uWrite;

/// Axes a position report names.
pub const AXIS_LETTERS: [u8; 4] = [b'X', b'Y', b'Z', b'E'];

/// Whether a command's reply already carried the line's `ok`.
enum Acknowledged {
    Yes,
    No,
}

/// Everything the executor remembers between lines.
pub struct Machine {
    protocol: HostProtocol,
    /// Logical position per axis (X, Y, Z, E), in micrometres.
    position_um: [i32; 4],
    /// Position in motor steps per axis (X, Y, Z), for `Count` in `M114`.
    position_steps: [i32; 3],
    hotend: Heater,
    bed: Heater,
}

impl Default for Machine {
    fn default() -> Self {
        Self::new()
    }
}

impl Machine {
    pub const fn new() -> Self {
        Self {
            protocol: HostProtocol::new(),
            position_um: [0; 4],
            position_steps: [0; 3],
            hotend: Heater::new(),
            bed: Heater::new(),
        }
    }

    /// The start banner, printed once at boot. `start` is what Printrun and
    /// OctoPrint look for to learn that the firmware (re)started.
    pub fn write_banner<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        ufmt::uwrite!(out, "start\necho:{} {} ready\n", crate::FIRMWARE_NAME, crate::FIRMWARE_VERSION)
    }

    /// Latest measured temperatures (from the board's ADC conversion).
    pub fn set_measured(&mut self, hotend: Celsius, bed: Celsius) {
        self.hotend.measured = hotend;
        self.bed.measured = bed;
    }

    /// Handle one complete line from the host, writing every reply.
    pub fn handle_line<W: uWrite + ?Sized>(&mut self, line: Line<'_>, out: &mut W) -> Result<(), W::Error> {
        let body = match self.protocol.accept(line) {
            Ok(body) => body,
            Err(rejection) => return self.protocol.write_rejection(rejection, out),
        };
        let acknowledged = match gcode::parse(body) {
            Ok(command) => self.execute(&command, body, out)?,
            Err(ParseError::Empty) => Acknowledged::No,
            Err(error) => {
                write_parse_error(error, out)?;
                Acknowledged::No
            }
        };
        match acknowledged {
            Acknowledged::Yes => Ok(()),
            Acknowledged::No => out.write_str("ok\n"),
        }
    }

    fn execute<W: uWrite + ?Sized>(&mut self, command: &Command, text: &[u8], out: &mut W) -> Result<Acknowledged, W::Error> {
        let result = match command.code {
            Code::M(105) => {
                // Marlin puts the report on the `ok` line itself.
                out.write_str("ok ")?;
                self.write_temperatures(out)?;
                return Ok(Acknowledged::Yes);
            }
            Code::M(110) => {
                match command.value(b'N') {
                    Ok(Some(n)) => match n.to_int() {
                        Some(n) => self.protocol.set_last_line(n),
                        None => write_parse_error(ParseError::NumberOutOfRange(b'N'), out)?,
                    },
                    Ok(None) => {}
                    Err(error) => write_parse_error(error, out)?,
                }
                Ok(())
            }
            Code::M(114) => self.report_position(out),
            Code::M(115) => write_capabilities(out),
            _ => {
                let start = text.iter().position(|&b| b != b' ').unwrap_or(0);
                ufmt::uwrite!(out, "echo:Unknown command: \"{}\"\n", Printable(&text[start..]))
            }
        };
        result.map(|()| Acknowledged::No)
    }

    /// ` T:… /… B:… /… @:… B@:…` (used by M105 and auto-reports).
    pub fn write_temperatures<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        ufmt::uwrite!(
            out,
            "T:{} /{} B:{} /{} @:{} B@:{}\n",
            self.hotend.measured,
            self.hotend.target,
            self.bed.measured,
            self.bed.target,
            self.hotend.power,
            self.bed.power
        )
    }

    /// `M114`: `X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0`.
    fn report_position<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        for (letter, um) in AXIS_LETTERS.iter().zip(self.position_um) {
            ufmt::uwrite!(out, "{}:{} ", char::from(*letter), Fixed::hundredths(um / 10))?;
        }
        let [x, y, z] = self.position_steps;
        ufmt::uwrite!(out, "Count X:{} Y:{} Z:{}\n", x, y, z)
    }
}

/// `M115`: the firmware line and the `Cap:` lines hosts read to decide what
/// to send (OctoPrint enables auto-reporting and the emergency parser from
/// these).
pub fn write_capabilities<W: uWrite + ?Sized>(out: &mut W) -> Result<(), W::Error> {
    ufmt::uwrite!(
        out,
        "FIRMWARE_NAME:{} {} (Rust) SOURCE_CODE_URL:local PROTOCOL_VERSION:1.0 MACHINE_TYPE:RepRap EXTRUDER_COUNT:1\n",
        crate::FIRMWARE_NAME,
        crate::FIRMWARE_VERSION
    )?;
    for (name, on) in CAPABILITIES {
        ufmt::uwrite!(out, "Cap:{}:{}\n", *name, u8::from(*on))?;
    }
    Ok(())
}

/// The capabilities reported by `M115`, honestly: on only when implemented.
const CAPABILITIES: &[(&str, bool)] = &[
    ("SERIAL_XON_XOFF", false),
    ("BINARY_FILE_TRANSFER", false),
    ("EEPROM", false),
    ("VOLUMETRIC", false),
    ("AUTOREPORT_TEMP", false),
    ("AUTOREPORT_POS", false),
    ("PROGRESS", false),
    ("PRINT_JOB", false),
    ("AUTOLEVEL", false),
    ("Z_PROBE", false),
    ("LEVELING_DATA", false),
    ("SOFTWARE_POWER", false),
    ("TOGGLE_LIGHTS", false),
    ("EMERGENCY_PARSER", false),
    ("HOST_ACTION_COMMANDS", false),
    ("PROMPT_SUPPORT", false),
    ("SDCARD", false),
    ("AUTOREPORT_SD_STATUS", false),
    ("THERMAL_PROTECTION", false),
    ("MOTION_MODES", false),
    ("ARCS", false),
    ("BABYSTEPPING", false),
    ("CHAMBER_TEMPERATURE", false),
];

fn write_parse_error<W: uWrite + ?Sized>(error: ParseError, out: &mut W) -> Result<(), W::Error> {
    out.write_str("Error:")?;
    match error {
        ParseError::BadNumber(letter) => ufmt::uwrite!(out, "Bad number after {}", char::from(letter)),
        ParseError::NumberOutOfRange(letter) => ufmt::uwrite!(out, "Number out of range after {}", char::from(letter)),
        ParseError::WordWithoutValue(letter) => ufmt::uwrite!(out, "Missing value after {}", char::from(letter)),
        ParseError::UnterminatedComment => out.write_str("Unterminated comment"),
        ParseError::UnexpectedByte(byte) => ufmt::uwrite!(out, "Unexpected character (byte {})", byte),
        ParseError::DuplicateWord(letter) => ufmt::uwrite!(out, "Repeated word {}", char::from(letter)),
        ParseError::TooManyWords => out.write_str("Too many words"),
        ParseError::BadCommandNumber => out.write_str("Bad command number"),
        ParseError::Empty => Ok(()),
    }?;
    out.write_str("\n")
}
