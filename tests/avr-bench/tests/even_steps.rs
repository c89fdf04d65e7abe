//! Even steps across block boundaries on the real ELF (issue 23): a
//! cruise over a long move the firmware cuts into pieces and 30 collinear
//! 2 mm moves, with the serial, tick and ADC interrupts running, keeps
//! every interval within ±10 % of the median. Before the block set-up
//! moved to the main loop the first interval of every block was 1 460
//! cycles at any rate and this broke from 10 750 steps/s; before the
//! receive handler's part 1 was cut to ≈ 50 cycles, a byte arriving just
//! before a step broke it from ≈ 13 000.
//!
//! The ELF comes from `$FERROSTEP_ELF`, or is built once when missing.

use avr_bench::bench::{boot, even_trial, far_endstops};
use avr_bench::board::RampsConfig;
use avr_bench::build::mega2560_elf;

fn judged(axes: usize, rate_hz: f64) {
    let mut config = RampsConfig::stock(115_200);
    config.endstops = far_endstops();
    let mut board = boot(&mega2560_elf(), config).expect("the firmware boots");
    let trial = even_trial(&mut board, axes, rate_hz).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(trial.failure(), None, "{axes} axes at {rate_hz} steps/s: {:?}", trial.verdicts);
}

#[test]
fn one_stepper_steps_evenly_at_20000_per_s_across_block_boundaries() {
    judged(1, 20_000.0);
}

#[test]
fn three_steppers_step_evenly_at_20000_per_s_each_across_block_boundaries() {
    judged(3, 20_000.0);
}
