//! Serial abuse (issue 9): whatever a serial line delivers, the firmware
//! keeps answering, asks for what it lost, and executes nothing that did
//! not arrive intact.

use end_to_end::mega2560_elf;
use hal_sim::board::SimBoard;
use std::time::Duration;

/// A small deterministic generator (xorshift32): the same noise every run.
struct Noise(u32);

impl Noise {
    fn byte(&mut self) -> u8 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        (self.0 >> 24) as u8
    }
    fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.byte()).collect()
    }
}

fn checksummed(number: i32, command: &str) -> String {
    let line = format!("N{number} {command}");
    let sum = line.bytes().fold(0u8, |s, b| s ^ b);
    format!("{line}*{sum}\n")
}

/// Random bytes at full line rate (115200 baud) for one simulated minute,
/// then a plain command: answered. M112 may appear in noise only at a line
/// start followed by a delimiter, which this generator's stream is checked
/// not to contain, so the board must still be running.
#[test]
fn a_minute_of_random_bytes_at_full_baud_leaves_the_board_answering() {
    let mut board = SimBoard::new();
    board.take_output();
    let mut noise = Noise(0x1234_5678);
    // Strip CR/LF-led "M112"-like emergencies out of the noise: an
    // emergency stop caused by noise would be correct, but not this test.
    let mut sent = 0usize;
    for _second in 0..60 {
        let chunk: Vec<u8> = noise.bytes(11_520).into_iter().map(|b| if b == b'M' || b == b'm' { b'#' } else { b }).collect();
        sent += chunk.len();
        board.receive(&chunk);
        board.advance(1_000);
        board.take_output();
    }
    assert_eq!(sent, 691_200);
    board.receive(b"\nM118 E1 still here\n");
    board.advance(50);
    let output = board.take_output();
    assert!(output.ends_with("echo:still here\nok\n"), "{output}");
    assert!(!board.link.machine.is_halted());
}

/// Noise bursts between the lines of a numbered stream: each damaged line is
/// refused with a resend; resent lines execute once and in order.
#[test]
fn line_noise_in_a_numbered_stream_is_resent_and_nothing_runs_twice() {
    let mut board = SimBoard::new();
    let mut noise = Noise(42);
    board.receive(checksummed(0, "M110 N0").as_bytes());
    let mut executed = Vec::new();
    let mut number = 1;
    let mut attempts = 0;
    while number <= 50 && attempts < 500 {
        attempts += 1;
        let mut line = checksummed(number, &format!("M118 E1 seq {number}")).into_bytes();
        if attempts % 7 == 0 {
            // Damage the line: replace a few bytes in the middle with noise.
            let middle = line.len() / 2;
            for (i, b) in noise.bytes(3).into_iter().enumerate() {
                line[middle + i] = if b == b'\n' || b == b'\r' { b'~' } else { b };
            }
        }
        board.receive(&line);
        board.advance(20);
        let output = board.take_output();
        for reply in output.lines() {
            if let Some(seq) = reply.strip_prefix("echo:seq ") {
                executed.push(seq.parse::<i32>().unwrap());
            }
        }
        // Resend requests name the next line the board expects.
        match output.lines().find_map(|l| l.strip_prefix("Resend: ")) {
            Some(resend) => number = resend.parse().unwrap(),
            None => number += 1,
        }
    }
    assert_eq!(executed, (1..=50).collect::<Vec<_>>());
}

/// A host that drops mid-line and reconnects: the half line and the next
/// line merge into garbage, which is refused; the stream then resumes.
#[test]
fn a_host_that_disconnects_mid_line_and_reconnects_can_resume() {
    let mut board = SimBoard::new();
    board.receive(checksummed(0, "M110 N0").as_bytes());
    board.receive(checksummed(1, "G92 X5").as_bytes());
    board.receive(b"N2 G92 X1");
    board.advance(20);
    board.take_output();
    // Reconnect: the host starts over with M110, as printcore does.
    board.receive(checksummed(-1, "M110").as_bytes());
    board.advance(20);
    let refused = board.take_output();
    assert!(refused.starts_with("Error:"), "{refused}");
    board.receive(checksummed(-1, "M110").as_bytes());
    board.receive(checksummed(0, "M114").as_bytes());
    board.advance(20);
    let resumed = board.take_output();
    assert_eq!(resumed, "ok\nX:5.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0\nok\n");
}

/// More bytes than the receive ring holds, arriving faster than a UART can
/// deliver them: the loss is reported (with a resend for numbered lines),
/// and the damaged line never runs.
#[test]
fn a_receive_overrun_is_reported_and_the_damaged_line_never_runs() {
    let mut board = SimBoard::new();
    board.receive(checksummed(0, "M110 N0").as_bytes());
    board.advance(10);
    board.take_output();
    let mut burst = Vec::new();
    for n in 1..=30 {
        burst.extend_from_slice(checksummed(n, &format!("M118 E1 seq {n}")).as_bytes());
    }
    board.inject(&burst);
    board.advance(50);
    // The line the ring cut is refused once its end arrives: the host's
    // next line brings it (a host that ignores `ok` keeps sending).
    board.receive(checksummed(31, "M118 E1 seq 31").as_bytes());
    board.advance(50);
    let output = board.take_output();
    assert!(output.contains("Error:Serial receive overrun, line lost (checksum not verified), Last Line: "), "{output}");
    assert!(output.contains("Resend: "), "{output}");
    let executed: Vec<i32> =
        output.lines().filter_map(|l| l.strip_prefix("echo:seq ")).map(|s| s.parse().unwrap()).collect();
    // What ran, ran in order from 1 without gaps: nothing after a loss ran.
    assert_eq!(executed, (1..=executed.len() as i32).collect::<Vec<_>>(), "{output}");
}

/// The real ELF on QEMU: seconds of random bytes at 115200 baud, then a
/// command, answered.
#[test]
fn the_emulated_mega2560_survives_random_bytes_at_full_baud() {
    let mut board = end_to_end::qemu::boot(&mega2560_elf());
    board.read_until(Duration::from_secs(20), |l| l.ends_with("Settings Loaded") || l.contains("retrieved"));
    let mut noise = Noise(7);
    let garbage: Vec<u8> = noise.bytes(23_040).into_iter().map(|b| if b == b'M' || b == b'm' { b'#' } else { b }).collect();
    board.send(&garbage);
    board.send(b"\nM118 E1 alive\n");
    let replies = board.read_until(Duration::from_secs(30), |l| l == "echo:alive");
    assert_eq!(replies.last().unwrap(), "echo:alive");
}
