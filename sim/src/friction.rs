//! Friction elements for the simulator's explicit fixed-step integrator (DESIGN.md §4).
//!
//! Models, all forces in N, velocities in m/s, displacements in m:
//! - Stribeck (Armstrong-Hélouvry 1991 form with shape exponent δ):
//!   F = sgn(v)·[Fc + (Fs − Fc)·exp(−|v/vs|^δ)] + Fv·v — the one [`StribeckLaw`] of vmt, defined in the
//!   crate `vmt-core` that the estimators fit too; Coulomb (F = Fc·sgn(v), [`StribeckLaw::coulomb`])
//!   and viscous (F = Fv·v, Fc = Fs = 0) friction are its special cases;
//! - LuGre (Canudas de Wit, Olsson, Åström, Lischinsky 1995, "A new model for control of systems
//!   with friction", IEEE TAC 40(3):419–425):
//!   dz/dt = v − σ0·|v|/g(v)·z,  g(v) = Fc + (Fs − Fc)·exp(−|v/vs|^δ),
//!   F = σ0·z + σ1·dz/dt + σ2·v   (the paper uses δ = 2).
//!
//! Sign convention: the functions named `*_force` return the friction force the surface exerts
//! on the moving body *in the direction opposing motion as a positive number for positive v*, i.e.
//! the steady-state curves F(v) above (odd in v). The step functions for the integrator
//! ([`stick_slip_step`], [`lugre_step`]) return the force *acting on the body* along +x (so for
//! sliding at v > 0 it is negative); they say so in their doc comments.
//!
//! Integrator contract (DESIGN.md §4): a semi-implicit Euler step of length dt
//! (v_{n+1} = v_n + dt·(F_ext + F_friction)/m, x_{n+1} = x_n + dt·v_{n+1}); the friction force for the
//! step is computed from the state at the start of the step.

use serde::{Deserialize, Serialize};
use vmt_core::friction::check;
pub use vmt_core::friction::{stribeck_weight, FrictionError, StribeckLaw};

/// LuGre friction (Canudas de Wit et al. 1995):
/// dz/dt = v − σ0·|v|/g(v)·z, g(v) = Fc + (Fs − Fc)·exp(−|v/vs|^δ), F = σ0·z + σ1·dz/dt + σ2·v:
/// the bristles (σ0, σ1) on the one Stribeck law of vmt, whose steady state it is (Fc, Fs, vs, δ
/// and Fv = σ2).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LugreParams {
    /// Bristle stiffness σ0, N/m (> 0).
    pub sigma0: f64,
    /// Bristle (micro-)damping σ1, N·s/m (≥ 0).
    pub sigma1: f64,
    /// The steady state: Fc (N, > 0), Fs (N, ≥ Fc), vs (m/s, > 0), δ (> 0; 2 in the 1995 paper,
    /// exp(−(v/vs)²)) and the viscous coefficient σ2 = Fv (N·s/m, ≥ 0).
    pub steady: StribeckLaw,
}

impl LugreParams {
    /// Checks σ0 > 0, σ1 ≥ 0, σ2 ≥ 0, 0 < Fc ≤ Fs, vs > 0, δ > 0, all finite.
    pub fn validate(&self) -> Result<(), FrictionError> {
        let s = &self.steady;
        check("sigma0", self.sigma0, self.sigma0 > 0.0, "finite and > 0 N/m")?;
        check("sigma1", self.sigma1, self.sigma1 >= 0.0, "finite and >= 0 N*s/m")?;
        check("sigma2", s.fv, s.fv >= 0.0, "finite and >= 0 N*s/m")?;
        check("fc", s.fc, s.fc > 0.0, "finite and > 0 N")?;
        check("fs", s.fs, s.fs >= s.fc, "finite and >= fc")?;
        check("vs", s.vs, s.vs > 0.0, "finite and > 0 m/s")?;
        check("delta", s.delta, s.delta > 0.0, "finite and > 0")
    }

    /// The parameters of the 1995 paper (Table I): σ0 = 1e5 N/m, σ1 = √1e5 N·s/m, σ2 = 0.4 N·s/m,
    /// Fc = 1 N, Fs = 1.5 N, vs = 1e-3 m/s, δ = 2.
    pub fn canudas1995() -> LugreParams {
        LugreParams {
            sigma0: 1e5,
            sigma1: 1e5f64.sqrt(),
            steady: StribeckLaw { fc: 1.0, fs: 1.5, vs: 1e-3, delta: 2.0, fv: 0.4 },
        }
    }
}

/// Steady-state friction at constant velocity v (m/s), the Stribeck curve (DESIGN.md §4):
/// F(v) = sgn(v)·[Fc + (Fs − Fc)·exp(−|v/vs|^δ)] + Fv·v, N, opposing the motion (F has the sign
/// of v). At v = 0 exactly the static force is undetermined in [−Fs, Fs]; this returns 0.
/// This is what a friction sweep (constant velocities, both directions) measures.
pub fn stribeck_force(p: &StribeckLaw, v: f64) -> Result<f64, FrictionError> {
    p.validate()?;
    check("v", v, true, "a finite velocity in m/s")?;
    Ok(p.force(v))
}

/// Steady-state friction of the LuGre model at constant velocity v (m/s), N:
/// with dz/dt = 0, z = sgn(v)·g(v)/σ0, so F = sgn(v)·g(v) + σ2·v (Canudas de Wit 1995, eq. 6).
pub fn lugre_steady_state_force(p: &LugreParams, v: f64) -> Result<f64, FrictionError> {
    p.validate()?;
    check("v", v, true, "a finite velocity in m/s")?;
    Ok(p.steady.force(v))
}

/// Inputs of one integrator step for a friction element with sticking.
///
/// For a multi-DOF body, project onto the sliding direction: `v` is the body's velocity along it,
/// `f_ext` the sum of all other forces projected on it, and `mass` the effective (reflected) mass
/// along it, m_eff = 1/(dᵀ·M⁻¹·d) for unit direction d and mass matrix M (for a translating rigid
/// body simply its mass; add the reflected rotor inertia J·(2π/lead)² for a screw-driven axis).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepInput {
    /// Velocity along the sliding direction at the start of the step, m/s.
    pub v: f64,
    /// Sum of the other forces on the body along the sliding direction for this step, N.
    pub f_ext: f64,
    /// Effective mass along the sliding direction, kg (> 0).
    pub mass: f64,
    /// Step length, s (> 0), e.g. 1e-4.
    pub dt: f64,
    /// Stick band, m/s (≥ 0): |v| ≤ this counts as "at rest" (Karnopp 1985). 0 is right for a
    /// 1-DOF integrator (the element stops the body at exactly 0); a coupled multi-DOF solver that
    /// leaves a tiny residual velocity may use e.g. 1e-7 m/s.
    pub stick_band: f64,
}

impl StepInput {
    fn validate(&self) -> Result<(), FrictionError> {
        // All conditions at once for the common case (checked every physics step); a failure goes
        // through the named checks below for the message.
        let finite = [self.v, self.f_ext, self.mass, self.dt, self.stick_band].iter().all(|v| v.is_finite());
        if finite && self.mass > 0.0 && self.dt > 0.0 && self.stick_band >= 0.0 {
            return Ok(());
        }
        check("v", self.v, true, "a finite velocity in m/s")?;
        check("f_ext", self.f_ext, true, "a finite force in N")?;
        check("mass", self.mass, self.mass > 0.0, "finite and > 0 kg")?;
        check("dt", self.dt, self.dt > 0.0, "finite and > 0 s")?;
        check("stick_band", self.stick_band, self.stick_band >= 0.0, "finite and >= 0 m/s")
    }
}

/// Friction force on the body for one explicit step, with TRUE STICKING (no tanh smear):
/// a Karnopp-style stick/slip switch on the Stribeck curve. Returns the force acting on the body
/// along +x, N (negative when sliding at v > 0).
///
/// Rule (m = effective mass, F_ext = other forces, semi-implicit Euler v' = v + dt·(F_ext + F)/m):
/// 1. The sticking force is the force that makes the end-of-step velocity exactly zero:
///    F_stick = −(m·v/dt + F_ext).
/// 2. At rest (|v| ≤ stick band): F = clamp(F_stick, −Fs, +Fs). If |F_stick| ≤ Fs the body stays
///    exactly at rest (v' = 0, so the displacement over the step is exactly 0); otherwise it breaks
///    away with the static force Fs opposing the would-be motion.
/// 3. Sliding (|v| > stick band): F_slide = −[sgn(v)·g(v) + Fv·v] (the Stribeck curve). If the
///    velocity would change sign within the step (v' = v + dt·(F_ext + F_slide)/m has the opposite
///    sign of v, or is zero), the body is stopped at zero instead of overshooting:
///    F = clamp(F_stick, −Fs, +Fs) (so a reversal only happens if |F_stick| > Fs, i.e. the other
///    forces exceed the static level). Otherwise F = F_slide.
///
/// Coulomb friction uses this with Fs = Fc ([`StribeckLaw::coulomb`]).
pub fn stick_slip_step(p: &StribeckLaw, input: &StepInput) -> Result<f64, FrictionError> {
    p.validate()?;
    input.validate()?;
    Ok(stick_slip_force(p, input))
}

/// The force of [`stick_slip_step`] (N, on the body along +x) for a law and an input its checks
/// accept ([`StribeckLaw::validate`]; v, F_ext finite, m > 0, dt > 0, stick band ≥ 0), without
/// checking them again: a simulator checks its law once per run instead of every step.
pub(crate) fn stick_slip_force(p: &StribeckLaw, input: &StepInput) -> f64 {
    let StepInput { v, f_ext, mass, dt, stick_band } = *input;
    let f_stick = -(mass * v / dt + f_ext);
    // clamp: the law is valid (caller's contract): fs finite and ≥ fc ≥ 0, so −fs ≤ fs.
    let stuck = f_stick.clamp(-p.fs, p.fs);
    if v.abs() <= stick_band {
        return stuck;
    }
    let f_slide = -p.force(v);
    let v_next = v + dt * (f_ext + f_slide) / mass;
    if v_next * v <= 0.0 {
        stuck
    } else {
        f_slide
    }
}

/// Result of one LuGre step.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LugreStep {
    /// Bristle deflection at the end of the step, m.
    pub z_next: f64,
    /// Mean bristle rate over the step, (z_next − z)/dt, m/s.
    pub dz_dt: f64,
    /// Friction force on the body along +x for the step, N: −(σ0·z̄ + σ1·dz/dt + σ2·v), with z̄ the
    /// mean of z over the step.
    pub force_on_body: f64,
}

/// One step of the LuGre model (Canudas de Wit et al. 1995) at the velocity v (m/s) of the start of
/// the step, from bristle state z (m), over dt (s).
///
/// Update of z: with v held fixed over the step, dz/dt = v − a·z with a = σ0·|v|/g(v) (1/s) is a
/// linear ODE, integrated EXACTLY:
///   z(t) = z_ss + (z − z_ss)·e^{−a·t},  z_ss = v/a = sgn(v)·g(v)/σ0,
/// evaluated as z_next = z·e^{−a·dt} + v·dt·φ(a·dt), φ(x) = (1 − e^{−x})/x (φ(0) = 1, via expm1), so it
/// is unconditionally stable and exact for any a·dt — explicit Euler on z needs a·dt < 2, which the
/// paper's parameters violate (a ≈ σ0·|v|/Fc ≈ 4e4 1/s at 0.4 m/s, a·dt ≈ 4 at dt = 1e-4 s).
/// The force is the exact time mean over the step at fixed v:
///   F = σ0·z̄ + σ1·(z_next − z)/dt + σ2·v,  z̄ = z_ss + (z − z_ss)·φ(a·dt),
/// and `force_on_body` = −F. The remaining explicit coupling (v frozen over the step) needs
/// (σ1 + σ2)·dt/m < 2 and √(σ0/m)·dt ≪ 1 for the body's integrator — 0.03 for the paper's 1 kg.
pub fn lugre_step(p: &LugreParams, z: f64, v: f64, dt: f64) -> Result<LugreStep, FrictionError> {
    p.validate()?;
    check("z", z, true, "a finite bristle deflection in m")?;
    check("v", v, true, "a finite velocity in m/s")?;
    check("dt", dt, dt > 0.0, "finite and > 0 s")?;
    Ok(lugre_step_unchecked(p, z, v, dt))
}

/// The step of [`lugre_step`] for parameters and inputs its checks accept ([`LugreParams::validate`]; z, v
/// finite, dt > 0), without checking them again: a simulator checks its law once per run instead of
/// every step.
///
/// e^{−x} and 1 − e^{−x} (x = a·dt) come from one transcendental: below ln 2 from expm1, e^{−x} =
/// 1 + expm1(−x) (≥ 1/2, within an ulp); from ln 2 on from exp, 1 − e^{−x} (≥ 1/2, within an ulp).
/// Each is as accurate as evaluating both exp and expm1; the last bits of z and F can differ from that.
pub(crate) fn lugre_step_unchecked(p: &LugreParams, z: f64, v: f64, dt: f64) -> LugreStep {
    let g = p.steady.level(v);
    let a = p.sigma0 * v.abs() / g;
    let x = a * dt;
    let (decay, one_minus_decay) = if x < std::f64::consts::LN_2 {
        let em = (-x).exp_m1();
        (1.0 + em, -em)
    } else {
        let e = (-x).exp();
        (e, 1.0 - e)
    };
    // φ(x) = (1 − e^{−x})/x, accurate for small x.
    let phi = if x < 1e-12 { 1.0 - 0.5 * x } else { one_minus_decay / x };
    let z_next = z * decay + v * dt * phi;
    // Mean of z over the step: (1/dt)∫ z dt = z_ss + (z − z_ss)·φ; written without z_ss (a may be 0)
    // as z·φ + v·dt·(1 − φ)/x, and (1 − φ)/x → 1/2 for x → 0.
    let one_minus_phi_over_x = if x < 1e-6 { 0.5 - x / 6.0 } else { (1.0 - phi) / x };
    let z_mean = z * phi + v * dt * one_minus_phi_over_x;
    let dz_dt = (z_next - z) / dt;
    let force = p.sigma0 * z_mean + p.sigma1 * dz_dt + p.steady.fv * v;
    LugreStep { z_next, dz_dt, force_on_body: -force }
}

/// A 1-DOF mass–spring–friction trajectory sample (the Canudas de Wit 1995 stick-slip experiment).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpringPullSample {
    /// Time, s.
    pub t: f64,
    /// Mass position, m.
    pub x: f64,
    /// Mass velocity, m/s.
    pub v: f64,
    /// Friction force (opposing motion, positive for v > 0), N.
    pub friction: f64,
}

/// Simulates the stick-slip experiment of Canudas de Wit et al. 1995 (Fig. 2): a mass m (kg) on a
/// LuGre contact, pulled through a spring of stiffness k (N/m) whose free end moves at constant
/// speed `pull_speed` (m/s) from x = 0 at t = 0: m·ẍ = k·(pull_speed·t − x) − F_LuGre.
/// Semi-implicit Euler with step dt (s) for `duration` (s), LuGre updated by [`lugre_step`];
/// returns one sample every `every` steps (≥ 1), starting at t = 0.
pub fn lugre_spring_pull(
    p: &LugreParams,
    mass: f64,
    k: f64,
    pull_speed: f64,
    dt: f64,
    duration: f64,
    every: usize,
) -> Result<Vec<SpringPullSample>, FrictionError> {
    p.validate()?;
    check("mass", mass, mass > 0.0, "finite and > 0 kg")?;
    check("k", k, k >= 0.0, "finite and >= 0 N/m")?;
    check("pull_speed", pull_speed, true, "a finite speed in m/s")?;
    check("dt", dt, dt > 0.0, "finite and > 0 s")?;
    check("duration", duration, duration >= 0.0 && duration / dt < 1e9, "finite, >= 0 s and at most 1e9 steps")?;
    check("every", every as f64, every >= 1, ">= 1")?;
    // index: 0 ≤ duration/dt < 1e9 by the checks above: a bounded step count.
    let n = (duration / dt).round() as usize;
    let (mut x, mut v, mut z) = (0.0f64, 0.0f64, 0.0f64);
    let mut out = Vec::with_capacity(n / every + 1);
    for i in 0..=n {
        let t = i as f64 * dt;
        let step = lugre_step(p, z, v, dt)?;
        if i % every == 0 {
            out.push(SpringPullSample { t, x, v, friction: -step.force_on_body });
        }
        let f_spring = k * (pull_speed * t - x);
        v += dt * (f_spring + step.force_on_body) / mass;
        x += dt * v;
        z = step.z_next;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> StribeckLaw {
        StribeckLaw { fc: 10.0, fs: 15.0, vs: 0.01, delta: 2.0, fv: 50.0 }
    }

    #[test]
    fn stribeck_curve_hand_worked_values() {
        // v = vs: g = 10 + 5·e^{-1} = 11.839397; + 50·0.01 = 0.5 → 12.339397 (hand-worked).
        let f = stribeck_force(&p(), 0.01).unwrap();
        assert!((f - (10.0 + 5.0 * (-1.0f64).exp() + 0.5)).abs() < 1e-12);
        // Odd in v (exact by construction).
        assert_eq!(stribeck_force(&p(), -0.01).unwrap(), -f);
        // Far above vs the Stribeck term vanishes: 10 + 50·1 = 60 (e^{-10000} underflows to 0).
        assert_eq!(stribeck_force(&p(), 1.0).unwrap(), 60.0);
    }

    #[test]
    fn bad_parameters_are_rejected_with_a_message() {
        let mut q = p();
        q.fs = 5.0;
        let e = stribeck_force(&q, 0.1).unwrap_err().to_string();
        assert!(e.contains("fs") && e.contains(">= fc"), "{e}");
        q = p();
        q.vs = f64::NAN;
        assert!(stribeck_force(&q, 0.1).is_err());
        assert!(stribeck_force(&p(), f64::NAN).is_err());
        let inp = StepInput { v: 0.0, f_ext: 1.0, mass: 0.0, dt: 1e-4, stick_band: 0.0 };
        assert!(stick_slip_step(&p(), &inp).is_err());
    }

    #[test]
    fn sticks_below_fs_and_slides_above() {
        let mut inp = StepInput { v: 0.0, f_ext: 14.9, mass: 2.0, dt: 1e-4, stick_band: 0.0 };
        // Below Fs: friction cancels F_ext exactly.
        assert_eq!(stick_slip_step(&p(), &inp).unwrap(), -14.9);
        // Above Fs: the static level opposes.
        inp.f_ext = -15.1;
        assert_eq!(stick_slip_step(&p(), &inp).unwrap(), 15.0);
        // Sliding at v = 0.1 with no other force: Stribeck curve, opposing.
        inp.f_ext = 0.0;
        inp.v = 0.1;
        let f = stick_slip_step(&p(), &inp).unwrap();
        assert_eq!(f, -stribeck_force(&p(), 0.1).unwrap());
        // Sliding slowly: would reverse within the step → stopped at exactly zero.
        inp.v = 1e-4;
        let f = stick_slip_step(&p(), &inp).unwrap();
        let v_next = inp.v + inp.dt * (inp.f_ext + f) / inp.mass;
        assert_eq!(v_next, 0.0);
    }

    #[test]
    fn lugre_step_matches_fine_euler_for_one_stiff_step() {
        // At v = 0.4 m/s, a·dt ≈ 4: compare the exact update with 1e5 explicit-Euler sub-steps.
        let q = LugreParams::canudas1995();
        let (z0, v, dt) = (0.0, 0.4, 1e-4);
        let s = lugre_step(&q, z0, v, dt).unwrap();
        let n = 100_000;
        let h = dt / n as f64;
        let g = q.steady.level(v);
        let (mut z, mut zsum) = (z0, 0.0);
        for _ in 0..n {
            zsum += z + 0.5 * h * (v - q.sigma0 * v.abs() / g * z);
            z += h * (v - q.sigma0 * v.abs() / g * z);
        }
        let zbar = zsum / n as f64;
        // Euler's global error is O(h·a) ≈ 4e-5 relative; tolerance 1e-4 relative of z_ss = 1e-5 m.
        assert!((s.z_next - z).abs() < 1e-4 * 1e-5, "{} vs {z}", s.z_next);
        let f_ref = q.sigma0 * zbar + q.sigma1 * (z - z0) / dt + q.steady.fv * v;
        assert!((-s.force_on_body - f_ref).abs() < 1e-4 * f_ref.abs());
        // At rest z does not move.
        let r = lugre_step(&q, 1e-6, 0.0, dt).unwrap();
        assert_eq!(r.z_next, 1e-6);
        assert!((r.force_on_body + 0.1).abs() < 1e-15);
    }

    /// The one-transcendental update (e^{−x} and 1 − e^{−x} from expm1 below ln 2, from exp above) agrees
    /// with evaluating both exp and expm1 to within 4 ulp of the terms' scale in z_next (|z·e^{−x}| +
    /// |v·dt·φ|) and in the force (σ0·(|z·φ| + |v·dt·(1 − φ)/x|) + σ1·(|z_next| + |z|)/dt + |σ2·v|: the
    /// bristle rate is a difference of nearby deflections, so z_next's last bit moves it by more than
    /// its own ulp), over a·dt from below 1e-8 to about 40 (velocities 1e-9 to 4 m/s both ways, bristles at rest,
    /// with and against their steady state).
    #[test]
    fn lugre_step_with_one_transcendental_agrees_with_exp_and_expm1() {
        let q = LugreParams::canudas1995();
        let dt = 1e-4;
        // (z_next, its scale, force, its scale, a·dt) from exp and expm1 both (the two-transcendental update).
        let both = |z: f64, v: f64| {
            let g = q.steady.level(v);
            let x = q.sigma0 * v.abs() / g * dt;
            let phi = if x < 1e-12 { 1.0 - 0.5 * x } else { -(-x).exp_m1() / x };
            let (carried, driven) = (z * (-x).exp(), v * dt * phi);
            let z_next = carried + driven;
            let one_minus_phi_over_x = if x < 1e-6 { 0.5 - x / 6.0 } else { (1.0 - phi) / x };
            let mean = [z * phi, v * dt * one_minus_phi_over_x];
            let force = q.sigma0 * (mean[0] + mean[1]) + q.sigma1 * (z_next - z) / dt + q.steady.fv * v;
            // The force's terms as the roundings of its inputs move them: σ1·ż through z_next and z.
            let f_scale = q.sigma0 * (mean[0].abs() + mean[1].abs())
                + q.sigma1 * (z_next.abs() + z.abs()) / dt
                + (q.steady.fv * v).abs();
            (z_next, carried.abs() + driven.abs(), force, f_scale, x)
        };
        let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
        for i in 0..=400 {
            let speed = 1e-9 * 10f64.powf(i as f64 * 9.6 / 400.0);
            for v in [speed, -speed] {
                for z in [0.0, 3e-6, -2e-6] {
                    let s = lugre_step_unchecked(&q, z, v, dt);
                    let (z_ref, z_scale, f_ref, f_scale, x) = both(z, v);
                    (lo, hi) = (lo.min(x), hi.max(x));
                    let ulps = |a: f64, b: f64, scale: f64| (a - b).abs() / (f64::EPSILON * scale);
                    assert!(
                        ulps(s.z_next, z_ref, z_scale) <= 4.0,
                        "z_next {} vs {z_ref} at z {z:e} m, v {v:e} m/s",
                        s.z_next
                    );
                    let f = -s.force_on_body;
                    assert!(
                        ulps(f, f_ref, f_scale) <= 4.0,
                        "F {f} vs {f_ref} N at z {z:e} m, v {v:e} m/s, scale {f_scale:e}, x {x:e}"
                    );
                }
            }
        }
        assert!(lo < 1e-8 && hi > 30.0, "a·dt covered {lo:e} .. {hi:e}");
    }
}
