//! An emulator process (QEMU's Mega 2560 or its SKR Pro stand-in) whose
//! serial port is its stdin/stdout: reply lines arrive on a channel filled
//! by a reader thread, bytes go out at a host's line rate. Both boards'
//! test drivers (`qemu`, `qemu_arm`) are this plus how to start them.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

/// A running emulator, talked to line by line. Dropping it kills the
/// emulator.
pub struct EmulatedSerial {
    child: Child,
    input: ChildStdin,
    lines: Receiver<String>,
}

impl EmulatedSerial {
    /// Start `command` (stdin and stdout piped); `missing` says what to
    /// install when it cannot start.
    pub fn spawn(mut command: Command, missing: &str) -> Self {
        let mut child = command.spawn().unwrap_or_else(|e| panic!("{missing} ({e})"));
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

    /// Send bytes at 115200 baud. QEMU's USARTs have no baud rate: they
    /// hand the next byte over as soon as the firmware has read the last
    /// one, far faster than any serial line, and a host never sends faster
    /// than its line; so the bytes go in chunks of 8 at 11.52 bytes per ms.
    pub fn send(&mut self, bytes: &[u8]) {
        send_at_line_rate(&mut self.input, bytes);
    }

    /// Bytes in one write, as fast as the emulator takes them: a host (or a
    /// stalled emulator catching up) that outruns the main loop.
    pub fn send_burst(&mut self, bytes: &[u8]) {
        let _ = self.input.write_all(bytes);
        let _ = self.input.flush();
    }

    /// Reply lines until one satisfies `last` (inclusive); panics with what
    /// was received if that takes longer than `timeout`.
    pub fn read_until(&mut self, timeout: Duration, last: impl Fn(&str) -> bool) -> Vec<String> {
        let deadline = Instant::now() + timeout;
        let mut received = Vec::new();
        loop {
            match self.lines.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Ok(line) => {
                    let done = last(&line);
                    received.push(line);
                    if done {
                        return received;
                    }
                }
                Err(RecvTimeoutError::Timeout) => panic!("no matching reply within {timeout:?}; received {received:?}"),
                Err(RecvTimeoutError::Disconnected) => panic!("the emulator exited; received {received:?}"),
            }
        }
    }

    /// One command line, and its replies up to the final `ok`.
    pub fn command(&mut self, line: &str) -> Vec<String> {
        self.send(format!("{line}\n").as_bytes());
        self.read_until(Duration::from_secs(10), |l| l == "ok" || l.starts_with("ok "))
    }
}

impl Drop for EmulatedSerial {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `program` with `args`, its serial port on stdin/stdout (stderr
/// dropped), killed when the test process dies (so an aborted test leaves
/// no emulator behind).
pub fn emulator_command<S: AsRef<std::ffi::OsStr>>(program: &str, args: impl IntoIterator<Item = S>) -> Command {
    use std::os::unix::process::CommandExt;
    let mut command = Command::new(program);
    command.args(args).stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::null());
    // SAFETY: prctl is async-signal-safe; nothing else runs in the child.
    unsafe {
        command.pre_exec(|| nix::sys::prctl::set_pdeathsig(nix::sys::signal::Signal::SIGKILL).map_err(std::io::Error::from));
    }
    command
}

/// See [`EmulatedSerial::send`].
pub fn send_at_line_rate(input: &mut ChildStdin, bytes: &[u8]) {
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
