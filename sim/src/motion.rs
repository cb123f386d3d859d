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

/// Ticks per metre of the grid on which every recorded commanded position lies: 1 pm, the resolution
/// at which the recorder logs the CNC's command (as a controller logs its command in whole increments).
/// The servo follows the plan's exact command (the machine's physics does not depend on the grid); the
/// recorded `x_cmd` is within 0.5 pm of it and a short exact decimal (`0.101875`, not the plan's
/// `0.10187500000000001`).
pub const POSITION_GRID_PER_M: f64 = 1e12;

/// A position (m) on the 1 pm grid: x' = round(x·g)/g with g = [`POSITION_GRID_PER_M`]. For |x| below
/// 9000 m, round(x·g) is an exact integer k and the quotient the double nearest to the decimal k·10⁻¹²
/// (both operands exact, the division correctly rounded), so x' is written as that decimal, with at most
/// 15 significant digits below 1000 m. |x' − x| ≤ 0.5 pm. NaN and ±∞ pass through.
pub fn on_position_grid(x: f64) -> f64 {
    (x * POSITION_GRID_PER_M).round() / POSITION_GRID_PER_M
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

    /// The command at time t as the recorder logs it: [`MotionPlan::at`] with the position on the 1 pm
    /// grid ([`on_position_grid`]); velocity and acceleration as planned.
    pub fn recorded_at(&self, t: f64) -> Command {
        let c = self.at(t);
        Command { pos: on_position_grid(c.pos), ..c }
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

    /// Significant digits of a number as Rust writes it (shortest round-trip decimal).
    fn significant_digits(x: f64) -> usize {
        let text = format!("{:e}", x.abs());
        text.split('e').next().unwrap_or("").chars().filter(char::is_ascii_digit).count()
    }

    /// Issue 13: a recorded commanded position is a short exact decimal. A slow pass (0.1 → 0.9 m at
    /// 15 mm/s, 0.5 m/s²) sampled at 1 kHz: the plan's exact values carry a double's digits (17
    /// significant digits, as 0.10187500000000001) in many samples; the recorded commands carry at most
    /// 13 significant digits, each within 0.5 pm of the exact value and a whole number of picometres.
    #[test]
    fn commanded_positions_lie_on_the_picometre_grid_and_are_written_short() {
        let mut p = MotionPlan::starting_at(0.1);
        let (t0, t1) = p.move_to(0.9, 0.015, 0.5);
        let (mut noisy_exact, mut n) = (0, 0);
        let mut t = t0;
        while t < t1 {
            let (exact, cmd) = (p.at(t).pos, p.recorded_at(t).pos);
            noisy_exact += usize::from(significant_digits(exact) > 15);
            assert!(significant_digits(cmd) <= 13, "t = {t} s: x_cmd = {cmd}");
            assert!((cmd - exact).abs() <= 0.5e-12 + 1e-16, "t = {t} s: {cmd} for {exact}");
            assert_eq!((cmd * 1e12).round() / 1e12, cmd);
            n += 1;
            t = crate::procedures::recorder_time(t + 1e-3);
        }
        assert!(n > 50_000 && noisy_exact > n / 10, "{noisy_exact} of {n} exact values carry float noise");
        assert_eq!(on_position_grid(0.10187500000000001).to_string(), "0.101875");
        assert!(on_position_grid(f64::NAN).is_nan() && on_position_grid(f64::INFINITY) == f64::INFINITY);
    }
}
