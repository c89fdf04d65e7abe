//! The machine's tunable settings: what `M92`, `M201`, `M203`, `M204`,
//! `M205`, `M220` and `M221` change and `M503` prints (and, once storage
//! lands, what `M500`/`M501` save and load).
//!
//! Values are fixed point with three decimals ("milli" units) so that they
//! print back exactly as typed and need no float: steps/mm × 1000, mm/s ×
//! 1000 (= µm/s), mm/s² × 1000 (= µm/s²). Units are Marlin's.

use crate::machine::modal::{AXES, AXIS_LETTERS};
use crate::reply::Fixed;
use ufmt::uWrite;

/// Every tunable value. `repr(C)` and only 32-bit integer fields: the
/// storage image is this struct's bytes (see `storage`).
#[derive(Clone, Debug, PartialEq, Eq)]
#[repr(C)]
pub struct Settings {
    /// `M92`: steps per mm × 1000, per axis X Y Z E.
    pub steps_per_mm_milli: [i32; AXES],
    /// `M203`: maximum feed rate per axis, µm/s.
    pub max_feed_um_per_s: [i32; AXES],
    /// `M201`: maximum acceleration per axis, µm/s².
    pub max_accel_um_per_s2: [i32; AXES],
    /// `M204 P`: acceleration of printing moves, µm/s².
    pub print_accel_um_per_s2: i32,
    /// `M204 R`: acceleration of retracts (E-only moves), µm/s².
    pub retract_accel_um_per_s2: i32,
    /// `M204 T`: acceleration of travel (non-extruding) moves, µm/s².
    pub travel_accel_um_per_s2: i32,
    /// `M205 J`: junction deviation, µm (Marlin's default 0.013 mm).
    pub junction_deviation_um: i32,
    /// `M205 S`: minimum feed rate of printing moves, µm/s.
    pub min_feed_um_per_s: i32,
    /// `M205 T`: minimum feed rate of travel moves, µm/s.
    pub min_travel_feed_um_per_s: i32,
    /// `M205 B`: minimum segment time, µs.
    pub min_segment_time_us: i32,
    /// `M220 S`: feed-rate override, percent.
    pub feed_percent: i32,
    /// `M221 S`: flow (extrusion) override, percent.
    pub flow_percent: i32,
    /// `M301 P I D` (hot end) and the bed's gains, Marlin's units × 10⁴
    /// (see `thermal::Gains`); `M303 U1` sets them too.
    pub hotend_pid: [i32; 3],
    pub bed_pid: [i32; 3],
}

/// Numbers of the fields [`Settings::field_mut`] reaches (the per-axis
/// arrays take four each, X Y Z E).
pub mod field {
    pub const STEPS_PER_MM: usize = 0;
    pub const MAX_FEED: usize = 4;
    pub const MAX_ACCEL: usize = 8;
    pub const PRINT_ACCEL: usize = 12;
    pub const RETRACT_ACCEL: usize = 13;
    pub const TRAVEL_ACCEL: usize = 14;
    pub const JUNCTION_DEVIATION: usize = 15;
    pub const MIN_FEED: usize = 16;
    pub const MIN_TRAVEL_FEED: usize = 17;
    pub const MIN_SEGMENT_TIME: usize = 18;
    pub const FEED_PERCENT: usize = 19;
    pub const FLOW_PERCENT: usize = 20;
}

impl Default for Settings {
    fn default() -> Self {
        Self::prusa_i3()
    }
}

/// Number of `i32` fields of [`Settings`] (its only fields).
const FIELDS: usize = 27;
const _: () = assert!(core::mem::size_of::<Settings>() == FIELDS * 4);

/// [`Settings::prusa_i3`] in flash, field by field, for
/// [`Settings::init_for_machine`].
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
static PRUSA_I3: crate::progmem::Flash<[i32; FIELDS]> =
    crate::progmem::Flash::new(prusa_i3_fields());

const fn prusa_i3_fields() -> [i32; FIELDS] {
    // SAFETY: `Settings` is `repr(C)` with exactly `FIELDS` `i32`s.
    unsafe { core::mem::transmute::<Settings, [i32; FIELDS]>(Settings::prusa_i3()) }
}

/// `value` × 1000, rounded, to `slot`: a figure in milli-units. By
/// reference: each call is two pointers.
#[inline(never)]
fn milli(value: &f32, slot: &mut i32) {
    *slot = crate::motion::math::round_to_i32(*value * 1000.0);
}

impl Settings {
    /// The defaults of a machine: its motion configuration's figures in
    /// milli-units, the rest as on the Prusa i3.
    pub fn for_machine(config: &crate::motion::MotionConfig) -> Self {
        let mut settings = core::mem::MaybeUninit::uninit();
        Self::init_for_machine(&mut settings, config);
        // SAFETY: `init_for_machine` wrote every field.
        unsafe { settings.assume_init() }
    }

    /// [`Settings::for_machine`] written in place (the machine builds its
    /// defaults in their field). The Prusa i3's image is copied out of
    /// flash and the configured figures written over it: field by field,
    /// the constants cost four bytes of code per byte.
    #[inline(never)]
    pub fn init_for_machine(
        slot: &mut core::mem::MaybeUninit<Self>,
        config: &crate::motion::MotionConfig,
    ) {
        let values = slot.as_mut_ptr().cast::<i32>();
        for index in 0..FIELDS {
            // SAFETY: `Settings` is `repr(C)` and holds `FIELDS` `i32`s
            // and nothing else (asserted below), so `index` is in it.
            unsafe { values.add(index).write(PRUSA_I3.get(index).unwrap_or(0)) };
        }
        // SAFETY: every field was written above.
        let settings = unsafe { slot.assume_init_mut() };
        for axis in 0..AXES {
            milli(
                &config.steps_per_mm[axis],
                &mut settings.steps_per_mm_milli[axis],
            );
            milli(
                &config.max_feed[axis],
                &mut settings.max_feed_um_per_s[axis],
            );
            milli(
                &config.max_accel[axis],
                &mut settings.max_accel_um_per_s2[axis],
            );
        }
        milli(&config.print_accel, &mut settings.print_accel_um_per_s2);
        milli(&config.retract_accel, &mut settings.retract_accel_um_per_s2);
        milli(&config.travel_accel, &mut settings.travel_accel_um_per_s2);
        milli(
            &config.junction_deviation,
            &mut settings.junction_deviation_um,
        );
    }

    /// SPEC §1: the Cartesian Prusa i3 on RAMPS (A4988 at 1/16, GT2 16-tooth
    /// pulleys: 100 steps/mm on X and Y; M8 Z rods: 400 steps/mm; E 93).
    pub const fn prusa_i3() -> Self {
        Self {
            steps_per_mm_milli: [100_000, 100_000, 400_000, 93_000],
            max_feed_um_per_s: [300_000, 300_000, 5_000, 25_000],
            max_accel_um_per_s2: [3_000_000, 3_000_000, 100_000, 10_000_000],
            print_accel_um_per_s2: 1_500_000,
            retract_accel_um_per_s2: 1_500_000,
            travel_accel_um_per_s2: 1_500_000,
            junction_deviation_um: 13,
            min_feed_um_per_s: 0,
            min_travel_feed_um_per_s: 0,
            min_segment_time_us: 20_000,
            feed_percent: 100,
            flow_percent: 100,
            // Marlin's DEFAULT_Kp/Ki/Kd and DEFAULT_bedKp/Ki/Kd.
            hotend_pid: [222_000, 10_800, 1_140_000],
            bed_pid: [100_000, 230, 3_054_000],
        }
    }

    /// The `i32` field numbered `index` ([`field`] names them), for the
    /// table-driven setting commands (`M92`, `M201`, ...); `None` past the
    /// last.
    pub fn field_mut(&mut self, index: u8) -> Option<&mut i32> {
        let index = usize::from(index);
        Some(match index {
            field::STEPS_PER_MM..=3 => &mut self.steps_per_mm_milli[index - field::STEPS_PER_MM],
            field::MAX_FEED..=7 => &mut self.max_feed_um_per_s[index - field::MAX_FEED],
            field::MAX_ACCEL..=11 => &mut self.max_accel_um_per_s2[index - field::MAX_ACCEL],
            field::PRINT_ACCEL => &mut self.print_accel_um_per_s2,
            field::RETRACT_ACCEL => &mut self.retract_accel_um_per_s2,
            field::TRAVEL_ACCEL => &mut self.travel_accel_um_per_s2,
            field::JUNCTION_DEVIATION => &mut self.junction_deviation_um,
            field::MIN_FEED => &mut self.min_feed_um_per_s,
            field::MIN_TRAVEL_FEED => &mut self.min_travel_feed_um_per_s,
            field::MIN_SEGMENT_TIME => &mut self.min_segment_time_us,
            field::FEED_PERCENT => &mut self.feed_percent,
            field::FLOW_PERCENT => &mut self.flow_percent,
            _ => return None,
        })
    }

    /// `M503`: the settings as the commands that would set them, in
    /// Marlin's layout.
    pub fn report<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        crate::flash_str!("echo:; Steps per unit:\necho:  M92").write_to(out)?;
        write_axes(out, &self.steps_per_mm_milli)?;
        crate::flash_str!("\necho:; Max feedrates (units/s):\necho:  M203").write_to(out)?;
        write_axes(out, &self.max_feed_um_per_s)?;
        crate::flash_str!("\necho:; Max Acceleration (units/s2):\necho:  M201").write_to(out)?;
        write_axes(out, &self.max_accel_um_per_s2)?;
        crate::flash_str!(
            "\necho:; Acceleration (units/s2) (P<print-accel> R<retract-accel> T<travel-accel>):\necho:  M204"
        )
        .write_to(out)?;
        write_milli_word(out, b'P', self.print_accel_um_per_s2)?;
        write_milli_word(out, b'R', self.retract_accel_um_per_s2)?;
        write_milli_word(out, b'T', self.travel_accel_um_per_s2)?;
        crate::flash_str!(
            "\necho:; Advanced (B<min_segment_time_us> S<min_feedrate> T<min_travel_feedrate> J<junc_dev>):\necho:  M205"
        )
        .write_to(out)?;
        write_word(out, b'B', self.min_segment_time_us, 0)?;
        write_milli_word(out, b'S', self.min_feed_um_per_s)?;
        write_milli_word(out, b'T', self.min_travel_feed_um_per_s)?;
        write_word(out, b'J', self.junction_deviation_um, 3)?;
        crate::flash_str!("\necho:; Feedrate and flow:\necho:  M220").write_to(out)?;
        write_word(out, b'S', self.feed_percent, 0)?;
        crate::flash_str!("\necho:  M221").write_to(out)?;
        write_word(out, b'S', self.flow_percent, 0)?;
        out.write_str("\n")?;
        crate::flash_str!("echo:; Hotend PID:\necho:  ").write_to(out)?;
        let [kp, ki, kd] = self.hotend_pid;
        if let Some(gains) = crate::thermal::Gains::new(kp, ki, kd) {
            gains.write_m301(out)?;
        }
        crate::flash_str!("\necho:; Bed PID:\necho:  ").write_to(out)?;
        let [kp, ki, kd] = self.bed_pid;
        if let Some(gains) = crate::thermal::Gains::new(kp, ki, kd) {
            gains.write_as(304, out)?;
        }
        out.write_str("\n")
    }
}

/// ` <letter><value>`: a word of `M503`'s report, `mantissa × 10^-digits`
/// with every decimal. One out-of-line writer for every word: each
/// `uwrite!` of a word inlined its own formatter calls.
#[inline(never)]
fn write_word<W: uWrite + ?Sized>(
    out: &mut W,
    letter: u8,
    mantissa: i32,
    digits: u8,
) -> Result<(), W::Error> {
    out.write_str(" ")?;
    out.write_char(char::from(letter))?;
    ufmt::uwrite!(out, "{}", Fixed { mantissa, digits })
}

/// ` <letter><value>` of a milli-unit value, with two decimals, rounded
/// (Marlin prints two).
#[inline(never)]
fn write_milli_word<W: uWrite + ?Sized>(
    out: &mut W,
    letter: u8,
    value: i32,
) -> Result<(), W::Error> {
    let rounded = if value >= 0 {
        (value + 5) / 10
    } else {
        (value - 5) / 10
    };
    write_word(out, letter, rounded, 2)
}

fn write_axes<W: uWrite + ?Sized>(out: &mut W, values: &[i32; AXES]) -> Result<(), W::Error> {
    for (letter, value) in AXIS_LETTERS.iter().zip(values) {
        write_milli_word(out, *letter, *value)?;
    }
    Ok(())
}
