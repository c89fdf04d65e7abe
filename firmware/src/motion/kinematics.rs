//! Kinematics: where the motors must be for a Cartesian nozzle position, and
//! back. One [`Kinematics`] per machine family of the SPEC, chosen by the
//! machine configuration through [`MachineKinematics`].
//!
//! Motor coordinates are in *motor units*: millimetres of travel for a
//! Cartesian axis, a delta carriage or a lead screw; degrees for an arm
//! joint. [`Kinematics::motor_steps_per_unit`] turns them into steps, and
//! rounding to the nearest step happens once, in [`to_steps`].
//!
//! Only the three positioning motors (indices 0, 1, 2) go through the
//! kinematics; the extruder (index 3) is always linear.
//!
//! All of this is main-loop float code (SPEC §2 and §3 give the formulas);
//! the step interrupt never sees a float.

use super::math::{self, atan2, round_to_i32, sin_cos, sqrt};
use crate::progmem::Flash;

/// Cartesian axes (X, Y, Z) and the motors that position them.
pub const LINEAR_AXES: usize = 3;

/// A point or a motor position, one value per positioning motor.
pub type Vector3 = [f32; LINEAR_AXES];

/// Why a position cannot be reached.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KinematicsError {
    /// A delta rod or the arm cannot reach the point (L² − d² ≤ 0, or the
    /// arm's |cos θ2| > 1).
    OutOfReach,
    /// Outside the configured printable radius of a delta.
    OutsidePrintable,
    /// A delta rod would lean more than the configured tilt limit.
    TooTilted,
    /// The forward solution does not exist (carriage heights inconsistent).
    NoSolution,
}

/// Inverse and forward kinematics of one machine family.
pub trait Kinematics {
    /// Cartesian nozzle position (mm) → motor coordinates (motor units).
    fn inverse(&self, cartesian: Vector3) -> Result<Vector3, KinematicsError>;
    /// Motor coordinates (motor units) → Cartesian nozzle position (mm).
    fn forward(&self, motors: Vector3) -> Result<Vector3, KinematicsError>;
    /// Longest Cartesian piece (mm) that may be interpolated linearly in
    /// motor space; `None` when straight lines stay straight (Cartesian).
    fn segment_mm(&self) -> Option<f32>;
    /// Steps per motor unit, given the `M92` steps/mm of X, Y, Z.
    fn motor_steps_per_unit(&self, steps_per_mm: Vector3) -> Vector3;
}

/// Motor coordinates → whole steps, rounded to the nearest step (half away
/// from zero).
pub fn to_steps(motors: Vector3, steps_per_unit: Vector3) -> [i32; LINEAR_AXES] {
    motor_steps(
        &motors,
        &[steps_per_unit[0], steps_per_unit[1], steps_per_unit[2], 0.0],
    )
}

/// [`to_steps`] given the steps per unit of all four motors (the motion
/// layer's `steps_per_unit`, E last and unused), by reference: passed by
/// value, the AVR copied both arrays at every call.
pub fn motor_steps(motors: &Vector3, steps_per_unit: &[f32; 4]) -> [i32; LINEAR_AXES] {
    [
        round_to_i32(motors[0] * steps_per_unit[0]),
        round_to_i32(motors[1] * steps_per_unit[1]),
        round_to_i32(motors[2] * steps_per_unit[2]),
    ]
}

/// Whole steps → motor coordinates.
pub fn from_steps(steps: [i32; LINEAR_AXES], steps_per_unit: Vector3) -> Vector3 {
    [
        steps[0] as f32 / steps_per_unit[0],
        steps[1] as f32 / steps_per_unit[1],
        steps[2] as f32 / steps_per_unit[2],
    ]
}

/// SPEC §1: one motor per Cartesian axis (the Prusa i3). Which way a motor
/// turns for +Y is the step generator's direction-inversion mask, so that
/// +Y always means the nozzle's +Y even though the belt moves the bed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cartesian;

impl Kinematics for Cartesian {
    fn inverse(&self, cartesian: Vector3) -> Result<Vector3, KinematicsError> {
        Ok(cartesian)
    }
    fn forward(&self, motors: Vector3) -> Result<Vector3, KinematicsError> {
        Ok(motors)
    }
    fn segment_mm(&self) -> Option<f32> {
        None
    }
    fn motor_steps_per_unit(&self, steps_per_mm: Vector3) -> Vector3 {
        steps_per_mm
    }
}

/// SPEC §2: a linear delta. Motor i is the carriage of tower i; its
/// coordinate is the carriage height h_i in mm:
///
/// h_i = z + OF + √(L² − (R·cosθ_i − x)² − (R·sinθ_i − y)²)
///
/// with L the rod length, R the radius of the rod pivots, OF the nozzle's
/// offset below the effector pivots and θ_i the tower angles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Delta {
    rod_length: f32,
    radius: f32,
    effector_offset: f32,
    tower_angles_deg: Vector3,
    /// Tower pivot positions (R·cosθ_i, R·sinθ_i).
    towers: [[f32; 2]; 3],
    /// Points farther than this from the centre are refused (mm).
    pub printable_radius: f32,
    /// Largest allowed rod tilt from vertical, as sin²; `None`: no check.
    pub max_tilt_sin_sqr: Option<f32>,
    /// `M665 H`: nozzle height when every carriage is at its top endstop.
    pub homed_height: f32,
    /// `M666`: how far each tower's endstop sits above the nominal one (mm).
    pub endstop_trim: Vector3,
    /// Longest straight piece between inverse-kinematics points (mm).
    pub segment_length: f32,
}

impl Delta {
    /// A delta with the given geometry (mm, degrees); printable radius
    /// defaults to the reach L − R, no tilt check, no trim.
    pub fn new(
        rod_length: f32,
        radius: f32,
        effector_offset: f32,
        tower_angles_deg: Vector3,
    ) -> Self {
        let mut delta = Self::unplaced(rod_length, radius, effector_offset, tower_angles_deg);
        delta.place_towers();
        delta
    }

    /// [`Self::new`] without the tower positions (sines and cosines, not
    /// `const`): [`Self::place_towers`] must follow before use. `const`,
    /// so a board can keep its machine in flash.
    pub const fn unplaced(
        rod_length: f32,
        radius: f32,
        effector_offset: f32,
        tower_angles_deg: Vector3,
    ) -> Self {
        Self {
            rod_length,
            radius,
            effector_offset,
            tower_angles_deg,
            towers: [[0.0; 2]; 3],
            printable_radius: rod_length - radius,
            max_tilt_sin_sqr: None,
            homed_height: 300.0,
            endstop_trim: [0.0; 3],
            segment_length: 1.0,
        }
    }

    /// SPEC §2's printer: L 361, R 227, OF 64, towers at 0°/120°/240°
    /// (`repetier_layout` gives 90°/330°/210°), printable radius 130 mm.
    pub fn spec_printer(repetier_layout: bool) -> Self {
        let mut delta = Self::spec_printer_unplaced(repetier_layout);
        delta.place_towers();
        delta
    }

    /// [`Self::spec_printer`] before [`Self::place_towers`].
    pub const fn spec_printer_unplaced(repetier_layout: bool) -> Self {
        let angles = if repetier_layout {
            [90.0, 330.0, 210.0]
        } else {
            [0.0, 120.0, 240.0]
        };
        let mut delta = Self::unplaced(361.0, 227.0, 64.0, angles);
        delta.printable_radius = 130.0;
        delta
    }

    /// `M665 L R`: new rod length and radius (the tower angles stay).
    pub fn set_geometry(&mut self, rod_length: f32, radius: f32) {
        self.rod_length = rod_length;
        self.radius = radius;
        self.place_towers();
    }

    /// New tower angles (degrees).
    pub fn set_tower_angles(&mut self, tower_angles_deg: Vector3) {
        self.tower_angles_deg = tower_angles_deg;
        self.place_towers();
    }

    pub fn rod_length(&self) -> f32 {
        self.rod_length
    }

    pub fn radius(&self) -> f32 {
        self.radius
    }

    /// The tower pivots from the radius and the angles.
    pub fn place_towers(&mut self) {
        for (tower, angle) in self.towers.iter_mut().zip(&self.tower_angles_deg) {
            let (sin, cos) = sin_cos(math::radians(*angle));
            *tower = [self.radius * cos, self.radius * sin];
        }
    }

    /// Run the float program in [`STEPS`] from step `first` to `end` on
    /// the delta's registers, `input` the carriage heights, the point or
    /// the trims; the result is in `OUT`. Shared by the three programs:
    /// the registers are filled in one place. (Slower than the formulas
    /// in line: on the AVR bench, the delta's 1 mm segment streams went
    /// from 67 to 61 lines/s.)
    #[inline(never)]
    fn run(&self, first: usize, end: usize, input: &Vector3) -> Result<Vector3, KinematicsError> {
        // On the AVR the registers live in a `static` (reached through a
        // pointer): in this frame they made it 143 bytes, and each access
        // beyond 63 several instructions longer. Only the main loop runs
        // the kinematics, one program at a time.
        #[cfg(target_arch = "avr")]
        // SAFETY: the only reference to REGISTER_FILE, and `run` is neither
        // reentrant nor called from an interrupt.
        let regs = unsafe { core::hint::black_box(&mut *core::ptr::addr_of_mut!(REGISTER_FILE)) };
        #[cfg(not(target_arch = "avr"))]
        let regs = &mut [0.0; REGISTERS];
        // Every run starts from zeros, as a fresh array on the stack would.
        *regs = [0.0; REGISTERS];
        // The delta through a pointer the compiler does not follow: the
        // AVR build knows where the machine's delta is, and copied its
        // figures with a 4-byte absolute load per 2 bytes, not a memcpy
        // call. Whole arrays into constant chunks: no bounds checks.
        let delta = core::hint::black_box(self);
        let towers = delta.towers.as_flattened().first_chunk::<6>();
        if let Some((constants, rest)) = regs.split_first_chunk_mut::<{ OUT - OF }>() {
            *constants = [
                delta.effector_offset,
                delta.rod_length,
                1.0,
                0.5,
                -f32::from_bits(1),
                0.0,
                delta.printable_radius,
                // No tilt check: nothing is more than infinitely tilted.
                match delta.max_tilt_sin_sqr {
                    Some(limit) => limit,
                    None => f32::INFINITY,
                },
                delta.radius,
                delta.homed_height,
            ];
            if let (Some((pivots, rest)), Some(towers)) =
                (rest[3..].split_first_chunk_mut::<6>(), towers)
            {
                // `copy_from_slice`: a memcpy (an assignment became a
                // memmove, 650 bytes of compiler-builtins).
                pivots.copy_from_slice(towers);
                if let Some(inputs) = rest.first_chunk_mut::<3>() {
                    inputs.copy_from_slice(input);
                }
            }
        }
        run_float_program(regs, first, end)?;
        Ok([regs[OUT], regs[OUT + 1], regs[OUT + 2]])
    }

    /// Carriage height of every tower when all sit at their top endstops:
    /// the nozzle is then at (0, 0, homed_height), trims aside:
    /// trim + (H + OF + √(L² − R²)). Run as [`HOMED_STEPS`] (see [`Self::forward`]).
    pub fn homed_carriage_heights(&self) -> Vector3 {
        self.homed_heights().unwrap_or([0.0; 3])
    }

    /// [`Self::homed_carriage_heights`] as the steps return it (they
    /// refuse nothing): the homing takes the `Result` as it is.
    pub(crate) fn homed_heights(&self) -> Result<Vector3, KinematicsError> {
        self.run(HOMED, STEP_COUNT, &self.endstop_trim)
    }
}

impl Kinematics for Delta {
    /// h_i = z + OF + √(L² − d_i²) for each tower, d_i the horizontal
    /// distance from the tower's pivot; refused outside the printable
    /// radius, where L² − d_i² ≤ 0, or where d_i > L·sin(tilt limit).
    /// Run as [`INVERSE_STEPS`] (see [`Self::forward`]).
    fn inverse(&self, p: Vector3) -> Result<Vector3, KinematicsError> {
        self.run(INVERSE, HOMED, &p)
    }

    /// Trilateration: the nozzle (less OF) lies at distance L from each
    /// carriage pivot (tower x, tower y, h_i − OF); of the two
    /// intersections of the three spheres, the one below the carriages.
    ///
    /// Written for the soft-float AVR, where each operation spelled out is
    /// a call with its operands loaded and its result stored (2 KB
    /// inline, 1.4 KB through vector helpers): the steps are
    /// [`TRILATERATION_STEPS`], in flash 3 bytes each, run by
    /// [`Delta::run`]. The same operations in the same order as the
    /// formulas, so the same bits (a test keeps them so).
    fn forward(&self, heights: Vector3) -> Result<Vector3, KinematicsError> {
        self.run(0, INVERSE, &heights)
    }

    fn segment_mm(&self) -> Option<f32> {
        Some(self.segment_length)
    }

    fn motor_steps_per_unit(&self, steps_per_mm: Vector3) -> Vector3 {
        steps_per_mm
    }
}

/// [`Delta::run`]'s registers on the AVR.
#[cfg(target_arch = "avr")]
static mut REGISTER_FILE: [f32; REGISTERS] = [0.0; REGISTERS];

/// Float registers of [`run_float_program`] (a power of two: indices are
/// masked into range, no bounds checks).
const REGISTERS: usize = 32;

// The registers of the programs: constants and the delta's figures
// (−(smallest subnormal): x ≥ 0 is x > it; the tilt limit as sin²,
// infinite when none), the result (these first: the caller's stack
// offsets stay below 64), the towers' x and y, the input (the carriage
// heights, the point or the trims), then the programs' own. The programs
// may overwrite what they do not need: every run fills them again.
const OF: usize = 0;
const ROD: usize = 1;
const ONE: usize = 2;
const HALF: usize = 3;
const BELOW_ZERO: usize = 4;
const ZERO: usize = 5;
const PRINTABLE: usize = 6;
const TILT: usize = 7;
const RADIUS: usize = 8;
const HOMED_HEIGHT: usize = 9;
const OUT: usize = 10;
const TX0: usize = 13;
const TY0: usize = 14;
const TX1: usize = 15;
const TY1: usize = 16;
const TX2: usize = 17;
const TY2: usize = 18;
const IN: usize = 19;

// The trilateration's: the heights become the pivots' z = h − OF, then
// h1 and h2 scalars; ex = (p2 − p1)/d; p3 − p1, which becomes ez; ey; the
// scalars (x in d), in place of figures it does not need.
const H0: usize = IN;
const H1: usize = IN + 1;
const H2: usize = IN + 2;
const I: usize = H1;
const J: usize = H2;
const EX: usize = 22;
const P31: usize = 25;
const EZ: usize = P31;
const EY: usize = 28;
const D: usize = 31;
const X: usize = D;
const Y: usize = RADIUS;
const Z: usize = HOMED_HEIGHT;
const T: usize = PRINTABLE;
const T2: usize = TILT;

// The inverse's: the point, L², L²·sin²(tilt limit), z + OF, then per
// tower dx, dy (squared in place), d², L² − d².
const PX: usize = IN;
const PY: usize = IN + 1;
const PZ: usize = IN + 2;
const RS: usize = 22;
const LR: usize = 23;
const ZOF: usize = 24;
const DX: usize = 25;
const DY: usize = 26;
const HS: usize = 27;
const VS: usize = 28;
const R: usize = 29;
const R2: usize = 30;

/// Operations of a float program step: `dst ← a op b`.
const ADD: u8 = 0;
const SUB: u8 = 1;
const MUL: u8 = 2;
const DIV: u8 = 3;
/// `dst ← √a` ([`math::sqrt`]).
const SQRT: u8 = 4;
/// `dst ← dst + a·b` (the product rounded, then the sum).
const MUL_ADD: u8 = 5;
/// Fail unless `a > b`, or (`dst` | [`UNLESS`]) if `a > b`, with the
/// error numbered `dst` & 3 (`OUT_OF_REACH`…).
const REQUIRE: u8 = 6;
/// `dst ← −dst` unless `a < b`.
const NEGATE_UNLESS_LESS: u8 = 7;

/// `REQUIRE`'s `dst` flag: fail if `a > b`.
const UNLESS: usize = 4;

/// `REQUIRE`'s errors (`dst` & 3).
const OUT_OF_REACH: usize = 0;
const OUTSIDE_PRINTABLE: usize = 1;
const TOO_TILTED: usize = 2;
const NO_SOLUTION: usize = 3;

/// One step: the operation in the top 3 bits of the first byte, `dst` in
/// the low 5, then `a` and `b`.
const fn step(op: u8, dst: usize, a: usize, b: usize) -> [u8; 3] {
    [op << 5 | dst as u8, a as u8, b as u8]
}

/// Steps of the trilateration, [`Delta::forward`]'s formulas one operation
/// at a time, in their order (a dot product summed left to right).
const TRILATERATION_STEPS: [[u8; 3]; 80] = [
    // The pivots' heights h_i − OF.
    step(SUB, H0, H0, OF),
    step(SUB, H1, H1, OF),
    step(SUB, H2, H2, OF),
    // p2 − p1 (to become ex) and p3 − p1.
    step(SUB, EX, TX1, TX0),
    step(SUB, EX + 1, TY1, TY0),
    step(SUB, EX + 2, H1, H0),
    step(SUB, P31, TX2, TX0),
    step(SUB, P31 + 1, TY2, TY0),
    step(SUB, P31 + 2, H2, H0),
    // d = |p2 − p1| > 0; ex = (p2 − p1)·(1/d).
    step(MUL, D, EX, EX),
    step(MUL_ADD, D, EX + 1, EX + 1),
    step(MUL_ADD, D, EX + 2, EX + 2),
    step(SQRT, D, D, 0),
    step(REQUIRE, NO_SOLUTION, D, ZERO),
    step(DIV, T, ONE, D),
    step(MUL, EX, EX, T),
    step(MUL, EX + 1, EX + 1, T),
    step(MUL, EX + 2, EX + 2, T),
    // i = ex·(p3 − p1); ey = p3 − p1 − ex·i, normalised.
    step(MUL, I, EX, P31),
    step(MUL_ADD, I, EX + 1, P31 + 1),
    step(MUL_ADD, I, EX + 2, P31 + 2),
    step(MUL, T, EX, I),
    step(SUB, EY, P31, T),
    step(MUL, T, EX + 1, I),
    step(SUB, EY + 1, P31 + 1, T),
    step(MUL, T, EX + 2, I),
    step(SUB, EY + 2, P31 + 2, T),
    step(MUL, T, EY, EY),
    step(MUL_ADD, T, EY + 1, EY + 1),
    step(MUL_ADD, T, EY + 2, EY + 2),
    step(SQRT, T, T, 0),
    step(REQUIRE, NO_SOLUTION, T, ZERO),
    step(DIV, T, ONE, T),
    step(MUL, EY, EY, T),
    step(MUL, EY + 1, EY + 1, T),
    step(MUL, EY + 2, EY + 2, T),
    // j = ey·(p3 − p1). All three radii are L, so the r₁² − r₂² terms
    // vanish: x = d/2, y = (i² + j²)/(2j) − i·x/j.
    step(MUL, J, EY, P31),
    step(MUL_ADD, J, EY + 1, P31 + 1),
    step(MUL_ADD, J, EY + 2, P31 + 2),
    step(MUL, X, D, HALF),
    step(MUL, T, I, I),
    step(MUL, T2, J, J),
    step(ADD, T, T, T2),
    step(ADD, T2, J, J),
    step(DIV, T, T, T2),
    step(MUL, T2, I, X),
    step(DIV, T2, T2, J),
    step(SUB, Y, T, T2),
    // z = √(L² − x² − y²), L² − x² − y² ≥ 0.
    step(MUL, T, ROD, ROD),
    step(MUL, T2, X, X),
    step(SUB, T, T, T2),
    step(MUL, T2, Y, Y),
    step(SUB, T, T, T2),
    step(REQUIRE, NO_SOLUTION, T, BELOW_ZERO),
    step(SQRT, Z, T, 0),
    // The base point p1 + ex·x + ey·y.
    step(MUL, T, EX, X),
    step(ADD, OUT, TX0, T),
    step(MUL, T, EX + 1, X),
    step(ADD, OUT + 1, TY0, T),
    step(MUL, T, EX + 2, X),
    step(ADD, OUT + 2, H0, T),
    step(MUL_ADD, OUT, EY, Y),
    step(MUL_ADD, OUT + 1, EY + 1, Y),
    step(MUL_ADD, OUT + 2, EY + 2, Y),
    // ez = ex × ey.
    step(MUL, T, EX + 1, EY + 2),
    step(MUL, T2, EX + 2, EY + 1),
    step(SUB, EZ, T, T2),
    step(MUL, T, EX + 2, EY),
    step(MUL, T2, EX, EY + 2),
    step(SUB, EZ + 1, T, T2),
    step(MUL, T, EX, EY + 1),
    step(MUL, T2, EX + 1, EY),
    step(SUB, EZ + 2, T, T2),
    // Of base ± ez·z, the lower (base − ez·z when neither is).
    step(MUL, T, EZ + 2, Z),
    step(ADD, T2, OUT + 2, T),
    step(SUB, I, OUT + 2, T),
    step(NEGATE_UNLESS_LESS, Z, T2, I),
    step(MUL_ADD, OUT, EZ, Z),
    step(MUL_ADD, OUT + 1, EZ + 1, Z),
    step(MUL_ADD, OUT + 2, EZ + 2, Z),
];

/// Steps of the inverse, [`Delta::inverse`]'s formulas one operation at a
/// time, in their order.
const INVERSE_STEPS: [[u8; 3]; 38] = [
    // x² + y² > R_printable²: outside.
    step(MUL, R, PX, PX),
    step(MUL, R2, PY, PY),
    step(ADD, R, R, R2),
    step(MUL, R2, PRINTABLE, PRINTABLE),
    step(REQUIRE, OUTSIDE_PRINTABLE | UNLESS, R, R2),
    step(MUL, RS, ROD, ROD),
    step(MUL, LR, TILT, RS),
    step(ADD, ZOF, PZ, OF),
    // Tower 1.
    step(SUB, DX, TX0, PX),
    step(SUB, DY, TY0, PY),
    step(MUL, DX, DX, DX),
    step(MUL, DY, DY, DY),
    step(ADD, HS, DX, DY),
    step(SUB, VS, RS, HS),
    // L² − d² > 0, else out of reach; d² > L²·sin²: too tilted.
    step(REQUIRE, OUT_OF_REACH, VS, ZERO),
    step(REQUIRE, TOO_TILTED | UNLESS, HS, LR),
    step(SQRT, VS, VS, 0),
    step(ADD, OUT, ZOF, VS),
    // Tower 2.
    step(SUB, DX, TX1, PX),
    step(SUB, DY, TY1, PY),
    step(MUL, DX, DX, DX),
    step(MUL, DY, DY, DY),
    step(ADD, HS, DX, DY),
    step(SUB, VS, RS, HS),
    step(REQUIRE, OUT_OF_REACH, VS, ZERO),
    step(REQUIRE, TOO_TILTED | UNLESS, HS, LR),
    step(SQRT, VS, VS, 0),
    step(ADD, OUT + 1, ZOF, VS),
    // Tower 3.
    step(SUB, DX, TX2, PX),
    step(SUB, DY, TY2, PY),
    step(MUL, DX, DX, DX),
    step(MUL, DY, DY, DY),
    step(ADD, HS, DX, DY),
    step(SUB, VS, RS, HS),
    step(REQUIRE, OUT_OF_REACH, VS, ZERO),
    step(REQUIRE, TOO_TILTED | UNLESS, HS, LR),
    step(SQRT, VS, VS, 0),
    step(ADD, OUT + 2, ZOF, VS),
];

/// Steps of [`Delta::homed_carriage_heights`]: trim + (H + OF + √(L² − R²)).
const HOMED_STEPS: [[u8; 3]; 9] = [
    step(MUL, T, ROD, ROD),
    step(MUL, T2, RADIUS, RADIUS),
    step(SUB, T, T, T2),
    step(SQRT, T, T, 0),
    step(ADD, T2, HOMED_HEIGHT, OF),
    step(ADD, T, T2, T),
    step(ADD, OUT, IN, T),
    step(ADD, OUT + 1, IN + 1, T),
    step(ADD, OUT + 2, IN + 2, T),
];

/// Step offsets in [`STEPS`]: the inverse's steps follow the
/// trilateration's, the homed heights' the inverse's; the end.
const INVERSE: usize = TRILATERATION_STEPS.len();
const HOMED: usize = INVERSE + INVERSE_STEPS.len();
const STEP_COUNT: usize = HOMED + HOMED_STEPS.len();

/// The programs in flash, one after the other, read a step at a time (a
/// byte at a time, three calls per step, was 36 bytes smaller but slowed
/// the delta's 1 mm segment streams from 61 to 54 lines/s).
#[cfg_attr(target_arch = "avr", link_section = ".progmem.data")]
static STEPS: Flash<[[u8; 3]; STEP_COUNT]> =
    Flash::new(flatten(TRILATERATION_STEPS, INVERSE_STEPS, HOMED_STEPS));

/// The programs' steps one after the other.
const fn flatten<const A: usize, const B: usize, const C: usize, const M: usize>(
    a: [[u8; 3]; A],
    b: [[u8; 3]; B],
    c: [[u8; 3]; C],
) -> [[u8; 3]; M] {
    let mut steps = [[0; 3]; M];
    let mut n = 0;
    while n < M {
        steps[n] = if n < A {
            a[n]
        } else if n < A + B {
            b[n - A]
        } else {
            c[n - A - B]
        };
        n += 1;
    }
    steps
}

/// Run the steps of [`STEPS`] from `index` to `end` over `regs`;
/// `Err` when a `REQUIRE` fails.
#[inline(always)]
fn run_float_program(
    regs: &mut [f32; REGISTERS],
    mut index: usize,
    end: usize,
) -> Result<(), KinematicsError> {
    while index < end {
        let Some([head, a, b]) = STEPS.get(index) else {
            break;
        };
        index += 1;
        let dst = (head & 31) as usize;
        let (a, b) = (a as usize & 31, b as usize & 31);
        let (x, y) = (regs[a], regs[b]);
        regs[dst] = match head >> 5 {
            ADD => x + y,
            SUB => x - y,
            MUL => x * y,
            DIV => x / y,
            SQRT => sqrt(x),
            MUL_ADD => regs[dst] + x * y,
            REQUIRE => {
                if (x > y) != (dst & UNLESS != 0) {
                    continue;
                }
                // (Numbered in the enum's order: no table, which would be
                // copied to RAM.)
                return Err(match dst & 3 {
                    OUT_OF_REACH => KinematicsError::OutOfReach,
                    OUTSIDE_PRINTABLE => KinematicsError::OutsidePrintable,
                    TOO_TILTED => KinematicsError::TooTilted,
                    _ => KinematicsError::NoSolution,
                });
            }
            _ => {
                if x < y {
                    continue;
                }
                -regs[dst]
            }
        };
    }
    Ok(())
}

/// |a|, the squares summed left to right.
pub(crate) fn length3(a: &Vector3) -> f32 {
    sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
}

/// SPEC §3: the planar RR arm in the Y–Z plane with a lead-screw X.
/// Motor 0 is X (mm), motor 1 ("Y") the elbow θ2, motor 2 ("Z") the
/// shoulder θ1, both in degrees. With py = origin_py − y, pz = origin_pz − z:
///
/// θ2 = −acos((py² + pz² − L1² − L2²)/(2·L1·L2)),
/// θ1 = atan2(pz, py) + atan2(L2·sinθ2, L1 + L2·cosθ2).
///
/// θ2 is computed as −2·atan2(√((L1+L2)² − r²), √(r² − (L1−L2)²)), the same
/// angle without acos' loss of precision near full stretch (where 1 − cos
/// cancels in single precision).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arm {
    /// Upper arm (shoulder → elbow), mm.
    pub l1: f32,
    /// Forearm (elbow → tool), mm.
    pub l2: f32,
    /// py of the work origin (y = 0) in the shoulder's frame, mm.
    pub origin_py: f32,
    /// pz of the work origin (z = 0) in the shoulder's frame, mm.
    pub origin_pz: f32,
    /// Joint pulses per degree: gearbox × driver pulses per rev / 360.
    pub joint_steps_per_degree: f32,
    /// Longest straight piece between inverse-kinematics points (mm).
    pub segment_length: f32,
}

impl Arm {
    /// SPEC §3's arm (L1 120, L2 200, origin at (120, 200) from the
    /// shoulder, 100:1 gearboxes) with `ppr` driver pulses per motor turn
    /// (200 on the bench, 400 on the machine), 0.35 mm segments.
    pub fn spec_arm(ppr: u16) -> Self {
        Self {
            l1: 120.0,
            l2: 200.0,
            origin_py: 120.0,
            origin_pz: 200.0,
            joint_steps_per_degree: 100.0 * ppr as f32 / 360.0,
            segment_length: 0.35,
        }
    }

    /// (θ2, θ1) in degrees for a point (y, z).
    pub fn joint_angles(&self, y: f32, z: f32) -> Result<(f32, f32), KinematicsError> {
        let py = self.origin_py - y;
        let pz = self.origin_pz - z;
        let reach_sqr = py * py + pz * pz;
        let outer = self.l1 + self.l2;
        let inner = self.l1 - self.l2;
        // (1 − cosθ2) and (1 + cosθ2), each times 2·L1·L2, computed without
        // cancellation: |cos θ2| > 1 means one of them is negative.
        let one_minus_cos = outer * outer - reach_sqr;
        let one_plus_cos = reach_sqr - inner * inner;
        if !(one_minus_cos >= 0.0) || !(one_plus_cos >= 0.0) {
            return Err(KinematicsError::OutOfReach);
        }
        let elbow = -2.0 * atan2(sqrt(one_minus_cos), sqrt(one_plus_cos));
        let two_l1_l2 = 2.0 * self.l1 * self.l2;
        let cos_elbow = (one_plus_cos - one_minus_cos) / (2.0 * two_l1_l2);
        let sin_elbow = -sqrt(one_minus_cos * one_plus_cos) / two_l1_l2;
        let shoulder = atan2(pz, py) + atan2(self.l2 * sin_elbow, self.l1 + self.l2 * cos_elbow);
        Ok((math::degrees(elbow), math::degrees(shoulder)))
    }
}

impl Kinematics for Arm {
    fn inverse(&self, p: Vector3) -> Result<Vector3, KinematicsError> {
        let (elbow, shoulder) = self.joint_angles(p[1], p[2])?;
        Ok([p[0], elbow, shoulder])
    }

    /// py = L1·cosθ1 + L2·cos(θ1 − θ2), pz = L1·sinθ1 + L2·sin(θ1 − θ2).
    fn forward(&self, motors: Vector3) -> Result<Vector3, KinematicsError> {
        let elbow = math::radians(motors[1]);
        let shoulder = math::radians(motors[2]);
        let (sin1, cos1) = sin_cos(shoulder);
        let (sin12, cos12) = sin_cos(shoulder - elbow);
        let py = self.l1 * cos1 + self.l2 * cos12;
        let pz = self.l1 * sin1 + self.l2 * sin12;
        Ok([motors[0], self.origin_py - py, self.origin_pz - pz])
    }

    fn segment_mm(&self) -> Option<f32> {
        Some(self.segment_length)
    }

    fn motor_steps_per_unit(&self, steps_per_mm: Vector3) -> Vector3 {
        [
            steps_per_mm[0],
            self.joint_steps_per_degree,
            self.joint_steps_per_degree,
        ]
    }
}

/// The kinematics a machine configuration selects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MachineKinematics {
    Cartesian(Cartesian),
    #[cfg(feature = "delta")]
    Delta(Delta),
    #[cfg(feature = "arm")]
    Arm(Arm),
}

impl Kinematics for MachineKinematics {
    fn inverse(&self, cartesian: Vector3) -> Result<Vector3, KinematicsError> {
        match self {
            Self::Cartesian(k) => k.inverse(cartesian),
            #[cfg(feature = "delta")]
            Self::Delta(k) => k.inverse(cartesian),
            #[cfg(feature = "arm")]
            Self::Arm(k) => k.inverse(cartesian),
        }
    }
    fn forward(&self, motors: Vector3) -> Result<Vector3, KinematicsError> {
        match self {
            Self::Cartesian(k) => k.forward(motors),
            #[cfg(feature = "delta")]
            Self::Delta(k) => k.forward(motors),
            #[cfg(feature = "arm")]
            Self::Arm(k) => k.forward(motors),
        }
    }
    fn segment_mm(&self) -> Option<f32> {
        match self {
            Self::Cartesian(k) => k.segment_mm(),
            #[cfg(feature = "delta")]
            Self::Delta(k) => k.segment_mm(),
            #[cfg(feature = "arm")]
            Self::Arm(k) => k.segment_mm(),
        }
    }
    fn motor_steps_per_unit(&self, steps_per_mm: Vector3) -> Vector3 {
        match self {
            Self::Cartesian(k) => k.motor_steps_per_unit(steps_per_mm),
            #[cfg(feature = "delta")]
            Self::Delta(k) => k.motor_steps_per_unit(steps_per_mm),
            #[cfg(feature = "arm")]
            Self::Arm(k) => k.motor_steps_per_unit(steps_per_mm),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_heights(delta: &Delta, x: f32, y: f32, want: Vector3) {
        let got = delta.inverse([x, y, 0.25]).unwrap();
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() <= 0.005, "({x}, {y}): {got:?}, want {want:?}");
        }
        // And back: forward kinematics lands on the point.
        let back = delta.forward(got).unwrap();
        for (b, w) in back.iter().zip([x, y, 0.25]) {
            assert!(
                (b - w).abs() <= 0.002,
                "forward({got:?}) = {back:?}, want ({x}, {y}, 0.25)"
            );
        }
    }

    #[test]
    fn delta_spec_vectors_0_120_240() {
        let delta = Delta::spec_printer(false);
        assert_heights(&delta, 0.0, 0.0, [344.95; 3]);
        assert_heights(&delta, -25.0, 25.0, [321.53, 369.29, 335.15]);
        assert_heights(&delta, -25.0, -25.0, [321.53, 335.15, 369.29]);
        assert_heights(&delta, 25.0, -25.0, [362.40, 313.32, 350.08]);
        assert_heights(&delta, 25.0, 25.0, [362.40, 350.08, 313.32]);
    }

    #[test]
    fn delta_spec_vectors_repetier_layout() {
        let delta = Delta::spec_printer(true);
        assert_heights(&delta, -25.0, 25.0, [362.40, 313.32, 350.08]);
        assert_heights(&delta, 25.0, -25.0, [321.53, 369.29, 335.15]);
    }

    #[test]
    fn delta_steps_at_80_per_mm() {
        let delta = Delta::spec_printer(false);
        let spu = delta.motor_steps_per_unit([80.0; 3]);
        let low = to_steps(delta.inverse([0.0, 0.0, 0.0]).unwrap(), spu);
        let high = to_steps(delta.inverse([0.0, 0.0, 50.0]).unwrap(), spu);
        // Z +50 mm at the centre = 4000 steps per carriage (SPEC §2).
        for i in 0..3 {
            assert_eq!(high[i] - low[i], 4000);
        }
    }

    #[test]
    fn delta_reach_and_radius_checks() {
        let mut delta = Delta::spec_printer(false);
        assert_eq!(
            delta.inverse([131.0, 0.0, 0.0]),
            Err(KinematicsError::OutsidePrintable)
        );
        delta.printable_radius = 1000.0;
        // Reach is L − R = 134 mm straight away from a tower (opposite tower 0).
        assert!(delta.inverse([-133.9, 0.0, 0.0]).is_ok());
        assert_eq!(
            delta.inverse([-134.1, 0.0, 0.0]),
            Err(KinematicsError::OutOfReach)
        );
        // Exactly on the reach circle L² − d² = 0 is refused too.
        assert_eq!(
            delta.inverse([-134.0, 0.0, 0.0]),
            Err(KinematicsError::OutOfReach)
        );
        // Tilt: limit the rod to 40° from vertical.
        let sin40 = sin_cos(math::radians(40.0)).0;
        delta.max_tilt_sin_sqr = Some(sin40 * sin40);
        assert!(delta.inverse([0.0, 0.0, 0.0]).is_ok()); // 227/361 → 39°
        assert_eq!(
            delta.inverse([-20.0, 0.0, 0.0]),
            Err(KinematicsError::TooTilted)
        );
    }

    #[test]
    fn delta_forward_round_trips_over_the_bed() {
        let delta = Delta::spec_printer(true);
        for xi in -12..=12 {
            for yi in -12..=12 {
                let (x, y) = (xi as f32 * 10.0, yi as f32 * 10.0);
                if x * x + y * y > 130.0 * 130.0 {
                    continue;
                }
                let h = delta.inverse([x, y, 7.5]).unwrap();
                let p = delta.forward(h).unwrap();
                assert!(
                    (p[0] - x).abs() < 0.002
                        && (p[1] - y).abs() < 0.002
                        && (p[2] - 7.5).abs() < 0.002,
                    "{x},{y}: {p:?}"
                );
            }
        }
    }

    /// a · b, summed left to right, as the former trilateration had it.
    fn dot3(a: &Vector3, b: &Vector3) -> f32 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }

    /// a ← a + v·k, as the former trilateration had it.
    fn add_scaled3(a: &mut Vector3, v: &Vector3, k: f32) {
        for axis in 0..3 {
            a[axis] += v[axis] * k;
        }
    }

    /// The trilateration as it was written before the float program,
    /// operation by operation (the f32 operations are IEEE's, on the AVR
    /// as here): the program must give the same bits.
    fn forward_reference(delta: &Delta, h: Vector3) -> Option<Vector3> {
        let of = delta.effector_offset;
        let t = delta.towers;
        let p1 = [t[0][0], t[0][1], h[0] - of];
        let mut ex = [t[1][0], t[1][1], h[1] - of];
        let mut p31 = [t[2][0], t[2][1], h[2] - of];
        add_scaled3(&mut ex, &p1, -1.0);
        add_scaled3(&mut p31, &p1, -1.0);
        let d = length3(&ex);
        if !(d > 0.0) {
            return None;
        }
        let inv = 1.0 / d;
        ex = [ex[0] * inv, ex[1] * inv, ex[2] * inv];
        let i = dot3(&ex, &p31);
        let mut ey = p31;
        add_scaled3(&mut ey, &ex, -i);
        let ey_len = length3(&ey);
        if !(ey_len > 0.0) {
            return None;
        }
        let inv = 1.0 / ey_len;
        ey = [ey[0] * inv, ey[1] * inv, ey[2] * inv];
        let j = dot3(&ey, &p31);
        let x = d / 2.0;
        let y = (i * i + j * j) / (2.0 * j) - i * x / j;
        let z_sqr = delta.rod_length * delta.rod_length - x * x - y * y;
        if !(z_sqr >= 0.0) {
            return None;
        }
        let z = sqrt(z_sqr);
        let mut base = p1;
        add_scaled3(&mut base, &ex, x);
        add_scaled3(&mut base, &ey, y);
        let ez = [
            ex[1] * ey[2] - ex[2] * ey[1],
            ex[2] * ey[0] - ex[0] * ey[2],
            ex[0] * ey[1] - ex[1] * ey[0],
        ];
        let z = if base[2] + ez[2] * z < base[2] - ez[2] * z {
            z
        } else {
            -z
        };
        add_scaled3(&mut base, &ez, z);
        Some(base)
    }

    /// The inverse as it was written before the float program.
    fn inverse_reference(delta: &Delta, p: Vector3) -> Result<Vector3, KinematicsError> {
        if p[0] * p[0] + p[1] * p[1] > delta.printable_radius * delta.printable_radius {
            return Err(KinematicsError::OutsidePrintable);
        }
        let rod_sqr = delta.rod_length * delta.rod_length;
        let mut heights = [0.0; 3];
        for (height, tower) in heights.iter_mut().zip(&delta.towers) {
            let dx = tower[0] - p[0];
            let dy = tower[1] - p[1];
            let horizontal_sqr = dx * dx + dy * dy;
            let vertical_sqr = rod_sqr - horizontal_sqr;
            if !(vertical_sqr > 0.0) {
                return Err(KinematicsError::OutOfReach);
            }
            if let Some(limit) = delta.max_tilt_sin_sqr {
                if horizontal_sqr > limit * rod_sqr {
                    return Err(KinematicsError::TooTilted);
                }
            }
            *height = p[2] + delta.effector_offset + sqrt(vertical_sqr);
        }
        Ok(heights)
    }

    #[test]
    fn delta_inverse_program_keeps_the_bits() {
        let sin40 = sin_cos(math::radians(40.0)).0;
        let mut errors = [0; 3];
        for repetier in [false, true] {
            for (printable, tilt) in [(130.0, None), (1000.0, None), (1000.0, Some(sin40 * sin40))]
            {
                let mut delta = Delta::spec_printer(repetier);
                delta.printable_radius = printable;
                delta.max_tilt_sin_sqr = tilt;
                for xi in -30..=30 {
                    for yi in -30..=30 {
                        for z in [0.0, 0.25, -7.5, 123.4] {
                            let p = [xi as f32 * 4.9 + 0.013, yi as f32 * 4.7, z];
                            let want = inverse_reference(&delta, p);
                            let got = delta.inverse(p);
                            assert_eq!(
                                got.map(|h| h.map(f32::to_bits)),
                                want.map(|h| h.map(f32::to_bits)),
                                "{p:?}"
                            );
                            match want {
                                Err(KinematicsError::OutsidePrintable) => errors[0] += 1,
                                Err(KinematicsError::OutOfReach) => errors[1] += 1,
                                Err(KinematicsError::TooTilted) => errors[2] += 1,
                                _ => {}
                            }
                        }
                    }
                }
            }
        }
        // Every refusal was met.
        assert!(errors.iter().all(|&n| n > 0), "{errors:?}");
    }

    #[test]
    fn delta_homed_heights_program_keeps_the_bits() {
        for (rod, radius, height, trim) in [
            (361.0, 227.0, 300.0, [0.0, -3.0, 0.0]),
            (250.5, 101.25, 287.3, [0.013, -0.4, 19.9]),
        ] {
            let mut delta = Delta::spec_printer(false);
            delta.set_geometry(rod, radius);
            delta.homed_height = height;
            delta.endstop_trim = trim;
            let nominal = height + delta.effector_offset + sqrt(rod * rod - radius * radius);
            let want = [nominal + trim[0], nominal + trim[1], nominal + trim[2]];
            assert_eq!(
                delta.homed_carriage_heights().map(f32::to_bits),
                want.map(f32::to_bits)
            );
        }
    }

    #[test]
    fn delta_forward_program_keeps_the_bits() {
        for repetier in [false, true] {
            let delta = Delta::spec_printer(repetier);
            let mut checked = 0;
            for xi in -14..=14 {
                for yi in -14..=14 {
                    for z in [0.0, 0.25, 7.5, 123.4] {
                        let (x, y) = (xi as f32 * 9.7, yi as f32 * 9.3);
                        let Ok(h) = delta.inverse([x, y, z]) else {
                            continue;
                        };
                        // Off the exact heights too (trims, rounded steps).
                        for dh in [0.0, 0.0125, -3.0] {
                            let h = [h[0] + dh, h[1], h[2] - dh];
                            let want = forward_reference(&delta, h);
                            let got = delta.forward(h).ok();
                            assert_eq!(
                                got.map(|p| p.map(f32::to_bits)),
                                want.map(|p| p.map(f32::to_bits)),
                                "{h:?}"
                            );
                            checked += 1;
                        }
                    }
                }
            }
            assert!(checked > 5000, "{checked}");
        }
        // No solution: carriages too far apart, or two pivots the same.
        let delta = Delta::spec_printer(false);
        for h in [[0.0, 0.0, 900.0], [0.0, 900.0, 0.0]] {
            assert_eq!(forward_reference(&delta, h), None);
        }
        assert_eq!(
            delta.forward([0.0, 0.0, 900.0]),
            Err(KinematicsError::NoSolution)
        );
        let mut same = delta;
        same.towers[1] = same.towers[0];
        assert_eq!(forward_reference(&same, [300.0; 3]), None);
        assert_eq!(same.forward([300.0; 3]), Err(KinematicsError::NoSolution));
    }

    #[test]
    fn delta_homed_heights_include_trim() {
        let mut delta = Delta::spec_printer(false);
        delta.homed_height = 300.0;
        delta.endstop_trim = [0.0, -3.0, 0.0];
        let h = delta.homed_carriage_heights();
        let p = delta.forward([h[0], h[1] + 3.0, h[2]]).unwrap();
        assert!(
            p[0].abs() < 1e-3 && p[1].abs() < 1e-3 && (p[2] - 300.0).abs() < 2e-3,
            "{p:?}"
        );
    }

    /// SPEC §3: (y, z) → θ2°, θ1°, elbow pulses, shoulder pulses at 200 ppr.
    const ARM_VECTORS: [(f32, f32, f32, f32, i32, i32); 6] = [
        (0.0, 0.0, -90.0, 0.0, -5000, 0),
        (-107.0, 68.0, -72.3508, -16.3572, -4019, -909),
        (50.0, 10.0, -106.2105, -1.7495, -5901, -97),
        (0.0, 50.0, -111.3819, -24.4717, -6188, -1360),
        (110.0, -40.0, -86.0578, 31.4494, -4781, 1747),
        (0.0, 0.0, -90.0, 0.0, -5000, 0),
    ];

    #[test]
    fn arm_spec_vectors() {
        let arm = Arm::spec_arm(200);
        let spu = arm.motor_steps_per_unit([50.0; 3]);
        for (y, z, elbow, shoulder, elbow_pulses, shoulder_pulses) in ARM_VECTORS {
            let m = arm.inverse([0.0, y, z]).unwrap();
            assert!(
                (m[1] - elbow).abs() < 1e-3,
                "({y}, {z}) θ2 {} want {elbow}",
                m[1]
            );
            assert!(
                (m[2] - shoulder).abs() < 1e-3,
                "({y}, {z}) θ1 {} want {shoulder}",
                m[2]
            );
            let steps = to_steps(m, spu);
            assert_eq!(
                (steps[1], steps[2]),
                (elbow_pulses, shoulder_pulses),
                "({y}, {z})"
            );
            let back = arm.forward(m).unwrap();
            assert!(
                (back[1] - y).abs() < 1e-3 && (back[2] - z).abs() < 1e-3,
                "forward: {back:?}"
            );
        }
        // r = 332.4 > 320: out of reach.
        assert_eq!(
            arm.inverse([0.0, -110.0, -40.0]),
            Err(KinematicsError::OutOfReach)
        );
    }

    /// The f64 reference: SPEC §3's formulas verbatim (acos), rounded to
    /// pulses.
    fn arm_reference_pulses(y: f64, z: f64, ppr: f64) -> Option<(i64, i64)> {
        let (l1, l2) = (120.0_f64, 200.0_f64);
        let (py, pz) = (120.0 - y, 200.0 - z);
        let cos2 = (py * py + pz * pz - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
        if cos2.abs() > 1.0 {
            return None;
        }
        let t2 = -cos2.acos();
        let t1 = pz.atan2(py) + (l2 * t2.sin()).atan2(l1 + l2 * t2.cos());
        let per_degree = 100.0 * ppr / 360.0;
        Some((
            (t2.to_degrees() * per_degree).round() as i64,
            (t1.to_degrees() * per_degree).round() as i64,
        ))
    }

    #[test]
    fn arm_within_one_pulse_of_f64_over_the_whole_travel_box() {
        for ppr in [200_u16, 400] {
            let arm = Arm::spec_arm(ppr);
            let spu = arm.motor_steps_per_unit([50.0; 3]);
            let (mut checked, mut refused, mut worst) = (0, 0, 0_i64);
            for y in -110..=110 {
                for z in -40..=40 {
                    let reference = arm_reference_pulses(y as f64, z as f64, ppr as f64);
                    match (arm.inverse([0.0, y as f32, z as f32]), reference) {
                        (Ok(m), Some((elbow, shoulder))) => {
                            let s = to_steps(m, spu);
                            worst = worst
                                .max((s[1] as i64 - elbow).abs())
                                .max((s[2] as i64 - shoulder).abs());
                            checked += 1;
                        }
                        (Err(_), None) => refused += 1,
                        (ours, reference) => {
                            panic!("({y}, {z}) ppr {ppr}: {ours:?} vs {reference:?}")
                        }
                    }
                }
            }
            assert!(worst <= 1, "ppr {ppr}: worst {worst} pulses");
            assert_eq!(checked + refused, 221 * 81);
            assert!(
                refused > 0 && checked > 17_000,
                "{checked} reachable, {refused} not"
            );
        }
    }

    #[test]
    fn cartesian_is_identity() {
        let k = MachineKinematics::Cartesian(Cartesian);
        assert_eq!(k.inverse([1.0, 2.0, 3.0]), Ok([1.0, 2.0, 3.0]));
        assert_eq!(to_steps([10.0, 0.005, -0.005], [100.0; 3]), [1000, 1, -1]);
        assert_eq!(k.segment_mm(), None);
    }
}
