//! SPEC §1's NSE-5310 linear encoders on X and Y (`M820`–`M824`, `M828`
//! traces; the loops themselves: `firmware::closed_loop::printer`).
//!
//! Wiring (configuration, see the README):
//! - both chips on the Mega's TWI bus (SDA D20, SCL D21, 400 kHz), X at
//!   0x40 (the factory address) and Y at 0x41 (OTP-programmed): SPEC §1
//!   leaves separate buses, chip-select gating or OTP addresses open;
//!   ours is OTP, one bus and no extra pins;
//! - their Index outputs on A9 (PK1, X) and A10 (PK2, Y) of RAMPS AUX-2,
//!   pin-change interrupt PCINT2, debounced there.
//!
//! Timing: the 1 kHz tick (clock.rs) calls [`on_tick`] with interrupts
//! enabled; every [`LOOP_PERIOD_MS`]th millisecond it reads both chips
//! (two 2-byte reads, ≈ 60 µs each; the step interrupt keeps running) and
//! runs the loops, every millisecond it makes the correction steps the
//! loops ask for. Who masks the tick around the loops: see
//! `interrupts.rs` ([`with_loops`]). While every loop is off (the default) the tick
//! does nothing here and the I²C bus stays idle.

use avr_device::atmega2560::Peripherals;
use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use firmware::closed_loop::nse5310::{decode_frame, IndexDebouncer};
use firmware::closed_loop::printer::{AxisReport, EncoderLoops, AXES, LOOP_PERIOD_MS};
use firmware::closed_loop::trace;
use firmware::closed_loop::{AxisFault, Reading};
use firmware::machine::Machine;
use ufmt::uWrite;

/// 7-bit I²C addresses of the X and Y chips.
pub const ADDRESSES: [u8; AXES] = [0x40, 0x41];
/// Index inputs: PK1 (A9) for X, PK2 (A10) for Y.
const INDEX_BITS: [u8; AXES] = [1 << 1, 1 << 2];
/// Index edges closer than this are bounces (the index pulse of a 2 mm
/// pole pair at 300 mm/s comes every 6.7 ms).
const INDEX_MIN_SPACING_US: u32 = 500;
/// TWBR for 400 kHz with prescaler 1: 16 MHz / (16 + 2·12).
const TWBR_400KHZ: u8 = 12;
/// Polls of TWINT before a transfer step counts as failed: one byte takes
/// ≈ 360 cycles at 400 kHz, a poll ≈ 8.
const TWI_POLLS: u16 = 400;

// TWCR bits.
const TWINT: u8 = 1 << 7;
const TWEA: u8 = 1 << 6;
const TWSTA: u8 = 1 << 5;
const TWEN: u8 = 1 << 2;

/// The loops, valid once `READY` (set by [`init`]; `Option` would put
/// the 250 bytes in `.data`, i.e. in flash as well). Owned by the tick
/// (Timer3 compare A); the main loop reaches them through [`with_loops`].
static mut LOOPS: MaybeUninit<EncoderLoops> = MaybeUninit::uninit();
static mut READY: bool = false;
/// Index debouncers, written by PCINT2 and read by the tick, both under
/// a critical section.
static mut INDEX: [IndexDebouncer; AXES] = [IndexDebouncer::new(INDEX_MIN_SPACING_US); AXES];
/// PINK at the last pin change (for rising edges).
static mut LAST_PINK: u8 = 0;
/// A copy of `any_enabled()`, so that the tick's common case is one load.
static mut ACTIVE: bool = false;
/// X's and Y's steps/mm (thousandths) the loops were last given (main
/// loop only): `M92` is followed by the next `service`.
static mut SCALE_MILLI: [i32; AXES] = [0; AXES];

/// TWI at 400 kHz, the Index pins as pulled-up inputs with their
/// pin-change interrupt, and the loops for X's and Y's steps/mm and
/// fastest speed (from the settings; `service` follows later `M92`s).
pub fn init(dp: &Peripherals, steps_per_mm: [f32; AXES], max_speed_mm_s: [u16; AXES]) {
    dp.TWI.twbr.write(|w| w.bits(TWBR_400KHZ));
    // The status bits are read-only.
    dp.TWI.twsr.write(|w| w.twps().prescaler_1());
    dp.TWI.twcr.write(|w| w.twen().set_bit());
    for bit in INDEX_BITS {
        dp.PORTK.ddrk.modify(|r, w| unsafe { w.bits(r.bits() & !bit) });
        dp.PORTK.portk.modify(|r, w| unsafe { w.bits(r.bits() | bit) });
    }
    // PCINT17/18 in PCMSK2 and PCIE2 in PCICR (safe writes: every value is valid).
    dp.EXINT.pcmsk2.modify(|r, w| w.pcint().bits(r.pcint().bits() | INDEX_BITS[0] | INDEX_BITS[1]));
    // The levels now (pulled up) are the reference for the first change:
    // no edge counted at start.
    // SAFETY: before the pin-change interrupt is enabled.
    unsafe { *addr_of_mut!(LAST_PINK) = dp.PORTK.pink.read().bits() };
    dp.EXINT.pcicr.modify(|r, w| w.pcie().bits(r.pcie().bits() | 1 << 2));
    // SAFETY: main loop only.
    unsafe { *addr_of_mut!(SCALE_MILLI) = steps_per_mm.map(|spm| (spm * 1000.0) as i32) };
    if let Some(loops) = EncoderLoops::new(steps_per_mm, max_speed_mm_s) {
        // SAFETY: called from main before any `with_loops`, with the tick
        // not looking yet (`ACTIVE` is false until a loop is switched on).
        unsafe {
            (*addr_of_mut!(LOOPS)).write(loops);
            *addr_of_mut!(READY) = true;
        }
    }
}

/// Run `f` on the loops with the tick's interrupt masked (not every
/// interrupt: the steps keep their times). `None` if the machine's X/Y
/// cannot be read often enough for their speed (no loops).
pub fn with_loops<R>(dp: &Peripherals, f: impl FnOnce(&mut EncoderLoops) -> R) -> Option<R> {
    crate::clock::mask_tick(dp, true);
    // SAFETY: the only other user, the tick, cannot run while masked (and
    // this is called from the main loop only).
    let result = loops_if_ready().map(|loops| {
        let result = f(loops);
        // SAFETY: as above.
        unsafe { *addr_of_mut!(ACTIVE) = loops.needs_readings() };
        result
    });
    crate::clock::mask_tick(dp, false);
    result
}

/// The loops once [`init`] made them. Callers hold them exclusively: the
/// tick, or the main loop with the tick masked.
fn loops_if_ready() -> Option<&'static mut EncoderLoops> {
    // SAFETY: READY is written once, before either caller runs; LOOPS is
    // initialised when it is set.
    unsafe { (*addr_of_mut!(READY)).then(|| (*addr_of_mut!(LOOPS)).assume_init_mut()) }
}

/// From the tick (Timer3 compare A, interrupts enabled), every millisecond.
/// Out of line: the tick's handler then saves only what it uses itself.
#[inline(never)]
pub fn on_tick(dp: &Peripherals, now_ms: u32) {
    // SAFETY: the tick owns the loops (see `with_loops`).
    if !unsafe { *addr_of_mut!(ACTIVE) } {
        return;
    }
    let Some(loops) = loops_if_ready() else { return };
    if now_ms % u32::from(LOOP_PERIOD_MS) == 0 {
        let readings = [read(dp, ADDRESSES[0]), read(dp, ADDRESSES[1])];
        // SAFETY: PCINT2 writes the debouncers with interrupts off; so do we.
        let edges = avr_device::interrupt::free(|_| unsafe { (*addr_of_mut!(INDEX)).each_mut().map(|index| index.take()) });
        loops.tick(crate::stepping::xy_positions(), readings, edges);
    }
    let (steps, positive) = loops.emit();
    if steps != 0 {
        crate::stepping::correction_steps(dp, steps, positive);
    }
}

/// The main loop's share (out of line, called once a pass): install changed settings, re-zero after a
/// homing, report a fault, refresh what `M822` shows, stop on a halt.
#[inline(never)]
pub fn service<W: uWrite + ?Sized>(dp: &Peripherals, machine: &mut Machine, refresh_report: bool, out: &mut W) -> Result<(), W::Error> {
    while let Some((axis, settings, gains)) = machine.take_encoder_settings() {
        let steps = crate::stepping::xy_positions();
        with_loops(dp, |loops| loops.configure(axis, &settings, gains, steps[axis]));
    }
    // `M92 X… Y…`: the loops' scale follows (and re-zeroes that encoder).
    for axis in 0..AXES {
        let milli = machine.settings().steps_per_mm_milli[axis];
        // SAFETY: main loop only.
        let known = unsafe { &mut (*addr_of_mut!(SCALE_MILLI))[axis] };
        if milli != *known {
            *known = milli;
            let steps = crate::stepping::xy_positions()[axis];
            with_loops(dp, |loops| loops.set_steps_per_mm(axis, milli as f32 / 1000.0, steps));
        }
    }
    if machine.take_encoder_rehome() {
        let steps = crate::stepping::xy_positions();
        with_loops(dp, |loops| loops.rehome(steps));
    }
    if machine.is_halted() {
        with_loops(dp, |loops| loops.stop_all(AxisFault::Stopped));
    }
    if let Some(Some((axis, fault))) = with_loops(dp, |loops| loops.take_fault()) {
        machine.on_encoder_fault(axis, fault, out)?;
    }
    // M828: start or stop recording; the samples out as `TR:` lines (one
    // every 4 ms, 26 bytes: 2.3 ms of this pass at 115200 baud), then,
    // after a stop, the totals.
    let request = machine.take_trace_request();
    if let Some(on) = request {
        with_loops(dp, |loops| loops.set_tracing(on));
    }
    while let Some(Some(sample)) = with_loops(dp, |loops| loops.take_trace_sample()) {
        sample.write_line(out)?;
    }
    if request == Some(false) {
        if let Some((recorded, dropped)) = with_loops(dp, |loops| loops.trace_totals()) {
            trace::write_end(recorded, dropped, out)?;
        }
    }
    if refresh_report {
        if let Some(reports) = with_loops(dp, |loops| [loops.report(0), loops.report(1)]) {
            machine.set_encoder_reports(reports);
        } else {
            machine.set_encoder_reports([AxisReport::EMPTY; AXES]);
        }
    }
    Ok(())
}

/// One NSE-5310 read: START, SLA+R, two bytes (ACK, NACK), STOP.
fn read(dp: &Peripherals, address: u8) -> Reading {
    let twi = &dp.TWI;
    let mut frame = [0u8; 2];
    let ok = (|| {
        command(dp, TWINT | TWSTA | TWEN)?;
        expect(dp, &[0x08, 0x10])?;
        twi.twdr.write(|w| w.bits(address << 1 | 1));
        command(dp, TWINT | TWEN)?;
        expect(dp, &[0x40])?;
        command(dp, TWINT | TWEN | TWEA)?;
        expect(dp, &[0x50])?;
        frame[0] = twi.twdr.read().bits();
        command(dp, TWINT | TWEN)?;
        expect(dp, &[0x58])?;
        frame[1] = twi.twdr.read().bits();
        Some(())
    })();
    // STOP (also after a failure: releases the bus).
    twi.twcr.write(|w| w.twint().set_bit().twen().set_bit().twsto().set_bit());
    match (ok, decode_frame(frame)) {
        (Some(()), Ok(raw)) => Reading::Raw(raw),
        _ => Reading::Failed,
    }
}

/// Start one TWI step and wait for it (bounded).
fn command(dp: &Peripherals, bits: u8) -> Option<()> {
    // SAFETY: TWCR control bits of this driver.
    dp.TWI.twcr.write(|w| unsafe { w.bits(bits) });
    for _ in 0..TWI_POLLS {
        if dp.TWI.twcr.read().bits() & TWINT != 0 {
            return Some(());
        }
    }
    None
}

fn expect(dp: &Peripherals, statuses: &[u8]) -> Option<()> {
    let status = dp.TWI.twsr.read().bits() & 0xF8;
    statuses.contains(&status).then_some(())
}

/// PCINT2: an Index line changed. Rising edges go to the debouncers.
#[avr_device::interrupt(atmega2560)]
fn PCINT2() {
    // SAFETY: PINK is read-only input state.
    let pink = unsafe { Peripherals::steal() }.PORTK.pink.read().bits();
    avr_device::interrupt::free(|cs| {
        // SAFETY: interrupts are off; the tick takes the counts the same way.
        let (last, index) = unsafe { (&mut *addr_of_mut!(LAST_PINK), &mut *addr_of_mut!(INDEX)) };
        let rising = pink & !*last;
        *last = pink;
        if rising & (INDEX_BITS[0] | INDEX_BITS[1]) == 0 {
            return;
        }
        let now_us = crate::clock::micros(cs);
        for (bit, debouncer) in INDEX_BITS.into_iter().zip(index.iter_mut()) {
            if rising & bit != 0 {
                debouncer.on_edge(now_us);
            }
        }
    });
}
