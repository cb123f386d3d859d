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

/// Mutable state of the servo loops.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ServoState {
    pub integral: f64,
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
    let force = unclipped.clamp(-cfg.force_limit, cfg.force_limit);
    if force == unclipped {
        st.integral += e_v * ts;
    }
    st.force = force;
    force
}
