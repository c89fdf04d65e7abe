//! The Mega 2560 ELF on QEMU's `mega2560` machine, with USART0 on pipes.
//!
//! QEMU is not cycle-accurate and has no ADC (thermistors read as shorted):
//! it checks that the real build boots and talks. Timing and pins are the
//! simavr bench's job (`tests/avr-bench`).

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

/// `qemu-system-avr` for `elf`, with USART0 on stdin/stdout, dying with
/// the test process (so an aborted test leaves no emulator behind).
fn qemu_command(elf: &Path) -> Command {
    use std::os::unix::process::CommandExt;
    let mut command = Command::new("qemu-system-avr");
    command
        .args(["-M", "mega2560", "-display", "none", "-serial", "stdio", "-monitor", "none", "-bios"])
        .arg(elf)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    // SAFETY: prctl is async-signal-safe; nothing else runs in the child.
    unsafe {
        command.pre_exec(|| {
            nix::sys::prctl::set_pdeathsig(nix::sys::signal::Signal::SIGKILL).map_err(std::io::Error::from)
        });
    }
    command
}

/// QEMU's USART has no baud rate: it hands the next byte over as soon as
/// the firmware has read the last one, far faster than any serial line. A
/// host never sends faster than its line, so the tests pace their bytes at
/// 115200 baud (11.52 bytes per ms), in chunks of 8.
fn send_at_line_rate(input: &mut ChildStdin, bytes: &[u8]) {
    const CHUNK: usize = 8;
    let chunk_time = Duration::from_micros(CHUNK as u64 * 10 * 1_000_000 / 115_200);
    for chunk in bytes.chunks(CHUNK) {
        let started = Instant::now();
        let _ = input.write_all(chunk);
        let _ = input.flush();
        if let Some(left) = chunk_time.checked_sub(started.elapsed()) {
            std::thread::sleep(left);
        }
    }
}

/// A running emulated board.
pub struct QemuBoard {
    child: Child,
    input: ChildStdin,
    lines: Receiver<String>,
}

impl QemuBoard {
    /// Boot `elf` on an emulated Mega 2560.
    pub fn boot(elf: &Path) -> Self {
        let mut child = qemu_command(elf)
            .spawn()
            .expect("cannot start qemu-system-avr (run bash tests/scripts/test.sh, which installs qemu-system-misc)");
        let input = child.stdin.take().expect("piped stdin");
        let output = child.stdout.take().expect("piped stdout");
        let (sender, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(output).lines() {
                let Ok(line) = line else { break };
                if sender.send(line).is_err() {
                    break;
                }
            }
        });
        Self { child, input, lines }
    }

    /// Send raw bytes to the board's serial port, at 115200 baud.
    pub fn send(&mut self, bytes: &[u8]) {
        send_at_line_rate(&mut self.input, bytes);
    }

    /// Collect reply lines until one satisfies `last` (inclusive); panics
    /// with everything received if that takes longer than `timeout`.
    pub fn read_until(&mut self, timeout: Duration, last: impl Fn(&str) -> bool) -> Vec<String> {
        let deadline = Instant::now() + timeout;
        let mut received = Vec::new();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    let done = last(&line);
                    received.push(line);
                    if done {
                        return received;
                    }
                }
                Err(RecvTimeoutError::Timeout) => panic!("no matching reply within {timeout:?}; received {received:?}"),
                Err(RecvTimeoutError::Disconnected) => panic!("QEMU exited; received {received:?}"),
            }
        }
    }

    /// Send one command line and return its replies up to the final `ok`.
    pub fn command(&mut self, line: &str) -> Vec<String> {
        self.send(format!("{line}\n").as_bytes());
        self.read_until(Duration::from_secs(10), |l| l == "ok" || l.starts_with("ok "))
    }
}

impl Drop for QemuBoard {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The emulated board as a raw byte port (for the printcore relay).
pub struct QemuPort {
    child: Child,
    input: ChildStdin,
    chunks: Receiver<Vec<u8>>,
}

impl QemuPort {
    pub fn boot(elf: &Path) -> Self {
        let mut child = qemu_command(elf)
            .spawn()
            .expect("cannot start qemu-system-avr (run bash tests/scripts/test.sh, which installs qemu-system-misc)");
        let input = child.stdin.take().expect("piped stdin");
        let mut output = child.stdout.take().expect("piped stdout");
        let (sender, chunks) = mpsc::channel();
        std::thread::spawn(move || {
            let mut buffer = [0u8; 512];
            while let Ok(n) = std::io::Read::read(&mut output, &mut buffer) {
                if n == 0 || sender.send(buffer[..n].to_vec()).is_err() {
                    break;
                }
            }
        });
        Self { child, input, chunks }
    }
}

impl crate::printcore::BoardPort for QemuPort {
    fn send(&mut self, bytes: &[u8]) {
        send_at_line_rate(&mut self.input, bytes);
    }

    fn receive(&mut self) -> Vec<u8> {
        let mut bytes = Vec::new();
        while let Ok(chunk) = self.chunks.try_recv() {
            bytes.extend_from_slice(&chunk);
        }
        bytes
    }
}

impl Drop for QemuPort {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
