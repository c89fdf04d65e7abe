//! The run command's printer (`ramps-sim`, what `scripts/run.sh` starts):
//! a host on its pseudo-terminal heats the hot end and sees the
//! temperature rise, homes, moves and reads the position back; the status
//! line reports the same.
//!
//! The ELF comes from `$FERROSTEP_ELF`, or is built as the quick bench
//! builds it.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

struct Printer {
    child: Child,
    port: std::fs::File,
    replies: mpsc::Receiver<String>,
    status: mpsc::Receiver<String>,
}

impl Drop for Printer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Printer {
    /// Send one line and collect the replies up to its `ok`.
    fn command(&mut self, line: &str, timeout: Duration) -> Vec<String> {
        writeln!(self.port, "{line}").expect("write to the pty");
        let end = Instant::now() + timeout;
        let mut got = Vec::new();
        loop {
            let left = end.saturating_duration_since(Instant::now());
            match self.replies.recv_timeout(left) {
                Ok(reply) => {
                    let done = reply.starts_with("ok");
                    got.push(reply);
                    if done {
                        return got;
                    }
                }
                Err(_) => panic!("no ok for {line:?} within {timeout:?}; got {got:?}"),
            }
        }
    }

    fn hotend_celsius(&mut self) -> f64 {
        let replies = self.command("M105", Duration::from_secs(10));
        let report = replies.iter().find(|r| r.starts_with("ok T:")).unwrap_or_else(|| panic!("{replies:?}"));
        report["ok T:".len()..].split(' ').next().unwrap().parse().unwrap_or_else(|_| panic!("{report}"))
    }
}

fn start() -> Printer {
    let elf = avr_bench::build::mega2560_elf();
    let mut child = Command::new(env!("CARGO_BIN_EXE_ramps-sim"))
        .args(["--elf".as_ref(), elf.as_os_str(), "--no-stdin".as_ref(), "--speed".as_ref(), "4".as_ref()])
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
    let path = path_rx.recv_timeout(Duration::from_secs(60)).expect("ramps-sim prints its pty");
    let port = std::fs::OpenOptions::new().read(true).write(true).open(&path).expect("open the pty");
    let reader = BufReader::new(port.try_clone().unwrap());
    let (reply_tx, replies) = mpsc::channel();
    std::thread::spawn(move || {
        for line in reader.lines().map_while(Result::ok) {
            if reply_tx.send(line.trim_end().to_string()).is_err() {
                break;
            }
        }
    });
    Printer { child, port, replies, status }
}

#[test]
fn a_host_on_the_pty_heats_homes_moves_and_reads_the_position() {
    let mut printer = start();
    // The banner arrives first (the firmware boots when the simulator starts).
    let end = Instant::now() + Duration::from_secs(30);
    while !printer
        .replies
        .recv_timeout(end.saturating_duration_since(Instant::now()))
        .expect("the banner")
        .ends_with("ready")
    {}

    // (The start-up messages about stored settings may come first.)
    let heat = printer.command("M104 S200", Duration::from_secs(10));
    assert!(heat.iter().all(|r| !r.starts_with("Error")) && heat.last().unwrap() == "ok", "{heat:?}");
    let first = printer.hotend_celsius();
    std::thread::sleep(Duration::from_secs(2));
    let mut last = first;
    for _ in 0..40 {
        last = printer.hotend_celsius();
        if last > first + 3.0 {
            break;
        }
        std::thread::sleep(Duration::from_millis(250));
    }
    assert!(first < 40.0 && last > first + 3.0, "hot end {first} °C, then {last} °C");

    let homed: Vec<String> = printer
        .command("G28", Duration::from_secs(60))
        .into_iter()
        .filter(|r| !r.starts_with("echo:busy"))
        .collect();
    assert_eq!(homed, ["ok"]);
    assert_eq!(printer.command("G1 X20 Y30 Z2 F6000", Duration::from_secs(10)), ["ok"]);
    assert_eq!(printer.command("M400", Duration::from_secs(30)).last().map(String::as_str), Some("ok"));
    assert_eq!(
        printer.command("M114", Duration::from_secs(10)),
        ["X:20.00 Y:30.00 Z:2.00 E:0.00 Count X:2000 Y:3000 Z:800", "ok"]
    );

    // The status line measures from the switches: the head stands where
    // M114 says, and the heater is on.
    let end = Instant::now() + Duration::from_secs(20);
    loop {
        let line = printer
            .status
            .recv_timeout(end.saturating_duration_since(Instant::now()))
            .expect("a status line with the new position");
        if line.contains("X 20.00 Y 30.00 Z 2.00") {
            assert!(!line.contains("heater 0 % | bed"), "{line}");
            break;
        }
    }
}
