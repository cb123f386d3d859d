//! Feed drives (DESIGN.md §4). A linear motor pushes the moving body directly at its drive point; a
//! ball-screw drive has a motor (rotor inertia, force limit) turning a screw (lead, axial stiffness and
//! damping, backlash as a dead zone, lead error) whose nut pushes the body at its real offset from the
//! centre of mass. Everything is written in the screw's linear coordinate: motor position u = θ·lead/2π,
//! equivalent rotor mass m_r = J·(2π/lead)².

use serde::{Deserialize, Serialize};

/// Where the position loop takes its feedback.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FeedbackKind {
    /// Rotary encoder on the motor (semi-closed loop): screw errors and backlash reach the table.
    Rotary,
    /// Linear scale on the axis (closed loop): the scale's own errors reach the table.
    Linear,
}

/// A ball-screw drive.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BallScrewConfig {
    /// Screw lead, m per revolution.
    pub lead: f64,
    /// Motor rotor + screw + coupling inertia, kg·m².
    pub rotor_inertia: f64,
    /// Axial stiffness of screw, nut and bearings, N/m.
    pub stiffness: f64,
    /// Damping ratio of the axial mode (c = 2ζ·√(k·m_body)).
    pub damping_ratio: f64,
    /// Where the position loop takes its feedback (motor encoder or linear scale).
    pub feedback: FeedbackKind,
}

impl Default for BallScrewConfig {
    fn default() -> Self {
        BallScrewConfig {
            lead: 0.016,
            rotor_inertia: 0.002,
            stiffness: 2e8,
            damping_ratio: 0.1,
            feedback: FeedbackKind::Linear,
        }
    }
}

impl BallScrewConfig {
    /// Equivalent rotor mass in the screw's linear coordinate, m_r = J·(2π/lead)², kg.
    pub fn rotor_mass(&self) -> f64 {
        self.rotor_inertia * (std::f64::consts::TAU / self.lead).powi(2)
    }
}

/// Drive of an axis.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum DriveConfig {
    /// Direct drive: the servo force acts on the body at the drive point; feedback from a linear scale.
    #[default]
    LinearMotor,
    /// Ball-screw drive: motor, screw and nut with axial stiffness ([`BallScrewConfig`]).
    BallScrew(BallScrewConfig),
}

/// Force of a contact with clearance (backlash b, m) and stiffness k: the dead zone
/// F = k·(δ − b/2) for δ > b/2, k·(δ + b/2) for δ < −b/2, else 0; damping c·δ̇ acts only in contact.
pub fn dead_zone_force(delta: f64, delta_rate: f64, backlash: f64, k: f64, c: f64) -> f64 {
    let h = 0.5 * backlash;
    if delta > h {
        k * (delta - h) + c * delta_rate
    } else if delta < -h {
        k * (delta + h) + c * delta_rate
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dead_zone_is_silent_inside_the_clearance_and_linear_outside() {
        assert_eq!(dead_zone_force(1e-6, 1.0, 4e-6, 1e8, 10.0), 0.0);
        assert!((dead_zone_force(3e-6, 0.0, 4e-6, 1e8, 10.0) - 100.0).abs() < 1e-9);
        assert!((dead_zone_force(-3e-6, 0.0, 4e-6, 1e8, 10.0) + 100.0).abs() < 1e-9);
    }

    #[test]
    fn rotor_mass_of_a_16_mm_screw() {
        // 0.002 kg·m² · (2π/0.016)² = 0.002 · 154 212.6 = 308.4 kg
        assert!((BallScrewConfig::default().rotor_mass() - 308.425).abs() < 0.01);
    }
}
