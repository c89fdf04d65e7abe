//! A 16×2 HD44780 character display in 4-bit mode (SPEC §5), over
//! embedded-hal 1 output pins (RS, E, D4–D7; R/W tied to ground, so the
//! busy flag is never read and every command waits its worst-case
//! execution time instead) and a [`DelayNs`].
//!
//! Timing (Hitachi HD44780U datasheet, 5 V, fosc 270 kHz):
//! - power-on: wait > 40 ms after Vcc reaches 2.7 V (we wait 50 ms);
//! - 4-bit initialisation by instruction (datasheet figure 24): nibble 3,
//!   wait > 4.1 ms (4.5 ms); nibble 3, wait > 100 µs (150 µs); nibble 3,
//!   wait (150 µs); nibble 2 (now 4-bit), wait (150 µs); then function set
//!   `0x28` (4-bit, two lines, 5×8 dots), display off `0x08`, clear `0x01`,
//!   entry mode `0x06` (increment, no shift), display on `0x0C` (no
//!   cursor, no blink);
//! - E high ≥ 450 ns and an E cycle ≥ 1 µs: E is held high 1 µs and low
//!   1 µs after each nibble; data is set up before E rises;
//! - instructions and data take 37 µs (we wait 50 µs: slower RC
//!   oscillators on clones), clear and home 1.52 ms (we wait 2 ms).
//!
//! Writing the 32 characters of a screen blocks ≈ 2 ms: call it from the
//! main loop at a few Hz, never from an interrupt.

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;

/// Columns and rows of the display.
pub const COLUMNS: u8 = 16;
pub const ROWS: u8 = 2;

/// Instructions (datasheet table 6).
pub const CLEAR: u8 = 0x01;
pub const HOME: u8 = 0x02;
pub const ENTRY_INCREMENT: u8 = 0x06;
pub const DISPLAY_OFF: u8 = 0x08;
pub const DISPLAY_ON: u8 = 0x0C;
pub const FUNCTION_4BIT_2LINE: u8 = 0x28;
pub const SET_DDRAM: u8 = 0x80;

/// DDRAM address of the start of each row on a two-line display.
const ROW_ADDRESS: [u8; 2] = [0x00, 0x40];

/// Execution time of ordinary instructions and data writes, µs.
pub const EXECUTION_US: u32 = 50;
/// Execution time of clear and home, ms.
pub const CLEAR_MS: u32 = 2;

/// A pin refused a write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PinError;

/// Where a character goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CursorError {
    OutOfRange,
}

/// The display on six output pins.
pub struct Hd44780<Rs, E, D4, D5, D6, D7> {
    rs: Rs,
    e: E,
    d4: D4,
    d5: D5,
    d6: D6,
    d7: D7,
}

impl<Rs, E, D4, D5, D6, D7> Hd44780<Rs, E, D4, D5, D6, D7>
where
    Rs: OutputPin,
    E: OutputPin,
    D4: OutputPin,
    D5: OutputPin,
    D6: OutputPin,
    D7: OutputPin,
{
    /// Take the pins; nothing is written until [`init`](Self::init).
    pub fn new(rs: Rs, e: E, d4: D4, d5: D5, d6: D6, d7: D7) -> Self {
        Self { rs, e, d4, d5, d6, d7 }
    }

    /// The power-on initialisation by instruction (see the module docs).
    /// Leaves the display on, cleared, cursor at (0, 0).
    pub fn init(&mut self, delay: &mut impl DelayNs) -> Result<(), PinError> {
        self.e.set_low().map_err(|_| PinError)?;
        self.rs.set_low().map_err(|_| PinError)?;
        delay.delay_ms(50);
        self.write_nibble(0x3, delay)?;
        delay.delay_us(4_500);
        self.write_nibble(0x3, delay)?;
        delay.delay_us(150);
        self.write_nibble(0x3, delay)?;
        delay.delay_us(150);
        self.write_nibble(0x2, delay)?;
        delay.delay_us(150);
        self.command(FUNCTION_4BIT_2LINE, delay)?;
        self.command(DISPLAY_OFF, delay)?;
        self.clear(delay)?;
        self.command(ENTRY_INCREMENT, delay)?;
        self.command(DISPLAY_ON, delay)
    }

    /// Clear the display and put the cursor at (0, 0).
    pub fn clear(&mut self, delay: &mut impl DelayNs) -> Result<(), PinError> {
        self.write_byte(false, CLEAR, delay)?;
        delay.delay_ms(CLEAR_MS);
        Ok(())
    }

    /// Put the cursor at `column` (0–15) of `row` (0–1).
    pub fn set_cursor(&mut self, column: u8, row: u8, delay: &mut impl DelayNs) -> Result<(), CursorOrPinError> {
        if column >= COLUMNS || row >= ROWS {
            return Err(CursorOrPinError::Cursor(CursorError::OutOfRange));
        }
        self.command(SET_DDRAM | (ROW_ADDRESS[usize::from(row)] + column), delay).map_err(CursorOrPinError::Pin)
    }

    /// Write characters at the cursor (the character ROM maps 0x20–0x7D
    /// like ASCII; other bytes show ROM glyphs).
    pub fn write_bytes(&mut self, text: &[u8], delay: &mut impl DelayNs) -> Result<(), PinError> {
        for &byte in text {
            self.write_byte(true, byte, delay)?;
            delay.delay_us(EXECUTION_US);
        }
        Ok(())
    }

    /// Write text at the cursor.
    pub fn write_str(&mut self, text: &str, delay: &mut impl DelayNs) -> Result<(), PinError> {
        self.write_bytes(text.as_bytes(), delay)
    }

    /// Show a whole screen: 16 characters on each row.
    pub fn show(&mut self, screen: &[u8; 32], delay: &mut impl DelayNs) -> Result<(), PinError> {
        for row in 0..ROWS {
            let start = usize::from(row) * usize::from(COLUMNS);
            self.command(SET_DDRAM | ROW_ADDRESS[usize::from(row)], delay)?;
            self.write_bytes(&screen[start..start + usize::from(COLUMNS)], delay)?;
        }
        Ok(())
    }

    /// An instruction (RS low) and its execution time.
    pub fn command(&mut self, instruction: u8, delay: &mut impl DelayNs) -> Result<(), PinError> {
        self.write_byte(false, instruction, delay)?;
        delay.delay_us(EXECUTION_US);
        Ok(())
    }

    /// Give the pins back.
    pub fn release(self) -> (Rs, E, D4, D5, D6, D7) {
        (self.rs, self.e, self.d4, self.d5, self.d6, self.d7)
    }

    fn write_byte(&mut self, data: bool, byte: u8, delay: &mut impl DelayNs) -> Result<(), PinError> {
        self.rs.set_state(data.into()).map_err(|_| PinError)?;
        self.write_nibble(byte >> 4, delay)?;
        self.write_nibble(byte & 0x0F, delay)
    }

    /// D4–D7 from the low four bits, then an E pulse (the display latches
    /// on E's falling edge).
    fn write_nibble(&mut self, nibble: u8, delay: &mut impl DelayNs) -> Result<(), PinError> {
        self.d4.set_state((nibble & 0x1 != 0).into()).map_err(|_| PinError)?;
        self.d5.set_state((nibble & 0x2 != 0).into()).map_err(|_| PinError)?;
        self.d6.set_state((nibble & 0x4 != 0).into()).map_err(|_| PinError)?;
        self.d7.set_state((nibble & 0x8 != 0).into()).map_err(|_| PinError)?;
        self.e.set_high().map_err(|_| PinError)?;
        delay.delay_us(1);
        self.e.set_low().map_err(|_| PinError)?;
        delay.delay_us(1);
        Ok(())
    }
}

/// [`Hd44780::set_cursor`]'s error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CursorOrPinError {
    Cursor(CursorError),
    Pin(PinError),
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::cell::RefCell;
    use embedded_hal_mock::eh1::delay::{CheckedDelay, NoopDelay, Transaction as Delay};
    use embedded_hal_mock::eh1::digital::{Mock as PinMock, State, Transaction as Pin};
    use std::rc::Rc;
    use std::string::String;
    use std::vec;
    use std::vec::Vec;

    fn level(high: bool) -> Pin {
        Pin::set(if high { State::High } else { State::Low })
    }

    /// The expectations for a list of nibbles (RS level, nibble), per pin
    /// and for the delay, with `after` delays following each nibble.
    struct Expected {
        rs: Vec<Pin>,
        e: Vec<Pin>,
        d: [Vec<Pin>; 4],
        delay: Vec<Delay>,
    }

    impl Expected {
        fn new() -> Self {
            Self { rs: vec![], e: vec![], d: [vec![], vec![], vec![], vec![]], delay: vec![] }
        }

        fn nibble(&mut self, nibble: u8) {
            for bit in 0..4 {
                self.d[bit].push(level(nibble >> bit & 1 == 1));
            }
            self.e.push(level(true));
            self.delay.push(Delay::delay_us(1));
            self.e.push(level(false));
            self.delay.push(Delay::delay_us(1));
        }

        fn byte(&mut self, data: bool, byte: u8, wait: Delay) {
            self.rs.push(level(data));
            self.nibble(byte >> 4);
            self.nibble(byte & 0xF);
            self.delay.push(wait);
        }

        fn run(self, body: impl FnOnce(&mut Hd44780<PinMock, PinMock, PinMock, PinMock, PinMock, PinMock>, &mut CheckedDelay)) {
            let mut rs = PinMock::new(&self.rs);
            let mut e = PinMock::new(&self.e);
            let mut d: Vec<PinMock> = self.d.iter().map(PinMock::new).collect();
            let mut delay = CheckedDelay::new(&self.delay);
            let mut lcd = Hd44780::new(rs.clone(), e.clone(), d[0].clone(), d[1].clone(), d[2].clone(), d[3].clone());
            body(&mut lcd, &mut delay);
            rs.done();
            e.done();
            for pin in d.iter_mut() {
                pin.done();
            }
            delay.done();
        }
    }

    #[test]
    fn init_follows_the_datasheet_4_bit_sequence() {
        let mut x = Expected::new();
        x.e.push(level(false));
        x.rs.push(level(false));
        x.delay.push(Delay::delay_ms(50));
        for (nibble, wait) in [(0x3, 4_500), (0x3, 150), (0x3, 150), (0x2, 150)] {
            x.nibble(nibble);
            x.delay.push(Delay::delay_us(wait));
        }
        x.byte(false, 0x28, Delay::delay_us(50));
        x.byte(false, 0x08, Delay::delay_us(50));
        x.byte(false, 0x01, Delay::delay_ms(2));
        x.byte(false, 0x06, Delay::delay_us(50));
        x.byte(false, 0x0C, Delay::delay_us(50));
        x.run(|lcd, delay| lcd.init(delay).unwrap());
    }

    #[test]
    fn one_character_is_rs_high_and_two_nibbles_high_first() {
        // 'A' = 0x41: nibble 4 (D6 high) then 1 (D4 high).
        let mut x = Expected::new();
        x.byte(true, b'A', Delay::delay_us(50));
        assert_eq!(x.d[0], [level(false), level(true)]);
        assert_eq!(x.d[2], [level(true), level(false)]);
        x.run(|lcd, delay| lcd.write_str("A", delay).unwrap());
    }

    #[test]
    fn cursor_addresses_rows_at_0x00_and_0x40() {
        let mut x = Expected::new();
        x.byte(false, 0x80 | 0x45, Delay::delay_us(50));
        x.byte(false, 0x80, Delay::delay_us(50));
        x.run(|lcd, delay| {
            lcd.set_cursor(5, 1, delay).unwrap();
            lcd.set_cursor(0, 0, delay).unwrap();
            assert_eq!(lcd.set_cursor(16, 0, delay), Err(CursorOrPinError::Cursor(CursorError::OutOfRange)));
            assert_eq!(lcd.set_cursor(0, 2, delay), Err(CursorOrPinError::Cursor(CursorError::OutOfRange)));
        });
    }

    #[test]
    fn clear_waits_for_the_slow_instruction() {
        let mut x = Expected::new();
        x.byte(false, 0x01, Delay::delay_ms(2));
        x.run(|lcd, delay| lcd.clear(delay).unwrap());
    }

    /// A shared log of every pin write in order, to see the interleaving
    /// the per-pin mocks cannot: data is set before E rises.
    #[derive(Clone)]
    struct Logged(&'static str, Rc<RefCell<Vec<String>>>);
    impl embedded_hal::digital::ErrorType for Logged {
        type Error = core::convert::Infallible;
    }
    impl OutputPin for Logged {
        fn set_low(&mut self) -> Result<(), Self::Error> {
            self.1.borrow_mut().push(std::format!("{}0", self.0));
            Ok(())
        }
        fn set_high(&mut self) -> Result<(), Self::Error> {
            self.1.borrow_mut().push(std::format!("{}1", self.0));
            Ok(())
        }
    }

    #[test]
    fn data_lines_settle_before_e_rises_and_e_falls_to_latch() {
        let log = Rc::new(RefCell::new(Vec::new()));
        let pin = |name| Logged(name, log.clone());
        let mut lcd = Hd44780::new(pin("RS"), pin("E"), pin("D4"), pin("D5"), pin("D6"), pin("D7"));
        lcd.write_str("A", &mut NoopDelay::new()).unwrap();
        assert_eq!(
            log.borrow().join(" "),
            "RS1 D40 D50 D61 D70 E1 E0 D41 D50 D60 D70 E1 E0"
        );
    }

    #[test]
    fn a_screen_is_two_rows_of_sixteen() {
        let log = Rc::new(RefCell::new(Vec::new()));
        let pin = |name| Logged(name, log.clone());
        let mut lcd = Hd44780::new(pin("RS"), pin("E"), pin("D4"), pin("D5"), pin("D6"), pin("D7"));
        lcd.show(&[b'x'; 32], &mut NoopDelay::new()).unwrap();
        let rs_high = log.borrow().iter().filter(|s| *s == "RS1").count();
        let rs_low = log.borrow().iter().filter(|s| *s == "RS0").count();
        assert_eq!((rs_high, rs_low), (32, 2));
    }
}
