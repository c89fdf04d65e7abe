//! Arcs (`G2` clockwise, `G3` counter-clockwise) in the XY, ZX or YZ plane
//! (`G17`/`G18`/`G19`), cut into straight chords that stay within a
//! tolerance of the true circle.
//!
//! The plane's two axes and its linear (helix) axis are Grbl's: G17 (X, Y;
//! Z), G18 (Z, X; Y), G19 (Y, Z; X), each a right-handed frame, so
//! "clockwise" means clockwise seen from the positive end of the linear
//! axis in all three. The cutter permutes its points into that frame and
//! back; the maths below is written for the first two coordinates.
//!
//! The cutter is an iterator of line end points, computed one at a time (no
//! arrays: the AVR has no RAM for them). Z and E move linearly along the
//! arc (a helix for Z). The last point is the programmed end point exactly,
//! so rounding never accumulates from one arc to the next.
//!
//! A chord of angle φ on radius r strays r·(1 − cos(φ/2)) from the circle;
//! keeping that below the tolerance τ means a chord no longer than
//! 2·√(τ·(2r − τ)), so the arc of length |sweep|·r needs
//! n = ⌈|sweep|·r / (2·√(τ·(2r − τ)))⌉ chords. Each point is computed
//! directly from its angle (no incremental rotation, so no drift).
//!
//! Validity checks follow Grbl: with a centre (I/J), the start and end
//! radii may differ by at most 0.5 mm, and by at most 0.1 % of the radius
//! beyond 0.005 mm; with a radius (R), the end point must be within 2·|R|,
//! and a negative R asks for the arc longer than half a turn. I/J with the
//! end point on the start point is a full circle.

use super::math::{atan2, clamp, length2, max, min, sin_cos, sqrt, to_u32, PI};

/// X, Y, Z, E in mm.
pub type Point = [f32; 4];

/// The plane of an arc.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plane {
    /// `G17` (the default): X, Y; helix along Z.
    Xy,
    /// `G18`: Z, X; helix along Y.
    Zx,
    /// `G19`: Y, Z; helix along X.
    Yz,
}

impl Plane {
    /// Indices of the plane's first and second axis and of its linear axis.
    pub const fn axes(self) -> [usize; 3] {
        match self {
            Plane::Xy => [0, 1, 2],
            Plane::Zx => [2, 0, 1],
            Plane::Yz => [1, 2, 0],
        }
    }

    /// A point in the plane's frame: (first, second, linear, E). Inline:
    /// a call (its point through memory both ways) cost 36 bytes more.
    #[inline(always)]
    fn to_frame(self, p: Point) -> Point {
        let [a, b, l] = self.axes();
        [p[a], p[b], p[l], p[3]]
    }

    /// The inverse of [`Self::to_frame`] (named as its pair).
    #[allow(clippy::wrong_self_convention)]
    fn from_frame(self, q: Point) -> Point {
        let [a, b, l] = self.axes();
        let mut p = [0.0; 4];
        p[a] = q[0];
        p[b] = q[1];
        p[l] = q[2];
        p[3] = q[3];
        p
    }
}

/// Why an arc cannot be cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArcError {
    /// The radius is zero (centre on the start point).
    ZeroRadius,
    /// Start and end are not on one circle around the given centre.
    RadiusMismatch,
    /// An R arc whose end point is farther than 2·|R| or on the start.
    RadiusTooSmall,
}

/// The chord end points of one arc.
#[derive(Clone, Debug, PartialEq)]
pub struct ArcCutter {
    centre: [f32; 2],
    radius: f32,
    start_angle: f32,
    sweep: f32,
    /// Start and target in the plane's frame.
    start: Point,
    target: Point,
    /// The target as given (returned exactly as the last point).
    exact_target: Point,
    plane: Plane,
    chords: u32,
    done: u32,
}

/// How an arc's centre is given, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Centre {
    /// The centre's offset from the start in the plane's two axes (`I J`
    /// in G17, `K I` in G18, `J K` in G19).
    Offset([f32; 2]),
    /// `R`: negative picks the arc over half a turn.
    Radius(f32),
}

impl ArcCutter {
    /// `G2`/`G3` with the centre's offset from the start in the plane's two
    /// axes (`I J` in G17, `K I` in G18, `J K` in G19).
    pub fn with_centre(plane: Plane, start: Point, target: Point, offset: [f32; 2], clockwise: bool, tolerance: f32) -> Result<Self, ArcError> {
        Self::new(plane, &start, &target, &Centre::Offset(offset), clockwise, tolerance)
    }

    /// `G2`/`G3` with `R`: the centre is where a circle of radius |R|
    /// passes through both points; R < 0 picks the arc over half a turn.
    pub fn with_radius(plane: Plane, start: Point, target: Point, radius: f32, clockwise: bool, tolerance: f32) -> Result<Self, ArcError> {
        Self::new(plane, &start, &target, &Centre::Radius(radius), clockwise, tolerance)
    }

    /// Either form: one constructor, so the AVR has one copy of the frame
    /// changes and of the cutter's construction (a copy per form cost
    /// flash). Points and centre by reference: arguments must stay within
    /// 18 bytes (see [`Self::cut`]).
    pub fn new(plane: Plane, start: &Point, target: &Point, centre: &Centre, clockwise: bool, tolerance: f32) -> Result<Self, ArcError> {
        let mut arc = Self::EMPTY;
        arc.init(plane, start, target, centre, clockwise, tolerance)?;
        Ok(arc)
    }

    /// Nothing to cut (a placeholder for [`Self::init`]).
    pub const EMPTY: Self = Self {
        centre: [0.0; 2],
        radius: 0.0,
        start_angle: 0.0,
        sweep: 0.0,
        start: [0.0; 4],
        target: [0.0; 4],
        exact_target: [0.0; 4],
        plane: Plane::Xy,
        chords: 0,
        done: 0,
    };

    /// [`Self::new`] in place: the motion layer builds the cutter where it
    /// keeps it (as a temporary the AVR needed a frame of over 63 bytes,
    /// where every stack access costs 12 bytes of code, and a copy). On
    /// `Err` the cutter is left half set: discard it.
    pub fn init(&mut self, plane: Plane, start: &Point, target: &Point, centre: &Centre, clockwise: bool, tolerance: f32) -> Result<(), ArcError> {
        self.exact_target = *target;
        self.plane = plane;
        self.done = 0;
        self.start = plane.to_frame(*start);
        self.target = plane.to_frame(*target);
        let (start, target) = (&self.start, &self.target);
        let (centre, radius) = match *centre {
            Centre::Offset(offset) => {
                let centre = [start[0] + offset[0], start[1] + offset[1]];
                let radius = length2(offset[0], offset[1]);
                if !(radius > 0.0) {
                    return Err(ArcError::ZeroRadius);
                }
                let (ex, ey) = (target[0] - centre[0], target[1] - centre[1]);
                let mismatch = (length2(ex, ey) - radius).abs();
                if mismatch > 0.5 || (mismatch > 0.005 && mismatch > 0.001 * radius) {
                    return Err(ArcError::RadiusMismatch);
                }
                (centre, radius)
            }
            Centre::Radius(radius) => {
                let (dx, dy) = (target[0] - start[0], target[1] - start[1]);
                let chord = length2(dx, dy);
                let r = radius.abs();
                let half = chord / 2.0;
                if !(chord > 0.0) || !(r >= half) {
                    return Err(ArcError::RadiusTooSmall);
                }
                // Distance from the chord's midpoint to the centre; for an
                // arc of at most half a turn the centre lies to the right of
                // the chord when going clockwise, to the left when
                // counter-clockwise.
                let rise = sqrt(max(r * r - half * half, 0.0));
                let (ux, uy) = (dx / chord, dy / chord);
                let mut side = if clockwise { 1.0 } else { -1.0 };
                if radius < 0.0 {
                    side = -side;
                }
                ([start[0] + dx / 2.0 + side * rise * uy, start[1] + dy / 2.0 - side * rise * ux], r)
            }
        };
        self.centre = centre;
        self.radius = radius;
        self.cut(clockwise, tolerance);
        Ok(())
    }

    /// The sweep and the number of chords of an arc whose centre, radius
    /// and end points are set. (Few arguments on purpose: beyond 18 bytes
    /// of them the AVR back end passes the rest on the stack, which it
    /// miscompiles on the ATmega2560, see `size-check.sh`.)
    fn cut(&mut self, clockwise: bool, tolerance: f32) {
        let (start, target, centre, radius) = (&self.start, &self.target, &self.centre, self.radius);
        let start_angle = atan2(start[1] - centre[1], start[0] - centre[0]);
        let end_angle = atan2(target[1] - centre[1], target[0] - centre[0]);
        let mut sweep = end_angle - start_angle;
        const EPSILON: f32 = 5.0e-7;
        if clockwise {
            if sweep >= -EPSILON {
                sweep -= 2.0 * PI;
            }
        } else if sweep <= EPSILON {
            sweep += 2.0 * PI;
        }
        let tolerance = clamp(tolerance, 1.0e-4, radius);
        let chord = 2.0 * sqrt(tolerance * (2.0 * radius - tolerance));
        let chords = max(sweep.abs() * radius / chord, 1.0);
        // Round up, saturating far beyond any real arc.
        let chords = (to_u32(min(chords, 1.0e6)) + 1).min(1_000_000);
        self.start_angle = start_angle;
        self.sweep = sweep;
        self.chords = chords;
    }

    /// Chords in this arc.
    pub fn chords(&self) -> u32 {
        self.chords
    }

    /// Signed angle swept, radians (negative: clockwise).
    pub fn sweep(&self) -> f32 {
        self.sweep
    }

    pub fn radius(&self) -> f32 {
        self.radius
    }

    pub fn centre(&self) -> [f32; 2] {
        self.centre
    }
}

impl ArcCutter {
    /// The next chord's end into `end`; false (and `end` unchanged) when
    /// the arc is done. Into the caller's buffer: the motion loop's frame
    /// holds no `Option<Point>` (beyond 63 bytes of frame every access
    /// costs the AVR several instructions more; out of line it grew).
    pub fn next_into(&mut self, end: &mut Point) -> bool {
        if self.done >= self.chords {
            return false;
        }
        self.done += 1;
        if self.done == self.chords {
            *end = self.exact_target;
            return true;
        }
        let fraction = self.done as f32 / self.chords as f32;
        let (sin, cos) = sin_cos(self.start_angle + self.sweep * fraction);
        *end = self.plane.from_frame([
            self.centre[0] + self.radius * cos,
            self.centre[1] + self.radius * sin,
            self.start[2] + (self.target[2] - self.start[2]) * fraction,
            self.start[3] + (self.target[3] - self.start[3]) * fraction,
        ]);
        true
    }
}

impl Iterator for ArcCutter {
    type Item = Point;

    fn next(&mut self) -> Option<Point> {
        let mut end = [0.0; 4];
        self.next_into(&mut end).then_some(end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    fn distance_to_circle(p: Point, centre: [f32; 2], r: f32) -> f32 {
        (sqrt((p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2)) - r).abs()
    }

    #[test]
    fn quarter_circle_clockwise_with_centre() {
        // (0,10) → (10,0) around the origin, clockwise: a quarter turn.
        let arc = ArcCutter::with_centre(Plane::Xy, [0.0, 10.0, 0.0, 0.0], [10.0, 0.0, 2.0, 1.0], [0.0, -10.0], true, 0.002).unwrap();
        assert!((arc.sweep() + PI / 2.0).abs() < 1e-5);
        let chords = arc.chords();
        let points: Vec<Point> = arc.clone().collect();
        assert_eq!(points.len() as u32, chords);
        assert_eq!(*points.last().unwrap(), [10.0, 0.0, 2.0, 1.0]);
        let mut previous = [0.0, 10.0, 0.0, 0.0];
        for p in &points {
            assert!(distance_to_circle(*p, [0.0, 0.0], 10.0) < 1e-4);
            // The chord's midpoint is within the tolerance of the circle.
            let mid = [(p[0] + previous[0]) / 2.0, (p[1] + previous[1]) / 2.0, 0.0, 0.0];
            assert!(distance_to_circle(mid, [0.0, 0.0], 10.0) <= 0.002 + 1e-4);
            assert!(p[0] >= previous[0] - 1e-5, "clockwise from the top goes +X");
            previous = *p;
        }
        // ≈ 15.7 mm of arc in chords of 2·√(0.002·19.998) = 0.4 mm.
        assert!((39..=41).contains(&chords), "{chords}");
    }

    #[test]
    fn full_circle_when_end_equals_start() {
        let arc = ArcCutter::with_centre(Plane::Xy, [10.0, 0.0, 0.0, 0.0], [10.0, 0.0, 0.0, 0.0], [-10.0, 0.0], false, 0.01).unwrap();
        assert!((arc.sweep() - 2.0 * PI).abs() < 1e-5);
        let points: Vec<Point> = arc.collect();
        // Counter-clockwise from (10, 0): first points have y > 0.
        assert!(points[0][1] > 0.0);
        assert!(points.iter().all(|p| distance_to_circle(*p, [0.0, 0.0], 10.0) < 1e-4));
    }

    #[test]
    fn radius_form_picks_the_right_centre() {
        let start = [0.0, 0.0, 0.0, 0.0];
        let target = [10.0, 0.0, 0.0, 0.0];
        // R 10 clockwise from (0,0) to (10,0): the short arc bulges to +Y,
        // centre below the chord.
        let arc = ArcCutter::with_radius(Plane::Xy, start, target, 10.0, true, 0.002).unwrap();
        assert!((arc.centre()[0] - 5.0).abs() < 1e-5 && arc.centre()[1] < 0.0);
        assert!(arc.sweep() < 0.0 && arc.sweep() > -PI);
        let mid = arc.clone().nth(arc.chords() as usize / 2).unwrap();
        assert!(mid[1] > 0.0);
        // R −10: the long way round.
        let long = ArcCutter::with_radius(Plane::Xy, start, target, -10.0, true, 0.002).unwrap();
        assert!(long.sweep() < -PI);
        assert!(long.centre()[1] > 0.0);
        // Counter-clockwise short arc bulges to −Y.
        let ccw = ArcCutter::with_radius(Plane::Xy, start, target, 10.0, false, 0.002).unwrap();
        let mid = ccw.clone().nth(ccw.chords() as usize / 2).unwrap();
        assert!(mid[1] < 0.0);
        assert_eq!(ArcCutter::with_radius(Plane::Xy, start, target, 4.0, true, 0.002), Err(ArcError::RadiusTooSmall));
        assert_eq!(ArcCutter::with_radius(Plane::Xy, start, start, 4.0, true, 0.002), Err(ArcError::RadiusTooSmall));
    }

    #[test]
    fn mismatched_radii_and_zero_radius_are_refused() {
        let start = [0.0, 10.0, 0.0, 0.0];
        assert_eq!(ArcCutter::with_centre(Plane::Xy, start, [11.0, 0.0, 0.0, 0.0], [0.0, -10.0], true, 0.002), Err(ArcError::RadiusMismatch));
        assert_eq!(ArcCutter::with_centre(Plane::Xy, start, [10.0, 0.0, 0.0, 0.0], [0.0, 0.0], true, 0.002), Err(ArcError::ZeroRadius));
        // Within 0.1 % of the radius is accepted (slicer rounding).
        assert!(ArcCutter::with_centre(Plane::Xy, start, [10.008, 0.0, 0.0, 0.0], [0.0, -10.0], true, 0.002).is_ok());
    }

    /// G18: the arc turns in Z and X, the helix runs along Y; clockwise
    /// seen from +Y. From (X0, Z10) around the origin to (X10, Z0): in the
    /// (Z, X) frame that is (10, 0) → (0, 10), a quarter turn
    /// counter-clockwise, so G2 goes the long way (three quarters).
    #[test]
    fn a_g18_arc_turns_in_z_and_x_and_ends_exactly() {
        let start = [0.0, 0.0, 10.0, 0.0];
        let target = [10.0, 5.0, 0.0, 0.0];
        let ccw = ArcCutter::with_centre(Plane::Zx, start, target, [-10.0, 0.0], false, 0.002).unwrap();
        assert!((ccw.sweep() - PI / 2.0).abs() < 1e-5, "{}", ccw.sweep());
        let points: Vec<Point> = ccw.collect();
        assert_eq!(*points.last().unwrap(), target);
        for p in &points {
            assert!(((p[0] * p[0] + p[2] * p[2]).sqrt() - 10.0).abs() < 1e-4, "{p:?}");
            assert!(p[1] >= 0.0 && p[1] <= 5.0, "Y is the helix axis: {p:?}");
        }
        let cw = ArcCutter::with_centre(Plane::Zx, start, target, [-10.0, 0.0], true, 0.002).unwrap();
        assert!((cw.sweep() + 1.5 * PI).abs() < 1e-5, "{}", cw.sweep());
    }

    /// G19: Y and Z, helix along X.
    #[test]
    fn a_g19_arc_turns_in_y_and_z() {
        let arc = ArcCutter::with_radius(Plane::Yz, [3.0, 0.0, 0.0, 0.0], [3.0, 10.0, 0.0, 0.0], 5.0, false, 0.002).unwrap();
        let points: Vec<Point> = arc.collect();
        assert!(points.iter().all(|p| p[0] == 3.0));
        let mid = points[points.len() / 2];
        // Counter-clockwise from +X: from (Y0, Z0) to (Y10, Z0) the short
        // way passes below, through Z -5.
        assert!((mid[1] - 5.0).abs() < 0.5 && (mid[2] + 5.0).abs() < 0.1, "{mid:?}");
    }
}
