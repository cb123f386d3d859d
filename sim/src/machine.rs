//! The immutable model of one simulated linear axis: the moving body's mass properties, its guideway
//! bearings, drive point and servo, built from a machine structure (URDF) and a machine section.
//! Like MuJoCo's mjModel: built once, never changed by a run; the run's state lives in `axis_sim`.

use crate::drive::DriveConfig;
use crate::geometry::{ErrorMotions, MotionsAt};
use crate::servo::ServoConfig;
use crate::urdf::{Frame, MachineStructure};
use rapier3d_f64::glamx::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// Guideway bearings of a prismatic joint (DESIGN.md §4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GuidewayConfig {
    /// Links of the moving body that are bearing blocks; empty: every link whose name starts with "block".
    pub blocks: Vec<String>,
    /// Stiffness of each block across the axis (axis-frame y), N/m.
    pub stiffness_y: f64,
    /// Stiffness of each block normal to the guideway (axis-frame z), N/m.
    pub stiffness_z: f64,
    /// Damping ratio of the guideway modes (sets each block's damping c = 2ζ·√(k·m/n_blocks)).
    pub damping_ratio: f64,
}

impl Default for GuidewayConfig {
    fn default() -> Self {
        GuidewayConfig { blocks: Vec::new(), stiffness_y: 1e9, stiffness_z: 1e9, damping_ratio: 0.05 }
    }
}

/// The machine section of a scenario: what URDF cannot say about one axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AxisConfig {
    /// Prismatic joint name in the URDF.
    pub joint: String,
    /// Link where the drive (ball-screw nut) acts; empty: the link named "nut", else the body frame origin.
    pub nut_link: String,
    pub guideway: GuidewayConfig,
    pub servo: ServoConfig,
    pub drive: DriveConfig,
    /// Maximum feed (m/s) and acceleration (m/s²) of the axis.
    pub max_feed: f64,
    pub max_accel: f64,
    /// Physics time step, s.
    pub dt: f64,
    /// Integrator of the moving body: set from the scenario's top-level `fidelity` key.
    #[serde(skip)]
    pub fidelity: Fidelity,
}

impl Default for AxisConfig {
    fn default() -> Self {
        AxisConfig {
            joint: "x".into(),
            nut_link: String::new(),
            guideway: GuidewayConfig::default(),
            servo: ServoConfig::default(),
            drive: DriveConfig::default(),
            max_feed: 0.5,
            max_accel: 2.0,
            dt: 1e-4,
            fidelity: Fidelity::default(),
        }
    }
}

/// Which integrator advances the moving body (DESIGN.md §4 "multi-fidelity"; scenario key `fidelity`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Fidelity {
    /// rapier3d-f64: the reference engine (the default until `tests/fidelity.rs` has been seen to
    /// pass on every bundled scenario; then the faster `Fast` becomes the default).
    #[default]
    Reference,
    /// vmt's own semi-implicit Euler of the same rigid body (the update rapier performs for a body
    /// with no collider, joint or contact), held to the reference by `tests/fidelity.rs`.
    Fast,
}

/// Why an axis model could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MachineError {
    #[error("machine has no prismatic joint `{0}` (prismatic joints: {1})")]
    NoJoint(String, String),
    #[error("axis `{0}`: {1}")]
    Invalid(String, String),
}

/// Immutable model of one axis. Frames: the axis frame has its origin at the axis reference point (the
/// moving body's frame origin at axis position 0), x along the motion; error motions are expressed in it.
#[derive(Clone, Debug)]
pub struct AxisModel {
    pub joint: String,
    /// Moving body: mass (kg), centre of mass and inertia in the body frame.
    pub mass: f64,
    pub com: DVec3,
    pub inertia: rapier3d_f64::glamx::DMat3,
    /// Body frame at axis position 0 in the machine (world) frame.
    pub home: Frame,
    /// Unit vector of motion in the world frame; the axis frame's rotation takes x onto it.
    pub axis: DVec3,
    pub axis_rotation: DQuat,
    /// Bearing blocks, body frame, m.
    pub blocks: Vec<DVec3>,
    pub k_y: f64,
    pub k_z: f64,
    pub c_y: f64,
    pub c_z: f64,
    /// Drive point, body frame, m.
    pub nut: DVec3,
    pub servo: ServoConfig,
    pub drive: DriveConfig,
    /// Viscous damping along the axis from URDF `<dynamics damping>`, N·s/m.
    pub axis_damping: f64,
    pub travel: (f64, f64),
    pub max_feed: f64,
    pub max_accel: f64,
    pub dt: f64,
    /// Integrator of the moving body.
    pub fidelity: Fidelity,
    /// Servo period in physics steps.
    pub servo_steps: usize,
    /// Links of the moving body (name, placement in the body frame), for sensor mounting.
    pub links: Vec<(String, Frame)>,
    /// The CNC's compensation table (seed 004): the controller adds c(x_fb) to its position feedback,
    /// so the table lands near command − c (zero: no compensation), m.
    pub compensation: crate::profile::Profile,
}

impl AxisModel {
    /// Builds the model of the axis `cfg.joint` of a machine structure.
    pub fn build(m: &MachineStructure, cfg: &AxisConfig) -> Result<AxisModel, MachineError> {
        AxisModel::build_inner(m, cfg, false)
    }

    /// Builds the model of the axis `cfg.joint` whose parent may be a moving body (a carriage of a
    /// stacked chain, see `chain`): the parent is treated as rigid ground, so every frame of the model
    /// (home, axis, gravity along −Z) is the parent body's frame at its nominal pose.
    pub fn build_on_parent(m: &MachineStructure, cfg: &AxisConfig) -> Result<AxisModel, MachineError> {
        AxisModel::build_inner(m, cfg, true)
    }

    fn build_inner(m: &MachineStructure, cfg: &AxisConfig, stacked: bool) -> Result<AxisModel, MachineError> {
        let ax = m.axis_by_joint(&cfg.joint).ok_or_else(|| {
            MachineError::NoJoint(
                cfg.joint.clone(),
                m.axes.iter().map(|a| a.joint.as_str()).collect::<Vec<_>>().join(", "),
            )
        })?;
        let bad = |what: String| MachineError::Invalid(cfg.joint.clone(), what);
        if !stacked && m.bodies[ax.parent].name != m.bodies[0].name {
            return Err(bad(
                "vmt simulates axes whose parent is the fixed base; stacked axes are not supported yet".into()
            ));
        }
        let body = &m.bodies[ax.child];
        let mp = &body.mass;
        if !(mp.mass > 0.0) || !crate::urdf::positive_definite(&mp.inertia) {
            return Err(bad(format!(
                "moving body `{}` has mass {} kg and a non-positive-definite inertia: a simulated moving body needs positive mass and inertia (add <inertial> to its links)",
                body.name, mp.mass
            )));
        }
        let blocks: Vec<DVec3> = body
            .links
            .iter()
            .filter(|(n, _)| {
                if cfg.guideway.blocks.is_empty() {
                    n.starts_with("block")
                } else {
                    cfg.guideway.blocks.contains(n)
                }
            })
            .map(|(_, f)| f.translation)
            .collect();
        if blocks.len() < 3 {
            return Err(bad(format!(
                "needs at least 3 bearing blocks not on one line (links named block* or listed in guideway.blocks); found {}",
                blocks.len()
            )));
        }
        for (name, v) in [("stiffness_y", cfg.guideway.stiffness_y), ("stiffness_z", cfg.guideway.stiffness_z)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(format!("guideway.{name} must be a positive stiffness in N/m, got {v}")));
            }
        }
        if !(cfg.guideway.damping_ratio >= 0.0 && cfg.guideway.damping_ratio < 1.0) {
            return Err(bad(format!("guideway.damping_ratio must be in [0, 1), got {}", cfg.guideway.damping_ratio)));
        }
        if !(cfg.dt > 0.0 && cfg.dt <= 1e-3) {
            return Err(bad(format!("dt must be in (0, 1e-3] s, got {}", cfg.dt)));
        }
        let nut = match (cfg.nut_link.as_str(), body.link_frame("nut")) {
            ("", Some(f)) => f.translation,
            ("", None) => DVec3::ZERO,
            (n, _) => {
                body.link_frame(n)
                    .ok_or_else(|| bad(format!("nut_link `{n}` is not a link of the moving body")))?
                    .translation
            }
        };
        if let DriveConfig::BallScrew(b) = &cfg.drive {
            for (k, v) in [("lead", b.lead), ("rotor_inertia", b.rotor_inertia), ("stiffness", b.stiffness)] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(bad(format!("drive.{k} must be positive, got {v}")));
                }
            }
            if !(b.damping_ratio >= 0.0 && b.damping_ratio < 1.0) {
                return Err(bad(format!("drive.damping_ratio must be in [0, 1), got {}", b.damping_ratio)));
            }
        }
        let mass = body.mass.mass;
        let n = blocks.len() as f64;
        let damping = |k: f64| 2.0 * cfg.guideway.damping_ratio * (k * mass / n).sqrt();
        let servo_steps = ((1.0 / cfg.servo.rate) / cfg.dt).round().max(1.0) as usize;
        Ok(AxisModel {
            joint: cfg.joint.clone(),
            mass,
            com: body.mass.com,
            inertia: body.mass.inertia,
            home: ax.origin,
            axis: ax.axis,
            axis_rotation: DQuat::from_rotation_arc(DVec3::X, ax.axis),
            blocks,
            k_y: cfg.guideway.stiffness_y,
            k_z: cfg.guideway.stiffness_z,
            c_y: damping(cfg.guideway.stiffness_y),
            c_z: damping(cfg.guideway.stiffness_z),
            nut,
            servo: cfg.servo.clone(),
            drive: cfg.drive.clone(),
            axis_damping: ax.damping,
            travel: (ax.lower, ax.upper),
            max_feed: if ax.velocity > 0.0 { cfg.max_feed.min(ax.velocity) } else { cfg.max_feed },
            max_accel: cfg.max_accel,
            dt: cfg.dt,
            fidelity: cfg.fidelity,
            servo_steps,
            links: body.links.clone(),
            compensation: crate::profile::Profile::zero(),
        })
    }

    /// Placement of a link of the moving body in the body frame.
    pub fn link(&self, name: &str) -> Option<Frame> {
        self.links.iter().find(|(n, _)| n == name).map(|(_, f)| *f)
    }

    /// A body-frame point expressed in the axis frame (from the reference point).
    pub fn body_to_axis(&self, p: DVec3) -> DVec3 {
        self.axis_rotation.inverse() * (self.home.rotation * p)
    }

    /// Rest pose of the body frame at axis position x with the error motions applied (first order):
    /// translation home + axis·x + R_a·E(x), rotation (R_a·ε(x)) ∘ home rotation.
    pub fn rest_pose(&self, errors: &ErrorMotions, x: f64) -> Frame {
        self.rest_pose_at(&errors.at(x), x)
    }

    /// As [`AxisModel::rest_pose`], from error motions already evaluated at x.
    pub fn rest_pose_at(&self, at: &MotionsAt, x: f64) -> Frame {
        let e = self.axis_rotation * at.translation;
        let eps = self.axis_rotation * at.rotation;
        Frame {
            translation: self.home.translation + self.axis * x + e,
            rotation: DQuat::from_scaled_axis(eps) * self.home.rotation,
        }
    }
}
