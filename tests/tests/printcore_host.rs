//! A real host, Printrun's printcore, streams a job with line numbers and
//! checksums into the firmware — on the emulated Mega 2560 (QEMU, the real
//! ELF) and on the hal-sim board — while a relay corrupts some lines.
//! Every line must be executed exactly once and in order.

use end_to_end::printcore::{stream, BoardPort, Corruption};
use end_to_end::{mega2560_elf, qemu::QemuPort};
use hal_sim::board::SimBoard;
use std::path::PathBuf;
use std::time::Duration;

const LINES: usize = 120;

/// A job whose every line leaves a trace: `M118 E1 seq <k>` echoes, with
/// moves and settings in between (those must be acknowledged too).
fn job() -> PathBuf {
    let mut text = String::from("; a job for printcore\nG21\nG90\nM83\n");
    for k in 1..=LINES {
        text.push_str(&format!("M118 E1 seq {k}\n"));
        if k % 10 == 0 {
            text.push_str(&format!("G92 X{k} ; comment stripped by printcore\n"));
        }
    }
    let path = std::env::temp_dir().join(format!("ferrostep-printcore-{}.gcode", std::process::id()));
    std::fs::write(&path, text).unwrap();
    path
}

/// printcore numbers lines from 0 after its `M110 N-1`; corrupt a spread.
fn corruption() -> Corruption {
    Corruption { line_numbers: [3, 17, 18, 60, 99, 131].into_iter().collect() }
}

fn assert_executed_once_in_order(output: &[String]) {
    let seen: Vec<usize> =
        output.iter().filter_map(|l| l.strip_prefix("echo:seq ")).map(|k| k.parse().unwrap()).collect();
    let expected: Vec<usize> = (1..=LINES).collect();
    assert_eq!(seen, expected, "board output: {output:?}");
}

#[test]
fn printcore_streams_into_the_emulated_mega2560_with_corrupted_lines_resent() {
    let board = QemuPort::boot(&mega2560_elf());
    let result = stream(board, &job(), corruption(), Duration::from_secs(120));
    assert_eq!(result.corrupted, 6);
    let resends = result.board_output.iter().filter(|l| l.starts_with("Resend: ")).count();
    assert!(resends >= 6, "{resends} resends for 6 corrupted lines: {:?}", result.board_output);
    assert_executed_once_in_order(&result.board_output);
}

/// The simulated board as a byte port.
struct SimPort(SimBoard);

impl BoardPort for SimPort {
    fn send(&mut self, bytes: &[u8]) {
        self.0.receive(bytes);
    }
    fn receive(&mut self) -> Vec<u8> {
        self.0.advance(1);
        self.0.take_output().into_bytes()
    }
}

#[test]
fn printcore_streams_into_the_simulated_board_with_corrupted_lines_resent() {
    let result = stream(SimPort(SimBoard::new()), &job(), corruption(), Duration::from_secs(120));
    assert_eq!(result.corrupted, 6);
    assert_executed_once_in_order(&result.board_output);
}
