//! Judging a recorded step stream against the move that was commanded.
//!
//! The plan is the ideal trapezoid of the move (from rest to rest, constant
//! acceleration `a` up to the commanded speed `v`, a triangle when the move
//! is too short), on one axis, with `steps_per_mm`.
//!
//! A stream is **on time** when all of these hold (what `cargo benchmark`
//! calls "before steps come late"):
//! 1. Count and direction: exactly the planned number of rising STEP edges,
//!    all with the same DIR level.
//! 2. Cruise, edge by edge: over the cruise plateau (trimmed by 2 % of its
//!    steps at each end, at least 2 steps) each edge `k` is compared with
//!    the schedule `t0 + k·I`, `I` the planned interval at `v`. A step
//!    generator fires at its scheduled time at the earliest, so `t0` is
//!    taken from the earliest edge (the one with the smallest `t_k − k·I`);
//!    an edge is **late** when it comes more than 10 % of `I` after its
//!    scheduled time.
//! 3. Cruise rate: the least-squares rate over the plateau is within 1 % of
//!    `steps_per_mm·v` (otherwise the profile departs from the plan: the
//!    firmware did not reach, or exceeded, the commanded speed).
//! 4. Ramps: the time from the first edge to the first plateau edge, and
//!    from the last plateau edge to the last edge, each within 10 % of the
//!    plan's (ramps are where firmware discretisations differ: 10 % lets an
//!    AVR446-style ramp pass and catches a missing or wrong ramp). A move
//!    with no plateau (a triangle) is held to 5 % on its whole duration.

use crate::board::{StepEdge, CPU_HZ};

#[derive(Clone, Copy, Debug)]
pub struct MovePlan {
    pub steps: u64,
    pub steps_per_mm: f64,
    pub feed_mm_s: f64,
    pub accel_mm_s2: f64,
}

impl MovePlan {
    pub fn length_mm(&self) -> f64 {
        self.steps as f64 / self.steps_per_mm
    }

    /// The speed actually reached (lower than `feed` for a triangle).
    pub fn peak_mm_s(&self) -> f64 {
        self.feed_mm_s
            .min((self.accel_mm_s2 * self.length_mm()).sqrt())
    }

    fn accel_distance(&self) -> f64 {
        let v = self.peak_mm_s();
        v * v / (2.0 * self.accel_mm_s2)
    }

    /// Seconds from the start of the move until position `x` (mm).
    pub fn time_at(&self, x: f64) -> f64 {
        let (a, v, len) = (self.accel_mm_s2, self.peak_mm_s(), self.length_mm());
        let d = self.accel_distance();
        let ta = v / a;
        if x <= d {
            (2.0 * x / a).sqrt()
        } else if x <= len - d {
            ta + (x - d) / v
        } else {
            let cruise = (len - 2.0 * d) / v;
            let rest = (len - x).max(0.0);
            2.0 * ta + cruise - (2.0 * rest / a).sqrt()
        }
    }

    pub fn duration(&self) -> f64 {
        self.time_at(self.length_mm())
    }

    /// Cruise rate, steps per second.
    pub fn cruise_hz(&self) -> f64 {
        self.feed_mm_s * self.steps_per_mm
    }

    /// Steps (1-based) that lie on the cruise plateau, trimmed.
    pub fn cruise_steps(&self) -> Option<(u64, u64)> {
        if self.peak_mm_s() < self.feed_mm_s {
            return None;
        }
        let d_steps = self.accel_distance() * self.steps_per_mm;
        let first = d_steps.ceil() as u64 + 1;
        let last = (self.steps as f64 - d_steps).floor() as u64;
        if last <= first + 4 {
            return None;
        }
        let trim = ((last - first) / 50).max(2);
        Some((first + trim, last - trim))
    }
}

/// The outcome of judging one stream.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    /// None: on time. Some: why not (late, or departing from the plan).
    pub failure: Option<String>,
    /// Worst lateness on the cruise plateau, as a fraction of the interval.
    pub worst_late: f64,
    /// Least-squares cruise rate, steps/s.
    pub cruise_hz: f64,
    /// (first, last) rising-edge cycles of the cruise plateau.
    pub cruise_span: Option<(u64, u64)>,
    pub steps: u64,
}

/// Judge the rising edges of one axis (see the module docs).
pub fn judge(plan: &MovePlan, edges: &[StepEdge]) -> Verdict {
    let rises: Vec<&StepEdge> = edges.iter().filter(|e| e.rising).collect();
    let steps = rises.len() as u64;
    let mut verdict = Verdict {
        failure: None,
        worst_late: 0.0,
        cruise_hz: 0.0,
        cruise_span: None,
        steps,
    };
    if steps != plan.steps {
        verdict.failure = Some(format!("departs: {steps} steps instead of {}", plan.steps));
        return verdict;
    }
    if steps == 0 {
        return verdict;
    }
    if rises.iter().any(|e| e.dir != rises[0].dir) {
        verdict.failure = Some("departs: DIR changed during the move".into());
        return verdict;
    }
    let hz = f64::from(CPU_HZ);
    if let Some((first, last)) = plan.cruise_steps() {
        let interval = hz / plan.cruise_hz();
        let plateau: Vec<(f64, f64)> = (first..=last)
            .map(|k| (k as f64, rises[(k - 1) as usize].cycle as f64))
            .collect();
        verdict.cruise_span = Some((
            rises[(first - 1) as usize].cycle,
            rises[(last - 1) as usize].cycle,
        ));
        // Least-squares slope: cycles per step.
        let n = plateau.len() as f64;
        let (sk, st) = plateau
            .iter()
            .fold((0.0, 0.0), |(a, b), (k, t)| (a + k, b + t));
        let (mk, mt) = (sk / n, st / n);
        let (num, den) = plateau.iter().fold((0.0, 0.0), |(a, b), (k, t)| {
            (a + (k - mk) * (t - mt), b + (k - mk) * (k - mk))
        });
        verdict.cruise_hz = hz / (num / den);
        let t0 = plateau
            .iter()
            .map(|(k, t)| t - k * interval)
            .fold(f64::INFINITY, f64::min);
        let (worst_k, worst) = plateau
            .iter()
            .map(|(k, t)| (*k, (t - t0 - k * interval) / interval))
            .fold(
                (0.0, 0.0f64),
                |best, cur| if cur.1 > best.1 { cur } else { best },
            );
        verdict.worst_late = worst;
        let rate_error = (verdict.cruise_hz - plan.cruise_hz()) / plan.cruise_hz();
        if rate_error.abs() > 0.01 {
            verdict.failure = Some(format!(
                "departs: cruise at {:.0} steps/s instead of {:.0}",
                verdict.cruise_hz,
                plan.cruise_hz()
            ));
            return verdict;
        }
        if worst > 0.10 {
            verdict.failure = Some(format!(
                "late: step {} came {:.0} % of its interval after its scheduled time",
                worst_k as u64,
                worst * 100.0
            ));
            return verdict;
        }
        let at = |k: u64| plan.time_at(k as f64 / plan.steps_per_mm);
        let edge = |k: u64| rises[(k - 1) as usize].cycle as f64 / hz;
        for (name, planned, measured) in [
            ("acceleration", at(first) - at(1), edge(first) - edge(1)),
            (
                "deceleration",
                at(steps) - at(last),
                edge(steps) - edge(last),
            ),
        ] {
            if ((measured - planned) / planned).abs() > 0.10 {
                verdict.failure = Some(format!(
                    "departs: the {name} ramp took {measured:.5} s instead of {planned:.5} s"
                ));
                return verdict;
            }
        }
        return verdict;
    }
    let planned = plan.duration() - plan.time_at(1.0 / plan.steps_per_mm);
    let measured = (rises[rises.len() - 1].cycle - rises[0].cycle) as f64 / hz;
    if planned > 0.0 && ((measured - planned) / planned).abs() > 0.05 {
        verdict.failure = Some(format!(
            "departs: the move took {:.4} s instead of {:.4} s",
            measured, planned
        ));
    }
    verdict
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> MovePlan {
        MovePlan {
            steps: 4000,
            steps_per_mm: 100.0,
            feed_mm_s: 100.0,
            accel_mm_s2: 5000.0,
        }
    }

    /// Edges exactly on the plan (step k at position k/steps_per_mm).
    fn ideal(plan: &MovePlan, jitter: impl Fn(u64) -> f64) -> Vec<StepEdge> {
        (1..=plan.steps)
            .flat_map(|k| {
                let t = plan.time_at(k as f64 / plan.steps_per_mm) * f64::from(CPU_HZ)
                    + 1000.0
                    + jitter(k);
                let c = t.round() as u64;
                [
                    StepEdge {
                        cycle: c,
                        rising: true,
                        dir: true,
                        isr_cycles: 0,
                    },
                    StepEdge {
                        cycle: c + 16,
                        rising: false,
                        dir: true,
                        isr_cycles: 0,
                    },
                ]
            })
            .collect()
    }

    #[test]
    fn the_plan_is_a_trapezoid() {
        let p = plan();
        // 40 mm at 100 mm/s with 5000 mm/s²: 1 mm ramps of 20 ms, 38 mm cruise.
        assert!((p.duration() - (0.04 + 0.38)).abs() < 1e-9);
        let (first, last) = p.cruise_steps().unwrap();
        assert!(
            (176..=177).contains(&first) && last == 3825,
            "{first} {last}"
        );
    }

    #[test]
    fn an_ideal_stream_is_on_time() {
        let p = plan();
        let v = judge(&p, &ideal(&p, |_| 0.0));
        assert_eq!(v.failure, None, "{v:?}");
        assert!((v.cruise_hz - 10_000.0).abs() < 1.0);
    }

    #[test]
    fn small_jitter_passes_and_a_late_edge_fails() {
        let p = plan();
        // Interval at 10 kHz: 1600 cycles; 100 cycles of jitter is 6 %.
        let v = judge(&p, &ideal(&p, |k| if k % 7 == 0 { 100.0 } else { 0.0 }));
        assert_eq!(v.failure, None, "{v:?}");
        let v = judge(&p, &ideal(&p, |k| if k == 2000 { 200.0 } else { 0.0 }));
        assert!(
            v.failure.as_deref().unwrap().starts_with("late: step 2000"),
            "{v:?}"
        );
    }

    #[test]
    fn a_missing_step_or_slow_cruise_departs() {
        let p = plan();
        let mut edges = ideal(&p, |_| 0.0);
        edges.truncate(edges.len() - 2);
        assert!(judge(&p, &edges).failure.unwrap().contains("3999 steps"));
        let slow = MovePlan {
            feed_mm_s: 98.0,
            ..p
        };
        let v = judge(&p, &ideal(&slow, |_| 0.0));
        assert!(v.failure.unwrap().contains("cruise at 9800"));
    }

    #[test]
    fn a_stream_without_ramps_departs() {
        let p = plan();
        let flat = MovePlan {
            accel_mm_s2: 1e9,
            ..p
        };
        let v = judge(&p, &ideal(&flat, |_| 0.0));
        assert!(
            v.failure.as_deref().unwrap().contains("acceleration ramp"),
            "{v:?}"
        );
    }
}
