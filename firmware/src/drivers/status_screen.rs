//! The text of a 16×2 status screen (state, position, temperatures), built
//! into a `[u8; 32]` without allocation; [`Hd44780::show`](super::hd44780::Hd44780::show)
//! puts it on the display.
//!
//! ```text
//! row 0: <state, left>   <axis><position mm, 2 decimals, right>
//! row 1: <label><measured>/<target> ... (whole °C, space-separated)
//! ```
//!
//! e.g. `Printing Z12.35` / `T210/210 B60/60`, `Layer 12  Z-3.40` /
//! (no heaters) a blank row, `Auto 2.850mm` / `T210/210` on the extrusion
//! line. Text that does not fit is cut at the row's end, never wrapped.

use crate::thermal::Celsius;

/// One temperature: label letter (`T`, `B`), measured and target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Temperature {
    pub label: u8,
    pub measured: Celsius,
    pub target: Celsius,
}

/// A 16-character row being filled from the left.
#[derive(Clone, Copy, Debug)]
pub struct Row {
    text: [u8; 16],
    length: usize,
}

impl Default for Row {
    fn default() -> Self {
        Self::new()
    }
}

impl Row {
    pub const fn new() -> Self {
        Self { text: [b' '; 16], length: 0 }
    }

    pub fn push_bytes(&mut self, bytes: &[u8]) -> &mut Self {
        for &byte in bytes {
            if self.length < 16 {
                self.text[self.length] = byte;
                self.length += 1;
            }
        }
        self
    }

    pub fn push_str(&mut self, text: &str) -> &mut Self {
        self.push_bytes(text.as_bytes())
    }

    /// A signed integer.
    pub fn push_int(&mut self, value: i32) -> &mut Self {
        let mut digits = [0u8; 12];
        let length = format_fixed(value, 0, &mut digits);
        self.push_bytes(&digits[..length])
    }

    /// `value / 10^decimals` with that many decimals.
    pub fn push_fixed(&mut self, value: i32, decimals: u8) -> &mut Self {
        let mut digits = [0u8; 12];
        let length = format_fixed(value, decimals, &mut digits);
        self.push_bytes(&digits[..length])
    }

    pub fn len(&self) -> usize {
        self.length
    }

    pub fn is_empty(&self) -> bool {
        self.length == 0
    }

    pub fn bytes(&self) -> &[u8; 16] {
        &self.text
    }
}

/// Write `value / 10^decimals` (decimals ≤ 6) into `out`; returns the length.
/// Built from the end, digit by digit through the parser's small divider
/// (no 32-bit library division): the longest text, `-2147483648` or a
/// negative value with a point, is 12 bytes.
pub fn format_fixed(value: i32, decimals: u8, out: &mut [u8; 12]) -> usize {
    let decimals = decimals.min(6);
    let mut magnitude = value.unsigned_abs();
    let mut text = [0u8; 12];
    let mut start = text.len();
    let mut digits = 0u8;
    // At least one digit before the point.
    while magnitude > 0 || digits <= decimals {
        if decimals > 0 && digits == decimals {
            start -= 1;
            text[start] = b'.';
        }
        let (quotient, digit) = crate::gcode::number::div_rem_small(magnitude, 10);
        start -= 1;
        text[start] = b'0' + digit;
        magnitude = quotient;
        digits += 1;
    }
    if value < 0 {
        start -= 1;
        text[start] = b'-';
    }
    let length = text.len() - start;
    out[..length].copy_from_slice(&text[start..]);
    length
}

/// Build a screen: `state` on the left of row 0, the position (µm, shown
/// in mm with two decimals) on its right, the temperatures on row 1.
pub fn format_status(state: &str, position: Option<(u8, i32)>, temperatures: &[Temperature]) -> [u8; 32] {
    let mut screen = [b' '; 32];
    let mut right = Row::new();
    if let Some((axis, um)) = position {
        // µm → hundredths of a mm, rounded half away from zero
        let hundredths = if um >= 0 { (um + 5) / 10 } else { (um - 5) / 10 };
        right.push_bytes(&[axis]).push_fixed(hundredths, 2);
    }
    let room = if right.is_empty() { 16 } else { 15 - right.len() };
    let state = state.as_bytes();
    let state = &state[..state.len().min(room)];
    screen[..state.len()].copy_from_slice(state);
    let start = 16 - right.len();
    screen[start..16].copy_from_slice(&right.bytes()[..right.len()]);

    let mut row = Row::new();
    for (index, temperature) in temperatures.iter().enumerate() {
        if index > 0 {
            row.push_str(" ");
        }
        row.push_bytes(&[temperature.label])
            .push_int(whole_degrees(temperature.measured))
            .push_str("/")
            .push_int(whole_degrees(temperature.target));
    }
    screen[16..].copy_from_slice(row.bytes());
    screen
}

/// Hundredths of °C → whole °C, rounded.
fn whole_degrees(celsius: Celsius) -> i32 {
    let centi = celsius.0;
    if centi >= 0 {
        (centi + 50) / 100
    } else {
        (centi - 50) / 100
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text(screen: &[u8; 32]) -> (&str, &str) {
        (core::str::from_utf8(&screen[..16]).unwrap(), core::str::from_utf8(&screen[16..]).unwrap())
    }

    fn t(label: u8, measured: i32, target: i32) -> Temperature {
        Temperature { label, measured: Celsius(measured), target: Celsius(target) }
    }

    #[test]
    fn printer_screen_state_position_and_two_temperatures() {
        let screen = format_status("Printing", Some((b'Z', 12_345)), &[t(b'T', 20_960, 21_000), t(b'B', 6_000, 6_000)]);
        assert_eq!(text(&screen), ("Printing  Z12.35", "T210/210 B60/60 "));
    }

    #[test]
    fn long_states_are_cut_before_the_position_and_negative_positions_show() {
        let screen = format_status("Measuring travel", Some((b'Z', -3_400)), &[]);
        assert_eq!(text(&screen), ("Measuring Z-3.40", "                "));
    }

    #[test]
    fn no_position_gives_the_state_the_whole_row() {
        let screen = format_status("Auto 2.850mm 3.9", None, &[t(b'T', 21_000, 21_000)]);
        assert_eq!(text(&screen), ("Auto 2.850mm 3.9", "T210/210        "));
    }

    #[test]
    fn fixed_point_formatting() {
        let mut out = [0u8; 12];
        let n = format_fixed(5, 2, &mut out);
        assert_eq!(&out[..n], b"0.05");
        let n = format_fixed(-123_456, 3, &mut out);
        assert_eq!(&out[..n], b"-123.456");
        let n = format_fixed(0, 0, &mut out);
        assert_eq!(&out[..n], b"0");
        let n = format_fixed(i32::MIN, 0, &mut out);
        assert_eq!(&out[..n], b"-2147483648");
        let n = format_fixed(-7, 6, &mut out);
        assert_eq!(&out[..n], b"-0.000007");
        let n = format_fixed(i32::MIN, 6, &mut out);
        assert_eq!(&out[..n], b"-2147.483648");
        let n = format_fixed(2_100, 1, &mut out);
        assert_eq!(&out[..n], b"210.0");
    }
}
