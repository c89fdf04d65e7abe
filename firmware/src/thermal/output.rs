//! Heater outputs: the duty goes either to a hardware PWM compare register
//! (MOSFET outputs: the duty value 0–255 as is) or, for solid-state relays,
//! through [`SlowPwm`], a time-proportioning window driven by a
//! millisecond clock.
//!
//! # Time-proportioning (SPEC §4)
//! A window of `period_ms` (200 ms) is on for `duty/255` of its length,
//! then off. The duty is latched at each window start, so every on and off
//! slot lasts at least `min_slot_ms` (10 ms, a zero-crossing SSR needs
//! whole mains half-cycles):
//! - duty at or below `min_slot/period` (5 %: duty ≤ 12) → off all window;
//! - duty at or above `1 − min_slot/period` (95 %: duty ≥ 243) → on all window;
//! - otherwise on for `duty·period/255` ms (rounded), kept within
//!   `[min_slot, period − min_slot]`.
//!
//! A new duty takes effect at the next window, at most one period later
//! (200 ms, well inside the 1 s the protections allow). When the board must
//! switch off at once (halt, watchdog), it calls [`SlowPwm::stop`].

/// Window and shortest slot of a time-proportioning output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimeProportioning {
    pub period_ms: u16,
    pub min_slot_ms: u16,
}

impl TimeProportioning {
    /// SPEC §4: 200 ms window, slots of at least 10 ms.
    pub const SSR: TimeProportioning = TimeProportioning { period_ms: 200, min_slot_ms: 10 };

    /// On-time in a window for `duty` (0–255).
    pub fn on_ms(&self, duty: u8) -> u16 {
        let period = u32::from(self.period_ms);
        let slot = u32::from(self.min_slot_ms).min(period / 2);
        let scaled = u32::from(duty) * period;
        if scaled <= slot * 255 {
            return 0;
        }
        if scaled >= (period - slot) * 255 {
            return self.period_ms;
        }
        ((scaled + 127) / 255).clamp(slot, period - slot) as u16
    }
}

/// Where a heater's duty goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputMode {
    /// Hardware PWM (the duty into a compare register, e.g. OC2A for D10,
    /// OC4C ≥ 4 kHz for D8 behind a triac RC filter, SPEC §2).
    HardwarePwm,
    /// A pin switched by [`SlowPwm`] (solid-state relay).
    TimeProportioning(TimeProportioning),
}

/// The state of one time-proportioning output: 7 bytes.
#[derive(Clone, Copy, Debug)]
pub struct SlowPwm {
    window_start_ms: u32,
    on_ms: u16,
    running: bool,
}

impl Default for SlowPwm {
    fn default() -> Self {
        Self::new()
    }
}

impl SlowPwm {
    pub const fn new() -> Self {
        Self { window_start_ms: 0, on_ms: 0, running: false }
    }

    /// The pin level at `now_ms` (call at least every millisecond for
    /// exact slots; coarser calls round slots to the call interval).
    /// `duty` is the controller's latest output; it is latched when a
    /// window starts.
    pub fn level(&mut self, timing: &TimeProportioning, now_ms: u32, duty: u8) -> bool {
        let period = u32::from(timing.period_ms.max(1));
        let elapsed = now_ms.wrapping_sub(self.window_start_ms);
        if !self.running || elapsed >= period {
            // Windows follow each other back to back; after a stall (or
            // at the start) a new one starts now.
            self.window_start_ms = if self.running && elapsed < 2 * period { self.window_start_ms.wrapping_add(period) } else { now_ms };
            self.on_ms = timing.on_ms(duty);
            self.running = true;
        }
        now_ms.wrapping_sub(self.window_start_ms) < u32::from(self.on_ms)
    }

    /// Off now; the next [`level`](Self::level) starts a fresh window.
    pub fn stop(&mut self) {
        *self = Self::new();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SSR: TimeProportioning = TimeProportioning::SSR;

    #[test]
    fn five_percent_and_below_is_off_and_ninety_five_and_above_is_on() {
        // 5 % of 255 is 12.75: duty 12 is ≤ 5 %, 13 is above.
        assert_eq!(SSR.on_ms(0), 0);
        assert_eq!(SSR.on_ms(12), 0);
        assert_eq!(SSR.on_ms(13), 10); // 10.2 ms
        // 95 % of 255 is 242.25: 242 is below (189.8 ms on, 10.2 off), 243 is full.
        assert_eq!(SSR.on_ms(242), 190);
        assert_eq!(SSR.on_ms(243), 200);
        assert_eq!(SSR.on_ms(255), 200);
        assert_eq!(SSR.on_ms(128), 100); // 100.4 ms
    }

    #[test]
    fn every_duty_gives_slots_of_at_least_ten_ms() {
        for duty in 0..=255u8 {
            let on = SSR.on_ms(duty);
            assert!(on == 0 || on == 200 || (10..=190).contains(&on), "duty {duty}: {on} ms");
        }
    }

    /// Run `duties` (one per window) at 1 ms and return the (level, length)
    /// of every slot.
    fn slots(duties: &[u8]) -> std::vec::Vec<(bool, u32)> {
        let mut pwm = SlowPwm::new();
        let mut slots: std::vec::Vec<(bool, u32)> = std::vec::Vec::new();
        for now in 0..200 * duties.len() as u32 {
            let duty = duties[(now / 200) as usize];
            let level = pwm.level(&SSR, 1000 + now, duty);
            match slots.last_mut() {
                Some((last, length)) if *last == level => *length += 1,
                _ => slots.push((level, 1)),
            }
        }
        slots
    }

    #[test]
    fn a_window_is_on_for_the_duty_then_off() {
        assert_eq!(slots(&[128, 128]), [(true, 100), (false, 100), (true, 100), (false, 100)]);
        assert_eq!(slots(&[13]), [(true, 10), (false, 190)]);
        assert_eq!(slots(&[12, 255, 243, 0]), [(false, 200), (true, 400), (false, 200)]);
    }

    #[test]
    fn any_sequence_of_duties_keeps_every_inner_slot_at_least_ten_ms() {
        let duties: std::vec::Vec<u8> = (0..200u32).map(|i| ((i * 97 + i * i * 13) % 256) as u8).collect();
        let slots = slots(&duties);
        // The last slot may be cut by the end of the run.
        for (level, length) in &slots[..slots.len() - 1] {
            assert!(*length >= 10, "{level} slot of {length} ms in {slots:?}");
        }
    }

    #[test]
    fn a_new_duty_waits_for_the_next_window() {
        let mut pwm = SlowPwm::new();
        assert!(pwm.level(&SSR, 0, 255));
        assert!(pwm.level(&SSR, 50, 0)); // latched: still on
        assert!(pwm.level(&SSR, 199, 0));
        assert!(!pwm.level(&SSR, 200, 0)); // next window
    }

    #[test]
    fn stop_switches_off_at_once_and_restarts_the_window() {
        let mut pwm = SlowPwm::new();
        assert!(pwm.level(&SSR, 0, 255));
        pwm.stop();
        assert!(pwm.level(&SSR, 70, 128)); // fresh window from 70 ms
        assert!(!pwm.level(&SSR, 170, 128));
        assert!(pwm.level(&SSR, 270, 128));
    }

    #[test]
    fn windows_survive_the_millisecond_counter_wrapping() {
        let mut pwm = SlowPwm::new();
        let start = u32::MAX - 50;
        assert!(pwm.level(&SSR, start, 128));
        assert!(pwm.level(&SSR, start.wrapping_add(99), 128));
        assert!(!pwm.level(&SSR, start.wrapping_add(100), 128));
        assert!(pwm.level(&SSR, start.wrapping_add(200), 128));
    }
}
