//! Issue 22 end to end: a real OctoPrint server (1.11.8, pip-installed,
//! its default settings) prints a sliced file to the real release ELF on
//! the simulated Mega 2560 + RAMPS (`ramps-sim`, what `scripts/run.sh`
//! starts), through the simulator's pseudo-terminal at 115200 baud; then
//! prints it once more through a line that flips bits.
//!
//! ```text
//! OctoPrint ──pty── relay (records both ways; flips bits on the 2nd job) ──pty── ramps-sim (ELF on simavr)
//! ```
//!
//! OctoPrint is driven by `tests/hosts/octoprint_print.py` through its
//! REST API only (connect, upload, select and print, poll the job), as a
//! user drives its web page. Asserted: OctoPrint recognises the firmware
//! and its temperature auto-report, turns it on (`M155 S2`) and shows the
//! reported temperatures; each job (heating with `M190`/`M109`, then every
//! line) reaches the end; after each, `M114` reports the file's last
//! position to the step, the extruder's motor has turned exactly the
//! file's extrusion (relative E: a line run twice or lost shows there),
//! and the board never reset. The noise job needs resends and converges.
//!
//! The file (`tests/hosts/octoprint-cube.gcode`) is a 10 mm square, four
//! layers, in PrusaSlicer's layout: start code with `M104`/`M140`/`M190`/
//! `M109`, `M73` progress lines, `;` comments, E with five decimals, end
//! code. Low temperatures (180 °C, bed 35 °C) keep the heat-up short on
//! the simulated board; the bed's last degree under its PID is most of
//! the test's four minutes.

use std::io::{BufRead, BufReader, Read, Write};
use std::os::fd::{AsFd, AsRawFd};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant};

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::pty::openpty;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};

/// Steps per mm of the default build's Prusa i3 (X, Y, Z, E).
const STEPS_PER_MM: [f64; 4] = [100.0, 100.0, 400.0, 93.0];
/// Bit flips on the second job: one in this many millionths of the bytes
/// of numbered lines (0.5 %).
const FLIPS_PER_MILLION: u64 = 5_000;

fn gcode_file() -> PathBuf {
    end_to_end::workspace_root().join("tests/hosts/octoprint-cube.gcode")
}

/// What the file leaves: the last X, Y, Z (absolute) and the sum of its
/// extrusion (E relative after `M83`, as PrusaSlicer writes it).
fn file_end(path: &Path) -> ([f64; 3], f64) {
    let text = std::fs::read_to_string(path).unwrap();
    let (mut xyz, mut e_total, mut relative_e) = ([0.0f64; 3], 0.0f64, false);
    for line in text.lines() {
        let code = line.split(';').next().unwrap().trim();
        let mut words = code.split_whitespace();
        match words.next() {
            Some("M83") => relative_e = true,
            Some("M82") => relative_e = false,
            Some("G0" | "G1") => {
                for word in words {
                    let value: f64 = word[1..].parse().unwrap_or_else(|_| panic!("{line}"));
                    match &word[..1] {
                        "X" => xyz[0] = value,
                        "Y" => xyz[1] = value,
                        "Z" => xyz[2] = value,
                        "E" => {
                            assert!(relative_e, "the test counts relative E only: {line}");
                            e_total += value;
                        }
                        _ => {}
                    }
                }
            }
            Some("G28") => xyz = [0.0; 3],
            _ => {}
        }
    }
    (xyz, e_total)
}

/// One line on the wire, as the relay saw it.
#[derive(Clone, Debug)]
enum Wire {
    /// From OctoPrint; `flipped`: the relay flipped a bit in it.
    Host { text: String, flipped: bool },
    Board(String),
}

/// xorshift64*: the seeded noise.
struct Noise(u64);

impl Noise {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// At most one flipped bit per line (the checksum is an XOR, which two
    /// flips of one bit cancel), never in or into a line end (the relay
    /// works line by line). Only numbered lines: nothing in the protocol
    /// protects an unnumbered one.
    fn corrupt(&mut self, line: &mut [u8]) -> bool {
        if line.first() != Some(&b'N') {
            return false;
        }
        for byte in line.iter_mut() {
            if matches!(*byte, b'\n' | b'\r') || self.next() % 1_000_000 >= FLIPS_PER_MILLION {
                continue;
            }
            let flipped = *byte ^ (1 << (self.next() % 8));
            if !matches!(flipped, b'\n' | b'\r') {
                *byte = flipped;
                return true;
            }
        }
        false
    }
}

struct Relay {
    host_port: String,
    wire: Arc<Mutex<Vec<Wire>>>,
    noise: Arc<Mutex<Option<Noise>>>,
    stop: Arc<AtomicBool>,
    threads: Vec<std::thread::JoinHandle<()>>,
    _host_slave: std::os::fd::OwnedFd,
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

fn non_blocking(fd: &impl AsRawFd) {
    let flags = OFlag::from_bits_truncate(fcntl(fd.as_raw_fd(), FcntlArg::F_GETFL).unwrap());
    fcntl(fd.as_raw_fd(), FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK)).unwrap();
}

/// Read what is there (nothing: WouldBlock, or EIO while nobody holds
/// the other end).
fn read_some(file: &mut std::fs::File, buffer: &mut [u8]) -> usize {
    file.read(buffer).unwrap_or(0)
}

fn write_all_retrying(file: &mut std::fs::File, mut bytes: &[u8], stop: &AtomicBool) {
    while !bytes.is_empty() && !stop.load(Ordering::Relaxed) {
        match file.write(bytes) {
            Ok(n) => bytes = &bytes[n..],
            Err(_) => std::thread::sleep(Duration::from_millis(2)),
        }
    }
}

/// A pseudo-terminal for OctoPrint, relayed line by line to `board_port`.
fn relay(board_port: &str) -> Relay {
    let pty = openpty(None, None).expect("openpty");
    let mut termios = tcgetattr(pty.slave.as_fd()).unwrap();
    cfmakeraw(&mut termios);
    tcsetattr(pty.slave.as_fd(), SetArg::TCSANOW, &termios).unwrap();
    let host_port = std::fs::read_link(format!("/proc/self/fd/{}", pty.slave.as_raw_fd())).unwrap().display().to_string();
    non_blocking(&pty.master);
    let board = std::fs::OpenOptions::new().read(true).write(true).open(board_port).expect("open the simulator's pty");
    non_blocking(&board);
    let wire = Arc::new(Mutex::new(Vec::new()));
    let noise: Arc<Mutex<Option<Noise>>> = Arc::new(Mutex::new(None));
    let stop = Arc::new(AtomicBool::new(false));
    let mut host_in = std::fs::File::from(pty.master.try_clone().unwrap());
    let mut host_out = std::fs::File::from(pty.master);
    let mut board_in = board.try_clone().unwrap();
    let mut board_out = board;

    let to_board = {
        let (wire, noise, stop) = (Arc::clone(&wire), Arc::clone(&noise), Arc::clone(&stop));
        std::thread::spawn(move || {
            let (mut line, mut buffer) = (Vec::new(), [0u8; 512]);
            while !stop.load(Ordering::Relaxed) {
                let n = read_some(&mut host_in, &mut buffer);
                if n == 0 {
                    std::thread::sleep(Duration::from_millis(1));
                    continue;
                }
                for &byte in &buffer[..n] {
                    line.push(byte);
                    if byte != b'\n' {
                        continue;
                    }
                    let text = String::from_utf8_lossy(&line).trim_end().to_string();
                    let flipped = noise.lock().unwrap().as_mut().is_some_and(|noise| noise.corrupt(&mut line));
                    wire.lock().unwrap().push(Wire::Host { text, flipped });
                    write_all_retrying(&mut board_out, &line, &stop);
                    line.clear();
                }
            }
        })
    };
    let to_host = {
        let (wire, stop) = (Arc::clone(&wire), Arc::clone(&stop));
        std::thread::spawn(move || {
            let (mut line, mut buffer) = (Vec::new(), [0u8; 512]);
            while !stop.load(Ordering::Relaxed) {
                let n = read_some(&mut board_in, &mut buffer);
                if n == 0 {
                    std::thread::sleep(Duration::from_millis(1));
                    continue;
                }
                for &byte in &buffer[..n] {
                    if byte == b'\n' {
                        wire.lock().unwrap().push(Wire::Board(String::from_utf8_lossy(&line).trim_end().to_string()));
                        line.clear();
                    } else {
                        line.push(byte);
                    }
                }
                write_all_retrying(&mut host_out, &buffer[..n], &stop);
            }
        })
    };
    Relay { host_port, wire, noise, stop, threads: vec![to_board, to_host], _host_slave: pty.slave }
}

/// ramps-sim with the release ELF, unpaced (`--speed 0`: about twice real
/// time on a loaded two-core machine; a faster board is only easier for
/// OctoPrint's timeouts, and the test stays short); its pty path and a
/// channel of its status lines.
struct Simulator {
    child: Child,
    port: String,
    status: mpsc::Receiver<String>,
}

impl Drop for Simulator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start_simulator() -> Simulator {
    let elf = avr_bench::build::mega2560_elf();
    let mut child = Command::new(env!("CARGO_BIN_EXE_ramps-sim"))
        .args(["--elf".as_ref(), elf.as_os_str(), "--no-stdin".as_ref(), "--speed".as_ref(), "0".as_ref()])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("ramps-sim starts");
    let stderr = BufReader::new(child.stderr.take().unwrap());
    let (path_tx, path_rx) = mpsc::channel();
    let (status_tx, status) = mpsc::channel();
    std::thread::spawn(move || {
        for line in stderr.lines().map_while(Result::ok) {
            if let Some(at) = line.find("/dev/pts/") {
                let path: String = line[at..].chars().take_while(|c| !c.is_whitespace()).collect();
                let _ = path_tx.send(path);
            } else if line.contains(" mm | hot end ") {
                let _ = status_tx.send(line);
            }
        }
    });
    let port = path_rx.recv_timeout(Duration::from_secs(60)).expect("ramps-sim prints its pty");
    Simulator { child, port, status }
}

/// `Count X:… Y:… Z:…` of an M114 reply.
fn counts(reply: &str) -> Option<[i64; 3]> {
    let rest = &reply[reply.find("Count ")? + "Count ".len()..];
    let mut values = rest.split_whitespace().map(|word| word.split(':').nth(1).and_then(|v| v.parse().ok()));
    Some([values.next()??, values.next()??, values.next()??])
}

/// The E motor's position (mm from power-up) on the simulator's status line.
fn status_e_mm(line: &str) -> Option<f64> {
    let at = line.find(" E ")? + 3;
    line[at..].split_whitespace().next()?.parse().ok()
}

/// The driver script, killed if the test fails midway (its OctoPrint
/// server dies with it: PR_SET_PDEATHSIG in the script).
struct Driver(Child);

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

#[test]
fn octoprint_prints_a_sliced_file_to_the_exact_end_then_again_through_noise() {
    let python = end_to_end::octoprint::octoprint_python();
    let file = gcode_file();
    let (end_mm, e_per_job) = file_end(&file);
    let expected_counts: Vec<i64> = (0..3).map(|axis| (end_mm[axis] * STEPS_PER_MM[axis]).round() as i64).collect();

    let simulator = start_simulator();
    let relay = relay(&simulator.port);
    let basedir = std::env::temp_dir().join(format!("ferrostep-octoprint-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&basedir);
    let mut driver = Driver(Command::new(&python)
        .arg(end_to_end::workspace_root().join("tests/hosts/octoprint_print.py"))
        .arg(&basedir)
        .arg(&relay.host_port)
        .arg(&file)
        .arg(free_tcp_port().to_string())
        .arg("2")
        .arg("420")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run the OctoPrint driver"));
    let mut to_driver = driver.0.stdin.take().unwrap();
    let (events_tx, events) = mpsc::channel();
    let stdout = BufReader::new(driver.0.stdout.take().unwrap());
    let mut stderr = driver.0.stderr.take().unwrap();
    let stderr = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text);
        text
    });
    std::thread::spawn(move || {
        for line in stdout.lines().map_while(Result::ok) {
            let _ = events_tx.send(line);
        }
    });
    let transcript = |wire: &[Wire]| -> String {
        let tail = wire.len().saturating_sub(400);
        wire[tail..]
            .iter()
            .map(|w| match w {
                Wire::Host { text, flipped } => format!("> {text}{}\n", if *flipped { "   [bit flipped]" } else { "" }),
                Wire::Board(text) => format!("< {text}\n"),
            })
            .collect()
    };

    let started = Instant::now();
    let mut driver_said = Vec::new();
    let mut last_status = String::new();
    let mut finished_jobs = 0;
    let mut counts_seen = 0;
    loop {
        let line = match events.recv_timeout(Duration::from_secs(600)) {
            Ok(line) => line,
            Err(_) => break,
        };
        eprintln!("[octoprint {:5.0} s] {line}", started.elapsed().as_secs_f64());
        driver_said.push(line.clone());
        let Some(job) = line.strip_prefix("PRINTED ") else { continue };
        let job: usize = job.parse().unwrap();
        // The M114 after the job's M400: the file's last position.
        let end = Instant::now() + Duration::from_secs(120);
        let reply = loop {
            let wire = relay.wire.lock().unwrap().clone();
            let replies: Vec<&str> = wire
                .iter()
                .filter_map(|w| match w {
                    Wire::Board(text) if text.contains("Count ") => Some(text.as_str()),
                    _ => None,
                })
                .collect();
            if replies.len() > counts_seen {
                counts_seen = replies.len();
                break replies.last().unwrap().to_string();
            }
            assert!(Instant::now() < end, "no M114 reply after job {job}\n{}", transcript(&wire));
            std::thread::sleep(Duration::from_millis(200));
        };
        let wire = relay.wire.lock().unwrap().clone();
        assert_eq!(counts(&reply).map(Vec::from), Some(expected_counts.clone()), "job {job}: {reply}\n{}", transcript(&wire));
        // The extruder: the status line once E stopped changing.
        std::thread::sleep(Duration::from_secs(2));
        while let Ok(status) = simulator.status.try_recv() {
            last_status = status;
        }
        let e_mm = status_e_mm(&last_status).unwrap_or_else(|| panic!("no E on the status line {last_status:?}"));
        let expected_e = e_per_job * job as f64;
        eprintln!("job {job}: {reply}; E motor {e_mm:.2} mm, the file's E {expected_e:.5} mm");
        // Within one E step (1/93 mm) and the status line's 0.005 mm rounding.
        assert!((e_mm - expected_e).abs() <= 1.0 / STEPS_PER_MM[3] + 0.005, "job {job}: E {e_mm} mm, file {expected_e} mm");
        finished_jobs = job;
        if job == 1 {
            *relay.noise.lock().unwrap() = Some(Noise(0x22_0c70));
            writeln!(to_driver, "next").unwrap();
        } else {
            writeln!(to_driver, "quit").unwrap();
        }
    }
    drop(to_driver);
    let status = driver.0.wait().unwrap();
    let stderr = stderr.join().unwrap();
    let wire = relay.wire.lock().unwrap().clone();
    assert!(
        status.success() && finished_jobs == 2,
        "OctoPrint driver: {status} after {finished_jobs} jobs\n{}\n{stderr}\nwire (tail):\n{}",
        driver_said.join("\n"),
        transcript(&wire)
    );

    // OctoPrint recognised the firmware and its temperature auto-report.
    let said = driver_said.join("\n");
    assert!(said.contains("Printer reports firmware name \"Ferrostep"), "{said}");
    assert!(said.contains("supports temperature autoreporting"), "{said}");
    let host_lines: Vec<&str> = wire.iter().filter_map(|w| if let Wire::Host { text, .. } = w { Some(text.as_str()) } else { None }).collect();
    let board_lines: Vec<&str> = wire.iter().filter_map(|w| if let Wire::Board(text) = w { Some(text.as_str()) } else { None }).collect();
    assert!(host_lines.iter().any(|l| l.contains("M155 S2")), "OctoPrint never turned the auto-report on");
    let reports = board_lines.iter().filter(|l| l.trim_start().starts_with("T:")).count();
    // The temperatures OctoPrint showed: it saw both heaters reach their
    // targets (180 and 35 °C, within M190's 1 °C) during the first job.
    let temps = driver_said.iter().find(|l| l.starts_with("TEMPS {\"job\": 1")).expect("temperatures of job 1");
    let max = |name: &str| -> f64 {
        let start = temps.find(&format!("\"{name}\": [")).unwrap();
        temps[start..]
            .split("[[")
            .nth(1)
            .unwrap()
            .split("]]")
            .next()
            .unwrap()
            .split("], [")
            .map(|pair| pair.split(',').next().unwrap().trim().parse::<f64>().unwrap())
            .fold(0.0, f64::max)
    };
    let (hot_end, bed) = (max("tool0"), max("bed"));
    let polls = host_lines.iter().filter(|l| l.contains("M105")).count();
    eprintln!("{reports} auto-reports, {polls} M105 polls; OctoPrint showed up to {hot_end} °C (hot end), {bed} °C (bed)");
    // The temperatures came from the auto-report: OctoPrint polled far less.
    assert!(polls * 4 < reports, "{polls} M105 polls, {reports} auto-reports");
    assert!(reports >= 20, "{reports} auto-reports");
    assert!(hot_end >= 179.0 && bed >= 34.0, "OctoPrint showed {hot_end} °C / {bed} °C");

    // No reset: one boot banner in the whole session.
    assert_eq!(board_lines.iter().filter(|l| **l == "start").count(), 1, "{}", transcript(&wire));
    // The second job went through noise and was mended by resends.
    let flips = wire.iter().filter(|w| matches!(w, Wire::Host { flipped: true, .. })).count();
    let resends = board_lines.iter().filter(|l| l.starts_with("Resend:")).count();
    eprintln!("noise job: {flips} lines with a flipped bit, {resends} resends; {:.0} s in all", started.elapsed().as_secs_f64());
    assert!(flips >= 3, "only {flips} flips");
    assert!(resends >= 1 && resends <= 3 * flips + 2, "{flips} flips, {resends} resends");
    let _ = std::fs::remove_dir_all(&basedir);
}
