//! The step interrupt: Timer1 compare A at 2 MHz drives the core's
//! [`StepGenerator`] and puts its actions on the RAMPS STEP/DIR pins.
//!
//! Timer1 runs free (normal mode, clock / 8 = 2 MHz, 0.5 µs per tick); each
//! interrupt schedules the next one by adding the generator's interval to
//! OCR1A, so intervals are measured from the previous compare, not from
//! whenever the handler got to run: a late interrupt does not stretch the
//! step train. If a handler is so late that the next compare time has
//! already passed, the compare is set a few ticks ahead instead of waiting
//! for the counter to wrap (32 ms).
//!
//! Per interrupt, in order: endstops (only when the generator watches any),
//! DIR pins (only when they change) and STEP pins high from
//! `pins_now()` (the event computed last time), then the next event is
//! computed, the next compare is set, and every STEP pin goes low. The
//! generator presents a direction change in an action without steps and
//! waits its set-up time before the next step, so DIR is always settled
//! before STEP rises.
//!
//! # What an event costs, and why the handler looks as it does
//!
//! Measured on simavr (the bench's `step_trials` and `even_steps diag`,
//! one stepper): an ordinary event, entry to `reti`, takes 240–260 cycles
//! (335 before this layout), one that also takes the next segment of the
//! running block 340–360 (≈ 480), one that takes the next block in the
//! same directions 400–420 (≈ 620 while it went through the cold path).
//! At 50 000 steps/s an interval is 320 cycles.
//!
//! - The compiler saves, in the prologue of an interrupt handler that
//!   contains a call, every register a call may clobber, on every run. So
//!   the handler makes no call it can see: everything an ordinary event
//!   needs is inline ([`StepGenerator::ordinary_ready`], which also takes
//!   the next segment of the running block, or the next block, and
//!   [`StepGenerator::ordinary_event`]), and the rare work (reading the
//!   endstops while homing or with hard limits on, a piece of a long
//!   wait, a start from idle or a homing block, a direction change's
//!   lead, the end of the queue) is in [`cold_path`], reached through
//!   `ferrostep_step_cold`, which saves and restores the call-clobbered
//!   registers itself, on that path only. The prologue saves the 14
//!   registers the inline code uses (r16–r27, r30, r31; r16/r17 since
//!   the block change shares the path) instead of 24 and has no stack
//!   frame.
//! - STEP high on PORTF/PORTA (I/O space) is a skip-if-clear and an `sbi`
//!   per pin; STEP low clears all four pins unconditionally, so the mask
//!   is not held in a register across the computation.
//! - The port and timer registers are reached at their fixed addresses
//!   (`Peripherals::steal` stored a flag on every event).
//! - The generator counts only `events_left` per event (the events done
//!   are derived from it), does its Bresenham before the wait sum (nothing
//!   live across the loop), and tests one byte to see whether the running
//!   block may continue with the queue's next segment.
//!
//! Tried and dropped (measured): the Bresenham unrolled with fixed
//! addresses (+440 B, no faster), its state as one array of records (more
//! registers), the wait sum byte by byte (+21 cycles), the long-wait
//! branch out of line (no faster, +30 B).
//!
//! | motor | STEP | DIR |
//! |---|---|---|
//! | X | PF0 | PF1 |
//! | Y | PF6 | PF7 |
//! | Z | PL3 | PL1 |
//! | E0 | PA4 | PA6 |
//!
//! What this handler shares with the main loop (PORTF's and PORTA's
//! enable bits among them), what nests in it and its longest paths: see
//! `interrupts.rs`.

// Without the printers (`printer` feature off) the queues are still split
// (the core's machine holds the feeder) but nothing steps: the interrupt
// and what only the printers' main loop calls are compiled for them only.


use avr_device::atmega2560::Peripherals;
#[cfg(feature = "motion")]
use avr_device::atmega2560::TC1;
use avr_device::interrupt::{self, CriticalSection};
use core::ptr::addr_of_mut;
use firmware::motion::{StepFault, StepFeeder, StepGenerator, StepQueues, StepperConfig};
#[cfg(feature = "motion")]
use firmware::motion::StepperStatus;

#[cfg(feature = "motion")]
/// Extra CPU cycles (16 MHz) the STEP pins stay high after the next
/// event's computation and the compare update, which alone take ≥ 120
/// cycles (7.5 µs; the bench's `min_step_pulse_cycles`, printed by the
/// `step_trials` example): the A4988 needs
/// 1 µs, the DRV8825 1.9 µs, a TB6600 or CL86T 5 µs; raise this for slower
/// drivers.
pub const STEP_PULSE_MIN_EXTRA_CYCLES: u32 = 0;

#[cfg(feature = "motion")]
/// Least distance from now to the next compare when a handler ran late:
/// 4 ticks = 32 cycles, twice what the handler takes from reading TCNT1 to
/// writing OCR1A. A larger margin gives away time on every late handler
/// (the compare moves to `now + margin` and the schedule shifts): at
/// 16 ticks the bench's one-stepper ceiling was 20 000 steps/s, at 4 it is
/// 20 700.
const MIN_AHEAD_TICKS: u16 = 4;

static mut QUEUES: StepQueues = StepQueues::new();
/// The generator, touched by the step interrupt and, inside critical
/// sections, by the main loop.
static mut GENERATOR: Option<StepGenerator<'static>> = None;
#[cfg(feature = "motion")]
/// Last DIR levels written (bit 0 X, 1 Y, 2 Z, 3 E0).
static mut DIR_LEVELS: u8 = 0;

/// Split the step queues (once, before interrupts are enabled), keep the
/// generator for the interrupt and return the main loop's end. Starts
/// Timer1.
pub fn init(dp: &Peripherals, config: StepperConfig) -> StepFeeder<'static> {
    // SAFETY: called once from main before interrupts are enabled; from
    // here on the queues are used only through their two ends.
    let queues = unsafe { &mut *addr_of_mut!(QUEUES) };
    let (feeder, generator) = queues.split(config);
    // SAFETY: interrupts are still disabled (see above).
    unsafe { *addr_of_mut!(GENERATOR) = Some(generator) };
    for pin in crate::pins::STEP.into_iter().chain(crate::pins::DIR) {
        crate::pins::make_output(dp, pin, false);
    }
    let timer = &dp.TC1;
    // Normal mode (WGM13:10 = 0), clock / 8, compare A interrupt.
    timer.tccr1a.write(|w| w.wgm1().bits(0b00));
    timer.tccr1b.write(|w| w.wgm1().bits(0b00).cs1().prescale_8());
    timer.ocr1a.write(|w| w.bits(timer.tcnt1.read().bits().wrapping_add(1000)));
    // Without the printers nothing queues steps: no step interrupt.
    #[cfg(feature = "motion")]
    timer.timsk1.write(|w| w.ocie1a().set_bit());
    feeder
}

/// Stop the interrupt at once (kill, panic): no further STEP pulses.
pub fn stop_timer(dp: &Peripherals) {
    dp.TC1.timsk1.write(|w| w.ocie1a().clear_bit());
    // SAFETY: the flag is written with interrupts off (kill, panic) and
    // read by the step interrupt's cold path.
    unsafe { *addr_of_mut!(TIMER_STOPPED) = true };
}

/// `stop_timer` ran: the step interrupt's general path, which lets the
/// receive interrupt in (and so an `M112`), must not switch its own source
/// back on.
static mut TIMER_STOPPED: bool = false;

fn with_generator<R>(_cs: CriticalSection<'_>, f: impl FnOnce(&mut StepGenerator<'static>) -> R) -> Option<R> {
    // SAFETY: the critical section keeps the step interrupt out, and the
    // main loop is the only other user.
    unsafe { (*addr_of_mut!(GENERATOR)).as_mut().map(f) }
}

#[cfg(feature = "motion")]
/// The generator's status (a copy) for the main loop, in short interrupt
/// locks: the progress a field or two at a time on every pass, the homing
/// stops only while the generator is idle, when they are final and the
/// only time the core reads them. One lock copying everything took 82
/// cycles on every main-loop pass and made steps late at 30 000 steps/s
/// (the bench's allowance there is 53 cycles); each lock here takes at
/// most ~30.
///
/// The fields may come from different moments; the core only relies on
/// what that allows: `blocks_done` is read before `busy`, so a finished
/// block is never seen as idle with an old count, and a block cannot
/// start between the reads unless the main loop itself queued it.
pub fn status() -> StepperStatus {
    let (blocks_done, fault) = interrupt::free(|cs| with_generator(cs, |g| (g.blocks_done(), g.fault()))).unwrap_or_default();
    // Queue first, then the running block (see `has_queued_segments`).
    let busy = interrupt::free(|cs| with_generator(cs, |g| g.has_queued_segments())).unwrap_or_default()
        || interrupt::free(|cs| with_generator(cs, |g| g.is_running())).unwrap_or_default();
    let underruns = interrupt::free(|cs| with_generator(cs, |g| g.underruns())).unwrap_or_default();
    let mut status = StepperStatus { blocks_done, busy, fault, underruns, ..StepperStatus::default() };
    if !status.busy {
        interrupt::free(|cs| with_generator(cs, |g| g.homing_stops(&mut status)));
    }
    status
}

#[cfg(feature = "motion")]
pub fn clear_fault() {
    interrupt::free(|cs| with_generator(cs, |g| g.clear_fault()));
}

#[cfg(feature = "motion")]
/// New stepper configuration (`M120`/`M121`).
pub fn configure(config: StepperConfig) {
    interrupt::free(|cs| with_generator(cs, |g| g.set_config(config)));
}

/// X's and Y's step positions since boot (the encoder loops' reference):
/// a short copy with interrupts off, the arithmetic after.
#[cfg(feature = "encoders")]
pub fn xy_positions() -> [i32; 2] {
    interrupt::free(|cs| with_generator(cs, |g| g.axis_progress())).unwrap_or_default().positions()
}

/// One correction step on X and/or Y (`steps` bit 0 X, bit 1 Y; `positive`
/// the same bits for +) for the encoder loops, between the planner's steps:
/// with interrupts off, the directions are set for the correction, held
/// for the configured set-up time, pulsed for 2 µs, then put back as the
/// step interrupt left them (≈ 2 × set-up + 3 µs with interrupts off, at
/// most once a millisecond).
#[cfg(feature = "encoders")]
pub fn correction_steps(dp: &Peripherals, steps: u8, positive: u8) {
    interrupt::free(|cs| {
        let Some(config) = with_generator(cs, |g| g.config()) else { return };
        // SAFETY: interrupts are off; the step interrupt owns DIR_LEVELS otherwise.
        let levels = unsafe { *addr_of_mut!(DIR_LEVELS) };
        let wanted = (levels & !steps) | ((positive ^ config.dir_invert) & steps);
        let setup_cycles = u32::from(config.dir_setup_ticks.max(2)) * 8;
        write_dirs(wanted);
        avr_device::asm::delay_cycles(setup_cycles);
        let _ = dp;
        step_high(steps & 0b11);
        avr_device::asm::delay_cycles(32);
        step_low();
        avr_device::asm::delay_cycles(setup_cycles);
        write_dirs(levels);
    });
}

pub fn halt() {
    interrupt::free(|cs| with_generator(cs, |g| g.halt(StepFault::Stopped)));
}

#[cfg(feature = "motion")]
/// Endstops in the generator's layout (bit i motor i min, 4 + i max),
/// 1 = triggered, each switch's polarity from the machine file.
#[inline(always)]
fn endstops(dp: &Peripherals) -> u8 {
    crate::pins::endstops_triggered(dp)
}

#[cfg(feature = "motion")]
#[avr_device::interrupt(atmega2560)]
fn TIMER1_COMPA() {
    // SAFETY (for the accesses to GENERATOR and DIR_LEVELS below):
    // interrupts are off in this handler (and in `cold_path`'s window with
    // them on, only handlers that never touch either can run), so it has
    // them to itself; the main loop takes them only in critical sections.
    // No reference to the generator is held across a `cold_call`, which
    // takes its own.
    // SAFETY: `Some`: `init` sets GENERATOR before it enables this
    // interrupt (OCIE1A), and nothing sets it back to `None`.
    let generator = || unsafe { (*addr_of_mut!(GENERATOR)).as_mut().unwrap_unchecked() };
    if generator().endstop_mask() != 0 {
        cold_call(COLD_ENDSTOPS);
    }
    // The pins first, the computation of the next event after: the edges
    // keep their scheduled times whatever that computation costs.
    let (steps, dir) = generator().pins_now();
    let dir_levels = unsafe { &mut *addr_of_mut!(DIR_LEVELS) };
    if dir != *dir_levels {
        write_dirs(dir);
        *dir_levels = dir;
    }
    step_high(steps);
    let mut ticks = 0;
    if !generator().ordinary_ready() {
        ticks = cold_call(COLD_GENERAL);
    }
    if ticks == 0 {
        ticks = generator().ordinary_event();
    }
    // SAFETY: the register block of Timer1, at its fixed address.
    schedule_next(unsafe { &*TC1::ptr() }, ticks);
    // The computation and the scheduling took well over the pulse width;
    // the delay only guarantees it.
    if STEP_PULSE_MIN_EXTRA_CYCLES > 0 {
        avr_device::asm::delay_cycles(STEP_PULSE_MIN_EXTRA_CYCLES);
    }
    step_low();
}

#[cfg(feature = "motion")]
/// [`cold_path`]: read the endstops and let the generator act on them.
const COLD_ENDSTOPS: u8 = 0;
#[cfg(feature = "motion")]
/// [`cold_path`]: the generator's general path (long wait, new block, end
/// of the queue, ...).
const COLD_GENERAL: u8 = 1;

// The step interrupt's way to its cold paths. The compiler saves, in the
// prologue of an interrupt handler that contains a call, every register a
// call may clobber, on every run, even when the call is on a path that
// rarely runs. So the handler makes no call the compiler sees: it calls
// this routine from inline assembly (`cold_call`), and the routine saves
// the call-clobbered registers of avr-gcc's convention (which LLVM's AVR
// back end follows) other than r24/r25, which carry the argument and the
// result: r18–r23, r26, r27, r30, r31. r0 is LLVM's scratch register
// (never live across an instruction sequence it did not emit) and r1,
// the zero register, stays zero across any call.
#[cfg(feature = "motion")]
core::arch::global_asm!(
    ".section .text.ferrostep_step_cold,\"ax\",@progbits",
    "ferrostep_step_cold:",
    "push r18", "push r19", "push r20", "push r21", "push r22",
    "push r23", "push r26", "push r27", "push r30", "push r31",
    "call {f}",
    "pop r31", "pop r30", "pop r27", "pop r26", "pop r23",
    "pop r22", "pop r21", "pop r20", "pop r19", "pop r18",
    "ret",
    f = sym cold_path,
);

#[cfg(feature = "motion")]
/// Runs [`cold_path`]`(what)` from the step interrupt without the
/// compiler's register saves (see `ferrostep_step_cold` above).
#[inline(always)]
fn cold_call(what: u8) -> u16 {
    let (lo, hi): (u8, u8);
    // SAFETY: `ferrostep_step_cold` preserves every register but r24/r25
    // (declared here as the argument and outputs); `cold_path` is an
    // ordinary `extern "C"` function. The stack has room for the routine's
    // ten bytes and the call as for any call. Memory is not declared
    // untouched, so the compiler reloads the generator afterwards.
    unsafe {
        core::arch::asm!(
            "call ferrostep_step_cold",
            inout("r24") what => lo,
            out("r25") hi,
        );
    }
    u16::from(hi) << 8 | u16::from(lo)
}

#[cfg(feature = "motion")]
/// The step interrupt's rare cases (the handler holds no reference to the
/// generator across the call): [`COLD_ENDSTOPS`], or [`COLD_GENERAL`]:
/// returns the ticks to the next compare, or 0 when the running segment's
/// next event is still to be computed (by the handler, inline).
///
/// A block change in the same directions is not here: it is as cheap as
/// a segment change and inline in the handler
/// (`StepGenerator::ordinary_ready`). The general path (a start from
/// idle, a direction change: up to ≈ 1 000 cycles) lets the serial
/// receive interrupt in: at 250 000 baud a byte arrives every 640 cycles
/// and the UART holds two, so a step interrupt that long with interrupts
/// off lost bytes (the bench's 250 000-baud stream, once its host sent at
/// the real rate). Which handlers may run in that window, and which are
/// masked: see `interrupts.rs`. The STEP pins are high and the next compare not
/// yet set: a byte makes the pulse a little longer, never a step late
/// (the compare is set from the previous one).
extern "C" fn cold_path(what: u8) -> u16 {
    // SAFETY: see above.
    let Some(generator) = (unsafe { (*addr_of_mut!(GENERATOR)).as_mut() }) else { return IDLE_TICKS };
    if what == COLD_ENDSTOPS {
        // SAFETY: only the pin registers are read.
        generator.on_endstops(endstops(&unsafe { Peripherals::steal() }));
        return 0;
    }
    // SAFETY: Timer1's interrupt mask (OCIE1A is the only one used).
    let timer = unsafe { &*TC1::ptr() };
    timer.timsk1.write(|w| unsafe { w.bits(0) });
    #[cfg(feature = "encoders")]
    let tick = crate::clock::hold_tick();
    // SAFETY: the handlers that may now run do not use the generator, and
    // this one's own source is off.
    unsafe { avr_device::interrupt::enable() };
    let ticks = generator.on_timer_general();
    avr_device::interrupt::disable();
    #[cfg(feature = "encoders")]
    crate::clock::release_tick(tick);
    // SAFETY: as above; a kill in between keeps the timer stopped.
    if !unsafe { *addr_of_mut!(TIMER_STOPPED) } {
        timer.timsk1.write(|w| unsafe { w.bits(1 << 1) });
    }
    ticks
}

#[cfg(feature = "motion")]
const IDLE_TICKS: u16 = firmware::motion::stepper::IDLE_POLL_TICKS;


/// For each of the four motors, `$body` with `PIN` the motor's pin from
/// `$table` (`pins::STEP` or `pins::DIR`), `IO` its port's I/O address
/// (`None` beyond I/O space) and `$motor` its number: unrolled, so every
/// pin is a constant and no table is read at run time.
#[cfg(feature = "motion")]
macro_rules! for_each_motor_pin {
    ($table:path, |$motor:ident| $body:block) => {
        for_each_motor_pin!(@one $table, 0, $motor, $body);
        for_each_motor_pin!(@one $table, 1, $motor, $body);
        for_each_motor_pin!(@one $table, 2, $motor, $body);
        for_each_motor_pin!(@one $table, 3, $motor, $body);
    };
    (@one $table:path, $n:literal, $motor:ident, $body:block) => {{
        #[allow(dead_code)]
        const PIN: crate::pins::Pin = $table[$n];
        #[allow(dead_code)]
        const IO: Option<u8> = PIN.port.port_io_address();
        #[allow(dead_code)]
        const IO_OR_0: u8 = match IO { Some(a) => a, None => 0 };
        #[allow(unused_macros)]
        macro_rules! $motor { () => { $n } }
        $body
    }};
}

/// STEP high for the motors in `steps` (bit m: motor m), on the machine
/// file's `pins::STEP`. A pin in I/O space (ports A–G) is a
/// skip-if-bit-clear and an `sbi`, 2–3 cycles (the compiler's mask,
/// compare and branch took 5–6); others a test and a read-modify-write.
#[cfg(feature = "motion")]
#[inline(always)]
fn step_high(steps: u8) {
    for_each_motor_pin!(crate::pins::STEP, |motor| {
        if IO.is_some() {
            // SAFETY: sets one STEP bit of an I/O-space port (any value is
            // valid for a port register; interrupts are off here, so `sbi`'s
            // read-modify-write cannot interleave with another writer);
            // `sbrc`/`sbi` leave SREG and memory alone.
            unsafe {
                core::arch::asm!(
                    "sbrc {s}, {m}",
                    "sbi {io}, {bit}",
                    s = in(reg) steps,
                    m = const motor!(),
                    io = const IO_OR_0,
                    bit = const PIN.bit,
                    options(nostack, preserves_flags),
                )
            }
        } else if steps & (1 << motor!()) != 0 {
            write_port_bit(PIN, true);
        }
    });
}

#[cfg(feature = "motion")]
/// Every STEP pin low (those already low stay so): no register holds the
/// step mask across the computation.
#[inline(always)]
fn step_low() {
    for_each_motor_pin!(crate::pins::STEP, |_motor| {
        if IO.is_some() {
            // SAFETY: clears one STEP bit of an I/O-space port (as above).
            unsafe { core::arch::asm!("cbi {io}, {bit}", io = const IO_OR_0, bit = const PIN.bit, options(nostack, preserves_flags)) }
        } else {
            write_port_bit(PIN, false);
        }
    });
}

/// Set (`high`) or clear one bit of a port's PORTx register (a port beyond
/// I/O space: a load, an or/and and a store). Interrupts must be off or the
/// port not shared (the step interrupt's callers).
#[cfg(feature = "motion")]
#[inline(always)]
fn write_port_bit(pin: crate::pins::Pin, high: bool) {
    let port = pin.port.pin_register().wrapping_add(2);
    // SAFETY: PORTx of an existing port; any bit pattern is valid there.
    unsafe {
        let value = port.read_volatile();
        port.write_volatile(if high { value | 1 << pin.bit } else { value & !(1 << pin.bit) });
    }
}

#[cfg(feature = "motion")]
/// OCR1A += interval, or a little ahead of now if that is already past.
/// Returns the counter as read (the time the STEP pins went high, within a
/// few cycles).
#[inline(always)]
fn schedule_next(timer: &avr_device::atmega2560::tc1::RegisterBlock, interval: u16) -> u16 {
    let now = timer.tcnt1.read().bits();
    let mut next = timer.ocr1a.read().bits().wrapping_add(interval);
    if (next.wrapping_sub(now) as i16) < MIN_AHEAD_TICKS as i16 {
        next = now.wrapping_add(MIN_AHEAD_TICKS);
    }
    timer.ocr1a.write(|w| w.bits(next));
    now
}

#[cfg(feature = "motion")]
/// DIR levels (bit m: motor m high), on the machine file's `pins::DIR`.
#[inline(always)]
fn write_dirs(dir: u8) {
    for_each_motor_pin!(crate::pins::DIR, |motor| {
        if IO.is_some() {
            // SAFETY: sets or clears one DIR bit of an I/O-space port (as in
            // `step_high`).
            unsafe {
                core::arch::asm!(
                    "sbrc {d}, {m}",
                    "sbi {io}, {bit}",
                    "sbrs {d}, {m}",
                    "cbi {io}, {bit}",
                    d = in(reg) dir,
                    m = const motor!(),
                    io = const IO_OR_0,
                    bit = const PIN.bit,
                    options(nostack, preserves_flags),
                )
            }
        } else {
            write_port_bit(PIN, dir & (1 << motor!()) != 0);
        }
    });
}
