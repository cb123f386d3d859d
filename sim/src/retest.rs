//! A compensated positioning re-test derived from the same re-test simulated without compensation
//! (issue 12: a tolerance study estimates a new compensation table in every trial; simulating the
//! compensated re-test once per table cost a full positioning run of physics per trial).
//!
//! The CNC's table acts on its feedback only (seed 004, [`crate::machine::AxisModel::compensation`]):
//! the loop drives the compensated feedback f + c(f) where it drove f before. Every sample of a
//! positioning run is recorded at rest, at the end of a dwell; so the compensated run holds its feedback
//! f_c at the solution of f_c + c(f_c) = f_u, f_u the feedback the uncompensated run held at the same
//! time, and the table sits where that feedback puts it: [`at_rest_with_compensation`] moves each
//! recorded sample there — along the axis by the feedback's change carried through the positioning
//! chain, across it and in rotation by the change of the guideway's rest pose — keeping its deflection
//! from the rest pose (bearings, servo residual, nut contact, friction hold) as it was.
//!
//! What this neglects, and its size (c the table's correction, a few µm to tens of µm):
//! - the settling state (servo residual, the bearings' deflection, where friction holds the table
//!   inside the backlash) is taken as at the uncompensated position; it changes with position only
//!   through the slopes of the error motions, O(|c|·|∂δ/∂x|) with δ ≲ 1 µm and ∂/∂x ≲ 1e-4 /m: below
//!   1e-14 m;
//! - the loop gain: the table makes the loop see f + c(f), its gain scaled by 1 + c'(f), so an error δ
//!   the loop has not yet settled at a reading (δ = command − feedback: µm after a short dwell, nm after
//!   a long one) changes by about |c'|·|δ| (c' ≲ 3e-4 on the bundled tables);
//! - the feedback quantisation r: the loop holds its quantised feedback on the target's count, and where
//!   inside that count the table rests is not transported: up to one count r (1 nm on the bundled
//!   scenarios) per sample, a deterministic offset that does not average out over a dwell;
//! - the table's own slope, the lead error and the positioning chain enter exactly (fixed points, not
//!   first order), and the error motions through their values at the new position.

use crate::axis_sim::AxisTruth;
use crate::drive::{DriveConfig, FeedbackKind};
use crate::machine::AxisModel;
use crate::procedures::{Layout, RunTruth};
use crate::profile::Profile;
use crate::servo::quantise;
use rapier3d_f64::glamx::DQuat;

/// Iterations of the fixed points below: each gains a factor |c'| ≲ 1e-3 (table slope) or |E'| ≲ 1e-3
/// (positioning chain), so four take a 100 µm correction below 1e-16 m.
const FIXED_POINT_ITERATIONS: usize = 4;

/// The solution y of y + c(y) = f (the feedback the compensated CNC holds where the uncompensated one
/// held f), by the fixed point y ← f − c(y).
fn compensated_feedback(c: &Profile, f: f64) -> f64 {
    (0..FIXED_POINT_ITERATIONS).fold(f - c.value(f), |y, _| f - c.value(y))
}

/// The positioning run `run` (simulated on `model` without compensation) as it reads with the
/// compensation table `table` (m of correction against feedback position, m) in the CNC: each sample moved
/// to where the table's action puts the body at rest (module docs: the equations and what is neglected).
/// `None` for a time series, whose samples are not at rest.
pub fn at_rest_with_compensation(
    model: &AxisModel,
    physics: &AxisTruth,
    run: &RunTruth,
    table: &Profile,
) -> Option<RunTruth> {
    let Layout::PointTable { .. } = run.layout else { return None };
    let res = model.servo.resolution;
    let m = &physics.motions;
    let mut out = run.clone();
    for s in out.samples.iter_mut() {
        let tau = run.start_time + s.t;
        // Positioning chain: the nominal position q the machine believes for an actual axis coordinate x is
        // q = x − EXX(x) − e(x, τ) (`AxisSim::nominal`).
        let chain = |x: f64| m.positioning.value(x) + physics.feedback.error(x, tau);
        let actual_of = |q: f64| (0..FIXED_POINT_ITERATIONS).fold(q + chain(q), |x, _| q + chain(x));
        let x_u = model.axis.dot(s.pos - model.home.translation);
        let q_u = x_u - chain(x_u);
        // Where the loop's feedback moves, and the table with it.
        let (x_c, q_c, motor_c) = match &model.drive {
            DriveConfig::BallScrew(b) if b.feedback == FeedbackKind::Rotary => {
                // Semi-closed: the motor holds u_c + c(u_c) = u_u; the nut, and the table on it, move with the
                // screw's free position u + lead(u) + EXX(u) + e(u, τ) (`AxisSim::step`).
                let nut = |u: f64| u + physics.lead_error.value(u) + chain(u);
                let u_u = s.motor;
                let u_c = compensated_feedback(table, u_u);
                let x_c = x_u + nut(u_c) - nut(u_u);
                (x_c, x_c - chain(x_c), quantise(u_c, res))
            }
            DriveConfig::BallScrew(_) => {
                // Closed loop on the scale: the scale holds q_c + c(q_c) = q_u; the motor follows the table.
                let q_c = compensated_feedback(table, q_u);
                let x_c = actual_of(q_c);
                (x_c, q_c, quantise(s.motor + (x_c - x_u), res))
            }
            DriveConfig::LinearMotor => {
                let q_c = compensated_feedback(table, q_u);
                (actual_of(q_c), q_c, quantise(q_c, res))
            }
        };
        // The rest pose's change from q_u to q_c (straightness and angles), the axial part replaced by the
        // actual move x_c − x_u; the deflection from the rest pose kept.
        let (rest_u, rest_c) = (model.rest_pose(m, q_u), model.rest_pose(m, q_c));
        let shift = rest_c.translation - rest_u.translation;
        let across = shift - model.axis * model.axis.dot(shift);
        s.pos += across + model.axis * (x_c - x_u);
        let turn = rest_c.rotation * rest_u.rotation.inverse() * DQuat::from_scaled_axis(s.rot);
        s.rot = turn.to_scaled_axis();
        s.scale = quantise(q_c, res);
        s.motor = motor_c;
        let fb = match &model.drive {
            DriveConfig::BallScrew(b) if b.feedback == FeedbackKind::Rotary => motor_c,
            DriveConfig::BallScrew(_) | DriveConfig::LinearMotor => q_c,
        };
        s.feedback = quantise(fb + table.value(fb), res);
    }
    Some(out)
}
