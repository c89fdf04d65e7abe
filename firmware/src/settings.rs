//! The machine's tunable settings: what `M92`, `M201`, `M203`, `M204`,
//! `M205`, `M220` and `M221` change and `M503` prints (and, once storage
//! lands, what `M500`/`M501` save and load).
//!
//! Values are fixed point with three decimals ("milli" units) so that they
//! print back exactly as typed and need no float: steps/mm × 1000, mm/s ×
//! 1000 (= µm/s), mm/s² × 1000 (= µm/s²). Units are Marlin's.

use crate::machine::modal::AXES;
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
    /// `M665 L R H` (a delta): rod length, radius and homed height, µm
    /// (zeros on other machines).
    pub delta_geometry_um: [i32; 3],
    /// `M666 X Y Z` (a delta): each tower's endstop trim, µm.
    pub delta_trim_um: [i32; 3],
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
const FIELDS: usize = 33;
const _: () = assert!(core::mem::size_of::<Settings>() == FIELDS * 4);

/// Fields of [`Settings`] taken from the motion configuration (the
/// first ones: steps/mm, feeds, accelerations, junction deviation).
const CONFIGURED: usize = field::JUNCTION_DEVIATION + 1;

/// Where each configured field's figure lies in `MotionConfig`, in bytes.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
static CONFIG_OFFSETS: crate::progmem::Flash<[u16; CONFIGURED]> = crate::progmem::Flash::new({
    use crate::motion::MotionConfig;
    use core::mem::offset_of;
    let mut offsets = [0u16; CONFIGURED];
    let mut axis = 0;
    while axis < AXES {
        offsets[field::STEPS_PER_MM + axis] =
            (offset_of!(MotionConfig, steps_per_mm) + 4 * axis) as u16;
        offsets[field::MAX_FEED + axis] = (offset_of!(MotionConfig, max_feed) + 4 * axis) as u16;
        offsets[field::MAX_ACCEL + axis] = (offset_of!(MotionConfig, max_accel) + 4 * axis) as u16;
        axis += 1;
    }
    offsets[field::PRINT_ACCEL] = offset_of!(MotionConfig, print_accel) as u16;
    offsets[field::RETRACT_ACCEL] = offset_of!(MotionConfig, retract_accel) as u16;
    offsets[field::TRAVEL_ACCEL] = offset_of!(MotionConfig, travel_accel) as u16;
    offsets[field::JUNCTION_DEVIATION] = offset_of!(MotionConfig, junction_deviation) as u16;
    offsets
});

/// The other fields of [`Settings::prusa_i3`], in flash, for
/// [`Settings::init_for_machine`].
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
static PRUSA_I3_REST: crate::progmem::Flash<[i32; FIELDS - CONFIGURED]> =
    crate::progmem::Flash::new({
        // SAFETY: `Settings` is `repr(C)` with exactly `FIELDS` `i32`s.
        let all = unsafe { core::mem::transmute::<Settings, [i32; FIELDS]>(Settings::prusa_i3()) };
        let mut rest = [0; FIELDS - CONFIGURED];
        let mut i = 0;
        while i < rest.len() {
            rest[i] = all[CONFIGURED + i];
            i += 1;
        }
        rest
    });

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
    /// defaults in their field), in one loop: each configured figure read
    /// at its offset in the configuration and rounded to milli-units, the
    /// rest copied out of flash. Field by field, the constants cost four
    /// bytes of code per byte, and each conversion its own call.
    pub fn init_for_machine(
        slot: &mut core::mem::MaybeUninit<Self>,
        config: &crate::motion::MotionConfig,
    ) {
        let values = slot.as_mut_ptr().cast::<i32>();
        let base = (config as *const crate::motion::MotionConfig).cast::<u8>();
        for index in 0..FIELDS {
            let value = match CONFIG_OFFSETS.get(index) {
                // SAFETY: the offset is that of an `f32` field of
                // `MotionConfig` (`offset_of!` above), so it lies inside
                // `*config` and is aligned.
                Some(offset) => {
                    let figure = unsafe { base.add(usize::from(offset)).cast::<f32>().read() };
                    crate::motion::math::round_to_i32(figure * 1000.0)
                }
                None => PRUSA_I3_REST.get(index - CONFIGURED).unwrap_or(0),
            };
            // SAFETY: `Settings` is `repr(C)` and holds `FIELDS` `i32`s
            // and nothing else (asserted above), so `index` is in it.
            unsafe { values.add(index).write(value) };
        }
        // A delta's geometry and trims (M665, M666), saved with the rest.
        #[cfg(feature = "delta")]
        if let crate::motion::kinematics::MachineKinematics::Delta(delta) = &config.kinematics {
            let um = |mm: f32| crate::motion::math::round_to_i32(mm * 1000.0);
            // SAFETY: every field was written by the loop above.
            let settings = unsafe { slot.assume_init_mut() };
            settings.delta_geometry_um = [um(delta.rod_length()), um(delta.radius()), um(delta.homed_height)];
            settings.delta_trim_um = delta.endstop_trim.map(um);
        }
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
            delta_geometry_um: [0; 3],
            delta_trim_um: [0; 3],
        }
    }

    /// The `i32` field numbered `index` ([`field`] names them), for the
    /// table-driven setting commands (`M92`, `M201`, ...); `None` past the
    /// last.
    pub fn field_mut(&mut self, index: u8) -> Option<&mut i32> {
        let index = usize::from(index);
        if index > field::FLOW_PERCENT {
            return None;
        }
        // SAFETY: `Settings` is `repr(C)` and holds `FIELDS` `i32`s and
        // nothing else, in the order [`field`] numbers them; `index` is
        // below `FIELDS`.
        Some(unsafe { &mut *(self as *mut Self).cast::<i32>().add(index) })
    }

    /// `M503`: the settings as the commands that would set them, in
    /// Marlin's layout: [`M503_SCRIPT`] read out, then each heater's gains.
    pub fn report<W: uWrite + ?Sized>(&self, out: &mut W) -> Result<(), W::Error> {
        let mut at = 0;
        for (&[kp, ki, kd], code) in [(&self.hotend_pid, 301), (&self.bed_pid, 304)] {
            at = self.write_script(at, out)?;
            if let Some(gains) = crate::thermal::Gains::new(kp, ki, kd) {
                gains.write_as(code, out)?;
            }
        }
        out.write_str("\n")?;
        // A delta's geometry and trims (zeros on other machines).
        if self.delta_geometry_um[0] > 0 {
            for (title, code, letters, values) in [
                ("echo:; Delta settings (L<diagonal rod> R<radius> H<height>):\n", 665u16, b"LRH", &self.delta_geometry_um),
                ("echo:; Endstop adjustment:\n", 666, b"XYZ", &self.delta_trim_um),
            ] {
                out.write_str(title)?;
                ufmt::uwrite!(out, "echo:  M{}", crate::reply::Whole(code))?;
                for (&letter, &um) in letters.iter().zip(values) {
                    let hundredths = if um >= 0 { (um + 5) / 10 } else { (um - 5) / 10 };
                    ufmt::uwrite!(out, " {}{}", char::from(letter), Fixed { mantissa: hundredths, digits: 2 })?;
                }
                out.write_str("\n")?;
            }
        }
        Ok(())
    }

    /// The `i32` field numbered `index` (0 past the last).
    fn value(&self, index: usize) -> i32 {
        if index >= FIELDS {
            return 0;
        }
        // SAFETY: `Settings` is `repr(C)` and holds `FIELDS` `i32`s and
        // nothing else, so field `index` lies inside it.
        unsafe { *(self as *const Self).cast::<i32>().add(index) }
    }

    /// [`M503_SCRIPT`] from byte `at` to the next NUL, with every field
    /// marker replaced by its value; returns where the next part starts.
    #[inline(never)]
    fn write_script<W: uWrite + ?Sized>(
        &self,
        mut at: usize,
        out: &mut W,
    ) -> Result<usize, W::Error> {
        while let Some(byte) = M503_SCRIPT.get(at) {
            at += 1;
            match byte {
                0 => break,
                // Stored without the `echo:` that follows it.
                b'\n' => {
                    out.write_char('\n')?;
                    crate::flash_str!(LINE_START).write_to(out)?;
                }
                1..=0x7F => out.write_char(char::from(byte))?,
                _ => {
                    let value = self.value(usize::from(byte & FIELD_MASK));
                    let (mantissa, digits) = match byte & !FIELD_MASK {
                        // Marlin prints two decimals, rounded.
                        MILLI => (
                            if value >= 0 {
                                (value + 5) / 10
                            } else {
                                (value - 5) / 10
                            },
                            2,
                        ),
                        WHOLE => (value, 0),
                        _ => (value, 3),
                    };
                    ufmt::uwrite!(out, "{}", Fixed { mantissa, digits })?;
                }
            }
        }
        Ok(at)
    }
}

/// In [`M503_SCRIPT`]: a byte with the top bit set stands for field
/// `byte & FIELD_MASK`, printed as `byte & !FIELD_MASK` says.
const FIELD_MASK: u8 = 0x1F;
/// A milli-unit value, shown with two decimals.
const MILLI: u8 = 0x80;
/// A whole number.
const WHOLE: u8 = 0xA0;
/// First field of the hot end's and of the bed's gains (P, I, D).
const HOTEND_PID: usize = 21;
const BED_PID: usize = 24;

/// `M503`'s text with markers for the values (see [`FIELD_MASK`]), in two
/// parts ended by NUL: up to the hot end's gains, up to the bed's. Every
/// line after the first starts with `echo:`: stored without it, and
/// [`Settings::write_script`] writes it after each newline.
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
static M503_SCRIPT: crate::progmem::Flash<[u8; SCRIPT_LEN]> = crate::progmem::Flash::new(script_bytes());

/// What every newline of [`M503_TEXT`] is followed by.
const LINE_START: &str = "echo:";

/// [`M503_TEXT`]'s length without the `echo:` after each newline.
const SCRIPT_LEN: usize = {
    let mut newlines = 0;
    let mut i = 0;
    while i < M503_TEXT.len() {
        if M503_TEXT[i] == b'\n' {
            newlines += 1;
        }
        i += 1;
    }
    M503_TEXT.len() - newlines * LINE_START.len()
};

const fn script_bytes() -> [u8; SCRIPT_LEN] {
    let mut bytes = [0; SCRIPT_LEN];
    let (mut from, mut to) = (0, 0);
    while from < M503_TEXT.len() {
        bytes[to] = M503_TEXT[from];
        to += 1;
        if M503_TEXT[from] == b'\n' {
            // Each newline is followed by `echo:` (checked here).
            let mut k = 0;
            while k < LINE_START.len() {
                assert!(M503_TEXT[from + 1 + k] == LINE_START.as_bytes()[k]);
                k += 1;
            }
            from += LINE_START.len();
        }
        from += 1;
    }
    bytes
}

const M503_TEXT: &[u8] = b"echo:; Steps per unit:\necho:  M92 X\x80 Y\x81 Z\x82 E\x83\n\
echo:; Max feedrates (units/s):\necho:  M203 X\x84 Y\x85 Z\x86 E\x87\n\
echo:; Max Acceleration (units/s2):\necho:  M201 X\x88 Y\x89 Z\x8a E\x8b\n\
echo:; Acceleration (units/s2) (P<print-accel> R<retract-accel> T<travel-accel>):\necho:  M204 P\x8c R\x8d T\x8e\n\
echo:; Advanced (B<min_segment_time_us> S<min_feedrate> T<min_travel_feedrate> J<junc_dev>):\n\
echo:  M205 B\xb2 S\x90 T\x91 J\xcf\n\
echo:; Feedrate and flow:\necho:  M220 S\xb3\necho:  M221 S\xb4\n\
echo:; Hotend PID:\necho:  \0\
\necho:; Bed PID:\necho:  \0";

const _: () = {
    // The markers above name these fields.
    use field::*;
    assert!(
        STEPS_PER_MM == 0
            && MAX_FEED == 4
            && MAX_ACCEL == 8
            && PRINT_ACCEL == 12
            && JUNCTION_DEVIATION == 15
    );
    assert!(MIN_FEED == 16 && MIN_SEGMENT_TIME == 18 && FEED_PERCENT == 19 && FLOW_PERCENT == 20);
    assert!(HOTEND_PID == FLOW_PERCENT + 1 && BED_PID == HOTEND_PID + 3 && BED_PID + 3 + 6 == FIELDS);
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_numbers_reach_their_fields() {
        let mut settings = Settings::prusa_i3();
        for index in 0..=field::FLOW_PERCENT as u8 {
            *settings.field_mut(index).unwrap() = -1 - i32::from(index);
        }
        assert_eq!(settings.field_mut(field::FLOW_PERCENT as u8 + 1), None);
        assert_eq!(settings.steps_per_mm_milli, [-1, -2, -3, -4]);
        assert_eq!(settings.max_feed_um_per_s, [-5, -6, -7, -8]);
        assert_eq!(settings.max_accel_um_per_s2, [-9, -10, -11, -12]);
        assert_eq!(settings.print_accel_um_per_s2, -13);
        assert_eq!(settings.retract_accel_um_per_s2, -14);
        assert_eq!(settings.travel_accel_um_per_s2, -15);
        assert_eq!(settings.junction_deviation_um, -16);
        assert_eq!(settings.min_feed_um_per_s, -17);
        assert_eq!(settings.min_travel_feed_um_per_s, -18);
        assert_eq!(settings.min_segment_time_us, -19);
        assert_eq!(settings.feed_percent, -20);
        assert_eq!(settings.flow_percent, -21);
        assert_eq!(settings.hotend_pid, Settings::prusa_i3().hotend_pid);
        assert_eq!(settings.value(HOTEND_PID), 222_000);
        assert_eq!(settings.value(BED_PID + 2), 3_054_000);
        assert_eq!(settings.value(FIELDS), 0);
    }

    #[test]
    fn every_configured_figure_lands_in_its_field() {
        let mut config = crate::motion::MotionConfig::prusa_i3();
        config.steps_per_mm = [1.0, 2.0, 3.0, 4.0];
        config.max_feed = [5.0, 6.0, 7.0, 8.0];
        config.max_accel = [9.0, 10.0, 11.0, 12.0];
        config.print_accel = 13.0;
        config.retract_accel = 14.0;
        config.travel_accel = 15.0;
        config.junction_deviation = 0.0165;
        let settings = Settings::for_machine(&config);
        assert_eq!(settings.steps_per_mm_milli, [1000, 2000, 3000, 4000]);
        assert_eq!(settings.max_feed_um_per_s, [5000, 6000, 7000, 8000]);
        assert_eq!(settings.max_accel_um_per_s2, [9000, 10000, 11000, 12000]);
        assert_eq!(settings.print_accel_um_per_s2, 13000);
        assert_eq!(settings.retract_accel_um_per_s2, 14000);
        assert_eq!(settings.travel_accel_um_per_s2, 15000);
        assert_eq!(settings.junction_deviation_um, 17);
        let prusa = Settings::prusa_i3();
        assert_eq!(settings.min_segment_time_us, prusa.min_segment_time_us);
        assert_eq!(
            (settings.hotend_pid, settings.bed_pid),
            (prusa.hotend_pid, prusa.bed_pid)
        );
    }

    #[test]
    fn the_flash_image_is_the_prusa_i3() {
        let config = crate::motion::MotionConfig::prusa_i3();
        assert_eq!(Settings::for_machine(&config), Settings::prusa_i3());
    }
}
