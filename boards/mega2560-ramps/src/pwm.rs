//! Hardware PWM for the RAMPS MOSFET outputs.
//!
//! | pin | channel | timer | frequency | RAMPS 1.4 |
//! |---|---|---|---|---|
//! | D10 = PB4 | OC2A | Timer2, fast PWM 8-bit, /64 | 976 Hz | hot end |
//! | D9 = PH6 | OC2B | Timer2 (shared) | 976 Hz | fan |
//! | D8 = PH5 | OC4C | Timer4, fast PWM 8-bit, /8 | 7.8 kHz | bed |
//!
//! Which output (hot end, bed, fan) is on which channel is the machine
//! file's choice (`pins::*_PWM`).
//!
//! D8 runs at 7.8 kHz because SPEC §2's bed drives a triac stage
//! through a 40 Hz RC filter: the ripple is 1.6 % at 3.9 kHz and worse
//! below, so its PWM must stay at or above 4 kHz.
//!
//! A duty of 0 disconnects the pin from its timer and drives it low: a PWM
//! compare unit at 0 would still emit a one-cycle spike every period in
//! fast PWM mode.

use avr_device::atmega2560::Peripherals;

/// What an output is for; which channel drives it is the machine file's
/// (`pins::HOTEND_PWM`, `BED_PWM`, `FAN_PWM`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(any(feature = "machine-extrusion-line", feature = "machine-powder-bed"), allow(dead_code))]
pub enum Output {
    Hotend,
    #[cfg_attr(feature = "bed-ssr", allow(dead_code))]
    Bed,
    Fan,
}

/// The hardware PWM channels on the RAMPS MOSFET pins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[allow(dead_code)]
pub enum Channel {
    /// D10 = PB4, Timer2 A.
    Oc2a,
    /// D9 = PH6, Timer2 B.
    Oc2b,
    /// D8 = PH5, Timer4 C.
    Oc4c,
}

impl Channel {
    /// The pin, and the COMnx1 (non-inverting) bit in its TCCRnA.
    const fn pin_and_connect_bit(self) -> (crate::pins::Pin, u8) {
        use crate::pins::{pin, Port};
        match self {
            Channel::Oc2a => (pin(Port::B, 4), 7),
            Channel::Oc2b => (pin(Port::H, 6), 5),
            Channel::Oc4c => (pin(Port::H, 5), 3),
        }
    }
}

/// Start both timers with every output disconnected (low).
pub fn init(dp: &Peripherals) {
    // Timer2: fast PWM, TOP 0xFF (WGM22 = 0); clk/64; compare outputs off.
    dp.TC2.tccr2a.write(|w| w.wgm2().pwm_fast());
    dp.TC2.tccr2b.write(|w| w.cs2().prescale_64());
    // Timer4: mode 5, fast PWM 8-bit (WGM43:42 = 01, WGM41:40 = 01);
    // clk/8; compare outputs off.
    dp.TC4.tccr4a.write(|w| w.wgm4().bits(0b01));
    dp.TC4.tccr4b.write(|w| w.wgm4().bits(0b01).cs4().prescale_8());
}

/// Set one output's duty, 0 (off) to 255 (fully on); nothing if the
/// machine has no such output.
pub fn set(dp: &Peripherals, output: Output, duty: u8) {
    let channel = match output {
        Output::Hotend => crate::pins::HOTEND_PWM,
        Output::Fan => crate::pins::FAN_PWM,
        Output::Bed => crate::pins::BED_PWM,
    };
    if let Some(channel) = channel {
        set_channel(dp, channel, duty);
    }
}

fn set_channel(dp: &Peripherals, channel: Channel, duty: u8) {
    let (pin, connect_bit) = channel.pin_and_connect_bit();
    // 0 and 255 are plain levels, as Arduino's analogWrite makes them: a
    // compare unit at either end of fast PWM still emits a one-cycle pulse
    // each period (and a pin that never toggles reads as a level anyway).
    let connect = duty != 0 && duty != 255;
    match channel {
        Channel::Oc2a => dp.TC2.ocr2a.write(|w| w.bits(duty)),
        Channel::Oc2b => dp.TC2.ocr2b.write(|w| w.bits(duty)),
        Channel::Oc4c => dp.TC4.ocr4c.write(|w| w.bits(u16::from(duty))),
    }
    let update = |bits: u8| if connect { bits | (1 << connect_bit) } else { bits & !(1 << connect_bit) };
    match channel {
        // SAFETY: only the output's own COM bit changes.
        Channel::Oc2a | Channel::Oc2b => dp.TC2.tccr2a.modify(|r, w| unsafe { w.bits(update(r.bits())) }),
        Channel::Oc4c => dp.TC4.tccr4a.modify(|r, w| unsafe { w.bits(update(r.bits())) }),
    }
    // The PORT level whenever the compare unit is disconnected (high only
    // for full power); the pin must be an output for the unit to drive it.
    crate::pins::make_output(dp, pin, duty == 255);
}

/// Disconnect every PWM output from its timer (then the pins follow their
/// PORT bits, which the caller drives low).
pub fn disconnect_all(dp: &Peripherals) {
    // The COM fields only; waveform mode bits are kept.
    dp.TC2.tccr2a.modify(|_, w| w.com2a().disconnected().com2b().disconnected());
    dp.TC4.tccr4a.modify(|_, w| w.com4a().disconnected().com4b().disconnected().com4c().disconnected());
}
