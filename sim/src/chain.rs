//! A multi-axis machine as a serial chain of single-axis rapier models (DESIGN.md §3 `vmc_3axis`, §4
//! "multi-fidelity"): bed → axis 1 → axis 2 → … → tool, e.g. bed → X → Y → Z → tool for the 21-error
//! methods (3 × 6 error motions + 3 squareness, seed 001).
//!
//! # Model and its simplification
//!
//! Each prismatic joint j is simulated by its own [`AxisSim`](crate::axis_sim::AxisSim): its moving
//! body carries the **merged mass of its whole subtree** (its own body plus every body above it in
//! the chain), lumped **once** with the upper axes at their reference positions (the lower end of
//! their travel): a fixed mass, centre of mass and inertia. Its parent body is treated as **rigid
//! ground**: the model lives in the parent body's frame at its nominal pose, with gravity along −Z.
//! The axis carries the error motions and drive effects of `axis = j` of the truth
//! ([`axis_physics`]). There is **no dynamic coupling between the axes**: the reaction of the upper
//! carriages on the lower guideways (their inertial forces while they accelerate, the shift of
//! their weight as they move) is not modelled, so a lower carriage does not pitch when an upper one
//! moves. The quasi-static pose of each carriage is its injected error motion plus the constant sag
//! of its bearings under the fixed lumped weight.
//!
//! A URDF moving body with fewer than three `block*` links (vmc_3axis's Y and Z carriages) gets four
//! synthetic bearing blocks at ±[`SYNTHETIC_BLOCK_HALF_SPAN`] along the axis and across it, in the
//! plane of the axis reference point (axis-frame x–y plane).
//!
//! # Error motions and their directions
//!
//! Effects are named as in FORMAT.md §2 and `EffectName::iso230_symbol`: for axis J,
//! `straightness_y`/`straightness_z` are the deviations along the first/second transverse machine
//! direction (x, y, z order with J skipped) and `pitch`/`yaw` the rotations about them, so for Y:
//! EYY, EXY, EZY, EBY, EAY, ECY and for Z: EZZ, EXZ, EYZ, ECZ, EAZ, EBZ. The single-axis simulator
//! works in its own axis frame (x along the motion, the frame's rotation taking x onto the axis), so
//! the profiles are re-expressed in that frame (sign flips and swaps only) before simulation.
//!
//! # Composition (exact rigid transforms, not first order)
//!
//! With s_j the rapier sample of axis j (origin `pos_j`, rotation `R_j` relative to the home
//! orientation), home frame H_j = (h_j, Q_j) in the parent body, and S_j the squareness rotation of
//! axis j, the body frame of j in its parent is
//!
//! ```text
//!   T_j = ( h_j + S_j·(pos_j − h_j),  R_j·Q_j ),     P(r) = T_1 ∘ T_2 ∘ … ∘ T_n ∘ T_tool · r
//! ```
//!
//! i.e. squareness is a fixed rotation of the direction (and straightness frame) along which axis j
//! travels relative to its parent; it does not rotate the carriage's orientation (a constant
//! orientation offset is a constant angular error motion, which laser readings cannot tell from a
//! line zero). S_j = Π_{a before j} Rot(ĉ_aj, θ_aj), ĉ the third direction, so that the path of j
//! tilts by θ_aj·(ĉ × ê_j): for X → Y → Z, S_Y = Rz(EC0Y), S_Z = Rx(EA0Z)·Ry(EB0Z), giving to first
//! order δ_sq = (−EC0Y·q_y + EB0Z·q_z, −EA0Z·q_z, 0) — the convention of
//! `vmt_estimators::laser_ls` (EC0Y = `squareness_xy`, EB0Z = `squareness_xz`, EA0Z = `squareness_yz`).
//! The nominal point uses T_j⁰ = (h_j + ê_j·q_j, Q_j). Axes must appear in x, y, z order.
//!
//! # Motion
//!
//! A multi-axis move is a straight line in joint space: all axes start together and arrive together,
//! each axis's trapezoid scaled by |Δq_j|/|Δq| (feed and acceleration of the path given), so the
//! tool point follows the commanded line (DESIGN.md §6 diagonal measurements of seed 001).

use crate::axis_sim::{simulate_in_session, AxisTruth, Sample, Trace};
use crate::effects::{EffectName, EffectParams, EffectSet};
use crate::geometry::ErrorMotions;
use crate::machine::{AxisConfig, AxisModel, MachineError};
use crate::motion::{MotionPlan, Segment};
use crate::procedures::{recorder_time, ProcedureKind, RunData, RunRecord, Visit};
use crate::profile::{Profile, Term};
use crate::rng::source_rng;
use crate::truth::{axis_physics, Adjustments};
use crate::urdf::{Frame, MachineStructure};
use crate::Axis;
use rand_distr::{Distribution, Normal};
use rapier3d_f64::glamx::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// Half-span of the synthetic bearing blocks of a body without `block*` links, m (along and across
/// the axis): a 400 mm × 400 mm carriage, typical of a medium machining centre's Y and Z guideways.
pub const SYNTHETIC_BLOCK_HALF_SPAN: f64 = 0.2;

/// Why a chain could not be built or a chain procedure is invalid. Messages say what was expected.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ChainError {
    /// A chain or chain procedure that breaks a rule; the message names the key and what was expected.
    #[error("{0}")]
    Invalid(String),
    /// A machine error of one of the chain's axes.
    #[error(transparent)]
    Machine(#[from] MachineError),
}

/// The axes' letters run together, as messages show a chain (`xyz`).
fn axis_letters(axes: &[Axis]) -> String {
    axes.iter().map(|a| a.letter()).collect()
}

fn invalid<T>(m: String) -> Result<T, ChainError> {
    Err(ChainError::Invalid(m))
}

/// Unit vector of a machine axis (X → (1, 0, 0), …).
fn axis_unit(axis: Axis) -> DVec3 {
    DVec3::from_array(axis.unit())
}

/// The three squareness angles of a 3-axis machine (ISO 230-1 location errors), rad:
/// `xy` = EC0Y (Y about Z), `xz` = EB0Z (Z about Y), `yz` = EA0Z (Z about X).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SquarenessAngles {
    /// EC0Y, squareness of Y to X (rotation of the Y axis about Z), rad.
    pub xy: f64,
    /// EB0Z, squareness of Z to X (rotation of the Z axis about Y), rad.
    pub xz: f64,
    /// EA0Z, squareness of Z to Y (rotation of the Z axis about X), rad.
    pub yz: f64,
}

impl SquarenessAngles {
    /// The `squareness_xy`, `squareness_xz`, `squareness_yz` effects of a truth (`value`, rad; the
    /// effect's `axis` key is irrelevant), zero where absent.
    pub fn from_effects(set: &EffectSet) -> SquarenessAngles {
        let mut s = SquarenessAngles::default();
        for e in &set.effects {
            if let EffectParams::Squareness(q) = &e.params {
                match e.name {
                    EffectName::SquarenessXy => s.xy = q.value,
                    EffectName::SquarenessXz => s.xz = q.value,
                    EffectName::SquarenessYz => s.yz = q.value,
                    // Squareness parameters under another name: not a squareness of the chain.
                    crate::error_motions!()
                    | EffectName::Backlash
                    | EffectName::CyclicLead
                    | EffectName::ScaleError
                    | EffectName::ThermalExpansion
                    | EffectName::ThermalDrift
                    | EffectName::InterpolationError
                    | EffectName::Coulomb
                    | EffectName::Viscous
                    | EffectName::Stribeck
                    | EffectName::Lugre
                    | EffectName::ServoLag
                    | EffectName::Resonance
                    | EffectName::GravityTilt
                    | EffectName::AccelBiasDrift => {}
                }
            }
        }
        s
    }

    /// Angle θ_ab of the pair (a, b) in chain order and its third direction ĉ, the axis it turns about.
    pub fn pair(&self, a: Axis, b: Axis) -> Option<(f64, Axis)> {
        match (a, b) {
            (Axis::X, Axis::Y) => Some((self.xy, Axis::Z)),
            (Axis::X, Axis::Z) => Some((self.xz, Axis::Y)),
            (Axis::Y, Axis::Z) => Some((self.yz, Axis::X)),
            // Not two different axes in chain order.
            (Axis::X, Axis::X)
            | (Axis::Y, Axis::Y)
            | (Axis::Z, Axis::Z)
            | (Axis::Y, Axis::X)
            | (Axis::Z, Axis::X)
            | (Axis::Z, Axis::Y) => None,
        }
    }

    /// As [EC0Y, EB0Z, EA0Z] = [xy, xz, yz].
    pub fn to_array(&self) -> [f64; 3] {
        [self.xy, self.xz, self.yz]
    }
}

/// One axis of the chain.
#[derive(Clone, Debug)]
pub struct ChainAxis {
    /// The axis (X, Y or Z): the joint name's last letter.
    pub axis: Axis,
    /// The single-axis model in its parent body's frame, with the merged subtree mass.
    pub model: AxisModel,
    /// The physics of this axis, error motions in the simulator's axis frame.
    pub truth: AxisTruth,
    /// The error motions as injected (FORMAT.md names, machine directions of `iso230_symbol`).
    pub motions: ErrorMotions,
    /// Squareness rotation S_j of the axis's travel in its parent frame.
    pub squareness: DQuat,
}

/// A serial chain bed → axes → tool (module doc).
#[derive(Clone, Debug)]
pub struct ChainModel {
    /// Axes in chain order, from the bed.
    pub axes: Vec<ChainAxis>,
    /// The tool (measuring reference) link's placement in the last body's frame.
    pub tool: Frame,
    /// The injected squareness.
    pub squareness: SquarenessAngles,
}

/// A profile times −1.
fn negated(p: &Profile) -> Profile {
    let terms = p
        .terms
        .iter()
        .map(|t| match t {
            Term::Poly(c) => Term::Poly(c.iter().map(|v| -v).collect()),
            Term::Harmonics(h) => Term::Harmonics(
                h.iter().map(|k| crate::profile::Harmonic { amplitude: -k.amplitude, ..k.clone() }).collect(),
            ),
            Term::Random { spec, cosines } => {
                Term::Random { spec: spec.clone(), cosines: cosines.iter().map(|&(a, k, f)| (-a, k, f)).collect() }
            }
            Term::Table { x, y } => Term::Table { x: x.clone(), y: y.iter().map(|v| -v).collect() },
        })
        .collect();
    Profile { terms }
}

/// Machine directions of the FORMAT.md components of `axis`: [axis, first transverse, second
/// transverse] (x, y, z order with the axis skipped; `iso230_symbol`).
fn component_directions(axis: Axis) -> [DVec3; 3] {
    let [t1, t2] = axis.transverse();
    [axis_unit(axis), axis_unit(t1), axis_unit(t2)]
}

/// Re-expresses error motions named by machine direction (FORMAT.md) in the simulator's axis frame
/// (basis b_k = axis_rotation·e_k): component k of the axis frame is ±(the FORMAT component along b_k).
fn to_axis_frame(m: &ErrorMotions, axis: Axis, axis_rotation: DQuat) -> ErrorMotions {
    let dirs = component_directions(axis);
    let pick = |k: usize, profiles: [&Profile; 3]| -> Profile {
        let b = axis_rotation * [DVec3::X, DVec3::Y, DVec3::Z][k];
        for (c, d) in dirs.iter().enumerate() {
            let s = b.dot(*d);
            if s > 0.5 {
                return profiles[c].clone();
            }
            if s < -0.5 {
                return negated(profiles[c]);
            }
        }
        Profile::zero()
    };
    let t = [&m.positioning, &m.straightness_y, &m.straightness_z];
    let r = [&m.roll, &m.pitch, &m.yaw];
    ErrorMotions {
        positioning: pick(0, t),
        straightness_y: pick(1, t),
        straightness_z: pick(2, t),
        roll: pick(0, r),
        pitch: pick(1, r),
        yaw: pick(2, r),
    }
}

/// Rotation by angle θ (rad) about the machine axis `about`.
fn coordinate_rotation(about: Axis, theta: f64) -> DQuat {
    match about {
        Axis::X => DQuat::from_rotation_x(theta),
        Axis::Y => DQuat::from_rotation_y(theta),
        Axis::Z => DQuat::from_rotation_z(theta),
    }
}

impl ChainModel {
    /// Builds the chain of the prismatic joints `configs[j].joint` (in chain order from the bed) of a
    /// machine, with the truth `set`, measuring from the link `tool_link` on the last body.
    ///
    /// Requirements (each refused with a message): the joints form a serial chain starting on the
    /// base; their letters (joint name's last letter) are x, y, z in that order (a subsequence);
    /// each joint's frame is unrotated and moves along its letter's machine direction; the tool link
    /// is on the last body; squareness effects only between axes of the chain.
    pub fn build(
        m: &MachineStructure,
        configs: &[AxisConfig],
        set: &EffectSet,
        tool_link: &str,
    ) -> Result<ChainModel, ChainError> {
        if configs.is_empty() || configs.len() > 3 {
            return invalid(format!("a chain needs 1 to 3 axes, got {}", configs.len()));
        }
        let mut joints = Vec::new();
        for cfg in configs {
            let ax = m.axis_by_joint(&cfg.joint).ok_or_else(|| {
                MachineError::NoJoint(
                    cfg.joint.clone(),
                    m.axes.iter().map(|a| a.joint.as_str()).collect::<Vec<_>>().join(", "),
                )
            })?;
            joints.push(ax.clone());
        }
        let mut letters: Vec<Axis> = Vec::new();
        for ax in &joints {
            let Some(l) = Axis::of_joint(&ax.joint) else {
                return invalid(format!("joint `{}`: expected a name ending in x, y or z", ax.joint));
            };
            letters.push(l);
        }
        for (j, (ax, &l)) in joints.iter().zip(&letters).enumerate() {
            let e = axis_unit(l);
            if j > 0 && letters[j - 1] >= l {
                return invalid(format!(
                    "axes must be given in chain order x, y, z (a subsequence), got {}",
                    axis_letters(&letters)
                ));
            }
            let parent_ok = if j == 0 { ax.parent == 0 } else { ax.parent == joints[j - 1].child };
            if !parent_ok {
                let want = if j == 0 { m.bodies[0].name.clone() } else { m.bodies[joints[j - 1].child].name.clone() };
                return invalid(format!(
                    "joint `{}` moves `{}` on `{}`, but the chain needs it on `{want}`",
                    ax.joint, m.bodies[ax.child].name, m.bodies[ax.parent].name
                ));
            }
            if (ax.axis - e).length() > 1e-9 || ax.origin.rotation.angle_between(DQuat::IDENTITY) > 1e-9 {
                return invalid(format!(
                    "joint `{}`: expected an unrotated joint frame moving along +{l}, got axis {:?}",
                    ax.joint, ax.axis
                ));
            }
        }
        let last_body = joints[joints.len() - 1].child;
        let tool = match m.body_of_link(tool_link) {
            Some(b) if b == last_body => m.bodies[b].link_frame(tool_link).unwrap_or(Frame::IDENTITY),
            Some(b) => {
                return invalid(format!(
                    "tool link `{tool_link}` is on `{}`, expected a link of the last body `{}`",
                    m.bodies[b].name, m.bodies[last_body].name
                ))
            }
            None => return invalid(format!("no link `{tool_link}` in the machine")),
        };
        let squareness = SquarenessAngles::from_effects(set);
        for (name, v, a, b) in [
            ("squareness_xy", squareness.xy, Axis::X, Axis::Y),
            ("squareness_xz", squareness.xz, Axis::X, Axis::Z),
            ("squareness_yz", squareness.yz, Axis::Y, Axis::Z),
        ] {
            if v != 0.0 && !(letters.contains(&a) && letters.contains(&b)) {
                return invalid(format!(
                    "effect `{name}` needs axes {a} and {b} in the chain, which has {}",
                    axis_letters(&letters)
                ));
            }
        }
        let mut axes = Vec::new();
        for (j, cfg) in configs.iter().enumerate() {
            let child = joints[j].child;
            // Merged subtree mass at the reference positions (lower travel end) of the upper axes.
            let mut merged = m.bodies[child].mass;
            let mut f = Frame::IDENTITY;
            for up in &joints[j + 1..] {
                let q = up.lower;
                f = f
                    .compose(&Frame { translation: up.origin.translation + up.axis * q, rotation: up.origin.rotation });
                merged = merged.combine(&m.bodies[up.child].mass.transformed(&f));
            }
            let mut s = m.clone();
            s.bodies[child].mass = merged;
            let n_blocks = s.bodies[child].links.iter().filter(|(n, _)| n.starts_with("block")).count();
            if cfg.guideway.blocks.is_empty() && n_blocks < 3 {
                let rot = DQuat::from_rotation_arc(DVec3::X, joints[j].axis);
                let (a, c) = (joints[j].axis, rot * DVec3::Y);
                let h = SYNTHETIC_BLOCK_HALF_SPAN;
                for (k, (sa, sc)) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)].iter().enumerate() {
                    s.bodies[child].links.push((
                        format!("block_chain_{}", k + 1),
                        Frame { translation: a * (sa * h) + c * (sc * h), rotation: DQuat::IDENTITY },
                    ));
                }
            }
            let mut model = AxisModel::build_on_parent(&s, cfg)?;
            let letter = letters[j];
            let (truth, adj): (AxisTruth, Adjustments) =
                axis_physics(set, letter, &model).map_err(|e| ChainError::Invalid(e.to_string()))?;
            adj.apply(&mut model);
            let motions = truth.motions.clone();
            let truth = AxisTruth { motions: to_axis_frame(&motions, letter, model.axis_rotation), ..truth };
            let mut sq = DQuat::IDENTITY;
            for &a in &letters[..j] {
                if let Some((theta, c)) = squareness.pair(a, letter) {
                    sq *= coordinate_rotation(c, theta);
                }
            }
            axes.push(ChainAxis { axis: letter, model, truth, motions, squareness: sq });
        }
        Ok(ChainModel { axes, tool, squareness })
    }

    /// The axes in chain order.
    pub fn axis_names(&self) -> Vec<Axis> {
        self.axes.iter().map(|a| a.axis).collect()
    }

    /// Travel (lower, upper) of each axis, m.
    pub fn travels(&self) -> Vec<(f64, f64)> {
        self.axes.iter().map(|a| a.model.travel).collect()
    }

    /// Nominal world frames of every body at joint positions q (m), T_j⁰ = (h_j + ê_j·q_j, Q_j).
    pub fn nominal_frames(&self, q: &[f64]) -> Vec<Frame> {
        let mut f = Frame::IDENTITY;
        self.axes
            .iter()
            .zip(q)
            .map(|(a, &qj)| {
                let m = &a.model;
                f = f.compose(&Frame { translation: m.home.translation + m.axis * qj, rotation: m.home.rotation });
                f
            })
            .collect()
    }

    /// Nominal world position (m) of the point r (m, tool-link frame, from the tool reference point)
    /// at joint positions q.
    pub fn nominal_point(&self, q: &[f64], r: DVec3) -> DVec3 {
        let f = self.nominal_frames(q).last().copied().unwrap_or(Frame::IDENTITY);
        f.compose(&self.tool).transform_point(r)
    }

    /// Actual world position (m) of the point r composed exactly from one rapier sample per axis
    /// (module doc): P = T_1 ∘ … ∘ T_n ∘ T_tool · r, T_j = (h_j + S_j·(pos_j − h_j), R_j·Q_j).
    /// A structural mode of a carriage is not included.
    pub fn actual_point(&self, samples: &[&Sample], r: DVec3) -> DVec3 {
        let mut f = Frame::IDENTITY;
        for (a, s) in self.axes.iter().zip(samples) {
            let h = a.model.home;
            f = f.compose(&Frame {
                translation: h.translation + a.squareness * (s.pos - h.translation),
                rotation: DQuat::from_scaled_axis(s.rot) * h.rotation,
            });
        }
        f.compose(&self.tool).transform_point(r)
    }

    /// First-order volumetric error (m) at point r and joint positions q, the model of
    /// `vmt_estimators::laser_ls` with the physical lever arms:
    /// δ = Σ_j [E_j(q_j) + ε_j(q_j) × ρ_j] + Σ_{a<b} θ_ab·(ĉ × ê_b)·q_b, with E_j, ε_j the injected
    /// error motions in machine directions and ρ_j = P⁰(q, r) − O_j⁰(q) the nominal lever arm from
    /// axis j's reference point (its body origin) to the point. Feedback and drive errors (scale
    /// error, backlash, …) are not included.
    pub fn first_order_deviation(&self, q: &[f64], r: DVec3) -> DVec3 {
        let frames = self.nominal_frames(q);
        let p = self.nominal_point(q, r);
        let mut d = DVec3::ZERO;
        for (j, a) in self.axes.iter().enumerate() {
            let dirs = component_directions(a.axis);
            let mo = &a.motions;
            let e = dirs[0] * mo.positioning.value(q[j])
                + dirs[1] * mo.straightness_y.value(q[j])
                + dirs[2] * mo.straightness_z.value(q[j]);
            let eps = dirs[0] * mo.roll.value(q[j]) + dirs[1] * mo.pitch.value(q[j]) + dirs[2] * mo.yaw.value(q[j]);
            d += e + eps.cross(p - frames[j].translation);
            for b in self.axes.iter().enumerate().skip(j + 1) {
                if let Some((theta, c)) = self.squareness.pair(a.axis, b.1.axis) {
                    let cv = DVec3::from(c.unit());
                    d += cv.cross(b.1.model.axis) * (theta * q[b.0]);
                }
            }
        }
        d
    }

    /// Squareness as laser line sets see it (the reporting convention of `laser_ls`): the angles
    /// between the least-squares lines of the paths of the tool reference point (r = 0) along each
    /// axis over `positions[j]` (m), the other axes at their first position, from the first-order
    /// deviation: EC0Y' = −(s_yx + s_xy), EB0Z' = s_zx + s_xz, EA0Z' = −(s_zy + s_yz), with s_ab the
    /// least-squares slope of δ_a along axis b. Equal to the injected angles when the error motions
    /// do not tilt the tool point's paths (no linear trend in the straightness at the tool point, the
    /// angular errors' lever-arm terms included, and no angle at the reference positions).
    pub fn effective_squareness(&self, positions: &[Vec<f64>]) -> SquarenessAngles {
        let q0: Vec<f64> = positions.iter().map(|p| p.first().copied().unwrap_or(0.0)).collect();
        let idx = |l: Axis| self.axes.iter().position(|a| a.axis == l);
        // slope of δ_a along axis b
        let slope = |a: Axis, b: Axis| -> f64 {
            let Some(j) = idx(b) else { return 0.0 };
            let xs = &positions[j];
            let ys: Vec<f64> = xs
                .iter()
                .map(|&x| {
                    let mut q = q0.clone();
                    q[j] = x;
                    self.first_order_deviation(&q, DVec3::ZERO).to_array()[a.index()]
                })
                .collect();
            ls_slope(xs, &ys)
        };
        let has = |a: Axis, b: Axis| idx(a).is_some() && idx(b).is_some();
        let (x, y, z) = (Axis::X, Axis::Y, Axis::Z);
        SquarenessAngles {
            xy: if has(x, y) { -(slope(y, x) + slope(x, y)) } else { 0.0 },
            xz: if has(x, z) { slope(z, x) + slope(x, z) } else { 0.0 },
            yz: if has(y, z) { -(slope(z, y) + slope(y, z)) } else { 0.0 },
        }
    }
}

/// Least-squares slope of y against x: Σ(x − x̄)(y − ȳ)/Σ(x − x̄)²; 0 for fewer than two distinct x.
fn ls_slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().max(1) as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxx: f64 = x.iter().map(|v| (v - mx) * (v - mx)).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    if sxx > 0.0 {
        sxy / sxx
    } else {
        0.0
    }
}

/// Motion plans of all the axes of a chain, kept synchronised (module doc, "Motion").
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChainPlan {
    /// One plan per axis, in chain order.
    pub axes: Vec<MotionPlan>,
    /// End time of the last segment, s.
    pub end: f64,
}

impl ChainPlan {
    /// At rest at joint positions q (m) at t = 0.
    pub fn starting_at(q: &[f64]) -> ChainPlan {
        ChainPlan { axes: q.iter().map(|&x| MotionPlan::starting_at(x)).collect(), end: 0.0 }
    }

    /// Current end position of every axis, m.
    pub fn end_positions(&self) -> Vec<f64> {
        self.axes.iter().map(|p| p.end_pos()).collect()
    }

    /// Appends a dwell of `duration` s on every axis; returns (start, end) time.
    pub fn dwell(&mut self, duration: f64) -> (f64, f64) {
        let t0 = self.end;
        for p in &mut self.axes {
            let x = p.end_pos();
            p.segments.push(Segment::Dwell { t0, x, duration });
        }
        self.end = t0 + duration;
        (t0, self.end)
    }

    /// Appends a synchronised straight-line move to q1 (m) with path feed `feed` (m/s) and path
    /// acceleration `accel` (m/s²): axis j gets the trapezoid of feed·|Δq_j|/L, accel·|Δq_j|/L
    /// (L = |Δq|), so every axis has the duration T of the path's trapezoid. Returns (start, end).
    pub fn move_to(&mut self, q1: &[f64], feed: f64, accel: f64) -> (f64, f64) {
        let q0 = self.end_positions();
        let len = q0.iter().zip(q1).map(|(a, b)| (b - a) * (b - a)).sum::<f64>().sqrt();
        if len.is_nan() || len <= 0.0 {
            return (self.end, self.end);
        }
        let t0 = self.end;
        let duration = Segment::Move { t0: 0.0, x0: 0.0, x1: len, feed, accel }.duration();
        for ((p, &a), &b) in self.axes.iter_mut().zip(&q0).zip(q1) {
            let w = (b - a).abs() / len;
            if w > 0.0 {
                p.segments.push(Segment::Move { t0, x0: a, x1: b, feed: feed * w, accel: accel * w });
            } else {
                p.segments.push(Segment::Dwell { t0, x: a, duration });
            }
        }
        self.end = t0 + duration;
        (t0, self.end)
    }
}

/// Simulates a chain plan axis by axis (each in its own rapier world, parent as rigid ground) and
/// returns one trace per axis sampled at `record_times` (s, increasing).
pub fn simulate_chain(chain: &ChainModel, plan: &ChainPlan, record_times: &[f64]) -> Vec<Trace> {
    simulate_chain_in_session(chain, plan, record_times, 0.0)
}

/// As [`simulate_chain`], for a plan that starts `session_start` s into the measurement session (the
/// session clock of `crate::procedures::plan_session`: time-dependent effects see session_start + t).
pub fn simulate_chain_in_session(
    chain: &ChainModel,
    plan: &ChainPlan,
    record_times: &[f64],
    session_start: f64,
) -> Vec<Trace> {
    chain
        .axes
        .iter()
        .zip(&plan.axes)
        .map(|(a, p)| simulate_in_session(&a.model, &a.truth, p, record_times, session_start))
        .collect()
}

// Defaults of the laser-line procedure's optional keys.
defaults! {
    d_dwell: f64 = 0.3;
    d_average: f64 = 0.1;
    d_rate: f64 = 500.0;
    d_settle: f64 = 1.0;
}

/// One laser line of a [`LaserLinesSpec`]: the tool moves along the straight joint-space line from
/// `from` to `to` (m, joint positions in chain order) and stops at `n` equally spaced targets
/// (both ends included); the laser reads the displacement of the reflector at `point` (m, tool
/// frame, from the tool reference point) along `direction` (machine frame; default: along the
/// line, (to − from)/|to − from|).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaserLineSpec {
    /// Line name; the run is named `{procedure}_{name}` and the laser column after it.
    pub name: String,
    /// Start of the line, joint positions in chain order, m.
    pub from: Vec<f64>,
    /// End of the line, joint positions in chain order, m.
    pub to: Vec<f64>,
    /// Number of equally spaced targets, both ends included.
    pub n: usize,
    /// Reflector position in the tool frame, from the tool reference point, m (default: the reference point).
    #[serde(default)]
    pub point: [f64; 3],
    /// Beam direction in the machine frame (normalised on use); `None`: along the line.
    #[serde(default)]
    pub direction: Option<[f64; 3]>,
}

impl LaserLineSpec {
    /// Unit beam direction (given, normalised; or along the line).
    pub fn beam(&self) -> DVec3 {
        match self.direction {
            Some(d) => DVec3::from_array(d).normalize_or_zero(),
            None => {
                let mut d = DVec3::ZERO;
                for (k, (a, b)) in self.from.iter().zip(&self.to).enumerate().take(3) {
                    d[k] = b - a;
                }
                d.normalize_or_zero()
            }
        }
    }

    /// Length of the line in joint space, m.
    pub fn length(&self) -> f64 {
        self.from.iter().zip(&self.to).map(|(a, b)| (b - a) * (b - a)).sum::<f64>().sqrt()
    }

    /// Joint positions of target k (0..n), m, on the 1 pm grid of commanded positions
    /// ([`crate::motion::on_position_grid`]).
    pub fn target(&self, k: usize) -> Vec<f64> {
        let w = if self.n > 1 { k as f64 / (self.n - 1) as f64 } else { 0.0 };
        self.from.iter().zip(&self.to).map(|(a, b)| crate::motion::on_position_grid(a + (b - a) * w)).collect()
    }
}

/// A multi-axis laser line-set measurement (seed 001: lines along X, Y, Z at offsets, face and body
/// diagonals): each line is one run, a point table (FORMAT.md §1) whose `target` is the distance
/// along the line from `from` (m), with columns `x_cmd`, `y_cmd`, `z_cmd` (the commanded joint
/// positions of the target) and the laser column named after the line, holding the deviation
/// u·(P_actual − P_nominal) averaged over the last `average` s of a `dwell` s stop sampled at
/// `rate` Hz, plus white noise of 1σ `sigma` (m) per reading. Each line starts at rest at `from`
/// after `settle` s (the servo integrators take the weight of a vertical axis), then moves target
/// to target at path feed `feed` (m/s) and acceleration `accel` (m/s², default: the smallest
/// max_accel of the axes).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaserLinesSpec {
    /// Procedure name, the prefix of its runs.
    pub name: String,
    /// The laser lines, one run each, measured in this order.
    pub lines: Vec<LaserLineSpec>,
    /// Path feed between targets, m/s.
    pub feed: f64,
    /// Path acceleration, m/s²; `None`: the smallest `max_accel` of the chain's axes.
    #[serde(default)]
    pub accel: Option<f64>,
    /// Stop at each target, s.
    #[serde(default = "d_dwell")]
    pub dwell: f64,
    /// Averaging window at the end of each stop, s (≤ `dwell`).
    #[serde(default = "d_average")]
    pub average: f64,
    /// Laser sample rate during the averaging window, Hz.
    #[serde(default = "d_rate")]
    pub rate: f64,
    /// Rest at `from` before the first move, s (the servo integrators take up a vertical axis's weight).
    #[serde(default = "d_settle")]
    pub settle: f64,
    /// 1σ noise of one laser reading, m.
    #[serde(default)]
    pub sigma: f64,
}

/// A procedure on a chain, as a scenario declares it under `[[chain_procedures]]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ChainProcedureSpec {
    /// A laser line set ([`LaserLinesSpec`], seed 001).
    LaserLines(LaserLinesSpec),
}

impl ChainProcedureSpec {
    /// The procedure's name.
    pub fn name(&self) -> &str {
        match self {
            ChainProcedureSpec::LaserLines(s) => &s.name,
        }
    }
}

impl LaserLinesSpec {
    /// The name of the run that records `line` of this set: `{procedure}_{line}` (the one place this
    /// format is written; the session plan, the truth view and the chain-line lookup use it).
    pub fn run_name(&self, line: &LaserLineSpec) -> String {
        format!("{}_{}", self.name, line.name)
    }

    /// Path acceleration, m/s².
    pub fn path_accel(&self, chain: &ChainModel) -> f64 {
        self.accel.unwrap_or_else(|| chain.axes.iter().map(|a| a.model.max_accel).fold(f64::INFINITY, f64::min))
    }

    /// Checks the procedure against the chain; returns (key path relative to the procedure, message)
    /// of the first problem: one joint position per axis within its travel at both ends of each line,
    /// n ≥ 2, a non-zero line, unique names, a unit beam, feed within each axis's max feed along the
    /// line, dwell/average/rate/settle/sigma in range.
    pub fn check(&self, chain: &ChainModel) -> Result<(), (String, String)> {
        let fin = |v: f64| v.is_finite();
        if !(fin(self.feed) && self.feed > 0.0) {
            return Err(("feed".into(), format!("expected a path feed > 0 m/s, got {}", self.feed)));
        }
        if let Some(a) = self.accel {
            if !(fin(a) && a > 0.0) {
                return Err(("accel".into(), format!("expected an acceleration > 0 m/s², got {a}")));
            }
        }
        if !(fin(self.dwell) && self.dwell > 0.0 && self.average > 0.0 && self.average <= self.dwell) {
            return Err((
                "dwell".into(),
                format!("expected dwell > 0 and 0 < average ≤ dwell (s), got {} and {}", self.dwell, self.average),
            ));
        }
        if !(fin(self.rate) && self.rate > 0.0 && fin(self.settle) && self.settle >= 0.0) {
            return Err((
                "rate".into(),
                format!("expected rate > 0 Hz and settle ≥ 0 s, got {} and {}", self.rate, self.settle),
            ));
        }
        if !(fin(self.sigma) && self.sigma >= 0.0) {
            return Err(("sigma".into(), format!("expected a noise 1σ ≥ 0 m, got {}", self.sigma)));
        }
        if self.lines.is_empty() {
            return Err(("lines".into(), "expected at least one line".into()));
        }
        let travels = chain.travels();
        let letters = chain.axis_names();
        for (i, l) in self.lines.iter().enumerate() {
            let at = |k: &str| format!("lines[{i}] ({}).{k}", l.name);
            if l.name.is_empty() || l.name.contains(['[', ']', ',', '"']) || l.name == "t" || l.name.ends_with("_cmd") {
                return Err((
                    at("name"),
                    "expected a column name without brackets, commas or quotes, not `t` or `*_cmd`".into(),
                ));
            }
            if self.lines[..i].iter().any(|o| o.name == l.name) {
                return Err((at("name"), "line names must be unique".into()));
            }
            for (key, q) in [("from", &l.from), ("to", &l.to)] {
                if q.len() != travels.len() {
                    return Err((
                        at(key),
                        format!(
                            "expected {} joint positions (axes {}), got {}",
                            travels.len(),
                            axis_letters(&letters),
                            q.len()
                        ),
                    ));
                }
                for ((&x, &(lo, hi)), c) in q.iter().zip(&travels).zip(&letters) {
                    if !(x.is_finite() && x >= lo - 1e-9 && x <= hi + 1e-9) {
                        return Err((at(key), format!("{c} = {x} m is outside the travel [{lo}, {hi}] m")));
                    }
                }
            }
            if l.n < 2 {
                return Err((at("n"), format!("expected at least 2 targets, got {}", l.n)));
            }
            let len = l.length();
            if len.is_nan() || len <= 0.0 {
                return Err((at("to"), "expected `to` different from `from`".into()));
            }
            if !l.point.iter().all(|v| v.is_finite() && v.abs() < 10.0) {
                return Err((at("point"), format!("expected a point within 10 m, got {:?}", l.point)));
            }
            if let Some(d) = l.direction {
                if !d.iter().all(|v| v.is_finite()) || DVec3::from_array(d).length() < 1e-6 {
                    return Err((at("direction"), format!("expected a non-zero finite direction, got {d:?}")));
                }
            }
            for ((a, b), (ax, c)) in l.from.iter().zip(&l.to).zip(chain.axes.iter().zip(&letters)) {
                let v = self.feed * (b - a).abs() / len;
                if v > ax.model.max_feed * (1.0 + 1e-9) {
                    return Err((
                        "feed".into(),
                        format!(
                            "line {}: axis {c} would move at {v} m/s, above its max feed {} m/s",
                            l.name, ax.model.max_feed
                        ),
                    ));
                }
            }
        }
        self.budget(chain)
    }

    /// The size budget of the single-axis procedures ([`ProcedureSpec::budget`](crate::procedures::ProcedureSpec::budget))
    /// for a laser-line set, checked before planning (issue 14: `rate = 1e12` aborted on a 4 GiB
    /// allocation and `dwell = 1e9` hung): times ≤ `MAX_SECONDS`, one sample per physics step at most
    /// (rate ≤ 1/dt of the coarsest axis), at most `MAX_TARGETS` stops a line, and the recorded samples
    /// and physics steps of the whole set within `MAX_SAMPLES` and `MAX_STEPS`.
    fn budget(&self, chain: &ChainModel) -> Result<(), (String, String)> {
        use crate::procedures::{MAX_SAMPLES, MAX_SECONDS, MAX_STEPS, MAX_TARGETS};
        for (k, v) in [("dwell", self.dwell), ("average", self.average), ("settle", self.settle)] {
            if v.is_nan() || v > MAX_SECONDS {
                return Err((k.into(), format!("expected a time ≤ {MAX_SECONDS:e} s, got {v}")));
            }
        }
        let dt = chain.axes.iter().map(|a| a.model.dt).fold(f64::MIN_POSITIVE, f64::max);
        if self.rate * dt > 1.0 + 1e-9 {
            return Err((
                "rate".into(),
                format!("expected a sampling rate ≤ 1/dt = {} Hz (dt = {dt} s), got {}", 1.0 / dt, self.rate),
            ));
        }
        let accel = self.path_accel(chain);
        let (mut samples, mut time) = (0.0, 0.0);
        for (i, l) in self.lines.iter().enumerate() {
            if l.n > MAX_TARGETS {
                return Err((
                    format!("lines[{i}] ({}).n", l.name),
                    format!("{} targets; the limit is {MAX_TARGETS}", l.n),
                ));
            }
            let n = l.n as f64;
            samples += n * (self.average * self.rate + 1.0);
            // Settle, a dwell per stop, the line at the feed, each stop's move v/a longer, and the way back.
            time += self.settle + n * (self.dwell + self.feed / accel) + 2.0 * l.length() / self.feed;
        }
        if samples > MAX_SAMPLES as f64 {
            return Err((
                "lines".into(),
                format!("the lines record about {samples:.3e} samples; the limit is {MAX_SAMPLES:e}"),
            ));
        }
        let dt_min = chain.axes.iter().map(|a| a.model.dt).fold(f64::INFINITY, f64::min);
        let steps = time / dt_min;
        if steps.is_nan() || steps > MAX_STEPS {
            return Err((
                "lines".into(),
                format!(
                    "the lines need about {steps:.3e} physics steps ({time:.4e} s of machine time, from their \
                     settle, dwells, feed, accel and lengths); the limit is {MAX_STEPS:e}"
                ),
            ));
        }
        Ok(())
    }
}

/// The noise-free truth of one line: its plan, its session start time (s) and one trace per axis
/// (same times).
#[derive(Clone, Debug)]
pub struct LineTruth {
    /// The line's plan: command, record times and visits.
    pub plan: LinePlan,
    /// Start of the line in the session's time, s.
    pub start_time: f64,
    /// One noise-free trace per chain axis, sampled at `plan.record_times`.
    pub traces: Vec<Trace>,
}

/// One line of a laser line set before any physics: the chain's commanded motion, the record times
/// and the visits (target = distance along the line, m) with their sample windows.
#[derive(Clone, Debug)]
pub struct LinePlan {
    /// Run name `{procedure}_{line}` ([`LaserLinesSpec::run_name`]).
    pub name: String,
    /// The line as the procedure declares it.
    pub line: LaserLineSpec,
    /// The stops at the targets, with their averaging windows.
    pub visits: Vec<Visit>,
    /// The chain's commanded joint motion along the line.
    pub plan: ChainPlan,
    /// Times at which the physics is recorded, s (the visits' sample windows).
    pub record_times: Vec<f64>,
}

impl LinePlan {
    /// How long the line occupies the machine, s.
    pub fn duration(&self) -> f64 {
        self.plan.end.max(self.record_times.last().copied().unwrap_or(0.0))
    }
}

/// Plans every line of a laser line set (check it first with [`LaserLinesSpec::check`]).
pub fn plan_laser_lines(chain: &ChainModel, spec: &LaserLinesSpec) -> Vec<LinePlan> {
    let accel = spec.path_accel(chain);
    spec.lines
        .iter()
        .map(|line| {
            let mut plan = ChainPlan::starting_at(&line.from);
            plan.dwell(spec.settle);
            // index: average ≤ dwell ≤ MAX_SECONDS and rate ≤ 1/dt (LaserLinesSpec::check and its budget), so `per`
            // is a bounded count ≥ 1, and `times` below holds ≥ 1 sample per visit (its len − 1 is the visit's
            // last).
            let per = ((spec.average * spec.rate).round() as usize).max(1);
            let mut times = Vec::new();
            let mut visits = Vec::new();
            let len = line.length();
            for k in 0..line.n {
                plan.move_to(&line.target(k), spec.feed, accel);
                let (_, t1) = plan.dwell(spec.dwell);
                let first = times.len();
                for i in 0..per {
                    times.push(recorder_time(t1 - (per - 1 - i) as f64 / spec.rate));
                }
                // The distance along the line, written as `target`: on the 1 pm grid (√3·0.1 m is written
                // 0.173205080757, not 0.17320508075688773).
                let s = crate::motion::on_position_grid(len * k as f64 / (line.n - 1) as f64);
                visits.push(Visit { target: s, run: 1, direction: 1, first, last: times.len() - 1 });
            }
            LinePlan { name: spec.run_name(line), line: line.clone(), visits, plan, record_times: times }
        })
        .collect()
}

/// Simulates one planned line starting at session time `session_start` (s).
pub fn simulate_line(chain: &ChainModel, p: &LinePlan, session_start: f64) -> LineTruth {
    LineTruth {
        plan: p.clone(),
        start_time: session_start,
        traces: simulate_chain_in_session(chain, &p.plan, &p.record_times, session_start),
    }
}

/// Simulates every line of a laser line set, back to back from session time 0 (check it first with
/// [`LaserLinesSpec::check`]).
pub fn simulate_laser_lines(chain: &ChainModel, spec: &LaserLinesSpec) -> Vec<LineTruth> {
    let mut clock = 0.0;
    plan_laser_lines(chain, spec)
        .iter()
        .map(|p| {
            let t = simulate_line(chain, p, clock);
            clock += p.duration();
            t
        })
        .collect()
}

/// Noise-free deviation u·(P_actual − P_nominal) (m) of a line's reflector, averaged over each visit's
/// window, one value per visit.
pub fn line_deviations(chain: &ChainModel, truth: &LineTruth) -> Vec<f64> {
    let u = truth.plan.line.beam();
    let r = DVec3::from_array(truth.plan.line.point);
    truth
        .plan
        .visits
        .iter()
        .enumerate()
        .map(|(k, v)| {
            let q = truth.plan.line.target(k);
            let nominal = chain.nominal_point(&q, r);
            let mut sum = 0.0;
            for i in v.first..=v.last {
                let samples: Vec<&Sample> = truth.traces.iter().map(|t| &t.samples[i]).collect();
                sum += u.dot(chain.actual_point(&samples, r) - nominal);
            }
            sum / (v.last - v.first + 1) as f64
        })
        .collect()
}

/// Reads a line with its laser: the averaged deviations plus N(0, σ²) noise seeded by
/// (seed, "run/line"), as a point-table run record (procedure `positioning`, FORMAT.md §1).
pub fn read_line(chain: &ChainModel, truth: &LineTruth, sigma: f64, seed: u64) -> RunRecord {
    let mut values = line_deviations(chain, truth);
    if sigma > 0.0 {
        let mut rng = source_rng(seed, &format!("{}/{}", truth.plan.name, truth.plan.line.name));
        if let Ok(n) = Normal::new(0.0, sigma) {
            values.iter_mut().for_each(|v| *v += n.sample(&mut rng));
        }
    }
    let mut columns = Vec::new();
    for (j, a) in chain.axes.iter().enumerate() {
        columns.push((
            format!("{}_cmd", a.axis),
            (0..truth.plan.visits.len()).map(|k| truth.plan.line.target(k)[j]).collect(),
        ));
    }
    columns.push((truth.plan.line.name.clone(), values));
    let last_t = |v: &Visit| truth.traces.first().map_or(0.0, |t| t.samples[v.last].t);
    RunRecord {
        name: truth.plan.name.clone(),
        procedure: ProcedureKind::Positioning,
        feed: None,
        direction: None,
        start_time: truth.start_time,
        data: RunData::PointTable {
            target: truth.plan.visits.iter().map(|v| v.target).collect(),
            run: truth.plan.visits.iter().map(|v| v.run).collect(),
            direction: truth.plan.visits.iter().map(|v| v.direction).collect(),
            t: Some(truth.plan.visits.iter().map(last_t).collect()),
            columns,
        },
    }
}

/// The axis a line mostly moves (largest |Δq|; first on ties), for the manifest's `axis`; `None` for a
/// chain without axes.
pub fn dominant_axis(chain: &ChainModel, line: &LaserLineSpec) -> Option<Axis> {
    let mut best = (0usize, -1.0);
    for (j, (a, b)) in line.from.iter().zip(&line.to).enumerate() {
        if (b - a).abs() > best.1 + 1e-12 {
            best = (j, (b - a).abs());
        }
    }
    chain.axes.get(best.0).map(|a| a.axis)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn squareness_rotations_tilt_the_later_axes_as_laser_ls_says() {
        // Hand-worked: Y tilted by EC0Y = 1e-3 about Z moves along (−sin θ, cos θ, 0): at q_y = 0.5 m
        // the point shifts by −θ·q_y = −0.5 mm in x (first order; sin θ − θ ≈ 1.7e-10 relative).
        let s = SquarenessAngles { xy: 1e-3, xz: 0.0, yz: 0.0 };
        let (theta, c) = s.pair(Axis::X, Axis::Y).unwrap();
        let moved = coordinate_rotation(c, theta) * (DVec3::Y * 0.5);
        assert!((moved.x - (-0.5e-3)).abs() < 1e-9, "{moved:?}");
        // Z tilted by EB0Z about Y moves +x, by EA0Z about X moves −y.
        let z = coordinate_rotation(Axis::Y, 2e-3) * DVec3::Z;
        assert!((z.x - 2e-3).abs() < 1e-8);
        let z = coordinate_rotation(Axis::X, 3e-3) * DVec3::Z;
        assert!((z.y + 3e-3).abs() < 1e-8);
    }

    #[test]
    fn synchronised_moves_arrive_together() {
        let mut p = ChainPlan::starting_at(&[0.0, 0.1, 0.2]);
        let (t0, t1) = p.move_to(&[0.3, 0.1, 0.6], 0.2, 1.0);
        for (j, want) in [0.3, 0.1, 0.6].iter().enumerate() {
            assert!((p.axes[j].at(t1).pos - want).abs() < 1e-12);
            assert!((p.axes[j].end_time() - t1).abs() < 1e-12, "axis {j} ends at {}", p.axes[j].end_time());
        }
        // Midway the point is on the straight line: (x − 0)/0.3 = (z − 0.2)/0.4.
        let tm = 0.5 * (t0 + t1) - 0.37;
        let (x, z) = (p.axes[0].at(tm).pos, p.axes[2].at(tm).pos);
        assert!((x / 0.3 - (z - 0.2) / 0.4).abs() < 1e-12);
    }

    #[test]
    fn profiles_are_reexpressed_in_the_axis_frame() {
        // Y: axis frame y = −X, so straightness_y (EXY, along +X) becomes −EXY in the frame.
        let m = ErrorMotions {
            straightness_y: Profile::poly(vec![1e-6]),
            pitch: Profile::poly(vec![2e-6]),
            ..Default::default()
        };
        let rot = DQuat::from_rotation_arc(DVec3::X, DVec3::Y);
        let f = to_axis_frame(&m, Axis::Y, rot);
        let world_t = rot * f.translation(0.0);
        let world_r = rot * f.rotation(0.0);
        assert!((world_t - DVec3::new(1e-6, 0.0, 0.0)).length() < 1e-18);
        assert!((world_r - DVec3::new(2e-6, 0.0, 0.0)).length() < 1e-18);
        // Z: straightness_y = EXZ along +X, straightness_z = EYZ along +Y, yaw = EBZ about +Y.
        let m = ErrorMotions {
            straightness_y: Profile::poly(vec![1e-6]),
            straightness_z: Profile::poly(vec![3e-6]),
            yaw: Profile::poly(vec![5e-6]),
            ..Default::default()
        };
        let rot = DQuat::from_rotation_arc(DVec3::X, DVec3::Z);
        let f = to_axis_frame(&m, Axis::Z, rot);
        assert!((rot * f.translation(0.0) - DVec3::new(1e-6, 3e-6, 0.0)).length() < 1e-18);
        assert!((rot * f.rotation(0.0) - DVec3::new(0.0, 5e-6, 0.0)).length() < 1e-18);
    }
}
