//! Relay auto-tune (Åström–Hägglund) for DC servo axes, SPEC §5.
//!
//! Runs in the loop tick in place of the controller: the output is ±d
//! around a bias, switching when the position leaves a noise band around
//! the set-point (hysteresis, so sensor noise cannot chatter the relay).
//! Each full cycle (from one switch to "+d" to the next) gives a period and
//! an amplitude a = (max − min)/2 of the position over the cycle, measured
//! the same way as d. When two successive cycles agree within 5 % in both
//! amplitude and period, the experiment is done and the main loop turns the
//! result into gains with [`relay_ziegler_nichols`](super::tuning::relay_ziegler_nichols).
//!
//! Integer only; 32 bytes of state. (The thermal auto-tune, when it lands,
//! can share this state machine: it knows nothing about positions.)

/// Result of a finished experiment, in the loop's own units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RelayResult {
    /// d: the relay amplitude (output units).
    pub relay_amplitude: i32,
    /// a: half the peak-to-peak oscillation of the measurement.
    pub oscillation_amplitude: i32,
    /// Pu in ticks.
    pub period_ticks: u32,
}

/// What the tick should do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RelayStep {
    /// Apply this output and call again next tick.
    Output(i32),
    /// Finished: stop the output (brake) and hand the result to the main loop.
    Done(RelayResult),
    /// No steady oscillation within the allowed cycles, or the position left
    /// the allowed excursion: stop the output.
    Failed,
}

#[derive(Clone, Copy, Debug)]
pub struct RelayAutotune {
    setpoint: i32,
    relay_amplitude: i32,
    bias: i32,
    noise_band: i32,
    max_excursion: i32,
    max_cycles: u8,
    high: bool,
    cycles: u8,
    tick: u32,
    cycle_start: u32,
    max: i32,
    min: i32,
    previous: Option<(i32, u32)>,
}

impl RelayAutotune {
    /// Oscillate around `setpoint` with output `bias ± relay_amplitude`,
    /// switching outside `±noise_band`; give up after `max_cycles` cycles or
    /// if the position strays more than `max_excursion` from the set-point.
    pub const fn new(setpoint: i32, relay_amplitude: i32, bias: i32, noise_band: i32, max_excursion: i32, max_cycles: u8) -> Self {
        Self {
            setpoint,
            relay_amplitude,
            bias,
            noise_band,
            max_excursion,
            max_cycles,
            high: true,
            cycles: 0,
            tick: 0,
            cycle_start: 0,
            max: i32::MIN,
            min: i32::MAX,
            previous: None,
        }
    }

    /// One tick with the measured position.
    pub fn tick(&mut self, measured: i32) -> RelayStep {
        self.tick = self.tick.wrapping_add(1);
        let error = self.setpoint.saturating_sub(measured);
        if error.unsigned_abs() > self.max_excursion.unsigned_abs() {
            return RelayStep::Failed;
        }
        self.max = self.max.max(measured);
        self.min = self.min.min(measured);
        if self.high && error < -self.noise_band {
            self.high = false;
        } else if !self.high && error > self.noise_band {
            self.high = true;
            if let Some(result) = self.cycle_completed() {
                return result;
            }
        }
        let output = if self.high { self.relay_amplitude } else { -self.relay_amplitude };
        RelayStep::Output(self.bias.saturating_add(output))
    }

    /// The relay just switched up: a cycle ended (the first one, from rest,
    /// is not representative and only starts the count).
    fn cycle_completed(&mut self) -> Option<RelayStep> {
        let period = self.tick.wrapping_sub(self.cycle_start);
        let amplitude = self.max.saturating_sub(self.min) / 2;
        let first = self.cycles == 0;
        self.cycles = self.cycles.saturating_add(1);
        self.cycle_start = self.tick;
        self.max = i32::MIN;
        self.min = i32::MAX;
        if first {
            return None;
        }
        if let Some((previous_amplitude, previous_period)) = self.previous {
            if within_5_percent(amplitude, previous_amplitude) && within_5_percent(period as i32, previous_period as i32) {
                return Some(RelayStep::Done(RelayResult {
                    relay_amplitude: self.relay_amplitude,
                    oscillation_amplitude: amplitude,
                    period_ticks: period,
                }));
            }
        }
        if self.cycles > self.max_cycles {
            return Some(RelayStep::Failed);
        }
        self.previous = Some((amplitude, period));
        None
    }
}

/// |a − b| ≤ 5 % of max(|a|, |b|), without division.
fn within_5_percent(a: i32, b: i32) -> bool {
    let difference = i64::from(a) - i64::from(b);
    let larger = i64::from(a.unsigned_abs().max(b.unsigned_abs()));
    difference.abs() * 20 <= larger
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An integrator with a dead time, ticked at 1 kHz: x += k·u per tick
    /// with u delayed by `delay` ticks.
    fn run(relay: &mut RelayAutotune, delay: usize, gain_per_tick: f64) -> RelayStep {
        let mut pending = std::collections::VecDeque::from(std::vec![0i32; delay]);
        let mut x = 0.0f64;
        for _ in 0..100_000 {
            match relay.tick(x.round() as i32) {
                RelayStep::Output(u) => {
                    pending.push_back(u);
                    x += gain_per_tick * f64::from(pending.pop_front().unwrap());
                }
                other => return other,
            }
        }
        panic!("no result");
    }

    #[test]
    fn an_integrator_with_dead_time_oscillates_at_four_dead_times() {
        // For k/s·e^(−θs) under a relay, Pu = 4θ and a = k·d·θ (no noise
        // band): θ = 50 ticks, k·d = 2 units per tick → Pu 200, a 100.
        let mut relay = RelayAutotune::new(0, 127, 0, 0, 10_000, 20);
        let RelayStep::Done(result) = run(&mut relay, 50, 2.0 / 127.0) else { panic!() };
        assert_eq!(result.relay_amplitude, 127);
        assert!((result.period_ticks as i32 - 200).abs() <= 4, "{result:?}");
        assert!((result.oscillation_amplitude - 100).abs() <= 3, "{result:?}");
    }

    #[test]
    fn stops_with_failed_when_the_axis_runs_away() {
        let mut relay = RelayAutotune::new(0, 100, 0, 0, 50, 20);
        // wrong sign: the plant moves away from the set-point
        let mut x = 0;
        let mut step = RelayStep::Output(0);
        for _ in 0..1000 {
            step = relay.tick(x);
            match step {
                RelayStep::Output(u) => x -= u / 10,
                _ => break,
            }
        }
        assert_eq!(step, RelayStep::Failed);
    }

    #[test]
    fn five_percent_agreement() {
        assert!(within_5_percent(100, 105));
        assert!(!within_5_percent(100, 106));
        assert!(within_5_percent(-100, -96));
    }
}
