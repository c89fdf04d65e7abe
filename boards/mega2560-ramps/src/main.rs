//! Firmware for an Arduino Mega 2560 with a RAMPS 1.4 shield.
//!
//! This crate is the board: pins, clocks, interrupt vectors and the main
//! loop. Every decision is made by the `firmware` core; the interrupt
//! handlers here only move bytes and ticks into it.
//!
//! Boot order matters for safety: heaters off and drivers disabled before
//! anything else, then the watchdog, then the peripherals.
#![no_std]
#![no_main]
#![feature(abi_avr_interrupt)]
#![feature(asm_experimental_arch)]
#![deny(unsafe_op_in_unsafe_fn)]

mod adc;
#[cfg(feature = "machine-powder-bed")]
mod bed;
mod clock;
#[cfg(feature = "display-hd44780")]
mod display;
mod eeprom;
// Documentation only: every handler's priority, nesting and longest path.
mod interrupts;
#[cfg(feature = "encoders")]
mod encoders;
#[cfg(feature = "machine-extrusion-line")]
mod line;
mod pins;
mod pwm;
mod serial;
#[cfg(any(feature = "bed-ssr", feature = "machine-extrusion-line"))]
mod ssr;
mod stepping;
mod watchdog;

use avr_device::atmega2560::Peripherals;
use firmware::host_link::HostLink;
use firmware::machine::Machine;
use firmware::motion::MotionConfig;
#[cfg(feature = "motion")]
use firmware::motion::StepperRequest;
use firmware::rx::{self, RxQueue};

/// How often the thermistors are read, in milliseconds.
const THERMAL_PERIOD_MS: u32 = 100;

static mut RX_QUEUE: RxQueue = RxQueue::new();

/// The machine and its host link live here, not on main's stack.
static mut LINK: core::mem::MaybeUninit<HostLink<'static>> = core::mem::MaybeUninit::uninit();

#[avr_device::entry]
fn main() -> ! {
    // SAFETY: the only call to steal(); `take()` would cost a flag in RAM.
    let dp = unsafe { Peripherals::steal() };
    pins::all_outputs_safe(&dp);
    watchdog::start(&dp);

    let mut tx = serial::Tx;
    let (link, mut rx) = boot(&dp, &mut tx);
    // SAFETY: the EEPROM registers are used by this driver only.
    let mut eeprom = eeprom::Eeprom::new(unsafe { Peripherals::steal() }.EEPROM);
    let _ = link.machine.load_settings(&mut eeprom, &mut tx);
    #[cfg(feature = "encoders")]
    {
        let settings = link.machine.settings();
        let axis = |i: usize| (settings.steps_per_mm_milli[i] as f32 / 1000.0, (settings.max_feed_um_per_s[i] / 1000) as u16);
        let (x, y) = (axis(0), axis(1));
        encoders::init(&dp, [x.0, y.0], [x.1, y.1]);
    }
    let mut next_thermal_ms = 0u32;
    // Hot end and bed thermistors, averaged in the ADC interrupt.
    #[cfg(feature = "heaters")]
    let mut readings = adc::Readings::new();
    #[cfg(feature = "display-hd44780")]
    let (mut lcd, mut next_screen_ms) = (display::init(), 0u32);
    let mut outputs = Outputs::default();
    // The safety inputs at the last pass (the arm).
    #[cfg(feature = "machine-arm")]
    let mut safety_was = 0u8;
    #[cfg(feature = "machine-powder-bed")]
    let mut last_bed_ms = 0u32;
    #[cfg(feature = "encoders")]
    let mut last_encoder_ms = 0u32;

    // The loop never sleeps: QEMU's AVR machine does not wake from `sleep`
    // on its timer interrupt and avr-tester stops at the first `sleep`, and
    // a printer board has no battery to save.
    loop {
        watchdog::feed();
        let now = clock::millis();
        // The printers' motion: planner, segments, homing (the extrusion
        // line and the powder bed drive their motors themselves).
        #[cfg(feature = "motion")]
        match link.machine.poll_motion(&stepping::status(), now, &mut tx) {
            Ok(StepperRequest::ClearFault) => stepping::clear_fault(),
            Ok(StepperRequest::Halt) => stepping::halt(),
            Ok(StepperRequest::Configure(config)) => stepping::configure(config),
            _ => {}
        }
        // SPEC §3: a driver that lost sync stops the job.
        #[cfg(feature = "machine-arm")]
        let _ = link.machine.on_driver_alarms(pins::driver_alarms(&dp), &mut tx);
        // SPEC §3: the light curtain's relay and the e-stop stop every
        // motor; re-arm, then G28. A new trip halts the step interrupt
        // here, in this pass, not at the core's next motion poll.
        #[cfg(feature = "machine-arm")]
        {
            let safety = pins::safety_inputs(&dp);
            if safety & !safety_was & pins::SAFETY_TRIPS != 0 {
                stepping::halt();
            }
            safety_was = safety;
            let _ = link.machine.on_safety_inputs(safety, &mut tx);
        }
        let _ = link.service(&mut rx, &mut eeprom, now, &mut tx);
        // SPEC §1: the encoder loops' settings, faults and reports, once a
        // millisecond: each look masks the 1 kHz tick that runs the loops,
        // and masking it on every (short) pass delayed ticks past the next.
        #[cfg(feature = "encoders")]
        if now != last_encoder_ms {
            last_encoder_ms = now;
            let _ = encoders::service(&dp, &mut link.machine, now.wrapping_sub(next_thermal_ms) < u32::MAX / 2, &mut tx);
        }
        // The powder bed's millisecond: read, decide, drive.
        #[cfg(feature = "machine-powder-bed")]
        if now != last_bed_ms {
            last_bed_ms = now;
            let inputs = bed::read(&dp);
            let Ok(decided) = link.machine.powder_bed_tick(&inputs, &mut tx);
            bed::drive(&dp, &decided, now);
        }
        #[cfg(feature = "machine-extrusion-line")]
        {
            let Ok(timers) = link.machine.poll_line(now, &mut tx);
            line::apply(&dp, timers, link.machine.extrusion_line());
        }
        if now.wrapping_sub(next_thermal_ms) < u32::MAX / 2 {
            next_thermal_ms = now.wrapping_add(THERMAL_PERIOD_MS);
            #[cfg(feature = "heaters")]
            {
                let [hotend, bed] = readings.take();
                // A machine without a bed (its file has none) has no bed
                // thermistor to judge: the input would read open.
                let bed = if pins::BED.is_some() { bed } else { None };
                let _ = link.machine.on_thermal_samples(hotend, bed, &mut tx);
            }
            link.machine.set_endstop_levels(pins::endstop_levels(&dp));
        }
        #[cfg(feature = "display-hd44780")]
        if now.wrapping_sub(next_screen_ms) < u32::MAX / 2 {
            next_screen_ms = now.wrapping_add(display::REFRESH_MS);
            let _ = lcd.show(&link.machine.status_screen(), &mut display::BusyDelay);
        }
        apply_outputs(&dp, &link.machine, &mut outputs);
    }
}

/// Peripherals, interrupts and the machine, built in place in `LINK`; the
/// banner. Not inlined: the temporaries of the construction (the machine
/// configuration, the planner ring's initial value) live in this frame,
/// which is gone before the main loop starts, and main's own frame stays
/// small enough for short `Y+q` addressing.
#[inline(never)]
fn boot(dp: &Peripherals, tx: &mut serial::Tx) -> (&'static mut HostLink<'static>, serial::Rx) {
    // SAFETY: the queue is split exactly once, here, before interrupts are
    // enabled; afterwards only its two ends are used.
    let queue = unsafe { &mut *core::ptr::addr_of_mut!(RX_QUEUE) };
    let (producer, consumer) = rx::split(queue);
    serial::init(dp, producer);
    let config = machine_config();
    let feeder = stepping::init(dp, config.stepper());
    clock::init(dp);
    adc::init(dp);
    pwm::init(dp);
    // SAFETY: everything the interrupts touch is initialised.
    unsafe { avr_device::interrupt::enable() };
    // SAFETY: called once, from main, before anything else uses `LINK`.
    let link = HostLink::init_in(unsafe { &mut *core::ptr::addr_of_mut!(LINK) }, config, feeder);
    #[cfg(feature = "machine-extrusion-line")]
    {
        link.machine.become_extrusion_line();
        line::init(dp);
    }
    #[cfg(feature = "machine-powder-bed")]
    {
        link.machine.become_powder_bed();
        bed::init(dp);
    }
    // The machine file's heaters, gains and endstop polarity (after the
    // machines' own set-up above, which it refines).
    link.machine.use_machine_file();
    pins::init_endstops(dp);
    #[cfg(feature = "machine-arm")]
    for input in pins::DRIVER_ALARMS.into_iter().chain([pins::SAFETY_RELAY, pins::EMERGENCY_STOP, pins::REARM]) {
        pins::make_input_pulled_up(dp, input);
    }
    let _ = link.machine.write_banner(tx);
    (link, serial::Rx { consumer })
}

/// The machine file's motion configuration, kept in flash (it is
/// `const`) and copied out once at boot: building it in code costs 2 KB of
/// stores.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
static MOTION: firmware::progmem::Flash<MotionConfig> = firmware::progmem::Flash::new(firmware::machine_file::MOTION);

/// The machine this firmware is built for (its machine file). Out of
/// line: the configuration is built in the caller's slot through a
/// pointer. A delta's tower positions (sines and cosines) are computed
/// here, at boot.
#[inline(never)]
fn machine_config() -> MotionConfig {
    #[cfg(feature = "machine-delta")]
    {
        let mut config = MOTION.load();
        config.place_towers();
        config
    }
    #[cfg(not(feature = "machine-delta"))]
    MOTION.load()
}

/// What the outputs were last set to (`None`: not yet), so that the main
/// loop writes a pin only when its value changes: each write holds the
/// step interrupt off for a moment.
#[derive(Default)]
#[cfg_attr(any(feature = "machine-extrusion-line", feature = "machine-powder-bed"), allow(dead_code))]
struct Outputs {
    drivers_enabled: Option<bool>,
    fan_duty: Option<u8>,
    heater_duties: Option<(u8, u8)>,
}

/// Drive the outputs the core decides: all off once halted.
fn apply_outputs(dp: &Peripherals, machine: &Machine, last: &mut Outputs) {
    if machine.is_halted() {
        stepping::halt();
        #[cfg(any(feature = "bed-ssr", feature = "machine-extrusion-line"))]
        ssr::stop();
        #[cfg(feature = "machine-extrusion-line")]
        line::stop(dp);
        #[cfg(feature = "machine-powder-bed")]
        bed::stop(dp);
        pins::all_outputs_safe(dp);
        *last = Outputs { drivers_enabled: Some(false), fan_duty: Some(0), heater_duties: Some((0, 0)) };
        return;
    }
    // The line's and the powder bed's drivers are their own (line.rs, bed.rs).
    #[cfg(not(any(feature = "machine-extrusion-line", feature = "machine-powder-bed")))]
    {
        let enabled = machine.steppers_enabled();
        if last.drivers_enabled != Some(enabled) {
            pins::set_steppers_enabled(dp, enabled);
            last.drivers_enabled = Some(enabled);
        }
    }
    let fan = machine.fan_duty();
    if last.fan_duty != Some(fan) {
        // On the machine file's fan pin (the extrusion line's fans are on
        // D8: its D9 is the barrel's relay).
        pwm::set(dp, pwm::Output::Fan, fan);
        last.fan_duty = Some(fan);
    }
    // The powder bed has no heaters: D10 and D8 are its roller and suction.
    #[cfg(not(feature = "machine-powder-bed"))]
    let heaters = machine.heater_duties();
    #[cfg(not(feature = "machine-powder-bed"))]
    if last.heater_duties != Some(heaters) {
        #[cfg(not(feature = "machine-extrusion-line"))]
        pwm::set(dp, pwm::Output::Hotend, heaters.0);
        #[cfg(not(any(feature = "bed-ssr", feature = "machine-extrusion-line")))]
        pwm::set(dp, pwm::Output::Bed, heaters.1);
        #[cfg(feature = "bed-ssr")]
        ssr::set_duty(heaters.1);
        // The barrel is heater 0, behind its SSR on D9.
        #[cfg(feature = "machine-extrusion-line")]
        ssr::set_duty(heaters.0);
        last.heater_duties = Some(heaters);
    }
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    avr_device::interrupt::disable();
    // SAFETY: interrupts are off; nothing else runs from here on.
    let dp = unsafe { Peripherals::steal() };
    stepping::stop_timer(&dp);
    #[cfg(feature = "machine-extrusion-line")]
    line::stop(&dp);
    #[cfg(feature = "machine-powder-bed")]
    bed::stop(&dp);
    pins::all_outputs_safe(&dp);
    watchdog::stop(&dp);
    let mut tx = serial::Tx;
    let _ = ufmt::uwrite!(tx, "Error:Firmware panic: heaters off, motors disabled. Reset the board.\n");
    loop {
        avr_device::asm::sleep();
    }
}
