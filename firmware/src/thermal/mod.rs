//! Temperatures and heaters: thermistors, PID/bang-bang control, SSR
//! time-proportioning, relay auto-tune, and the protections.
//!
//! Integer only (no float anywhere in this module), no allocation, nothing
//! that runs in an interrupt except [`SampleAverager::push`].
//!
//! | module | what |
//! |---|---|
//! | [`thermistor`] | build-time β tables (54 non-uniform rows, ≤ 0.1 °C from 0 to 300 °C), [`SampleAverager`], open/short thresholds |
//! | [`pid`] | [`Gains`] in Marlin's units (× 10⁴), the fixed-point PID (conditional integration, derivative on the measurement), bang-bang |
//! | [`output`] | [`OutputMode`]: hardware PWM duty, or [`SlowPwm`] time-proportioning for SSRs (200 ms, slots ≥ 10 ms) |
//! | [`autotune`] | `M303` relay auto-tune (Åström–Hägglund, Ziegler–Nichols), [`relay_gains`] |
//! | [`guard`] | [`HeaterGuard`]: sensor open/short, MAXTEMP/MINTEMP, thermal runaway, heating failed; [`ColdExtrusionGuard`] (`M302`) |
//! | [`channel`] | [`HeaterChannel`]: one heater, reading → guard → law → duty |
//! | [`report`] | `M105` line, [`AutoReport`] (`M155`), [`TemperatureWait`] (`M109`/`M190`) |
//!
//! # Integration note (for the executor and the boards)
//!
//! **Ownership.** The executor (`Machine`) owns one [`HeaterChannel`] per
//! heater — `HeaterChannel::new(&channel::HOTEND_0, Gains::MARLIN_HOTEND)`,
//! `HeaterChannel::new(&channel::BED, Gains::MARLIN_BED)` (or `BED_BANG_BANG`;
//! SPEC §2's slow bed wants `GuardConfig::SLOW_BED` in its own flash
//! config), for the extrusion line `&channel::BARREL` with
//! `Gains::THESIS_BARREL` — plus a [`ColdExtrusionGuard`] (`HOTEND`, or
//! `EXTRUSION_LINE` at 175 °C). A config is a `static Flash<HeaterConfig>`
//! (see [`HeaterConfig`]). The channels replace `Machine::{hotend, bed}:
//! Heater` (use [`HeaterChannel::heater`] where a [`Heater`] snapshot is
//! wanted; `Celsius`, `Heater`, `thermistor::celsius_from_adc` and the
//! `NTC100K_B3950_4K7`/`_4K8` tables keep their names).
//!
//! **ADC interrupt (board).** One [`SampleAverager`] per thermistor
//! (`SampleAverager::new(16)`; 10 for SPEC §4): on each conversion,
//! `averager.push(adc_10_bit)`, then start the next channel. Nothing else.
//!
//! **Main loop (board → core), every `config().sample_period_ms`** (100 ms
//! for all stock configs; the barrel's PI runs every 10th sample, T = 1 s,
//! inside the channel):
//! ```text
//! let reading = critical_section(|| averager.take());        // Option<Oversampled>
//! if let Some(reading) = reading {
//!     if let Some(fault) = channel.on_sample(reading) {       // once, when it latches
//!         fault.write(channel.id(), out)?;                    // "Error:Thermal Runaway, system stopped! Heater_ID: 0"
//!         machine.kill(out)?;                                 // "Error:Printer halted. kill() called!", stop motion,
//!     }                                                       //  every heater .turn_off()
//! }
//! ```
//! A missing reading (no `take()` for several periods) is the board's
//! problem to treat as a fault; the watchdog covers a hung loop.
//!
//! **Outputs (board), every loop pass:** `HardwarePwm` →
//! `pwm::set(pin, channel.duty())` (0 while faulted or off).
//! `TimeProportioning(t)` → `pin.set(slow.level(&t, now_ms, channel.duty()))`
//! with one [`SlowPwm`] per SSR heater, called at least every millisecond
//! (or from the 1 kHz tick); on halt `slow.stop()` and the pin low. When
//! the machine is halted the board forces every heater pin low anyway.
//!
//! **G-code (executor):**
//! - `M104 S<°C>` / `M140 S<°C>`: `channel.set_target(Celsius)` → `Ok(applied)`
//!   (clamped to `max_c − margin`, Marlin's behaviour) or `Err(fault)` when
//!   latched (refuse with the fault's line).
//! - `M109 S|R<°C>` / `M190 S|R`: set the target, then
//!   `TemperatureWait::new(WaitConfig::HOTEND|BED, target, r_given, now)`
//!   and `poll(now, channel.measured())` every loop: `Waiting(w)` → once a
//!   second print the `M105` line without `\n` plus ` W:<w>` / ` W:?`
//!   (Marlin), `Reached`/`CoolingStalled` → `ok`, `TimedOut` → an
//!   `Error:` line and `ok`. `M108` ends the wait.
//! - `M105`: `ok ` then [`write_temperatures`]`(&hotend, Some(&bed), out)`.
//! - `M155 S<n>`: [`AutoReport::set_interval`]; every loop
//!   `if auto.due(now) { write_temperatures(..) }`.
//! - `M301 P I D` (E0): `Gains::new(p.to_scaled(4), i.to_scaled(4), d.to_scaled(4))`
//!   (missing letters keep `channel.gains()`'s values) → `set_gains`;
//!   bare `M301` / `M503`: `echo:` + [`Gains::write_m301`]. Gains are
//!   Marlin's units (Ki per second, Kd in seconds) whatever the sample
//!   period: the law converts with it. Save them in the settings as the
//!   three `u32` of [`Gains`].
//! - `M303 E<n> S<°C> C<cycles> U<0|1>`: `let mut tune = Autotune::new(
//!   TuneConfig { cycles, ..TuneConfig::new(target, channel.config().sample_period_ms) })`
//!   (bed: `E-1`), print `PID Autotune start`, `channel.start_tuning(&tune)`,
//!   then each sample `channel.on_tuning_sample(reading, &mut tune)` in place
//!   of `on_sample`: `Cycle` → `tune.last_cycle().write(out)`;
//!   `Done(result)` → `result.write_finished(channel.id(), out)`, and on
//!   `U1` `channel.set_gains(result.gains)`; `Failed(e)` → `e.write(out)`;
//!   `Fault(f)` → as for `on_sample`. The executor keeps answering
//!   `busy: processing` meanwhile (Marlin blocks on M303 too). A slow bed
//!   needs `timeout_s` above its heat-up time (SPEC §2's: 3000).
//! - `M302 [S<°C>] [P<0|1>]`: `cold.m302(s, p)`; `true` → `cold.write_state(out)`.
//!   Before an extruding move: `cold.check(hotend.measured())`; `Err` →
//!   `ColdExtrusionGuard::write_prevented(out)` and drop the E part of the
//!   move (Marlin). The extrusion line takes a [`ColdExtrusionReading`]
//!   (it implements `machines::extrusion_line::ColdExtrusionCheck`).
//! - `M112`/`kill()`: `channel.turn_off()` on every heater; `M999` (reset):
//!   `channel.clear_fault()`.
//!
//! **RAM (AVR, packed).** `HeaterChannel` 44 bytes (a compile-time
//! assertion keeps it there); its 28-byte `HeaterConfig` stays in flash
//! ([`channel::HOTEND_0`], [`channel::BED`], [`channel::BARREL`]…, copied
//! out per sample). `SampleAverager` 7, `SlowPwm` 7, `AutoReport` 5,
//! `ColdExtrusionGuard` 5; `Autotune` 76 and `TemperatureWait` 34 only
//! while `M303`/`M109` run (in the executor's running-command state, which
//! can share one slot: they never run together). Strings are in flash
//! ([`flash_str!`](crate::flash_str)).
//!
//! **Flash (AVR, measured with a stand-alone harness driving a hot end and
//! a bed through every call above, `opt-level = "s"`, LTO):** ≈ 8.6 KiB
//! beyond what the firmware already links (u32 division, `ufmt` integers,
//! `write_fixed`, `FlashStr`), of which ≈ 2 KiB is the harness's own
//! executor-like glue; the two 54-row tables 216 bytes each (a build links only the ones its configurations name). `M303`
//! (auto-tune, gains, its messages) adds ≈ 6 KiB and is linked only if the
//! executor calls it. No float, no 64-bit division, no `checked_mul`.

pub mod autotune;
pub mod channel;
pub mod guard;
mod math;
pub mod output;
pub mod pid;
pub mod report;
pub mod thermistor;

pub use autotune::{relay_gains, Autotune, TuneConfig, TuneError, TuneResult};
pub use channel::{HeaterChannel, HeaterConfig, TuneProgress};
pub use guard::{ColdExtrusionGuard, ColdExtrusionReading, GuardConfig, HeaterGuard, ThermalFault};
pub use output::{OutputMode, SlowPwm, TimeProportioning};
pub use pid::{Control, Gains, Law};
pub use report::{write_temperatures, AutoReport, TemperatureWait, WaitConfig, WaitStatus};
pub use thermistor::{CompletedSum, Oversampled, SampleAverager, Thermistor};

/// A temperature in hundredths of a degree Celsius (`21050` is 210.50 °C):
/// exact decimal printing, and integer arithmetic on every board.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub struct Celsius(pub i32);

impl Celsius {
    pub const fn from_degrees(degrees: i32) -> Self {
        Self(degrees * 100)
    }
}

impl ufmt::uDisplay for Celsius {
    fn fmt<W: ufmt::uWrite + ?Sized>(&self, f: &mut ufmt::Formatter<'_, W>) -> Result<(), W::Error> {
        crate::reply::write_fixed(f, self.0, 2)
    }
}

/// `a − b`, saturating. For a bound `c ≥ 0` (not near `i32::MIN`),
/// `a > b.saturating_add(c)` ⟺ `excess(a, b) > c` and
/// `a < b.saturating_sub(c)` ⟺ `excess(a, b) < −c`, exactly (also where
/// the bounds saturate): one subtraction for several comparisons.
#[inline(never)]
pub(crate) fn excess(a: Celsius, b: Celsius) -> i32 {
    a.0.saturating_sub(b.0)
}

/// `seconds` in milliseconds (one multiplication for every timer).
#[inline(never)]
pub(crate) fn millis(seconds: u16) -> u32 {
    u32::from(seconds) * 1000
}

/// Which heater, as Marlin names it in messages (`Heater_ID: 0`,
/// `Heater_ID: bed`) and in `M303 E` (`E-1` is the bed, `E-2` the chamber).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeaterId {
    /// Hot end (or the extrusion line's barrel) number n.
    Hotend(u8),
    Bed,
    Chamber,
}

impl ufmt::uDisplay for HeaterId {
    fn fmt<W: ufmt::uWrite + ?Sized>(&self, f: &mut ufmt::Formatter<'_, W>) -> Result<(), W::Error> {
        match self {
            Self::Hotend(n) => ufmt::uwrite!(f, "{}", crate::reply::Whole((*n).into())),
            Self::Bed => f.write_str("bed"),
            Self::Chamber => f.write_str("chamber"),
        }
    }
}

/// What is known about one heater: measured and target temperature, and the
/// power applied (0–127, Marlin's `@:` scale).
#[derive(Clone, Copy, Debug, Default)]
pub struct Heater {
    pub measured: Celsius,
    pub target: Celsius,
    pub power: u8,
}

impl Heater {
    pub const fn new() -> Self {
        Self { measured: Celsius(0), target: Celsius(0), power: 0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn excess_compares_like_the_saturated_bounds() {
        let values = [i32::MIN, i32::MIN + 1, i32::MIN + 2_999, i32::MIN + 3_000, i32::MIN + 3_001, -100_000, -1, 0, 1, 2_999, 3_000, 20_000, i32::MAX - 3_001, i32::MAX - 3_000, i32::MAX - 1, i32::MAX];
        for a in values {
            for b in values {
                for c in [0, 1, 30, 400, 3_000, 25_900, 32_767] {
                    let e = excess(Celsius(a), Celsius(b));
                    assert_eq!(a > b.saturating_add(c), e > c, "{a} > {b} + {c}");
                    assert_eq!(a < b.saturating_sub(c), e < -c, "{a} < {b} - {c}");
                    assert_eq!(a >= b.saturating_sub(c), e >= -c, "{a} >= {b} - {c}");
                }
            }
        }
    }
}
