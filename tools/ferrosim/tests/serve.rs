//! The virtual printer with a real host: Printrun's printcore streams a
//! file into `ferrosim serve` through its pseudo-terminal.

use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Read from the pty until `done` holds for what came, or `timeout`.
fn read_until(port: &mut std::fs::File, timeout: Duration, done: impl Fn(&str) -> bool) -> String {
    let deadline = Instant::now() + timeout;
    let mut text = String::new();
    let mut buffer = [0u8; 256];
    while Instant::now() < deadline && !done(&text) {
        match port.read(&mut buffer) {
            Ok(n) if n > 0 => text.push_str(&String::from_utf8_lossy(&buffer[..n])),
            _ => std::thread::sleep(Duration::from_millis(5)),
        }
    }
    text
}

#[test]
fn printcore_streams_a_file_into_the_virtual_printer_and_every_line_is_executed() {
    let mut server = Command::new(env!("CARGO_BIN_EXE_ferrosim"))
        .args(["serve", "--speed", "20"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("ferrosim serve");
    let mut path = String::new();
    BufReader::new(server.stdout.take().unwrap()).read_line(&mut path).unwrap();
    let path = path.trim().to_string();
    assert!(path.starts_with("/dev/pts/"), "{path}");

    let dir = std::env::temp_dir().join(format!("ferrosim-serve-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let gcode = dir.join("square.gcode");
    let mut file = String::from("; a 20 mm square, twice\nG21\nG90\nM83\nM302 P1\n");
    for _ in 0..2 {
        file.push_str("G1 X20 Y0 E1 F3000\nG1 X20 Y20 E1\nG1 X0 Y20 E1\nG1 X0 Y0 E1\n");
    }
    file.push_str("G1 X12.5 Y7.25 F6000\n");
    std::fs::write(&gcode, file).unwrap();

    let python = end_to_end::printcore::printcore_python();
    let script = end_to_end::workspace_root().join("tests/hosts/printcore_stream.py");
    let status = Command::new(python).arg(script).arg(&path).arg(&gcode).arg("60").status().unwrap();
    assert!(status.success(), "printcore: {status}");

    // The motion of every line happened: ask the printer where it is.
    let mut port = std::fs::OpenOptions::new().read(true).write(true).open(&path).unwrap();
    let _ = read_until(&mut port, Duration::from_millis(300), |_| false);
    port.write_all(b"M400\nM114\n").unwrap();
    let reply = read_until(&mut port, Duration::from_secs(10), |t| t.contains("Count"));
    let _ = server.kill();
    let _ = server.wait();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(reply.contains("X:12.50 Y:7.25 Z:0.00 E:8.00 Count X:1250 Y:725 Z:0"), "{reply:?}");
}
