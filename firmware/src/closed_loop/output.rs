//! Where the loop's command goes: a step rate for stepper axes (the
//! firmware's velocity mode), or an H-bridge for DC servo axes (SPEC §5);
//! and the fault inputs (driver ALARM, bridge EN/DIAG) with their polarity.

use super::control::mul_shift;
use embedded_hal::digital::{InputPin, OutputPin};
use embedded_hal::pwm::SetDutyCycle;

/// A signed step rate in steps per second, Q24.8 (`256` = 1 step/s): what
/// the stepper's velocity mode runs at until the next tick.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepRate(pub i32);

impl StepRate {
    /// Whole steps per second (truncated toward zero).
    pub fn steps_per_s(self) -> i32 {
        self.0 / 256
    }
}

/// Loop units/s → steps/s for one stepper axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepperScale {
    /// Steps per loop unit, Q16.16 (100 steps/mm over 2048 units/mm = 3200).
    steps_per_unit_q16: i32,
}

impl StepperScale {
    /// From steps/mm and loop units/mm (main loop; f32 allowed).
    pub fn new(steps_per_mm: f32, units_per_mm: f32) -> Option<Self> {
        let q16 = steps_per_mm / units_per_mm * 65536.0;
        if !(1.0..2_147_483_000.0).contains(&q16) {
            return None;
        }
        Some(Self { steps_per_unit_q16: (q16 + 0.5) as i32 })
    }

    /// In the tick: velocity (units/s) → step rate (one multiply).
    pub fn step_rate(self, units_per_s: i32) -> StepRate {
        StepRate(mul_shift::<8>(units_per_s, self.steps_per_unit_q16))
    }
}

/// Which level of a fault line means "fault".
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActiveLevel {
    High,
    Low,
}

impl ActiveLevel {
    /// Whether a line reading `is_high` is asserted.
    pub fn is_asserted(self, is_high: bool) -> bool {
        match self {
            ActiveLevel::High => is_high,
            ActiveLevel::Low => !is_high,
        }
    }
}

/// A fault input (a driver's ALARM output, SPEC §3) with its polarity,
/// which the theses leave to configuration. A pin that cannot be read
/// counts as asserted (fail safe).
pub struct FaultInput<P> {
    pin: P,
    active: ActiveLevel,
}

impl<P: InputPin> FaultInput<P> {
    pub fn new(pin: P, active: ActiveLevel) -> Self {
        Self { pin, active }
    }

    pub fn is_asserted(&mut self) -> bool {
        match self.pin.is_high() {
            Ok(high) => self.active.is_asserted(high),
            Err(_) => true,
        }
    }
}

/// A Pololu VNH5019-style bridge: INA/INB choose the direction, PWM sets
/// |duty|, EN/DIAG reports a fault. Zero output brakes to ground (INA = INB
/// = 0, ours); a fault, or an error from a pin, brakes too.
pub struct HBridge<Pwm, Ina, Inb, Diag> {
    pwm: Pwm,
    ina: Ina,
    inb: Inb,
    diag: FaultInput<Diag>,
}

/// A pin or the PWM refused a write: the bridge was left braking if possible.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BridgeWriteError;

impl<Pwm: SetDutyCycle, Ina: OutputPin, Inb: OutputPin, Diag: InputPin> HBridge<Pwm, Ina, Inb, Diag> {
    /// `diag_active`: the VNH5019 pulls EN/DIAG low on a fault (`Low`).
    pub fn new(pwm: Pwm, ina: Ina, inb: Inb, diag: Diag, diag_active: ActiveLevel) -> Self {
        let mut bridge = Self { pwm, ina, inb, diag: FaultInput::new(diag, diag_active) };
        let _ = bridge.brake();
        bridge
    }

    /// The largest |duty| this PWM accepts (the loop's output limit).
    pub fn max_duty(&self) -> u16 {
        self.pwm.max_duty_cycle()
    }

    /// Whether EN/DIAG reports a fault now.
    pub fn fault(&mut self) -> bool {
        self.diag.is_asserted()
    }

    /// Apply a signed duty (clamped to ±max_duty): positive drives INA,
    /// negative INB, zero brakes.
    pub fn drive(&mut self, duty: i32) -> Result<(), BridgeWriteError> {
        if duty == 0 {
            return self.brake();
        }
        let max = i32::from(self.pwm.max_duty_cycle());
        let magnitude = duty.unsigned_abs().min(max as u32) as u16;
        // Direction first with the PWM off, so a reversal never shoots through.
        self.pwm.set_duty_cycle(0).map_err(|_| BridgeWriteError)?;
        let (a, b) = if duty > 0 { (true, false) } else { (false, true) };
        self.ina.set_state(a.into()).map_err(|_| BridgeWriteError)?;
        self.inb.set_state(b.into()).map_err(|_| BridgeWriteError)?;
        self.pwm.set_duty_cycle(magnitude).map_err(|_| BridgeWriteError)
    }

    /// Brake to ground: INA = INB = 0, PWM 0.
    pub fn brake(&mut self) -> Result<(), BridgeWriteError> {
        let pwm = self.pwm.set_duty_cycle(0);
        let a = self.ina.set_low();
        let b = self.inb.set_low();
        if pwm.is_err() || a.is_err() || b.is_err() {
            return Err(BridgeWriteError);
        }
        Ok(())
    }

    /// Give the pins back.
    pub fn release(self) -> (Pwm, Ina, Inb, Diag) {
        (self.pwm, self.ina, self.inb, self.diag.pin)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::cell::RefCell;
    use std::rc::Rc;
    use std::vec::Vec;

    type Log = Rc<RefCell<Vec<&'static str>>>;

    struct Pin(&'static str, Log, bool);
    impl embedded_hal::digital::ErrorType for Pin {
        type Error = core::convert::Infallible;
    }
    impl OutputPin for Pin {
        fn set_low(&mut self) -> Result<(), Self::Error> {
            self.1.borrow_mut().push(if self.0 == "A" { "A0" } else { "B0" });
            Ok(())
        }
        fn set_high(&mut self) -> Result<(), Self::Error> {
            self.1.borrow_mut().push(if self.0 == "A" { "A1" } else { "B1" });
            Ok(())
        }
    }
    impl InputPin for Pin {
        fn is_high(&mut self) -> Result<bool, Self::Error> {
            Ok(self.2)
        }
        fn is_low(&mut self) -> Result<bool, Self::Error> {
            Ok(!self.2)
        }
    }
    struct Pwm(Log, Rc<RefCell<u16>>);
    impl embedded_hal::pwm::ErrorType for Pwm {
        type Error = core::convert::Infallible;
    }
    impl SetDutyCycle for Pwm {
        fn max_duty_cycle(&self) -> u16 {
            255
        }
        fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Self::Error> {
            *self.1.borrow_mut() = duty;
            self.0.borrow_mut().push("pwm");
            Ok(())
        }
    }

    type Fixture = (HBridge<Pwm, Pin, Pin, Pin>, Log, Rc<RefCell<u16>>);

    fn bridge(diag_high: bool) -> Fixture {
        let log: Log = Rc::default();
        let duty = Rc::new(RefCell::new(99));
        let b = HBridge::new(
            Pwm(log.clone(), duty.clone()),
            Pin("A", log.clone(), false),
            Pin("B", log.clone(), false),
            Pin("D", log.clone(), diag_high),
            ActiveLevel::Low,
        );
        log.borrow_mut().clear();
        (b, log, duty)
    }

    #[test]
    fn positive_duty_drives_ina_negative_inb_with_pwm_off_while_switching() {
        let (mut b, log, duty) = bridge(true);
        b.drive(100).unwrap();
        assert_eq!(*log.borrow(), ["pwm", "A1", "B0", "pwm"]);
        assert_eq!(*duty.borrow(), 100);
        log.borrow_mut().clear();
        b.drive(-300).unwrap();
        assert_eq!(*log.borrow(), ["pwm", "A0", "B1", "pwm"]);
        assert_eq!(*duty.borrow(), 255, "clamped to max duty");
    }

    #[test]
    fn zero_output_brakes_to_ground() {
        let (mut b, log, duty) = bridge(true);
        b.drive(50).unwrap();
        log.borrow_mut().clear();
        b.drive(0).unwrap();
        assert_eq!(*log.borrow(), ["pwm", "A0", "B0"]);
        assert_eq!(*duty.borrow(), 0);
    }

    #[test]
    fn en_diag_low_is_a_fault_with_the_vnh5019_polarity() {
        assert!(bridge(false).0.fault());
        assert!(!bridge(true).0.fault());
    }

    #[test]
    fn alarm_polarity_is_configurable() {
        assert!(ActiveLevel::High.is_asserted(true));
        assert!(!ActiveLevel::High.is_asserted(false));
        assert!(ActiveLevel::Low.is_asserted(false));
        let log: Log = Rc::default();
        assert!(FaultInput::new(Pin("D", log.clone(), true), ActiveLevel::High).is_asserted());
        assert!(!FaultInput::new(Pin("D", log, true), ActiveLevel::Low).is_asserted());
    }

    #[test]
    fn step_rate_for_100_steps_per_mm_and_the_nse5310_unit() {
        let scale = StepperScale::new(100.0, 2048.0).unwrap();
        // 5 mm/s = 10240 units/s = 500 steps/s
        assert_eq!(scale.step_rate(10_240), StepRate(500 * 256));
        assert_eq!(scale.step_rate(-10_240).steps_per_s(), -500);
        // 200 mm/s = 20 000 steps/s
        assert_eq!(scale.step_rate(409_600).steps_per_s(), 20_000);
    }
}
