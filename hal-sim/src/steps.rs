//! A step/direction recorder: what a logic analyser on the STEP and DIR pins
//! would see, on virtual time.
//!
//! Feed it every step-timer action (`step_mask`, `dir_mask`,
//! `next_interval_ticks`, the fields of the firmware's `TimerAction`, passed
//! as plain integers so that this file does not depend on the firmware's
//! types) and it keeps, per motor, the time and direction of every step, the
//! position, and the checks a driver would make: a direction change in the
//! same action as a step is a set-up violation.

/// One motor's record.
#[derive(Clone, Debug, Default)]
pub struct MotorTrace {
    /// Steps from the start, signed.
    pub position: i64,
    /// (time in ticks, +1 or −1) of every step.
    pub steps: Vec<(u64, i8)>,
}

impl MotorTrace {
    /// Times of the steps, ticks.
    pub fn times(&self) -> impl Iterator<Item = u64> + '_ {
        self.steps.iter().map(|s| s.0)
    }

    pub fn first_step(&self) -> Option<u64> {
        self.steps.first().map(|s| s.0)
    }

    pub fn last_step(&self) -> Option<u64> {
        self.steps.last().map(|s| s.0)
    }

    /// Shortest time between two steps, ticks.
    pub fn min_interval(&self) -> Option<u64> {
        self.steps.windows(2).map(|w| w[1].0 - w[0].0).min()
    }

    /// Speed in steps/s averaged over windows of `window` steps: (mid time
    /// in seconds, steps/s). Windows never span a reversal or a pause longer
    /// than `max_gap_ticks`.
    pub fn speeds(&self, window: usize, timer_hz: f64, max_gap_ticks: u64) -> Vec<(f64, f64)> {
        let mut out = Vec::new();
        let mut start = 0;
        while start + window < self.steps.len() {
            let slice = &self.steps[start..=start + window];
            let same_direction = slice.iter().all(|s| s.1 == slice[0].1);
            let no_gap = slice.windows(2).all(|w| w[1].0 - w[0].0 <= max_gap_ticks);
            if same_direction && no_gap {
                let span = (slice[window].0 - slice[0].0) as f64 / timer_hz;
                let mid = (slice[window].0 + slice[0].0) as f64 / 2.0 / timer_hz;
                out.push((mid, window as f64 / span));
            }
            start += window;
        }
        out
    }
}

/// The recorder.
#[derive(Clone, Debug)]
pub struct StepRecorder {
    /// Virtual time of the next action, ticks.
    pub now: u64,
    pub timer_hz: u32,
    /// Direction pin bits that are inverted by the wiring (pin high means
    /// negative for these motors). Before the first action every motor's
    /// logical direction is negative.
    pub dir_invert: u8,
    pub motors: [MotorTrace; 4],
    /// Actions that changed a direction pin while stepping that motor.
    pub setup_violations: usize,
    /// Every action seen.
    pub actions: usize,
    /// Keep every step's time in `motors[..].steps` (default); off, only
    /// positions and counts are kept (hour-long simulations).
    pub keep_steps: bool,
    /// Steps of each motor so far (kept even when `keep_steps` is off).
    pub step_counts: [u64; 4],
    last_dir: u8,
}

impl StepRecorder {
    pub fn new(timer_hz: u32, dir_invert: u8) -> Self {
        Self {
            now: 0,
            timer_hz,
            dir_invert,
            motors: Default::default(),
            setup_violations: 0,
            actions: 0,
            keep_steps: true,
            step_counts: [0; 4],
            last_dir: dir_invert,
        }
    }

    /// One action at the current time; time then moves on by its interval.
    pub fn record(&mut self, step_mask: u8, dir_mask: u8, next_interval_ticks: u16) {
        self.actions += 1;
        if (dir_mask ^ self.last_dir) & step_mask != 0 {
            self.setup_violations += 1;
        }
        self.last_dir = dir_mask;
        let logical = dir_mask ^ self.dir_invert;
        for (motor, trace) in self.motors.iter_mut().enumerate() {
            if step_mask & (1 << motor) != 0 {
                let sign = if logical & (1 << motor) != 0 { 1 } else { -1 };
                trace.position += sign as i64;
                self.step_counts[motor] += 1;
                if self.keep_steps {
                    trace.steps.push((self.now, sign));
                }
            }
        }
        self.now += next_interval_ticks as u64;
    }

    /// Seconds of virtual time.
    pub fn seconds(&self, ticks: u64) -> f64 {
        ticks as f64 / self.timer_hz as f64
    }

    pub fn positions(&self) -> [i64; 4] {
        [self.motors[0].position, self.motors[1].position, self.motors[2].position, self.motors[3].position]
    }

    /// Forget the steps (positions stay), e.g. between phases of a test.
    pub fn clear_steps(&mut self) {
        for trace in &mut self.motors {
            trace.steps.clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_positions_times_and_violations() {
        let mut recorder = StepRecorder::new(2_000_000, 0b10);
        recorder.record(0, 0b01, 100); // directions first: motor 0 +, motor 1 pin low = + (inverted)
        recorder.record(0b01, 0b01, 100);
        recorder.record(0b11, 0b01, 100);
        recorder.record(0b01, 0b00, 100); // direction change with a step: violation
        assert_eq!(recorder.positions(), [1, 1, 0, 0]);
        assert_eq!(recorder.setup_violations, 1);
        assert_eq!(recorder.motors[0].times().collect::<Vec<_>>(), [100, 200, 300]);
        assert_eq!(recorder.motors[0].min_interval(), Some(100));
        let speeds = recorder.motors[0].speeds(1, 2e6, 1000);
        assert_eq!(speeds[0].1, 20_000.0);
    }
}
