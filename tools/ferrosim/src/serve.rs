//! The virtual printer: the firmware core on the simulated board behind a
//! pseudo-terminal, for Printrun, OctoPrint or a terminal.
//!
//! The pty is raw (no echo, no line editing), as a USB serial port is. Time
//! runs at `speed` times real time: each turn of the loop moves the
//! simulated board on by the wall time elapsed (times `speed`), at most 50
//! ms of virtual time per turn so that a slow turn does not make a jump.
//! The serial line keeps its 115200-baud byte rate in virtual time.

use hal_sim::board::{SimBoard, SimEeprom};
use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::pty::openpty;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use std::io::{Read, Write};
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::time::{Duration, Instant};

use crate::simulate::MachineKind;

/// A running virtual printer.
pub struct VirtualPrinter {
    master: std::fs::File,
    /// Kept open so that the pty never hangs up between host connections.
    _slave: OwnedFd,
    pub path: String,
    board: SimBoard,
    speed: f64,
}

impl VirtualPrinter {
    pub fn open(machine: MachineKind, speed: f64) -> Result<Self, String> {
        let pty = openpty(None, None).map_err(|e| format!("openpty: {e}"))?;
        let mut termios = tcgetattr(pty.slave.as_fd()).map_err(|e| e.to_string())?;
        cfmakeraw(&mut termios);
        tcsetattr(pty.slave.as_fd(), SetArg::TCSANOW, &termios).map_err(|e| e.to_string())?;
        let path = std::fs::read_link(format!("/proc/self/fd/{}", pty.slave.as_raw_fd()))
            .map_err(|e| format!("the pty's path: {e}"))?
            .display()
            .to_string();
        let flags = OFlag::from_bits_truncate(fcntl(pty.master.as_raw_fd(), FcntlArg::F_GETFL).map_err(|e| e.to_string())?);
        fcntl(pty.master.as_raw_fd(), FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK)).map_err(|e| e.to_string())?;
        let mut board = SimBoard::with_machine(machine.config(), SimEeprom::new());
        board.set_record_steps(false);
        Ok(Self { master: std::fs::File::from(pty.master), _slave: pty.slave, path, board, speed: speed.max(0.01) })
    }

    /// Run until `stop` says so (checked every turn).
    pub fn run(&mut self, mut stop: impl FnMut(&SimBoard) -> bool) -> Result<(), String> {
        let mut last = Instant::now();
        let mut owed_ms = 0.0;
        let mut buffer = [0u8; 512];
        while !stop(&self.board) {
            match self.master.read(&mut buffer) {
                Ok(n) if n > 0 => self.board.receive(&buffer[..n]),
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
                // EIO: no host has the port open right now.
                Err(e) if e.raw_os_error() == Some(nix::libc::EIO) => {}
                Err(e) => return Err(format!("pty: {e}")),
            }
            let now = Instant::now();
            owed_ms += now.duration_since(last).as_secs_f64() * 1000.0 * self.speed;
            last = now;
            let ms = (owed_ms.floor() as u32).min(50);
            if ms > 0 {
                self.board.advance(ms);
                owed_ms -= f64::from(ms);
            }
            let output = self.board.take_output();
            if !output.is_empty() {
                let _ = self.master.write_all(output.as_bytes());
            }
            std::thread::sleep(Duration::from_micros(500));
        }
        Ok(())
    }
}
