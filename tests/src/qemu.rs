//! The Mega 2560 ELF on QEMU's `mega2560` machine, with USART0 on pipes.
//!
//! QEMU is not cycle-accurate and has no ADC (thermistors read as shorted):
//! it checks that the real build boots and talks. Timing and pins are the
//! simavr bench's job (`tests/avr-bench`).

use crate::emulated::{emulator_command, send_at_line_rate, EmulatedSerial};
use std::path::Path;
use std::process::{Child, ChildStdin, Command};
use std::sync::mpsc::{self, Receiver};

/// `qemu-system-avr` for `elf`, with USART0 on stdin/stdout, dying with
/// the test process (so an aborted test leaves no emulator behind).
fn qemu_command(elf: &Path) -> Command {
    let args = ["-M", "mega2560", "-display", "none", "-serial", "stdio", "-monitor", "none", "-bios"];
    emulator_command("qemu-system-avr", args.iter().map(std::ffi::OsStr::new).chain([elf.as_os_str()]))
}

/// A running emulated board (its serial port: see [`EmulatedSerial`]).
pub type QemuBoard = EmulatedSerial;

/// Boot `elf` on an emulated Mega 2560.
pub fn boot(elf: &Path) -> QemuBoard {
    EmulatedSerial::spawn(qemu_command(elf), "cannot start qemu-system-avr (run bash tests/scripts/test.sh, which installs qemu-system-misc)")
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
