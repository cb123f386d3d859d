//! Cascade position/velocity servo of a CNC feed axis, discrete at the servo rate (DESIGN.md §4):
//! position P loop → velocity PI loop → ideal current (force) loop with a force limit, optional
//! velocity and acceleration feed-forward.

use serde::{Deserialize, Serialize};

/// Servo gains and limits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServoConfig {
    /// Position-loop gain K_p, 1/s (the CNC "kv factor"; 1 m/min/mm = 16.7 1/s).
    pub kp: f64,
    /// Velocity-loop bandwidth, Hz: proportional gain K_v = m·2π·f_v (N·s/m) with m the moving mass.
    pub velocity_bandwidth: f64,
    /// Velocity-loop integral corner, Hz: F = K_v·(e_v + 2π·f_i·∫e_v dt).
    pub integral_corner: f64,
    /// Force limit of the motor, N.
    pub force_limit: f64,
    /// Servo rate, Hz (rounded to a whole number of physics steps).
    pub rate: f64,
    /// Velocity feed-forward (commanded velocity added to the velocity reference).
    pub velocity_feed_forward: bool,
    /// Acceleration feed-forward (m·commanded acceleration added to the force).
    pub acceleration_feed_forward: bool,
    /// Feedback resolution (quantisation of the position feedback), m.
    pub resolution: f64,
}

impl Default for ServoConfig {
    fn default() -> Self {
        ServoConfig {
            kp: 50.0,
            velocity_bandwidth: 40.0,
            integral_corner: 8.0,
            force_limit: 20_000.0,
            rate: 5000.0,
            velocity_feed_forward: true,
            acceleration_feed_forward: true,
            resolution: 1e-9,
        }
    }
}

impl ServoConfig {
    /// Range checks of the servo keys for a physics step `dt` (s): kp, velocity_bandwidth,
    /// force_limit and rate finite and > 0, integral_corner finite and ≥ 0, resolution in [0, 1 mm],
    /// and rate ≤ 1/dt (the servo cannot update more often than the physics steps). Returns the
    /// message naming the `servo.KEY` at fault.
    pub fn check(&self, dt: f64) -> Result<(), (String, String)> {
        for (k, v, unit) in [
            ("kp", self.kp, "1/s"),
            ("velocity_bandwidth", self.velocity_bandwidth, "Hz"),
            ("force_limit", self.force_limit, "N"),
            ("rate", self.rate, "Hz"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((format!("servo.{k}"), format!("expected a finite value > 0 {unit}, got {v}")));
            }
        }
        if !(self.integral_corner.is_finite() && self.integral_corner >= 0.0) {
            return Err((
                "servo.integral_corner".into(),
                format!("expected a finite value ≥ 0 Hz, got {}", self.integral_corner),
            ));
        }
        if !(self.resolution.is_finite() && (0.0..=1e-3).contains(&self.resolution)) {
            return Err((
                "servo.resolution".into(),
                format!("expected a feedback step in [0, 1e-3] m, got {}", self.resolution),
            ));
        }
        if self.rate * dt > 1.0 + 1e-9 {
            return Err((
                "servo.rate".into(),
                format!(
                    "{} Hz is faster than the physics step dt = {dt} s allows: expected rate ≤ 1/dt = {} Hz",
                    self.rate,
                    1.0 / dt
                ),
            ));
        }
        Ok(())
    }

    /// Discrete stability of the loops at the servo period `ts` (s). The velocity loop on a mass with
    /// the velocity taken as a backward difference and the force held over the period is
    /// v_{k+1} = v_k + K·(r − (v_k + v_{k−1})/2), K = 2π·f_v·ts: characteristic z² + (K/2 − 1)·z + K/2,
    /// stable for 0 < K < 2 (Jury). The position and integral loops add lag, so each of K, kp·ts and
    /// 2π·f_i·ts must stay ≤ 1 (a gain margin of 2 on the velocity loop). Returns the message naming
    /// the key and the limit.
    pub fn check_discrete(&self, ts: f64) -> Result<(), (String, String)> {
        let tau = std::f64::consts::TAU;
        for (k, g, scale) in [
            ("velocity_bandwidth", self.velocity_bandwidth, tau * ts),
            ("integral_corner", self.integral_corner, tau * ts),
            ("kp", self.kp, ts),
        ] {
            if g * scale > 1.0 {
                return Err((
                    format!("servo.{k}"),
                    format!(
                        "{g} makes the discrete servo loop unstable at the servo period {ts:e} s (rate {} Hz): \
                         expected {k} ≤ {} (gain·period ≤ 1), or a higher servo.rate",
                        1.0 / ts,
                        crate::effects::fmt_num(1.0 / scale)
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Mutable state of the servo loops.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ServoState {
    /// Integral of the velocity error ∫e_v dt, m (the velocity loop's I term).
    pub integral: f64,
    /// Velocity feedback of the last servo update, m (`None` before the first; differenced for velocity).
    pub last_feedback: Option<f64>,
    /// Force being applied (held between servo updates), N.
    pub force: f64,
}

/// Quantises a feedback reading to the resolution q: q·round(x/q).
pub fn quantise(x: f64, q: f64) -> f64 {
    if q > 0.0 {
        (x / q).round() * q
    } else {
        x
    }
}

/// One servo update, period `ts` (s). `feedback` is the quantised position feedback (m) of the position
/// loop, `velocity_feedback` the quantised position whose difference the velocity loop uses (the motor
/// encoder of a ball-screw drive, or the same scale); `mass` the moving mass (kg). Returns the force command (N), limited to ±force_limit; the integrator stops
/// while the force saturates (anti-windup).
#[allow(clippy::too_many_arguments)]
pub fn servo_update(
    cfg: &ServoConfig,
    st: &mut ServoState,
    mass: f64,
    ts: f64,
    cmd_pos: f64,
    cmd_vel: f64,
    cmd_acc: f64,
    feedback: f64,
    velocity_feedback: f64,
) -> f64 {
    let v_fb = st.last_feedback.map_or(cmd_vel, |p| (velocity_feedback - p) / ts);
    st.last_feedback = Some(velocity_feedback);
    let v_ref = cfg.kp * (cmd_pos - feedback) + if cfg.velocity_feed_forward { cmd_vel } else { 0.0 };
    let e_v = v_ref - v_fb;
    let kv = mass * std::f64::consts::TAU * cfg.velocity_bandwidth;
    let ki = std::f64::consts::TAU * cfg.integral_corner;
    let ff = if cfg.acceleration_feed_forward { mass * cmd_acc } else { 0.0 };
    let unclipped = kv * (e_v + ki * (st.integral + e_v * ts)) + ff;
    // clamp: force_limit finite and > 0 (ServoConfig::validate, run when the scenario is read).
    let force = unclipped.clamp(-cfg.force_limit, cfg.force_limit);
    if force == unclipped {
        st.integral += e_v * ts;
    }
    st.force = force;
    force
}
