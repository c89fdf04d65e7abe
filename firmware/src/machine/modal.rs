//! Modal state, as RS274/NGC and the RepRap firmwares define it: what a
//! line means depends on earlier lines.
//!
//! - `G90`/`G91`: absolute or relative X, Y, Z (and E, as in Marlin);
//!   `M82`/`M83` switch E alone;
//! - `G20`/`G21`: inches or millimetres for every length and feed rate;
//! - `F`: the feed rate persists until changed (mm/min or in/min);
//! - `G92`: declares the current position to be a given value, by shifting
//!   the logical coordinates (the machine does not move);
//! - `G0`/`G1`/`G2`/`G3`: the motion mode, repeated by a line of bare axis
//!   words (`X5 Y6`).
//!
//! Lengths are kept in whole micrometres (`i32`: ±2147 m, so even a long
//! print's absolute E fits), exact for millimetre and inch input alike
//! (1 in = 25 400 µm). Feed rates are in µm/s.

use super::error::CommandError;
use crate::gcode::{Command, Decimal, Code};

/// Axes a move names, in this order.
pub const AXIS_LETTERS: [u8; 4] = [b'X', b'Y', b'Z', b'E'];
/// Number of axes the executor tracks.
pub const AXES: usize = AXIS_LETTERS.len();
// The per-axis settings are these axes.
const _: () = assert!(AXES == crate::settings::AXES);

/// Largest coordinate accepted, in µm (±2000 m leaves headroom in `i32`).
pub const MAX_COORDINATE_UM: i32 = 2_000_000_000;
/// Highest feed rate accepted, in µm/s (100 m/s: far beyond any machine,
/// but a typo like `F6000000` is refused rather than clamped silently).
pub const MAX_FEED_UM_PER_S: i32 = 100_000_000;

/// A position or a distance per axis (X, Y, Z, E), in µm.
pub type Position = [i32; AXES];

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Distance {
    Absolute,
    Relative,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Units {
    Millimetres,
    Inches,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MotionMode {
    Rapid,
    Linear,
    ClockwiseArc,
    CounterClockwiseArc,
}

/// The modal state of the interpreter.
#[derive(Clone, Debug)]
pub struct ModalState {
    pub motion_mode: MotionMode,
    /// `G90`/`G91` for X, Y, Z.
    pub distance: Distance,
    /// `M82`/`M83` for E.
    pub extruder_distance: Distance,
    pub units: Units,
    /// Current feed rate in µm/s (Marlin's default: 1500 mm/min).
    pub feed_um_per_s: i32,
    /// Where the machine is (or will be, once queued motion completes), in
    /// machine coordinates.
    pub position: Position,
    /// What the program asked for beyond the µm of `position`, in nm per
    /// axis (within ±500): the exact position is `position + residue/1000`
    /// µm. Carried into the next relative move (round and carry), so a
    /// file's steps add up to its exact positions however many decimals it
    /// writes (issue 22: 200 × `G1 E.04929` made 49 µm each, 0.6 % short).
    pub residue_nm: [i16; AXES],
    /// The residues of the target [`ModalState::target`] computed last,
    /// committed with it ([`ModalState::commit`]).
    pending_residue_nm: core::cell::Cell<[i16; AXES]>,
    /// `G92` shift: logical = machine + offset.
    pub offset: Position,
    /// `G17`/`G18`/`G19`: the plane of arcs.
    pub plane: Plane,
    /// A mode this firmware does not run (`G93` inverse-time feed) was
    /// asked for: moves are refused until it is switched back (`G94`) or
    /// the program ends (`M2`/`M30`), so no move runs in a mode other than
    /// the one the program meant.
    pub unsupported: Option<Code>,
    /// `G53` on the line being executed: its target is in machine
    /// coordinates (no `G92` shift) and absolute. Cleared after the line.
    pub machine_frame: bool,
    /// `G54`–`G59`: the work coordinate system in use (0 = `G54`).
    pub work: u8,
    /// Where each work system's zero lies in machine coordinates, µm, X Y Z
    /// (`G10 L2`/`L20`; Grbl's). All zero at power-up (they are not saved).
    pub work_offsets: [[i32; 3]; WORK_SYSTEMS],
}

/// `G54`–`G59`.
pub const WORK_SYSTEMS: usize = 6;

pub use crate::motion::Plane;

impl Default for ModalState {
    fn default() -> Self {
        Self::new()
    }
}

impl ModalState {
    pub const fn new() -> Self {
        Self {
            motion_mode: MotionMode::Linear,
            distance: Distance::Absolute,
            extruder_distance: Distance::Absolute,
            units: Units::Millimetres,
            feed_um_per_s: 25_000,
            position: [0; AXES],
            residue_nm: [0; AXES],
            pending_residue_nm: core::cell::Cell::new([0; AXES]),
            offset: [0; AXES],
            plane: Plane::Xy,
            unsupported: None,
            machine_frame: false,
            work: 0,
            work_offsets: [[0; 3]; WORK_SYSTEMS],
        }
    }

    /// [`ModalState::new`] written in place: the zeros (positions, offsets,
    /// the work systems) with one fill, then every other field. Built on
    /// the stack and copied, the 72 bytes of work offsets cost a loop and
    /// a copy.
    ///
    /// # Safety
    /// `p` is valid for writes of a `ModalState`.
    pub unsafe fn init_in(p: *mut Self) {
        use core::ptr::addr_of_mut;
        // SAFETY: `p` is valid (caller); the fill makes every integer zero,
        // and each field that is not an integer is written below, before
        // anything reads the state.
        unsafe {
            core::ptr::write_bytes(p, 0, 1);
            addr_of_mut!((*p).motion_mode).write(MotionMode::Linear);
            addr_of_mut!((*p).distance).write(Distance::Absolute);
            addr_of_mut!((*p).extruder_distance).write(Distance::Absolute);
            addr_of_mut!((*p).units).write(Units::Millimetres);
            addr_of_mut!((*p).feed_um_per_s).write(25_000);
            addr_of_mut!((*p).plane).write(Plane::Xy);
            addr_of_mut!((*p).unsupported).write(None);
            addr_of_mut!((*p).machine_frame).write(false);
        }
    }

    /// logical = machine + this, per axis: the `G92` shift less the work
    /// system's zero (X, Y, Z; E has no work offset).
    pub fn shift(&self, axis: usize) -> i32 {
        sat_sub(self.offset[axis], self.work_zero(axis))
    }

    /// The work system's zero on `axis` (0 for E).
    #[inline(always)]
    fn work_zero(&self, axis: usize) -> i32 {
        // `work` is always below WORK_SYSTEMS (G54–G59 set it); `get`
        // rather than `%`, which cost a division on the AVR.
        self.work_offsets.get(usize::from(self.work)).and_then(|zero| zero.get(axis)).copied().unwrap_or(0)
    }

    /// The logical position (what `M114` reports and `G90` targets mean).
    pub fn logical_position(&self) -> Position {
        let mut logical = [0; AXES];
        for (axis, value) in logical.iter_mut().enumerate() {
            *value = self.logical(axis);
        }
        logical
    }

    /// The logical position of one axis.
    pub fn logical(&self, axis: usize) -> i32 {
        sat_add(self.position[axis], self.shift(axis))
    }

    /// A length word in µm, in the current units.
    pub fn length_um(&self, letter: u8, value: Decimal) -> Result<i32, CommandError> {
        // One scaling call for both units: thousandths of a mm are µm,
        // hundred-thousandths of an inch are converted.
        let inches = self.units == Units::Inches;
        let scaled = value.to_scaled(if inches { 5 } else { 3 }).ok_or(CommandError::OutOfRange(letter))?;
        let um = if inches { inches_to_um(scaled) } else { scaled };
        if um.unsigned_abs() > MAX_COORDINATE_UM as u32 {
            return Err(CommandError::OutOfRange(letter));
        }
        Ok(um)
    }

    /// Read `F` if present: it must be positive (`F0` and negative feeds are
    /// refused, and the stored feed rate is left as it was).
    pub fn read_feed(&self, command: &Command) -> Result<Option<i32>, CommandError> {
        let Some(value) = command.value(b'F')? else { return Ok(None) };
        if value.is_negative() || value.is_zero() {
            return Err(CommandError::InvalidFeedRate);
        }
        // Positive (checked above), so the unsigned shift-add division is
        // exact (a 32-bit `/` costs over a thousand cycles on the AVR).
        let per_minute = self.length_um(b'F', value)?;
        let per_second = crate::gcode::number::div_60(per_minute as u32) as i32;
        if per_second == 0 || per_second > MAX_FEED_UM_PER_S {
            return Err(CommandError::InvalidFeedRate);
        }
        Ok(Some(per_second))
    }

    /// The machine-coordinate target of a move word set (`X`, `Y`, `Z`,
    /// `E`), honouring G90/G91, M82/M83, G20/G21 and G92. Axes not named
    /// stay where they are. Nothing is changed: the caller commits the
    /// target once the move is accepted.
    pub fn target(&self, command: &Command) -> Result<Position, CommandError> {
        let mut target = self.position;
        let mut residues = self.residue_nm;
        for (axis, &letter) in AXIS_LETTERS.iter().enumerate() {
            let Some(value) = command.value(letter)? else { continue };
            let distance = if letter == b'E' { self.extruder_distance } else { self.distance };
            let relative = distance == Distance::Relative && !(self.machine_frame && letter != b'E');
            // The value in nm (millimetres only, and within `i32`: ±2 m);
            // otherwise µm as before, and no residue.
            let nm = if self.units == Units::Millimetres { value.to_scaled(6) } else { None };
            let carried = if relative { residues[axis] } else { 0 };
            let (um, residue) = match nm {
                // A whole number of µm (≤ 3 decimals, a slicer's X and Y)
                // with a residue strictly inside ±500 nm: the sum's split
                // is that µm and that residue, without the division.
                Some(_) if value.fraction_digits() <= 3 && carried.unsigned_abs() < 500 => {
                    (value.to_scaled(3).ok_or(CommandError::OutOfRange(letter))?, carried)
                }
                Some(nm) => split_nm(nm.saturating_add(i32::from(carried))),
                // Within ±2 147 mm in nm, the µm are far inside
                // MAX_COORDINATE_UM: only the other values need the check.
                None => (self.length_um(letter, value)?, 0),
            };
            residues[axis] = residue;
            // Checked `i32` rather than `i64` (half the code on the AVR): a
            // sum that overflows `i32` lies beyond MAX_COORDINATE_UM anyway.
            let machine = match distance {
                _ if self.machine_frame && letter != b'E' => Some(um),
                Distance::Absolute => um.checked_sub(self.shift(axis)),
                Distance::Relative => self.position[axis].checked_add(um),
            };
            match machine {
                Some(machine) if machine.unsigned_abs() <= MAX_COORDINATE_UM as u32 => target[axis] = machine,
                _ => return Err(CommandError::OutOfRange(letter)),
            }
        }
        self.pending_residue_nm.set(residues);
        Ok(target)
    }

    /// The move to `target` (from [`ModalState::target`]) was accepted: it
    /// is the position now, with the residues computed for it.
    pub fn commit(&mut self, target: &Position) {
        self.position = *target;
        self.residue_nm = self.pending_residue_nm.get();
    }

    /// `G92`: declare the named axes' logical position (all axes to zero
    /// when none is named, as in Marlin).
    pub fn set_logical_position(&mut self, command: &Command) -> Result<(), CommandError> {
        let mut offset = self.offset;
        let named = AXIS_LETTERS.iter().any(|&l| command.has(l));
        for (axis, &letter) in AXIS_LETTERS.iter().enumerate() {
            let value = match command.value(letter)? {
                Some(value) => self.length_um(letter, value)?,
                None if !named => 0,
                None => continue,
            };
            // logical = machine + G92 − work zero = value
            offset[axis] = sat_add(sat_sub(value, self.position[axis]), self.work_zero(axis));
            // The program's frame starts again at exactly `value`.
            self.residue_nm[axis] = 0;
        }
        self.offset = offset;
        Ok(())
    }

    /// `G10 L<n>` (the caller saw `L`): `L2` or `L20`, else out of range.
    #[inline(always)]
    pub fn work_offsets_command(&mut self, command: &Command) -> Result<(), CommandError> {
        let l20 = match command.value(b'L')?.and_then(|l| l.to_int()) {
            Some(2) => false,
            Some(20) => true,
            _ => return Err(CommandError::OutOfRange(b'L')),
        };
        self.set_work_offsets(command, l20)
    }

    /// `G10 L2 P<n>` (`l20`: false) sets work system `n`'s zero to the
    /// given machine coordinates; `G10 L20 P<n>` (true) sets it so that
    /// the machine stands at the given coordinates in it. `P0` is the
    /// system in use, `P1`–`P6` are `G54`–`G59`. Axes not named keep theirs.
    pub fn set_work_offsets(&mut self, command: &Command, l20: bool) -> Result<(), CommandError> {
        // No `P`, or `P0`: the system in use.
        let mut p = 0;
        super::set_scaled(command, b'P', 0, 0, WORK_SYSTEMS as i32, &mut p)?;
        let system = if p == 0 { usize::from(self.work) } else { p as usize - 1 };
        // Always there (`work` is below WORK_SYSTEMS); `get` rather than
        // an index that would bring its panic path.
        let Some(&zero) = self.work_offsets.get(system) else { return Ok(()) };
        let mut zero = zero;
        for (axis, &letter) in AXIS_LETTERS[..3].iter().enumerate() {
            let Some(value) = command.value(letter)? else { continue };
            let um = self.length_um(letter, value)?;
            zero[axis] = if l20 {
                // logical = machine + G92 − zero = um
                sat_sub(sat_add(self.position[axis], self.offset[axis]), um)
            } else {
                um
            };
        }
        if let Some(slot) = self.work_offsets.get_mut(system) {
            *slot = zero;
        }
        Ok(())
    }
}

/// `a + b`, saturating: one copy of the overflow checks (each inlined one
/// cost some fifty bytes on the AVR).
#[inline(never)]
fn sat_add(a: i32, b: i32) -> i32 {
    a.saturating_add(b)
}

/// `a - b`, saturating (see [`sat_add`]).
#[inline(never)]
fn sat_sub(a: i32, b: i32) -> i32 {
    a.saturating_sub(b)
}

/// nm to µm, rounded half away from zero, and what is left (nm, within
/// ±500): no 32-bit division (n / 1000 = n / 125 / 8, by the shared
/// small divider).
fn split_nm(nm: i32) -> (i32, i16) {
    let magnitude = nm.unsigned_abs();
    let (by_125, rest) = crate::gcode::number::div_rem_small(magnitude, 125);
    let mut um = (by_125 >> 3) as i32;
    let mut left = ((by_125 & 7) * 125) as i32 + i32::from(rest);
    if left >= 500 {
        um += 1;
        left -= 1000;
    }
    if nm < 0 {
        (-um, -left as i16)
    } else {
        (um, left as i16)
    }
}

/// Inches to µm without float: `value · 25 400`, from units of 10⁻⁵ in
/// (0.254 µm each), split so that no product leaves `i32` (64-bit division
/// costs almost 3 KiB of flash on the AVR). `to_scaled(5)` already bounds
/// the input to ±21 474 in.
fn inches_to_um(hundred_thousandths: i32) -> i32 {
    let whole = hundred_thousandths / 1000 * 254;
    let rest = hundred_thousandths % 1000 * 254;
    // Half away from zero, with one division.
    let half = if rest >= 0 { 500 } else { -500 };
    whole + (rest + half) / 1000
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::parse;

    fn target(state: &ModalState, line: &str) -> Result<Position, CommandError> {
        state.target(&parse(line.as_bytes()).unwrap())
    }

    #[test]
    fn nm_split_into_um_and_a_residue() {
        assert_eq!(split_nm(49_290), (49, 290));
        assert_eq!(split_nm(49_500), (50, -500));
        assert_eq!(split_nm(-49_500), (-50, 500));
        assert_eq!(split_nm(-1_499), (-1, -499));
        assert_eq!(split_nm(0), (0, 0));
        assert_eq!(split_nm(i32::MAX), (2_147_484, -353));
    }

    /// Issue 22, finding 3: relative moves of 0.04929 mm lost 0.29 µm each.
    #[test]
    fn relative_moves_carry_what_the_micrometre_cannot_hold() {
        let mut state = ModalState::new();
        state.extruder_distance = Distance::Relative;
        let line = parse(b"G1 E.04929").unwrap();
        for _ in 0..200 {
            let t = state.target(&line).unwrap();
            state.commit(&t);
        }
        assert_eq!(state.position[3], 9_858);
        // Six decimals, both signs.
        let line = parse(b"G1 E-0.000333").unwrap();
        for _ in 0..3000 {
            let t = state.target(&line).unwrap();
            state.commit(&t);
        }
        assert_eq!(state.position[3], 9_858 - 999);
    }

    /// Words of whole µm (≤ 3 decimals) take a fast path in `target`: they
    /// must move and carry exactly as `split_nm` of the word plus the
    /// residue left by finer words does, ±500 nm residues included.
    #[test]
    fn whole_micrometre_words_carry_the_residue_of_finer_ones() {
        let mut state = ModalState::new();
        state.extruder_distance = Distance::Relative;
        let words: [(&[u8], i32); 7] =
            [(b"G1 E.0005", 500), (b"G1 E.001", 1_000), (b"G1 E-.0015", -1_500), (b"G1 E.0004", 400), (b"G1 E-.002", -2_000), (b"G1 E-.0001", -100), (b"G1 E.003", 3_000)];
        let (mut position, mut residue) = (0, 0);
        let mut residues_seen = [false; 3];
        for (line, nm) in words.iter().cycle().take(70) {
            let target = state.target(&parse(line).unwrap()).unwrap();
            state.commit(&target);
            let (um, left) = split_nm(nm + i32::from(residue));
            (position, residue) = (position + um, left);
            assert_eq!((state.position[3], state.residue_nm[3]), (position, residue), "after {line:?}");
            residues_seen[usize::from(residue == -500) + 2 * usize::from(residue == 500)] = true;
        }
        // Both ±500 nm residues were carried into a whole-µm word.
        assert_eq!(residues_seen, [true; 3]);
    }

    #[test]
    fn absolute_targets_are_the_values_in_micrometres() {
        let state = ModalState::new();
        assert_eq!(target(&state, "G1 X10.5 Y-3 E0.04521"), Ok([10_500, -3_000, 0, 45]));
    }

    #[test]
    fn relative_targets_add_to_the_position() {
        let mut state = ModalState::new();
        state.position = [1_000, 2_000, 3_000, 4_000];
        state.distance = Distance::Relative;
        assert_eq!(target(&state, "G1 X1 Z-1"), Ok([2_000, 2_000, 2_000, 4_000]));
    }

    #[test]
    fn e_follows_m82_m83_independently_of_g90() {
        let mut state = ModalState::new();
        state.position = [0, 0, 0, 5_000];
        state.extruder_distance = Distance::Relative;
        assert_eq!(target(&state, "G1 X1 E1"), Ok([1_000, 0, 0, 6_000]));
    }

    #[test]
    fn inches_are_exact() {
        let mut state = ModalState::new();
        state.units = Units::Inches;
        assert_eq!(target(&state, "G1 X1 Y-0.5 Z0.001"), Ok([25_400, -12_700, 25, 0]));
        assert_eq!(target(&state, "G1 X-1.00001"), Ok([-25_400, 0, 0, 0]));
        assert_eq!(target(&state, "G1 X21000"), Ok([533_400_000, 0, 0, 0]));
        assert_eq!(target(&state, "G1 X80000"), Err(CommandError::OutOfRange(b'X')));
        assert_eq!(state.read_feed(&parse(b"G1 F60").unwrap()), Ok(Some(25_400)));
    }

    #[test]
    fn g92_shifts_logical_coordinates_without_moving() {
        let mut state = ModalState::new();
        state.position = [5_000, 0, 0, 7_000];
        state.set_logical_position(&parse(b"G92 X0 E0").unwrap()).unwrap();
        assert_eq!(state.position, [5_000, 0, 0, 7_000]);
        assert_eq!(state.logical_position(), [0, 0, 0, 0]);
        // Absolute X10 now means machine 15 mm.
        assert_eq!(target(&state, "G1 X10"), Ok([15_000, 0, 0, 7_000]));
    }

    #[test]
    fn g92_without_axes_zeroes_every_axis() {
        let mut state = ModalState::new();
        state.position = [1, 2, 3, 4];
        state.set_logical_position(&parse(b"G92").unwrap()).unwrap();
        assert_eq!(state.logical_position(), [0; AXES]);
    }

    #[test]
    fn feed_rates_must_be_positive() {
        let state = ModalState::new();
        assert_eq!(state.read_feed(&parse(b"G1 F0").unwrap()), Err(CommandError::InvalidFeedRate));
        assert_eq!(state.read_feed(&parse(b"G1 F-100").unwrap()), Err(CommandError::InvalidFeedRate));
        assert_eq!(state.read_feed(&parse(b"G1 F0.001").unwrap()), Err(CommandError::InvalidFeedRate));
        assert_eq!(state.read_feed(&parse(b"G1 F1800").unwrap()), Ok(Some(30_000)));
        assert_eq!(state.read_feed(&parse(b"G1 X1").unwrap()), Ok(None));
    }

    #[test]
    fn coordinates_beyond_range_are_refused() {
        let state = ModalState::new();
        assert_eq!(target(&state, "G1 X2000001"), Err(CommandError::OutOfRange(b'X')));
        let mut relative = ModalState::new();
        relative.distance = Distance::Relative;
        relative.position = [MAX_COORDINATE_UM, 0, 0, 0];
        assert_eq!(target(&relative, "G1 X1"), Err(CommandError::OutOfRange(b'X')));
    }

    #[test]
    fn targets_beyond_i32_after_the_shift_are_refused() {
        let mut state = ModalState::new();
        state.offset = [-MAX_COORDINATE_UM, MAX_COORDINATE_UM, 0, 0];
        assert_eq!(target(&state, "G1 X2000000"), Err(CommandError::OutOfRange(b'X')));
        assert_eq!(target(&state, "G1 Y-2000000"), Err(CommandError::OutOfRange(b'Y')));
        assert_eq!(target(&state, "G1 X-2000000 Y2000000"), Ok([0, 0, 0, 0]));
        state.distance = Distance::Relative;
        state.position = [-MAX_COORDINATE_UM, 0, 0, 0];
        assert_eq!(target(&state, "G1 X-2000000"), Err(CommandError::OutOfRange(b'X')));
    }

    #[test]
    fn built_in_place_is_new() {
        let mut slot = core::mem::MaybeUninit::<ModalState>::uninit();
        // SAFETY: the slot is valid for writes; `init_in` writes it whole.
        let built = unsafe {
            ModalState::init_in(slot.as_mut_ptr());
            slot.assume_init()
        };
        assert_eq!(std::format!("{built:?}"), std::format!("{:?}", ModalState::new()));
    }

    #[test]
    fn a_flag_axis_is_an_error() {
        let state = ModalState::new();
        assert_eq!(
            target(&state, "G1 X"),
            Err(CommandError::Parse(crate::gcode::ParseError::WordWithoutValue(b'X')))
        );
    }
}
