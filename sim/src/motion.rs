//! Commanded motion: a CNC-style plan of moves (trapezoidal velocity, limited acceleration) and dwells.

/// One segment of a motion plan, starting at `t0` (s).
#[derive(Clone, Debug, PartialEq)]
pub enum Segment {
    /// Hold position `x` (m) for `duration` (s).
    Dwell {
        /// Start time, s.
        t0: f64,
        /// Held position, m.
        x: f64,
        /// Length of the hold, s.
        duration: f64,
    },
    /// Move from `x0` to `x1` (m) with peak feed `feed` (m/s) and acceleration `accel` (m/s²):
    /// trapezoidal velocity profile (triangular if the move is too short to reach the feed).
    Move {
        /// Start time, s.
        t0: f64,
        /// Start position, m.
        x0: f64,
        /// End position, m.
        x1: f64,
        /// Peak feed (speed), m/s.
        feed: f64,
        /// Acceleration and deceleration, m/s².
        accel: f64,
    },
}

/// Commanded position, velocity and acceleration at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Command {
    /// Position, m.
    pub pos: f64,
    /// Velocity, m/s.
    pub vel: f64,
    /// Acceleration, m/s².
    pub acc: f64,
}

impl Segment {
    /// Start time, s.
    pub fn t0(&self) -> f64 {
        match *self {
            Segment::Dwell { t0, .. } | Segment::Move { t0, .. } => t0,
        }
    }

    /// Duration, s.
    pub fn duration(&self) -> f64 {
        match *self {
            Segment::Dwell { duration, .. } => duration,
            Segment::Move { x0, x1, feed, accel, .. } => {
                let d = (x1 - x0).abs();
                let (ta, vp) = ramp(d, feed, accel);
                2.0 * ta + (d - vp * ta) / vp.max(f64::MIN_POSITIVE)
            }
        }
    }

    /// Command at time t (s) within the segment (clamped to its ends).
    pub fn at(&self, t: f64) -> Command {
        match *self {
            Segment::Dwell { x, .. } => Command { pos: x, vel: 0.0, acc: 0.0 },
            Segment::Move { t0, x0, x1, feed, accel } => {
                let d = (x1 - x0).abs();
                let s = (x1 - x0).signum();
                let (ta, vp) = ramp(d, feed, accel);
                let total = self.duration();
                let tau = (t - t0).max(0.0).min(total); // no clamp: a NaN bound must not panic
                if tau >= total {
                    return Command { pos: x1, vel: 0.0, acc: 0.0 };
                }
                let (p, v, a) = if tau < ta {
                    (0.5 * accel * tau * tau, accel * tau, accel)
                } else if tau <= total - ta {
                    (0.5 * vp * ta + vp * (tau - ta), vp, 0.0)
                } else {
                    let r = total - tau;
                    (d - 0.5 * accel * r * r, accel * r, -accel)
                };
                Command { pos: x0 + s * p, vel: s * v, acc: s * a }
            }
        }
    }
}

/// Ramp time and peak velocity of a trapezoidal move of length d: (t_a, v_peak).
fn ramp(d: f64, feed: f64, accel: f64) -> (f64, f64) {
    let vp = feed.min((d * accel).sqrt());
    (vp / accel, vp)
}

/// A sequence of segments, back to back in time.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MotionPlan {
    /// The segments in time order; each starts where the previous one ends.
    pub segments: Vec<Segment>,
}

impl MotionPlan {
    /// A plan that starts at rest at `x`, at t = 0.
    pub fn starting_at(x: f64) -> MotionPlan {
        MotionPlan { segments: vec![Segment::Dwell { t0: 0.0, x, duration: 0.0 }] }
    }

    /// End of the last segment, s.
    pub fn end_time(&self) -> f64 {
        self.segments.last().map_or(0.0, |s| s.t0() + s.duration())
    }

    /// Commanded position at the end of the plan, m (0 for an empty plan).
    pub fn end_pos(&self) -> f64 {
        self.segments.last().map_or(0.0, |s| s.at(f64::INFINITY).pos)
    }

    /// Appends a dwell at the current position; returns (start, end) time.
    pub fn dwell(&mut self, duration: f64) -> (f64, f64) {
        let t0 = self.end_time();
        self.segments.push(Segment::Dwell { t0, x: self.end_pos(), duration });
        (t0, t0 + duration)
    }

    /// Appends a move to x1; returns (start, end) time.
    pub fn move_to(&mut self, x1: f64, feed: f64, accel: f64) -> (f64, f64) {
        let t0 = self.end_time();
        let s = Segment::Move { t0, x0: self.end_pos(), x1, feed, accel };
        let t1 = t0 + s.duration();
        self.segments.push(s);
        (t0, t1)
    }

    /// Command at time t.
    pub fn at(&self, t: f64) -> Command {
        let i = self.segments.partition_point(|s| s.t0() <= t).max(1) - 1;
        match self.segments.get(i) {
            Some(s) => s.at(t),
            None => Command::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trapezoidal_move_reaches_its_end_with_the_right_duration() {
        // 1 m at 0.5 m/s, 2 m/s²: ramps 0.25 s over 0.0625 m each, cruise 0.875 m in 1.75 s: 2.25 s.
        let mut p = MotionPlan::starting_at(0.0);
        let (_, t1) = p.move_to(1.0, 0.5, 2.0);
        assert!((t1 - 2.25).abs() < 1e-12);
        assert!((p.at(t1).pos - 1.0).abs() < 1e-12);
        let mid = p.at(1.0);
        assert!((mid.vel - 0.5).abs() < 1e-12 && mid.acc == 0.0);
        assert!((mid.pos - (0.0625 + 0.5 * 0.75)).abs() < 1e-12);
    }

    #[test]
    fn backwards_moves_and_dwells_chain() {
        let mut p = MotionPlan::starting_at(0.5);
        p.move_to(0.1, 0.2, 1.0);
        let (a, b) = p.dwell(1.0);
        assert_eq!(p.at(0.5 * (a + b)).pos, 0.1);
        assert!(p.at(0.3).vel < 0.0);
    }
}
