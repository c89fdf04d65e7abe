//! A working printer without a printer: the Mega 2560 release ELF (the
//! very file `scripts/run.sh /dev/ttyACM0` would flash) on the simulated
//! Mega 2560 + RAMPS 1.4 of this bench, paced to the wall clock.
//!
//! - The serial port is this terminal: each line typed on stdin goes to
//!   the firmware after the `ok` of the one before (as a host paces it);
//!   `M112`, `M108` and `M410` go at once (the firmware reads them in its
//!   receive interrupt, even while a command waits). Everything the
//!   firmware says goes to stdout.
//! - The same port is also a pseudo-terminal whose path is printed at
//!   start: Pronterface, OctoPrint or `screen` open it (any baud rate; the
//!   simulated wire runs at 115200). Hosts there pace themselves.
//! - A status line on stderr, at most once a second and only when
//!   something changed: simulated time, the axes' positions measured from
//!   their MIN switches, both temperatures with their heater duties, the
//!   fan.
//!
//! The machine: the Prusa i3 of the default build (100 steps/mm X/Y, 400
//! Z, 93 E), the head at X 50 Y 50 Z 5 mm at power-up (the firmware
//! believes 0, 0, 0 until `G28`), MIN and MAX switches at 0 and 200 mm
//! (Z: 0 and 180 mm), a 40 W hot end and an MK2 bed heating their
//! thermistors from 25 °C.
//!
//! ```text
//! ramps-sim [--elf PATH] [--speed X] [--no-stdin] [--no-status] [--link PATH]
//! ```
//! `--speed 0` runs as fast as the simulation goes; `--no-stdin` keeps
//! running without a terminal (for a host on the pty only); `--link` makes
//! a symbolic link to the pty (a fixed name for OctoPrint's port list).
//! With stdin, end of input (Ctrl-D, or the end of a piped file) stops the
//! printer once every line has its `ok`.

use avr_bench::board::{Board, Endstop, RampsConfig, E0, X, Y, Z};
use avr_bench::host::HostConfig;
use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::pty::openpty;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use std::io::{BufRead, Read, Write};
use std::os::fd::{AsFd, AsRawFd};
use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Steps per mm of X, Y, Z, E0 (the default build's Prusa i3).
const STEPS_PER_MM: [f64; 4] = [100.0, 100.0, 400.0, 93.0];
/// Where the head stands at power-up, mm from the MIN switches.
const START_MM: [f64; 3] = [50.0, 50.0, 5.0];
/// The MAX switches, mm from the MIN switches (the soft limits' ends).
const TRAVEL_MM: [f64; 3] = [200.0, 200.0, 180.0];
/// Simulated time run between two looks at the inputs and the clock.
const SLICE_MS: f64 = 5.0;

struct Options {
    elf: Option<PathBuf>,
    speed: f64,
    stdin: bool,
    status: bool,
    link: Option<PathBuf>,
}

fn options() -> Result<Options, String> {
    let mut options = Options { elf: None, speed: 1.0, stdin: true, status: true, link: None };
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let mut value = |name: &str| args.next().ok_or_else(|| format!("{name} needs a value"));
        match arg.as_str() {
            "--elf" => options.elf = Some(PathBuf::from(value("--elf")?)),
            "--speed" => {
                options.speed = value("--speed")?.parse().map_err(|_| "--speed takes a number (0: unpaced)".to_string())?
            }
            "--link" => options.link = Some(PathBuf::from(value("--link")?)),
            "--no-stdin" => options.stdin = false,
            "--no-status" => options.status = false,
            "-h" | "--help" => {
                println!("ramps-sim [--elf PATH] [--speed X] [--no-stdin] [--no-status] [--link PATH]");
                std::process::exit(0);
            }
            other => return Err(format!("unknown argument {other:?} (try --help)")),
        }
    }
    Ok(options)
}

/// The virtual RAMPS: stock heaters and thermistors, switches around the
/// head's start position, the Y motor counted the nozzle's way (the
/// firmware inverts its DIR: the belt moves the bed).
fn ramps() -> RampsConfig {
    let mut config = RampsConfig::stock(115_200);
    config.host = HostConfig::raw(115_200);
    config.dir_high_is_positive[Y] = false;
    for axis in [X, Y, Z] {
        let steps = STEPS_PER_MM[axis];
        let min = (-START_MM[axis] * steps).round() as i64;
        let max = ((TRAVEL_MM[axis] - START_MM[axis]) * steps).round() as i64;
        config.endstops[2 * axis] = Some(Endstop { axis, at_steps: min, is_min: true, pressed_level: true });
        config.endstops[2 * axis + 1] = Some(Endstop { axis, at_steps: max, is_min: false, pressed_level: true });
    }
    config
}

/// The pty, raw (no echo, no line editing: a USB serial port), its path.
fn open_pty() -> Result<(std::fs::File, std::os::fd::OwnedFd, String), String> {
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
    Ok((std::fs::File::from(pty.master), pty.slave, path))
}

/// Commands the firmware takes from its receive interrupt: they must not
/// wait behind the `ok` of a command that is waiting itself.
fn is_urgent(line: &str) -> bool {
    let word: String = line.trim_start().chars().take_while(|c| !c.is_whitespace() && *c != ';').collect();
    matches!(word.to_ascii_uppercase().as_str(), "M112" | "M108" | "M410")
}

fn status(board: &Board) -> String {
    let mm = |axis: usize| {
        let from_min = if axis == E0 { 0.0 } else { START_MM[axis] };
        from_min + board.position(axis) as f64 / STEPS_PER_MM[axis]
    };
    let sample = board.thermal_history().last();
    let duty = |i: usize| sample.and_then(|s| s.duty.get(i).copied()).unwrap_or(0.0) * 100.0;
    let celsius = |channel: u8| board.sensor_celsius(channel).unwrap_or(f64::NAN);
    format!(
        "X {:.2} Y {:.2} Z {:.2} E {:.2} mm | hot end {:.1} °C, heater {:.0} % | bed {:.1} °C, heater {:.0} % | fan {:.0} %",
        mm(X),
        mm(Y),
        mm(Z),
        mm(E0),
        celsius(13),
        duty(0),
        celsius(14),
        duty(1),
        sample.map_or(0.0, |s| s.fan_duty * 100.0),
    )
}

fn main() {
    let options = options().unwrap_or_else(|e| {
        eprintln!("ramps-sim: {e}");
        std::process::exit(2)
    });
    let elf = options.elf.clone().unwrap_or_else(avr_bench::build::mega2560_elf);
    let (mut master, _slave, pty_path) = open_pty().unwrap_or_else(|e| {
        eprintln!("ramps-sim: {e}");
        std::process::exit(1)
    });
    if let Some(link) = &options.link {
        let _ = std::fs::remove_file(link);
        if let Err(e) = std::os::unix::fs::symlink(&pty_path, link) {
            eprintln!("ramps-sim: cannot link {} to {pty_path}: {e}", link.display());
        }
    }
    let mut board = Board::load(&elf, ramps()).unwrap_or_else(|e| {
        eprintln!("ramps-sim: {e}");
        std::process::exit(1)
    });
    eprintln!("[ramps-sim] {} on a simulated Mega 2560 + RAMPS 1.4 (simavr, 16 MHz)", elf.display());
    eprintln!("[ramps-sim] serial port: this terminal, and {pty_path} for Pronterface/OctoPrint (any baud rate)");
    if let Some(link) = &options.link {
        eprintln!("[ramps-sim] also reachable as {}", link.display());
    }
    if options.stdin {
        eprintln!("[ramps-sim] type G-code and press Enter (M104 S200, M105, G28, G1 X100 F3000, M114); Ctrl-D or Ctrl-C quits");
    }

    let (lines_tx, lines_rx) = mpsc::channel::<String>();
    if options.stdin {
        std::thread::spawn(move || {
            for line in std::io::stdin().lock().lines() {
                let Ok(line) = line else { break };
                if lines_tx.send(line).is_err() {
                    break;
                }
            }
        });
    } else {
        // Never disconnects: no end of input.
        std::mem::forget(lines_tx);
    }

    let started = Instant::now();
    let sim_start = board.seconds();
    let mut forwarded = 0usize;
    let mut pty_line = Vec::new();
    let mut buffer = [0u8; 512];
    let mut input_ended = false;
    let mut ended_at: Option<f64> = None;
    let mut last_status = String::new();
    let mut last_status_at = Instant::now() - Duration::from_secs(1);
    // Lines typed (or piped) before the firmware is up wait, as a host
    // waits for the banner: then the first M105 already has readings.
    let mut held: std::collections::VecDeque<String> = std::collections::VecDeque::new();
    let mut accepting_at: Option<f64> = None;
    let mut stdout = std::io::stdout();
    // The firmware is in the middle of a line on stdout: the status line
    // waits, so that the two never mix on one terminal line.
    let mut mid_line = false;
    loop {
        // Lines typed (or piped) on stdin.
        loop {
            match lines_rx.try_recv() {
                Ok(line) => held.push_back(line),
                Err(mpsc::TryRecvError::Empty) => break,
                Err(mpsc::TryRecvError::Disconnected) => {
                    input_ended = true;
                    break;
                }
            }
        }
        if accepting_at.is_none() && board.host().replies.iter().any(|r| r.text.ends_with(" ready")) {
            accepting_at = Some(board.seconds() + 0.5);
        }
        if accepting_at.is_some_and(|at| board.seconds() >= at) {
            for line in held.drain(..) {
                if is_urgent(&line) {
                    board.host_mut().send_now(line.trim());
                } else {
                    board.send([line.trim_end().to_string()]);
                }
            }
        }
        // Bytes from a host on the pty, a whole line at a time (so they
        // never interleave with a terminal line on the wire).
        match master.read(&mut buffer) {
            Ok(n) => {
                for &byte in &buffer[..n] {
                    if byte == b'\n' || byte == b'\r' {
                        if !pty_line.is_empty() {
                            board.host_mut().send_now(&String::from_utf8_lossy(&pty_line));
                            pty_line.clear();
                        }
                    } else {
                        pty_line.push(byte);
                    }
                }
            }
            // EIO: no host has the pty open; WouldBlock: nothing typed.
            Err(_) => {}
        }

        board.run_for_ms(SLICE_MS);
        if let Some(reason) = board.halted_reason() {
            eprintln!("[ramps-sim] the simulated CPU stopped: {reason}");
            std::process::exit(1);
        }

        // What the firmware said: to the terminal and to the pty.
        let bytes: Vec<u8> = board.host().rx_bytes[forwarded..].iter().map(|&(_, b)| b).collect();
        forwarded += bytes.len();
        if let Some(&last) = bytes.last() {
            mid_line = last != b'\n';
            let _ = stdout.write_all(&bytes);
            let _ = stdout.flush();
            // Nobody reading the pty: its buffer fills and the rest is dropped.
            let _ = master.write(&bytes);
        }
        if board.host().is_done() && board.host().wire_len() == 0 && board.host().rx_bytes.len() > 1 << 16 {
            board.host_mut().clear_log();
            forwarded = 0;
        }
        board.clear_step_edges();

        if options.status && !mid_line && last_status_at.elapsed() >= Duration::from_secs(1) {
            let line = status(&board);
            if line != last_status {
                eprintln!("[{:7.1} s] {line}", board.seconds() - sim_start);
                last_status = line;
                last_status_at = Instant::now();
            }
        }

        if input_ended && held.is_empty() && board.host().is_done() && board.host().wire_len() == 0 {
            // Let the last replies (e.g. M114 after M400) arrive, then stop.
            let now = board.seconds();
            if now - *ended_at.get_or_insert(now) > 0.2 {
                break;
            }
        }

        // Pace to the wall clock: never ahead of it (behind it if the
        // machine cannot keep up; the status line's time shows that).
        if options.speed > 0.0 {
            let due = Duration::from_secs_f64((board.seconds() - sim_start) / options.speed);
            let elapsed = started.elapsed();
            if due > elapsed {
                std::thread::sleep(due - elapsed);
            }
        }
    }
}
