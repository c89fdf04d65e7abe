//! The machines that are not printers: the filament extrusion line
//! (SPEC §4) and the powder-bed retrofit (SPEC §5). Everything here is a
//! pure state machine or function, host-tested; `hal-sim` runs both
//! machines end to end (`extrusion_plant`, `powder_bed_plant`).
//!
//! - [`velocity`]: steppers at a set RPM (half periods in whole timer
//!   ticks, slew-limited ramp);
//! - [`diameter`]: the diameter loop (PI through [`diameter::PiLaw`],
//!   bumpless start, stale watchdog, manual/automatic modes);
//! - [`extrusion_line`]: screw + puller + diameter loop + cold-extrusion
//!   interlock;
//! - [`powder_bed`]: platform driver polarities, travel measurement, layer
//!   cycle, the no-heater reply;
//! - [`config`]: one configuration per machine, with its pin map.
//!
//! The executor runs them in `machine::line` and `machine::powder_bed`
//! (G-code, main-loop and 1 kHz duties), and the Mega 2560 wires them in
//! `boards/mega2560-ramps/src/line.rs` and `bed.rs` (features
//! `machine-extrusion-line`, `machine-powder-bed`). The notes below are the
//! design those follow; where they differ (the line's fans on D8 and its
//! step timers on Timer5, the carriage's X/Y moves from `G0`/`G1`, the
//! `M821`–`M825` carriage codes), the code and the README are current.
//!
//! # Integration (the design)
//!
//! ## Extrusion line (`machine-extrusion-line`)
//!
//! **State** (one `static`: 76 bytes on the host without the PI — two
//! steppers 20 each, the loop 36 —, 160 with the [`diameter::ClosedLoopPi`]
//! adapter, whose `AxisController` carries position-loop fields it does not need):
//! `ExtrusionLine<ClosedLoopPi>` built from
//! `config::extrusion_line(DriveTrain::PULLER_6_TO_1)`; set the thesis
//! gains once: `line.diameter.set_gains(THESIS_KP, THESIS_KI)`.
//! When the thermal module's PI lands, implement [`diameter::PiLaw`] for it
//! and use it instead of [`diameter::ClosedLoopPi`] (an adapter over the
//! closed-loop module's loop law, with a documented limitation).
//!
//! **Board, timers and pins.** Two compare channels of a 16-bit timer at
//! 2 MHz (16 MHz / 8), one per stepper (e.g. Timer1 OCR1A for the screw,
//! OCR1B for the puller; Timer3 stays the 1 kHz tick): on compare,
//! `if let Some(edge) = stepper.on_timer() { write STEP = edge.step_high;
//! OCRnx += edge.next_ticks } else { disable the compare interrupt }`.
//! Each call is one add and a shift; at the operating point (screw 10 rpm,
//! puller ≈ 4 rpm) that is 16 000 + 5 100 interrupts/s, at the limits
//! (20 and 15 rpm) 32 000 + 19 200. Pins (RAMPS): screw E0 STEP D26 DIR
//! D28 EN D24 (low = enabled), puller X STEP A0 DIR A1 EN D38; DIR is
//! constant (set once at start, `VelocityConfig::invert_direction`).
//! Barrel: SSR on D9 with the thermal module's slow PWM (200 ms, slots
//! ≥ 10 ms), thermistor A13 with 4.8 kΩ, PI Kp 2.4 Ki 0.008 (in
//! `ExtrusionLineMachine`); fans on D8, on at start.
//!
//! **Call order.**
//! 1. Every 20 ms (50 Hz, from the 1 kHz tick's flag, main loop), inside a
//!    critical section: `let (screw, puller) = line.update(&cfg)`; for each
//!    [`velocity::TimerChange::Start`]`{ first_ticks }` enable the driver,
//!    arm the compare `first_ticks` ahead and enable its interrupt; for
//!    `Stop` disable the interrupt (STEP low).
//! 2. Once per second (main loop): `let report = line.on_second(&barrel_check)`
//!    where `barrel_check` implements [`extrusion_line::ColdExtrusionCheck`]
//!    over the thermal module's cold-extrusion check (175 °C, `M302`);
//!    print `report.diameter` with `DiameterWarning::write` and
//!    `report.screw_stopped` with `ColdExtrusion::write_stopped`.
//! 3. Commands (below) call the matching method and print its reply.
//! 4. `M112`/`M410`/watchdog: `line.halt()` and act on both `Stop`s.
//!
//! **M-codes** (standard Marlin where one fits; each line then `ok`):
//!
//! | command | effect | reply |
//! |---|---|---|
//! | `M104 S<°C>` / `M109 S<°C>` | barrel setpoint (heater 0), `M109` waits | Marlin's |
//! | `M106 [S<0–255>]` / `M107` | fans on D8 | — |
//! | `M302 [S<°C>] [P0/1]` | cold-extrusion minimum (default 175) / override | Marlin's `echo:Cold extrudes are enabled (min temp 175C)` |
//! | `M3 S<rpm>` | screw speed (milli-RPM resolution, `S10.5`), ramped; refused while cold | refusal: `Error:Cold extrusion prevented: barrel 24.00 C, minimum 175.00 C (M302 P1 overrides)`; above 20 rpm `Error:Value out of range for S` |
//! | `M5` | screw stop (ramped) | — |
//! | `M4` | (reverse) refused | `Error:The screw does not run in reverse` |
//! | `M860 S<rpm>` | puller at a fixed speed (0, or 1–15), switches the puller to manual | `echo:Puller manual 5.000 rpm` |
//! | `M861 P<px>` or `D<mm>` | one camera measurement (px, e.g. `P132.9`, or mm) | none (just `ok`, once a second); implausible (< 0.5 mm or > 6 mm): `Error:Value out of range for P` |
//! | `M404 [W<mm>] [P<px>]` | diameter setpoint (Marlin: nominal filament width); no word: report | `echo:Diameter setpoint 2.850 mm (132.87 px)` |
//! | `M405` | automatic diameter control on (bumpless from the puller's speed) | `echo:Diameter control on` |
//! | `M406` | automatic off: the puller keeps its speed, manual | `echo:Diameter control off, puller 3.912 rpm` |
//! | `M407` | report | `echo:Diameter 2.851 mm (132.91 px) setpoint 2.850 mm (132.87 px) puller 3.912 rpm auto` (`ExtrusionLine::write_report`) |
//! | `M862 [P<kp>] [I<ki>]` | diameter PI gains, rpm/px and rpm/px per sample, both ≤ 0; no word: report | `echo:Diameter PI Kp:-0.0700 Ki:-0.0040` ; positive: `Error:Diameter gains must be <= 0 (reverse acting)` |
//! | `M863 S<s>` | stale-measurement watchdog, seconds (1–255) | `echo:Diameter watchdog 5 s` |
//! | watchdog (unsolicited) | no `M861` for 5 s in automatic | `echo:Diameter measurement stale (5 s), puller held at 3.878 rpm` |
//! | interlock (unsolicited) | barrel fell below the minimum with the screw turning | `Error:Barrel cooled to 170.00 C (minimum 175.00 C): screw stopped` |
//!
//! `M115`: `Cap:EXTRUSION_LINE:1`. The thesis' own dialect (`G20 XXX`
//! heater on, `G32` screw, `G42` puller, `G70`–`G79`) is not implemented:
//! it collides with G20/G21; if wanted, an explicit `M864 S1`
//! compatibility mode could map it onto the calls above.
//!
//! ## Powder bed (`machine-powder-bed`)
//!
//! **State**: `TravelMeasurement` (≈ 16 bytes, one at a time),
//! `LayerCycle` (≈ 32 bytes), the closed-loop module's two servo axes
//! (`AxisController` + `QuadratureDecoder` + `HBridge` each).
//! Configuration: `config::powder_bed()`.
//!
//! **Board**: platform steppers through `PlatformDriver` (M542: ENA low =
//! enabled, STEP idle high, the step is the falling edge, pulse ≥ 5 µs;
//! DIR high = down, set ≥ 5 µs before the edge); reed switches read with
//! `PlatformSwitches::from_levels(lower, upper, machine.switch_active)`;
//! carriage sensors C−/C+ (active low); roller and suction are on/off
//! outputs (D10, D8 MOSFETs); the carriage servo loop at 1 kHz as in the
//! closed-loop module's notes (pin-change/INT interrupts for A/B).
//!
//! **Travel measurement** (`M880 [F] [B]`, blocking with busy keep-alive):
//! per platform, at 1 kHz (the tick): `match routine.tick(&limits,
//! switches) { Step(dir) => pulse, Wait => {}, Finished | Failed => done }`,
//! then `write_travel_report(platform, routine.report(&driver).unwrap(), out)`:
//! `echo:Feed platform travel 40000 steps 200.000 mm` or
//! `Error:Feed platform travel: upper switch (B) not found`.
//!
//! **Layer cycle** (`M881 [L<mm>] [N<layers>]`, default 0.1 mm, 1 layer;
//! blocking with busy keep-alive): `let mut cmd = cycle.start(&feed, &build,
//! carriage_at)`; execute `cmd` (roller, suction, carriage stroke until
//! its sensor trips, platform steps at 1 kHz), then
//! `cmd = cycle.on_event(Done | CarriageArrived(end) | Failed)` until
//! `Finished { layer }` (print `echo:Layer <n> done`) or `Aborted(fault)`
//! (roller and suction off, carriage braked: `Error:Layer cycle aborted`).
//! A stroke that has not reached its sensor within the configured length,
//! a bridge fault or a following error answers `Failed`. `M112`/`M410`
//! answer `Failed` too.
//!
//! **Other codes**: `M3`/`M5` roller on/off (spindle), `M10`/`M11` suction
//! on/off (Marlin's air evacuation), `M882 S0`/`S1` carriage to C−/C+.
//! `M104`/`M109`/`M140`/`M190` answer at once, never block:
//! `echo:M109 ignored: this machine has no heaters` (then `ok`;
//! [`powder_bed::write_no_heaters`]). `M115`: `Cap:POWDER_BED:1`.
//!
//! ## The display
//!
//! [`crate::drivers::hd44780`] on the Smart Controller header pins (RS D16,
//! E D17, D4–D7 D23/D25/D27/D29): `init` once at boot (≈ 60 ms), then
//! `show(&format_status(...))` from the main loop at 1–2 Hz (≈ 2 ms of
//! blocking delays; never in an interrupt).

pub mod config;
pub mod diameter;
pub mod extrusion_line;
pub mod powder_bed;
pub mod velocity;
