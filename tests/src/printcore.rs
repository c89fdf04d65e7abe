//! Printrun's `printcore` (a real host) streaming into a board through a
//! pseudo-terminal, with a relay in the middle that can corrupt lines.
//!
//! ```text
//! printcore ──pty── relay (corrupts chosen lines once) ── board serial
//! ```
//!
//! The relay records everything the board sends, so a test can check that
//! every line was executed once and in order.

use nix::pty::openpty;
use std::collections::BTreeSet;
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::OwnedFd;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::workspace_root;

/// A Python with Printrun 2.2.0 (printcore needs only pyserial), in a venv
/// under `target/`; created on first use.
pub fn printcore_python() -> PathBuf {
    static PYTHON: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    PYTHON.get_or_init(create_printcore_venv).clone()
}

fn create_printcore_venv() -> PathBuf {
    let root = workspace_root();
    let target = std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from).unwrap_or_else(|| root.join("target"));
    let venv = target.join("printrun-venv");
    let python = venv.join("bin/python");
    let ready = venv.join(".installed-2.2.0");
    if !ready.exists() {
        let status = Command::new("python3").arg("-m").arg("venv").arg(&venv).status().expect("python3 is needed");
        assert!(status.success(), "python3 -m venv failed (Debian: apt-get install python3-venv)");
        let status = Command::new(&python)
            .args(["-m", "pip", "install", "--quiet", "--no-deps", "printrun==2.2.0", "pyserial"])
            .status()
            .expect("pip");
        assert!(status.success(), "pip install printrun failed");
        std::fs::write(&ready, b"").unwrap();
    }
    python
}

/// Which host lines (by their `N` number) to corrupt, once each.
#[derive(Clone, Default)]
pub struct Corruption {
    pub line_numbers: BTreeSet<i64>,
}

/// Outcome of a streamed job.
pub struct Streamed {
    /// Everything the board sent, as lines.
    pub board_output: Vec<String>,
    /// How many host lines the relay corrupted.
    pub corrupted: usize,
}

/// The board side of the relay: bytes in, bytes out.
pub trait BoardPort: Send + 'static {
    /// Deliver bytes to the board's serial input.
    fn send(&mut self, bytes: &[u8]);
    /// Bytes the board has sent since the last call (may block briefly).
    fn receive(&mut self) -> Vec<u8>;
}

/// Stream `gcode` with printcore into `board`, corrupting as told.
pub fn stream(board: impl BoardPort, gcode: &Path, corruption: Corruption, timeout: Duration) -> Streamed {
    let pty = openpty(None, None).expect("openpty");
    let slave_name = nix::unistd::ttyname(&pty.slave).expect("ttyname");
    let master: OwnedFd = pty.master;
    let mut from_host = File::from(master.try_clone().unwrap());
    let mut to_host = File::from(master);
    let board = Arc::new(Mutex::new(board));
    let recorded = Arc::new(Mutex::new(Vec::<u8>::new()));
    let corrupted = Arc::new(Mutex::new(0usize));
    let stop = Arc::new(AtomicBool::new(false));

    // Host → board, line by line, corrupting chosen lines the first time.
    let host_to_board = {
        let board = Arc::clone(&board);
        let corrupted = Arc::clone(&corrupted);
        std::thread::spawn(move || {
            let mut pending = Vec::new();
            let mut done = BTreeSet::new();
            let mut buffer = [0u8; 256];
            while let Ok(n) = from_host.read(&mut buffer) {
                if n == 0 {
                    break;
                }
                for &byte in &buffer[..n] {
                    pending.push(byte);
                    if byte != b'\n' {
                        continue;
                    }
                    if let Some(number) = line_number(&pending) {
                        if corruption.line_numbers.contains(&number) && done.insert(number) {
                            corrupt(&mut pending);
                            *corrupted.lock().unwrap() += 1;
                        }
                    }
                    board.lock().unwrap().send(&pending);
                    pending.clear();
                }
            }
        })
    };
    // Board → host, recording everything.
    let board_to_host = {
        let board = Arc::clone(&board);
        let recorded = Arc::clone(&recorded);
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || loop {
            if stop.load(Ordering::Relaxed) {
                break;
            }
            let bytes = board.lock().unwrap().receive();
            if bytes.is_empty() {
                std::thread::sleep(Duration::from_millis(1));
                continue;
            }
            recorded.lock().unwrap().extend_from_slice(&bytes);
            if to_host.write_all(&bytes).is_err() {
                break;
            }
        })
    };

    let output = Command::new(printcore_python())
        .arg(workspace_root().join("tests/hosts/printcore_stream.py"))
        .arg(&slave_name)
        .arg(gcode)
        .arg(timeout.as_secs().to_string())
        .output()
        .expect("run printcore");
    // Stop the relay: closing the last slave descriptor ends the master's
    // reads; then the board (and an emulator behind it) is dropped.
    stop.store(true, Ordering::Relaxed);
    drop(pty.slave);
    let _ = board_to_host.join();
    let _ = host_to_board.join();
    drop(board);
    assert!(
        output.status.success(),
        "printcore failed: {}\nstderr: {}\nboard said: {}",
        output.status,
        String::from_utf8_lossy(&output.stderr),
        String::from_utf8_lossy(&recorded.lock().unwrap())
    );
    let text = String::from_utf8_lossy(&recorded.lock().unwrap()).into_owned();
    let corrupted = *corrupted.lock().unwrap();
    Streamed { board_output: text.lines().map(str::to_owned).collect(), corrupted }
}

fn line_number(line: &[u8]) -> Option<i64> {
    let text = std::str::from_utf8(line).ok()?;
    let rest = text.strip_prefix('N')?;
    rest.split(' ').next()?.parse().ok()
}

/// Flip one bit of a byte in the middle of the line (never the newline).
fn corrupt(line: &mut [u8]) {
    let index = line.len() / 2;
    line[index] ^= 0x04;
    if line[index] == b'\n' || line[index] == b'\r' {
        line[index] ^= 0x08;
    }
}
