//! A simulated board running the firmware core on virtual time.
//!
//! The serial port goes through the same receive ring (`firmware::rx`,
//! emergency scanner included) and the same main-loop duties
//! (`firmware::host_link`) as on the Mega 2560; only the clock is virtual:
//! [`SimBoard::advance`] moves it on by whole milliseconds, so a long job
//! simulates in moments.
//!
//! Motion runs as on the board: each millisecond the main loop polls the
//! planner side, then the step generator runs for that millisecond of
//! 2 MHz timer ticks, its STEP/DIR actions recorded by a [`StepRecorder`]
//! (what a logic analyser on the pins would see). Endstops are a function
//! of the motor positions ([`SimBoard::set_endstops`]).

use firmware::emergency::Pending;
use firmware::host_link::{HostLink, SerialLink};
use firmware::machine::Machine;
use firmware::motion::{stepper, Motion, MotionConfig, StepFault, StepGenerator, StepQueues, StepperRequest};
use firmware::rx::{self, RxConsumer, RxProducer, RxQueue};
use firmware::storage::MemoryStorage;

use crate::steps::StepRecorder;
use crate::thermal_plant::{HeaterPlant, PlantModel, ThermistorCircuit, PLANT_STEP_MS};
use firmware::thermal::Oversampled;

/// What a thermistor input reads on the simulated board.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Thermistor {
    /// The heater plant's temperature through the RAMPS divider.
    Plant,
    /// A fixed ADC count (0: shorted sensor, 1023: open sensor).
    Count(u16),
}

/// A bed plant fast enough for tests, which Marlin's default bed gains
/// hold within a degree: 325 °C at full power (a 24 V silicone heater on a
/// thin plate), τ 200 s, 3 s dead time.
pub const TEST_BED: PlantModel = PlantModel { gain_c_per_percent: 3.0, time_constant_s: 200.0, dead_time_s: 3.0, ambient_c: 25.0 };

/// Endstops as a function of the motor positions (steps from boot): bit i
/// motor i's min switch, bit 4 + i its max switch, 1 = triggered.
pub type Endstops = Box<dyn Fn(&[i64; 4]) -> u8 + Send>;

/// The simulated EEPROM: 4 KiB like the ATmega2560's.
pub type SimEeprom = MemoryStorage<4096>;

/// Marlin's default line rate.
pub const DEFAULT_BAUD: u32 = 115_200;

/// The firmware core on a simulated board.
pub struct SimBoard {
    pub link: HostLink<'static>,
    generator: StepGenerator<'static>,
    /// Every step the generator made.
    pub steps: StepRecorder,
    endstops: Endstops,
    /// The hot end (40 W, SPEC §4-like) and the bed, driven by the
    /// firmware's heater duties.
    pub hotend_plant: HeaterPlant,
    pub bed_plant: HeaterPlant,
    pub hotend_sensor: Thermistor,
    pub bed_sensor: Thermistor,
    pub eeprom: SimEeprom,
    producer: RxProducer<'static>,
    /// Bytes sent by the host and still on the wire.
    wire: std::collections::VecDeque<u8>,
    /// Line rate in bytes per second (8N1: baud / 10).
    bytes_per_s: u32,
    /// Fraction of a byte carried over between milliseconds, in 1/1000.
    wire_credit: u32,
    rx: SimRx,
    now_ms: u32,
    output: String,
    /// The extrusion line's two velocity step timers, when the machine is
    /// the line ([`SimBoard::extrusion_line`]).
    pub line: Option<LineTimersSim>,
    /// The powder bed's platforms, carriage, roller and suction, when the
    /// machine is the powder bed ([`SimBoard::powder_bed`]).
    pub powder_bed: Option<crate::powder_bed_plant::PowderBed>,
    /// Driver ALARM inputs (bit i: motor i), read by the firmware every
    /// millisecond ([`SimBoard::set_driver_alarms`]).
    driver_alarms: u8,
}

/// The extrusion line's step timers as the Mega runs them (Timer5 compare
/// A: the screw, B: the puller): each the interrupt's own copy of the
/// firmware's velocity stepper, following the model after every ramp
/// update, with its rising STEP edges counted.
#[derive(Clone, Debug, Default)]
pub struct LineTimersSim {
    pub isr: [firmware::machines::velocity::VelocityStepper; 2],
    /// Timer tick of each timer's next compare (`None`: stopped).
    next_edge: [Option<u64>; 2],
    /// Rising STEP edges per motor (screw, puller).
    pub steps: [u64; 2],
    /// Ticks of the last rising edge of each (for speed measurements).
    pub last_rise: [u64; 2],
}

struct SimRx {
    consumer: RxConsumer<'static>,
    dropped: u8,
    emergencies: Pending,
}

impl SerialLink for SimRx {
    fn pop(&mut self) -> Option<u8> {
        self.consumer.pop()
    }
    fn take_dropped(&mut self) -> u8 {
        core::mem::take(&mut self.dropped)
    }
    fn take_emergencies(&mut self) -> Pending {
        core::mem::take(&mut self.emergencies)
    }
}

impl Default for SimBoard {
    fn default() -> Self {
        Self::new()
    }
}

impl SimBoard {
    /// A board that has just booted with a blank EEPROM (its banner is in
    /// the output).
    pub fn new() -> Self {
        Self::with_eeprom(SimEeprom::new())
    }

    /// A booted board (blank EEPROM) whose banner has been read.
    pub fn booted() -> Self {
        let mut board = Self::new();
        board.take_output();
        board
    }

    /// A booted Prusa i3 homed on the default switches (where the motors
    /// were at boot); `None` if `G28` did not end with a plain `ok`.
    pub fn homed() -> Option<Self> {
        let mut board = Self::booted();
        let output = board.run_gcode("G28\n", 60_000);
        (output.replace("echo:busy: processing\n", "") == "ok\n").then_some(board)
    }

    /// A board booting with `eeprom`'s contents (e.g. after a power loss).
    pub fn with_eeprom(eeprom: SimEeprom) -> Self {
        Self::with_machine(MotionConfig::prusa_i3(), eeprom)
    }

    /// A board running the machine `config` (Prusa i3, delta, arm).
    pub fn with_machine(config: MotionConfig, eeprom: SimEeprom) -> Self {
        // One small ring per board for the life of the process (tests).
        let queue: &'static mut RxQueue = Box::leak(Box::new(RxQueue::new()));
        let (producer, consumer) = rx::split(queue);
        let step_queues: &'static mut StepQueues = Box::leak(Box::new(StepQueues::new()));
        let (feeder, generator) = step_queues.split(config.stepper());
        let mut board = Self {
            link: HostLink::new(Machine::new(Motion::new(config, feeder))),
            generator,
            steps: StepRecorder::new(stepper::TIMER_HZ, config.stepper().dir_invert),
            // Min switches where the motors were at boot.
            endstops: Box::new(|p: &[i64; 4]| (0..3).filter(|&m| p[m] <= 0).fold(0, |bits, m| bits | 1 << m)),
            hotend_plant: HeaterPlant::new(PlantModel::HOTEND_40W),
            bed_plant: HeaterPlant::new(TEST_BED),
            hotend_sensor: Thermistor::Plant,
            bed_sensor: Thermistor::Plant,
            eeprom,
            producer,
            wire: std::collections::VecDeque::new(),
            bytes_per_s: DEFAULT_BAUD / 10,
            wire_credit: 0,
            rx: SimRx { consumer, dropped: 0, emergencies: Pending::NONE },
            now_ms: 0,
            output: String::new(),
            line: None,
            powder_bed: None,
            driver_alarms: 0,
        };
        let _ = board.link.machine.write_banner(&mut Output(&mut board.output));
        let _ = board.link.machine.load_settings(&mut board.eeprom, &mut Output(&mut board.output));
        board
    }

    /// A booted extrusion line (SPEC §4): the barrel plant of SPEC §4 on
    /// heater 0 read through its 4.8 kΩ divider, the screw and the puller
    /// on velocity step timers. The banner has been read.
    pub fn extrusion_line() -> Self {
        let mut board = Self::new();
        board.link.machine.become_extrusion_line();
        board.hotend_plant = HeaterPlant::new(PlantModel::BARREL_PUBLISHED);
        board.line = Some(LineTimersSim::default());
        board.take_output();
        board
    }

    /// A booted powder bed (SPEC §5): both platforms with 200 mm (40 000
    /// steps) between their reed switches, the carriage at C−; its tick
    /// runs every millisecond as the board's does. The banner has been read.
    pub fn powder_bed() -> Self {
        let mut board = Self::new();
        board.link.machine.become_powder_bed();
        board.powder_bed = Some(crate::powder_bed_plant::PowderBed::new(firmware::machine::powder_bed::PLATFORM, 40_000));
        board.take_output();
        board
    }

    /// The powder bed's millisecond: read the plant, run the firmware's
    /// tick, drive the plant (platform step, carriage duty for 1 ms).
    fn run_powder_bed(&mut self) {
        use firmware::machine::powder_bed::BedInputs;
        use firmware::machines::powder_bed::{CarriageEnd, Platform};
        let Some(bed) = self.powder_bed.as_mut() else { return };
        let at = bed.carriage.at();
        let inputs = BedInputs {
            feed_switches: bed.feed.switch_levels(),
            build_switches: bed.build.switch_levels(),
            at_minus: at == Some(CarriageEnd::Minus),
            at_plus: at == Some(CarriageEnd::Plus),
            carriage_count: bed.carriage.decoder.count(),
            bridge_fault: false,
            carriage_y_count: bed.carriage_y.decoder.count(),
            bridge_y_fault: false,
        };
        let Ok(outputs) = self.link.machine.powder_bed_tick(&inputs, &mut Output(&mut self.output));
        for platform in [&mut bed.feed, &mut bed.build] {
            let level = platform.driver.enable_level(outputs.platforms_enabled);
            platform.set_enable(level);
        }
        if let Some((platform, direction)) = outputs.step {
            match platform {
                Platform::Feed => bed.feed.pulse(direction),
                Platform::Build => bed.build.pulse(direction),
            }
        }
        bed.roller_on = outputs.roller;
        bed.suction_on = outputs.suction;
        bed.carriage.drive(outputs.carriage_duty);
        bed.carriage_y.drive(outputs.carriage_y_duty);
    }

    /// Send one line and run until its `ok` (Marlin's bare `ok`, or `ok `
    /// with a report) for at most `max_ms`: the replies, the busy
    /// keep-alives of a blocking command left out. Panics without an `ok`.
    pub fn reply_to(&mut self, line: &str, max_ms: u32) -> String {
        self.receive(format!("{line}\n").as_bytes());
        let mut output = String::new();
        for _ in 0..max_ms {
            self.advance(1);
            output.push_str(&self.take_output());
            if output.ends_with('\n') && output.lines().last().is_some_and(|l| l == "ok" || l.starts_with("ok ")) {
                return output.replace("echo:busy: processing\n", "");
            }
        }
        panic!("no ok for {line:?} within {max_ms} ms: {output:?}");
    }

    /// Set the drivers' ALARM inputs (bit i: motor i active).
    pub fn set_driver_alarms(&mut self, alarms: u8) {
        self.driver_alarms = alarms;
    }

    /// Bytes sent by the host: they arrive at the line rate (115200 baud,
    /// 8N1) while [`SimBoard::advance`] runs, as on a real serial line.
    pub fn receive(&mut self, bytes: &[u8]) {
        self.wire.extend(bytes);
    }

    /// Bytes arriving all at once, faster than any UART: for tests of what
    /// happens when the receive ring overflows.
    pub fn inject(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            if let Some(emergency) = self.producer.push(byte, false) {
                self.rx.emergencies = self.rx.emergencies.with(emergency);
            }
        }
        self.rx.dropped = self.rx.dropped.saturating_add(self.producer.take_dropped());
    }

    /// Run the main loop for `ms` milliseconds of virtual time (one pass per
    /// millisecond).
    pub fn advance(&mut self, ms: u32) {
        for _ in 0..ms.max(1) {
            self.wire_credit += self.bytes_per_s;
            let arriving = (self.wire_credit / 1000) as usize;
            self.wire_credit %= 1000;
            let bytes: Vec<u8> = self.wire.drain(..arriving.min(self.wire.len())).collect();
            self.inject(&bytes);
            let status = self.generator.status();
            let mut out = Output(&mut self.output);
            match self.link.machine.poll_motion(&status, self.now_ms, &mut out) {
                Ok(StepperRequest::ClearFault) => self.generator.clear_fault(),
                Ok(StepperRequest::Halt) => self.generator.halt(StepFault::Stopped),
                Ok(StepperRequest::Configure(config)) => self.generator.set_config(config),
                _ => {}
            }
            let _ = self.link.machine.on_driver_alarms(self.driver_alarms, &mut out);
            let _ = self.link.service(&mut self.rx, &mut self.eeprom, self.now_ms, &mut out);
            if self.line.is_some() {
                let Ok(timers) = self.link.machine.poll_line(self.now_ms, &mut out);
                self.apply_line_timers(timers);
            }
            self.run_powder_bed();
            if self.link.machine.is_halted() {
                self.generator.halt(StepFault::Stopped);
            }
            self.run_heaters();
            self.now_ms = self.now_ms.wrapping_add(1);
            let tick = u64::from(self.now_ms) * u64::from(stepper::TIMER_HZ / 1000);
            self.run_line_until(tick);
            self.run_steps_until(tick);
        }
    }

    /// The board's part of [`Machine::poll_line`]: the timers' copies
    /// follow the models; a start arms the compare, a stop disarms it.
    fn apply_line_timers(&mut self, timers: firmware::machine::line::LineTimers) {
        use firmware::machines::velocity::TimerChange;
        let Some(line) = self.line.as_mut().filter(|_| timers.changed) else { return };
        let Some(model) = self.link.machine.extrusion_line() else { return };
        let now = self.steps.now;
        for (index, (change, model)) in [(timers.screw, &model.extruder), (timers.puller, &model.puller)].into_iter().enumerate() {
            line.isr[index].follow(model);
            match change {
                TimerChange::Start { first_ticks } => line.next_edge[index] = Some(now + u64::from(first_ticks)),
                TimerChange::Stop => line.next_edge[index] = None,
                TimerChange::None => {}
            }
        }
    }

    /// The two compare interrupts of the line's step timers up to `tick`.
    fn run_line_until(&mut self, tick: u64) {
        let Some(line) = self.line.as_mut() else { return };
        for index in 0..2 {
            while let Some(at) = line.next_edge[index].filter(|&at| at <= tick) {
                match line.isr[index].on_timer() {
                    Some(edge) => {
                        if edge.step_high {
                            line.steps[index] += 1;
                            line.last_rise[index] = at;
                        }
                        line.next_edge[index] = Some(at + u64::from(edge.next_ticks));
                    }
                    None => line.next_edge[index] = None,
                }
            }
        }
    }

    /// The heater plants on the firmware's duties, and every 100 ms the
    /// averaged thermistor readings into the firmware (as the Mega's main
    /// loop does).
    fn run_heaters(&mut self) {
        if self.now_ms.is_multiple_of(PLANT_STEP_MS as u32) {
            let (hotend, bed) = self.link.machine.heater_duties();
            self.hotend_plant.step(f64::from(hotend) / 255.0);
            self.bed_plant.step(f64::from(bed) / 255.0);
        }
        if self.now_ms.is_multiple_of(100) {
            // The line's barrel thermistor has SPEC §4's 4.8 kΩ pull-up.
            let hotend_circuit = if self.line.is_some() { ThermistorCircuit::SPEC_4K8 } else { ThermistorCircuit::RAMPS };
            let read = |sensor: Thermistor, plant: &HeaterPlant, circuit: ThermistorCircuit| {
                Oversampled(match sensor {
                    Thermistor::Plant => (circuit.adc(plant.temperature_c()) * 16.0).round() as u16,
                    Thermistor::Count(count) => count.min(1023) * 16,
                })
            };
            let hotend = read(self.hotend_sensor, &self.hotend_plant, hotend_circuit);
            let bed = read(self.bed_sensor, &self.bed_plant, ThermistorCircuit::RAMPS);
            let _ = self.link.machine.on_thermal_samples(Some(hotend), Some(bed), &mut Output(&mut self.output));
        }
    }

    /// The step interrupt, from the recorder's time up to `tick`.
    fn run_steps_until(&mut self, tick: u64) {
        while self.steps.now < tick {
            if self.generator.endstop_mask() != 0 {
                let triggered = (self.endstops)(&self.steps.positions());
                self.generator.on_endstops(triggered);
            }
            let action = self.generator.on_timer();
            self.steps.record(action.step_mask, action.dir_mask, action.next_interval_ticks);
        }
    }

    /// Replace the endstops (see [`Endstops`]).
    pub fn set_endstops(&mut self, endstops: Endstops) {
        self.endstops = endstops;
    }

    /// Send `gcode` as a host with `ok` flow control does (the next line
    /// once the previous one is answered) and run until every line is
    /// answered and the machine is idle, or `max_ms` passed; the output.
    pub fn run_gcode(&mut self, gcode: &str, max_ms: u32) -> String {
        let mut lines = gcode.lines().filter(|l| !l.trim().is_empty());
        let mut output = String::new();
        let mut in_flight = false;
        for _ in 0..max_ms {
            if !in_flight {
                match lines.next() {
                    Some(line) => {
                        self.receive(line.as_bytes());
                        self.receive(b"\n");
                        in_flight = true;
                    }
                    None if self.link.machine.motion_idle() => break,
                    None => {}
                }
            }
            self.advance(1);
            let new = self.take_output();
            if new.lines().any(|l| l == "ok" || l.starts_with("ok ")) {
                in_flight = false;
            }
            output.push_str(&new);
        }
        output
    }

    /// The serial line's rate (8N1), from now on.
    pub fn set_baud(&mut self, baud: u32) {
        self.bytes_per_s = (baud / 10).max(1);
    }

    /// Keep every step's time (default), or only positions and counts.
    pub fn set_record_steps(&mut self, keep: bool) {
        self.steps.keep_steps = keep;
    }

    /// Times the step interrupt ran out of prepared segments in the middle
    /// of a block (the planner side starved it).
    pub fn underruns(&self) -> u16 {
        self.generator.status().underruns
    }

    /// Virtual time since boot, ms.
    pub fn now_ms(&self) -> u32 {
        self.now_ms
    }

    /// Take everything the firmware has written since the last call.
    pub fn take_output(&mut self) -> String {
        core::mem::take(&mut self.output)
    }
}

struct Output<'a>(&'a mut String);

impl ufmt::uWrite for Output<'_> {
    type Error = core::convert::Infallible;
    fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
        self.0.push_str(s);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_simulated_board_boots_and_answers() {
        let mut board = SimBoard::new();
        assert_eq!(
            board.take_output(),
            "start\necho:Ferrostep 0.1.0 ready\necho:No stored settings\necho:Hardcoded Default Settings Loaded\n"
        );
        board.receive(b"M114\n");
        board.advance(1);
        assert_eq!(board.take_output(), "X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0\nok\n");
    }

    #[test]
    fn a_burst_beyond_the_ring_is_reported_not_lost_silently() {
        let mut board = SimBoard::new();
        board.take_output();
        // 200 bytes at once: more than the 127-byte ring holds.
        let burst = "M118 a\n".repeat(28);
        board.inject(burst.as_bytes());
        board.advance(10);
        board.receive(b"M118 z\n");
        board.advance(10);
        let output = board.take_output();
        // The 18 lines that fit ran; the one cut by the gap and the 9 lost
        // whole are each refused with an error and their `ok` (29 lines
        // sent, 29 `ok`s: a host counting them never waits).
        assert_eq!(output.matches("a\nok\n").count(), 18, "{output}");
        assert_eq!(output.matches("Error:Serial receive overrun, line lost (checksum not verified)\nok\n").count(), 10, "{output}");
        // The next line arrives whole and runs.
        assert!(output.ends_with("z\nok\n"), "{output}");
        assert_eq!(output.matches("ok\n").count(), 29, "{output}");
    }

    #[test]
    fn settings_saved_with_m500_survive_a_reboot() {
        let mut board = SimBoard::new();
        board.receive(b"M92 E415\nM500\n");
        board.advance(10);
        let mut rebooted = SimBoard::with_eeprom(SimEeprom { bytes: board.eeprom.bytes, ..SimEeprom::new() });
        assert!(rebooted.take_output().contains("echo:V3 stored settings retrieved"));
        assert_eq!(rebooted.link.machine.settings().steps_per_mm_milli[3], 415_000);
    }

    #[test]
    fn m112_acts_even_when_the_queue_is_full() {
        let mut board = SimBoard::new();
        board.receive(b"G4 S100\nM114\nM114\nM114\nM114\nM112\n");
        board.advance(5);
        assert!(board.take_output().contains("Error:Printer halted. kill() called!\n"));
        assert!(board.link.machine.is_halted());
    }
}
