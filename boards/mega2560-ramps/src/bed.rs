//! The powder-bed retrofit's hardware (cargo feature `machine-powder-bed`,
//! SPEC §5; pins from `firmware::machines::config::powder_bed`).
//!
//! | part | pins |
//! |---|---|
//! | feed platform (M542) | STEP D46 = PL3, DIR D48 = PL1, ENA A8 = PK0 |
//! | build platform (M542) | STEP D26 = PA4, DIR D28 = PA6, ENA D24 = PA2 |
//! | reed switches (to ground) | feed A D18 = PD3, B D19 = PD2; build A D14 = PJ1, B D15 = PJ0 |
//! | carriage encoder | A D2 = PE4 (INT4), B D3 = PE5 (INT5), both edges |
//! | carriage X H-bridge (VNH5019) | PWM D44 = PL5 (OC5C, 7.8 kHz), INA D40 = PG1, INB D42 = PL7, DIAG A5 = PF5 (low = fault) |
//! | carriage Y encoder | A D21 = PD0 (INT0), B D20 = PD1 (INT1), both edges |
//! | carriage Y H-bridge (VNH5019) | PWM D45 = PL4 (OC5B), INA A9 = PK1, INB A10 = PK2, DIAG A11 = PK3 |
//! | carriage end sensors (to ground) | C− D11 = PB5, C+ D6 = PH3 |
//! | roller, suction | D10 = PB4, D8 = PH5 (MOSFETs) |
//!
//! The quadrature decoder runs in the two external interrupts (the core's
//! `QuadratureDecoder::on_edge`: a table lookup and an add). Everything
//! else happens once a millisecond in the main loop ([`read`], the core's
//! `Machine::powder_bed_tick`, [`drive`]): an M542 step is DIR, 5 µs, the
//! falling STEP edge, 5 µs, STEP back high (the driver wants ≥ 5 µs each).
//!
//! Known limit: the carriage's servo loop runs at the main loop's
//! millisecond, so a main-loop pass longer than a few milliseconds (a long
//! report at 115 200 baud, a settings save) stretches its period. The
//! bridge must not keep its last duty meanwhile: the 1 kHz tick brakes it
//! when the main loop has not driven it for [`BRAKE_AFTER_MS`]
//! ([`on_tick`]), and the next pass drives it again. A stroke then runs
//! late, or ends in the loop's following-error stop, never runs away.

use crate::pins::{self, Pin, Port};
use avr_device::atmega2560::Peripherals;
use avr_device::interrupt::Mutex;
use core::cell::RefCell;
use firmware::closed_loop::quadrature::QuadratureDecoder;
use firmware::machine::powder_bed::{BedInputs, BedOutputs, PLATFORM};
use firmware::machines::powder_bed::{Platform, Vertical};

struct PlatformPins {
    step: Pin,
    dir: Pin,
    enable: Pin,
}

const FEED: PlatformPins = PlatformPins { step: pins::pin(Port::L, 3), dir: pins::pin(Port::L, 1), enable: pins::pin(Port::K, 0) };
const BUILD: PlatformPins = PlatformPins { step: pins::pin(Port::A, 4), dir: pins::pin(Port::A, 6), enable: pins::pin(Port::A, 2) };
const FEED_LOWER: Pin = pins::pin(Port::D, 3);
const FEED_UPPER: Pin = pins::pin(Port::D, 2);
const BUILD_LOWER: Pin = pins::pin(Port::J, 1);
const BUILD_UPPER: Pin = pins::pin(Port::J, 0);
const ENCODER_A: Pin = pins::pin(Port::E, 4);
const ENCODER_B: Pin = pins::pin(Port::E, 5);
const BRIDGE_PWM: Pin = pins::pin(Port::L, 5);
const BRIDGE_INA: Pin = pins::pin(Port::G, 1);
const BRIDGE_INB: Pin = pins::pin(Port::L, 7);
const BRIDGE_DIAG: Pin = pins::pin(Port::F, 5);
const ENCODER_Y_A: Pin = pins::pin(Port::D, 0);
const ENCODER_Y_B: Pin = pins::pin(Port::D, 1);
const BRIDGE_Y_PWM: Pin = pins::pin(Port::L, 4);
const BRIDGE_Y_INA: Pin = pins::pin(Port::K, 1);
const BRIDGE_Y_INB: Pin = pins::pin(Port::K, 2);
const BRIDGE_Y_DIAG: Pin = pins::pin(Port::K, 3);
const CARRIAGE_MINUS: Pin = pins::pin(Port::B, 5);
const CARRIAGE_PLUS: Pin = pins::pin(Port::H, 3);
const ROLLER: Pin = pins::pin(Port::B, 4);
const SUCTION: Pin = pins::pin(Port::H, 5);

/// COM5C1 / COM5B1: OC5C / OC5B driven by the timer (non-inverting).
const COM5C1: u8 = 1 << 3;
const COM5B1: u8 = 1 << 5;

/// The tick brakes the bridge after this long without [`drive`].
pub const BRAKE_AFTER_MS: u32 = 3;

/// When [`drive`] last ran (ms), and whether the bridge is driven.
static LAST_DRIVE: Mutex<core::cell::Cell<(u32, bool)>> = Mutex::new(core::cell::Cell::new((0, false)));

static DECODER: Mutex<RefCell<QuadratureDecoder>> = Mutex::new(RefCell::new(QuadratureDecoder::new(true, true, 0)));
static DECODER_Y: Mutex<RefCell<QuadratureDecoder>> = Mutex::new(RefCell::new(QuadratureDecoder::new(true, true, 0)));

/// Outputs safe, inputs pulled up, the encoder's interrupts on, Timer5 in
/// 8-bit fast PWM for the bridge (its output still disconnected).
pub fn init(dp: &Peripherals) {
    for platform in [&FEED, &BUILD] {
        // M542: STEP idles high, ENA high = disabled.
        pins::make_output(dp, platform.step, PLATFORM.step_idle_level());
        pins::make_output(dp, platform.dir, false);
        pins::make_output(dp, platform.enable, PLATFORM.enable_level(false));
    }
    for input in [FEED_LOWER, FEED_UPPER, BUILD_LOWER, BUILD_UPPER, CARRIAGE_MINUS, CARRIAGE_PLUS, BRIDGE_DIAG, ENCODER_A, ENCODER_B, BRIDGE_Y_DIAG, ENCODER_Y_A, ENCODER_Y_B] {
        pins::make_input_pulled_up(dp, input);
    }
    stop(dp);
    // Timer5: WGM52|WGM50 fast PWM 8-bit, CS51 clk/8 (7.8 kHz).
    // Mode 5: WGM53:52 = 01 (TCCR5B), WGM51:50 = 01 (TCCR5A).
    dp.TC5.tccr5a.write(|w| w.wgm5().bits(0b01));
    dp.TC5.tccr5b.write(|w| w.wgm5().bits(0b01).cs5().prescale_8());
    let (a, b) = (pins::read(dp, ENCODER_A), pins::read(dp, ENCODER_B));
    let (ya, yb) = (pins::read(dp, ENCODER_Y_A), pins::read(dp, ENCODER_Y_B));
    avr_device::interrupt::free(|cs| {
        *DECODER.borrow(cs).borrow_mut() = QuadratureDecoder::new(a, b, 0);
        *DECODER_Y.borrow(cs).borrow_mut() = QuadratureDecoder::new(ya, yb, 0);
    });
    // INT4, INT5 (X) and INT0, INT1 (Y) on any logical change (ISCn1:0 =
    // 01), then enabled.
    dp.EXINT.eicrb.modify(|_, w| w.isc4().val_0x01().isc5().val_0x01());
    dp.EXINT.eicra.modify(|_, w| w.isc0().val_0x01().isc1().val_0x01());
    dp.EXINT.eifr.write(|w| w.intf().bits(0b0011_0011));
    dp.EXINT.eimsk.modify(|r, w| w.int().bits(r.int().bits() | 0b0011_0011));
}

/// Carriage braked, roller and suction off, platform drivers disabled:
/// from any context (halt, `M112` in the receive interrupt, panic).
pub fn stop(dp: &Peripherals) {
    // SAFETY: clearing the bridges' compare-output bits only.
    dp.TC5.tccr5a.modify(|r, w| unsafe { w.bits(r.bits() & !(COM5C1 | COM5B1)) });
    for pin in [BRIDGE_PWM, BRIDGE_INA, BRIDGE_INB, BRIDGE_Y_PWM, BRIDGE_Y_INA, BRIDGE_Y_INB, ROLLER, SUCTION] {
        pins::make_output(dp, pin, false);
    }
    for platform in [&FEED, &BUILD] {
        pins::make_output(dp, platform.enable, PLATFORM.enable_level(false));
    }
}

/// What the machine needs to know this millisecond.
pub fn read(dp: &Peripherals) -> BedInputs {
    BedInputs {
        feed_switches: (pins::read(dp, FEED_LOWER), pins::read(dp, FEED_UPPER)),
        build_switches: (pins::read(dp, BUILD_LOWER), pins::read(dp, BUILD_UPPER)),
        // Sensors and DIAG pull low when active.
        at_minus: !pins::read(dp, CARRIAGE_MINUS),
        at_plus: !pins::read(dp, CARRIAGE_PLUS),
        carriage_count: avr_device::interrupt::free(|cs| DECODER.borrow(cs).borrow().count()),
        bridge_fault: !pins::read(dp, BRIDGE_DIAG),
        carriage_y_count: avr_device::interrupt::free(|cs| DECODER_Y.borrow(cs).borrow().count()),
        bridge_y_fault: !pins::read(dp, BRIDGE_Y_DIAG),
    }
}

/// Drive what the machine decided for millisecond `now_ms`.
pub fn drive(dp: &Peripherals, outputs: &BedOutputs, now_ms: u32) {
    avr_device::interrupt::free(|cs| LAST_DRIVE.borrow(cs).set((now_ms, outputs.carriage_duty != 0 || outputs.carriage_y_duty != 0)));
    for platform in [&FEED, &BUILD] {
        pins::make_output(dp, platform.enable, PLATFORM.enable_level(outputs.platforms_enabled));
    }
    if let Some((platform, direction)) = outputs.step {
        let pins = match platform {
            Platform::Feed => &FEED,
            Platform::Build => &BUILD,
        };
        step(dp, pins, direction);
    }
    pins::make_output(dp, ROLLER, outputs.roller);
    pins::make_output(dp, SUCTION, outputs.suction);
    set_bridge(dp, &BRIDGE_X, outputs.carriage_duty);
    set_bridge(dp, &BRIDGE_Y, outputs.carriage_y_duty);
}

struct Bridge {
    pwm: Pin,
    ina: Pin,
    inb: Pin,
    /// The channel's COM5x1 bit; `true`: OCR5C, `false`: OCR5B.
    com: u8,
    channel_c: bool,
}

const BRIDGE_X: Bridge = Bridge { pwm: BRIDGE_PWM, ina: BRIDGE_INA, inb: BRIDGE_INB, com: COM5C1, channel_c: true };
const BRIDGE_Y: Bridge = Bridge { pwm: BRIDGE_Y_PWM, ina: BRIDGE_Y_INA, inb: BRIDGE_Y_INB, com: COM5B1, channel_c: false };

/// One M542 step: DIR, ≥ 5 µs, the active (falling) edge, ≥ 5 µs, idle.
fn step(dp: &Peripherals, platform: &PlatformPins, direction: Vertical) {
    pins::make_output(dp, platform.dir, PLATFORM.dir_level(direction));
    avr_device::asm::delay_cycles(80);
    let idle = PLATFORM.step_idle_level();
    pins::make_output(dp, platform.step, !idle);
    avr_device::asm::delay_cycles(80);
    pins::make_output(dp, platform.step, idle);
}

/// A VNH5019: INA/INB set the direction, PWM the magnitude; 0 brakes
/// to ground (INA = INB = 0).
fn set_bridge(dp: &Peripherals, bridge: &Bridge, duty: i32) {
    let magnitude = duty.unsigned_abs().min(255) as u8;
    pins::make_output(dp, bridge.ina, duty > 0);
    pins::make_output(dp, bridge.inb, duty < 0);
    if bridge.channel_c {
        dp.TC5.ocr5c.write(|w| w.bits(u16::from(magnitude)));
    } else {
        dp.TC5.ocr5b.write(|w| w.bits(u16::from(magnitude)));
    }
    // SAFETY: this channel's COM bit only.
    dp.TC5.tccr5a.modify(|r, w| unsafe { w.bits(if magnitude == 0 { r.bits() & !bridge.com } else { r.bits() | bridge.com }) });
    // An output, low whenever the timer does not drive it.
    pins::make_output(dp, bridge.pwm, false);
}

/// From the 1 kHz tick: brake a bridge the main loop has left alone too
/// long (see the module docs).
pub fn on_tick(dp: &Peripherals, cs: avr_device::interrupt::CriticalSection, now_ms: u32) {
    let cell = LAST_DRIVE.borrow(cs);
    let (last, driven) = cell.get();
    if driven && now_ms.wrapping_sub(last) > BRAKE_AFTER_MS {
        // SAFETY: the bridges' COM bits only.
        dp.TC5.tccr5a.modify(|r, w| unsafe { w.bits(r.bits() & !(COM5C1 | COM5B1)) });
        for pin in [BRIDGE_PWM, BRIDGE_INA, BRIDGE_INB, BRIDGE_Y_PWM, BRIDGE_Y_INA, BRIDGE_Y_INB] {
            pins::make_output_in(dp, cs, pin, false);
        }
        cell.set((last, false));
    }
}

fn on_encoder_edge() {
    // SAFETY: reading port E's input register has no side effect.
    let dp = unsafe { Peripherals::steal() };
    let (a, b) = (pins::read(&dp, ENCODER_A), pins::read(&dp, ENCODER_B));
    avr_device::interrupt::free(|cs| DECODER.borrow(cs).borrow_mut().on_edge(a, b));
}

fn on_encoder_y_edge() {
    // SAFETY: reading port D's input register has no side effect.
    let dp = unsafe { Peripherals::steal() };
    let (a, b) = (pins::read(&dp, ENCODER_Y_A), pins::read(&dp, ENCODER_Y_B));
    avr_device::interrupt::free(|cs| DECODER_Y.borrow(cs).borrow_mut().on_edge(a, b));
}

#[avr_device::interrupt(atmega2560)]
fn INT0() {
    on_encoder_y_edge();
}

#[avr_device::interrupt(atmega2560)]
fn INT1() {
    on_encoder_y_edge();
}

#[avr_device::interrupt(atmega2560)]
fn INT4() {
    on_encoder_edge();
}

#[avr_device::interrupt(atmega2560)]
fn INT5() {
    on_encoder_edge();
}
