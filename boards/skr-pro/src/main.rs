//! Firmware for a BigTreeTech SKR Pro 1.2 (STM32F407ZGT6).
//!
//! This crate's binary is the board's vector table and main loop; the
//! board support is in the library next to it (`src/lib.rs`), and every
//! decision is made by the `firmware` core, exactly as on the Mega 2560.
//!
//! Boot order matters for safety: heaters off and drivers disabled before
//! anything else, then the watchdog, then the clocks and peripherals.
#![no_std]
#![no_main]
#![deny(unsafe_op_in_unsafe_fn)]

use core::cell::UnsafeCell;
use cortex_m_rt::{entry, exception};
use firmware::host_link::HostLink;
use firmware::machine::Machine;
use firmware::motion::{Motion, MotionConfig, StepperRequest};
use firmware::rx::{self, RxQueue};
use skr_pro::pac::{self, interrupt, Interrupt};
use skr_pro::{adc, clock, pins, priority, pwm, serial, stepper, storage, watchdog};

/// How often the thermistors and endstops are read, in milliseconds.
const THERMAL_PERIOD_MS: u32 = 100;

struct RxCell(UnsafeCell<RxQueue>);
// SAFETY: split exactly once in `main`, before interrupts are enabled.
unsafe impl Sync for RxCell {}
static RX_QUEUE: RxCell = RxCell(UnsafeCell::new(RxQueue::new()));

#[entry]
fn main() -> ! {
    pins::init();
    // SAFETY: the only call; `take()` would cost a flag and a panic path.
    let dp = unsafe { pac::Peripherals::steal() };
    // SAFETY: as above, for the core peripherals.
    let mut cp = unsafe { cortex_m::Peripherals::steal() };
    watchdog::start(&dp.IWDG);
    let clocks = clock::init(&dp.RCC, &dp.FLASH);

    // SAFETY: split exactly once, here, before interrupts are enabled;
    // afterwards only its two ends are used.
    let (producer, consumer) = rx::split(unsafe { &mut *RX_QUEUE.0.get() });
    serial::init(&dp.RCC, &dp.USART1, &clocks, producer);
    adc::init(&dp.RCC, &dp.ADC_COMMON, &dp.ADC3);
    pwm::init(&dp.RCC, &dp.TIM3, &dp.TIM4);
    let config = MotionConfig::prusa_i3();
    let feeder = stepper::init(&dp.RCC, &dp.TIM5, &clocks, config.stepper());
    // SAFETY: priorities are set before the lines are unmasked; everything
    // the handlers touch is initialised.
    unsafe {
        cp.SCB.set_priority(cortex_m::peripheral::scb::SystemHandler::SysTick, priority::TICK);
        cp.NVIC.set_priority(Interrupt::TIM5, priority::STEP_TIMER);
        cp.NVIC.set_priority(Interrupt::USART1, priority::SERIAL);
        cortex_m::peripheral::NVIC::unmask(Interrupt::TIM5);
        cortex_m::peripheral::NVIC::unmask(Interrupt::USART1);
    }
    clock::start_tick(&mut cp.SYST, &clocks);

    let mut tx = serial::Tx;
    let mut rx = serial::Rx { consumer };
    let mut link = HostLink::new(Machine::new(Motion::new(config, feeder)));
    let mut settings = storage::open();
    let _ = link.machine.write_banner(&mut tx);
    let _ = link.machine.load_settings(&mut settings, &mut tx);
    let mut next_thermal_ms = 0u32;

    loop {
        watchdog::feed();
        let now = clock::millis();
        match link.machine.poll_motion(&stepper::status(), now, &mut tx) {
            Ok(StepperRequest::ClearFault) => stepper::clear_fault(),
            Ok(StepperRequest::Halt) => stepper::halt(),
            Ok(StepperRequest::Configure(config)) => stepper::configure(config),
            _ => {}
        }
        let _ = link.service(&mut rx, &mut settings, now, &mut tx);
        if now.wrapping_sub(next_thermal_ms) < u32::MAX / 2 {
            next_thermal_ms = now.wrapping_add(THERMAL_PERIOD_MS);
            let hotend = adc::oversampled(&dp.ADC3, pins::HOTEND_THERMISTOR_CHANNEL);
            let bed = adc::oversampled(&dp.ADC3, pins::BED_THERMISTOR_CHANNEL);
            let _ = link.machine.on_thermal_samples(Some(hotend), Some(bed), &mut tx);
            link.machine.set_endstop_levels(pins::endstop_levels());
        }
        apply_outputs(&link.machine);
    }
}

/// Drive the outputs the core decides: all off once halted.
fn apply_outputs(machine: &Machine) {
    if machine.is_halted() {
        stepper::halt();
        pins::all_outputs_safe();
        return;
    }
    pins::set_steppers_enabled(machine.steppers_enabled());
    pwm::set_fan(machine.fan_duty());
    let (hotend, bed) = machine.heater_duties();
    pwm::set_hotend(hotend);
    pwm::set_bed(bed);
}

#[interrupt]
fn USART1() {
    serial::on_interrupt();
}

#[interrupt]
fn TIM5() {
    stepper::on_interrupt();
}

#[exception]
fn SysTick() {
    clock::on_tick();
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    pins::all_outputs_safe();
    let mut tx = serial::Tx;
    let _ = ufmt::uwrite!(tx, "Error:Firmware panic: heaters off, motors disabled. Reset the board.\n");
    loop {
        // The IWDG cannot be stopped: keep it fed so the board stays in
        // this safe state (as the Mega 2560 does) instead of rebooting.
        watchdog::feed();
        pins::all_outputs_safe();
    }
}
