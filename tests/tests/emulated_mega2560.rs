//! The real release ELF boots on an emulated Mega 2560 (QEMU) and answers
//! over its serial port as Marlin does.

use end_to_end::{mega2560_elf, qemu::QemuBoard};
use std::time::Duration;

fn booted_board() -> QemuBoard {
    let mut board = end_to_end::qemu::boot(&mega2560_elf());
    let banner = board.read_until(Duration::from_secs(20), |l| l.ends_with("Settings Loaded") || l.contains("retrieved"));
    assert_eq!(banner[0], "start", "banner: {banner:?}");
    assert!(banner[1].starts_with("echo:Ferrostep "), "banner: {banner:?}");
    // QEMU has no EEPROM: it reads back blank, so the defaults apply.
    assert_eq!(banner[2..], ["echo:No stored settings", "echo:Hardcoded Default Settings Loaded"], "banner: {banner:?}");
    // QEMU models no ADC: no conversion ever completes, so after three
    // sample periods the thermistors count as shorted and the thermal
    // protection halts the board, saying so; reports keep working.
    let lines = board.read_until(Duration::from_secs(10), |l| l.contains("Heater_ID: bed"));
    assert!(lines.iter().any(|l| l == "Error:Printer halted. kill() called!"), "{lines:?}");
    assert!(lines.iter().all(|l| l.starts_with("Error:")), "{lines:?}");
    board
}

#[test]
fn m115_reports_the_firmware_name_and_capabilities() {
    let mut board = booted_board();
    let reply = board.command("M115");
    assert!(reply[0].starts_with("FIRMWARE_NAME:Ferrostep "), "{reply:?}");
    assert!(reply[0].contains("PROTOCOL_VERSION:1.0"), "{reply:?}");
    let caps: Vec<&String> = reply.iter().filter(|l| l.starts_with("Cap:")).collect();
    assert!(caps.iter().any(|l| l.starts_with("Cap:EEPROM:")), "{reply:?}");
    assert!(caps.iter().all(|l| l.ends_with(":0") || l.ends_with(":1")), "{reply:?}");
    assert_eq!(reply.last().unwrap(), "ok");
}

#[test]
fn m105_and_m114_report_temperatures_and_position() {
    let mut board = booted_board();
    let temperatures = board.command("M105");
    assert_eq!(temperatures.len(), 1, "{temperatures:?}");
    assert!(temperatures[0].starts_with("ok T:"), "{temperatures:?}");
    assert!(temperatures[0].contains(" B:") && temperatures[0].contains(" @:"), "{temperatures:?}");
    let position = board.command("M114");
    assert_eq!(position, ["X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0", "ok"]);
}

#[test]
fn an_unknown_command_is_echoed_and_acknowledged() {
    let mut board = booted_board();
    assert_eq!(board.command("M9999 S1"), ["echo:Unknown command: \"M9999 S1\"", "ok"]);
}

#[test]
fn a_line_longer_than_the_buffer_is_an_error_and_the_board_keeps_answering() {
    let mut board = booted_board();
    // A `( … )` comment counts; a `;` comment of any length is ignored.
    let long = format!("G1 X1 ({})", "x".repeat(300));
    let reply = board.command(&long);
    // Refused either way: too long, or, when a loaded host makes QEMU hand
    // the bytes over in one burst that outruns the main loop, damaged in
    // the receive ring.
    assert!(
        reply == ["Error:Line too long", "ok"] || reply == ["Error:Serial receive overrun, line lost (checksum not verified)", "ok"],
        "{reply:?}"
    );
    assert_eq!(board.command("M114").last().unwrap(), "ok");
}

#[test]
fn a_numbered_line_with_a_bad_checksum_asks_for_a_resend() {
    let mut board = booted_board();
    assert_eq!(board.command("N1 M114*0"), ["Error:checksum mismatch, Last Line: 0", "Resend: 1", "ok"]);
}
