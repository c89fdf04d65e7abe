//! The Mega 2560 on simavr with a virtual RAMPS 1.4 around it.
//!
//! simavr executes the release ELF one instruction per `avr_run` call
//! (`run_cycle_limit` stays 1), so after every instruction the run loop
//! here sees the cycle counter, SREG's I flag, the interrupt nesting and SP.
//! Pins, the UART and the ADC are wired through simavr's IRQ API:
//! notifications on port-pin IRQs record STEP/DIR/heater edges with their
//! cycle; raising port-pin IRQs drives the endstop inputs; raising ADC IRQs
//! sets the thermistor voltages; UART0's IRQs carry bytes both ways.
//!
//! Corrections of simavr applied here (see README.md):
//! - UART frame time: simavr counts 11 bits per byte with parity off, and
//!   recomputes it only on a UBRRnL write (so U2X set afterwards is ignored,
//!   which halves the rate of this firmware). The bench wraps the write
//!   handlers of UBRR0L/H and UCSR0A/B/C and sets the frame from the
//!   registers: 1 start + data + parity (if on) + stop bits.
//! - Interrupt entry: simavr charges 0 cycles; the ATmega2560 takes 5 (PC
//!   push of 3 bytes, I clear, vector fetch). The run loop adds them to the
//!   cycle counter when an interrupt is entered.
//! - `sleep`: simavr's default sleep callback calls usleep(); the bench's
//!   does nothing (time still advances in cycles).
//! - UART polling: simavr usleep()s on UCSRnA reads by default
//!   (AVR_UART_FLAG_POLL_SLEEP); turned off.

use crate::elf::{ElfInfo, RAM_END};
use crate::host::{Host, HostConfig};
use crate::thermal::{SensorInput, ThermalPlant, Thermistor};
use simavr_ffi as ffi;
use std::ffi::{c_void, CString};
use std::path::Path;
use std::time::{Duration, Instant};

pub const CPU_HZ: u32 = 16_000_000;

const fn ioctl(a: u8, b: u8, c: u8, d: u8) -> u32 {
    (a as u32) << 24 | (b as u32) << 16 | (c as u32) << 8 | d as u32
}

// Data-space addresses of the ATmega2560 registers the bench touches.
const SPL: usize = 0x5D;
const SPH: usize = 0x5E;
const UCSR0A: u16 = 0xC0;
const UCSR0B: u16 = 0xC1;
const UCSR0C: u16 = 0xC2;
const UBRR0L: u16 = 0xC4;
const UBRR0H: u16 = 0xC5;
/// DOR0 in UCSR0A.
const DOR0: u8 = 1 << 3;

/// One pin: port letter and bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pin {
    pub port: u8,
    pub bit: u8,
}

pub const fn pin(port: u8, bit: u8) -> Pin {
    Pin { port, bit }
}

/// STEP/DIR pins of one stepper socket.
#[derive(Clone, Copy, Debug)]
pub struct AxisPins {
    pub name: &'static str,
    pub step: Pin,
    pub dir: Pin,
}

/// RAMPS 1.4 stepper sockets (Marlin's pin map, DESIGN.md).
pub const AXES: [AxisPins; 5] = [
    AxisPins {
        name: "X",
        step: pin(b'F', 0),
        dir: pin(b'F', 1),
    },
    AxisPins {
        name: "Y",
        step: pin(b'F', 6),
        dir: pin(b'F', 7),
    },
    AxisPins {
        name: "Z",
        step: pin(b'L', 3),
        dir: pin(b'L', 1),
    },
    AxisPins {
        name: "E0",
        step: pin(b'A', 4),
        dir: pin(b'A', 6),
    },
    AxisPins {
        name: "E1",
        step: pin(b'C', 1),
        dir: pin(b'C', 3),
    },
];
pub const X: usize = 0;
pub const Y: usize = 1;
pub const Z: usize = 2;
pub const E0: usize = 3;
pub const E1: usize = 4;

/// Endstop inputs in the firmware's order: X_MIN, X_MAX, Y_MIN, Y_MAX,
/// Z_MIN, Z_MAX.
pub const ENDSTOP_PINS: [Pin; 6] = [
    pin(b'E', 5),
    pin(b'E', 4),
    pin(b'J', 1),
    pin(b'J', 0),
    pin(b'D', 3),
    pin(b'D', 2),
];
pub const ENDSTOP_NAMES: [&str; 6] = ["X_MIN", "X_MAX", "Y_MIN", "Y_MAX", "Z_MIN", "Z_MAX"];

/// Heater and fan MOSFET gates.
pub const HOTEND_PIN: Pin = pin(b'B', 4);
pub const BED_PIN: Pin = pin(b'H', 5);
pub const FAN_PIN: Pin = pin(b'H', 6);
/// The RepRapDiscount display's E line on EXP1 (D17).
pub const LCD_E_PIN: Pin = pin(b'H', 0);

/// One recorded STEP edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepEdge {
    pub cycle: u64,
    pub rising: bool,
    /// DIR level at the edge.
    pub dir: bool,
    /// Cycles spent in interrupt handlers since boot, at this edge.
    pub isr_cycles: u64,
}

/// A limit switch at a position on an axis.
#[derive(Clone, Copy, Debug)]
pub struct Endstop {
    /// Index into [`AXES`] whose position moves the switch.
    pub axis: usize,
    /// The switch is pressed at or beyond this position (in steps).
    pub at_steps: i64,
    /// Pressed when the position is ≤ `at_steps` (a MIN switch) or ≥ (MAX).
    pub is_min: bool,
    /// Pin level while pressed (high: a normally-closed switch to ground
    /// opens and the pull-up wins; low: a normally-open switch to ground).
    pub pressed_level: bool,
}

/// How one thermistor input is produced.
#[derive(Clone, Debug)]
pub struct SensorConfig {
    pub adc_channel: u8,
    /// The heater pin that heats this sensor's plant, if any.
    pub heater: Option<Pin>,
    pub plant: ThermalPlant,
    pub thermistor: Thermistor,
    pub input: SensorInput,
}

/// The virtual RAMPS around the chip.
#[derive(Clone, Debug)]
pub struct RampsConfig {
    pub host: HostConfig,
    /// Per axis: DIR high means positive motion.
    pub dir_high_is_positive: [bool; 5],
    /// Per endstop input (X_MIN … Z_MAX): a switch, or none (the pull-up
    /// reads high).
    pub endstops: [Option<Endstop>; 6],
    pub sensors: Vec<SensorConfig>,
    /// Thermal plant update period, seconds.
    pub plant_period_s: f64,
    /// Thermal history sample period, seconds.
    pub sample_period_s: f64,
    /// Add the 5 cycles simavr leaves out of each interrupt entry.
    pub correct_interrupt_entry: bool,
    /// Emulate the USART's 2-byte receive FIFO: a byte arriving while two
    /// are unread is lost and DOR0 is set (simavr buffers 64).
    pub hardware_rx_fifo: bool,
    /// Other input pins driven from boot, at these levels (the arm's
    /// safety inputs: [`ARM_SAFETY_CLEAR`]); any other input floats on
    /// its pull-up. [`Board::drive_input`] changes them later.
    pub inputs: Vec<(Pin, bool)>,
}

/// The arm's safety inputs (boards/mega2560-ramps/src/pins.rs): the safety
/// relay on D40 = PG1 (high = tripped), the emergency stop on D42 = PL7
/// (high = pressed), re-arm on D44 = PL5 (low = pressed).
pub const SAFETY_RELAY_PIN: Pin = pin(b'G', 1);
pub const EMERGENCY_STOP_PIN: Pin = pin(b'L', 7);
pub const REARM_PIN: Pin = pin(b'L', 5);
/// The arm's safety circuit closed: curtain clear, e-stop released,
/// re-arm not pressed (the levels for [`RampsConfig::inputs`]).
pub const ARM_SAFETY_CLEAR: [(Pin, bool); 3] = [(SAFETY_RELAY_PIN, false), (EMERGENCY_STOP_PIN, false), (REARM_PIN, true)];

impl RampsConfig {
    pub fn stock(baud: u32) -> Self {
        Self {
            host: HostConfig::printcore(baud),
            dir_high_is_positive: [true; 5],
            endstops: [None; 6],
            sensors: vec![
                SensorConfig {
                    adc_channel: 13,
                    heater: Some(HOTEND_PIN),
                    plant: ThermalPlant::hotend(),
                    thermistor: Thermistor::NTC100K_B3950_4K7,
                    input: SensorInput::Plant,
                },
                SensorConfig {
                    adc_channel: 14,
                    heater: Some(BED_PIN),
                    plant: ThermalPlant::bed(),
                    thermistor: Thermistor::NTC100K_B3950_4K7,
                    input: SensorInput::Plant,
                },
                SensorConfig {
                    adc_channel: 15,
                    heater: None,
                    plant: ThermalPlant::unheated(),
                    thermistor: Thermistor::NTC100K_B3950_4K7,
                    input: SensorInput::Plant,
                },
            ],
            plant_period_s: 0.001,
            sample_period_s: 0.1,
            correct_interrupt_entry: true,
            hardware_rx_fifo: true,
            inputs: Vec::new(),
        }
    }
}

/// CPU-time accounting, updated after every instruction.
#[derive(Clone, Copy, Debug, Default)]
pub struct CpuStats {
    pub instructions: u64,
    /// Cycles of instructions that began with SREG.I clear (interrupt
    /// handlers, and critical sections of the main loop), plus interrupt
    /// entries.
    pub i_clear_cycles: u64,
    /// Cycles of instructions inside an interrupt handler (entry to RETI),
    /// plus interrupt entries.
    pub isr_cycles: u64,
    pub sleep_cycles: u64,
    pub interrupt_entries: u64,
    /// Lowest SP seen after any instruction, and the PC (byte address)
    /// of the instruction that took it there.
    pub min_sp: u16,
    pub min_sp_pc: u32,
    /// Times the CPU went back to the reset vector (watchdog, crash).
    pub resets: u64,
    /// `wdr` instructions executed (the firmware feeds its watchdog once
    /// per main-loop pass), the cycle of the last one, and the longest gap
    /// between two: the worst main-loop period.
    pub watchdog_feeds: u64,
    pub last_watchdog_feed: u64,
    pub max_watchdog_gap: u64,
}

/// Duty bookkeeping of one output pin.
#[derive(Clone, Copy, Debug, Default)]
struct DutyMeter {
    level: bool,
    since: u64,
    high_in_tick: u64,
    high_in_sample: u64,
    edges: u64,
}

impl DutyMeter {
    /// A level seen at `now`; `true` when it changed.
    fn edge(&mut self, now: u64, level: bool) -> bool {
        if level == self.level {
            return false;
        }
        if self.level {
            // (saturating: simavr restarts its cycle count at a reset)
            self.high_in_tick += now.saturating_sub(self.since);
            self.high_in_sample += now.saturating_sub(self.since);
        }
        self.level = level;
        self.since = now;
        self.edges += 1;
        true
    }

    fn close(&mut self, now: u64) {
        if self.level {
            // (saturating: simavr restarts its cycle count at a reset)
            self.high_in_tick += now.saturating_sub(self.since);
            self.high_in_sample += now.saturating_sub(self.since);
        }
        self.since = now;
    }
}

/// One point of the thermal history.
#[derive(Clone, Debug)]
pub struct ThermalSample {
    pub time_s: f64,
    /// Per sensor (in `RampsConfig::sensors` order): heater duty over the
    /// sample period (0..1), plant temperature, ADC counts presented.
    pub duty: Vec<f64>,
    pub celsius: Vec<f64>,
    pub adc: Vec<u16>,
    pub fan_duty: f64,
}

struct AxisState {
    step_level: bool,
    dir_level: bool,
    /// PORTx data address and bit of the DIR pin.
    dir_port: (u16, u8),
    dir_changed_at: Option<u64>,
    dir_setup_violations: u64,
    position: i64,
    rising_edges: u64,
    edges: Vec<StepEdge>,
    min_high_cycles: Option<u64>,
    last_rise: u64,
}

struct Sensor {
    config: SensorConfig,
    meter: Option<usize>,
    irq: *mut ffi::avr_irq_t,
    counts: u16,
}

/// Everything the C callbacks touch. Boxed (stable address); accessed only
/// from the thread that runs the simulation, either inside `avr_run`
/// (callbacks) or between calls.
struct Shared {
    avr: *mut ffi::avr_t,
    stats: CpuStats,
    axes: Vec<AxisState>,
    axis_of_pin: Vec<(*mut ffi::avr_irq_t, usize, bool)>,
    endstops: [Option<Endstop>; 6],
    endstop_irqs: [*mut ffi::avr_irq_t; 6],
    endstop_levels: [bool; 6],
    /// Input pins driven by [`Board::drive_input`] (`None`: released to
    /// the pull-up), with their IRQs.
    driven: Vec<(Pin, *mut ffi::avr_irq_t, Option<bool>)>,
    dir_high_is_positive: [bool; 5],
    meters: Vec<(Pin, *mut ffi::avr_irq_t, DutyMeter)>,
    /// Level changes of the bed pin (D8), when asked for.
    bed_edges: Option<Vec<(u64, bool)>>,
    /// The HD44780 on EXP1 as the firmware drives it.
    lcd: Lcd,
    /// Per meter: the TCCRnA address and bit shift of the compare unit
    /// that can drive the pin (COMnx1:0).
    meter_compare: Vec<(u16, u8)>,
    sensors: Vec<Sensor>,
    plant_period_cycles: u64,
    sample_period_cycles: u64,
    next_sample: u64,
    samples: Vec<ThermalSample>,
    host: Host,
    uart_input_irq: *mut ffi::avr_irq_t,
    uart0: *mut ffi::avr_uart_t,
    /// Wrapped write handlers of the UART registers: (addr, original).
    uart_handlers: Vec<(u16, ffi::avr_io_write_t, *mut c_void)>,
    avr_frame_cycles: u64,
    hardware_rx_fifo: bool,
    rx_overruns: u64,
    /// The cycle of each overrun.
    rx_overrun_cycles: Vec<u64>,
    tx_log: Vec<(u64, u8, u64)>,
    /// Bytes injected into the receiver: (start-bit cycle, byte).
    rx_log: Vec<(u64, u8)>,
    record_isr_intervals: bool,
    /// (cycle, pc) every `pc_sample_every` cycles, when sampling.
    pc_samples: Vec<(u64, u32)>,
    /// With the inclusive profile on: the call stack (function entries) at
    /// each PC sample.
    stack_samples: Vec<Vec<u32>>,
    pc_sample_every: u64,
    next_pc_sample: u64,
    /// Cycles of every `wdr` (main-loop pass boundaries), when sampling.
    watchdog_feeds_at: Vec<u64>,
    isr_entered_at: u64,
    /// Outermost interrupt handler runs: [entry, after RETI).
    isr_intervals: Vec<(u64, u64)>,
    /// The vector (flash byte address) of each recorded top-level run.
    isr_vectors: Vec<u32>,
    isr_entered_vector: u32,
    /// Main-loop stretches with interrupts off: (first pc, cycles), the
    /// longest first, while recording ISR intervals.
    main_cli: Vec<(u32, u64)>,
    main_cli_open: Option<(u32, u64)>,
    /// Handler runs open at each nesting level, while recording ISR
    /// intervals: (vector pc, entered, cycles of the runs nested in it).
    isr_open: Vec<(u32, u64, u64)>,
    /// Per vector (flash byte address): the longest run without the
    /// handlers nested in it, and the number of runs.
    isr_own_longest: std::collections::BTreeMap<u32, (u64, usize)>,
    /// Cycles per flash word address, when profiling.
    profile: Option<Vec<u64>>,
    /// Inclusive profile: cycles per function entry (word address) with
    /// everything it called, and the shadow call stack that feeds it.
    inclusive: Option<(Vec<u64>, Vec<(u32, u16)>)>,
    /// The inclusive profile counts main-loop cycles only (not those of
    /// the handlers that interrupted a function).
    inclusive_main_only: bool,
    /// SPEC §1's NSE-5310s on the TWI bus, once attached.
    nse: Option<Nse5310Pair>,
}

/// Two NSE-5310 linear encoders on the TWI bus (SPEC §1), answering for
/// X and Y: each reads where its carriage is, i.e. the STEP pulses the
/// bench counted on its axis (the planner's and the loops' corrections)
/// times `units_per_step`, plus a slip the test sets (a belt that jumped
/// teeth). 4096 counts per 2 mm pole pair; the frame is the chip's: D11..D4,
/// then D3..D0 with OCF set.
#[derive(Clone, Debug)]
pub struct Nse5310Pair {
    /// 7-bit addresses of the X and Y chips.
    pub addresses: [u8; 2],
    /// Encoder counts (1/2048 mm) per step of the axis.
    pub units_per_step: f64,
    /// +1 when the strip counts up with the axis' STEP edges as the bench
    /// counts them (by DIR pin level), −1 when the motor is wired inverted
    /// (the Prusa's Y): the encoder counts up with the firmware's +axis.
    pub count_sign: [f64; 2],
    /// Where each carriage is relative to its steps, counts.
    pub slip_units: [f64; 2],
    /// A chip that does not answer (unplugged) leaves its address NACKed.
    pub answering: [bool; 2],
    /// A jammed carriage: the encoder keeps reading this many counts (± 1
    /// of noise) whatever the steps do.
    pub jammed_at: [Option<f64>; 2],
    /// The carriages behind the motors (`crate::carriage`); `None`: each
    /// carriage is exactly where its steps put it.
    pub plant: Option<crate::carriage::CarriagePlant>,
    /// Completed reads per chip.
    pub reads: [u64; 2],
    /// Index pulses sent per chip (pole-pair crossings and injected glitches).
    pub index_pulses: [u64; 2],
    selected: Option<usize>,
    byte: u8,
    twi_input: *mut ffi::avr_irq_t,
    /// The Index outputs: A9 (PK1, X) and A10 (PK2, Y).
    index_irqs: [*mut ffi::avr_irq_t; 2],
    /// The pole pair each carriage was in at its last step.
    pole: [i64; 2],
    /// Cycle until which each Index output stays high.
    index_high_until: [Option<u64>; 2],
}

/// How long an Index pulse stays high: 200 µs. The firmware reads the
/// level in its pin-change handler, so a pulse shorter than its longest
/// interrupt latency (a segment change of the step interrupt, ≈ 50 µs)
/// can be missed; the tracker then counts an Index miss, it never
/// miscounts the position (README, the encoder loops).
const INDEX_PULSE_CYCLES: u64 = 3200;

impl Nse5310Pair {
    /// Counts the X (0) or Y (1) chip reads at cycle `now`, its motor at
    /// `position` steps (the plant, if any, is advanced to `now`).
    fn carriage_counts(&mut self, chip: usize, position: i64, now: u64) -> f64 {
        let noise = (self.reads[chip] % 2) as f64;
        let carriage = match self.plant.as_mut() {
            Some(plant) => plant.carriage_steps(chip, position, now),
            None => position as f64,
        };
        self.jammed_at[chip].map(|at| at + noise).unwrap_or(self.count_sign[chip] * carriage * self.units_per_step + self.slip_units[chip])
    }
}

impl Nse5310Pair {
    /// The SPEC §1 printer: X at 0x40, Y at 0x41, 100 steps/mm.
    pub fn prusa() -> Self {
        Self {
            addresses: [0x40, 0x41],
            units_per_step: 2048.0 / 100.0,
            count_sign: [1.0, -1.0],
            slip_units: [0.0; 2],
            answering: [true; 2],
            jammed_at: [None; 2],
            plant: None,
            reads: [0; 2],
            index_pulses: [0; 2],
            index_irqs: [std::ptr::null_mut(); 2],
            pole: [0; 2],
            index_high_until: [None; 2],
            selected: None,
            byte: 0,
            twi_input: std::ptr::null_mut(),
        }
    }
}

/// The simulated board.
pub struct Board {
    avr: *mut ffi::avr_t,
    shared: Box<Shared>,
    pub elf: ElfInfo,
    correct_interrupt_entry: bool,
    paint_from: u16,
    wall: Duration,
    wall_cycles: u64,
    /// Stop `run_*` when a reply line contains this (e.g. "Error:Firmware panic").
    halted_reason: Option<String>,
}

/// The pattern painted over free RAM at load.
pub const PAINT: u8 = 0xA5;

impl Board {
    /// Load `elf` on an ATmega2560 at 16 MHz with the virtual RAMPS.
    pub fn load(elf_path: &Path, config: RampsConfig) -> Result<Self, String> {
        let elf = ElfInfo::read(elf_path)?;
        // SAFETY: plain FFI calls on a freshly made simavr instance; every
        // pointer used below comes from simavr itself or lives in `shared`,
        // which outlives the instance (terminated in Drop first).
        unsafe {
            let name = CString::new("atmega2560").unwrap();
            let avr = ffi::avr_make_mcu_by_name(name.as_ptr());
            if avr.is_null() {
                return Err("simavr has no atmega2560 core".into());
            }
            if ffi::avr_init(avr) != 0 {
                return Err("avr_init failed".into());
            }
            (*avr).set_log(0);
            // simavr logs ELF loading with no instance (so `log` cannot
            // silence it) on stdout; the bench reports for itself.
            ffi::avr_global_logger_set(std::mem::transmute::<
                unsafe extern "C" fn(
                    *mut ffi::avr_t,
                    std::os::raw::c_int,
                    *const std::os::raw::c_char,
                    *mut c_void,
                ),
                ffi::avr_logger_p,
            >(quiet_logger));
            let mut firmware: Box<ffi::elf_firmware_t> = Box::new(std::mem::zeroed());
            let path =
                CString::new(elf_path.to_string_lossy().as_bytes()).map_err(|e| e.to_string())?;
            if ffi::elf_read_firmware(path.as_ptr(), &mut *firmware) != 0 {
                return Err(format!("simavr could not read {}", elf_path.display()));
            }
            ffi::avr_load_firmware(avr, &mut *firmware);
            (*avr).frequency = CPU_HZ;
            (*avr).avcc = 5000;
            (*avr).vcc = 5000;
            (*avr).aref = 5000;
            (*avr).set_log(0);
            (*avr).sleep = Some(no_sleep);

            let mut flags: u32 = 0;
            ffi::avr_ioctl(
                avr,
                ioctl(b'u', b'a', b's', b'0'),
                &mut flags as *mut u32 as *mut c_void,
            );

            let mut host = Host::new(config.host.clone(), CPU_HZ);
            host.next_start = 0.0;
            let mut shared = Box::new(Shared {
                avr,
                stats: CpuStats {
                    min_sp: RAM_END,
                    ..CpuStats::default()
                },
                axes: AXES
                    .iter()
                    .map(|pins| AxisState {
                        step_level: false,
                        dir_level: false,
                        dir_port: (port_register(pins.dir.port), pins.dir.bit),
                        dir_changed_at: None,
                        dir_setup_violations: 0,
                        position: 0,
                        rising_edges: 0,
                        edges: Vec::new(),
                        min_high_cycles: None,
                        last_rise: 0,
                    })
                    .collect(),
                axis_of_pin: Vec::new(),
                endstops: config.endstops,
                endstop_irqs: [std::ptr::null_mut(); 6],
                endstop_levels: [true; 6],
                driven: Vec::new(),
                dir_high_is_positive: config.dir_high_is_positive,
                meters: Vec::new(),
                bed_edges: None,
                lcd: Lcd::default(),
                meter_compare: Vec::new(),
                sensors: Vec::new(),
                plant_period_cycles: (config.plant_period_s * f64::from(CPU_HZ)).round() as u64,
                sample_period_cycles: (config.sample_period_s * f64::from(CPU_HZ)).round() as u64,
                next_sample: 0,
                samples: Vec::new(),
                host,
                uart_input_irq: ffi::avr_io_getirq(
                    avr,
                    ioctl(b'u', b'a', b'r', b'0'),
                    ffi::UART_IRQ_INPUT as i32,
                ),
                uart0: find_uart(avr, b'0'),
                uart_handlers: Vec::new(),
                avr_frame_cycles: 0,
                hardware_rx_fifo: config.hardware_rx_fifo,
                rx_overruns: 0,
                rx_overrun_cycles: Vec::new(),
                tx_log: Vec::new(),
                rx_log: Vec::new(),
                record_isr_intervals: false,
                pc_samples: Vec::new(),
                stack_samples: Vec::new(),
                pc_sample_every: 0,
                next_pc_sample: 0,
                watchdog_feeds_at: Vec::new(),
                isr_entered_at: 0,
                isr_intervals: Vec::new(),
                isr_vectors: Vec::new(),
                isr_entered_vector: 0,
                main_cli: Vec::new(),
                main_cli_open: None,
                isr_open: Vec::new(),
                isr_own_longest: Default::default(),
                profile: None,
                inclusive: None,
                inclusive_main_only: false,
                nse: None,
            });
            shared.next_sample = shared.sample_period_cycles;
            if shared.uart0.is_null() {
                return Err("simavr's atmega2560 has no UART0".into());
            }
            let param = &mut *shared as *mut Shared as *mut c_void;

            // Firmware output.
            let out = ffi::avr_io_getirq(
                avr,
                ioctl(b'u', b'a', b'r', b'0'),
                ffi::UART_IRQ_OUTPUT as i32,
            );
            ffi::avr_irq_register_notify(out, Some(on_uart_output), param);
            // Frame-time fix: wrap the UART configuration registers.
            for addr in [UBRR0L, UBRR0H, UCSR0A, UCSR0B, UCSR0C] {
                let slot = &mut (*avr).io[usize::from(addr) - 32].w;
                shared.uart_handlers.push((addr, slot.c, slot.param));
                slot.c = Some(on_uart_config_write);
                slot.param = param;
            }

            // STEP and DIR pins.
            for (axis, pins) in AXES.iter().enumerate() {
                for (p, is_step) in [(pins.step, true), (pins.dir, false)] {
                    let irq = port_irq(avr, p);
                    shared.axis_of_pin.push((irq, axis, is_step));
                    ffi::avr_irq_register_notify(irq, Some(on_axis_pin), param);
                }
            }
            // Heater and fan pins.
            // OC2A (TCCR2A COM2A, bits 7:6), OC4C (TCCR4A COM4C, 3:2),
            // OC2B (TCCR2A COM2B, 5:4).
            for (p, compare) in [
                (HOTEND_PIN, (0xB0, 6)),
                (BED_PIN, (0xA0, 2)),
                (FAN_PIN, (0xB0, 4)),
            ] {
                let irq = port_irq(avr, p);
                shared.meters.push((p, irq, DutyMeter::default()));
                shared.meter_compare.push(compare);
                ffi::avr_irq_register_notify(irq, Some(on_meter_pin), param);
            }
            // The HD44780's E line (D17 = PH0): data is latched on its
            // falling edge.
            ffi::avr_irq_register_notify(port_irq(avr, LCD_E_PIN), Some(on_lcd_enable), param);
            // Thermistors.
            for sensor in config.sensors {
                let meter = sensor
                    .heater
                    .and_then(|h| shared.meters.iter().position(|(p, _, _)| *p == h));
                let irq = ffi::avr_io_getirq(
                    avr,
                    ioctl(b'a', b'd', b'c', b'0'),
                    ffi::ADC_IRQ_ADC0 as i32 + i32::from(sensor.adc_channel),
                );
                shared.sensors.push(Sensor {
                    config: sensor,
                    meter,
                    irq,
                    counts: 0,
                });
            }
            shared.update_adc_inputs();
            // Endstops.
            for (i, p) in ENDSTOP_PINS.iter().enumerate() {
                shared.endstop_irqs[i] = port_irq(avr, *p);
            }
            for &(p, level) in &config.inputs {
                shared.driven.push((p, port_irq(avr, p), Some(level)));
                ffi::avr_raise_irq(port_irq(avr, p), u32::from(level));
            }
            shared.update_endstops(true);
            // The thermal plants run on a simavr cycle timer.
            let period = shared.plant_period_cycles;
            ffi::avr_cycle_timer_register(avr, period, Some(on_plant_tick), param);

            // Paint free RAM (between the static data and the stack top).
            let paint_from = elf.static_end();
            for addr in paint_from..=RAM_END {
                *(*avr).data.add(usize::from(addr)) = PAINT;
            }
            std::mem::forget(firmware);
            Ok(Self {
                avr,
                shared,
                elf,
                correct_interrupt_entry: config.correct_interrupt_entry,
                paint_from,
                wall: Duration::ZERO,
                wall_cycles: 0,
                halted_reason: None,
            })
        }
    }

    /// Put two NSE-5310s on the TWI bus (X's and Y's encoders).
    pub fn attach_nse5310(&mut self, mut pair: Nse5310Pair) {
        // SAFETY: `avr` is valid; the notify's param is the boxed `Shared`,
        // which outlives the instance.
        unsafe {
            // simavr's ATmega2560 TWI has no name: its ioctl ends in 0, not '0'.
            let twi = ioctl(b't', b'w', b'i', 0);
            pair.twi_input = ffi::avr_io_getirq(self.avr, twi, ffi::TWI_IRQ_INPUT as i32);
            pair.index_irqs = [port_irq(self.avr, pin(b'K', 1)), port_irq(self.avr, pin(b'K', 2))];
            for chip in 0..2 {
                ffi::avr_raise_irq(pair.index_irqs[chip], 0);
                let counts = pair.carriage_counts(chip, self.shared.axes[chip].position, (*self.avr).cycle);
                pair.pole[chip] = (counts / 4096.0).floor() as i64;
            }
            let output = ffi::avr_io_getirq(self.avr, twi, ffi::TWI_IRQ_OUTPUT as i32);
            self.shared.nse = Some(pair);
            let param = &mut *self.shared as *mut Shared as *mut c_void;
            ffi::avr_irq_register_notify(output, Some(on_twi_output), param);
        }
    }

    /// The encoders, to read their counters or change a slip.
    pub fn nse5310(&mut self) -> Option<&mut Nse5310Pair> {
        self.shared.nse.as_mut()
    }

    /// Where chip `chip`'s carriage is now, mm along the firmware's axis
    /// from where it was at boot (the encoder's view without its
    /// quantisation); `None` without encoders.
    pub fn encoder_carriage_mm(&mut self, chip: usize) -> Option<f64> {
        let now = self.cycle();
        let position = self.shared.axes[chip].position;
        let nse = self.shared.nse.as_mut()?;
        Some(nse.carriage_counts(chip, position, now) / 2048.0)
    }

    /// A spurious pulse on chip `chip`'s Index line (the noise the thesis
    /// saw), wherever the carriage is.
    pub fn glitch_index(&mut self, chip: usize) {
        // SAFETY: the shared state outlives the instance; called between runs.
        unsafe { self.shared.pulse_index(chip) };
    }

    pub fn cycle(&self) -> u64 {
        // SAFETY: `avr` is valid for the board's lifetime.
        unsafe { (*self.avr).cycle }
    }

    pub fn seconds(&self) -> f64 {
        self.cycle() as f64 / f64::from(CPU_HZ)
    }

    pub fn stats(&self) -> CpuStats {
        self.shared.stats
    }

    pub fn host(&self) -> &Host {
        &self.shared.host
    }

    pub fn host_mut(&mut self) -> &mut Host {
        &mut self.shared.host
    }

    /// Queue lines for the host to send.
    pub fn send<I, S>(&mut self, lines: I)
    where
        I: IntoIterator<Item = S>,
        S: AsRef<str>,
    {
        let now = self.cycle() as f64;
        let host = &mut self.shared.host;
        if host.is_done() {
            host.next_start = host.next_start.max(now);
        }
        host.queue(lines);
    }

    /// Queue the lines of a G-code file for the host to send.
    pub fn send_file(&mut self, path: &Path) -> Result<usize, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        let lines: Vec<&str> = text.lines().collect();
        let count = lines.len();
        self.send(lines);
        Ok(count)
    }

    /// Why the run stopped early (CPU crashed or stopped), if it did.
    pub fn halted_reason(&self) -> Option<&str> {
        self.halted_reason.as_deref()
    }

    /// Run until cycle `end` (or the CPU stops).
    pub fn run_until(&mut self, end: u64) {
        self.run_while(end, |_| true);
    }

    pub fn run_for_ms(&mut self, ms: f64) {
        let end = self.cycle() + (ms * f64::from(CPU_HZ) / 1000.0) as u64;
        self.run_until(end);
    }

    /// Run until the host has sent everything and got its `ok`s, or until
    /// `timeout_s` simulated seconds pass; true if the host finished.
    pub fn run_until_host_done(&mut self, timeout_s: f64) -> bool {
        let end = self.cycle() + (timeout_s * f64::from(CPU_HZ)) as u64;
        let shared: *const Shared = &*self.shared;
        // SAFETY: read-only peek at the host between instructions.
        self.run_while(end, |_| unsafe { !(*shared).host.is_done() });
        self.shared.host.is_done()
    }

    /// The core loop: one instruction per call, with the accounting.
    /// `keep_going` is checked every 1024 instructions.
    pub fn run_while(&mut self, mut end: u64, mut keep_going: impl FnMut(u64) -> bool) {
        let avr = self.avr;
        let started = Instant::now();
        let start_cycle = self.cycle();
        let shared: *mut Shared = &mut *self.shared;
        let mut countdown = 0u32;
        // SAFETY: `avr` and `shared` are valid; callbacks run only inside
        // avr_run, on this thread, and touch `shared` through the same
        // pointer.
        unsafe {
            loop {
                let cycle = (*avr).cycle;
                if cycle >= end {
                    break;
                }
                if countdown == 0 {
                    countdown = 1024;
                    if !keep_going(cycle) {
                        break;
                    }
                }
                countdown -= 1;
                if let Some(byte) = (*shared).host.poll_byte(cycle) {
                    (*shared).inject_rx(byte);
                }
                let i_clear = (*avr).sreg[ffi::S_I as usize] == 0;
                let nesting = (*avr).interrupts.running_ptr;
                let sleeping = (*avr).state == ffi::cpu_Sleeping as i32;
                let pc_before = (*avr).pc;
                // `wdr` is 0x95A8 (little endian in flash).
                let is_wdr = *(*avr).flash.add(pc_before as usize) == 0xA8
                    && *(*avr).flash.add(pc_before as usize + 1) == 0x95;
                let state = ffi::avr_run(avr);
                let after = (*avr).cycle;
                if after < cycle {
                    // A reset restarted simavr's cycle count: the deadline
                    // moves back with it, so the run still lasts as long.
                    end = end.saturating_sub(cycle - after);
                }
                // simavr restarts its cycle count at a reset (watchdog).
                let spent = after.saturating_sub(cycle);
                if let Some(profile) = &mut (*shared).profile {
                    if let Some(slot) = profile.get_mut((pc_before / 2) as usize) {
                        *slot += spent;
                    }
                }
                if let Some((cycles, stack)) = &mut (*shared).inclusive {
                    // Frames are (entry pc, SP just after the return address
                    // was pushed): a frame ends when SP rises above it,
                    // whatever popped it (ret, reti, a tail call's ret).
                    let word = u16::from(*(*avr).flash.add(pc_before as usize)) | u16::from(*(*avr).flash.add(pc_before as usize + 1)) << 8;
                    if nesting == 0 || !(*shared).inclusive_main_only {
                        for &(entry, _) in stack.iter() {
                            cycles[(entry / 2) as usize] += spent;
                        }
                    }
                    let sp = u16::from(*(*avr).data.add(SPL)) | u16::from(*(*avr).data.add(SPH)) << 8;
                    while stack.last().is_some_and(|&(_, at)| sp > at) {
                        stack.pop();
                    }
                    let entered_interrupt = (*avr).interrupts.running_ptr > nesting;
                    let is_call = word & 0xFE0E == 0x940E || word & 0xF000 == 0xD000 || word == 0x9509 || word == 0x9519;
                    if entered_interrupt || is_call {
                        stack.push(((*avr).pc, sp));
                    }
                }
                if (*shared).pc_sample_every != 0 {
                    if cycle >= (*shared).next_pc_sample {
                        (*shared).next_pc_sample = cycle + (*shared).pc_sample_every;
                        (*shared).pc_samples.push((cycle, pc_before));
                        if let Some((_, stack)) = &(*shared).inclusive {
                            let frames = stack.iter().map(|&(entry, _)| entry).collect();
                            (*shared).stack_samples.push(frames);
                        }
                    }
                    if is_wdr {
                        (*shared).watchdog_feeds_at.push(cycle);
                    }
                }
                let stats = &mut (*shared).stats;
                stats.instructions += 1;
                if is_wdr {
                    if stats.watchdog_feeds > 0 {
                        stats.max_watchdog_gap = stats.max_watchdog_gap.max(cycle.saturating_sub(stats.last_watchdog_feed));
                    }
                    stats.watchdog_feeds += 1;
                    stats.last_watchdog_feed = cycle;
                }
                if sleeping {
                    stats.sleep_cycles += spent;
                }
                if i_clear {
                    stats.i_clear_cycles += spent;
                }
                if (*shared).record_isr_intervals && nesting == 0 {
                    let off_after = (*avr).sreg[ffi::S_I as usize] == 0 && (*avr).interrupts.running_ptr == 0;
                    match ((*shared).main_cli_open, off_after) {
                        (None, true) => (*shared).main_cli_open = Some((pc_before, cycle)),
                        (Some((pc, from)), false) => {
                            (*shared).main_cli_open = None;
                            (*shared).main_cli.push((pc, after - from));
                        }
                        _ => {}
                    }
                }
                if nesting > 0 {
                    stats.isr_cycles += spent;
                }
                let nesting_after = (*avr).interrupts.running_ptr;
                if (*shared).record_isr_intervals {
                    // By instruction, not by the nesting count: a `reti`
                    // followed at once by the next pending vector leaves
                    // the count as it was. `reti` is 0x9518; an interrupt
                    // lands in the vector table (57 slots of 4 bytes).
                    let was_reti = *(*avr).flash.add(pc_before as usize) == 0x18
                        && *(*avr).flash.add(pc_before as usize + 1) == 0x95;
                    let entered = (*avr).pc < 57 * 4 && (*avr).pc != 0 && (was_reti || pc_before >= 57 * 4);
                    if was_reti {
                        if let Some((vector, at, nested)) = (*shared).isr_open.pop() {
                            let total = after - at;
                            if let Some(outer) = (*shared).isr_open.last_mut() {
                                outer.2 += total;
                            }
                            let own = (*shared).isr_own_longest.entry(vector).or_default();
                            own.0 = own.0.max(total - nested);
                            own.1 += 1;
                        }
                    }
                    if entered {
                        (*shared).isr_open.push(((*avr).pc, after, 0));
                    }
                }
                if nesting_after > nesting {
                    stats.interrupt_entries += 1;
                    if nesting == 0 {
                        (*shared).isr_entered_at = after;
                        (*shared).isr_entered_vector = (*avr).pc;
                    }
                    if self.correct_interrupt_entry {
                        (*avr).cycle += 5;
                        stats.i_clear_cycles += 5;
                        stats.isr_cycles += 5;
                    }
                } else if nesting_after == 0 && nesting > 0 && (*shared).record_isr_intervals {
                    let entered = (*shared).isr_entered_at;
                    (*shared).isr_intervals.push((entered, after));
                    let vector = (*shared).isr_entered_vector;
                    (*shared).isr_vectors.push(vector);
                }
                let sp = u16::from(*(*avr).data.add(SPL)) | u16::from(*(*avr).data.add(SPH)) << 8;
                if sp < stats.min_sp && sp >= crate::elf::RAM_START {
                    stats.min_sp = sp;
                    stats.min_sp_pc = pc_before;
                }
                if (*avr).pc == 0 {
                    stats.resets += 1;
                }
                if state == ffi::cpu_Crashed as i32 || state == ffi::cpu_Done as i32 {
                    self.halted_reason = Some(format!(
                        "simavr stopped the CPU ({}) at pc 0x{:05x}",
                        if state == ffi::cpu_Crashed as i32 {
                            "crashed"
                        } else {
                            "done: sleep with interrupts off"
                        },
                        (*avr).pc
                    ));
                    break;
                }
            }
        }
        self.wall += started.elapsed();
        self.wall_cycles += self.cycle().saturating_sub(start_cycle);
    }

    /// Simulated seconds per wall-clock second so far.
    pub fn speed(&self) -> f64 {
        let wall = self.wall.as_secs_f64();
        if wall == 0.0 {
            return 0.0;
        }
        self.wall_cycles as f64 / f64::from(CPU_HZ) / wall
    }

    pub fn wall_time(&self) -> Duration {
        self.wall
    }

    /// Stack high-water mark from SP: RAMEND − lowest SP seen, bytes.
    pub fn stack_peak_sp(&self) -> u32 {
        u32::from(RAM_END - self.shared.stats.min_sp)
    }

    /// Stack high-water mark from the paint: bytes from the lowest RAM byte
    /// that no longer holds the pattern up to RAMEND (a pushed 0xA5 at the
    /// very bottom would hide one byte).
    pub fn stack_peak_paint(&self) -> u32 {
        for addr in self.paint_from..=RAM_END {
            // SAFETY: inside simavr's data array.
            if unsafe { *(*self.avr).data.add(usize::from(addr)) } != PAINT {
                return u32::from(RAM_END - addr) + 1;
            }
        }
        0
    }

    /// Free RAM between the static data and the deepest stack use, bytes.
    pub fn ram_untouched(&self) -> u32 {
        u32::from(RAM_END - self.paint_from + 1) - self.stack_peak_paint()
    }

    pub fn read_ram(&self, addr: u16) -> u8 {
        // SAFETY: inside simavr's data array (64 KiB allocated).
        unsafe { *(*self.avr).data.add(usize::from(addr)) }
    }

    /// Net position of an axis in steps (DIR high = + unless configured).
    pub fn position(&self, axis: usize) -> i64 {
        self.shared.axes[axis].position
    }

    pub fn step_count(&self, axis: usize) -> u64 {
        self.shared.axes[axis].rising_edges
    }

    pub fn step_edges(&self, axis: usize) -> &[StepEdge] {
        &self.shared.axes[axis].edges
    }

    /// STEP rising edges that came less than 200 ns (4 cycles) after a DIR
    /// change, including DIR and STEP changed by one port write.
    pub fn dir_setup_violations(&self, axis: usize) -> u64 {
        self.shared.axes[axis].dir_setup_violations
    }

    /// Shortest STEP high time seen, cycles.
    pub fn min_step_pulse_cycles(&self, axis: usize) -> Option<u64> {
        self.shared.axes[axis].min_high_cycles
    }

    /// Forget recorded edges (counts and positions are kept).
    pub fn clear_step_edges(&mut self) {
        for axis in &mut self.shared.axes {
            axis.edges.clear();
        }
    }

    /// Highest step rate on an axis: `1/Δt` of the shortest interval
    /// between rising edges (instantaneous), and the highest mean over any
    /// `window` consecutive intervals.
    pub fn peak_step_rate(&self, axis: usize, window: usize) -> (f64, f64) {
        peak_rates(self.step_edges(axis), window)
    }

    pub fn set_endstop(&mut self, index: usize, endstop: Option<Endstop>) {
        self.shared.endstops[index] = endstop;
        // SAFETY: between instructions.
        unsafe { self.shared.update_endstops(false) };
    }

    /// Drive an input pin to `level` (`None`: let it float to its
    /// pull-up), from now on; the firmware sees it at its next read.
    pub fn drive_input(&mut self, p: Pin, level: Option<bool>) {
        // SAFETY: between instructions; the IRQ is the instance's own.
        unsafe {
            let irq = port_irq(self.avr, p);
            match self.shared.driven.iter_mut().find(|(q, _, _)| *q == p) {
                Some(entry) => entry.2 = level,
                None => self.shared.driven.push((p, irq, level)),
            }
            ffi::avr_raise_irq(irq, u32::from(level.unwrap_or(true)));
            self.shared.update_endstops(false);
        }
    }

    /// The level each endstop input is driven to.
    pub fn endstop_levels(&self) -> [bool; 6] {
        self.shared.endstop_levels
    }

    /// Replace what a sensor channel reads (plant or a fixed count).
    pub fn set_sensor_input(&mut self, adc_channel: u8, input: SensorInput) {
        for s in &mut self.shared.sensors {
            if s.config.adc_channel == adc_channel {
                s.config.input = input;
            }
        }
        // SAFETY: between instructions.
        unsafe { self.shared.update_adc_inputs() };
    }

    /// Set a plant's temperature (as if it had been heated or cooled).
    pub fn set_plant_celsius(&mut self, adc_channel: u8, celsius: f64) {
        for s in &mut self.shared.sensors {
            if s.config.adc_channel == adc_channel {
                s.config.plant.temperature_c = celsius;
            }
        }
        // SAFETY: between instructions.
        unsafe { self.shared.update_adc_inputs() };
    }

    pub fn sensor_celsius(&self, adc_channel: u8) -> Option<f64> {
        self.shared
            .sensors
            .iter()
            .find(|s| s.config.adc_channel == adc_channel)
            .map(|s| s.config.plant.temperature_c)
    }

    pub fn sensor_counts(&self, adc_channel: u8) -> Option<u16> {
        self.shared
            .sensors
            .iter()
            .find(|s| s.config.adc_channel == adc_channel)
            .map(|s| s.counts)
    }

    /// The HD44780 on EXP1 as the firmware has written it.
    pub fn lcd(&self) -> &Lcd {
        &self.shared.lcd
    }

    /// Start (or stop) recording the bed pin's level changes.
    pub fn record_bed_edges(&mut self, on: bool) {
        self.shared.bed_edges = on.then(Vec::new);
    }

    /// The bed pin's level changes since `record_bed_edges(true)`:
    /// (cycle, new level).
    pub fn bed_edges(&self) -> &[(u64, bool)] {
        self.shared.bed_edges.as_deref().unwrap_or(&[])
    }

    pub fn thermal_history(&self) -> &[ThermalSample] {
        &self.shared.samples
    }

    /// Bytes lost to the emulated 2-byte receive FIFO (DOR0 raised).
    pub fn rx_overruns(&self) -> u64 {
        self.shared.rx_overruns
    }

    /// When each receive overrun happened (cycles).
    pub fn rx_overrun_cycles(&self) -> &[u64] {
        &self.shared.rx_overrun_cycles
    }

    /// The AVR's UART frame, cycles (from its UBRR0/U2X0/UCSR0C setting).
    pub fn avr_frame_cycles(&self) -> u64 {
        self.shared.avr_frame_cycles
    }

    /// Every byte the firmware wrote to UDR0: (cycle, byte, ISR cycles then).
    pub fn tx_log(&self) -> &[(u64, u8, u64)] {
        &self.shared.tx_log
    }

    /// Every byte the host started sending: (start-bit cycle, byte). The
    /// firmware sees it (RXC) one AVR frame later.
    pub fn rx_log(&self) -> &[(u64, u8)] {
        &self.shared.rx_log
    }

    /// Record every outermost interrupt handler run from now on (for
    /// [`Board::isr_cycles_between`]).
    /// Sample the PC every `every` cycles (0: off) and note every
    /// watchdog feed, to see what the longest main-loop pass did.
    pub fn sample_pcs(&mut self, every: u64) {
        self.shared.pc_sample_every = every;
        self.shared.pc_samples.clear();
        self.shared.stack_samples.clear();
        self.shared.watchdog_feeds_at.clear();
    }

    /// Like [`Board::samples_between`], counting each function once per
    /// sample in which it was anywhere on the call stack (needs the
    /// inclusive profile on while sampling).
    pub fn stack_samples_between(&self, from: u64, to: u64) -> Vec<(String, usize)> {
        let mut counts: std::collections::BTreeMap<String, usize> = Default::default();
        for (&(cycle, pc), frames) in self.shared.pc_samples.iter().zip(&self.shared.stack_samples) {
            if cycle >= from && cycle < to {
                let mut seen = std::collections::BTreeSet::new();
                for &entry in frames.iter().chain(std::iter::once(&pc)) {
                    let name = self.symbol_at(entry).map(demangle).unwrap_or_else(|| format!("{entry:#x}"));
                    if seen.insert(name.clone()) {
                        *counts.entry(name).or_default() += 1;
                    }
                }
            }
        }
        let mut counts: Vec<_> = counts.into_iter().collect();
        counts.sort_by(|a, b| b.1.cmp(&a.1));
        counts
    }

    /// Functions sampled (see [`Board::sample_pcs`]) between two cycles,
    /// most samples first.
    pub fn samples_between(&self, from: u64, to: u64) -> Vec<(String, usize)> {
        let mut counts: std::collections::BTreeMap<String, usize> = Default::default();
        for &(cycle, pc) in &self.shared.pc_samples {
            if cycle >= from && cycle < to {
                let name = self.symbol_at(pc).map(demangle).unwrap_or_else(|| format!("{pc:#x}"));
                *counts.entry(name).or_default() += 1;
            }
        }
        let mut counts: Vec<_> = counts.into_iter().collect();
        counts.sort_by(|a, b| b.1.cmp(&a.1));
        counts
    }

    /// The sampled functions between two cycles in time order, runs of the
    /// same function merged: (first cycle, function, samples).
    pub fn timeline_between(&self, from: u64, to: u64) -> Vec<(u64, String, usize)> {
        let mut runs: Vec<(u64, String, usize)> = Vec::new();
        for &(cycle, pc) in &self.shared.pc_samples {
            if cycle >= from && cycle < to {
                let name = self.symbol_at(pc).map(demangle).unwrap_or_else(|| format!("{pc:#x}"));
                match runs.last_mut() {
                    Some((_, last, n)) if *last == name => *n += 1,
                    _ => runs.push((cycle, name, 1)),
                }
            }
        }
        runs
    }

    /// Main-loop passes (watchdog feed to feed) longer than `min_cycles`:
    /// their length and the functions sampled in them, most samples first.
    pub fn long_passes(&self, min_cycles: u64) -> Vec<(u64, Vec<(String, usize)>)> {
        self.shared
            .watchdog_feeds_at
            .windows(2)
            .filter(|w| w[1] - w[0] > min_cycles)
            .map(|w| (w[1] - w[0], self.samples_between(w[0], w[1])))
            .collect()
    }

    /// The PC samples taken during the longest main-loop pass: (its length
    /// in cycles, function name → samples).
    pub fn longest_pass_samples(&self) -> (u64, Vec<(String, usize)>) {
        let feeds = &self.shared.watchdog_feeds_at;
        let Some((start, end)) = feeds.windows(2).map(|w| (w[0], w[1])).max_by_key(|(a, b)| b - a) else {
            return (0, Vec::new());
        };
        (end - start, self.samples_between(start, end))
    }

    pub fn record_isr_intervals(&mut self, on: bool) {
        self.shared.record_isr_intervals = on;
        if !on {
            self.shared.isr_intervals.clear();
            self.shared.isr_vectors.clear();
            self.shared.main_cli.clear();
            self.shared.main_cli_open = None;
            self.shared.isr_open.clear();
            self.shared.isr_own_longest.clear();
        }
    }

    /// Per interrupt vector number, while ISR intervals were recorded: the
    /// longest run of its handler without the handlers nested in it
    /// (entry's 5 cycles to `reti`), and how many runs there were.
    pub fn isr_own_longest(&self) -> Vec<(u32, u64, usize)> {
        self.shared.isr_own_longest.iter().map(|(&pc, &(cycles, runs))| (pc / 4, cycles, runs)).collect()
    }

    /// Every top-level handler run recorded since
    /// [`Board::record_isr_intervals`] was turned on: (entered, returned)
    /// cycles, nested handlers inside their outer one.
    pub fn isr_intervals(&self) -> &[(u64, u64)] {
        &self.shared.isr_intervals
    }

    /// Main-loop stretches with interrupts off while ISR intervals were
    /// recorded: (flash byte address where they began, cycles).
    pub fn main_loop_interrupt_locks(&self) -> &[(u32, u64)] {
        &self.shared.main_cli
    }

    /// The interrupt vector number of each run in [`Board::isr_intervals`].
    pub fn isr_vector_numbers(&self) -> Vec<u32> {
        // The ATmega2560's vectors are 4 bytes apart from address 0.
        self.shared.isr_vectors.iter().map(|pc| pc / 4).collect()
    }

    /// Cycles spent in interrupt handlers within `[from, to)` (needs
    /// [`Board::record_isr_intervals`] on over that span; the 5-cycle entry
    /// is part of each handler run).
    pub fn isr_cycles_between(&self, from: u64, to: u64) -> u64 {
        let intervals = &self.shared.isr_intervals;
        let first = intervals.partition_point(|&(_, end)| end <= from);
        intervals[first..]
            .iter()
            .take_while(|&&(start, _)| start < to)
            .map(|&(start, end)| end.min(to).saturating_sub(start.max(from)))
            .sum()
    }

    /// The program counter (flash byte address).
    pub fn pc(&self) -> u32 {
        // SAFETY: `avr` is valid for the board's lifetime.
        unsafe { (*self.avr).pc }
    }

    /// The flash byte range of the first function whose symbol contains
    /// `name` (e.g. `"make_output"`).
    /// The flash address of the symbol named exactly `name` (labels of
    /// size 0 included, e.g. avr-libc's `__stop_program`).
    pub fn symbol_address(&self, name: &str) -> Option<u32> {
        self.elf.symbols.iter().find(|s| s.value < crate::elf::DATA_OFFSET && s.name == name).map(|s| s.value)
    }

    pub fn function_range(&self, name: &str) -> Option<std::ops::Range<u32>> {
        self.elf
            .symbols
            .iter()
            .find(|s| s.size > 0 && s.value < crate::elf::DATA_OFFSET && s.name.contains(name))
            .map(|s| s.value..s.value + s.size)
    }

    /// Write an I/O register as if the firmware had (through simavr's write
    /// handler, so pin IRQs and the recorders see it). For self-tests of
    /// the virtual RAMPS while the firmware itself does not step.
    pub fn write_io_as_firmware(&mut self, addr: u16, value: u8) {
        // SAFETY: between instructions; the handler table entry is simavr's.
        unsafe {
            let slot = (*self.avr).io[usize::from(addr) - 32].w;
            match slot.c {
                Some(write) => write(self.avr, addr, value, slot.param),
                None => *(*self.avr).data.add(usize::from(addr)) = value,
            }
        }
    }

    /// Make the CPU continue at flash byte address `addr` (as if the code
    /// had jumped there): for driving the firmware into its panic handler.
    pub fn jump_to(&mut self, addr: u32) {
        // SAFETY: between instructions; the PC is a plain field.
        unsafe { (*self.avr).pc = addr };
    }

    /// Read a data-space byte (I/O registers included) without side effects.
    pub fn peek(&self, addr: u16) -> u8 {
        // SAFETY: inside simavr's data array.
        unsafe { *(*self.avr).data.add(usize::from(addr)) }
    }

    /// Start (or stop and discard) the per-instruction cycle profile.
    pub fn profile(&mut self, on: bool) {
        self.shared.profile = on.then(|| vec![0; (crate::elf::FLASH_BYTES / 2) as usize]);
    }

    /// Start (or stop and discard) the inclusive profile: each function's
    /// cycles including what it calls (a shadow stack of call/ret and
    /// interrupt entries; a handler's cycles count for what it interrupted).
    pub fn inclusive_profile(&mut self, on: bool) {
        self.shared.inclusive = on.then(|| (vec![0; (crate::elf::FLASH_BYTES / 2) as usize], Vec::new()));
    }

    /// The inclusive profile counts only the main loop's own cycles: a
    /// function's figure leaves out the handlers that interrupted it.
    pub fn inclusive_main_loop_only(&mut self, on: bool) {
        self.shared.inclusive_main_only = on;
    }

    /// Inclusive cycles per function, highest first.
    pub fn inclusive_by_function(&self) -> Vec<(String, u64)> {
        let Some((cycles, _)) = &self.shared.inclusive else { return Vec::new() };
        let mut list: Vec<(String, u64)> = cycles
            .iter()
            .enumerate()
            .filter(|(_, &c)| c > 0)
            .map(|(word, &c)| {
                let pc = word as u32 * 2;
                (self.symbol_at(pc).map_or(format!("{pc:#x}"), demangle), c)
            })
            .collect();
        list.sort_by_key(|entry| std::cmp::Reverse(entry.1));
        list
    }

    /// Cycles spent on the instruction at flash byte address `pc` since
    /// profiling started (a `call` takes 5: its count of executions ×5).
    pub fn profile_at(&self, pc: u32) -> u64 {
        self.shared.profile.as_ref().and_then(|p| p.get((pc / 2) as usize).copied()).unwrap_or(0)
    }

    /// Cycles per function since profiling started, highest first
    /// (demangled names; instructions outside any sized symbol are
    /// grouped under "?").
    pub fn profile_by_function(&self) -> Vec<(String, u64)> {
        let Some(profile) = &self.shared.profile else {
            return Vec::new();
        };
        let mut totals: std::collections::HashMap<String, u64> = std::collections::HashMap::new();
        for (word, &cycles) in profile.iter().enumerate() {
            if cycles > 0 {
                let name = self
                    .symbol_at(word as u32 * 2)
                    .map_or("?".to_string(), demangle);
                *totals.entry(name).or_default() += cycles;
            }
        }
        let mut list: Vec<_> = totals.into_iter().collect();
        list.sort_by_key(|entry| std::cmp::Reverse(entry.1));
        list
    }

    /// The function holding a flash byte address, from the ELF symbols.
    pub fn symbol_at(&self, pc: u32) -> Option<&str> {
        self.elf
            .symbols
            .iter()
            .filter(|s| {
                s.size > 0
                    && s.value < crate::elf::DATA_OFFSET
                    && (s.value..s.value + s.size).contains(&pc)
            })
            .min_by_key(|s| s.size)
            .map(|s| s.name.as_str())
    }
}

impl Drop for Board {
    fn drop(&mut self) {
        // SAFETY: the instance is not used after this.
        unsafe { ffi::avr_terminate(self.avr) };
    }
}

/// A symbol as a Rust path without its hash.
pub fn demangle(symbol: &str) -> String {
    format!("{:#}", rustc_demangle::demangle(symbol))
}

/// (instantaneous peak, peak of the mean over `window` intervals), in Hz.
pub fn peak_rates(edges: &[StepEdge], window: usize) -> (f64, f64) {
    let rises: Vec<u64> = edges.iter().filter(|e| e.rising).map(|e| e.cycle).collect();
    let mut best = 0.0f64;
    for w in rises.windows(2) {
        if w[1] > w[0] {
            best = best.max(f64::from(CPU_HZ) / (w[1] - w[0]) as f64);
        }
    }
    let mut best_mean = 0.0f64;
    let window = window.max(1);
    if rises.len() > window {
        for i in window..rises.len() {
            let span = rises[i] - rises[i - window];
            if span > 0 {
                best_mean = best_mean.max(window as f64 * f64::from(CPU_HZ) / span as f64);
            }
        }
    }
    (best, best_mean)
}

/// Data-space address of PORTx.
fn port_register(port: u8) -> u16 {
    match port {
        b'A' => 0x22,
        b'B' => 0x25,
        b'C' => 0x28,
        b'D' => 0x2B,
        b'E' => 0x2E,
        b'F' => 0x31,
        b'G' => 0x34,
        b'H' => 0x102,
        b'J' => 0x105,
        b'K' => 0x108,
        b'L' => 0x10B,
        _ => panic!("the ATmega2560 has no port {}", port as char),
    }
}

unsafe fn port_irq(avr: *mut ffi::avr_t, p: Pin) -> *mut ffi::avr_irq_t {
    ffi::avr_io_getirq(avr, ioctl(b'i', b'o', b'g', p.port), i32::from(p.bit))
}

unsafe fn find_uart(avr: *mut ffi::avr_t, name: u8) -> *mut ffi::avr_uart_t {
    let mut io = (*avr).io_port;
    while !io.is_null() {
        let kind = std::ffi::CStr::from_ptr((*io).kind);
        if kind.to_bytes() == b"uart" {
            let uart = io as *mut ffi::avr_uart_t;
            if (*uart).name as u8 == name {
                return uart;
            }
        }
        io = (*io).next;
    }
    std::ptr::null_mut()
}

impl Shared {
    unsafe fn data(&self, addr: u16) -> u8 {
        *(*self.avr).data.add(usize::from(addr))
    }

    /// UART0's frame from its registers: start + data + parity + stop bits,
    /// each `8·(UBRR+1)` cycles with U2X0, `16·(UBRR+1)` without.
    unsafe fn fix_uart_frame(&mut self) {
        let ubrr = u64::from(self.data(UBRR0L)) | u64::from(self.data(UBRR0H) & 0x0F) << 8;
        let u2x = self.data(UCSR0A) & (1 << 1) != 0;
        let c = self.data(UCSR0C);
        let size = (c >> 1) & 0b11 | (self.data(UCSR0B) & (1 << 2));
        let data_bits = match size {
            0 => 5,
            1 => 6,
            2 => 7,
            7 => 9,
            _ => 8,
        };
        let parity = u64::from((c >> 4) & 0b11 != 0);
        let stop = 1 + u64::from(c & (1 << 3) != 0);
        let bit = (ubrr + 1) * if u2x { 8 } else { 16 };
        let frame = bit * (1 + data_bits + parity + stop);
        self.avr_frame_cycles = frame;
        (*self.uart0).cycles_per_byte = frame;
        self.host.set_min_frame(frame as f64);
    }

    /// A byte's start bit reaches the AVR now. simavr raises RXC one frame
    /// after a byte enters its (empty) input FIFO, i.e. at the stop bit.
    unsafe fn inject_rx(&mut self, byte: u8) {
        self.rx_log.push(((*self.avr).cycle, byte));
        if self.hardware_rx_fifo {
            let fifo = &(*self.uart0).input;
            let unread = fifo.write.wrapping_sub(fifo.read) & 63;
            // The real USART holds two received bytes plus the one in the
            // shift register; a fourth start bit with two unread means the
            // byte in the shift register is lost (DOR0).
            if unread >= 3 {
                self.rx_overruns += 1;
                self.rx_overrun_cycles.push((*self.avr).cycle);
                *(*self.avr).data.add(usize::from(UCSR0A)) |= DOR0;
                return;
            }
        }
        ffi::avr_raise_irq(self.uart_input_irq, u32::from(byte));
    }

    /// X's or Y's carriage stepped: an Index pulse when it entered another
    /// pole pair (the chip's Index fires at count 0 of each).
    unsafe fn index_on_step(&mut self, axis: usize, position: i64) {
        let now = (*self.avr).cycle;
        let Some(nse) = self.nse.as_mut() else { return };
        if axis >= 2 || nse.jammed_at[axis].is_some() {
            return;
        }
        let pole = (nse.carriage_counts(axis, position, now) / 4096.0).floor() as i64;
        if pole != nse.pole[axis] {
            nse.pole[axis] = pole;
            self.pulse_index(axis);
        }
    }

    /// Raise chip `chip`'s Index output for `INDEX_PULSE_CYCLES`.
    unsafe fn pulse_index(&mut self, chip: usize) {
        let now = (*self.avr).cycle;
        let Some(nse) = self.nse.as_mut() else { return };
        nse.index_pulses[chip] += 1;
        ffi::avr_raise_irq(nse.index_irqs[chip], 1);
        nse.index_high_until[chip] = Some(now + INDEX_PULSE_CYCLES);
        let param = self as *mut Shared as *mut c_void;
        ffi::avr_cycle_timer_register(self.avr, INDEX_PULSE_CYCLES, Some(on_index_pulse_end), param);
    }

    unsafe fn update_endstops(&mut self, force: bool) {
        let mut per_port: Vec<(u8, u8, u8)> = Vec::new();
        for (i, p) in ENDSTOP_PINS.iter().enumerate() {
            let level = match self.endstops[i] {
                None => true,
                Some(e) => {
                    let pos = self.axes[e.axis].position;
                    let pressed = if e.is_min {
                        pos <= e.at_steps
                    } else {
                        pos >= e.at_steps
                    };
                    if pressed {
                        e.pressed_level
                    } else {
                        !e.pressed_level
                    }
                }
            };
            if force || level != self.endstop_levels[i] {
                self.endstop_levels[i] = level;
                ffi::avr_raise_irq(self.endstop_irqs[i], u32::from(level));
            }
            match per_port.iter_mut().find(|(port, _, _)| *port == p.port) {
                Some(entry) => {
                    entry.1 |= 1 << p.bit;
                    entry.2 |= u8::from(level) << p.bit;
                }
                None => per_port.push((p.port, 1 << p.bit, u8::from(level) << p.bit)),
            }
        }
        // The other driven inputs share the ports' external state (a
        // released one leaves its port's mask, back to its pull-up).
        for &(p, _, level) in &self.driven {
            let (mask, value) = match level {
                Some(level) => (1 << p.bit, u8::from(level) << p.bit),
                None => (0, 0),
            };
            match per_port.iter_mut().find(|(port, _, _)| *port == p.port) {
                Some(entry) => {
                    entry.1 |= mask;
                    entry.2 |= value;
                }
                None => per_port.push((p.port, mask, value)),
            }
        }
        // Keep the levels when the firmware rewrites PORTx: simavr re-raises
        // the pull-up level of every input pin on each PORT/DDR write
        // unless the port has an "external" state for it.
        for (port, mask, value) in per_port {
            let mut external: ffi::avr_ioport_external_t = std::mem::zeroed();
            external.set_name(u64::from(port) as _);
            external.set_mask(u64::from(mask) as _);
            external.set_value(u64::from(value) as _);
            ffi::avr_ioctl(
                self.avr,
                ioctl(b'i', b'o', b'p', port),
                &mut external as *mut _ as *mut c_void,
            );
        }
    }

    unsafe fn update_adc_inputs(&mut self) {
        for s in &mut self.sensors {
            let counts = match s.config.input {
                SensorInput::Plant => s.config.thermistor.adc_counts(s.config.plant.temperature_c),
                SensorInput::Fixed(c) => c.min(1023),
            };
            if counts != s.counts || counts == 0 {
                s.counts = counts;
                // simavr converts `mV·1023/AVcc` (floor): the smallest mV
                // that floors to `counts` presents exactly `counts`.
                let mv = (u32::from(counts) * 5000).div_ceil(1023);
                ffi::avr_raise_irq(s.irq, mv);
            }
        }
    }

    unsafe fn plant_tick(&mut self, now: u64) {
        let dt = self.plant_period_cycles as f64 / f64::from(CPU_HZ);
        let mut duties = Vec::with_capacity(self.meters.len());
        for (_, _, meter) in &mut self.meters {
            meter.close(now);
            duties.push(meter.high_in_tick as f64 / self.plant_period_cycles as f64);
            meter.high_in_tick = 0;
        }
        for s in &mut self.sensors {
            let duty = s.meter.map_or(0.0, |m| duties[m]);
            s.config.plant.step(duty, dt);
        }
        self.update_adc_inputs();
        if now >= self.next_sample {
            self.next_sample += self.sample_period_cycles;
            let period = self.sample_period_cycles as f64;
            let mut sample_duty: Vec<f64> = self
                .meters
                .iter()
                .map(|(_, _, m)| m.high_in_sample as f64 / period)
                .collect();
            for (_, _, m) in &mut self.meters {
                m.high_in_sample = 0;
            }
            let fan_duty = sample_duty.pop().unwrap_or(0.0);
            self.samples.push(ThermalSample {
                time_s: now as f64 / f64::from(CPU_HZ),
                duty: self
                    .sensors
                    .iter()
                    .map(|s| s.meter.map_or(0.0, |m| sample_duty[m]))
                    .collect(),
                celsius: self
                    .sensors
                    .iter()
                    .map(|s| s.config.plant.temperature_c)
                    .collect(),
                adc: self.sensors.iter().map(|s| s.counts).collect(),
                fan_duty,
            });
        }
    }
}

/// Takes simavr's log lines and drops them (the `va_list` is never read,
/// so its ABI does not matter).
unsafe extern "C" fn quiet_logger(
    _avr: *mut ffi::avr_t,
    _level: std::os::raw::c_int,
    _format: *const std::os::raw::c_char,
    _args: *mut c_void,
) {
}

unsafe extern "C" fn no_sleep(_avr: *mut ffi::avr_t, _how_long: ffi::avr_cycle_count_t) {}

unsafe extern "C" fn on_uart_output(_irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    let shared = &mut *(param as *mut Shared);
    let cycle = (*shared.avr).cycle;
    let frame = shared.avr_frame_cycles;
    shared
        .tx_log
        .push((cycle, value as u8, shared.stats.isr_cycles));
    shared.host.on_firmware_byte(cycle, value as u8, frame);
}

unsafe extern "C" fn on_uart_config_write(
    avr: *mut ffi::avr_t,
    addr: ffi::avr_io_addr_t,
    v: u8,
    param: *mut c_void,
) {
    let shared = &mut *(param as *mut Shared);
    let original = shared
        .uart_handlers
        .iter()
        .find(|(a, _, _)| *a == addr)
        .map(|(_, c, p)| (*c, *p));
    match original {
        Some((Some(write), p)) => write(avr, addr, v, p),
        _ => ffi::avr_core_watch_write(avr, addr, v),
    }
    shared.fix_uart_frame();
}

unsafe extern "C" fn on_axis_pin(irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    let shared = &mut *(param as *mut Shared);
    let level = value & 1 != 0;
    let now = (*shared.avr).cycle;
    let Some(&(_, axis, is_step)) = shared.axis_of_pin.iter().find(|(i, _, _)| *i == irq) else {
        return;
    };
    let positive_high = shared.dir_high_is_positive[axis];
    let isr = shared.stats.isr_cycles;
    let data = (*shared.avr).data;
    let state = &mut shared.axes[axis];
    if !is_step {
        if level != state.dir_level {
            state.dir_level = level;
            state.dir_changed_at = Some(now);
        }
        return;
    }
    if level == state.step_level {
        return;
    }
    state.step_level = level;
    if level {
        // simavr notifies the bits of one PORT write in bit order, so a DIR
        // written together with STEP may not have been seen yet: DIR is
        // taken from the port register. A STEP less than 200 ns (4 cycles)
        // after a DIR change violates the drivers' set-up time (A4988,
        // DRV8825) and is counted.
        let (port, bit) = state.dir_port;
        let dir_now = *data.add(usize::from(port)) >> bit & 1 != 0;
        if dir_now != state.dir_level {
            state.dir_level = dir_now;
            state.dir_changed_at = Some(now);
        }
        if state.dir_changed_at.is_some_and(|t| now - t < 4) {
            state.dir_setup_violations += 1;
        }
    }
    state.edges.push(StepEdge {
        cycle: now,
        rising: level,
        dir: state.dir_level,
        isr_cycles: isr,
    });
    if level {
        state.rising_edges += 1;
        state.position += if state.dir_level == positive_high {
            1
        } else {
            -1
        };
        state.last_rise = now;
        let position = state.position;
        shared.update_endstops(false);
        shared.index_on_step(axis, position);
    } else {
        let high = now.saturating_sub(state.last_rise);
        state.min_high_cycles = Some(state.min_high_cycles.map_or(high, |m| m.min(high)));
    }
}

/// simavr lets every PORTx write set the pin's IRQ, even while a timer's
/// compare unit owns the pin (on the chip COMnx ≠ 0 overrides PORTx). The
/// firmware rewrites PORTH/PORTB in its main loop, so the level is taken
/// from the timer's edges (flagged AVR_IOPORT_OUTPUT) while the compare
/// unit is connected, and from port writes while it is not.
/// A 16×2 HD44780 in 4-bit mode, as far as the firmware uses it: nibbles
/// latched on E's falling edge (RS = PH1, D4–D7 = PA1/PA3/PA5/PA7),
/// the set-DDRAM-address and clear commands, and characters.
#[derive(Clone, Debug)]
pub struct Lcd {
    ddram: [u8; 128],
    address: u8,
    /// The high nibble of a byte in transfer, and its RS level.
    high: Option<(u8, bool)>,
    /// 8-bit mode until the function-set nibble 0x2 (power-on sequence).
    four_bit: bool,
    pub characters: u64,
}

impl Default for Lcd {
    fn default() -> Self {
        Self { ddram: [b' '; 128], address: 0, high: None, four_bit: false, characters: 0 }
    }
}

impl Lcd {
    fn latch(&mut self, nibble: u8, rs: bool) {
        if !self.four_bit {
            // Power-on: single nibbles 0x3, 0x3, 0x3, then 0x2 (4-bit).
            if nibble == 0x2 {
                self.four_bit = true;
            }
            return;
        }
        let Some((high, high_rs)) = self.high.take() else {
            self.high = Some((nibble, rs));
            return;
        };
        let byte = high << 4 | nibble;
        if high_rs {
            self.ddram[usize::from(self.address & 0x7F)] = byte;
            self.address = self.address.wrapping_add(1) & 0x7F;
            self.characters += 1;
        } else if byte & 0x80 != 0 {
            self.address = byte & 0x7F;
        } else if byte == 0x01 {
            self.ddram = [b' '; 128];
            self.address = 0;
        }
    }

    /// The two visible rows (DDRAM 0x00 and 0x40, 16 characters each).
    pub fn rows(&self) -> [String; 2] {
        [0x00usize, 0x40].map(|start| String::from_utf8_lossy(&self.ddram[start..start + 16]).into_owned())
    }
}

unsafe extern "C" fn on_lcd_enable(_irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    let shared = &mut *(param as *mut Shared);
    if value & 1 != 0 {
        return;
    }
    // PORTA (0x22) and PORTH (0x102) as the firmware last wrote them.
    let data = *(*shared.avr).data.add(0x22);
    let control = *(*shared.avr).data.add(0x102);
    let nibble = (data >> 1 & 1) | (data >> 3 & 1) << 1 | (data >> 5 & 1) << 2 | (data >> 7 & 1) << 3;
    shared.lcd.latch(nibble, control & 0b10 != 0);
}

unsafe extern "C" fn on_meter_pin(irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    const AVR_IOPORT_OUTPUT: u32 = 0x100;
    let shared = &mut *(param as *mut Shared);
    let now = (*shared.avr).cycle;
    let from_timer = value & AVR_IOPORT_OUTPUT != 0;
    for (i, (_, pin_irq, meter)) in shared.meters.iter_mut().enumerate() {
        if *pin_irq == irq {
            let (tccr, shift) = shared.meter_compare[i];
            let connected = (*(*shared.avr).data.add(usize::from(tccr)) >> shift) & 0b11 != 0;
            if connected == from_timer && meter.edge(now, value & 1 != 0) {
                // Meter 1 is the bed (hot end, bed, fan: the order above).
                if let (Some(edges), 1) = (shared.bed_edges.as_mut(), i) {
                    edges.push((now, value & 1 != 0));
                }
            }
        }
    }
}

unsafe extern "C" fn on_plant_tick(
    _avr: *mut ffi::avr_t,
    when: ffi::avr_cycle_count_t,
    param: *mut c_void,
) -> ffi::avr_cycle_count_t {
    let shared = &mut *(param as *mut Shared);
    shared.plant_tick(when);
    when + shared.plant_period_cycles
}

/// The TWI master's side of a transfer (simavr raises its output IRQ with
/// a message: condition bits, the address byte, data); a chip answers by
/// raising the TWI input IRQ at once, as simavr's own I²C devices do.
unsafe extern "C" fn on_twi_output(_irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    const START: u32 = 1 << 0;
    const STOP: u32 = 1 << 1;
    const ACK: u32 = 1 << 3;
    const READ: u32 = 1 << 5;
    let shared = &mut *(param as *mut Shared);
    let positions = [shared.axes[0].position, shared.axes[1].position];
    let now = (*shared.avr).cycle;
    let Some(nse) = shared.nse.as_mut() else { return };
    // avr_twi_msg_t: unused (bits 0-7), msg, addr, data.
    let msg = (value >> 8) & 0xFF;
    let addr = ((value >> 16) & 0xFF) as u8;
    let reply = |msg: u32, addr: u8, data: u8| msg << 8 | u32::from(addr) << 16 | u32::from(data) << 24;
    if msg & START != 0 {
        nse.selected = nse.addresses.iter().position(|a| *a == addr >> 1).filter(|i| nse.answering[*i] && addr & 1 == 1);
        nse.byte = 0;
        if nse.selected.is_some() {
            ffi::avr_raise_irq(nse.twi_input, reply(ACK, addr, 1));
        }
        return;
    }
    if msg & STOP != 0 {
        nse.selected = None;
        return;
    }
    if msg & READ != 0 {
        let Some(chip) = nse.selected else { return };
        let carriage = nse.carriage_counts(chip, positions[chip], now);
        let counts = (carriage.round() as i64).rem_euclid(4096) as u16;
        let data = if nse.byte == 0 { (counts >> 4) as u8 } else { ((counts & 0xF) << 4) as u8 | 0x08 };
        nse.byte = nse.byte.saturating_add(1);
        if nse.byte == 2 {
            nse.reads[chip] += 1;
        }
        ffi::avr_raise_irq(nse.twi_input, reply(READ, addr, data));
    }
}


/// Index pulses end: lower the outputs whose time is up.
unsafe extern "C" fn on_index_pulse_end(avr: *mut ffi::avr_t, when: ffi::avr_cycle_count_t, param: *mut c_void) -> ffi::avr_cycle_count_t {
    let shared = &mut *(param as *mut Shared);
    let _ = avr;
    if let Some(nse) = shared.nse.as_mut() {
        for chip in 0..2 {
            if nse.index_high_until[chip].is_some_and(|until| until <= when) {
                nse.index_high_until[chip] = None;
                ffi::avr_raise_irq(nse.index_irqs[chip], 0);
            }
        }
        // A pulse still high (started later) needs another look.
        if let Some(next) = nse.index_high_until.iter().flatten().min() {
            return *next;
        }
    }
    0
}
