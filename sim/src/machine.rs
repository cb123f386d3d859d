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
    /// Guideway bearings: stiffness, damping, error motions, friction.
    pub guideway: GuidewayConfig,
    /// Position and velocity loop of the axis.
    pub servo: ServoConfig,
    /// Drive: linear motor or ball screw.
    pub drive: DriveConfig,
    /// Maximum feed (m/s) and acceleration (m/s²) of the axis.
    pub max_feed: f64,
    /// Maximum acceleration of the axis, m/s².
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
    /// rapier3d-f64: the reference engine, against which `tests/fidelity.rs` holds [`Fidelity::Fast`]
    /// on every bundled scenario.
    Reference,
    /// vmt's own semi-implicit Euler of the same rigid body (the update rapier performs for a body
    /// with no collider, joint or contact), held to the reference by `tests/fidelity.rs`. The default
    /// (issue 15: the faster engine once that test holds; `vmt run` on the default scenario 1.5 s CPU
    /// against 5.6 s with the reference).
    #[default]
    Fast,
}

/// Smallest physics step accepted, s: below it a second of motion costs over 10⁷ steps (the size
/// budget of one run, see `procedures::MAX_STEPS`).
pub const MIN_DT: f64 = 1e-7;

/// Largest ω·dt accepted for the explicitly integrated stiff modes (guideway bearings, ball screw).
/// Semi-implicit Euler on x'' = −ω²x is stable for ω·dt < 2 undamped (less with the explicit damping
/// force c = 2ζ√(km)); 1 keeps a factor 2 margin and a phase error of the mode below ~5 %.
pub const MAX_OMEGA_DT: f64 = 1.0;

/// Largest deflection of the guideway bearings under a load equal to the moving body's weight, m. Real
/// linear guides deflect a few µm; a stiffness that lets the body sag by more than this is a unit
/// mistake (N/µm written as N/m) and made the simulated slide hang metres below its rails (issue 14).
pub const MAX_BEARING_SAG: f64 = 1e-3;

/// The checks of an axis's numbers that need its moving mass (issue 14: each combination below wrote
/// metres of "positioning error" on a 1 m axis, exit 0): the drive must be able to accelerate the mass
/// at `max_accel`; the velocity loop must be faster than the position loop (the cascade's damping
/// ζ = ½·√(2π·f_v/k_p) ≥ ½); the bearings must carry the weight within [`MAX_BEARING_SAG`]. Returns the
/// key (`servo.force_limit`, …) and the message.
fn check_physical_ranges(cfg: &AxisConfig, mass: f64, blocks: f64) -> Result<(), (String, String)> {
    let needed = mass * cfg.max_accel;
    if cfg.servo.force_limit < needed {
        return Err((
            "servo.force_limit".into(),
            format!(
                "{} N cannot accelerate the moving mass {} kg at max_accel = {} m/s²: expected force_limit ≥ \
                 mass·max_accel = {} N (or a lower max_accel)",
                crate::effects::fmt_num(cfg.servo.force_limit),
                crate::effects::fmt_num(mass),
                crate::effects::fmt_num(cfg.max_accel),
                crate::effects::fmt_num(needed)
            ),
        ));
    }
    let f_min = cfg.servo.kp / std::f64::consts::TAU;
    if cfg.servo.velocity_bandwidth < f_min {
        return Err((
            "servo.velocity_bandwidth".into(),
            format!(
                "{} Hz is slower than the position loop (kp = {} 1/s): the cascade would ring (damping \
                 ½·√(2π·f_v/kp) < ½); expected velocity_bandwidth ≥ kp/(2π) = {} Hz",
                crate::effects::fmt_num(cfg.servo.velocity_bandwidth),
                crate::effects::fmt_num(cfg.servo.kp),
                crate::effects::fmt_num(f_min)
            ),
        ));
    }
    let weight = mass * crate::axis_sim::GRAVITY;
    for (k, stiffness) in [("stiffness_y", cfg.guideway.stiffness_y), ("stiffness_z", cfg.guideway.stiffness_z)] {
        let sag = weight / (blocks * stiffness);
        if sag > MAX_BEARING_SAG {
            return Err((
                format!("guideway.{k}"),
                format!(
                    "{} N/m per block lets the {} blocks deflect {} m under the moving weight ({} kg): expected \
                     a deflection ≤ {MAX_BEARING_SAG} m, i.e. {k} ≥ {} N/m (linear guides are 1e8–1e10 N/m)",
                    crate::effects::fmt_num(stiffness),
                    blocks,
                    crate::effects::fmt_num(sag),
                    crate::effects::fmt_num(mass),
                    crate::effects::fmt_num(weight / (blocks * MAX_BEARING_SAG))
                ),
            ));
        }
    }
    Ok(())
}

/// The axis frame's y and z (the guideway's stiff directions, world frame `R_a·y`, `R_a·z` with R_a
/// taking x onto the world-frame `axis`) expressed in the moving body's frame (rotation `home`).
fn body_axis_directions(axis: DVec3, home: DQuat) -> (DVec3, DVec3) {
    let r = DQuat::from_rotation_arc(DVec3::X, axis);
    (home.inverse() * (r * DVec3::Y), home.inverse() * (r * DVec3::Z))
}

/// Angular frequency of the stiffest rigid-body mode of a body of mass `m` (kg), centre of mass `com`
/// and inertia `inertia` (kg·m², about the centre of mass, body frame) on springs at `blocks` (body
/// frame, m), each with stiffness k (N/m) along each direction d of `dirs`: ω_max = √λ_max(M⁻¹K),
/// K = Σ k·J·Jᵀ with J = [d; (b − com) × d], M = diag(m, m, m, I). λ_max by power iteration on the
/// 6×6 matrix M⁻¹K (its eigenvalues are those of the symmetric M^-½KM^-½, real and ≥ 0), rad/s.
pub fn stiffest_mode(
    m: f64,
    com: DVec3,
    inertia: &rapier3d_f64::glamx::DMat3,
    blocks: &[DVec3],
    dirs: &[(DVec3, f64)],
) -> f64 {
    let mut k = [[0.0f64; 6]; 6];
    for b in blocks {
        for (d, kd) in dirs {
            let r = (*b - com).cross(*d);
            let j = [d.x, d.y, d.z, r.x, r.y, r.z];
            for (a, row) in k.iter_mut().enumerate() {
                for (c, v) in row.iter_mut().enumerate() {
                    *v += kd * j[a] * j[c];
                }
            }
        }
    }
    let inv_i = inertia.inverse();
    let apply = |x: &[f64; 6]| -> [f64; 6] {
        let mut kx = [0.0; 6];
        for (a, row) in k.iter().enumerate() {
            kx[a] = row.iter().zip(x).map(|(p, q)| p * q).sum();
        }
        let w = inv_i * DVec3::new(kx[3], kx[4], kx[5]);
        [kx[0] / m, kx[1] / m, kx[2] / m, w.x, w.y, w.z]
    };
    let mut x = [1.0, 0.9, 0.8, 0.7, 0.6, 0.5];
    let mut lambda = 0.0;
    for _ in 0..500 {
        let y = apply(&x);
        let n = y.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(n > 0.0 && n.is_finite()) {
            return if n == 0.0 { 0.0 } else { f64::INFINITY };
        }
        lambda = n / x.iter().map(|v| v * v).sum::<f64>().sqrt();
        x = y.map(|v| v / n);
    }
    lambda.sqrt()
}

/// Why an axis model could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MachineError {
    /// No prismatic joint of this name: (joint asked for, the machine's prismatic joints).
    #[error("machine has no prismatic joint `{0}` (prismatic joints: {1})")]
    NoJoint(String, String),
    /// An axis that cannot be modelled: (joint, what is wrong).
    #[error("axis `{0}`: {1}")]
    Invalid(String, String),
    /// A key of the machine section out of range: (joint, key path within the section, message).
    #[error("axis `{0}`: {1}: {2}")]
    Key(String, String, String),
}

/// Immutable model of one axis. Frames: the axis frame has its origin at the axis reference point (the
/// moving body's frame origin at axis position 0), x along the motion; error motions are expressed in it.
#[derive(Clone, Debug)]
pub struct AxisModel {
    /// Prismatic joint name in the URDF.
    pub joint: String,
    /// Moving body: mass (kg), centre of mass and inertia in the body frame.
    pub mass: f64,
    /// Centre of mass in the body frame, m.
    pub com: DVec3,
    /// Inertia tensor about the centre of mass in the body frame, kg·m².
    pub inertia: rapier3d_f64::glamx::DMat3,
    /// Body frame at axis position 0 in the machine (world) frame.
    pub home: Frame,
    /// Unit vector of motion in the world frame; the axis frame's rotation takes x onto it.
    pub axis: DVec3,
    /// Rotation of the axis frame in the world frame: takes x onto `axis`.
    pub axis_rotation: DQuat,
    /// Bearing blocks, body frame, m.
    pub blocks: Vec<DVec3>,
    /// Lateral (y, axis frame) stiffness of each bearing block, N/m.
    pub k_y: f64,
    /// Vertical (z, axis frame) stiffness of each bearing block, N/m.
    pub k_z: f64,
    /// Lateral damping of each bearing block, N·s/m (from the guideway's damping ratio).
    pub c_y: f64,
    /// Vertical damping of each bearing block, N·s/m (from the guideway's damping ratio).
    pub c_z: f64,
    /// Drive point, body frame, m.
    pub nut: DVec3,
    /// Position and velocity loop of the axis.
    pub servo: ServoConfig,
    /// Drive: linear motor or ball screw.
    pub drive: DriveConfig,
    /// Viscous damping along the axis from URDF `<dynamics damping>`, N·s/m.
    pub axis_damping: f64,
    /// Travel (lower, upper) from the URDF joint limits, m.
    pub travel: (f64, f64),
    /// Maximum feed, m/s.
    pub max_feed: f64,
    /// Maximum acceleration, m/s².
    pub max_accel: f64,
    /// Physics time step, s.
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
        if mp.mass.is_nan() || mp.mass <= 0.0 || !crate::urdf::positive_definite(&mp.inertia) {
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
        let key = |(k, m): (String, String)| MachineError::Key(cfg.joint.clone(), k, m);
        if !(cfg.dt >= MIN_DT && cfg.dt <= 1e-3) {
            return Err(key(("dt".into(), format!("expected a physics step in [{MIN_DT:e}, 1e-3] s, got {}", cfg.dt))));
        }
        for (k, v, unit) in [("max_feed", cfg.max_feed, "m/s"), ("max_accel", cfg.max_accel, "m/s²")] {
            if !(v.is_finite() && v > 0.0) {
                return Err(key((k.into(), format!("expected a finite value > 0 {unit}, got {v}"))));
            }
        }
        cfg.servo.check(cfg.dt).map_err(key)?;
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
        // index: servo.rate > 0 and rate·dt ≤ 1 (ServoConfig::check above), so 1/rate/dt is finite and ≥ 1.
        let servo_steps = ((1.0 / cfg.servo.rate) / cfg.dt).round().max(1.0) as usize;
        cfg.servo.check_discrete(cfg.dt * servo_steps as f64).map_err(key)?;
        check_physical_ranges(cfg, mass, n).map_err(key)?;
        let (y, z) = body_axis_directions(ax.axis, ax.origin.rotation);
        let dirs = [(y, cfg.guideway.stiffness_y), (z, cfg.guideway.stiffness_z)];
        let omega_guide = stiffest_mode(mass, body.mass.com, &body.mass.inertia, &blocks, &dirs);
        let omega_drive = match &cfg.drive {
            DriveConfig::BallScrew(b) => (b.stiffness * (1.0 / mass + 1.0 / b.rotor_mass())).sqrt(),
            DriveConfig::LinearMotor => 0.0,
        };
        for (what, w) in [("guideway bearings", omega_guide), ("ball-screw axial stiffness", omega_drive)] {
            if (w * cfg.dt).is_nan() || w * cfg.dt > MAX_OMEGA_DT {
                return Err(key((
                    "dt".into(),
                    format!(
                        "the explicit integration is unstable: the stiffest mode of the {what} has ω = {w:.4e} rad/s \
                     (moving mass {mass} kg), ω·dt = {:.3} > {MAX_OMEGA_DT}; a stable step is dt ≤ {:.3e} s, \
                     or raise the mass / lower the stiffness",
                        w * cfg.dt,
                        MAX_OMEGA_DT / w
                    ),
                )));
            }
        }
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
        let e = self.axis_to_world(at.translation);
        let eps = self.axis_to_world(at.rotation);
        let turn = small_rotation(eps);
        Frame {
            translation: self.home.translation + self.axis * x + e,
            rotation: if self.home.rotation == DQuat::IDENTITY { turn } else { turn * self.home.rotation },
        }
    }

    /// An axis-frame vector in the world frame, R_a·v (v itself for an axis along the world's x, whose
    /// rotation is the identity: the same numbers without the product).
    #[inline]
    pub fn axis_to_world(&self, v: DVec3) -> DVec3 {
        if self.axis_rotation == DQuat::IDENTITY {
            v
        } else {
            self.axis_rotation * v
        }
    }
}

/// The rotation by the rotation vector e (rad) as a unit quaternion (sin(θ/2)·e/θ, cos(θ/2)), θ = |e|
/// (`DQuat::from_scaled_axis`). For the error motions' angles (θ² < 1e-6) from the series
/// sin(θ/2)/θ = ½ − θ²/48 + θ⁴/3840 and cos(θ/2) = 1 − θ²/8 + θ⁴/384, whose next terms (θ⁶/645 120
/// and θ⁶/46 080, below 3e-23) are far under the 1.1e-16 rounding of the components: the same rotation
/// to rounding without the square root, division and sine of the exact form, which larger angles take.
fn small_rotation(e: DVec3) -> DQuat {
    let t2 = e.length_squared();
    if t2 >= 1e-6 {
        return DQuat::from_scaled_axis(e);
    }
    let s = 0.5 - t2 * (1.0 / 48.0 - t2 * (1.0 / 3840.0));
    let c = 1.0 - t2 * (0.125 - t2 * (1.0 / 384.0));
    DQuat::from_xyzw(e.x * s, e.y * s, e.z * s, c)
}
