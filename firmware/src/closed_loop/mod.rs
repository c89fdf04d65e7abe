//! Closed position loops on encoders (SPEC §1 printer with NSE-5310 linear
//! encoders, SPEC §3 driver ALARM inputs, SPEC §5 DC servo axes).
//!
//! Pieces, each a pure state machine tested on the host:
//! - [`nse5310`]: the I²C read, unwrapping across 2 mm pole pairs, Index
//!   debouncing and cross-check, stuck/absent sensor detection;
//! - [`quadrature`]: an A/B(/index) decoder for pin-change interrupts;
//! - [`reference`](mod@reference): straight pieces interpolated per tick, with a
//!   feedforward preview of the axis' dead time;
//! - [`control`]: the loop law (open loop, P + feedforward, robust PID,
//!   servo PID) in fixed point, anti-windup, saturation, following error;
//! - [`tuning`]: Normey-Rico and relay (Ziegler–Nichols) gains, f32, main
//!   loop only; [`relay`]: the relay experiment, in the tick;
//! - [`output`]: step rate for stepper axes, H-bridge for DC axes, fault
//!   inputs with configurable polarity; [`axis`]: an encoder stepper axis.
//!
//! # Integration (for the executor and the board)
//!
//! **Units.** The loop counts in [`Units`]: for an NSE-5310 axis one unit is
//! one encoder count, 1/2048 mm ([`nse5310::UNITS_PER_MM`]); for a
//! quadrature axis one count. Velocities are units/s, stepper output is a
//! [`StepRate`](output::StepRate) (steps/s, Q24.8), servo output is duty.
//!
//! **Static state** (one `static` in a `Mutex<RefCell<…>>` on the AVR):
//! `ReferencePath<2, 4>` for X and Y, two [`EncoderAxis`], two
//! [`IndexDebouncer`](nse5310::IndexDebouncer)s, two
//! [`Nse5310`](nse5310::Nse5310)s on separate buses (both answer at 0x40).
//!
//! **Board tick** at `LOOP_HZ` (250 Hz on the Mega: every 4th tick of the
//! 1 kHz Timer3 clock, or its own timer; the period must be constant, the
//! gains are computed for it; SPEC §1's "one read per 1 mm" holds up to
//! 225 mm/s, see [`TrackerConfig::for_read_rate`]):
//! 1. read both encoders: `nse.read_raw()` → [`Reading::Raw`] or
//!    [`Reading::Failed`] (blocking embedded-hal I²C, ≈ 60 µs each at
//!    400 kHz: either do it in the main loop when the tick flag is set, or
//!    run the TWI from its interrupt and call steps 2–5 from the TWI
//!    interrupt when the second read completes);
//! 2. `edges = index_debouncer.take()` per axis (the Index pin's external
//!    interrupt calls `index_debouncer.on_edge(micros())`);
//! 3. `let refs = path.advance();`
//! 4. per axis `axis.tick(refs[i], reading, edges, DriverStatus { alarm,
//!    bridge_fault })` → `Ok(rate)`: hand `rate` to the stepper's velocity
//!    mode until the next tick; `Err(fault)`: set every closed-loop axis'
//!    rate to 0, `path.clear()`, `other_axis.controller.stop(fault)`, and
//!    post the fault (axis letter + [`AxisFault`]) to the main loop;
//! 5. nothing else: no division, no float, no 64-bit arithmetic, no
//!    allocation in steps 2–4.
//!
//! **Cost, measured** on simavr (ATmega2560 at 16 MHz, release build,
//! `-Os`, LTO): `EncoderAxis::tick` with the robust PID ≈ 2700 cycles
//! (≈ 170 µs: tracker ≈ 450, controller ≈ 2000, step scale ≈ 300; the
//! controller alone is ≈ 800 in open loop and ≈ 1050 with P + FF);
//! `ReferencePath<2, 4>::advance` ≈ 1000. X and Y at 250 Hz: ≈ 6400 cycles
//! per tick, 10 % of the CPU, plus the two I²C reads (≈ 60 µs each at
//! 400 kHz, on the bus, not the CPU, with an interrupt-driven TWI).
//! **RAM** on the AVR (`size_of`): `EncoderAxis` 95 B (tracker 38, loop
//! 53, scale 4), `ReferencePath<2, 4>` 153 B, `IndexDebouncer` 12 B: about
//! 360 B for the printer's X and Y. `QuadratureDecoder` 14 B,
//! `RelayAutotune` ≈ 40 B (only while tuning).
//!
//! **Executor (main loop):** while a closed-loop job runs, cut each `G1`
//! into pieces (≈ 0.5 mm, or per planner segment) and `path.push(end_units,
//! ticks)` while `path.free_slots() > 0` (keep ≥ the preview time queued);
//! `M400` waits for `path.is_idle()`. On a posted fault print
//! `fault.write_error(b'X', out)` (an `Error:` line), abort the job (flush
//! the queue, like `M410`) and refuse moves until `G28`. After `G28` call
//! `axis.rehome(home_units)` and `path.restart_at(...)`. `M112` stops the
//! axes through `controller.stop`. Tuning (`M821`) computes
//! [`LoopGains`] with
//! [`Strategy::loop_gains`](tuning::Strategy::loop_gains) in the main loop
//! and installs them with `controller.set_gains` inside a critical section
//! while the axis is idle.
//!
//! **DC servo axes (SPEC §5):** the A/B pin-change interrupt calls
//! `decoder.on_edge(a, b)`; the tick calls `controller.tick(ref,
//! Ok(decoder.count()), DriverStatus { alarm: false, bridge_fault:
//! bridge.fault() })` and `bridge.drive(duty)` (or `bridge.brake()` on
//! `Err`). Auto-tune: the tick runs a [`RelayAutotune`](relay::RelayAutotune)
//! instead of the controller and drives the bridge with its output; on
//! `Done` the main loop calls
//! [`relay_ziegler_nichols`](tuning::relay_ziegler_nichols) (Pu in seconds
//! = ticks / LOOP_HZ) and reports.
//!
//! # Proposed M-codes (free in Marlin; list `Cap:CLOSED_LOOP:1` in M115)
//!
//! | command | effect | reply (then `ok`) |
//! |---|---|---|
//! | `M820 [X0/1] [Y0/1]` | closed loop off/on per axis (no word: report) | `echo:Closed loop X:1 Y:1` |
//! | `M821 X S<0-3> [P<kp>] [G<γ>] [I<ki>] [D<kd>]` | strategy: S0 open loop, S1 P+FF (P, default 4.3), S2 robust PID (G, default 0.5), S3 servo PID (P I D) | `echo:X S2 G0.500 K0:5.0000 Kp:1.7157 Ti:0.1000 Td:0.0500 Tf:0.0500` |
//! | `M822 [X] [Y]` | encoder report | `echo:X enc:12.3456 ref:12.3400 err:-0.0056 idx:12 glitch:3 bounce:0 missed:0 bad:0 fault:none` |
//! | `M823 X E<mm> [T<s>]` | following-error limit and hold time | `echo:X following error 1.000 mm for 0.50 s` |
//! | `M824 X [T<θ s>] [L<preview s>]` | plant dead time for the tuner, feedforward preview | `echo:X theta 0.100 preview 0.100` |
//! | `M825 X S<d> [B<band>] [N<cycles>] [A1]` | relay auto-tune (servo axes); `A1` applies the gains | `echo:X relay d:127 a:10.00 Pu:0.200 Ku:16.1701 Kp:9.7021 Ki:97.0209 Kd:0.2426` |
//!
//! Bad values answer `Error:Value out of range for <letter>` (the
//! executor's existing error) and change nothing. Faults print
//! [`AxisFault::write_error`]'s line, e.g.
//! `Error:X following error 2.510 mm, job stopped (re-home with G28)`.

pub mod axis;
pub mod control;
pub mod nse5310;
pub mod output;
#[cfg(feature = "encoders")]
pub mod printer;
pub mod quadrature;
pub mod reference;
pub mod relay;
#[cfg(feature = "encoders")]
pub mod trace;
pub mod tuning;

pub use axis::{EncoderAxis, Reading};
pub use control::{AxisController, DriverStatus, FixedGains, FollowingErrorLimit, LoopGains, Reference, Q16};
pub use nse5310::{EncoderFault, LinearTracker, TrackerConfig};
pub use tuning::Strategy;

/// Positions in the loop: encoder units (1/2048 mm on an NSE-5310 axis).
pub type Units = i32;

/// Why a closed-loop axis stopped. Latched until re-homing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AxisFault {
    /// |reference − measured| stayed above the limit (lost steps, belt
    /// slip in open loop, jam): `error` in units.
    FollowingError { error: Units },
    /// A driver ALARM input is active (SPEC §3).
    DriverAlarm,
    /// The H-bridge's EN/DIAG line reports a fault (SPEC §5).
    BridgeFault,
    /// The encoder is stuck or gives no readings.
    Encoder(EncoderFault),
    /// Another axis faulted, or the host stopped everything.
    Stopped,
}

impl AxisFault {
    /// The `Error:` line for `axis` (its letter), with the error in mm for a
    /// following error (`units_per_mm`: 2048 on the NSE-5310 axes).
    pub fn write_error<W: ufmt::uWrite + ?Sized>(self, axis: u8, units_per_mm: i32, out: &mut W) -> Result<(), W::Error> {
        use crate::flash_str;
        // The texts stay in flash (on the AVR a `&str` literal costs SRAM).
        flash_str!("Error:").write_to(out)?;
        ufmt::uwrite!(out, "{}", char::from(axis))?;
        out.write_str(" ")?;
        match self {
            AxisFault::FollowingError { error } => {
                flash_str!("following error ").write_to(out)?;
                write_millimetres(out, error, units_per_mm)?;
                flash_str!(" mm").write_to(out)?;
            }
            AxisFault::DriverAlarm => flash_str!("driver ALARM").write_to(out)?,
            AxisFault::BridgeFault => flash_str!("motor bridge fault (EN/DIAG)").write_to(out)?,
            AxisFault::Encoder(EncoderFault::Stuck) => flash_str!("encoder stuck").write_to(out)?,
            AxisFault::Encoder(EncoderFault::NoReading) => flash_str!("encoder not responding").write_to(out)?,
            AxisFault::Stopped => flash_str!("stopped").write_to(out)?,
        }
        flash_str!(", job stopped (re-home with G28)\n").write_to(out)
    }
}

/// `units / units_per_mm` with three decimals, rounded (32-bit only: the
/// main loop of the AVR has no 64-bit division to spare).
fn write_millimetres<W: ufmt::uWrite + ?Sized>(out: &mut W, units: Units, units_per_mm: i32) -> Result<(), W::Error> {
    let per_mm = units_per_mm.unsigned_abs().clamp(1, 1 << 20);
    let magnitude = units.unsigned_abs();
    let mut whole = magnitude / per_mm;
    // remainder < 2^20, × 1000 < 2^30
    let mut fraction = ((magnitude % per_mm) * 1000 + per_mm / 2) / per_mm;
    if fraction >= 1000 {
        whole += 1;
        fraction -= 1000;
    }
    if units < 0 {
        out.write_str("-")?;
    }
    ufmt::uwrite!(out, "{}.", whole)?;
    if fraction < 100 {
        out.write_str("0")?;
    }
    if fraction < 10 {
        out.write_str("0")?;
    }
    ufmt::uwrite!(out, "{}", fraction)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::string::String;

    struct Out(String);
    impl ufmt::uWrite for Out {
        type Error = ();
        fn write_str(&mut self, s: &str) -> Result<(), ()> {
            self.0.push_str(s);
            Ok(())
        }
    }

    fn line(fault: AxisFault) -> String {
        let mut out = Out(String::new());
        fault.write_error(b'X', 2048, &mut out).unwrap();
        out.0
    }

    #[test]
    fn faults_print_an_error_line_that_stops_the_job() {
        assert_eq!(line(AxisFault::FollowingError { error: 5140 }), "Error:X following error 2.510 mm, job stopped (re-home with G28)\n");
        assert_eq!(line(AxisFault::FollowingError { error: -20 }), "Error:X following error -0.010 mm, job stopped (re-home with G28)\n");
        assert_eq!(line(AxisFault::DriverAlarm), "Error:X driver ALARM, job stopped (re-home with G28)\n");
        assert_eq!(line(AxisFault::BridgeFault), "Error:X motor bridge fault (EN/DIAG), job stopped (re-home with G28)\n");
        assert_eq!(line(AxisFault::Encoder(EncoderFault::Stuck)), "Error:X encoder stuck, job stopped (re-home with G28)\n");
    }
}
