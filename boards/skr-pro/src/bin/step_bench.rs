//! Step-interrupt benchmark for the SKR Pro build: what one step event
//! costs the Cortex-M4, measured by counting, and the step rate that
//! follows.
//!
//! It runs the firmware's own step interrupt (`stepper::on_interrupt`,
//! the core's `StepGenerator::on_timer` between the pin writes) on a long
//! single-motor block, so every event steps X: the "1 stepper" case of
//! Klipper's benchmark. The interrupt is pended by software, with the step
//! timer stopped, so each measured entry runs exactly one step event:
//!
//! ```text
//! t0 = counter; pend TIM5; dsb; isb; t1 = counter     (the interrupt runs in between)
//! cost = (t1 − t0) − (the same without the pend)
//! ```
//!
//! so the figure includes the exception entry and return, as a timer
//! interrupt has them.
//!
//! The counter: the DWT cycle counter when it counts (silicon: exact core
//! cycles at 168 MHz). QEMU does not model the DWT; there the bench falls
//! back to TIM2 counting at its model's clock and says so. Under
//! `qemu-system-arm -icount shift=0` QEMU's virtual clock advances exactly
//! 1 ns per guest instruction, so TIM2 then counts *instructions*, not
//! cycles: the bench calibrates ticks per instruction on a loop of known
//! length and reports instructions. `tests/src/qemu_arm.rs` turns those into
//! a cycle figure with a stated model.
//!
//! Second part: one tick of the closed-loop position law (robust PID,
//! γ 0.5, 1 kHz, `AxisController::tick`) in each arithmetic of
//! `firmware::num`, timed the same way (`t0; tick; t1` less the bare
//! reads), so the board's choice of `Native` (f32 here) rests on figures.
//!
//! Output, one `key=value` per line on USART1, then `done`.
#![no_std]
#![no_main]

use cortex_m::peripheral::{DWT, NVIC};
use cortex_m_rt::entry;
use core::hint::black_box;
use firmware::closed_loop::control::{AxisController, DriverStatus, FollowingErrorLimit, LoopGains, Reference};
use firmware::closed_loop::tuning::Strategy;
use firmware::motion::stepper::{Segment, StepBlock, StepperConfig, TIMER_HZ};
use firmware::num::{FixedPoint, Float, LoopArithmetic};
use firmware::rx::{self, RxQueue};
use skr_pro::pac::{self, interrupt, Interrupt};
use skr_pro::{clock, pins, serial, stepper};
use ufmt::uwrite;

/// Measured step events (after the warm-up).
const SAMPLES: u32 = 2000;
/// Events run before measuring: the block start and the direction lead.
const WARM_UP: u32 = 64;
/// RCC_APB1ENR: TIM2EN.
const TIM2EN: u32 = 1 << 0;
/// Iterations of the calibration loop (two instructions each).
const CALIBRATION_LOOPS: u32 = 10_000;

static mut RX_QUEUE: RxQueue = RxQueue::new();

/// Which counter the figures come from.
#[derive(Clone, Copy, PartialEq)]
enum Counter {
    /// DWT CYCCNT: core cycles.
    Cycles,
    /// TIM2 (QEMU): its model's ticks.
    Timer,
}

#[inline(always)]
fn read(counter: Counter) -> u32 {
    match counter {
        Counter::Cycles => DWT::cycle_count(),
        // SAFETY: reading TIM2's counter has no side effect.
        Counter::Timer => unsafe { (*pac::TIM2::ptr()).cnt().read().bits() },
    }
}

/// Ticks of one pended interrupt (or of the bare measurement, `pend` off).
#[inline(never)]
fn one(counter: Counter, pend: bool) -> u32 {
    let start = read(counter);
    if pend {
        NVIC::pend(Interrupt::TIM5);
    }
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
    read(counter).wrapping_sub(start)
}

/// Ticks of `CALIBRATION_LOOPS` iterations of a two-instruction loop.
#[inline(never)]
fn calibration_loop(counter: Counter) -> u32 {
    let start = read(counter);
    // SAFETY: a register-only countdown loop.
    unsafe {
        core::arch::asm!(
            "2:",
            "subs {n}, {n}, #1",
            "bne 2b",
            n = inout(reg) CALIBRATION_LOOPS => _,
            options(nostack),
        );
    }
    read(counter).wrapping_sub(start)
}

struct Stats {
    min: u32,
    max: u32,
    sum: u64,
}

fn measure(counter: Counter, pend: bool) -> Stats {
    let mut stats = Stats { min: u32::MAX, max: 0, sum: 0 };
    for _ in 0..SAMPLES {
        let ticks = one(counter, pend);
        stats.min = stats.min.min(ticks);
        stats.max = stats.max.max(ticks);
        stats.sum += u64::from(ticks);
    }
    stats
}

/// Law ticks measured per arithmetic.
const LOOP_SAMPLES: u32 = 256;
const NO_FAULT: DriverStatus = DriverStatus { alarm: false, bridge_fault: false };

/// Counter ticks of the two reads alone, summed over `LOOP_SAMPLES`.
#[inline(never)]
fn law_bare(counter: Counter) -> u64 {
    let mut sum = 0u64;
    for _ in 0..LOOP_SAMPLES {
        let start = read(counter);
        let end = black_box(read(counter));
        sum += u64::from(end.wrapping_sub(start));
    }
    sum
}

/// Counter ticks of `LOOP_SAMPLES` robust-PID ticks in arithmetic `A` (a
/// 5 mm/s ramp, the following error wandering over ±0.05 mm), reads
/// included.
#[inline(never)]
fn law_cost<A: LoopArithmetic>(counter: Counter) -> u64 {
    let gains: LoopGains<A> =
        Strategy::RobustPid { gamma_milli: 500 }.loop_gains::<A>(0.1, 0.001).unwrap_or(LoopGains::OPEN_LOOP);
    let mut controller = AxisController::<A>::new(gains, 200 * 2048, FollowingErrorLimit::printer_default(1000));
    let mut sum = 0u64;
    for k in 0..LOOP_SAMPLES as i32 {
        let position = k * 10;
        let reference = black_box(Reference { position, velocity: 10_240 });
        let measured = black_box(Ok(position - ((k % 64) * 3 - 96)));
        let start = read(counter);
        let output = controller.tick(reference, measured, NO_FAULT);
        let end = read(counter);
        let _ = black_box(output);
        sum += u64::from(end.wrapping_sub(start));
    }
    sum
}

#[entry]
fn main() -> ! {
    pins::init();
    // SAFETY: the only call.
    let dp = unsafe { pac::Peripherals::steal() };
    // SAFETY: the only call.
    let mut cp = unsafe { cortex_m::Peripherals::steal() };
    let clocks = clock::init(&dp.RCC, &dp.FLASH);
    // SAFETY: split once, before interrupts are enabled.
    let (producer, _consumer) = rx::split(unsafe { &mut *core::ptr::addr_of_mut!(RX_QUEUE) });
    serial::init(&dp.RCC, &dp.USART1, &clocks, producer);
    let mut tx = serial::Tx;

    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    let before = DWT::cycle_count();
    cortex_m::asm::delay(100);
    let counter = if DWT::cycle_count() != before { Counter::Cycles } else { Counter::Timer };
    // TIM2: free-running at its full input clock, the fallback counter.
    // SAFETY (all `bits`): documented field values.
    dp.RCC.apb1enr().modify(|r, w| unsafe { w.bits(r.bits() | TIM2EN) });
    cortex_m::asm::dsb();
    dp.TIM2.psc().write(|w| unsafe { w.bits(0) });
    dp.TIM2.arr().write(|w| unsafe { w.bits(u32::MAX) });
    dp.TIM2.egr().write(|w| unsafe { w.bits(1) });
    dp.TIM2.cr1().write(|w| unsafe { w.bits(1) });

    let mut feeder = stepper::init(&dp.RCC, &dp.TIM5, &clocks, StepperConfig::default());
    // Stop the step timer: only the bench's pends run the interrupt.
    // SAFETY: CEN = 0.
    dp.TIM5.cr1().write(|w| unsafe { w.bits(0) });
    // One long X move, a step on every event, 10 µs apart (interval in
    // 1/256 ticks; its value does not change the work per event).
    let events = u16::MAX;
    let block = StepBlock { steps: [events, 0, 0, 0], events, direction: 0b0001, watch: 0, watch_release: false };
    let segment = Segment { interval: (TIMER_HZ / 100_000) << 8, add: 0, events, starts_block: true };
    let queued = feeder.push_block(block) && feeder.push_segment(segment);
    // SAFETY: the handler only touches the step state.
    unsafe {
        cp.NVIC.set_priority(Interrupt::TIM5, skr_pro::priority::STEP_TIMER);
        NVIC::unmask(Interrupt::TIM5);
    }
    for _ in 0..WARM_UP {
        one(counter, true);
    }
    let bare = measure(counter, false);
    let isr = measure(counter, true);
    let calibration = calibration_loop(counter);
    let loop_bare = law_bare(counter);
    let loop_fixed = law_cost::<FixedPoint>(counter);
    let loop_float = law_cost::<Float>(counter);

    let _ = uwrite!(tx, "bench:start\n");
    let _ = uwrite!(tx, "counter={}\n", if counter == Counter::Cycles { "dwt_cycles" } else { "tim2_ticks" });
    let _ = uwrite!(
        tx,
        "clock_source={}\n",
        match clocks.source {
            clock::ClockSource::Crystal => "crystal",
            clock::ClockSource::InternalRcPll => "internal_rc_pll",
            clock::ClockSource::InternalRc => "internal_rc",
            clock::ClockSource::Emulated => "emulated",
        }
    );
    let _ = uwrite!(tx, "sysclk_hz={}\n", clocks.sysclk_hz);
    let _ = uwrite!(tx, "step_timer_hz={}\n", TIMER_HZ);
    let _ = uwrite!(tx, "queued={}\n", u8::from(queued));
    let _ = uwrite!(tx, "samples={}\n", SAMPLES);
    let _ = uwrite!(tx, "bare_min={}\nbare_max={}\nbare_sum={}\n", bare.min, bare.max, bare.sum);
    let _ = uwrite!(tx, "isr_min={}\nisr_max={}\nisr_sum={}\n", isr.min, isr.max, isr.sum);
    let _ = uwrite!(tx, "calibration_instructions={}\ncalibration_ticks={}\n", 2 * CALIBRATION_LOOPS, calibration);
    let _ = uwrite!(tx, "loop_samples={}\nloop_bare_sum={}\n", LOOP_SAMPLES, loop_bare);
    let _ = uwrite!(tx, "loop_fixed_sum={}\nloop_f32_sum={}\n", loop_fixed, loop_float);
    if counter == Counter::Cycles {
        let cycles = (isr.sum - bare.sum) / u64::from(SAMPLES);
        let _ = uwrite!(tx, "arm_step_isr_cycles={}\n", cycles as u32);
        let rate = (u64::from(clocks.sysclk_hz) / cycles.max(1)).min(u64::from(TIMER_HZ));
        let _ = uwrite!(tx, "arm_step_rate_1_stepper_hz={}\n", rate as u32);
    }
    let _ = uwrite!(tx, "done\n");
    loop {
        cortex_m::asm::wfi();
    }
}

#[interrupt]
fn TIM5() {
    stepper::on_interrupt();
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    pins::all_outputs_safe();
    let _ = uwrite!(serial::Tx, "Error:bench panic\n");
    loop {}
}
