//! A simulated board running the firmware core on virtual time.
//!
//! The serial port goes through the same receive ring (`firmware::rx`,
//! emergency scanner included) and the same main-loop duties
//! (`firmware::host_link`) as on the Mega 2560; only the clock is virtual:
//! [`SimBoard::advance`] moves it on by whole milliseconds, so a long job
//! simulates in moments.

use firmware::emergency::Pending;
use firmware::host_link::{HostLink, SerialLink};
use firmware::rx::{self, RxConsumer, RxProducer, RxQueue};
use firmware::storage::MemoryStorage;

/// The simulated EEPROM: 4 KiB like the ATmega2560's.
pub type SimEeprom = MemoryStorage<4096>;

/// Marlin's default line rate.
pub const DEFAULT_BAUD: u32 = 115_200;

/// The firmware core on a simulated board.
pub struct SimBoard {
    pub link: HostLink,
    pub eeprom: SimEeprom,
    producer: RxProducer<'static>,
    /// Bytes sent by the host and still on the wire.
    wire: std::collections::VecDeque<u8>,
    /// Line rate in bytes per second (8N1: baud / 10).
    bytes_per_s: u32,
    /// Fraction of a byte carried over between milliseconds, in 1/1000.
    wire_credit: u32,
    rx: SimRx,
    now_ms: u32,
    output: String,
}

struct SimRx {
    consumer: RxConsumer<'static>,
    dropped: u8,
    emergencies: Pending,
}

impl SerialLink for SimRx {
    fn pop(&mut self) -> Option<u8> {
        self.consumer.pop()
    }
    fn take_dropped(&mut self) -> u8 {
        core::mem::take(&mut self.dropped)
    }
    fn take_emergencies(&mut self) -> Pending {
        core::mem::take(&mut self.emergencies)
    }
}

impl Default for SimBoard {
    fn default() -> Self {
        Self::new()
    }
}

impl SimBoard {
    /// A board that has just booted with a blank EEPROM (its banner is in
    /// the output).
    pub fn new() -> Self {
        Self::with_eeprom(SimEeprom::new())
    }

    /// A board booting with `eeprom`'s contents (e.g. after a power loss).
    pub fn with_eeprom(eeprom: SimEeprom) -> Self {
        // One small ring per board for the life of the process (tests).
        let queue: &'static mut RxQueue = Box::leak(Box::new(RxQueue::new()));
        let (producer, consumer) = rx::split(queue);
        let mut board = Self {
            link: HostLink::new(),
            eeprom,
            producer,
            wire: std::collections::VecDeque::new(),
            bytes_per_s: DEFAULT_BAUD / 10,
            wire_credit: 0,
            rx: SimRx { consumer, dropped: 0, emergencies: Pending::NONE },
            now_ms: 0,
            output: String::new(),
        };
        let _ = board.link.machine.write_banner(&mut Output(&mut board.output));
        let _ = board.link.machine.load_settings(&mut board.eeprom, &mut Output(&mut board.output));
        board
    }

    /// Bytes sent by the host: they arrive at the line rate (115200 baud,
    /// 8N1) while [`SimBoard::advance`] runs, as on a real serial line.
    pub fn receive(&mut self, bytes: &[u8]) {
        self.wire.extend(bytes);
    }

    /// Bytes arriving all at once, faster than any UART: for tests of what
    /// happens when the receive ring overflows.
    pub fn inject(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            if let Some(emergency) = self.producer.push(byte, false) {
                self.rx.emergencies = self.rx.emergencies.with(emergency);
            }
        }
        self.rx.dropped = self.rx.dropped.saturating_add(self.producer.take_dropped());
    }

    /// Run the main loop for `ms` milliseconds of virtual time (one pass per
    /// millisecond).
    pub fn advance(&mut self, ms: u32) {
        for _ in 0..ms.max(1) {
            self.wire_credit += self.bytes_per_s;
            let arriving = (self.wire_credit / 1000) as usize;
            self.wire_credit %= 1000;
            let bytes: Vec<u8> = self.wire.drain(..arriving.min(self.wire.len())).collect();
            self.inject(&bytes);
            let _ = self.link.service(&mut self.rx, &mut self.eeprom, self.now_ms, &mut Output(&mut self.output));
            self.now_ms = self.now_ms.wrapping_add(1);
        }
    }

    /// Virtual time since boot, ms.
    pub fn now_ms(&self) -> u32 {
        self.now_ms
    }

    /// Take everything the firmware has written since the last call.
    pub fn take_output(&mut self) -> String {
        core::mem::take(&mut self.output)
    }
}

struct Output<'a>(&'a mut String);

impl ufmt::uWrite for Output<'_> {
    type Error = core::convert::Infallible;
    fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
        self.0.push_str(s);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_simulated_board_boots_and_answers() {
        let mut board = SimBoard::new();
        assert_eq!(
            board.take_output(),
            "start\necho:Ferrostep 0.1.0 ready\necho:No stored settings\necho:Hardcoded Default Settings Loaded\n"
        );
        board.receive(b"M114\n");
        board.advance(1);
        assert_eq!(board.take_output(), "X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0\nok\n");
    }

    #[test]
    fn a_burst_beyond_the_ring_is_reported_not_lost_silently() {
        let mut board = SimBoard::new();
        board.take_output();
        // 200 bytes at once: more than the 127-byte ring holds.
        let burst = "M118 a\n".repeat(28);
        board.inject(burst.as_bytes());
        board.advance(10);
        let output = board.take_output();
        assert!(output.contains("Error:Serial receive overrun, line lost\n"), "{output}");
        // Every line got exactly one ok: lost ones through their error.
        let answered = output.matches("ok\n").count();
        assert!(answered >= 18 && answered <= 28, "{answered} in {output}");
    }

    #[test]
    fn settings_saved_with_m500_survive_a_reboot() {
        let mut board = SimBoard::new();
        board.receive(b"M92 E415\nM500\n");
        board.advance(10);
        let mut rebooted = SimBoard::with_eeprom(SimEeprom { bytes: board.eeprom.bytes, ..SimEeprom::new() });
        assert!(rebooted.take_output().contains("echo:V1 stored settings retrieved"));
        assert_eq!(rebooted.link.machine.settings().steps_per_mm_milli[3], 415_000);
    }

    #[test]
    fn m112_acts_even_when_the_queue_is_full() {
        let mut board = SimBoard::new();
        board.receive(b"G4 S100\nM114\nM114\nM114\nM114\nM112\n");
        board.advance(5);
        assert!(board.take_output().contains("Error:Printer halted. kill() called!\n"));
        assert!(board.link.machine.is_halted());
    }
}
