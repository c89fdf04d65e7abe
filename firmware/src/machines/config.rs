//! One configuration per machine, chosen at build time (the board crate's
//! features `machine-prusa-i3` (default), `machine-delta`, `machine-arm`,
//! `machine-extrusion-line`, `machine-powder-bed` each call one
//! constructor here). Pins are configuration: the theses' pin maps clash
//! (the extrusion line puts an SSR on D9, the RAMPS fan pin, and its fans
//! on D8, the bed pin), so each machine names its own.
//!
//! Pins are Arduino Mega 2560 digital numbers (`D54` = A0 … `D69` = A15);
//! the board maps them to port and bit. Analog inputs are ADC channels.
//! Default uses, on a RAMPS 1.4:
//!
//! | machine | use |
//! |---|---|
//! | Prusa i3 (SPEC §1) | Marlin's RAMPS map: X/Y/Z/E0 sockets, second Z on E1; hot end D10, bed D8, fan D9; T0 A13, bed A14 (4.7 kΩ); endstops X_MIN D3, Y_MIN D14, Z_MIN D18; NSE-5310 X and Y on I²C D20/D21 (both at 0x40: separate buses or gating), Index X on D2 (X_MAX), Y on D15 (Y_MAX) |
//! | delta (SPEC §2) | towers A/B/C on X/Y/Z sockets, extruder E0; max endstops D2, D15, D19; hot end D10; bed D8 = OC4C hardware PWM ≥ 4 kHz (triac filter); fan D9 |
//! | RR arm (SPEC §3, ours on a RAMPS; the thesis used a Controllino Mega) | shoulder θ1 ("Z") on the Z socket, elbow θ2 ("Y") on Y, X lead screws on X and E1; NC limit switches on the six endstop inputs; safety relay D40, e-stop D42, rearm D44; driver ALARMs D63, D64, D65, D66 |
//! | extrusion line (SPEC §4) | extruder screw on E0 (STEP D26, DIR D28, EN D24), puller on X (STEP A0 = D54, DIR A1 = D55, EN D38); barrel SSR D9 (slow PWM); fans D8 (on at start); thermistor A13 with 4.8 kΩ |
//! | powder bed (SPEC §5, ours) | feed platform on Z (D46/D48/D62), build platform on E0 (D26/D28/D24); reed switches feed A D18 / B D19, build A D14 / B D15 (active low); carriage X: VNH5019 PWM D44 (OC5C), INA D40, INB D42, EN/DIAG D59, encoder A/B D2/D3 (INT4/INT5); carriage Y: PWM D45 (OC5B), INA D63, INB D64, EN/DIAG D65, encoder D20/D21 (INT1/INT0); carriage sensors C− D11, C+ D6; roller D10 MOSFET, suction D8 MOSFET; LCD on the Smart Controller header: RS D16, E D17, D4 D23, D5 D25, D6 D27, D7 D29 |

use super::diameter::DiameterSettings;
use super::extrusion_line::{ExtrusionLineConfig, MIN_EXTRUSION_TEMPERATURE};
use super::powder_bed::{ActiveLevel, LayerSettings, PlatformDriver, TravelLimits};
use super::velocity::{DriveTrain, VelocityConfigError};
use crate::thermal::Celsius;

/// An Arduino Mega 2560 digital pin number (A0 = 54 … A15 = 69).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MegaPin(pub u8);

impl MegaPin {
    /// Analog pin `An` as a digital pin.
    pub const fn analog(n: u8) -> MegaPin {
        MegaPin(54 + n)
    }
}

/// STEP, DIR and EN of one stepper socket.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepperPins {
    pub step: MegaPin,
    pub dir: MegaPin,
    pub enable: MegaPin,
}

/// The RAMPS 1.4 sockets (Marlin's map).
pub mod ramps {
    use super::{MegaPin, StepperPins};
    pub const X: StepperPins = StepperPins { step: MegaPin::analog(0), dir: MegaPin::analog(1), enable: MegaPin(38) };
    pub const Y: StepperPins = StepperPins { step: MegaPin::analog(6), dir: MegaPin::analog(7), enable: MegaPin::analog(2) };
    pub const Z: StepperPins = StepperPins { step: MegaPin(46), dir: MegaPin(48), enable: MegaPin::analog(8) };
    pub const E0: StepperPins = StepperPins { step: MegaPin(26), dir: MegaPin(28), enable: MegaPin(24) };
    pub const E1: StepperPins = StepperPins { step: MegaPin(36), dir: MegaPin(34), enable: MegaPin(30) };
    pub const X_MIN: MegaPin = MegaPin(3);
    pub const X_MAX: MegaPin = MegaPin(2);
    pub const Y_MIN: MegaPin = MegaPin(14);
    pub const Y_MAX: MegaPin = MegaPin(15);
    pub const Z_MIN: MegaPin = MegaPin(18);
    pub const Z_MAX: MegaPin = MegaPin(19);
    /// MOSFET outputs: D10 (hot end), D9 (fan), D8 (bed).
    pub const D10: MegaPin = MegaPin(10);
    pub const D9: MegaPin = MegaPin(9);
    pub const D8: MegaPin = MegaPin(8);
}

/// Which machine a build is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MachineKind {
    PrusaI3,
    Delta,
    Arm,
    ExtrusionLine,
    PowderBed,
}

impl MachineKind {
    /// `MACHINE_TYPE` in `M115`.
    pub fn name(self) -> &'static str {
        match self {
            MachineKind::PrusaI3 => "Prusa i3",
            MachineKind::Delta => "Delta",
            MachineKind::Arm => "RR arm",
            MachineKind::ExtrusionLine => "Filament extrusion line",
            MachineKind::PowderBed => "Powder bed",
        }
    }

    /// Whether `M104`/`M109`/`M140`/`M190` do anything on this machine.
    pub fn has_heaters(self) -> bool {
        !matches!(self, MachineKind::PowderBed | MachineKind::Arm)
    }
}

/// Pins of a printer-type machine (the three printers and the arm): the
/// motion and thermal modules own what they mean.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PrinterPins {
    pub steppers: [Option<StepperPins>; 5],
    pub endstops: [Option<MegaPin>; 6],
    pub hotend: Option<MegaPin>,
    pub bed: Option<MegaPin>,
    pub fan: Option<MegaPin>,
    /// ADC channels of the hot-end and bed thermistors.
    pub hotend_adc: Option<u8>,
    pub bed_adc: Option<u8>,
    /// Extra inputs: encoder index lines (Prusa), safety inputs (arm).
    pub inputs: [Option<MegaPin>; 7],
}

/// SPEC §1 printer on a RAMPS (X, Y, Z, E0; second Z on E1).
pub const fn prusa_i3_pins() -> PrinterPins {
    PrinterPins {
        steppers: [Some(ramps::X), Some(ramps::Y), Some(ramps::Z), Some(ramps::E0), Some(ramps::E1)],
        endstops: [Some(ramps::X_MIN), None, Some(ramps::Y_MIN), None, Some(ramps::Z_MIN), None],
        hotend: Some(ramps::D10),
        bed: Some(ramps::D8),
        fan: Some(ramps::D9),
        hotend_adc: Some(13),
        bed_adc: Some(14),
        // NSE-5310 Index lines of X and Y
        inputs: [Some(ramps::X_MAX), Some(ramps::Y_MAX), None, None, None, None, None],
    }
}

/// SPEC §2 delta: towers on X/Y/Z, max endstops.
pub const fn delta_pins() -> PrinterPins {
    PrinterPins {
        steppers: [Some(ramps::X), Some(ramps::Y), Some(ramps::Z), Some(ramps::E0), None],
        endstops: [None, Some(ramps::X_MAX), None, Some(ramps::Y_MAX), None, Some(ramps::Z_MAX)],
        hotend: Some(ramps::D10),
        bed: Some(ramps::D8),
        fan: Some(ramps::D9),
        hotend_adc: Some(13),
        bed_adc: Some(14),
        inputs: [None; 7],
    }
}

/// SPEC §3 arm (ours on a RAMPS): X, elbow on Y, shoulder on Z, second X
/// lead screw on E1; every endstop input an NC limit; inputs: safety
/// relay, e-stop, rearm, four driver ALARMs.
pub const fn arm_pins() -> PrinterPins {
    PrinterPins {
        steppers: [Some(ramps::X), Some(ramps::Y), Some(ramps::Z), None, Some(ramps::E1)],
        endstops: [
            Some(ramps::X_MIN),
            Some(ramps::X_MAX),
            Some(ramps::Y_MIN),
            Some(ramps::Y_MAX),
            Some(ramps::Z_MIN),
            Some(ramps::Z_MAX),
        ],
        hotend: None,
        bed: None,
        fan: None,
        hotend_adc: None,
        bed_adc: None,
        inputs: [
            Some(MegaPin(40)),
            Some(MegaPin(42)),
            Some(MegaPin(44)),
            Some(MegaPin::analog(9)),
            Some(MegaPin::analog(10)),
            Some(MegaPin::analog(11)),
            Some(MegaPin::analog(12)),
        ],
    }
}

/// The extrusion line's pins (SPEC §4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExtrusionLinePins {
    pub extruder: StepperPins,
    pub puller: StepperPins,
    /// Solid-state relay of the barrel heater (slow time-proportioning PWM).
    pub barrel_ssr: MegaPin,
    pub fans: MegaPin,
    pub barrel_adc: u8,
    /// Series resistor of the barrel thermistor, Ω.
    pub thermistor_series_ohms: u16,
}

/// Everything the extrusion-line build needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExtrusionLineMachine {
    pub pins: ExtrusionLinePins,
    pub line: ExtrusionLineConfig,
    /// The screw's cold-extrusion minimum (the thermal module's check).
    pub min_extrusion_temperature: Celsius,
    /// Barrel PI of the thesis: Kp 2.4, Ki 0.008 per second, T = 1 s, 0–100 %.
    pub barrel_kp: f32,
    pub barrel_ki: f32,
    /// SSR slow PWM: 200 ms period, slots ≥ 10 ms (SPEC §4).
    pub ssr_period_ms: u16,
    pub ssr_min_slot_ms: u16,
    /// Fans on at start.
    pub fans_on_at_start: bool,
}

/// SPEC §4's line with the puller's `puller` drive (6:1 in the thesis
/// code, 4:1 in its table).
pub const fn extrusion_line(puller: DriveTrain) -> Result<ExtrusionLineMachine, VelocityConfigError> {
    let line = match ExtrusionLineConfig::thesis(puller) {
        Ok(line) => line,
        Err(error) => return Err(error),
    };
    Ok(ExtrusionLineMachine {
        pins: ExtrusionLinePins {
            extruder: ramps::E0,
            puller: ramps::X,
            barrel_ssr: ramps::D9,
            fans: ramps::D8,
            barrel_adc: 13,
            thermistor_series_ohms: 4_800,
        },
        line,
        min_extrusion_temperature: MIN_EXTRUSION_TEMPERATURE,
        barrel_kp: 2.4,
        barrel_ki: 0.008,
        ssr_period_ms: 200,
        ssr_min_slot_ms: 10,
        fans_on_at_start: true,
    })
}

/// The line the `machine-extrusion-line` build runs: the puller 6:1 as in
/// the thesis' code.
pub const EXTRUSION_LINE: ExtrusionLineMachine = match extrusion_line(DriveTrain::PULLER_6_TO_1) {
    Ok(machine) => machine,
    Err(_) => panic!("the thesis' drive trains fit the step timer"),
};

/// The diameter settings the line starts with.
pub const EXTRUSION_DIAMETER: DiameterSettings = DiameterSettings::THESIS;

/// One DC carriage axis: VNH5019 and quadrature encoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServoAxisPins {
    pub pwm: MegaPin,
    pub ina: MegaPin,
    pub inb: MegaPin,
    pub diag: MegaPin,
    pub encoder_a: MegaPin,
    pub encoder_b: MegaPin,
}

/// A 4-bit HD44780.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LcdPins {
    pub rs: MegaPin,
    pub e: MegaPin,
    pub data: [MegaPin; 4],
}

/// The powder bed's pins (ours, SPEC §5 gives none).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PowderBedPins {
    pub feed: StepperPins,
    pub build: StepperPins,
    /// Reed switches (A lower, B upper) of feed and build.
    pub feed_lower: MegaPin,
    pub feed_upper: MegaPin,
    pub build_lower: MegaPin,
    pub build_upper: MegaPin,
    pub carriage_x: ServoAxisPins,
    pub carriage_y: ServoAxisPins,
    pub carriage_minus: MegaPin,
    pub carriage_plus: MegaPin,
    pub roller: MegaPin,
    pub suction: MegaPin,
    pub lcd: LcdPins,
}

/// Everything the powder-bed build needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PowderBedMachine {
    pub pins: PowderBedPins,
    pub platform: PlatformDriver,
    pub switch_active: ActiveLevel,
    pub carriage_sensor_active: ActiveLevel,
    pub travel: TravelLimits,
    pub layer: LayerSettings,
    /// Platform step rate of the routines (the thesis: 1 kHz, no ramp).
    pub platform_step_hz: u16,
    /// Quadrature counts per motor revolution as read (SPEC §5: 200).
    pub encoder_counts_per_rev: u16,
}

/// SPEC §5 with our pin map (see the module docs).
pub const fn powder_bed() -> PowderBedMachine {
    PowderBedMachine {
        pins: PowderBedPins {
            feed: ramps::Z,
            build: ramps::E0,
            feed_lower: ramps::Z_MIN,
            feed_upper: ramps::Z_MAX,
            build_lower: ramps::Y_MIN,
            build_upper: ramps::Y_MAX,
            carriage_x: ServoAxisPins {
                pwm: MegaPin(44),
                ina: MegaPin(40),
                inb: MegaPin(42),
                diag: MegaPin::analog(5),
                encoder_a: MegaPin(2),
                encoder_b: MegaPin(3),
            },
            carriage_y: ServoAxisPins {
                pwm: MegaPin(45),
                ina: MegaPin::analog(9),
                inb: MegaPin::analog(10),
                diag: MegaPin::analog(11),
                encoder_a: MegaPin(20),
                encoder_b: MegaPin(21),
            },
            carriage_minus: MegaPin(11),
            carriage_plus: MegaPin(6),
            roller: ramps::D10,
            suction: ramps::D8,
            lcd: LcdPins { rs: MegaPin(16), e: MegaPin(17), data: [MegaPin(23), MegaPin(25), MegaPin(27), MegaPin(29)] },
        },
        platform: PlatformDriver::M542,
        switch_active: ActiveLevel::Low,
        carriage_sensor_active: ActiveLevel::Low,
        travel: TravelLimits::DEFAULT,
        layer: LayerSettings { thickness_um: 100, suction_while_spreading: true },
        platform_step_hz: 1000,
        encoder_counts_per_rev: 200,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// No pin is used twice within a machine.
    fn unique(pins: &[MegaPin]) -> bool {
        let mut seen = [false; 70];
        pins.iter().all(|p| !core::mem::replace(&mut seen[usize::from(p.0)], true))
    }

    fn stepper(p: StepperPins) -> [MegaPin; 3] {
        [p.step, p.dir, p.enable]
    }

    #[test]
    fn extrusion_line_uses_the_thesis_pins() {
        let m = extrusion_line(DriveTrain::PULLER_6_TO_1).unwrap();
        assert_eq!(stepper(m.pins.extruder), [MegaPin(26), MegaPin(28), MegaPin(24)]);
        assert_eq!(stepper(m.pins.puller), [MegaPin(54), MegaPin(55), MegaPin(38)]);
        assert_eq!((m.pins.barrel_ssr, m.pins.fans, m.pins.barrel_adc), (MegaPin(9), MegaPin(8), 13));
        assert_eq!(m.pins.thermistor_series_ohms, 4_800);
        assert_eq!(m.min_extrusion_temperature, Celsius(17_500));
        let mut all = std::vec::Vec::new();
        all.extend(stepper(m.pins.extruder));
        all.extend(stepper(m.pins.puller));
        all.extend([m.pins.barrel_ssr, m.pins.fans, MegaPin::analog(m.pins.barrel_adc)]);
        assert!(unique(&all));
    }

    #[test]
    fn powder_bed_pins_do_not_clash() {
        let m = powder_bed();
        let p = m.pins;
        let mut all = std::vec::Vec::new();
        all.extend(stepper(p.feed));
        all.extend(stepper(p.build));
        all.extend([p.feed_lower, p.feed_upper, p.build_lower, p.build_upper, p.carriage_minus, p.carriage_plus, p.roller, p.suction]);
        for axis in [p.carriage_x, p.carriage_y] {
            all.extend([axis.pwm, axis.ina, axis.inb, axis.diag, axis.encoder_a, axis.encoder_b]);
        }
        all.extend([p.lcd.rs, p.lcd.e]);
        all.extend(p.lcd.data);
        assert!(unique(&all));
        assert!(!MachineKind::PowderBed.has_heaters());
    }

    #[test]
    fn printer_pin_maps_do_not_clash() {
        for pins in [prusa_i3_pins(), delta_pins(), arm_pins()] {
            let mut all = std::vec::Vec::new();
            for s in pins.steppers.iter().flatten() {
                all.extend(stepper(*s));
            }
            all.extend(pins.endstops.iter().flatten());
            all.extend([pins.hotend, pins.bed, pins.fan].iter().flatten());
            all.extend(pins.inputs.iter().flatten());
            all.extend([pins.hotend_adc, pins.bed_adc].iter().flatten().map(|&c| MegaPin::analog(c)));
            assert!(unique(&all), "{pins:?}");
        }
    }
}
