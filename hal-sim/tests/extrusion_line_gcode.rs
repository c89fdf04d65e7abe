//! The extrusion line (SPEC §4) as the firmware runs it, driven over the
//! serial line with G-code: the firmware's own executor, barrel heater
//! (SPEC §4's plant and 4.8 kΩ thermistor, the thesis PI on the SSR's slow
//! PWM), the interlock, the two velocity step timers as the Mega runs them,
//! and the diameter plant fed by the motors' measured speeds, its camera
//! reporting to the firmware once a second with `M861`.

use hal_sim::board::SimBoard;
use hal_sim::extrusion_plant::{setpoint_mm, DiameterPlant, DiameterPlantConfig, MM_PER_PX, TOLERANCE_MM};

/// Microsteps per output turn: screw 200 × 15 × 16, puller 200 × 6 × 32.
const SCREW_STEPS_PER_REV: f64 = 48_000.0;
const PULLER_STEPS_PER_REV: f64 = 38_400.0;


fn steps(board: &SimBoard) -> [u64; 2] {
    board.line.as_ref().expect("the line's timers").steps
}

/// The plant and the camera beside the board: each 100 ms the plant runs at
/// the speeds the motors really turned (from their step counts).
struct Line {
    board: SimBoard,
    plant: DiameterPlant,
    last_steps: [u64; 2],
}

impl Line {
    fn run_seconds(&mut self, seconds: u32, camera: bool) -> Vec<f64> {
        let mut diameters = Vec::new();
        for _ in 0..seconds {
            for _ in 0..10 {
                self.board.advance(100);
                let now = steps(&self.board);
                let screw_rpm = (now[0] - self.last_steps[0]) as f64 / SCREW_STEPS_PER_REV * 600.0;
                let puller_rpm = (now[1] - self.last_steps[1]) as f64 / PULLER_STEPS_PER_REV * 600.0;
                self.last_steps = now;
                self.plant.advance(0.1, puller_rpm, screw_rpm);
            }
            if camera {
                if let Some(px) = self.plant.camera_px() {
                    self.board.reply_to(&format!("M861 P{px}"), 100);
                }
            }
            diameters.push(self.plant.diameter_mm());
        }
        diameters
    }
}

#[test]
fn the_line_heats_refuses_a_cold_screw_then_holds_2_85_mm_under_gcode() {
    let mut board = SimBoard::extrusion_line();
    assert!(board.reply_to("M115", 100).contains("Cap:EXTRUSION_LINE:1\n"));
    // No planner moves on this machine: its motors are the screw and puller.
    assert_eq!(board.reply_to("G1 X10", 100), "Error:Not available on this machine\nok\n");
    // Cold: the screw is refused, and does not turn.
    let refused = board.reply_to("M3 S10", 100);
    assert!(refused.starts_with("Error:Cold extrusion prevented: barrel 2"), "{refused}");
    assert!(refused.ends_with(" C, minimum 175.00 C (M302 P1 overrides)\nok\n"), "{refused}");
    assert_eq!(board.reply_to("M104 S210", 100), "ok\n");
    // Ask every 10 s until the barrel passes 175 °C.
    let mut waited_s = 0;
    loop {
        board.advance(10_000);
        waited_s += 10;
        board.take_output();
        assert_eq!(steps(&board), [0, 0], "nothing turns while cold");
        if board.reply_to("M3 S10", 100) == "ok\n" {
            break;
        }
        assert!(waited_s < 3_600, "the barrel never reached 175 °C");
    }
    let report = board.reply_to("M105", 100);
    let barrel: f64 = report.split("T:").nth(1).and_then(|t| t.split(' ').next()).and_then(|t| t.parse().ok()).expect(&report);
    assert!((175.0..185.0).contains(&barrel), "{report}");

    assert_eq!(board.reply_to("M860 S3.9", 100), "echo:Puller manual 3.900 rpm\nok\n");
    let mut line = Line { board, plant: DiameterPlant::new(DiameterPlantConfig::standard(), 0.01), last_steps: [0, 0] };
    line.run_seconds(30, true);
    // At speed: the screw 10 rpm = 8000 steps/s, the puller 3.9 rpm = 2496 steps/s.
    let before = steps(&line.board);
    line.board.advance(1000);
    let after = steps(&line.board);
    assert!((after[0] - before[0]).abs_diff(8000) <= 2, "{before:?} {after:?}");
    assert!((after[1] - before[1]).abs_diff(2496) <= 2, "{before:?} {after:?}");

    assert_eq!(line.board.reply_to("M405", 100), "echo:Diameter control on\nok\n");
    let diameters = line.run_seconds(300, true);
    let settled = &diameters[180..];
    let worst = settled.iter().map(|d| (d - setpoint_mm()).abs()).fold(0.0, f64::max);
    println!("screw allowed after {waited_s} s at {barrel} °C; worst {worst:.4} mm in the last 2 min");
    assert!(worst <= TOLERANCE_MM, "worst {worst:.4} mm off {:.4} after 3 min", setpoint_mm());
    let report = line.board.reply_to("M407", 100);
    assert!(report.starts_with("echo:Diameter ") && report.contains(" rpm auto\n"), "{report}");
    let measured_px: f64 = report.split('(').nth(1).and_then(|t| t.split(' ').next()).and_then(|t| t.parse().ok()).expect(&report);
    assert!((measured_px * MM_PER_PX - setpoint_mm()).abs() < 0.1, "{report}");

    // M112: both motors stop at once.
    line.board.receive(b"M112\n");
    line.board.advance(50);
    let stopped = steps(&line.board);
    line.board.advance(1000);
    assert_eq!(steps(&line.board), stopped);
}

#[test]
fn the_camera_going_silent_holds_the_puller_and_warns() {
    let mut board = SimBoard::extrusion_line();
    assert_eq!(board.reply_to("M302 P1", 100), "ok\n");
    assert_eq!(board.reply_to("M3 S10", 100), "ok\n");
    assert_eq!(board.reply_to("M860 S4", 100), "echo:Puller manual 4.000 rpm\nok\n");
    assert_eq!(board.reply_to("M405", 100), "echo:Diameter control on\nok\n");
    assert_eq!(board.reply_to("M861 P133", 100), "ok\n");
    board.advance(6_000);
    let output = board.take_output();
    assert!(output.contains("echo:Diameter measurement stale (5 s), puller held at "), "{output}");
}

#[test]
fn line_commands_check_their_values() {
    let mut board = SimBoard::extrusion_line();
    assert_eq!(board.reply_to("M302 P1", 100), "ok\n");
    assert_eq!(board.reply_to("M3 S25", 100), "Error:Value out of range for S\nok\n");
    assert_eq!(board.reply_to("M3", 100), "Error:Missing S word\nok\n");
    assert_eq!(board.reply_to("M4 S5", 100), "Error:Not available on this machine\nok\n");
    assert_eq!(board.reply_to("M860 S16", 100), "Error:Value out of range for S\nok\n");
    assert_eq!(board.reply_to("M861 P2", 100), "Error:Value out of range for P\nok\n");
    assert_eq!(board.reply_to("M862 P0.05", 100), "Error:Diameter gains must be <= 0 (reverse acting)\nok\n");
    assert_eq!(board.reply_to("M862", 100), "echo:Diameter PI Kp:-0.0700 Ki:-0.0040\nok\n");
    assert_eq!(board.reply_to("M862 P-0.08", 100), "echo:Diameter PI Kp:-0.0800 Ki:-0.0040\nok\n");
    assert_eq!(board.reply_to("M863 S0", 100), "Error:Value out of range for S\nok\n");
    assert_eq!(board.reply_to("M863 S7", 100), "echo:Diameter watchdog 7 s\nok\n");
    assert_eq!(board.reply_to("M404", 100), "echo:Diameter setpoint 2.850 mm (132.87 px)\nok\n");
    assert_eq!(board.reply_to("M404 W1.75", 100), "echo:Diameter setpoint 1.750 mm (81.59 px)\nok\n");
    assert_eq!(board.reply_to("M407", 100), "echo:Diameter no measurement setpoint 1.750 mm (81.59 px) puller 0.000 rpm manual\nok\n");
    assert_eq!(board.reply_to("M406", 100), "echo:Diameter control off, puller 0.000 rpm\nok\n");
}

/// SPEC §4: the line's fans (D8) run from power-up, before any command
/// (`fans_on_at_start`); `M107` stops them and `M106` starts them again.
#[test]
fn the_fans_run_from_power_up_until_m107() {
    let mut board = SimBoard::extrusion_line();
    assert_eq!(board.link.machine.fan_duty(), 255);
    assert_eq!(board.reply_to("M107", 100), "ok\n");
    assert_eq!(board.link.machine.fan_duty(), 0);
    assert_eq!(board.reply_to("M106", 100), "ok\n");
    assert_eq!(board.link.machine.fan_duty(), 255);
}
