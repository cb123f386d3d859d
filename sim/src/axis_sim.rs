//! Time integration of one axis in rapier3d-f64 (DESIGN.md §4): the moving body held by stiff, damped
//! guideway bearings whose rest pose follows the injected error motions at the current axis position,
//! driven along the axis by the cascade servo through a force at the nut. Gravity on. One solver
//! iteration, the body never sleeps, forces are reset every step.
//!
//! The run's mutable state (`AxisSim`) is separate from the immutable `AxisModel`.

use crate::geometry::ErrorMotions;
use crate::machine::AxisModel;
use crate::motion::{Command, MotionPlan};
use crate::servo::{quantise, servo_update, ServoState};
use rapier3d_f64::glamx::{DQuat, DVec3};
use rapier3d_f64::prelude::*;

/// Standard gravity, m/s² (acts along −Z of the machine frame).
pub const GRAVITY: f64 = 9.80665;

/// The state of the moving body and the drive at one instant (noise-free truth).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// Time, s.
    pub t: f64,
    pub cmd: Command,
    /// Position feedback as the controller sees it (quantised), m.
    pub feedback: f64,
    /// Drive force, N.
    pub force: f64,
    /// Body frame origin (the axis reference point), world frame, m.
    pub pos: DVec3,
    /// Body rotation relative to its home orientation, rotation vector, world frame, rad.
    pub rot: DVec3,
    /// Velocity of the body frame origin, world frame, m/s.
    pub vel: DVec3,
    /// Angular velocity, world frame, rad/s.
    pub angvel: DVec3,
}

impl Sample {
    fn lerp(&self, o: &Sample, w: f64) -> Sample {
        let l = |a: f64, b: f64| a + (b - a) * w;
        let lv = |a: DVec3, b: DVec3| a + (b - a) * w;
        Sample {
            t: l(self.t, o.t),
            cmd: self.cmd,
            feedback: l(self.feedback, o.feedback),
            force: self.force,
            pos: lv(self.pos, o.pos),
            rot: lv(self.rot, o.rot),
            vel: lv(self.vel, o.vel),
            angvel: lv(self.angvel, o.angvel),
        }
    }

    /// World position of a body-frame point p (m), given the home orientation.
    pub fn point(&self, model: &AxisModel, p: DVec3) -> DVec3 {
        self.pos + DQuat::from_scaled_axis(self.rot) * (model.home.rotation * p)
    }

    /// Velocity of a body-frame point p, world frame, m/s.
    pub fn point_velocity(&self, model: &AxisModel, p: DVec3) -> DVec3 {
        self.vel
            + self
                .angvel
                .cross(DQuat::from_scaled_axis(self.rot) * (model.home.rotation * p))
    }
}

/// Samples of a run at the requested record times.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trace {
    pub samples: Vec<Sample>,
}

/// The mutable state of a simulation run of one axis.
pub struct AxisSim<'a> {
    model: &'a AxisModel,
    errors: &'a ErrorMotions,
    world: PhysicsWorld,
    body: RigidBodyHandle,
    servo: ServoState,
    steps: u64,
    ey: DVec3,
    ez: DVec3,
}

impl<'a> AxisSim<'a> {
    /// A run starting at rest at axis position x0, the body placed on its rest pose lowered by the static
    /// sag of the bearings under gravity.
    pub fn new(model: &'a AxisModel, errors: &'a ErrorMotions, x0: f64) -> AxisSim<'a> {
        let mut world = PhysicsWorld::new();
        world.gravity = DVec3::new(0.0, 0.0, -GRAVITY);
        world.integration_parameters.dt = model.dt;
        world.integration_parameters.num_solver_iterations = 1;
        let ey = model.axis_rotation * DVec3::Y;
        let ez = model.axis_rotation * DVec3::Z;
        let x_fb0 = x0 + errors.positioning.value(x0);
        let rest = model.rest_pose(errors, x0);
        let sag_per_block = model.mass * GRAVITY / (model.blocks.len() as f64);
        let sag = DVec3::new(0.0, 0.0, -1.0) * sag_per_block / model.k_z.max(1.0) * (ez.z.abs());
        let _ = x_fb0;
        let rb = RigidBodyBuilder::dynamic()
            .pose(Pose::from_parts(rest.translation + sag, rest.rotation))
            .additional_mass_properties(MassProperties::with_inertia_matrix(
                model.com,
                model.mass,
                model.inertia,
            ))
            .can_sleep(false)
            .build();
        let body = world.bodies.insert(rb);
        AxisSim {
            model,
            errors,
            world,
            body,
            servo: ServoState::default(),
            steps: 0,
            ey,
            ez,
        }
    }

    /// Adds a velocity change to the body at its centre of mass (an impulse-hammer test), m/s.
    pub fn kick(&mut self, dv: DVec3) {
        let rb = &mut self.world.bodies[self.body];
        let v = rb.linvel();
        rb.set_linvel(v + dv, true);
    }

    /// Time of the current state, s.
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.model.dt
    }

    /// Actual axis coordinate of the reference point (m): axis · (origin − home).
    fn axis_coordinate(&self, rb: &RigidBody) -> f64 {
        self.model
            .axis
            .dot(rb.position().translation - self.model.home.translation)
    }

    /// Nominal axis position as the machine sees it: x_actual − EXX(x_actual). The servo drives it to the
    /// command, so the reference point lands at command + EXX (to first order).
    fn nominal(&self, x_actual: f64) -> f64 {
        x_actual - self.errors.positioning.value(x_actual)
    }

    /// Current truth sample.
    pub fn sample(&self, cmd: Command) -> Sample {
        let rb = &self.world.bodies[self.body];
        let pose = rb.position();
        let x = self.axis_coordinate(rb);
        Sample {
            t: self.time(),
            cmd,
            feedback: quantise(self.nominal(x), self.model.servo.resolution),
            force: self.servo.force,
            pos: pose.translation,
            rot: (pose.rotation * self.model.home.rotation.inverse()).to_scaled_axis(),
            vel: rb.velocity_at_point(pose.translation),
            angvel: rb.angvel(),
        }
    }

    /// Advances one physics step with the command `cmd` (servo updated every `servo_steps`).
    pub fn step(&mut self, cmd: Command) {
        let m = self.model;
        let ts = m.dt * m.servo_steps as f64;
        let (x_act, q_dot, pose) = {
            let rb = &self.world.bodies[self.body];
            let p = *rb.position();
            (
                self.axis_coordinate(rb),
                m.axis.dot(rb.velocity_at_point(p.translation)),
                p,
            )
        };
        let q = self.nominal(x_act);
        if self.steps % m.servo_steps as u64 == 0 {
            let fb = quantise(q, m.servo.resolution);
            servo_update(
                &m.servo,
                &mut self.servo,
                m.mass,
                ts,
                cmd.pos,
                cmd.vel,
                cmd.acc,
                fb,
            );
        }
        let rest = m.rest_pose(self.errors, q);
        let (de, deps) = self.errors.slope(q);
        let (de, deps) = (m.axis_rotation * de, m.axis_rotation * deps);
        let rb = &mut self.world.bodies[self.body];
        rb.reset_forces(false);
        rb.reset_torques(false);
        for b in &m.blocks {
            let p = pose.transform_point(*b);
            let rb_rest = rest.rotation * *b;
            let d = p - (rest.translation + rb_rest);
            let v_rest = q_dot * (m.axis + de + deps.cross(rb_rest));
            let dv = rb.velocity_at_point(p) - v_rest;
            let f = -(m.k_y * d.dot(self.ey) + m.c_y * dv.dot(self.ey)) * self.ey
                - (m.k_z * d.dot(self.ez) + m.c_z * dv.dot(self.ez)) * self.ez;
            rb.add_force_at_point(f, p, false);
        }
        let nut = pose.transform_point(m.nut);
        let f_drive = self.servo.force - m.axis_damping * q_dot;
        rb.add_force_at_point(m.axis * f_drive, nut, false);
        self.world.step();
        self.steps += 1;
    }
}

/// Simulates a motion plan and returns the truth sampled at `record_times` (s, increasing), linearly
/// interpolated between physics steps. The run ends at the later of the plan's end and the last record.
pub fn simulate(
    model: &AxisModel,
    errors: &ErrorMotions,
    plan: &MotionPlan,
    record_times: &[f64],
) -> Trace {
    let x0 = plan.at(0.0).pos;
    let mut sim = AxisSim::new(model, errors, x0);
    let t_end = record_times.last().copied().unwrap_or(0.0).max(0.0);
    let mut out = Vec::with_capacity(record_times.len());
    let mut next = 0;
    let mut prev = sim.sample(plan.at(0.0));
    while next < record_times.len() && record_times[next] <= prev.t {
        out.push(Sample {
            t: record_times[next],
            ..prev
        });
        next += 1;
    }
    while next < record_times.len() && sim.time() <= t_end + model.dt {
        let cmd = plan.at(sim.time());
        sim.step(cmd);
        let cur = sim.sample(plan.at(sim.time()));
        while next < record_times.len() && record_times[next] <= cur.t {
            let tr = record_times[next];
            let w = (tr - prev.t) / (cur.t - prev.t);
            let mut s = prev.lerp(&cur, w);
            s.cmd = plan.at(tr);
            s.force = cur.force;
            out.push(s);
            next += 1;
        }
        prev = cur;
    }
    Trace { samples: out }
}
