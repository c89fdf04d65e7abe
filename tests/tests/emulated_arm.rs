//! The SKR Pro release ELF (STM32F407, Cortex-M4F) boots on QEMU's
//! netduinoplus2 (STM32F405) and answers over USART1 exactly as the Mega
//! 2560 build does: the same core, another board.

use end_to_end::qemu_arm::{measure_step_cost, print_arm_benchmark, skr_pro_bench_elf, skr_pro_elf, ArmBoard, Elf, StepCost};
use std::sync::OnceLock;
use std::time::Duration;

/// The bench ELF's figures, measured once per test process (a traced run).
fn bench_cost() -> &'static StepCost {
    static COST: OnceLock<StepCost> = OnceLock::new();
    COST.get_or_init(|| measure_step_cost(&skr_pro_bench_elf()))
}

fn booted_board() -> ArmBoard {
    let mut board = end_to_end::qemu_arm::boot(&skr_pro_elf());
    let banner =
        board.read_until(Duration::from_secs(20), |l| l.ends_with("Settings Loaded") || l.contains("retrieved"));
    assert_eq!(banner[0], "start", "banner: {banner:?}");
    assert!(banner[1].starts_with("echo:Ferrostep "), "banner: {banner:?}");
    // Settings live in flash sector 11; QEMU's flash is ROM (zeroed past
    // the image) and holds no committed page: every boot starts blank.
    assert_eq!(
        banner[2..],
        ["echo:No stored settings", "echo:Hardcoded Default Settings Loaded"],
        "banner: {banner:?}"
    );
    wait_for_the_sensor_fault(&mut board);
    board
}

/// QEMU's ADC is not a thermistor: within a sample period (100 ms) the
/// thermal protection halts the board, as it would with a broken sensor,
/// and says so; reports keep working (tested below), moves are refused.
fn wait_for_the_sensor_fault(board: &mut ArmBoard) {
    let lines = board.read_until(Duration::from_secs(10), |l| l.contains("Heater_ID: bed"));
    assert!(lines.iter().any(|l| l == "Error:Printer halted. kill() called!"), "{lines:?}");
    assert!(lines.iter().all(|l| l.starts_with("Error:")), "{lines:?}");
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
fn a_short_gcode_stream_gets_the_same_replies_as_on_the_mega2560() {
    let mut board = booted_board();
    let temperatures = board.command("M105");
    assert_eq!(temperatures.len(), 1, "{temperatures:?}");
    assert!(temperatures[0].starts_with("ok T:"), "{temperatures:?}");
    assert!(temperatures[0].contains(" B:") && temperatures[0].contains(" @:"), "{temperatures:?}");
    assert_eq!(board.command("M114"), ["X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0", "ok"]);
    // Halted by the sensor fault (see `booted_board`): what would act is
    // refused with Marlin's line, the position is unchanged.
    assert_eq!(board.command("G92 X5 E2"), ["Error:Printer halted. kill() called!", "ok"]);
    assert_eq!(board.command("M114"), ["X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0", "ok"]);
    assert_eq!(board.command("M118 E1 hello from the ARM"), ["echo:hello from the ARM", "ok"]);
    assert_eq!(board.command("M9999 S1"), ["echo:Unknown command: \"M9999 S1\"", "ok"]);
}

#[test]
fn a_dwell_keeps_the_host_informed_on_the_millisecond_tick() {
    let mut board = booted_board();
    // G4 waits on the SysTick milliseconds; the core says busy every 2 s.
    let reply = board.command("G4 P2500");
    assert_eq!(reply, ["echo:busy: processing", "ok"]);
}

#[test]
fn a_line_longer_than_the_buffer_is_an_error_and_the_board_keeps_answering() {
    let mut board = booted_board();
    // A `( … )` comment counts; a `;` comment of any length is ignored.
    let long = format!("G1 X1 ({})", "x".repeat(300));
    let reply = board.command(&long);
    // Refused either way: too long, or, when a loaded host lets QEMU hand
    // the bytes over in one burst that outruns the main loop, damaged in
    // the receive ring (see the burst test below).
    assert!(
        reply == ["Error:Line too long", "ok"] || reply == ["Error:Serial receive overrun, line lost (checksum not verified)", "ok"],
        "{reply:?}"
    );
    assert_eq!(board.command("M114").last().unwrap(), "ok");
}

/// Lines arriving faster than the main loop takes them overflow the
/// receive ring; the lines that lost bytes (their ends included) are
/// refused, never executed, and every line still gets exactly one `ok`.
#[test]
fn a_burst_that_overflows_the_receive_ring_gets_one_ok_per_line() {
    let mut board = booted_board();
    let mut burst = Vec::new();
    for _ in 0..40 {
        burst.extend_from_slice(format!("G1 X1 ;{}\n", "x".repeat(60)).as_bytes());
        burst.extend_from_slice(b"M114\n");
    }
    board.send_burst(&burst);
    let mut oks = 0;
    let mut replies = Vec::new();
    while oks < 80 {
        let lines = board.read_until(Duration::from_secs(10), |l| l == "ok");
        oks += 1;
        replies.extend(lines);
    }
    assert_eq!(board.command("M114").last().unwrap(), "ok");
    let refused = replies.iter().filter(|l| l.as_str() == "Error:Serial receive overrun, line lost (checksum not verified)").count();
    let halted = replies.iter().filter(|l| l.as_str() == "Error:Printer halted. kill() called!").count();
    let positions = replies.iter().filter(|l| l.starts_with("X:0.00 Y:0.00")).count();
    // Each line is answered by what it was: a refused line, a G1 refused
    // by the halted board, or an M114.
    println!("refused {refused}, halted {halted}, positions {positions}");
    assert_eq!(refused + halted + positions, 80, "{replies:?}");
    assert_eq!(replies.len(), 160, "{replies:?}");
}

#[test]
fn a_numbered_line_with_a_bad_checksum_asks_for_a_resend() {
    let mut board = booted_board();
    assert_eq!(board.command("N1 M114*0"), ["Error:checksum mismatch, Last Line: 0", "Resend: 1", "ok"]);
}

#[test]
fn m112_on_a_halted_board_is_acknowledged_and_the_board_keeps_answering() {
    let mut board = booted_board();
    board.send(b"M112\n");
    let reply = board.read_until(Duration::from_secs(10), |l| l == "ok" || l.starts_with("ok "));
    assert_eq!(reply.last().unwrap(), "ok", "{reply:?}");
    assert_eq!(board.command("M114").last().unwrap(), "ok");
}

#[test]
fn the_firmware_fits_the_flash_behind_the_bootloader() {
    let elf = Elf::read(&skr_pro_elf());
    assert_eq!(elf.vector_table(), 0x0800_8000, "linked for BTT's SD-card bootloader");
    let flash = elf.flash_bytes();
    println!("arm_flash_bytes={flash}");
    // 1 MiB less the bootloader's 32 KiB and the settings sector's 128 KiB.
    assert!(flash > 4096 && flash < 864 * 1024, "{flash} bytes");
}

#[test]
fn one_step_event_costs_a_bounded_number_of_instructions() {
    let cost = bench_cost().clone();
    println!("{cost:?}");
    assert_eq!(cost.printed.get("queued").map(String::as_str), Some("1"), "{cost:?}");
    // The hot path: about 125 instructions today, Klipper's is far shorter;
    // this guards against a regression into loops or divisions.
    assert!((40..=250).contains(&cost.instructions), "{cost:?}");
    assert!(cost.cycles_min <= cost.cycles_max && cost.cycles_min >= cost.instructions, "{cost:?}");
    assert!(cost.step_rate_hz() > 100_000, "{cost:?}");
}

/// The numeric abstraction's choice for this board, measured rather than
/// assumed: one tick of the closed-loop law (robust PID) in f32 on the
/// FPU against Q16.16 fixed point, instructions counted on QEMU. The
/// board builds the core with `fpu`, so `firmware::num::Native` is f32.
#[test]
fn f32_is_the_faster_loop_arithmetic_on_the_cortex_m4() {
    let cost = bench_cost();
    let (fixed, float) = (cost.loop_tick("fixed"), cost.loop_tick("f32"));
    println!("loop tick: fixed {fixed:.0}, f32 {float:.0} instructions");
    assert!(float > 20.0 && fixed > 20.0, "{cost:?}");
    assert!(float < fixed, "fixed {fixed}, f32 {float}");
    // 168 MHz: even the slower one is a few microseconds.
    assert!(fixed < 600.0, "fixed {fixed}");
}

/// The benchmark keys for `cargo benchmark`:
/// `cargo test -p end-to-end --test emulated_arm -- --ignored --nocapture arm_benchmark`
#[test]
#[ignore = "prints the ARM benchmark figures; run on demand"]
fn arm_benchmark() {
    print_arm_benchmark();
}
