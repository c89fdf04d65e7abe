//! The fault-injection campaign: `cargo faults`.
//!
//! Each row injects one fault into the firmware core running on the
//! simulated board (virtual time, the same code as on the Mega 2560) and
//! checks that it ends in a safe state: motors stopped or never started,
//! heaters off where the fault concerns them, the host told with an
//! `Error:`/`echo:` line, and nothing executed that did not arrive intact.
//! The table shows what was expected and what was observed, with the time
//! from the injection to the safe state. The process exits with status 1
//! if any row fails, so the test command fails too.

use firmware::closed_loop::nse5310::TrackerConfig;
use firmware::closed_loop::control::FollowingErrorLimit;
use firmware::closed_loop::AxisFault;
use firmware::storage::{self, MemoryStorage};
use hal_sim::axis_plant::Rng;
use hal_sim::board::{SimBoard, SimEeprom, Thermistor};
use hal_sim::encoder_trace::{self, TraceRow};

/// One row of the table.
struct Outcome {
    fault: &'static str,
    injected: &'static str,
    expected: &'static str,
    observed: String,
    /// Time from the injection to the safe state, ms (None: not applicable).
    safe_after_ms: Option<u32>,
    passed: bool,
}

fn main() {
    let rows = vec![
        serial_garbage(),
        line_noise_in_a_numbered_stream(),
        host_disconnects_mid_line(),
        receive_ring_overrun(),
        eeprom_corruption(),
        power_loss_during_m500(),
        endstop_stuck_triggered(),
        endstop_never_triggers(),
        endstop_hit_mid_print(),
        m112_during_a_fast_move(),
        thermal_fault("thermistor open", "hot-end input at 1023 counts while heating to 200 °C", "Error:MINTEMP triggered (thermistor open)", |b| b.hotend_sensor = Thermistor::Count(1023), 2_000),
        thermal_fault("thermistor shorted", "hot-end input at 0 counts while heating to 200 °C", "Error:MAXTEMP triggered (thermistor shorted)", |b| b.hotend_sensor = Thermistor::Count(0), 2_000),
        thermistor_intermittent(),
        thermal_fault("heater disconnected", "the hot end's heater wire cut at M104 S200", "Error:Heating failed", |b| b.hotend_plant.disconnect_heater(), 30_000),
        heater_dies_while_holding(),
        slow_bed_heater_lost_under_pid(),
        thermal_fault("heater stuck on", "a shorted MOSFET: full power whatever the firmware drives", "Error:MAXTEMP triggered", |b| b.hotend_plant.stick_output(1.0), 400_000),
        encoder_disconnected(),
        watchdog_reset_mid_print(),
    ];
    print_table(&rows);
    let failed = rows.iter().filter(|r| !r.passed).count();
    if failed > 0 {
        eprintln!("{failed} of {} faults were not brought to a safe state", rows.len());
        std::process::exit(1);
    }
    println!("all {} faults brought to a safe state", rows.len());
}

fn print_table(rows: &[Outcome]) {
    println!("| fault | how injected | expected reaction | observed reaction | time to safe state | verdict |");
    println!("|---|---|---|---|---|---|");
    for row in rows {
        let time = row.safe_after_ms.map_or("—".to_string(), |ms| format!("{ms} ms"));
        let verdict = if row.passed { "safe" } else { "UNSAFE" };
        println!("| {} | {} | {} | {} | {} | {} |", row.fault, row.injected, row.expected, row.observed, time, verdict);
    }
}

fn booted() -> SimBoard {
    SimBoard::booted()
}

fn homed() -> SimBoard {
    SimBoard::homed().expect("the simulated Prusa i3 homes")
}

/// Steps made so far on X, Y, Z, E.
fn positions(board: &SimBoard) -> [i64; 4] {
    board.steps.positions()
}

/// Run until `done` or `max_ms`; the milliseconds it took.
fn run_until(board: &mut SimBoard, max_ms: u32, mut done: impl FnMut(&SimBoard) -> bool) -> Option<u32> {
    for ms in 0..max_ms {
        if done(board) {
            return Some(ms);
        }
        board.advance(1);
    }
    None
}

/// Lines of `bytes` that are valid moves, cut and checked by the
/// firmware's own line assembler, protocol and parser (random bytes make a
/// valid `X5` or `g1y2;…` now and then; those are G-code that arrived
/// intact, and a firmware must run them like any other line).
fn valid_moves_in(bytes: &[u8]) -> usize {
    use firmware::gcode::{self, Code};
    let mut assembler = firmware::line::LineAssembler::new();
    let mut protocol = firmware::protocol::HostProtocol::new();
    let mut moves = 0;
    for &byte in bytes {
        let Some(line) = assembler.push(byte) else { continue };
        let Ok(body) = protocol.accept(line) else { continue };
        if let Ok(command) = gcode::parse(body) {
            let axis = [b'X', b'Y', b'Z', b'E'].iter().any(|&l| command.has(l));
            if matches!(command.code, Code::G(0..=3) | Code::Modal) && axis || command.code == Code::G(28) {
                moves += 1;
            }
        }
    }
    moves
}

fn serial_garbage() -> Outcome {
    let mut board = homed();
    let before = positions(&board);
    let mut rng = Rng::new(0x5eed);
    // 60 s at 115200 baud: 11 520 bytes/s of uniformly random bytes.
    let bytes: Vec<u8> = (0..60 * 11_520).map(|_| (rng.next_u64() >> 56) as u8).collect();
    let chance_moves = valid_moves_in(&bytes);
    board.receive(&bytes);
    board.advance(61_000);
    let output = board.take_output();
    let moved = positions(&board) != before;
    // Afterwards the firmware still answers a well-formed command.
    // (a newline first ends whatever partial line the garbage left)
    board.receive(b"\n");
    board.advance(10);
    board.take_output();
    let reply = board.run_gcode("M114\n", 2_000);
    let answers = reply.contains("Count X:") && reply.ends_with("ok\n");
    let errors = output.matches("Error:").count();
    Outcome {
        fault: "serial garbage",
        injected: "60 s of random bytes at 115200 baud",
        expected: "errors reported, still answers; moves only from lines that are valid G-code by chance",
        observed: format!(
            "{errors} Error: lines; {chance_moves} valid move lines by chance, motors {}; answers M114: {answers}",
            if moved { "moved" } else { "still" }
        ),
        safe_after_ms: None,
        passed: moved == (chance_moves > 0) && answers && errors > 0,
    }
}

/// A printcore-like host: numbered lines with checksums, resending from
/// the line the firmware asks for.
struct Host {
    lines: Vec<String>,
    next: usize,
}

impl Host {
    fn numbered(moves: &[&str]) -> Self {
        let mut lines = vec![with_checksum("N0 M110 N0")];
        for (i, body) in moves.iter().enumerate() {
            lines.push(with_checksum(&format!("N{} {}", i + 1, body)));
        }
        Self { lines, next: 0 }
    }
}

fn with_checksum(line: &str) -> String {
    let sum = line.bytes().fold(0u8, |a, b| a ^ b);
    format!("{line}*{sum}")
}

/// Stream `host`'s lines one per `ok`, corrupting the bytes `corrupt`
/// selects on their first sending; the output.
fn stream(board: &mut SimBoard, host: &mut Host, mut corrupt: impl FnMut(usize, &mut Vec<u8>), max_ms: u32) -> String {
    let mut output = String::new();
    let mut sent_once = vec![false; host.lines.len()];
    let mut waiting = false;
    for _ in 0..max_ms {
        if !waiting && host.next < host.lines.len() {
            let mut bytes = host.lines[host.next].clone().into_bytes();
            if !sent_once[host.next] {
                sent_once[host.next] = true;
                corrupt(host.next, &mut bytes);
            }
            bytes.push(b'\n');
            board.receive(&bytes);
            host.next += 1;
            waiting = true;
        }
        board.advance(1);
        let new = board.take_output();
        for line in new.lines() {
            if let Some(n) = line.strip_prefix("Resend: ") {
                host.next = n.trim().parse().unwrap_or(host.next);
            }
            if line.starts_with("ok") {
                waiting = false;
            }
        }
        output.push_str(&new);
        if host.next >= host.lines.len() && !waiting && board.link.machine.motion_idle() {
            break;
        }
    }
    output
}

fn line_noise_in_a_numbered_stream() -> Outcome {
    let mut board = homed();
    let start = positions(&board);
    let moves: Vec<String> = (1..=20).map(|i| format!("G1 X{} Y{} F6000", i * 2, i)).collect();
    let moves: Vec<&str> = moves.iter().map(String::as_str).collect();
    let mut host = Host::numbered(&moves);
    let mut rng = Rng::new(7);
    // One flipped bit in every fourth line on its first sending.
    let output = stream(
        &mut board,
        &mut host,
        |index, bytes| {
            if index % 4 == 2 {
                let at = (rng.next_u64() as usize) % bytes.len();
                bytes[at] ^= 1 << (rng.next_u64() % 7);
            }
        },
        60_000,
    );
    let resends = output.matches("Resend:").count();
    let end = positions(&board);
    let exact = end[0] - start[0] == 4000 && end[1] - start[1] == 2000;
    Outcome {
        fault: "line noise in a numbered stream",
        injected: "one flipped bit in every 4th line of 20 G1 moves",
        expected: "resend asked for, every move lands exactly",
        observed: format!("{resends} resends, X/Y moved {}/{} steps (want 4000/2000)", end[0] - start[0], end[1] - start[1]),
        safe_after_ms: None,
        passed: resends >= 5 && exact,
    }
}

fn host_disconnects_mid_line() -> Outcome {
    let mut board = homed();
    let before = positions(&board);
    // Half of a numbered line, silence (the host is gone), then a new host
    // that starts its numbered stream afresh (printcore, OctoPrint).
    board.receive(with_checksum("N7 G1 X150 Y1").as_bytes().split_at(9).0);
    board.advance(5_000);
    let mut host = Host::numbered(&["G1 X10 F6000", "M114"]);
    let output = stream(&mut board, &mut host, |_, _| {}, 10_000);
    let x = positions(&board)[0] - before[0];
    Outcome {
        fault: "host disconnects mid-line",
        injected: "half of \"N7 G1 X150 Y1*…\", 5 s of silence, then a new host's numbered stream",
        expected: "the half line never runs, the new stream does",
        observed: format!("X moved {x} steps (want 1000); {} resend(s)", output.matches("Resend:").count()),
        safe_after_ms: None,
        passed: x == 1000 && output.contains("Count X:1000"),
    }
}

fn receive_ring_overrun() -> Outcome {
    let mut board = homed();
    let before = positions(&board);
    // 40 moves at once, faster than any UART: far beyond the ring.
    let burst: String = (1..=40).map(|i| format!("G1 X{i}\n")).collect();
    board.inject(burst.as_bytes());
    board.advance(10_000);
    // The host goes on with its next line, which completes the cut one.
    board.receive(b"M118 next\n");
    board.advance(1_000);
    let output = board.take_output();
    let lost = output.contains("Error:Serial receive overrun");
    let x = positions(&board)[0] - before[0];
    // Whatever ran must be one of the intact moves: X ends on a whole mm.
    let on_a_sent_target = x % 100 == 0 && (0..=4000).contains(&x);
    Outcome {
        fault: "receive buffer overrun",
        injected: "40 lines (≈ 280 bytes) at once into a 128-byte ring",
        expected: "overrun reported, only intact lines run",
        observed: format!("overrun reported: {lost}, X at {} mm", x / 100),
        safe_after_ms: None,
        passed: lost && on_a_sent_target,
    }
}

fn eeprom_corruption() -> Outcome {
    let mut board = booted();
    board.run_gcode("M92 E415\nM500\n", 1_000);
    let mut bytes = board.eeprom.bytes;
    bytes[20] ^= 0x10;
    let mut rebooted = SimBoard::with_eeprom(SimEeprom { bytes, ..SimEeprom::new() });
    let output = rebooted.take_output();
    let reported = output.contains("echo:EEPROM CRC mismatch");
    let defaults = rebooted.link.machine.settings().steps_per_mm_milli[3] == 93_000;
    Outcome {
        fault: "EEPROM corruption",
        injected: "one bit flipped in the saved image, then a reboot",
        expected: "reported, defaults loaded, nothing half-loaded",
        observed: format!("reported: {reported}, E steps/mm {}", rebooted.link.machine.settings().steps_per_mm_milli[3] / 1000),
        safe_after_ms: Some(0),
        passed: reported && defaults,
    }
}

fn power_loss_during_m500() -> Outcome {
    let mut old = firmware::settings::Settings::default();
    old.steps_per_mm_milli[3] = 415_000;
    let mut new = old.clone();
    new.steps_per_mm_milli[3] = 500_000;
    let mut mixes = 0;
    let mut writes = 0;
    for cut in 0..storage::SLOT_LEN {
        let mut eeprom = MemoryStorage::<4096>::new();
        let _ = storage::save(&mut eeprom, &old);
        eeprom.writes_before_power_loss = Some(cut);
        let _ = storage::save(&mut eeprom, &new);
        eeprom.writes_before_power_loss = None;
        match storage::load(&mut eeprom) {
            Ok((loaded, _)) if loaded == old || loaded == new => {}
            _ => mixes += 1,
        }
        writes += 1;
    }
    Outcome {
        fault: "power loss during M500",
        injected: "the save cut after each of its 117 byte writes",
        expected: "old or new settings at the next boot, never a mix",
        observed: format!("{writes} cuts, {mixes} mixed or lost"),
        safe_after_ms: Some(0),
        passed: mixes == 0,
    }
}

fn homing_fault(fault: &'static str, injected: &'static str, endstops: hal_sim::board::Endstops) -> Outcome {
    let mut board = booted();
    board.set_endstops(endstops);
    board.receive(b"G28\n");
    let safe = run_until(&mut board, 120_000, |b| b.link.machine.is_halted());
    let output = board.take_output();
    let at = positions(&board);
    board.advance(1_000);
    let still = positions(&board) == at;
    let drivers_off = !board.link.machine.steppers_enabled();
    Outcome {
        fault,
        injected,
        expected: "Error:Homing Failed, halted, drivers off",
        observed: format!(
            "{}, motors {}, drivers {}",
            if output.contains("Error:Homing Failed") { "Error:Homing Failed" } else { "no error" },
            if still { "stopped" } else { "MOVING" },
            if drivers_off { "off" } else { "ON" }
        ),
        safe_after_ms: safe,
        passed: safe.is_some() && output.contains("Error:Homing Failed") && still && drivers_off,
    }
}

fn endstop_stuck_triggered() -> Outcome {
    homing_fault(
        "endstop stuck triggered",
        "X min reads triggered whatever the position",
        Box::new(|p: &[i64; 4]| 1 | (1..3).filter(|&m| p[m] <= 0).fold(0, |b, m| b | 1 << m)),
    )
}

fn endstop_never_triggers() -> Outcome {
    homing_fault("endstop wire broken", "X min never triggers", Box::new(|p: &[i64; 4]| (1..3).filter(|&m| p[m] <= 0).fold(0, |b, m| b | 1 << m)))
}

fn endstop_hit_mid_print() -> Outcome {
    let mut board = homed();
    board.run_gcode("M120\nG1 X50 F6000\nM400\n", 10_000);
    board.take_output();
    // The X switch trips 20 mm from home (a crash, a loose switch).
    board.set_endstops(Box::new(|p: &[i64; 4]| u8::from(p[0] <= 2000) | (1..3).filter(|&m| p[m] <= 0).fold(0, |b, m| b | 1 << m)));
    board.receive(b"G1 X10\n");
    let safe = run_until(&mut board, 10_000, |b| b.steps.positions()[0] <= 2000).and_then(|hit| {
        let at = positions(&board)[0];
        run_until(&mut board, 100, |b| b.link.machine.motion_idle()).map(|idle| (hit, idle, at))
    });
    let output = board.take_output();
    let after = positions(&board)[0];
    let refused = board.run_gcode("G1 X40\n", 1_000).contains("Error:Position unknown");
    let reported = output.contains("Error:Endstop hit");
    let (observed, ms, passed) = match safe {
        Some((_, idle, at)) => (
            format!("{}, stopped {} step(s) past the switch, next move {}", if reported { "Error:Endstop hit" } else { "no error" }, at - after, if refused { "refused until G28" } else { "ACCEPTED" }),
            Some(idle),
            reported && refused && positions(&board)[0] == after,
        ),
        None => ("never reached the switch".to_string(), None, false),
    };
    Outcome {
        fault: "endstop hit mid-print",
        injected: "with M120, the X switch trips 20 mm from home during a move",
        expected: "motion stops, Error: line, moves refused until G28",
        observed,
        safe_after_ms: ms,
        passed,
    }
}

/// Heat the hot end towards 200 °C, inject `fault` a second in, and wait
/// for the firmware's reaction: the named `Error:` line, every heater off,
/// halted.
fn thermal_fault(
    fault: &'static str,
    injected: &'static str,
    error: &'static str,
    inject: impl FnOnce(&mut SimBoard),
    max_ms: u32,
) -> Outcome {
    let mut board = booted();
    board.run_gcode("M104 S200\n", 1_000);
    board.take_output();
    inject(&mut board);
    let safe = run_until(&mut board, max_ms, |b| b.link.machine.is_halted() && b.link.machine.heater_duties() == (0, 0));
    let output = board.take_output();
    let named = output.lines().find(|l| l.starts_with(error)).map(str::to_string);
    Outcome {
        fault,
        injected,
        expected: "named Error: line, every heater off, halted",
        observed: match &named {
            Some(line) => format!("{line}; heaters off, halted"),
            None => format!("no {error:?} line"),
        },
        safe_after_ms: safe,
        passed: safe.is_some() && named.is_some(),
    }
}

/// Issue 22: the thermal-runaway case. Hold 200 °C, then the heater dies
/// (wire cut): caught within 20 s. Before that, the part fan to full and a
/// long travel's air (harder cooling for a while) must not trip it.
fn heater_dies_while_holding() -> Outcome {
    let mut board = booted();
    board.run_gcode("M104 S200\n", 1_000);
    // Reach and settle at 200 °C.
    run_until(&mut board, 300_000, |b| b.hotend_plant.temperature_c() > 199.5);
    board.advance(60_000);
    board.take_output();
    // The fan to full for a minute (a quarter of the power blown away),
    // then a long travel's worth of air on top, then back.
    for (cooling, ms) in [(0.25, 60_000), (0.4, 20_000), (0.0, 60_000)] {
        board.hotend_plant.set_extra_cooling(cooling);
        board.advance(ms);
    }
    let false_trip = board.link.machine.is_halted();
    board.hotend_plant.disconnect_heater();
    let safe = run_until(&mut board, 60_000, |b| b.link.machine.is_halted() && b.link.machine.heater_duties() == (0, 0));
    let output = board.take_output();
    let named = output.lines().find(|l| l.starts_with("Error:Thermal Runaway")).map(str::to_string);
    Outcome {
        fault: "heater dies while holding",
        injected: "wire cut after holding 200 °C through fan-to-full and travel cooling",
        expected: "no trip on the cooling; Thermal Runaway within 20 s of the cut",
        observed: match (&named, false_trip) {
            (_, true) => "halted by the cooling alone (false trip)".to_string(),
            (Some(line), _) => format!("{line}; heaters off, halted"),
            (None, _) => "no Thermal Runaway line".to_string(),
        },
        safe_after_ms: safe,
        passed: !false_trip && named.is_some() && safe.is_some_and(|ms| ms <= 20_000),
    }
}

/// Issue 22, finding 7: a 200 W bed with a 600 s time constant under the
/// slicer's stock bed gains (`M304 P10 I0.023 D305.4`) heats for `M190
/// S60`; from 50 °C the PID backs off (≈ 0.4 duty, under 2 °C a minute),
/// which must not be called a failed heater. At 52 °C the heater's wire
/// is cut: the bed cools, the PID goes back to full power and the watch
/// (2 °C in 60 s at full power) catches it.
fn slow_bed_heater_lost_under_pid() -> Outcome {
    use hal_sim::thermal_plant::{HeaterPlant, PlantModel};
    let mut board = booted();
    board.bed_plant = HeaterPlant::new(PlantModel::BED_200W);
    board.run_gcode("M304 P10 I0.023 D305.4\n", 1_000);
    board.receive(b"M190 S60\n");
    run_until(&mut board, 600_000, |b| b.bed_plant.temperature_c() >= 52.0 || b.link.machine.is_halted());
    let false_trip = board.link.machine.is_halted();
    board.take_output();
    board.bed_plant.disconnect_heater();
    let safe = run_until(&mut board, 300_000, |b| b.link.machine.is_halted() && b.link.machine.heater_duties() == (0, 0));
    let output = board.take_output();
    let named = output.lines().find(|l| l.starts_with("Error:Heating failed")).map(str::to_string);
    Outcome {
        fault: "slow bed heater lost under its PID",
        injected: "M304 P10 I0.023 D305.4, M190 S60 on a 200 W τ 600 s bed; wire cut at 52 °C",
        expected: "no trip while the PID backs off; Heating failed within 150 s of the cut",
        observed: match (&named, false_trip) {
            (_, true) => "halted before the cut (false heating failure)".to_string(),
            (Some(line), _) => format!("{line}; heaters off, halted"),
            (None, _) => "no Heating failed line".to_string(),
        },
        safe_after_ms: safe,
        passed: !false_trip && named.is_some() && safe.is_some_and(|ms| ms <= 150_000),
    }
}

fn thermistor_intermittent() -> Outcome {
    let mut board = booted();
    board.run_gcode("M104 S200\n", 1_000);
    board.take_output();
    // Open for 300 ms (three readings) every 2 s: a loose crimp.
    let mut safe = None;
    for ms in 0..20_000u32 {
        board.hotend_sensor = if ms % 2_000 < 300 { Thermistor::Count(1023) } else { Thermistor::Plant };
        board.advance(1);
        if board.link.machine.is_halted() {
            safe = Some(ms);
            break;
        }
    }
    let output = board.take_output();
    let named = output.contains("Error:MINTEMP triggered (thermistor open)");
    Outcome {
        fault: "thermistor intermittent",
        injected: "hot-end input open 300 ms of every 2 s while heating",
        expected: "fault once three readings in a row are bad, heaters off, halted",
        observed: format!("{}; heaters {}", if named { "Error:MINTEMP triggered (thermistor open)" } else { "no error" }, if board.link.machine.heater_duties() == (0, 0) { "off" } else { "ON" }),
        safe_after_ms: safe,
        passed: named && safe.is_some() && board.link.machine.heater_duties() == (0, 0),
    }
}

fn m112_during_a_fast_move() -> Outcome {
    let mut board = homed();
    board.receive(b"G1 X180 F12000\n");
    board.advance(400);
    board.inject(b"M112\n");
    let mut last = positions(&board);
    let mut stopped_after = None;
    for ms in 1..=1_000 {
        board.advance(1);
        let now = positions(&board);
        if now != last {
            stopped_after = None;
        } else if stopped_after.is_none() {
            stopped_after = Some(ms);
        }
        last = now;
    }
    let output = board.take_output();
    let halted = board.link.machine.is_halted() && !board.link.machine.steppers_enabled();
    Outcome {
        fault: "M112 during a 200 mm/s move",
        injected: "M112 from the host 400 ms into G1 X180",
        expected: "steps stop at once, halted, drivers and heaters off",
        observed: format!("{}halted: {halted}", if output.contains("kill() called") { "Error:Printer halted, " } else { "" }),
        safe_after_ms: stopped_after,
        passed: halted && stopped_after.is_some_and(|ms| ms <= 2),
    }
}

/// The watchdog resets the chip in the middle of a print (the main loop
/// hung): the board comes back with every output off and asks the host to
/// start over; nothing of the job resumes by itself.
fn watchdog_reset_mid_print() -> Outcome {
    let mut board = homed();
    board.run_gcode("M104 S200\nM140 S60\nM106 S255\nM17\n", 2_000);
    board.receive(b"G1 X150 F3000\n");
    board.advance(300);
    let heating = board.link.machine.heater_duties() != (0, 0);
    // The reset: a new core on the same EEPROM, as the chip reboots.
    let mut rebooted = SimBoard::with_eeprom(SimEeprom { bytes: board.eeprom.bytes, ..SimEeprom::new() });
    let banner = rebooted.take_output();
    let m = &rebooted.link.machine;
    let safe = m.heater_duties() == (0, 0) && m.fan_duty() == 0 && !m.steppers_enabled();
    rebooted.advance(2_000);
    let still = rebooted.steps.positions() == [0, 0, 0, 0] && rebooted.link.machine.heater_duties() == (0, 0);
    Outcome {
        fault: "watchdog reset mid-print",
        injected: "the chip resets while heating and moving (main loop hung)",
        expected: "boots with heaters, fan and drivers off; `start` tells the host; nothing resumes",
        observed: format!(
            "was heating: {heating}; after reset: outputs {}, `start` sent: {}, nothing moved or heated for 2 s: {still}",
            if safe { "off" } else { "ON" },
            banner.starts_with("start\n")
        ),
        safe_after_ms: Some(0),
        passed: heating && safe && still && banner.starts_with("start\n"),
    }
}

fn encoder_disconnected() -> Outcome {
    // The closed loop of a printer axis (SPEC §1) at 250 Hz, moving at
    // 10 mm/s; at 0.4 s the encoder stops answering on I²C.
    let mut rows = Vec::new();
    let per_mm = 2048.0;
    for tick in 0..250 {
        let time_s = f64::from(tick) / f64::from(encoder_trace::TRACE_LOOP_HZ);
        let mm = 10.0 * time_s;
        let raw = if time_s < 0.4 { Some(((mm * per_mm) as i64 % 4096) as u16) } else { None };
        rows.push(TraceRow { time_s, raw, index: 0, commanded_mm: Some(mm) });
    }
    let tracker = TrackerConfig::for_read_rate(200, encoder_trace::TRACE_LOOP_HZ).unwrap();
    let report = encoder_trace::replay(&rows, tracker, FollowingErrorLimit::printer_default(encoder_trace::TRACE_LOOP_HZ));
    let first_missing = rows.iter().position(|r| r.raw.is_none()).unwrap();
    let (observed, safe, passed) = match report.fault {
        Some((row, fault @ AxisFault::Encoder(_))) => {
            let ms = ((row - first_missing) as u32) * 1000 / u32::from(encoder_trace::TRACE_LOOP_HZ);
            (format!("{fault:?} after {} reads, axis stopped", row - first_missing), Some(ms), true)
        }
        Some((_, other)) => (format!("{other:?}"), None, false),
        None => ("no fault: the loop kept running blind".to_string(), None, false),
    };
    Outcome {
        fault: "encoder disconnected",
        injected: "NSE-5310 stops answering 0.4 s into a 10 mm/s move",
        expected: "encoder fault, closed-loop axis stopped",
        observed,
        safe_after_ms: safe,
        passed,
    }
}
