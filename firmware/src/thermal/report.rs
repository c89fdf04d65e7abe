//! Temperature reports: the `M105` line, `M155` auto-report timing, and
//! the `M109`/`M190` wait (Marlin's residency rule).

use super::channel::HeaterChannel;
use super::Celsius;

/// `T:210.00 /210.00 B:60.00 /60.00 @:127 B@:64` (and the newline), Marlin's
/// `M105` report; `@:` is the duty halved (0–127). Without a bed, `B:…`
/// and `B@:…` are left out.
pub fn write_temperatures<W: ufmt::uWrite + ?Sized>(hotend: &HeaterChannel, bed: Option<&HeaterChannel>, out: &mut W) -> Result<(), W::Error> {
    write_temperature_fields(hotend, bed, out)?;
    out.write_str("\n")
}

/// The `M105` report without its newline (`M109`'s keep-alive line adds
/// ` W:…` to it).
#[inline(never)]
pub fn write_temperature_fields<W: ufmt::uWrite + ?Sized>(hotend: &HeaterChannel, bed: Option<&HeaterChannel>, out: &mut W) -> Result<(), W::Error> {
    ufmt::uwrite!(out, "T:{} /{}", hotend.measured(), hotend.target())?;
    if let Some(bed) = bed {
        ufmt::uwrite!(out, " B:{} /{}", bed.measured(), bed.target())?;
    }
    ufmt::uwrite!(out, " @:{}", crate::reply::Whole(hotend.power_report().into()))?;
    if let Some(bed) = bed {
        ufmt::uwrite!(out, " B@:{}", crate::reply::Whole(bed.power_report().into()))?;
    }
    Ok(())
}

/// `M155 S<seconds>`: when the next automatic temperature report is due.
/// 5 bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AutoReport {
    interval_s: u8,
    next_ms: u32,
}

impl AutoReport {
    /// Marlin's limit on `M155 S`.
    pub const MAX_INTERVAL_S: u8 = 60;

    pub const fn new() -> Self {
        Self { interval_s: 0, next_ms: 0 }
    }

    pub fn interval_s(&self) -> u8 {
        self.interval_s
    }

    /// `M155 S<n>` at `now_ms` (0: off; clamped to 60 s). The first report
    /// comes one interval later.
    pub fn set_interval(&mut self, seconds: u8, now_ms: u32) {
        self.interval_s = seconds.min(Self::MAX_INTERVAL_S);
        self.next_ms = now_ms.wrapping_add(super::millis(u16::from(self.interval_s)));
    }

    /// Whether a report is due at `now_ms`; if so the next one is
    /// scheduled one interval after the previous one's due time (no
    /// drift), or after now if the loop fell more than an interval behind.
    pub fn due(&mut self, now_ms: u32) -> bool {
        if self.interval_s == 0 || (now_ms.wrapping_sub(self.next_ms) as i32) < 0 {
            return false;
        }
        let interval = super::millis(u16::from(self.interval_s));
        self.next_ms = self.next_ms.wrapping_add(interval);
        if (now_ms.wrapping_sub(self.next_ms) as i32) >= 0 {
            self.next_ms = now_ms.wrapping_add(interval);
        }
        true
    }
}

/// Settings of the `M109`/`M190` wait (Marlin's `TEMP_RESIDENCY_TIME`,
/// `TEMP_WINDOW`, `TEMP_HYSTERESIS`, and the cooling-slope escape).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WaitConfig {
    /// Seconds the temperature must stay near the target.
    pub residency_s: u8,
    /// The residency timer starts within this of the target (hundredths).
    pub window: u16,
    /// …and restarts when the temperature strays farther than this.
    pub hysteresis: u16,
    /// `R` waits that cool: give up when the temperature falls less than
    /// `min_cooling` in `cooling_check_s` (a stuck fan must not hang the
    /// host forever; Marlin's `MIN_COOLING_SLOPE_*`).
    pub min_cooling: u16,
    pub cooling_check_s: u8,
    /// Give up after this many seconds (0: never; ours, Marlin has none).
    pub timeout_s: u16,
}

impl WaitConfig {
    /// Marlin's hot end: 10 s within 1 °C (restart beyond 3 °C), cooling
    /// at least 1.5 °C per 60 s.
    pub const HOTEND: WaitConfig = WaitConfig { residency_s: 10, window: 100, hysteresis: 300, min_cooling: 150, cooling_check_s: 60, timeout_s: 0 };
    /// Marlin's bed: 10 s within 1 °C, restart beyond 3 °C, cooling at
    /// least 1 °C per 60 s.
    pub const BED: WaitConfig = WaitConfig { residency_s: 10, window: 100, hysteresis: 300, min_cooling: 100, cooling_check_s: 60, timeout_s: 0 };
}

/// Where a wait stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WaitStatus {
    /// Keep waiting; the residency countdown in whole seconds once it runs
    /// (Marlin's ` W:<s>`, ` W:?` before).
    Waiting(Option<u8>),
    /// The target was reached and held (or no wait was needed).
    Reached,
    /// Cooling too slowly for an `R` wait: stop waiting (Marlin does too).
    CoolingStalled,
    /// The timeout passed.
    TimedOut,
}

/// An `M109`/`M190` in progress: a pure state machine the executor polls
/// (every loop) while it prints `busy:`/temperature lines once a second.
/// 34 bytes on the AVR, only while waiting.
#[derive(Clone, Copy, Debug)]
pub struct TemperatureWait {
    config: WaitConfig,
    target: Celsius,
    /// `M109 R`: also wait while cooling.
    cooling: bool,
    started_ms: u32,
    /// When the residency timer (re)started, if it runs.
    residency_since: Option<u32>,
    /// Cooling check: temperature and time of the last check.
    cool_check: Option<(Celsius, u32)>,
    /// Decided at the first poll, as Marlin decides it when `M109` starts.
    wants_to_cool: Option<bool>,
}

impl TemperatureWait {
    /// Wait for `target`. `wait_for_cooling` is `M109 R`/`M190 R`; with `S`
    /// a heater that is hotter than the target does not wait at all.
    pub fn new(config: WaitConfig, target: Celsius, wait_for_cooling: bool, now_ms: u32) -> Self {
        Self { config, target, cooling: wait_for_cooling, started_ms: now_ms, residency_since: None, cool_check: None, wants_to_cool: None }
    }

    pub fn target(&self) -> Celsius {
        self.target
    }

    /// One poll with the heater's measured temperature.
    pub fn poll(&mut self, now_ms: u32, measured: Celsius) -> WaitStatus {
        let wants_to_cool = *self.wants_to_cool.get_or_insert(measured > self.target);
        if self.target.0 <= 0 || (wants_to_cool && !self.cooling) {
            return WaitStatus::Reached;
        }
        if self.config.timeout_s > 0 && now_ms.wrapping_sub(self.started_ms) >= super::millis(self.config.timeout_s) {
            return WaitStatus::TimedOut;
        }
        let distance = measured.0.abs_diff(self.target.0);
        match self.residency_since {
            None if distance < u32::from(self.config.window) => self.residency_since = Some(now_ms),
            Some(_) if distance > u32::from(self.config.hysteresis) => self.residency_since = Some(now_ms),
            _ => {}
        }
        if let Some(since) = self.residency_since {
            let held = now_ms.wrapping_sub(since);
            let residency = super::millis(u16::from(self.config.residency_s));
            if held >= residency {
                return WaitStatus::Reached;
            }
            return WaitStatus::Waiting(Some(((residency - held) / 1000) as u8));
        }
        if wants_to_cool {
            let period = super::millis(u16::from(self.config.cooling_check_s));
            match self.cool_check {
                None => self.cool_check = Some((measured, now_ms)),
                Some((previous, at)) if now_ms.wrapping_sub(at) >= period => {
                    if previous.0.saturating_sub(measured.0) < i32::from(self.config.min_cooling) {
                        return WaitStatus::CoolingStalled;
                    }
                    self.cool_check = Some((measured, now_ms));
                }
                Some(_) => {}
            }
        }
        WaitStatus::Waiting(None)
    }
}

#[cfg(test)]
mod tests {
    use super::super::channel::{BED, HOTEND_0};
    use super::super::pid::Gains;
    use super::super::thermistor::Oversampled;
    use super::*;
    use crate::reply::test_support::Text;

    #[test]
    fn m105_prints_hot_end_and_bed_with_marlin_power() {
        let mut hotend = HeaterChannel::new(&HOTEND_0, Gains::MARLIN_HOTEND);
        let mut bed = HeaterChannel::new(&BED, Gains::MARLIN_BED);
        hotend.on_sample(Oversampled::from_count(977)); // ≈25 °C
        bed.on_sample(Oversampled::from_count(977));
        hotend.set_target(Celsius(21_000)).unwrap();
        hotend.on_sample(Oversampled::from_count(977));
        let mut out = Text::default();
        write_temperatures(&hotend, Some(&bed), &mut out).unwrap();
        let t = hotend.measured();
        let mut expected = Text::default();
        ufmt::uwrite!(expected, "T:{} /210.00 B:{} /0.00 @:127 B@:0\n", t, bed.measured()).unwrap();
        assert_eq!(out.0, expected.0);
        assert!(out.0.starts_with("T:24.9") || out.0.starts_with("T:25.0"), "{}", out.0);
        let mut out = Text::default();
        write_temperatures(&hotend, None, &mut out).unwrap();
        assert!(out.0.ends_with(" /210.00 @:127\n"), "{}", out.0);
    }

    #[test]
    fn the_m109_keep_alive_line_is_the_report_fields_with_w() {
        let mut hotend = HeaterChannel::new(&HOTEND_0, Gains::MARLIN_HOTEND);
        let mut bed = HeaterChannel::new(&BED, Gains::MARLIN_BED);
        hotend.on_sample(Oversampled::from_count(300));
        bed.on_sample(Oversampled::from_count(900));
        hotend.set_target(Celsius(21_050)).unwrap();
        bed.set_target(Celsius(6_000)).unwrap();
        hotend.on_sample(Oversampled::from_count(301));
        bed.on_sample(Oversampled::from_count(901));
        // What the executor printed before it shared the fields.
        let mut expected = Text::default();
        ufmt::uwrite!(expected, " T:{} /{} B:{} /{} @:{} B@:{} W:", hotend.measured(), hotend.target(), bed.measured(), bed.target(), hotend.power_report(), bed.power_report()).unwrap();
        let mut out = Text::default();
        out.0.push(' ');
        write_temperature_fields(&hotend, Some(&bed), &mut out).unwrap();
        out.0.push_str(" W:");
        assert_eq!(out.0, expected.0);
    }

    #[test]
    fn auto_report_fires_every_interval_without_drift() {
        let mut report = AutoReport::new();
        assert!(!report.due(0));
        report.set_interval(2, 1_000);
        assert!(!report.due(2_999));
        assert!(report.due(3_000));
        assert!(!report.due(3_001));
        assert!(report.due(5_050)); // late by 50 ms…
        assert!(report.due(7_000)); // …the next is still on the grid
        assert!(report.due(20_000)); // far behind: resynchronise
        assert!(!report.due(21_999));
        assert!(report.due(22_000));
        report.set_interval(0, 22_000);
        assert!(!report.due(100_000));
        report.set_interval(200, 0);
        assert_eq!(report.interval_s(), 60);
    }

    #[test]
    fn auto_report_survives_the_millisecond_counter_wrapping() {
        let mut report = AutoReport::new();
        report.set_interval(1, u32::MAX - 500);
        assert!(!report.due(u32::MAX));
        assert!(report.due(499));
    }

    fn c(degrees: i32) -> Celsius {
        Celsius::from_degrees(degrees)
    }

    #[test]
    fn m109_waits_until_the_temperature_held_within_a_degree_for_10_s() {
        let mut wait = TemperatureWait::new(WaitConfig::HOTEND, c(210), false, 0);
        assert_eq!(wait.poll(0, c(25)), WaitStatus::Waiting(None));
        assert_eq!(wait.poll(60_000, Celsius(20_901)), WaitStatus::Waiting(Some(10)));
        assert_eq!(wait.poll(61_000, Celsius(21_200)), WaitStatus::Waiting(Some(9)));
        // Strayed beyond 3 °C: the residency restarts.
        assert_eq!(wait.poll(62_000, Celsius(21_301)), WaitStatus::Waiting(Some(10)));
        assert_eq!(wait.poll(71_999, c(210)), WaitStatus::Waiting(Some(0)));
        assert_eq!(wait.poll(72_000, c(210)), WaitStatus::Reached);
    }

    #[test]
    fn m109_s_does_not_wait_to_cool_but_m109_r_does() {
        let mut wait = TemperatureWait::new(WaitConfig::HOTEND, c(180), false, 0);
        assert_eq!(wait.poll(0, c(210)), WaitStatus::Reached);
        let mut wait = TemperatureWait::new(WaitConfig::HOTEND, c(180), true, 0);
        assert_eq!(wait.poll(0, c(210)), WaitStatus::Waiting(None));
        assert_eq!(wait.poll(30_000, c(195)), WaitStatus::Waiting(None));
        assert_eq!(wait.poll(60_000, Celsius(18_050)), WaitStatus::Waiting(Some(10)));
        assert_eq!(wait.poll(70_000, c(180)), WaitStatus::Reached);
    }

    #[test]
    fn m109_r_gives_up_when_cooling_stalls() {
        let mut wait = TemperatureWait::new(WaitConfig::HOTEND, c(30), true, 0);
        assert_eq!(wait.poll(0, c(60)), WaitStatus::Waiting(None));
        assert_eq!(wait.poll(60_000, Celsius(5_849)), WaitStatus::Waiting(None)); // 1.51 °C in 60 s
        assert_eq!(wait.poll(120_000, Celsius(5_700)), WaitStatus::CoolingStalled); // 1.49 °C
    }

    #[test]
    fn a_wait_with_a_timeout_gives_up() {
        let config = WaitConfig { timeout_s: 600, ..WaitConfig::BED };
        let mut wait = TemperatureWait::new(config, c(100), false, 1_000);
        assert_eq!(wait.poll(600_999, c(50)), WaitStatus::Waiting(None));
        assert_eq!(wait.poll(601_000, c(50)), WaitStatus::TimedOut);
    }

    #[test]
    fn a_target_of_zero_needs_no_wait() {
        let mut wait = TemperatureWait::new(WaitConfig::BED, c(0), true, 0);
        assert_eq!(wait.poll(0, c(60)), WaitStatus::Reached);
    }
}
