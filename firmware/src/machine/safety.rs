//! SPEC §3's safety inputs (the arm): the safety relay of the light
//! curtain, the emergency stop and the re-arm button.
//!
//! The board reads the three pins every pass of the main loop and hands
//! their meaning (polarity applied, see the board's `pins.rs`) to
//! [`Machine::on_safety_inputs`]:
//! - A relay trip or an emergency stop (each its own `Error:` line) stops
//!   every motor at once, as a driver ALARM does: the queued motion is
//!   dropped, the drivers are disabled (the relay has cut their power
//!   anyway) and the position is lost. Heaters, if the machine has any,
//!   are turned off.
//! - From then on every move and `G28` is refused, naming the input,
//!   until the re-arm button is pressed *while no trip input is active*
//!   (a press that begins while the curtain is still broken, or a button
//!   held down while it clears, does not count: re-arm is momentary).
//! - After the re-arm, moves are still refused until `G28` has homed every
//!   axis again: the position was lost with the motor power.
//!
//! An input can only stop motion or unlock `G28`; nothing here ever starts
//! a move, so a noisy or broken line cannot move the machine (an open
//! wire reads as a trip).
//!
//! Not kept: the thesis' last position and job progress in EEPROM. A trip
//! cuts motor power mid-move, so the last commanded position is not where
//! the arm is (the machine must home anyway), and the job belongs to the
//! host, which streams it line by line and knows how far it got; see
//! docs/machines.md.

use super::error::CommandError;
use super::Machine;
use ufmt::uWrite;

/// The safety relay reports a trip (the light curtain was broken).
pub const RELAY_TRIPPED: u8 = 1 << 0;
/// The emergency stop is pressed.
pub const EMERGENCY_STOP: u8 = 1 << 1;
/// The re-arm button is pressed.
pub const REARM: u8 = 1 << 2;
/// The inputs that stop the machine.
const TRIPS: u8 = RELAY_TRIPPED | EMERGENCY_STOP;

impl<'q> Machine<'q> {
    /// The safety inputs as the board read them ([`RELAY_TRIPPED`],
    /// [`EMERGENCY_STOP`], [`REARM`]: bit set = active). A new trip stops
    /// everything and says which input; a re-arm press with every trip
    /// input clear lets `G28` home again.
    pub fn on_safety_inputs<W: uWrite + ?Sized>(&mut self, inputs: u8, out: &mut W) -> Result<(), W::Error> {
        let previous = core::mem::replace(&mut self.safety_levels, inputs);
        let active = inputs & TRIPS;
        let new = active & !previous;
        if new != 0 {
            self.safety_latched |= new;
            self.motion.request_stop();
            self.motion.forget_home();
            self.lose_alarmed_position();
            self.steppers_enabled = false;
            self.hotend.turn_off();
            self.bed.turn_off();
            if new & RELAY_TRIPPED != 0 {
                crate::flash_str!("Error:Safety relay tripped: motion stopped, re-arm then home with G28\n").write_to(out)?;
            }
            if new & EMERGENCY_STOP != 0 {
                crate::flash_str!("Error:Emergency stop pressed: motion stopped, release it, re-arm, then home with G28\n").write_to(out)?;
            }
            return Ok(());
        }
        let pressed = inputs & REARM != 0 && previous & REARM == 0;
        if !pressed || self.safety_latched == 0 {
            return Ok(());
        }
        if active != 0 {
            return crate::flash_str!("echo:Re-arm ignored: a safety input is still active\n").write_to(out);
        }
        self.safety_latched = 0;
        crate::flash_str!("echo:Safety re-armed: home with G28\n").write_to(out)
    }

    /// Whether a safety trip still refuses moves and `G28` (the emergency
    /// stop named first when both tripped).
    pub(super) fn safety_check(&self) -> Result<(), CommandError> {
        match self.safety_latched {
            0 => Ok(()),
            latched if latched & EMERGENCY_STOP != 0 => Err(CommandError::SafetyStop(EMERGENCY_STOP)),
            _ => Err(CommandError::SafetyStop(RELAY_TRIPPED)),
        }
    }

    /// Safety trips not yet re-armed (bits as the inputs').
    pub fn safety_latched(&self) -> u8 {
        self.safety_latched
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::line::LineAssembler;
    use crate::motion::stepper::TIMER_HZ;
    use crate::motion::{Motion, MotionConfig, StepFault, StepGenerator, StepQueues, StepperRequest};
    use crate::reply::test_support::Text;
    use crate::storage::MemoryStorage;
    use hal_sim::steps::StepRecorder;
    use std::boxed::Box;
    use std::string::String;

    /// The main loop every 0.5 ms of virtual time.
    const MAIN_LOOP_TICKS: u64 = 1000;

    /// SPEC §3's arm (200 ppr) on virtual time: the executor, its step
    /// interrupt and NC limit switches, as the board runs them.
    struct Arm {
        machine: Machine<'static>,
        generator: StepGenerator<'static>,
        recorder: StepRecorder,
        assembler: LineAssembler,
        storage: MemoryStorage<512>,
        inputs: u8,
        next_main: u64,
        /// Limit switches wired (as in the motion tests, they are taken
        /// away once homed: the model is not the arm's geometry).
        switches: bool,
    }

    impl Arm {
        fn new() -> Self {
            let queues: &'static mut StepQueues = Box::leak(Box::new(StepQueues::new()));
            let config = MotionConfig::spec_arm(200);
            let (feeder, generator) = queues.split(config.stepper());
            let recorder = StepRecorder::new(TIMER_HZ, config.stepper.dir_invert);
            Self {
                machine: Machine::new(Motion::new(config, feeder)),
                generator,
                recorder,
                assembler: LineAssembler::new(),
                storage: MemoryStorage::new(),
                inputs: 0,
                next_main: 0,
                switches: true,
            }
        }

        /// The switches of the motion tests' homed arm: X and Y home to
        /// their max switch, Z to its min.
        fn switches(p: &[i64; 4]) -> u8 {
            u8::from(p[0] >= 3000) << 4 | u8::from(p[1] >= 900) << 5 | u8::from(p[2] <= -1200) << 2
        }

        fn main_loop(&mut self, out: &mut Text) {
            let now_ms = (self.recorder.now / 2000) as u32;
            let status = self.generator.status();
            match self.machine.poll_motion(&status, now_ms, out).unwrap() {
                StepperRequest::None => {}
                StepperRequest::ClearFault => self.generator.clear_fault(),
                StepperRequest::Halt => self.generator.halt(StepFault::Stopped),
                StepperRequest::Configure(config) => self.generator.set_config(config),
            }
            self.machine.on_safety_inputs(self.inputs, out).unwrap();
            self.machine.poll(now_ms, &mut self.storage, out).unwrap();
        }

        /// Send `lines`, then run `seconds` of virtual time; what the
        /// machine said (but `busy`).
        fn run(&mut self, lines: &str, seconds: f64) -> String {
            let mut out = Text::default();
            for &byte in lines.as_bytes() {
                if let Some(line) = self.assembler.push(byte) {
                    self.machine.receive_line(line, &mut out).unwrap();
                }
            }
            let end = self.recorder.now + (seconds * f64::from(TIMER_HZ)) as u64;
            while self.recorder.now < end {
                if self.recorder.now >= self.next_main {
                    self.main_loop(&mut out);
                    self.next_main += MAIN_LOOP_TICKS;
                }
                while self.recorder.now < self.next_main {
                    if self.generator.endstop_mask() != 0 {
                        let switches = if self.switches { Self::switches(&self.recorder.positions()) } else { 0 };
                        self.generator.on_endstops(switches);
                    }
                    let action = self.generator.on_timer();
                    self.recorder.record(action.step_mask, action.dir_mask, action.next_interval_ticks);
                }
            }
            // Without the keep-alive lines of long waits.
            out.0.lines().filter(|l| !l.starts_with("echo:busy")).map(|l| std::format!("{l}\n")).collect()
        }

        /// Set the inputs and run 10 ms.
        fn set(&mut self, inputs: u8) -> String {
            self.inputs = inputs;
            self.run("", 0.01)
        }

        fn homed() -> Self {
            let mut arm = Self::new();
            arm.home("G28\n");
            arm
        }

        /// `G28` (or the axes it names) with the switches in place.
        fn home(&mut self, line: &str) {
            self.switches = true;
            assert_eq!(self.run(line, 120.0), "ok\n");
            self.switches = false;
        }
    }

    const RELAY_TRIP: &str = "Error:Safety relay tripped: motion stopped, re-arm then home with G28\n";
    const ESTOP: &str = "Error:Emergency stop pressed: motion stopped, release it, re-arm, then home with G28\n";
    const MOVE_REFUSED_RELAY: &str = "Error:Safety relay tripped: clear the light curtain, press re-arm, then G28\nok\n";
    const MOVE_REFUSED_ESTOP: &str = "Error:Emergency stop pressed: release it, press re-arm, then G28\nok\n";
    const REARMED: &str = "echo:Safety re-armed: home with G28\n";
    const IGNORED: &str = "echo:Re-arm ignored: a safety input is still active\n";

    /// Trip → refused move → re-arm without clearing → still refused →
    /// clear and re-arm → moves still wait for `G28` → `G28` → moves.
    #[test]
    fn a_relay_trip_mid_move_stops_every_motor_and_needs_rearm_and_home() {
        let mut arm = Arm::homed();
        let home = arm.recorder.positions();
        assert_eq!(arm.run("G1 Y0 Z0 F600\n", 0.5), "ok\n");
        let moving = arm.recorder.positions();
        assert!(moving[1] != home[1] && moving[2] != home[2], "the move is under way: {home:?} → {moving:?}");
        assert_eq!(arm.set(RELAY_TRIPPED), RELAY_TRIP);
        let stopped = arm.recorder.positions();
        // Stopped within the main loop's pass (0.5 ms): a step or two.
        for motor in 0..3 {
            assert!((stopped[motor] - moving[motor]).abs() <= 2, "{moving:?} → {stopped:?}");
        }
        assert!(!arm.machine.steppers_enabled(), "drivers disabled");
        // Not one more step, whatever comes.
        assert_eq!(arm.run("G1 Y10 Z10\n", 1.0), MOVE_REFUSED_RELAY);
        assert_eq!(arm.recorder.positions(), stopped);
        assert_eq!(arm.run("G28\n", 1.0), MOVE_REFUSED_RELAY);
        assert_eq!(arm.recorder.positions(), stopped);
        // Re-arm pressed and released while the relay is still tripped.
        assert_eq!(arm.set(RELAY_TRIPPED | REARM), IGNORED);
        assert_eq!(arm.set(RELAY_TRIPPED), "");
        assert_eq!(arm.run("G1 Y10 Z10\n", 0.1), MOVE_REFUSED_RELAY);
        // Held while the relay clears: still not a re-arm.
        assert_eq!(arm.set(RELAY_TRIPPED | REARM), IGNORED);
        assert_eq!(arm.set(REARM), "");
        assert_eq!(arm.run("G28\n", 0.1), MOVE_REFUSED_RELAY);
        assert_eq!(arm.set(0), "");
        // A press once clear re-arms; the position is still unknown.
        assert_eq!(arm.set(REARM), REARMED);
        assert_eq!(arm.set(0), "");
        assert_eq!(arm.run("G1 Y10 Z10\n", 0.1), "Error:Position unknown after a motion stop: home with G28 first\nok\n");
        assert_eq!(arm.machine.motion.homed(), 0, "every axis must home again");
        assert_eq!(arm.recorder.positions(), stopped);
        // G28 X alone does not do.
        arm.home("G28 X\n");
        assert_eq!(arm.run("G1 Y10 Z10\n", 0.1), "Error:Position unknown after a motion stop: home with G28 first\nok\n");
        arm.home("G28\n");
        assert_eq!(arm.machine.motion.homed(), 0b111);
        let home = arm.recorder.positions();
        assert_eq!(arm.run("G1 Y0 Z0 F600\nM400\n", 30.0), "ok\nok\n");
        assert_ne!(arm.recorder.positions(), home, "moves again");
    }

    #[test]
    fn an_emergency_stop_is_told_apart_and_needs_its_own_release() {
        let mut arm = Arm::homed();
        assert_eq!(arm.run("G1 Y0 Z0 F600\n", 0.5), "ok\n");
        assert_eq!(arm.set(EMERGENCY_STOP), ESTOP);
        let stopped = arm.recorder.positions();
        assert_eq!(arm.run("G1 Y10\n", 0.5), MOVE_REFUSED_ESTOP);
        // The relay trips as well: both named, the e-stop refuses first.
        assert_eq!(arm.set(EMERGENCY_STOP | RELAY_TRIPPED), RELAY_TRIP);
        assert_eq!(arm.run("G28\n", 0.5), MOVE_REFUSED_ESTOP);
        // The relay clears but the e-stop is still pressed.
        assert_eq!(arm.set(EMERGENCY_STOP), "");
        assert_eq!(arm.set(EMERGENCY_STOP | REARM), IGNORED);
        assert_eq!(arm.set(0), "");
        assert_eq!(arm.set(REARM), REARMED);
        assert_eq!(arm.recorder.positions(), stopped);
        assert_eq!(arm.machine.safety_latched(), 0);
        arm.home("G28\n");
        assert_eq!(arm.run("G1 Y0 Z0 F600\nM400\n", 30.0), "ok\nok\n");
    }

    /// A trip while idle, and one present at boot, latch the same way; a
    /// re-arm with nothing tripped, or the inputs alone, move nothing.
    #[test]
    fn trips_at_rest_latch_and_the_inputs_alone_never_move_anything() {
        let mut arm = Arm::new();
        assert_eq!(arm.set(RELAY_TRIPPED), RELAY_TRIP);
        assert_eq!(arm.run("G28\n", 0.1), MOVE_REFUSED_RELAY);
        for inputs in [0, REARM, 0, REARM, EMERGENCY_STOP, 0, REARM, RELAY_TRIPPED | EMERGENCY_STOP | REARM, 0, REARM] {
            arm.set(inputs);
        }
        assert_eq!(arm.recorder.positions(), [0; 4]);
        assert_eq!(arm.machine.safety_latched(), 0);
        // Re-arm with nothing latched says nothing.
        assert_eq!(arm.set(0), "");
        assert_eq!(arm.set(REARM), "");
        assert_eq!(arm.recorder.positions(), [0; 4]);
    }
}
