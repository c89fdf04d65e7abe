//! What may interrupt what: every interrupt handler of this board, in one
//! place. The files of the handlers keep the comments on their own code;
//! the facts about priority, nesting, sharing and cost are stated here.
//!
//! # Priority
//!
//! The AVR has no priority levels. A handler runs with interrupts off
//! unless it turns them on itself (`sei`); when several interrupts are
//! pending at that moment, the one with the lowest vector number is taken
//! first. So "priority" below only orders pending requests; what really
//! decides a step's lateness is how long each handler (and the main loop)
//! keeps interrupts off.
//!
//! | vector | source | handler | builds | interrupts inside |
//! |---:|---|---|---|---|
//! | 1, 2 | INT0, INT1: carriage Y encoder A/B, any edge | `bed.rs` `INT0`, `INT1` | powder bed | off throughout |
//! | 5, 6 | INT4, INT5: carriage X encoder A/B, any edge | `bed.rs` `INT4`, `INT5` | powder bed | off throughout |
//! | 11 | PCINT2: NSE-5310 Index lines on PK1/PK2 (A9/A10) | `encoders.rs` `PCINT2` | encoder loops | off throughout |
//! | 17 | TIMER1_COMPA: the step interrupt, Timer1 at 2 MHz | `stepping.rs` `TIMER1_COMPA`, cold path `ferrostep_step_cold` | printers (`motion`) | off, except in the general path's window |
//! | 25 | USART0_RX: receive complete, the host link | `serial.rs` `__vector_25` (assembly) or `USART0_RX` (encoder builds), part 2 `ferrostep_rx_drain` | every build | part 1 off, part 2 on |
//! | 29 | ADC: conversion complete, the thermistors | `adc.rs` `__vector_29` | every build | on from the first instruction |
//! | 32 | TIMER3_COMPA: the 1 kHz tick | `clock.rs` `__vector_32` | every build | on from the first instruction, off in its critical section |
//! | 47, 48 | TIMER5_COMPA/B: screw and puller STEP edges | `line.rs` `TIMER5_COMPA`, `TIMER5_COMPB` | extrusion line | off throughout |
//!
//! No other vector is enabled: the watchdog resets (no `WDT` interrupt),
//! the PWM timers (Timer2, Timer4, Timer5 in the powder bed) and the TWI
//! run without interrupts, and transmitting is polled from the main loop.
//!
//! # Nesting: who turns interrupts on, and who masks whom
//!
//! - **Step interrupt (17).** Interrupts off for an ordinary event, a
//!   segment change and a block change in the same directions (all inline
//!   in the handler). Only the general path (start from idle, long wait, direction
//!   change's lead, end of the queue) turns them on, after switching its
//!   own source off (OCIE1A, so it cannot re-enter) and, in encoder builds,
//!   the tick's (`clock::hold_tick` … `clock::release_tick`): in that
//!   window the receive, ADC and (without encoders) tick handlers may run.
//!   None of them touches the generator. `stepping::stop_timer` (kill,
//!   panic) leaves OCIE1A off even if it is called inside the window.
//! - **Receive (25).** Part 1, interrupts off, moves the byte (and the
//!   overrun flag) into the `RAW` buffer, then turns interrupts on.
//!   Part 2 (`serial::drain`) runs only in a run of the handler that
//!   finds `DRAINING` clear, and feeds the bytes to the ring one by one
//!   with interrupts on (off ≈ 30 cycles a byte, to take it from `RAW`);
//!   the step interrupt and further receive runs nest inside it. It
//!   returns with interrupts on (encoder builds: off), so the register
//!   restores and `reti` of both parts do not hold a step up. The receive
//!   source stays enabled except while `RAW` is full. In encoder builds
//!   part 2 masks the tick (`clock::hold_tick`) before `sei`.
//! - **ADC (29) and tick (32).** `avr-non-blocking-interrupt`: `sei` is
//!   the first instruction, so a step is never held up by their entry.
//!   Neither can re-enter itself (1 ms between two runs). The tick keeps
//!   interrupts off only for its millisecond count and, in the powder-bed
//!   and SSR builds, for `bed::on_tick` / `ssr::on_tick` inside the same
//!   critical section; in encoder builds it then runs the loops
//!   (`encoders::on_tick`, I²C reads) with interrupts on.
//! - **The tick's mask (OCIE3A)** is the one interrupt source switched off
//!   by others: the step interrupt's window and receive part 2 (encoder
//!   builds, `hold_tick`/`release_tick`, which put back what they found),
//!   and the main loop around the encoder loops (`encoders::with_loops`,
//!   `clock::mask_tick`). A tick due meanwhile runs when unmasked.
//! - **PCINT2, INT0/1/4/5, TIMER5_COMPA/B** keep interrupts off to their
//!   `reti`.
//!
//! # What each handler shares with the main loop, and how
//!
//! | handler | shared data | how |
//! |---|---|---|
//! | step (17) | `GENERATOR` (step queues' generator end), `DIR_LEVELS`, `TIMER_STOPPED` | the queue is a single-producer/single-consumer ring split once before `sei` (`StepQueues::split`); the rest the main loop touches only in critical sections (short ones: `stepping::status` takes a field or two per lock) |
//! | step (17) | PORTF, PORTA (STEP/DIR bits next to enable bits) | the main loop writes those ports only with interrupts off (`pins::make_output`) |
//! | receive (25) | receive ring (`RX_PRODUCER` end), `RX_TROUBLE`, `EMERGENCIES` | lock-free SPSC ring, producer end here, consumer in the main loop; the flags in critical sections; `M112` stops the timers here, with interrupts off |
//! | ADC (29) | `SAMPLING` (the averagers) | the main loop takes each channel's sum in its own critical section (`adc::Readings::take`) |
//! | tick (32) | `MILLIS`; powder bed: `bed` state; SSR/extrusion line: `ssr` windows | `Mutex<Cell>` in a critical section, on both sides |
//! | tick (32), encoder builds | the encoder loops (`encoders::ACTIVE`, loop state) | the main loop masks the tick (`encoders::with_loops`), not every interrupt |
//! | PCINT2 (11) | `LAST_PINK`, the Index debouncers | critical section, the tick reads them the same way |
//! | INT0/1/4/5 | the quadrature decoders | `Mutex<RefCell>` in a critical section |
//! | TIMER5 (47, 48) | `line::STEPPERS` (each motor's copy) | `Mutex<RefCell>`; the main loop updates them in critical sections |
//!
//! # Longest paths, in cycles at 16 MHz (measured)
//!
//! All figures from simavr with the real ELF. "Own" is a handler's run
//! from its vector (the 5-cycle entry included) to `reti`, with the runs
//! of handlers nested in it taken out; "run" includes them. Source: the
//! bench's `isr_episodes` example (`tests/avr-bench/examples`, figures of
//! `Board::isr_own_longest` and `Board::isr_intervals`), on the ELFs of
//! commit 6df559b (the machine code of every handler is unchanged since:
//! the named register writers compile to the same instructions):
//!
//! - default build (`prusa-i3.toml`), `-- ELF 115200 --segments 120 0.5
//!   M105` (the bench's spiral of half-millimetre segments);
//! - extrusion line, `"M302 P1" "M3 S10" "M860 S4" "G4 P1500" M407`;
//! - powder bed, `M3 M822 "G1 X5 Y5 F600" "G4 P500" M822`;
//! - encoder build (`prusa-i3.toml` with `[encoders] enabled = true`),
//!   `--nse5310`, the same segments, with `M105` (loops off) or
//!   `"M820 X1 Y1" M822` (loops on).
//!
//! | vector | build | own | run | with interrupts off |
//! |---:|---|---:|---:|---|
//! | 17 step | default | 1 551 | 1 771 | ordinary event ≈ 240–260, next segment ≈ 340–360, next block in the same directions 400–420 (`docs/step-timing.md`, `even_steps diag`, on this branch's ELF); the 1 551 is the general path (start from idle, direction change), whose window has interrupts on |
//! | 25 receive | default | 643 | 1 627 | part 1 ≈ 43 to its `sei`, part 2 ≈ 30 a byte (`docs/step-timing.md`) |
//! | 25 receive | extrusion line, powder bed | 643 | 1 074 | as above |
//! | 29 ADC | default / extrusion line / powder bed | 159 / 162 / 151 | 1 361 / 1 044 / 151 | none (`sei` first) |
//! | 32 tick | default | 78 | 1 171 | part of the 78 (its critical section) |
//! | 32 tick | extrusion line (SSR windows) | 360 | 1 277 | most of the 360 (`ssr::on_tick` in the critical section) |
//! | 32 tick | powder bed | 1 247 | 1 381 | most of the 1 247 (`bed::on_tick`, the carriage's servo loop, in the critical section) |
//! | 47 screw / 48 puller | extrusion line | 462 / 420 | 462 / 420 | all |
//! | 17 step | encoder build | 2 320 | 2 320 | the general path (tick masked, window on) |
//! | 25 receive | encoder build | 680 | 2 078 | the compiler's part 1, ≈ 110–150 to `sei` (`docs/step-timing.md`) |
//! | 32 tick | encoder build, loops off / on (`M820 X1 Y1`) | 212 / 13 726 | 1 722 / 20 525 | within 212 (loops off); the loops run with interrupts on |
//! | 11 PCINT2 | encoder build (the bench's NSE-5310 pair) | 656 | 656 | all |
//! | 1, 2, 5, 6 | powder bed | not measured: the bench does not drive the carriage's encoder pins | | all |
//!
//! The bench's own figures for the step interrupt (`cargo benchmark`,
//! `docs/benchmarks.md`): `step_isr_longest_path_cycles` 1 603 (a run of
//! the general path, nested handlers included, in the chord stream; the
//! longest run while cruising over block boundaries is ≈ 420, see
//! `docs/step-timing.md`; 2 178 before issue 23), 16.1 % of the CPU in handlers at
//! 10 000 steps/s. The main loop's longest interrupt lock seen in the
//! default run was 106 cycles (`pins::make_output`), 120 in the powder bed
//! and 910 in the extrusion line's main loop.
