//! `M828`: X/Y encoder traces streamed to the host at the loop rate, for
//! recording a real machine and replaying it on a laptop
//! (`cargo sim replay`).
//!
//! The tick records one [`TraceSample`] per loop sample into a small ring
//! ([`TraceRecorder`]); the main loop takes them out and writes one line
//! each. The line is short because it must fit the wire 250 times a
//! second (26 bytes: 57 % of 115200 baud, 26 % of 250000):
//!
//! ```text
//! TR:start <loop Hz> <X steps/mm ×1000> <Y steps/mm ×1000>
//! TR:<ss><xxx><i><cccccc><yyy><j><dddddd>
//! TR:end <samples recorded> <samples dropped>
//! ```
//!
//! Sample lines are fixed-width upper-case hexadecimal, no separators:
//! `ss` the sample number modulo 256 (a gap means samples were dropped:
//! the host did not drain the ring fast enough); per axis, X then Y, `xxx`
//! the 12-bit raw count read from the NSE-5310 (`---` when the read
//! failed), `i` the debounced Index edges since the previous sample
//! (capped at 15), `cccccc` the commanded position: the steps the step
//! interrupt has made on that axis since boot, 24-bit two's complement.
//! The start line gives the scale (steps/mm in thousandths), the end line
//! the totals.

use super::Reading;
use crate::reply::Fixed;
use ufmt::uWrite;

/// Samples the ring holds between two main-loop visits (a visit every
/// millisecond, a sample every 4: the slack covers a long main-loop pass
/// of ≈ 30 ms).
pub const TRACE_DEPTH: usize = 8;
/// A failed read in a [`TraceSample`].
pub const FAILED_READ: u16 = 0xFFFF;

/// One loop sample of both axes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TraceSample {
    /// Sample number modulo 256.
    pub number: u8,
    /// Raw counts, [`FAILED_READ`] when the read failed.
    pub raw: [u16; 2],
    /// Debounced Index edges since the previous sample.
    pub index: [u8; 2],
    /// Steps made since boot (the commanded position).
    pub steps: [i32; 2],
}

impl TraceSample {
    pub fn new(number: u8, readings: [Reading; 2], index: [u8; 2], steps: [i32; 2]) -> Self {
        let raw = readings.map(|reading| match reading {
            Reading::Raw(raw) => raw & 0x0FFF,
            Reading::Failed => FAILED_READ,
        });
        Self { number, raw, index, steps }
    }

    /// The sample's line, `TR:…\n` (see the module's documentation).
    pub fn write_line<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        // (Bytes one by one: on the AVR a byte-string literal would be
        // copied to SRAM at boot.)
        let mut line = [b'-'; 26];
        line[0] = b'T';
        line[1] = b'R';
        line[2] = b':';
        hex(&mut line[3..5], u32::from(self.number));
        for axis in 0..2 {
            let at = 5 + axis * 10;
            if self.raw[axis] != FAILED_READ {
                hex(&mut line[at..at + 3], u32::from(self.raw[axis]));
            }
            hex(&mut line[at + 3..at + 4], u32::from(self.index[axis].min(15)));
            hex(&mut line[at + 4..at + 10], self.steps[axis] as u32 & 0x00FF_FFFF);
        }
        line[25] = b'\n';
        line.iter().try_for_each(|&byte| out.write_char(char::from(byte)))
    }
}

/// `value`'s low digits in upper-case hexadecimal, filling `digits`.
fn hex(digits: &mut [u8], mut value: u32) {
    for digit in digits.iter_mut().rev() {
        let nibble = (value & 0xF) as u8;
        *digit = if nibble < 10 { b'0' + nibble } else { b'A' + nibble - 10 };
        value >>= 4;
    }
}

/// The ring between the tick (producer) and the main loop (consumer);
/// both reach it with the other kept out (the board masks the tick).
#[derive(Clone, Copy, Debug)]
pub struct TraceRecorder {
    on: bool,
    next_number: u8,
    samples: [TraceSample; TRACE_DEPTH],
    /// Oldest sample and how many are held.
    head: u8,
    held: u8,
    recorded: u32,
    dropped: u32,
}

impl TraceRecorder {
    pub const fn new() -> Self {
        const EMPTY: TraceSample = TraceSample { number: 0, raw: [0; 2], index: [0; 2], steps: [0; 2] };
        Self { on: false, next_number: 0, samples: [EMPTY; TRACE_DEPTH], head: 0, held: 0, recorded: 0, dropped: 0 }
    }

    pub fn is_on(&self) -> bool {
        self.on
    }

    /// Start a capture (numbering and totals from zero, also when one was
    /// running) or stop one (the samples still held can be taken).
    pub fn set(&mut self, on: bool) {
        if on {
            *self = Self::new();
        }
        self.on = on;
    }

    /// From the tick: one sample (dropped, and counted, if the ring is full).
    pub fn record(&mut self, readings: [Reading; 2], index: [u8; 2], steps: [i32; 2]) {
        if !self.on {
            return;
        }
        let sample = TraceSample::new(self.next_number, readings, index, steps);
        self.next_number = self.next_number.wrapping_add(1);
        self.recorded = self.recorded.wrapping_add(1);
        if usize::from(self.held) == TRACE_DEPTH {
            self.dropped = self.dropped.wrapping_add(1);
            return;
        }
        let slot = (usize::from(self.head) + usize::from(self.held)) % TRACE_DEPTH;
        self.samples[slot] = sample;
        self.held += 1;
    }

    /// From the main loop: the oldest sample held.
    pub fn take(&mut self) -> Option<TraceSample> {
        if self.held == 0 {
            return None;
        }
        let sample = self.samples[usize::from(self.head)];
        self.head = ((usize::from(self.head) + 1) % TRACE_DEPTH) as u8;
        self.held -= 1;
        Some(sample)
    }

    /// Samples recorded and dropped since the capture started.
    pub fn totals(&self) -> (u32, u32) {
        (self.recorded, self.dropped)
    }
}

impl Default for TraceRecorder {
    fn default() -> Self {
        Self::new()
    }
}

/// `TR:start <hz> <x> <y>\n`: the loop rate and X's and Y's steps/mm in
/// thousandths.
pub fn write_start<W: uWrite + ?Sized>(loop_hz: u16, steps_per_mm_milli: [i32; 2], out: &mut W) -> Result<(), W::Error> {
    crate::flash_str!("TR:start ").write_to(out)?;
    let [x, y] = steps_per_mm_milli;
    numbers([i32::from(loop_hz), x, y], out)
}

/// `TR:end <recorded> <dropped>\n`.
pub fn write_end<W: uWrite + ?Sized>(recorded: u32, dropped: u32, out: &mut W) -> Result<(), W::Error> {
    crate::flash_str!("TR:end ").write_to(out)?;
    let total = |count: u32| count.min(i32::MAX as u32) as i32;
    numbers([total(recorded), total(dropped)], out)
}

/// Whole numbers separated by spaces, then the end of the line (without
/// `uwrite!`'s literals, which the AVR would keep in SRAM).
fn numbers<W: uWrite + ?Sized, const N: usize>(values: [i32; N], out: &mut W) -> Result<(), W::Error> {
    for (n, value) in values.into_iter().enumerate() {
        if n > 0 {
            out.write_char(' ')?;
        }
        ufmt::uDisplay::fmt(&Fixed::whole(value), &mut ufmt::Formatter::new(out))?;
    }
    out.write_char('\n')
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    struct Text(std::string::String);

    impl uWrite for Text {
        type Error = core::convert::Infallible;
        fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
            self.0.push_str(s);
            Ok(())
        }
    }

    fn line(sample: &TraceSample) -> std::string::String {
        let mut text = Text(std::string::String::new());
        let Ok(()) = sample.write_line(&mut text);
        text.0
    }

    #[test]
    fn a_sample_line_is_fixed_width_hexadecimal() {
        let sample = TraceSample::new(0x1A, [Reading::Raw(0xABC), Reading::Failed], [1, 20], [2000, -1]);
        assert_eq!(line(&sample), "TR:1AABC10007D0---FFFFFFF\n");
        assert_eq!(line(&sample).len(), 26);
    }

    #[test]
    fn the_ring_keeps_order_counts_drops_and_numbers_every_sample() {
        let mut recorder = TraceRecorder::new();
        recorder.record([Reading::Raw(1); 2], [0; 2], [0; 2]);
        assert_eq!(recorder.take(), None, "off: nothing recorded");
        recorder.set(true);
        for n in 0..(TRACE_DEPTH as i32 + 3) {
            recorder.record([Reading::Raw(n as u16); 2], [0; 2], [n, -n]);
        }
        assert_eq!(recorder.totals(), (TRACE_DEPTH as u32 + 3, 3));
        let taken: Vec<TraceSample> = core::iter::from_fn(|| recorder.take()).collect();
        assert_eq!(taken.len(), TRACE_DEPTH);
        assert!(taken.iter().enumerate().all(|(n, s)| usize::from(s.number) == n && s.steps == [n as i32, -(n as i32)]));
        // The numbering goes on past the drops: the host sees the gap.
        recorder.record([Reading::Raw(0); 2], [0; 2], [0; 2]);
        assert_eq!(recorder.take().map(|s| s.number), Some(TRACE_DEPTH as u8 + 3));
        recorder.set(false);
        recorder.record([Reading::Raw(0); 2], [0; 2], [0; 2]);
        assert_eq!(recorder.take(), None);
        assert_eq!(recorder.totals().0, TRACE_DEPTH as u32 + 4);
    }

    #[test]
    fn start_and_end_lines() {
        let mut text = Text(std::string::String::new());
        let Ok(()) = write_start(250, [100_000, 80_500], &mut text);
        let Ok(()) = write_end(1234, 2, &mut text);
        assert_eq!(text.0, "TR:start 250 100000 80500\nTR:end 1234 2\n");
    }
}
