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
//!
//! The linear delta ([`Delta`]). Each tower i has a carriage at height h_i
//! whose rod pivot sits at (R·cosθ_i, R·sinθ_i, h_i); a rod of length L
//! joins it to the effector, whose pivots are OF above the nozzle. Seen
//! from above, a rod spans the horizontal distance d_i from its tower's
//! pivot column to the nozzle (x, y), so it rises √(L² − d_i²):
//!
//!   inverse:  h_i = z + OF + √(L² − d_i²),
//!
//! refused where L² − d_i² ≤ 0 (the rod cannot reach), outside the
//! printable radius, and, with a tilt limit, where d_i² > L²·sin²(limit).
//! Forward, the nozzle raised by OF is the point at distance L from the
//! three lowered pivots p_i = (R·cosθ_i, R·sinθ_i, h_i − OF): the
//! intersection of three spheres of equal radius (trilateration). In the
//! frame ex = (p2 − p1)/d, d = |p2 − p1|, ey = the unit part of p3 − p1
//! square to ex, ez = ex × ey, with i = ex·(p3 − p1), j = ey·(p3 − p1),
//! subtracting the sphere equations pairwise (equal radii cancel) gives
//!
//!   x = d/2,  y = (i² + j²)/(2j) − i·x/j,  z = ±√(L² − x² − y²),
//!
//! and the point is p1 + x·ex + y·ey + z·ez, of the two signs the one
//! below the carriages. Two coincident pivots (d = 0, or p3 on the line
//! p1p2) or L² − x² − y² < 0 leave no solution.

use super::math::{self, atan2, round_to_i32, sin_cos, sqrt};

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

    /// Carriage height of every tower when all sit at their top endstops:
    /// the nozzle is then at (0, 0, homed_height), every rod at the
    /// horizontal distance R from its pivot, so h_i = trim_i + (H + OF +
    /// √(L² − R²)).
    pub fn homed_carriage_heights(&self) -> Vector3 {
        let rod_rise = sqrt(self.rod_length * self.rod_length - self.radius * self.radius);
        let nominal = (self.homed_height + self.effector_offset) + rod_rise;
        self.endstop_trim.map(|trim| trim + nominal)
    }

    /// The pivot of carriage `tower` at height `height`, lowered by the
    /// effector offset: the three spheres of radius L are centred there.
    fn lowered_pivot(&self, tower: usize, height: f32) -> Vector3 {
        let [x, y] = self.towers[tower];
        [x, y, height - self.effector_offset]
    }
}

impl Kinematics for Delta {
    /// h_i = z + OF + √(L² − d_i²) for each tower, d_i the horizontal
    /// distance from the tower's pivot; refused outside the printable
    /// radius, where L² − d_i² ≤ 0, or where d_i² > L²·sin²(tilt limit).
    fn inverse(&self, p: Vector3) -> Result<Vector3, KinematicsError> {
        let [x, y, z] = p;
        if x * x + y * y > self.printable_radius * self.printable_radius {
            return Err(KinematicsError::OutsidePrintable);
        }
        let rod_sqr = self.rod_length * self.rod_length;
        let tilt_limit = self.max_tilt_sin_sqr.map(|sin_sqr| sin_sqr * rod_sqr);
        let nozzle_pivot_z = z + self.effector_offset;
        let mut heights = [0.0; LINEAR_AXES];
        for (height, [tower_x, tower_y]) in heights.iter_mut().zip(self.towers) {
            let (dx, dy) = (tower_x - x, tower_y - y);
            let horizontal_sqr = dx * dx + dy * dy;
            let vertical_sqr = rod_sqr - horizontal_sqr;
            // (Written so that NaN is refused too.)
            if !(vertical_sqr > 0.0) {
                return Err(KinematicsError::OutOfReach);
            }
            if tilt_limit.is_some_and(|limit| horizontal_sqr > limit) {
                return Err(KinematicsError::TooTilted);
            }
            *height = nozzle_pivot_z + sqrt(vertical_sqr);
        }
        Ok(heights)
    }

    /// Trilateration: the effector pivot point lies at distance L from
    /// each carriage pivot p_i = (tower x, tower y, h_i − OF); of the two
    /// intersections of the three spheres, the one below the carriages
    /// (the module comment has the derivation).
    fn forward(&self, heights: Vector3) -> Result<Vector3, KinematicsError> {
        let p1 = self.lowered_pivot(0, heights[0]);
        let p2 = self.lowered_pivot(1, heights[1]);
        let p3 = self.lowered_pivot(2, heights[2]);
        // A frame on the pivots: ex towards p2, ey towards p3 in their plane.
        let p21 = sub3(&p2, &p1);
        let p31 = sub3(&p3, &p1);
        let d = length3(&p21);
        // (Written so that NaN is refused too.)
        if !(d > 0.0) {
            return Err(KinematicsError::NoSolution);
        }
        let ex = scale3(&p21, 1.0 / d);
        let i = dot3(&ex, &p31);
        let ey_unscaled = sub3(&p31, &scale3(&ex, i));
        let ey_length = length3(&ey_unscaled);
        if !(ey_length > 0.0) {
            return Err(KinematicsError::NoSolution);
        }
        let ey = scale3(&ey_unscaled, 1.0 / ey_length);
        let j = dot3(&ey, &p31);
        // All three radii are L, so the r₁² − r₂² terms vanish.
        let x = d * 0.5;
        let y = (i * i + j * j) / (j + j) - i * x / j;
        let z_sqr = self.rod_length * self.rod_length - x * x - y * y;
        if !(z_sqr >= 0.0) {
            return Err(KinematicsError::NoSolution);
        }
        let z = sqrt(z_sqr);
        let base = add3(&add3(&p1, &scale3(&ex, x)), &scale3(&ey, y));
        let ez = cross3(&ex, &ey);
        // Of base ± ez·z, the lower (base − ez·z when they are level).
        let z = if base[2] + ez[2] * z < base[2] - ez[2] * z { z } else { -z };
        Ok(add3(&base, &scale3(&ez, z)))
    }

    fn segment_mm(&self) -> Option<f32> {
        Some(self.segment_length)
    }

    fn motor_steps_per_unit(&self, steps_per_mm: Vector3) -> Vector3 {
        steps_per_mm
    }
}

/// a + b.
fn add3(a: &Vector3, b: &Vector3) -> Vector3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// a − b.
fn sub3(a: &Vector3, b: &Vector3) -> Vector3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// a·k.
fn scale3(a: &Vector3, k: f32) -> Vector3 {
    [a[0] * k, a[1] * k, a[2] * k]
}

/// a · b, summed left to right.
fn dot3(a: &Vector3, b: &Vector3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a × b.
fn cross3(a: &Vector3, b: &Vector3) -> Vector3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// |a|, the squares summed left to right.
pub(crate) fn length3(a: &Vector3) -> f32 {
    sqrt(dot3(a, a))
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

    /// A delta's geometry in f64, the towers placed from the angles anew.
    struct DeltaF64 {
        rod: f64,
        offset: f64,
        towers: [[f64; 2]; 3],
        printable: f64,
        tilt_sin_sqr: Option<f64>,
    }

    impl DeltaF64 {
        fn of(delta: &Delta) -> Self {
            let radius = f64::from(delta.radius);
            Self {
                rod: f64::from(delta.rod_length),
                offset: f64::from(delta.effector_offset),
                towers: delta.tower_angles_deg.map(|angle| {
                    let angle = f64::from(angle).to_radians();
                    [radius * angle.cos(), radius * angle.sin()]
                }),
                printable: f64::from(delta.printable_radius),
                tilt_sin_sqr: delta.max_tilt_sin_sqr.map(f64::from),
            }
        }

        /// SPEC §2's formulas in f64: the carriage heights, or the refusal
        /// (the same checks in the same order), and the smallest L² − d².
        fn inverse(&self, p: [f64; 3]) -> Result<([f64; 3], f64), KinematicsError> {
            if p[0].hypot(p[1]) > self.printable {
                return Err(KinematicsError::OutsidePrintable);
            }
            let rod_sqr = self.rod * self.rod;
            let mut heights = [0.0; 3];
            let mut least_vertical_sqr = f64::INFINITY;
            for (height, [tx, ty]) in heights.iter_mut().zip(self.towers) {
                let horizontal_sqr = (tx - p[0]).powi(2) + (ty - p[1]).powi(2);
                let vertical_sqr = rod_sqr - horizontal_sqr;
                if vertical_sqr <= 0.0 {
                    return Err(KinematicsError::OutOfReach);
                }
                if self.tilt_sin_sqr.is_some_and(|limit| horizontal_sqr > limit * rod_sqr) {
                    return Err(KinematicsError::TooTilted);
                }
                least_vertical_sqr = least_vertical_sqr.min(vertical_sqr);
                *height = p[2] + self.offset + vertical_sqr.sqrt();
            }
            Ok((heights, least_vertical_sqr))
        }

        /// The nozzle from the carriage heights by trilateration in f64,
        /// written independently of the firmware's: the nozzle raised by OF
        /// is the circumcentre c of the three pivots plus the distance
        /// √(L² − ρ²) (ρ the circumradius) along the downward normal of
        /// their plane.
        fn forward(&self, h: [f64; 3]) -> Option<[f64; 3]> {
            let p: [[f64; 3]; 3] =
                core::array::from_fn(|i| [self.towers[i][0], self.towers[i][1], h[i] - self.offset]);
            let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
            let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            let cross = |a: [f64; 3], b: [f64; 3]| {
                [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
            };
            let (a, b) = (sub(p[1], p[0]), sub(p[2], p[0]));
            let n = cross(a, b);
            let n_sqr = dot(n, n);
            if n_sqr == 0.0 {
                return None;
            }
            // c − p0 = (|a|²·(b × n) + |b|²·(n × a)) / (2|n|²).
            let (bn, na) = (cross(b, n), cross(n, a));
            let c: [f64; 3] =
                core::array::from_fn(|k| p[0][k] + (dot(a, a) * bn[k] + dot(b, b) * na[k]) / (2.0 * n_sqr));
            let rho_sqr = dot(sub(c, p[0]), sub(c, p[0]));
            let drop_sqr = self.rod * self.rod - rho_sqr;
            if drop_sqr < 0.0 {
                return None;
            }
            let n_len = n_sqr.sqrt();
            let down = if n[2] > 0.0 { -1.0 } else { 1.0 };
            Some(core::array::from_fn(|k| c[k] + down * n[k] / n_len * drop_sqr.sqrt()))
        }
    }

    /// The inverse against SPEC §2's formulas in f64, over a grid that meets
    /// every refusal: the same answers, and heights within 1e-4 mm plus
    /// what f32 loses in L² − d²: both near 130 000 mm², the difference
    /// is off by up to about 0.02 mm², and √ turns that into 0.01 mm² /
    /// √(L² − d²). Over SPEC §2's 130 mm printable disc every rod rises
    /// more than 50 mm: there the bound is 3e-4 mm, a 40th of a step at
    /// 80 steps/mm.
    #[test]
    fn delta_inverse_matches_f64() {
        let sin40 = sin_cos(math::radians(40.0)).0;
        let mut refusals = [0; 3];
        let (mut checked, mut worst_in_disc) = (0, 0.0_f64);
        for repetier in [false, true] {
            for (printable, tilt) in [(130.0, None), (1000.0, None), (1000.0, Some(sin40 * sin40))] {
                let mut delta = Delta::spec_printer(repetier);
                delta.printable_radius = printable;
                delta.max_tilt_sin_sqr = tilt;
                let reference = DeltaF64::of(&delta);
                for xi in -30..=30 {
                    for yi in -30..=30 {
                        for z in [0.0, 0.25, -7.5, 123.4] {
                            let p = [xi as f32 * 4.9 + 0.013, yi as f32 * 4.7, z];
                            let got = delta.inverse(p);
                            match (got, reference.inverse(p.map(f64::from))) {
                                (Ok(h), Ok((want, least_vertical_sqr))) => {
                                    let error = (0..3)
                                        .map(|i| (f64::from(h[i]) - want[i]).abs())
                                        .fold(0.0, f64::max);
                                    let rise = least_vertical_sqr.sqrt();
                                    let bound = 1e-4 + 0.01 / rise;
                                    assert!(error <= bound, "{p:?}: {h:?} vs {want:?}");
                                    if f64::from(p[0]).hypot(f64::from(p[1])) <= 130.0 {
                                        worst_in_disc = worst_in_disc.max(error);
                                    }
                                    checked += 1;
                                }
                                (Err(ours), Err(theirs)) => {
                                    assert_eq!(ours, theirs, "{p:?}");
                                    refusals[match ours {
                                        KinematicsError::OutsidePrintable => 0,
                                        KinematicsError::OutOfReach => 1,
                                        _ => 2,
                                    }] += 1;
                                }
                                (ours, theirs) => panic!("{p:?}: {ours:?} vs {theirs:?}"),
                            }
                        }
                    }
                }
            }
        }
        // Every refusal was met.
        assert!(refusals.iter().all(|&n| n > 0), "{refusals:?}");
        assert!(checked > 20_000 && worst_in_disc < 3e-4, "{checked}: {worst_in_disc}");
        std::println!("{checked} points, worst in the printable disc {worst_in_disc:.1e} mm");
    }

    /// The homed carriage heights against trim + H + OF + √(L² − R²) in f64.
    #[test]
    fn delta_homed_heights_match_f64() {
        for (rod, radius, height, trim) in [
            (361.0, 227.0, 300.0, [0.0, -3.0, 0.0]),
            (250.5, 101.25, 287.3, [0.013, -0.4, 19.9]),
        ] {
            let mut delta = Delta::spec_printer(false);
            delta.set_geometry(rod, radius);
            delta.homed_height = height;
            delta.endstop_trim = trim;
            let (rod, radius) = (f64::from(rod), f64::from(radius));
            let nominal = f64::from(height) + 64.0 + (rod * rod - radius * radius).sqrt();
            let got = delta.homed_carriage_heights();
            for i in 0..3 {
                let want = nominal + f64::from(trim[i]);
                assert!((f64::from(got[i]) - want).abs() < 1e-4, "{got:?}: {want}");
            }
        }
    }

    /// The trilateration against an f64 one by another route (see
    /// [`DeltaF64::forward`]), at the exact heights of points over the bed
    /// and off them (trims, rounded steps): within 5e-4 mm, and 99 % of
    /// them within 1e-4 mm (f32 rounding of the frame, of carriage heights
    /// near 350 mm). Then the heights that have no solution.
    #[test]
    fn delta_forward_matches_f64() {
        let (mut checked, mut over_1e4, mut worst) = (0, 0, 0.0_f64);
        for repetier in [false, true] {
            let delta = Delta::spec_printer(repetier);
            let reference = DeltaF64::of(&delta);
            for xi in -14..=14 {
                for yi in -14..=14 {
                    for z in [0.0, 0.25, 7.5, 123.4] {
                        let (x, y) = (xi as f32 * 9.7, yi as f32 * 9.3);
                        let Ok(h) = delta.inverse([x, y, z]) else {
                            continue;
                        };
                        for dh in [0.0, 0.0125, -3.0] {
                            let h = [h[0] + dh, h[1], h[2] - dh];
                            let got = delta.forward(h).unwrap_or_else(|e| panic!("{h:?}: {e:?}"));
                            let want = reference.forward(h.map(f64::from)).unwrap();
                            let error =
                                (0..3).map(|i| (f64::from(got[i]) - want[i]).abs()).fold(0.0, f64::max);
                            worst = worst.max(error);
                            over_1e4 += usize::from(error > 1e-4);
                            checked += 1;
                        }
                    }
                }
            }
        }
        assert!(checked > 5000, "{checked}");
        assert!(worst < 5e-4 && over_1e4 * 100 < checked, "{checked}: {over_1e4} over 1e-4 mm, worst {worst}");
        std::println!("{checked} heights, {over_1e4} over 1e-4 mm, worst {worst:.1e} mm");
        // No solution: carriages too far apart, or two pivots the same.
        let delta = Delta::spec_printer(false);
        for h in [[0.0, 0.0, 900.0], [0.0, 900.0, 0.0]] {
            assert_eq!(DeltaF64::of(&delta).forward(h.map(f64::from)), None);
            assert_eq!(delta.forward(h), Err(KinematicsError::NoSolution));
        }
        let mut same = delta;
        same.towers[1] = same.towers[0];
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
