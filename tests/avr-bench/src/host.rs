//! The host at the other end of USART0: streams G-code lines like Printrun's
//! printcore or OctoPrint do (one line in flight, the next one after `ok`),
//! at a real baud rate, and collects the firmware's reply lines.
//!
//! Timing model (all in CPU cycles of the simulated 16 MHz chip):
//! - A byte's start bit leaves the host at `start`; the next byte can start
//!   one frame later. A frame is 10 bits (start, 8 data, stop) at the
//!   host's baud rate, never shorter than the AVR's own frame: the host
//!   never sends faster than the UART carries.
//! - A byte the firmware writes to UDR0 at cycle `c` has arrived at the
//!   host when its stop bit ends, one AVR frame later.
//! - The host reacts to a completed `ok` line at once (no USB or OS latency):
//!   the figures are what the firmware and the wire allow, an upper bound
//!   for real hosts.

use std::collections::VecDeque;

/// How lines are paced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    /// One line in flight: the next line starts after the `ok` of the
    /// previous one (Printrun, OctoPrint, Repetier-Host, Pronterface).
    OkPerLine,
    /// Everything back to back at full line rate, ignoring replies (a
    /// misbehaving host, or a paste into a terminal): tests receive
    /// overflow handling.
    Burst,
    /// Up to this many lines sent and not yet acknowledged: a host that
    /// sends faster than the firmware takes lines (OctoPrint after a
    /// timeout, a streaming host that counts on the receive buffer). A
    /// `Resend:` empties the window: the host goes back to the line asked
    /// for and counts what it sent before as lost.
    InFlight(usize),
}

#[derive(Clone, Debug)]
pub struct HostConfig {
    /// The host's baud rate (the AVR's rate comes from its UBRR setting).
    pub baud: u32,
    pub flow: Flow,
    /// Add `N<n>` and `*<checksum>` to every line and start with
    /// `N-1 M110` (printcore's numbering); otherwise lines go out verbatim.
    pub numbering: bool,
    /// Honour `Resend: <n>` (only meaningful with `numbering`).
    pub resend: bool,
    /// printcore's flow: a `Resend:` line, like an `ok`, lets the next line
    /// go (its `clear` flag is set by both), so after a refusal two lines
    /// go out: the one asked for and the next.
    pub send_on_resend: bool,
    /// Bit flips on the way to the firmware: in this many millionths of
    /// the job's bytes, one bit flipped (at most one per line: Marlin's
    /// checksum is an XOR, which two flips of the same bit cancel).
    pub flips_per_million: u32,
    /// Seed of the flips.
    pub noise_seed: u64,
}

impl HostConfig {
    pub fn printcore(baud: u32) -> Self {
        Self {
            baud,
            flow: Flow::OkPerLine,
            numbering: true,
            resend: true,
            send_on_resend: false,
            flips_per_million: 0,
            noise_seed: 1,
        }
    }

    /// printcore as it is (a line on every `ok` and every `Resend:`),
    /// through a line that flips bits in `flips_per_million` of the bytes.
    pub fn noisy_printcore(baud: u32, flips_per_million: u32, noise_seed: u64) -> Self {
        Self { send_on_resend: true, flips_per_million, noise_seed, ..Self::printcore(baud) }
    }

    /// Lines verbatim, one at a time after `ok` (for protocol tests that
    /// write their own `N…*…`).
    pub fn raw(baud: u32) -> Self {
        Self {
            baud,
            flow: Flow::OkPerLine,
            numbering: false,
            resend: false,
            send_on_resend: false,
            flips_per_million: 0,
            noise_seed: 1,
        }
    }
}

/// One reply line from the firmware.
#[derive(Clone, Debug)]
pub struct Reply {
    pub text: String,
    /// Cycle at which the firmware wrote the line's first byte to UDR0.
    pub first_byte_cycle: u64,
    /// Cycle at which the line's last byte (`\n`) had arrived at the host.
    pub arrived_cycle: u64,
}

/// One line the host sent.
#[derive(Clone, Debug)]
pub struct SentLine {
    /// Index in the job (`None` for the host's own `M110` preamble).
    pub job_index: Option<usize>,
    pub text: String,
    /// Start bit of the first byte.
    pub start_cycle: u64,
    /// Start bit of the terminating `\n` (once sent).
    pub last_byte_start_cycle: Option<u64>,
    /// Index into `replies` of the first reply line that began after this
    /// line's `\n` was sent, and of the `ok` that acknowledged it.
    pub first_reply: Option<usize>,
    pub ok_reply: Option<usize>,
}

/// The host's state; driven by the board's run loop.
#[derive(Debug)]
pub struct Host {
    pub config: HostConfig,
    job: Vec<String>,
    /// Next job line to send.
    next: usize,
    /// The next line number (with `numbering`).
    line_number: i64,
    numbered_job_lines: Vec<(i64, usize)>,
    preamble_pending: bool,
    /// Bytes of the line being sent.
    wire: VecDeque<u8>,
    /// Cycle (fractional) at which the next start bit may go out.
    pub next_start: f64,
    /// Frame length in use, cycles: the host's own or the AVR's, whichever
    /// is longer.
    pub frame_cycles: f64,
    /// The host's own frame, cycles (10 bits at `baud`).
    own_frame_cycles: f64,
    awaiting_ok: bool,
    /// Lines sent and not yet acknowledged ([`Flow::InFlight`]).
    in_flight: usize,
    rx_line: Vec<u8>,
    rx_line_first_cycle: u64,
    pub sent: Vec<SentLine>,
    pub replies: Vec<Reply>,
    pub oks: usize,
    pub resends: Vec<i64>,
    /// Raw bytes received, with the cycle each was written to UDR0.
    pub rx_bytes: Vec<(u64, u8)>,
    /// Bits flipped on the way (see [`HostConfig::flips_per_million`]).
    pub flips: usize,
    noise_state: u64,
}

impl Host {
    pub fn new(config: HostConfig, cpu_hz: u32) -> Self {
        let frame_cycles = 10.0 * f64::from(cpu_hz) / f64::from(config.baud);
        Self {
            job: Vec::new(),
            next: 0,
            line_number: 0,
            numbered_job_lines: Vec::new(),
            preamble_pending: false,
            wire: VecDeque::new(),
            next_start: 0.0,
            frame_cycles,
            own_frame_cycles: frame_cycles,
            awaiting_ok: false,
            in_flight: 0,
            rx_line: Vec::new(),
            rx_line_first_cycle: 0,
            sent: Vec::new(),
            replies: Vec::new(),
            oks: 0,
            resends: Vec::new(),
            rx_bytes: Vec::new(),
            flips: 0,
            noise_state: config.noise_seed | 1,
            config,
        }
    }

    /// xorshift64*: the flips, reproducibly.
    fn noise(&mut self) -> u64 {
        self.noise_state ^= self.noise_state >> 12;
        self.noise_state ^= self.noise_state << 25;
        self.noise_state ^= self.noise_state >> 27;
        self.noise_state.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Queue lines to send (comments and blank lines are stripped, as hosts do;
    /// with `numbering` off lines go verbatim, so `"\n"` can be sent).
    pub fn queue<I, S>(&mut self, lines: I)
    where
        I: IntoIterator<Item = S>,
        S: AsRef<str>,
    {
        for line in lines {
            let line = line.as_ref();
            if self.config.numbering {
                let stripped = line.split(';').next().unwrap_or("").trim();
                if stripped.is_empty() {
                    continue;
                }
                if self.job.is_empty() && self.sent.is_empty() {
                    self.preamble_pending = true;
                }
                self.job.push(stripped.to_string());
            } else {
                self.job.push(line.to_string());
            }
        }
    }

    /// Put `line` on the wire now, behind the bytes already there, without
    /// waiting for an `ok`: a host that paces itself (Pronterface or
    /// OctoPrint on the run command's pty), or `M112`/`M108`/`M410`, which
    /// the firmware reads in its receive interrupt even while a command
    /// waits. Not recorded in `sent`.
    pub fn send_now(&mut self, line: &str) {
        self.wire.extend(line.bytes());
        self.wire.push_back(b'\n');
    }

    /// Bytes still to go out on the wire (of lines already started).
    pub fn wire_len(&self) -> usize {
        self.wire.len()
    }

    /// Every queued line has been sent and (with ok flow) acknowledged.
    pub fn is_done(&self) -> bool {
        self.next >= self.job.len()
            && !self.preamble_pending
            && self.wire.is_empty()
            && match self.config.flow {
                Flow::Burst => true,
                Flow::OkPerLine => !self.awaiting_ok,
                Flow::InFlight(_) => self.in_flight == 0,
            }
    }

    pub fn lines_acknowledged(&self) -> usize {
        self.sent
            .iter()
            .filter(|s| s.job_index.is_some() && s.ok_reply.is_some())
            .count()
    }

    /// The AVR's frame may be longer than the host's (a slower real baud):
    /// the host cannot send faster than the receiver takes bytes. Called on
    /// every write to the UART's setup registers: the frame follows the
    /// *current* setting. (Until session 8 it kept the longest frame ever
    /// seen, and the firmware writes UBRR0 before it sets U2X0, so for an
    /// instant the frame is twice as long: every host in the bench then
    /// sent at half the baud rate, 58 800 instead of 115 200, and every
    /// line-rate figure was about half what the wire allows.)
    pub fn set_min_frame(&mut self, avr_frame_cycles: f64) {
        self.frame_cycles = self.own_frame_cycles.max(avr_frame_cycles);
    }

    /// If a byte is due at `now`, return it (the board injects it).
    pub fn poll_byte(&mut self, now: u64) -> Option<u8> {
        if (now as f64) < self.next_start {
            return None;
        }
        if self.wire.is_empty() && !self.load_next_line(now) {
            return None;
        }
        let byte = self.wire.pop_front()?;
        let start = self.next_start.max(now as f64);
        if let Some(line) = self.sent.last_mut() {
            if byte == b'\n' && self.wire.is_empty() {
                line.last_byte_start_cycle = Some(start as u64);
            }
        }
        self.next_start = start + self.frame_cycles;
        Some(byte)
    }

    fn load_next_line(&mut self, now: u64) -> bool {
        if self.config.flow == Flow::OkPerLine && self.awaiting_ok {
            return false;
        }
        if matches!(self.config.flow, Flow::InFlight(window) if self.in_flight >= window) {
            return false;
        }
        let (text, job_index) = if self.preamble_pending {
            self.preamble_pending = false;
            self.line_number = 0;
            (with_checksum("N-1 M110"), None)
        } else if self.next < self.job.len() {
            let index = self.next;
            self.next += 1;
            if self.config.numbering {
                let n = self.line_number;
                self.line_number += 1;
                self.numbered_job_lines.push((n, index));
                (
                    with_checksum(&format!("N{n} {}", self.job[index])),
                    Some(index),
                )
            } else {
                (self.job[index].clone(), Some(index))
            }
        } else {
            return false;
        };
        let start = self.next_start.max(now as f64) as u64;
        let mut bytes: Vec<u8> = text.bytes().chain([b'\n']).collect();
        if job_index.is_some() && self.config.flips_per_million > 0 {
            for i in 0..bytes.len() {
                if self.noise() % 1_000_000 < u64::from(self.config.flips_per_million) {
                    let bit = self.noise() % 8;
                    bytes[i] ^= 1 << bit;
                    self.flips += 1;
                    break;
                }
            }
        }
        self.wire.extend(bytes);
        self.sent.push(SentLine {
            job_index,
            text,
            start_cycle: start,
            last_byte_start_cycle: None,
            first_reply: None,
            ok_reply: None,
        });
        self.awaiting_ok = true;
        self.in_flight += 1;
        true
    }

    /// A byte the firmware wrote to UDR0 at `cycle`, arriving at the host
    /// `avr_frame` cycles later.
    pub fn on_firmware_byte(&mut self, cycle: u64, byte: u8, avr_frame: u64) {
        self.rx_bytes.push((cycle, byte));
        if self.rx_line.is_empty() {
            self.rx_line_first_cycle = cycle;
        }
        if byte != b'\n' {
            self.rx_line.push(byte);
            return;
        }
        let arrived = cycle + avr_frame;
        let text = String::from_utf8_lossy(&self.rx_line)
            .trim_end_matches('\r')
            .to_string();
        self.rx_line.clear();
        let index = self.replies.len();
        self.replies.push(Reply {
            text: text.clone(),
            first_byte_cycle: self.rx_line_first_cycle,
            arrived_cycle: arrived,
        });
        let first_byte = self.rx_line_first_cycle;
        for line in self.sent.iter_mut().rev() {
            if line.first_reply.is_some() {
                break;
            }
            if line
                .last_byte_start_cycle
                .is_some_and(|end| first_byte >= end)
            {
                line.first_reply = Some(index);
            }
        }
        if let Some(rest) = text.strip_prefix("Resend:") {
            if let Ok(n) = rest.trim().parse::<i64>() {
                self.resends.push(n);
                if self.config.resend && self.config.numbering {
                    self.rewind_to(n);
                    if matches!(self.config.flow, Flow::InFlight(_)) {
                        self.in_flight = 0;
                    }
                }
                if self.config.send_on_resend && self.config.flow == Flow::OkPerLine {
                    self.awaiting_ok = false;
                    self.next_start = self.next_start.max((cycle + avr_frame) as f64);
                }
            }
        }
        if text.starts_with("ok") {
            self.oks += 1;
            if let Some(line) = self.sent.iter_mut().find(|l| l.ok_reply.is_none()) {
                line.ok_reply = Some(index);
            }
            self.in_flight = self.in_flight.saturating_sub(1);
            if self.config.flow == Flow::OkPerLine && (self.wire.is_empty() || self.config.send_on_resend) {
                self.awaiting_ok = false;
                self.next_start = self.next_start.max(arrived as f64);
            }
        }
    }

    fn rewind_to(&mut self, number: i64) {
        if let Some(&(_, index)) = self.numbered_job_lines.iter().find(|(n, _)| *n == number) {
            self.next = index;
            self.line_number = number;
            self.numbered_job_lines.retain(|(n, _)| *n < number);
        }
    }

    /// The reply texts, in order.
    pub fn reply_texts(&self) -> Vec<&str> {
        self.replies.iter().map(|r| r.text.as_str()).collect()
    }

    /// Everything received so far as one string.
    pub fn transcript(&self) -> String {
        String::from_utf8_lossy(&self.rx_bytes.iter().map(|(_, b)| *b).collect::<Vec<_>>())
            .into_owned()
    }

    /// Forget what was sent and received (between bench phases).
    pub fn clear_log(&mut self) {
        self.sent.clear();
        self.replies.clear();
        self.rx_bytes.clear();
        self.resends.clear();
        self.oks = 0;
        self.job.clear();
        self.next = 0;
        self.numbered_job_lines.clear();
    }
}

/// `line*<xor of every byte>`, Marlin's checksum.
pub fn with_checksum(line: &str) -> String {
    let sum = line.bytes().fold(0u8, |s, b| s ^ b);
    format!("{line}*{sum}")
}
