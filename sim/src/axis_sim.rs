//! Time integration of one axis in rapier3d-f64 (DESIGN.md §4): the moving body held by stiff, damped
//! guideway bearings whose rest pose follows the injected error motions at the current axis position,
//! driven along the axis by the cascade servo through a linear motor or a ball screw. Gravity on. One
//! solver iteration, the body never sleeps, forces are reset every step.
//!
//! The run's mutable state (`AxisSim`) is separate from the immutable `AxisModel` and `AxisTruth`.

use crate::drive::{dead_zone_force, DriveConfig, FeedbackKind};
use crate::feedback::FeedbackErrors;
use crate::friction::{lugre_step_unchecked, stick_slip_force, LugreParams, StepInput, StribeckLaw};
use crate::geometry::{ErrorMotions, MotionsAt};
use crate::machine::{AxisModel, Fidelity};
use crate::motion::{Command, MotionPlan};
use crate::profile::{Profile, Tabulated};
use crate::servo::{quantise, servo_update, ServoState};
use rapier3d_f64::glamx::{DMat3, DQuat, DVec3};
use rapier3d_f64::prelude::*;

/// Standard gravity, m/s² (acts along −Z of the machine frame).
pub const GRAVITY: f64 = 9.80665;

/// Everything injected into the physics of one axis.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AxisTruth {
    /// The six error motions of the guideway.
    pub motions: ErrorMotions,
    /// Errors of the feedback chain (scale error, interpolation, thermal), m.
    pub feedback: FeedbackErrors,
    /// Lead error of the screw (cyclic lead), m as a function of the screw position.
    pub lead_error: Profile,
    /// Backlash of the screw-nut contact, m.
    pub backlash: f64,
    /// Friction of the guideway on the moving body.
    pub friction: GuideFriction,
    /// A structural mode of the column (resonance effect), if any.
    pub mode: Option<StructuralMode>,
}

/// A structural mode of the moving body (the column bending), DESIGN.md §4 "structural resonance": a
/// modal oscillator per direction driven by the acceleration of the reference point (base excitation),
/// q̈ + 2ζω·q̇ + ω²·q = −a_base, with a linear mode shape φ(r) = r_z/h (h: `height`, the tip of the
/// column above the reference point): a point r of the body moves by φ(r)·q in addition to the rigid
/// motion. Sensors see it; the rigid-body dynamics does not (the modal mass is taken as small).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StructuralMode {
    /// Natural frequency, Hz.
    pub frequency: f64,
    /// Damping ratio ζ.
    pub damping: f64,
    /// Height of the mode shape's unit point above the reference point, m.
    pub height: f64,
}

impl StructuralMode {
    /// Mode shape at body point r (axis frame): φ = max(r_z, 0)/h.
    pub fn shape(&self, r: DVec3) -> f64 {
        r.z.max(0.0) / self.height
    }
}

/// Friction of a guideway (DESIGN.md §4): Coulomb and viscous are Stribeck special cases.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum GuideFriction {
    /// No friction force on the guideway.
    #[default]
    None,
    /// Static friction curve with true sticking.
    Stribeck(StribeckLaw),
    /// Dynamic (bristle) model: pre-sliding and stick-slip.
    LuGre(LugreParams),
}

/// Stick band of the sticking element, m/s: the body's velocity along the axis is not exactly zero
/// while stuck, because the bearings rock it slightly (multi-DOF body; see friction::StepInput).
const STICK_BAND: f64 = 1e-7;

impl AxisTruth {
    /// Truth with only geometric error motions.
    pub fn geometric(motions: ErrorMotions) -> AxisTruth {
        AxisTruth { motions, ..Default::default() }
    }
}

/// The state of the moving body and the drive at one instant (noise-free truth).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// Time, s.
    pub t: f64,
    /// The interpolator's command at `t`: position, m; velocity, m/s; acceleration, m/s².
    pub cmd: Command,
    /// Position feedback as the controller sees it (quantised), m.
    pub feedback: f64,
    /// Linear-scale reading of the table (quantised): x − EXX(x) − e(x, t), m.
    pub scale: f64,
    /// Motor position in the screw's linear coordinate (linear motor: the scale), m.
    pub motor: f64,
    /// Motor force (servo output), N.
    pub force: f64,
    /// Guideway friction force on the body along the axis, N.
    pub friction: f64,
    /// Body frame origin (the axis reference point), world frame, m.
    pub pos: DVec3,
    /// Body rotation relative to its home orientation, rotation vector, world frame, rad.
    pub rot: DVec3,
    /// Velocity of the body frame origin, world frame, m/s.
    pub vel: DVec3,
    /// Angular velocity, world frame, rad/s.
    pub angvel: DVec3,
    /// Modal displacement and velocity of the structural mode (zero without one), world frame.
    pub mode: DVec3,
    /// Modal velocity of the structural mode (time derivative of `mode`), world frame, m/s.
    pub mode_vel: DVec3,
}

impl Sample {
    fn lerp(&self, o: &Sample, w: f64) -> Sample {
        let l = |a: f64, b: f64| a + (b - a) * w;
        let lv = |a: DVec3, b: DVec3| a + (b - a) * w;
        Sample {
            t: l(self.t, o.t),
            cmd: self.cmd,
            feedback: l(self.feedback, o.feedback),
            scale: l(self.scale, o.scale),
            motor: l(self.motor, o.motor),
            force: o.force,
            friction: o.friction,
            pos: lv(self.pos, o.pos),
            rot: lv(self.rot, o.rot),
            vel: lv(self.vel, o.vel),
            angvel: lv(self.angvel, o.angvel),
            mode: lv(self.mode, o.mode),
            mode_vel: lv(self.mode_vel, o.mode_vel),
        }
    }

    /// World position of a body-frame point p (m), given the home orientation and the structural mode
    /// (if the truth has one).
    pub fn point(&self, model: &AxisModel, p: DVec3, mode: Option<&StructuralMode>) -> DVec3 {
        let flex = mode.map_or(DVec3::ZERO, |m| self.mode * m.shape(model.body_to_axis(p)));
        self.pos + DQuat::from_scaled_axis(self.rot) * (model.home.rotation * p) + flex
    }

    /// Velocity of a body-frame point p, world frame, m/s.
    pub fn point_velocity(&self, model: &AxisModel, p: DVec3, mode: Option<&StructuralMode>) -> DVec3 {
        self.point_velocity_turned(self.turn(), model, p, mode)
    }

    /// The body's rotation from its home orientation as a quaternion (from the rotation vector `rot`).
    pub fn turn(&self) -> DQuat {
        DQuat::from_scaled_axis(self.rot)
    }

    /// As [`Sample::point_velocity`], given `turn` = [`Sample::turn`] (computed once by a caller that
    /// also needs it): v + ω × (R·(H·p)) + φ(p)·q̇, m/s, with R the turn and H the home rotation.
    pub fn point_velocity_turned(
        &self,
        turn: DQuat,
        model: &AxisModel,
        p: DVec3,
        mode: Option<&StructuralMode>,
    ) -> DVec3 {
        let flex = mode.map_or(DVec3::ZERO, |m| self.mode_vel * m.shape(model.body_to_axis(p)));
        self.vel + self.angvel.cross(turn * (model.home.rotation * p)) + flex
    }
}

/// Samples of a run at the requested record times.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trace {
    /// One sample per record time, in time order.
    pub samples: Vec<Sample>,
}

/// Motor state of a ball-screw drive, in the screw's linear coordinate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Motor {
    u: f64,
    u_dot: f64,
}

/// Kinematic state of the moving body at one instant, world frame: the body frame's pose, the centre of
/// mass, and the velocity of the centre of mass and the angular velocity (m, m/s, rad/s).
#[derive(Clone, Copy, Debug)]
struct BodyState {
    pose: Pose,
    /// The pose's rotation as a matrix (computed once per step for the points it carries).
    rot: DMat3,
    com: DVec3,
    linvel: DVec3,
    angvel: DVec3,
}

impl BodyState {
    /// Velocity of a world point p attached to the body: v + ω × (p − c), m/s.
    fn velocity_at_point(&self, p: DVec3) -> DVec3 {
        self.linvel + self.angvel.cross(p - self.com)
    }
}

/// The moving body in rapier3d-f64 (the reference engine): one body, no collider, no joint.
struct RapierBody {
    world: PhysicsWorld,
    handle: RigidBodyHandle,
}

impl RapierBody {
    /// A world of gravity −[`GRAVITY`]·ẑ and step dt (s) holding one dynamic body at pose `start` with the
    /// mass properties `mprops`, which never sleeps; `prime`: [`prime_joint_buffers`] first (a speed
    /// measure; false only to test that it leaves the trajectory unchanged).
    fn new(dt: f64, start: Pose, mprops: MassProperties, prime: bool) -> RapierBody {
        let mut world = PhysicsWorld::new();
        world.gravity = DVec3::new(0.0, 0.0, -GRAVITY);
        world.integration_parameters.dt = dt;
        world.integration_parameters.num_solver_iterations = 1;
        // The world holds this one body and nothing else (no collider, joint or contact; the priming
        // bodies and joints are removed before it arrives), so
        // the passes that act on constraints have nothing to act on and are switched off;
        // none touches the body's state (the trajectory is bit-identical with and without
        // them): continuous collision detection, the constraint solver's velocity passes (with
        // and without bias) and its warm start, and the statistics counters (which otherwise
        // sum the contacts of the solver's 129 colour buckets every step). The force, the
        // gyroscopic correction and the pose update are integrated as before. A world given a
        // collider or joint would need the defaults back.
        world.integration_parameters.max_ccd_substeps = 0;
        world.integration_parameters.num_internal_pgs_iterations = 0;
        world.integration_parameters.num_internal_stabilization_iterations = 0;
        world.integration_parameters.warmstart_coefficient = 0.0;
        world.physics_pipeline.counters.disable();
        if prime {
            prime_joint_buffers(&mut world);
        }
        let rb = RigidBodyBuilder::dynamic().pose(start).additional_mass_properties(mprops).can_sleep(false).build();
        let handle = world.bodies.insert(rb);
        RapierBody { world, handle }
    }
}

/// Number of body pairs joined in one colour by [`prime_joint_buffers`]: rapier3d-f64 0.36 lays out a joint
/// colour as SIMD chunks from 64 joints on (`JOINT_BATCH · LAYOUT_REF_WORKERS / 2` = 16 · 8 / 2).
const PRIMING_PAIRS: usize = 65;

/// Gives rapier's joint-solver buffers an allocation before the world receives the moving body, so the
/// reference step does not pay four microcode assists per step (a speed measure only: the trajectory is
/// bit-identical with and without it, tested).
///
/// Why: every `&mut` access to a body makes rapier re-lay out its joints in the next step (the access
/// bumps the island manager's active-set epoch, and the joint layout is reused only under an unchanged
/// epoch), and the re-layout clears four joint buffers with `write_bytes(ptr, 0, len)`. With no joint
/// ever seen, those buffers are unallocated, `ptr` is a dangling address in the unmapped first page, and
/// glibc's AVX-512 `memset` of zero bytes there is a masked store whose fault suppression costs a
/// microcode assist of ~100 ns (measured: 20 % of a lone-body rapier step; the step accesses the body
/// once, to set the force and torque, which change every step). Once allocated, a buffer keeps its
/// capacity (`clear` + `reserve`), so the same zero-byte stores hit mapped memory.
///
/// How: [`PRIMING_PAIRS`] fixed–dynamic body pairs far from the axis, each joined by a fixed joint (one
/// colour of SIMD joints: the wide builder and constraint buffers), one more fixed joint on the first
/// dynamic body (a second colour of one joint, solved serially: the scalar builder and constraint
/// buffers), one step, then every priming body removed with its joints. The moving body is inserted
/// after this, so it never shares a step with them; the priming joints are solved with the world's passes
/// switched off (see [`RapierBody::new`]), which does not matter: only the buffers' allocation is kept.
fn prime_joint_buffers(world: &mut PhysicsWorld) {
    let unit = MassProperties::new(DVec3::ZERO, 1.0, DVec3::ONE);
    let far = |i: usize, y: f64| DVec3::new(1e3 + i as f64, y, 0.0);
    let mut bodies = Vec::with_capacity(2 * PRIMING_PAIRS + 1);
    let joint = |y: f64| FixedJointBuilder::new().local_anchor1(DVec3::new(0.0, y, 0.0)).build();
    for i in 0..PRIMING_PAIRS {
        let a = world.bodies.insert(RigidBodyBuilder::fixed().translation(far(i, 0.0)).build());
        let b = world
            .bodies
            .insert(RigidBodyBuilder::dynamic().translation(far(i, 1.0)).additional_mass_properties(unit).build());
        world.impulse_joints.insert(a, b, joint(1.0), true);
        bodies.extend([a, b]);
    }
    let extra = world.bodies.insert(RigidBodyBuilder::fixed().translation(far(0, 2.0)).build());
    world.impulse_joints.insert(extra, bodies[1], joint(-1.0), true);
    bodies.push(extra);
    world.step();
    for h in bodies {
        world.remove_body(h);
    }
}

/// The moving body integrated by vmt itself ([`Fidelity::Fast`]): the update rapier performs for a
/// dynamic body with no collider, joint or contact, written out (semi-implicit Euler, step dt):
///
/// ```text
/// v ← v + (F + m·g)/m · dt                         F: sum of the applied forces, N
/// ω ← ω + I_w⁻¹·τ · dt                             τ: their torque about the centre of mass c, N·m
/// ω ← gyroscopic correction (explicit −ω×Iω·dt, |L| preserved; rapier's per-substep pass)
/// q ← normalise((½ω·dt, 1) ⊗ q);  c ← c + v·dt    (linearised rotation, as rapier's integrator)
/// ```
///
/// with I_w⁻¹ = R·diag(1/I_p)·Rᵀ, R = q ∘ (principal frame); the principal decomposition is rapier's
/// (`MassProperties::with_inertia_matrix`), so both engines integrate the same numbers.
#[derive(Clone, Debug)]
struct FastBody {
    mprops: MassProperties,
    principal_inertia: DVec3,
    /// Orientation (of the body frame) and centre of mass, world frame.
    rot: DQuat,
    com: DVec3,
    linvel: DVec3,
    angvel: DVec3,
}

impl FastBody {
    fn step(&mut self, force: DVec3, torque: DVec3, dt: f64) {
        let mp = &self.mprops;
        self.linvel += (force + DVec3::new(0.0, 0.0, -GRAVITY) * (1.0 / mp.inv_mass)) * mp.inv_mass * dt;
        // The angular update in the principal frame A = R(q ∘ principal frame), one matrix for the three
        // rotations: w = Aᵀω + diag(1/I_p)·Aᵀτ·dt is Aᵀ of ω + I_w⁻¹·τ·dt (I_w⁻¹ = A·diag(1/I_p)·Aᵀ).
        let axes = DMat3::from_quat(self.rot * mp.principal_inertia_local_frame);
        let w = axes.mul_transpose_vec3(self.angvel) + mp.inv_principal_inertia * axes.mul_transpose_vec3(torque) * dt;
        // Gyroscopic correction, angular momentum magnitude preserved.
        let l = self.principal_inertia * w;
        let l_new = l - w.cross(l) * dt;
        let n2 = l_new.length_squared();
        self.angvel = if n2 != 0.0 {
            axes * (mp.inv_principal_inertia * (l_new * (l.length_squared() / n2).sqrt()))
        } else {
            axes * w
        };
        let h = self.angvel * (dt * 0.5);
        self.rot = (DQuat::from_xyzw(h.x, h.y, h.z, 1.0) * self.rot).normalize();
        self.com += self.linvel * dt;
    }

    fn state(&self) -> BodyState {
        let rot = DMat3::from_quat(self.rot);
        let origin = self.com - rot * self.mprops.local_com;
        BodyState {
            pose: Pose::from_parts(origin, self.rot),
            rot,
            com: self.com,
            linvel: self.linvel,
            angvel: self.angvel,
        }
    }
}

/// The moving body, in the engine the model's [`Fidelity`] selects.
enum Body {
    Reference(Box<RapierBody>),
    Fast(Box<FastBody>),
}

impl Body {
    fn new(fidelity: Fidelity, dt: f64, start: Pose, mprops: MassProperties) -> Body {
        match fidelity {
            Fidelity::Reference => Body::Reference(Box::new(RapierBody::new(dt, start, mprops, true))),
            Fidelity::Fast => Body::Fast(Box::new(FastBody {
                principal_inertia: mprops.principal_inertia(),
                rot: start.rotation,
                com: start * mprops.local_com,
                linvel: DVec3::ZERO,
                angvel: DVec3::ZERO,
                mprops,
            })),
        }
    }

    fn state(&self) -> BodyState {
        match self {
            Body::Reference(r) => {
                let rb = &r.world.bodies[r.handle];
                let pose = *rb.position();
                BodyState {
                    pose,
                    rot: DMat3::from_quat(pose.rotation),
                    com: rb.center_of_mass(),
                    linvel: rb.linvel(),
                    angvel: rb.angvel(),
                }
            }
            Body::Fast(f) => f.state(),
        }
    }

    /// Applies the force (N, at the centre of mass) and torque (N·m) for one step and advances dt;
    /// the rapier body is accessed mutably once.
    fn step(&mut self, force: DVec3, torque: DVec3, dt: f64) {
        match self {
            Body::Reference(r) => {
                let rb = &mut r.world.bodies[r.handle];
                rb.reset_forces(false);
                rb.reset_torques(false);
                rb.add_force(force, false);
                rb.add_torque(torque, false);
                r.world.step();
            }
            Body::Fast(f) => f.step(force, torque, dt),
        }
    }

    /// Adds dv to the velocity of the centre of mass, m/s.
    fn kick(&mut self, dv: DVec3) {
        match self {
            Body::Reference(r) => {
                let rb = &mut r.world.bodies[r.handle];
                let v = rb.linvel();
                rb.set_linvel(v + dv, true);
            }
            Body::Fast(f) => f.linvel += dv,
        }
    }
}

/// What the bearing blocks' spring-damper magnitudes a(b) = α + b·γ depend on in one step (see
/// [`AxisSim::step`]): the body's and the rest pose's rotations R and R_r and R − R_r, the offset o − o_r of
/// the body origin from its rest point (m), the origin's velocity relative to the rest point's (m/s), the
/// angular velocity ω (rad/s), the slope ε' of the angular error motions (rad/m) and the axis velocity q̇.
struct Bearing {
    rot: DMat3,
    rest_rot: DMat3,
    turn: DMat3,
    offset: DVec3,
    v_origin: DVec3,
    angvel: DVec3,
    deps: DVec3,
    q_dot: f64,
}

impl Bearing {
    /// (α, γ) of the blocks' magnitudes along the unit direction e with stiffness k (N/m) and damping c
    /// (N·s/m): α = k·(o − o_r)·e + c·v_o·e (N), γ = k·(R − R_r)ᵀ·e + c·(Rᵀ·(e × ω) − q̇·R_rᵀ·(e × ε')) (N/m).
    #[inline(always)]
    fn affine(&self, e: DVec3, k: f64, c: f64) -> (f64, DVec3) {
        let alpha = k * self.offset.dot(e) + c * self.v_origin.dot(e);
        let gamma = k * self.turn.mul_transpose_vec3(e)
            + c * (self.rot.mul_transpose_vec3(e.cross(self.angvel))
                - self.q_dot * self.rest_rot.mul_transpose_vec3(e.cross(self.deps)));
        (alpha, gamma)
    }
}

/// The mutable state of a simulation run of one axis.
pub struct AxisSim<'a> {
    model: &'a AxisModel,
    truth: &'a AxisTruth,
    body: Body,
    servo: ServoState,
    motor: Motor,
    /// LuGre bristle deflection, m.
    bristle: f64,
    /// Friction force of the last step on the body along the axis, N.
    friction_force: f64,
    /// The truth's guideway friction, its law checked once for the run ([`StribeckLaw::validate`],
    /// [`LugreParams::validate`]): a law that fails the check is no friction (the force stick_slip_step's
    /// or lugre_step's error gave).
    friction: GuideFriction,
    /// Structural mode state (displacement, velocity) and the reference point's last velocity.
    mode: (DVec3, DVec3),
    last_vel: Option<DVec3>,
    steps: u64,
    /// Session time at the start of this run, s: time-dependent effects see session_start + time().
    session_start: f64,
    ey: DVec3,
    ez: DVec3,
    /// The error motions and the lead error as this run's steps read them.
    profiles: StepProfiles,
    /// The feedback chain has no error ([`FeedbackErrors::is_zero`]): e(x, t) = 0 without evaluating it.
    feedback_zero: bool,
    /// The ball screw's constants a step reads, computed once ([`ScrewConstants`]); None for a linear motor.
    screw: Option<ScrewConstants>,
}

/// Constants of a ball-screw drive that each step uses, computed once per run from the model (the same
/// expressions, so the same values as computing them every step).
#[derive(Clone, Copy, Debug)]
struct ScrewConstants {
    /// Semi-closed loop (motor encoder feedback): the feedback chain's error moves the nut.
    semi: bool,
    /// Axial stiffness of the screw-nut contact, N/m.
    stiffness: f64,
    /// Axial damping of the screw-nut contact c = 2ζ·√(k·m), N·s/m (m: the moving mass).
    damping: f64,
    /// Rotor inertia as a linear mass m_r = J·(2π/lead)², kg.
    rotor_mass: f64,
    /// Mass the velocity loop drives: moving mass + rotor mass, kg.
    servo_mass: f64,
}

/// The profiles a step reads — the six error motions (ISO index 0..6: EXX, EYX, EZX, EAX, EBX, ECX), EXX
/// alone (the positioning chain) and the screw's lead error — tabulated ([`Tabulated`], value within
/// 1e-13, slope within 1e-11 of the exact profile) over the travel and a margin when the model's
/// fidelity is [`Fidelity::Fast`], exact otherwise (and wherever a table is not possible or the axis
/// leaves the domain). The fast engine evaluates every harmonic and random cosine once per run instead
/// of every step, and the six motions on one grid (one node index and one set of weights per step).
struct StepProfiles {
    /// The six error motions on one grid; one that cannot be tabulated is zero there and marked in `exact`.
    motions: Option<Tabulated<6>>,
    /// The motions evaluated exactly (not tabulable: a table term).
    exact: [bool; 6],
    /// EXX, for the positioning chain at positions other than the step's.
    positioning: Option<Tabulated>,
    /// The screw's lead error.
    lead: Option<Tabulated>,
}

impl StepProfiles {
    fn new(model: &AxisModel, truth: &AxisTruth) -> StepProfiles {
        let (lo, hi) = model.travel;
        let margin = 0.05 * (hi - lo).abs() + 0.01;
        let (lo, hi) = (lo - margin, hi + margin);
        let fast = match model.fidelity {
            Fidelity::Fast => true,
            Fidelity::Reference => false,
        };
        let m = &truth.motions;
        let exact = std::array::from_fn(|i| m.by_index(i).tabulation_step(lo, hi).is_none());
        let zero = Profile::default();
        let on_grid: [&Profile; 6] = std::array::from_fn(|i| if exact[i] { &zero } else { m.by_index(i) });
        let table = |p: &Profile| if fast && !p.is_zero() { p.tabulate(lo, hi) } else { None };
        StepProfiles {
            motions: if fast && exact.contains(&false) { Tabulated::of(on_grid, lo, hi) } else { None },
            exact,
            positioning: table(&m.positioning),
            lead: table(&truth.lead_error),
        }
    }

    /// Value and slope of a profile (`exact` is the profile itself, `table` its table if any) at x.
    #[inline(always)]
    fn eval2(table: Option<&Tabulated>, exact: &Profile, x: f64) -> [f64; 2] {
        if let Some(v) = table.and_then(|t| t.eval2(x)) {
            return v;
        }
        StepProfiles::exact2(exact, x)
    }

    /// Value and slope of the exact profile at x (no table, or x outside it; [0, 0] for a zero profile):
    /// kept out of line, so the table lookup above stays small where it is inlined. Marked cold: with
    /// the fast engine's tables it runs only for zero profiles (a quick return) or off the travel
    /// (measured: the physical study's step takes 1.7 % fewer instructions than testing for a zero
    /// profile before every lookup).
    #[cold]
    #[inline(never)]
    fn exact2(exact: &Profile, x: f64) -> [f64; 2] {
        if exact.is_zero() {
            return [0.0; 2];
        }
        let e = exact.eval3(x);
        [e[0], e[1]]
    }

    /// The six error motions and their slopes at x ([`ErrorMotions::at`]).
    fn motions_at(&self, m: &ErrorMotions, x: f64) -> MotionsAt {
        match self.motions.as_ref().and_then(|t| t.eval2_all(x)) {
            Some(v) => m.at_with(|i, exact| if self.exact[i] { StepProfiles::exact2(exact, x) } else { v[i] }),
            None => m.at_with(|_, exact| StepProfiles::exact2(exact, x)),
        }
    }
}

impl<'a> AxisSim<'a> {
    /// A run starting at rest at axis position x0, the body placed on its rest pose lowered by the static
    /// sag of the bearings under gravity.
    pub fn new(model: &'a AxisModel, truth: &'a AxisTruth, x0: f64) -> AxisSim<'a> {
        AxisSim::in_session(model, truth, x0, 0.0)
    }

    /// As [`AxisSim::new`], for a run that starts `session_start` s into the measurement session: the
    /// time-dependent effects of the feedback chain (thermal expansion, thermal drift) are evaluated at
    /// session time session_start + t.
    pub fn in_session(model: &'a AxisModel, truth: &'a AxisTruth, x0: f64, session_start: f64) -> AxisSim<'a> {
        let ey = model.axis_rotation * DVec3::Y;
        let ez = model.axis_rotation * DVec3::Z;
        let x_act0 = x0 + truth.motions.positioning.value(x0) + truth.feedback.error(x0, session_start);
        let rest = model.rest_pose(&truth.motions, x0);
        let sag = -ez.z * model.mass * GRAVITY / (model.blocks.len() as f64 * model.k_z);
        let start = rest.translation + model.axis * (x_act0 - x0) + DVec3::new(0.0, 0.0, sag);
        let mprops = MassProperties::with_inertia_matrix(model.com, model.mass, model.inertia);
        let body = Body::new(model.fidelity, model.dt, Pose::from_parts(start, rest.rotation), mprops);
        let mut sim = AxisSim {
            model,
            truth,
            body,
            servo: ServoState::default(),
            motor: Motor::default(),
            bristle: 0.0,
            friction_force: 0.0,
            friction: match &truth.friction {
                GuideFriction::Stribeck(p) if p.validate().is_err() => GuideFriction::None,
                GuideFriction::LuGre(p) if p.validate().is_err() => GuideFriction::None,
                f @ (GuideFriction::None | GuideFriction::Stribeck(_) | GuideFriction::LuGre(_)) => f.clone(),
            },
            mode: (DVec3::ZERO, DVec3::ZERO),
            last_vel: None,
            steps: 0,
            session_start,
            ey,
            ez,
            profiles: StepProfiles::new(model, truth),
            feedback_zero: truth.feedback.is_zero(),
            screw: match &model.drive {
                DriveConfig::BallScrew(b) => Some(ScrewConstants {
                    semi: b.feedback == FeedbackKind::Rotary,
                    stiffness: b.stiffness,
                    damping: 2.0 * b.damping_ratio * (b.stiffness * model.mass).sqrt(),
                    rotor_mass: b.rotor_mass(),
                    servo_mass: model.mass + b.rotor_mass(),
                }),
                DriveConfig::LinearMotor => None,
            },
        };
        // The motor starts where the nut sits on the body, in contact on the + side of the clearance.
        sim.motor.u = sim.motor_rest_position();
        sim
    }

    /// Motor position that puts the screw unloaded against the nut at the current body position.
    fn motor_rest_position(&self) -> f64 {
        let x = self.axis_coordinate(&self.body.state().pose);
        match &self.model.drive {
            DriveConfig::BallScrew(b) if b.feedback == FeedbackKind::Rotary => {
                // u + e(u) + lead(u) = x: one fixed-point pass is exact to second order in the errors.
                let e = |u: f64| self.chain_error(u) + self.lead_error(u);
                x - e(x - e(x)) + 0.5 * self.truth.backlash
            }
            DriveConfig::BallScrew(_) => x - self.lead_error(x) + 0.5 * self.truth.backlash,
            DriveConfig::LinearMotor => x,
        }
    }

    /// Adds a velocity change to the body at its centre of mass (an impulse-hammer test), m/s.
    pub fn kick(&mut self, dv: DVec3) {
        self.body.kick(dv);
    }

    /// Time of the current state, s.
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.model.dt
    }

    /// Actual axis coordinate of the reference point (m): axis · (origin − home).
    fn axis_coordinate(&self, pose: &Pose) -> f64 {
        self.model.axis.dot(pose.translation - self.model.home.translation)
    }

    /// Error of the positioning chain at x now: EXX(x) + feedback-chain error e(x, t), m.
    #[inline]
    fn chain_error(&self, x: f64) -> f64 {
        let e = if self.feedback_zero { 0.0 } else { self.truth.feedback.error(x, self.session_start + self.time()) };
        StepProfiles::eval2(self.profiles.positioning.as_ref(), &self.truth.motions.positioning, x)[0] + e
    }

    /// Lead error of the screw at screw position u, m.
    fn lead_error(&self, u: f64) -> f64 {
        StepProfiles::eval2(self.profiles.lead.as_ref(), &self.truth.lead_error, u)[0]
    }

    /// Nominal axis position (what the machine believes) for a table at x: x − EXX(x) − e(x, t).
    fn nominal(&self, x_actual: f64) -> f64 {
        x_actual - self.chain_error(x_actual)
    }

    /// Position feedback before quantisation, given the nominal position q of the table: the scale
    /// (linear motor, closed loop) or the motor (semi-closed loop), plus the CNC's compensation c(x).
    fn raw_feedback(&self, q: f64) -> f64 {
        let fb = match &self.model.drive {
            DriveConfig::BallScrew(b) => match b.feedback {
                FeedbackKind::Rotary => self.motor.u,
                FeedbackKind::Linear => q,
            },
            DriveConfig::LinearMotor => q,
        };
        if self.model.compensation.is_zero() {
            fb
        } else {
            fb + self.model.compensation.value(fb)
        }
    }

    /// Current truth sample.
    pub fn sample(&self, cmd: Command) -> Sample {
        let st = self.body.state();
        let pose = st.pose;
        let q = self.nominal(self.axis_coordinate(&pose));
        let res = self.model.servo.resolution;
        let scale = quantise(q, res);
        Sample {
            t: self.time(),
            cmd,
            feedback: quantise(self.raw_feedback(q), res),
            scale,
            motor: match self.model.drive {
                DriveConfig::LinearMotor => scale,
                DriveConfig::BallScrew(_) => quantise(self.motor.u, res),
            },
            force: self.servo.force,
            friction: self.friction_force,
            pos: pose.translation,
            rot: (pose.rotation * self.model.home.rotation.inverse()).to_scaled_axis(),
            vel: st.velocity_at_point(pose.translation),
            angvel: st.angvel,
            mode: self.mode.0,
            mode_vel: self.mode.1,
        }
    }

    /// Advances one physics step with the command `cmd` (servo updated every `servo_steps`).
    pub fn step(&mut self, cmd: Command) {
        let m = self.model;
        let ts = m.dt * m.servo_steps as f64;
        let st = self.body.state();
        let pose = st.pose;
        let x_act = self.axis_coordinate(&pose);
        let q_dot = m.axis.dot(st.velocity_at_point(pose.translation));
        let q = self.nominal(x_act);
        if self.steps.is_multiple_of(m.servo_steps as u64) {
            let fb = quantise(self.raw_feedback(q), m.servo.resolution);
            // Velocity loop on the motor encoder for a ball screw, on the scale for a linear motor.
            let (vel_fb, mass) = match self.screw {
                Some(sc) => (quantise(self.motor.u, m.servo.resolution), sc.servo_mass),
                None => (fb, m.mass),
            };
            servo_update(&m.servo, &mut self.servo, mass, ts, cmd.pos, cmd.vel, cmd.acc, fb, vel_fb);
        }
        // Every error motion evaluated once per step: value (rest pose) and slope (its velocity).
        let at = self.profiles.motions_at(&self.truth.motions, q);
        let rest = m.rest_pose_at(&at, q);
        let (de, deps) = (m.axis_to_world(at.translation_slope), m.axis_to_world(at.rotation_slope));
        // Drive force on the body at the nut, and the motor's own motion.
        let f_drive = match self.screw {
            None => self.servo.force,
            Some(sc) => {
                let u = self.motor.u;
                let nut_free = u + self.lead_error(u) + if sc.semi { self.chain_error(u) } else { 0.0 };
                let nut_x = x_act; // the nut rides on the body: its axial coordinate moves with the reference point
                let f = dead_zone_force(
                    nut_free - nut_x,
                    self.motor.u_dot - q_dot,
                    self.truth.backlash,
                    sc.stiffness,
                    sc.damping,
                );
                let m_r = sc.rotor_mass;
                self.motor.u_dot += (self.servo.force - f) / m_r * m.dt;
                self.motor.u += self.motor.u_dot * m.dt;
                f
            }
        };
        let f_axis = f_drive - m.axis_damping * q_dot;
        let f_friction = match &self.friction {
            GuideFriction::None => 0.0,
            GuideFriction::Stribeck(p) => {
                // The law was checked when the run started (`friction`); the model's mass and dt are > 0
                // (AxisModel::build); a non-finite state gets no friction force, as stick_slip_step's
                // error did.
                let input = StepInput { v: q_dot, f_ext: f_axis, mass: m.mass, dt: m.dt, stick_band: STICK_BAND };
                if q_dot.is_finite() && f_axis.is_finite() {
                    stick_slip_force(p, &input)
                } else {
                    0.0
                }
            }
            // The parameters were checked when the run started (`friction`), dt > 0 (AxisModel::build) and
            // the bristle state is finite (it starts at 0 and each step from finite inputs keeps it
            // finite); a non-finite velocity gets no friction force and leaves the bristles as they are,
            // as lugre_step's error did.
            GuideFriction::LuGre(p) => {
                if q_dot.is_finite() {
                    let st = lugre_step_unchecked(p, self.bristle, q_dot, m.dt);
                    self.bristle = st.z_next;
                    st.force_on_body
                } else {
                    0.0
                }
            }
        };
        self.friction_force = f_friction;
        // Bearing block i at body point b_i pushes back along e_y and e_z by the spring-damper magnitudes
        // a_i = k·d_i·e + c·Δv_i·e (k, c, e: k_y, c_y, e_y or k_z, c_z, e_z), with d_i its offset from its
        // rest point and Δv_i its velocity relative to the rest point's. With R, R_r the body's and the
        // rest pose's rotations, o, o_r their origins, c_m the centre of mass, v, ω the body's velocities:
        //   d_i  = (o − o_r) + (R − R_r)·b_i
        //   Δv_i = v + ω × (o − c_m + R·b_i) − q̇·(x̂ + E' + ε' × R_r·b_i)
        // so a_i = α + b_i·γ is affine in b_i (scalar triple products moved onto b_i):
        //   α = k·(o − o_r)·e + c·(v + ω × (o − c_m) − q̇·(x̂ + E'))·e
        //   γ = k·(R − R_r)ᵀ·e + c·(Rᵀ·(e × ω) − q̇·R_rᵀ·(e × ε'))
        // The blocks' force is −(Σa_i·e_y + Σa_i·e_z) and their torque −((Σa_i·r_i) × e_y + …) about c_m,
        // with the arms r_i = (o − c_m) + R·b_i: Σa_i·r_i = (Σa_i)·(o − c_m) + R·(Σa_i·b_i).
        let (rot, rest_rot) = (st.rot, DMat3::from_quat(rest.rotation));
        let origin_arm = pose.translation - st.com;
        let (offset, v_origin) =
            (pose.translation - rest.translation, st.linvel + st.angvel.cross(origin_arm) - q_dot * (m.axis + de));
        let bearing = Bearing { rot, rest_rot, turn: rot - rest_rot, offset, v_origin, angvel: st.angvel, deps, q_dot };
        let ((alpha_y, gamma_y), (alpha_z, gamma_z)) =
            (bearing.affine(self.ey, m.k_y, m.c_y), bearing.affine(self.ez, m.k_z, m.c_z));
        let (mut sum_y, mut sum_z, mut first_y, mut first_z) = (0.0, 0.0, DVec3::ZERO, DVec3::ZERO);
        for b in &m.blocks {
            let (a_y, a_z) = (alpha_y + b.dot(gamma_y), alpha_z + b.dot(gamma_z));
            (sum_y, sum_z) = (sum_y + a_y, sum_z + a_z);
            (first_y, first_z) = (first_y + a_y * *b, first_z + a_z * *b);
        }
        let (moment_y, moment_z) = (sum_y * origin_arm + rot * first_y, sum_z * origin_arm + rot * first_z);
        let mut force = -(sum_y * self.ey + sum_z * self.ez);
        let mut torque = -(moment_y.cross(self.ey) + moment_z.cross(self.ez));
        let mut add = |f: DVec3, arm: DVec3| {
            force += f;
            torque += arm.cross(f);
        };
        add(m.axis * f_axis, origin_arm + rot * m.nut);
        // Guideway friction acts in the plane of the bearing blocks, at the reference point.
        add(m.axis * f_friction, origin_arm);
        self.body.step(force, torque, m.dt);
        self.steps += 1;
        if let Some(md) = &self.truth.mode {
            // Base excitation from the reference point's acceleration over the step; semi-implicit Euler.
            let st = self.body.state();
            let v = st.velocity_at_point(st.pose.translation);
            let a_base = self.last_vel.map_or(DVec3::ZERO, |v0| (v - v0) / m.dt);
            self.last_vel = Some(v);
            let w = std::f64::consts::TAU * md.frequency;
            let (q, qd) = &mut self.mode;
            *qd += (-a_base - 2.0 * md.damping * w * *qd - w * w * *q) * m.dt;
            *q += *qd * m.dt;
        }
    }
}

/// Simulates a motion plan and returns the truth sampled at `record_times` (s, increasing), linearly
/// interpolated between physics steps.
pub fn simulate(model: &AxisModel, truth: &AxisTruth, plan: &MotionPlan, record_times: &[f64]) -> Trace {
    simulate_in_session(model, truth, plan, record_times, 0.0)
}

/// As [`simulate`], for a run that starts `session_start` s into the measurement session (the
/// recorded times stay relative to the run's start).
pub fn simulate_in_session(
    model: &AxisModel,
    truth: &AxisTruth,
    plan: &MotionPlan,
    record_times: &[f64],
    session_start: f64,
) -> Trace {
    let x0 = plan.at(0.0).pos;
    let mut sim = AxisSim::in_session(model, truth, x0, session_start);
    let t_end = record_times.last().copied().unwrap_or(0.0).max(0.0);
    let mut out = Vec::with_capacity(record_times.len());
    let mut next = 0;
    let prev = sim.sample(plan.at(0.0));
    while next < record_times.len() && record_times[next] <= prev.t {
        out.push(Sample { t: record_times[next], cmd: plan.recorded_at(0.0), ..prev });
        next += 1;
    }
    // `prev` is the truth sample before the step when a record time falls within it; samples are taken
    // only around record times (the same values as sampling every step: the state is the same).
    let mut prev = Some(prev);
    while next < record_times.len() && sim.time() <= t_end + model.dt {
        let cmd = plan.at(sim.time());
        let records = record_times[next] <= (sim.steps + 1) as f64 * model.dt;
        if !records {
            prev = None;
            sim.step(cmd);
            continue;
        }
        let before = prev.take().unwrap_or_else(|| sim.sample(cmd));
        sim.step(cmd);
        let cur = sim.sample(plan.at(sim.time()));
        while next < record_times.len() && record_times[next] <= cur.t {
            let tr = record_times[next];
            let w = (tr - before.t) / (cur.t - before.t);
            let mut s = before.lerp(&cur, w);
            s.cmd = plan.recorded_at(tr);
            out.push(s);
            next += 1;
        }
        prev = Some(cur);
    }
    Trace { samples: out }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`prime_joint_buffers`] is a speed measure only: a primed and an unprimed rapier body given the same
    /// forces and torques (varying every step, as the servo's and the bearings' do) stay bit-identical.
    #[test]
    fn priming_leaves_the_reference_trajectory_bit_identical() {
        let mprops = MassProperties::with_inertia_matrix(
            DVec3::new(0.01, -0.02, 0.3),
            120.0,
            DMat3::from_diagonal(DVec3::new(9.0, 7.0, 4.0)),
        );
        let start = Pose::from_parts(DVec3::new(0.2, 0.0, 0.5), DQuat::from_scaled_axis(DVec3::new(1e-5, -2e-5, 3e-5)));
        let mut bodies =
            [true, false].map(|prime| Body::Reference(Box::new(RapierBody::new(1e-4, start, mprops, prime))));
        for i in 0..3000 {
            let t = i as f64 * 1e-4;
            let force =
                DVec3::new(50.0 * (40.0 * t).sin(), 3.0 * (90.0 * t).cos(), 120.0 * GRAVITY + 5.0 * (7.0 * t).sin());
            let torque = DVec3::new(0.2 * (30.0 * t).cos(), -0.1 * (11.0 * t).sin(), 0.05 * t);
            for b in &mut bodies {
                b.step(force, torque, 1e-4);
            }
        }
        let [primed, plain] = bodies.map(|b| b.state());
        let bits = |s: &BodyState| {
            let p = s.pose.translation;
            let q = s.pose.rotation;
            [p.x, p.y, p.z, q.x, q.y, q.z, q.w, s.linvel.x, s.linvel.y, s.linvel.z, s.angvel.x, s.angvel.y, s.angvel.z]
                .map(f64::to_bits)
        };
        assert_eq!(bits(&primed), bits(&plain));
        // The body did move (the comparison is not of two resting states).
        assert!((primed.pose.translation - start.translation).length() > 1e-3, "{:?}", primed.pose.translation);
    }
}
