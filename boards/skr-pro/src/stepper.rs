//! The step timer: TIM5 (32 bit) in output-compare mode, counting at the
//! core's [`TIMER_HZ`] (2 MHz: APB1's 84 MHz timer clock / 42), with the
//! core's [`StepGenerator`] in its compare interrupt.
//!
//! Each interrupt: lower the STEP pins raised last time, let the core say
//! what to do, write the DIR pins if they change, raise the STEP pins
//! (one BSRR store: X, Y, Z and E0 step on port E), and move the compare
//! forward by the core's interval. The compare value advances from the
//! previous compare time, never from "now", so interrupt latency does not
//! accumulate into the step times. If an interrupt ran so late that the
//! counter has already passed the next compare time, the compare event is
//! forced at once (otherwise it would only match after the counter
//! wrapped, 35 minutes later).
//!
//! STEP pulse: high from one interrupt to the start of the next, so its
//! width is the step interval (≥ 0.5 µs at 2 MHz) less the interrupt
//! entry; low for at least the core's `on_timer` time between a lowering
//! and the next raise (≈ 0.3 µs here). Both suit TMC22xx/A4988/DRV8825 up
//! to ≈ 500 k steps/s per motor.
//!
//! QEMU's netduinoplus2 models TIM2–5 but no compare interrupts: there the
//! generator never runs, so moves queue up and never finish (the QEMU
//! tests send no moves).

use core::cell::UnsafeCell;
use firmware::motion::stepper::{
    StepFault, StepFeeder, StepGenerator, StepQueues, StepperConfig, StepperStatus, IDLE_POLL_TICKS, TIMER_HZ,
};
use stm32f4::stm32f407 as pac;

use crate::clock::Clocks;
use crate::pins;

/// RCC_APB1ENR: TIM5EN.
const TIM5EN: u32 = 1 << 3;
// TIMx_SR / DIER / EGR: capture-compare 1 bits.
const CC1IF: u32 = 1 << 1;
const CC1IE: u32 = 1 << 1;
const CC1G: u32 = 1 << 1;
const UG: u32 = 1 << 0;
const CEN: u32 = 1 << 0;

/// Everything the step interrupt owns.
struct StepState {
    generator: Option<StepGenerator<'static>>,
    /// DIR pin levels now on the pins (bit i: motor i).
    dir_levels: u8,
    /// The compare time the timer was last armed for.
    next_compare: u32,
}

struct StepCell(UnsafeCell<StepState>);
// SAFETY: written by `init` before the TIM5 interrupt is enabled; afterwards
// only that interrupt (which cannot preempt itself) uses it.
unsafe impl Sync for StepCell {}
static STATE: StepCell = StepCell(UnsafeCell::new(StepState { generator: None, dir_levels: 0, next_compare: 0 }));

struct QueueCell(UnsafeCell<StepQueues>);
// SAFETY: split once in `init`; the halves are lock-free SPSC ends.
unsafe impl Sync for QueueCell {}
static QUEUES: QueueCell = QueueCell(UnsafeCell::new(StepQueues::new()));

/// Set the timer up and hand the generator to the interrupt; returns the
/// main loop's end of the queues. Call once, before unmasking TIM5.
pub fn init(rcc: &pac::RCC, timer: &pac::TIM5, clocks: &Clocks, config: StepperConfig) -> StepFeeder<'static> {
    // SAFETY: called once, before the interrupt that uses STATE is enabled.
    let (feeder, generator) = unsafe { (*QUEUES.0.get()).split(config) };
    // SAFETY: as above.
    let state = unsafe { &mut *STATE.0.get() };
    state.generator = Some(generator);
    state.next_compare = u32::from(IDLE_POLL_TICKS);

    // SAFETY (all `bits`): documented field values.
    rcc.apb1enr().modify(|r, w| unsafe { w.bits(r.bits() | TIM5EN) });
    cortex_m::asm::dsb();
    timer.psc().write(|w| unsafe { w.bits(clocks.apb1_timer_hz / TIMER_HZ - 1) });
    timer.arr().write(|w| unsafe { w.bits(u32::MAX) });
    timer.ccmr1_output().write(|w| unsafe { w.bits(0) }); // frozen: compare only
    timer.ccr1().write(|w| unsafe { w.bits(state.next_compare) });
    timer.egr().write(|w| unsafe { w.bits(UG) }); // load the prescaler, count from 0
    timer.sr().write(|w| unsafe { w.bits(0) });
    timer.dier().write(|w| unsafe { w.bits(CC1IE) });
    timer.cr1().write(|w| unsafe { w.bits(CEN) });
    feeder
}

/// Endstops in the generator's layout (bit i: motor i's min endstop, bit
/// 4 + i its max), 1 = triggered. Switches with pull-ups read high when
/// pressed (Marlin's `*_ENDSTOP_INVERTING false`); E has none.
#[inline(always)]
fn endstops_triggered() -> u8 {
    let b = pins::Port::B.input();
    let e = pins::Port::E.input();
    let g = pins::Port::G.input();
    let bit = |port: u32, pin: u32, to: u32| (((port >> pin) & 1) << to) as u8;
    bit(b, 10, 0) | bit(e, 12, 1) | bit(g, 8, 2) | bit(e, 15, 4) | bit(e, 10, 5) | bit(g, 5, 6)
}

/// The TIM5 interrupt's body.
#[inline(always)]
pub fn on_interrupt() {
    // SAFETY: TIM5 belongs to this interrupt after `init`.
    let timer = unsafe { &*pac::TIM5::ptr() };
    // rc_w0: writing 0 clears CC1IF, writing 1 leaves the other flags.
    // SAFETY: documented flag bits.
    timer.sr().write(|w| unsafe { w.bits(!CC1IF) });
    pins::STEP_PORT.bsrr(pins::STEP_RESET_ALL);
    // SAFETY: see `StepCell`.
    let state = unsafe { &mut *STATE.0.get() };
    let Some(generator) = state.generator.as_mut() else { return };
    if generator.endstop_mask() != 0 {
        generator.on_endstops(endstops_triggered());
    }
    let action = generator.on_timer();
    let changed = action.dir_mask ^ state.dir_levels;
    if changed != 0 {
        for (motor, dir) in pins::DIRS.iter().enumerate() {
            if changed & (1 << motor) != 0 {
                dir.set(action.dir_mask & (1 << motor) != 0);
            }
        }
        state.dir_levels = action.dir_mask;
    }
    if action.step_mask != 0 {
        pins::STEP_PORT.bsrr(pins::STEP_SET[usize::from(action.step_mask & 0x0F)]);
    }
    let next = state.next_compare.wrapping_add(u32::from(action.next_interval_ticks));
    state.next_compare = next;
    // SAFETY: any compare value is valid.
    timer.ccr1().write(|w| unsafe { w.bits(next) });
    if (timer.cnt().read().bits().wrapping_sub(next) as i32) >= 0 {
        // SAFETY: CC1G forces the compare event (sets CC1IF) now.
        timer.egr().write(|w| unsafe { w.bits(CC1G) });
    }
}

/// Run `f` on the generator with the step interrupt held off.
fn with_generator<R: Default>(f: impl FnOnce(&mut StepGenerator<'static>) -> R) -> R {
    cortex_m::interrupt::free(|_| {
        // SAFETY: interrupts are off, so the step interrupt cannot run
        // while the main loop holds the state.
        let state = unsafe { &mut *STATE.0.get() };
        state.generator.as_mut().map(f).unwrap_or_default()
    })
}

/// The generator's status (a copy) for the main loop.
pub fn status() -> StepperStatus {
    with_generator(|g| g.status())
}

pub fn clear_fault() {
    with_generator(|g| g.clear_fault());
}

/// New stepper configuration (`M120`/`M121`).
pub fn configure(config: StepperConfig) {
    with_generator(|g| g.set_config(config));
}

/// Stop all motion now (M410, kill).
pub fn halt() {
    with_generator(|g| g.halt(StepFault::Stopped));
}
