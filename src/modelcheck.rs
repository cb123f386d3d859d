//! The model-check loop (DESIGN.md §8): `vmt compare`, `vmt diagnose`, `vmt add`.
//!
//! Phase 1 predicts the deviation columns of positioning point tables (FORMAT.md §1: `target`,
//! `run`, `direction`, optional `t`, then deviations actual − target) from a model (FORMAT.md §2).
//! For a sensor with unit direction u and measuring point r (axis frame, m), at target x, approach
//! direction d = ±1 and time t (run `start_time` + the table's `t`, s), the first-order model is
//!
//! ```text
//! ŷ = o_ch + u·(E(x) + ε(x) × r)                           (error motions, ISO 230-1, axis frame)
//!          + s_drive·[ −d·b/2 + A_l·sin(2πx/p_l + φ_l) ]        (backlash b, cyclic lead)
//!          + s_chain·[ k·x + α·ΔT∞·x·(1 − e^{−t/τ}) + d∞·(1 − e^{−t/τ}) + A_i·sin(2πx/p_i + φ_i) ]
//! ```
//!
//! with E = (EXX, EYX, EZX), ε = (EAX, EBX, ECX) and o_ch an offset per channel (run, sensor) for
//! the zeroing of the instrument. Signs follow the simulator (`vmt_sim::axis_sim`): the table
//! lands at command + EXX + e(x, t) (feedback-chain error e: scale error k, thermal, interpolation);
//! in a semi-closed loop the screw's lead error adds to it and backlash makes the table lag the
//! motor by b/2, so the ISO 230-2 reversal value is B = x̄↑ − x̄↓ = −b. For a laser
//! s_drive = s_chain = u·axis; a linear scale (`encoder_linear`, reading x − EXX − e) sees only the
//! drive terms (s_drive = 1, s_chain = 0, no error motions); a rotary encoder only its offset.
//!
//! Everything is linear in the unknowns except periods and time constants, which are searched on
//! a grid and refined by golden-section search on the weighted residual sum of squares with the
//! linear parameters eliminated (variable projection; Golub & Pereyra 1973). The statistics and
//! the candidate ranking come from `vmt_estimators::modelcheck`.
//!
//! Phase 2 (friction): the `motor_force` column of a `friction_sweep` or `constant_velocity` time
//! series, every sample at the run's steady velocity v = feed·direction, is predicted by
//! F = o + Fc·sgn v + Fv·v + (Fs − Fc)·sgn v·exp(−(v/vs)²) (Coulomb, viscous, Stribeck with the
//! catalogue's default shape δ = 2; the simulator's law, `vmt_sim::effects::EffectSet::friction`),
//! with one force offset o per sensor; vs is searched like a period.
//!
//! Phase 3 (accelerometers): the readings of an `accelerometer` (body-frame sensitive direction u,
//! measuring point r) in a `constant_velocity` run with a `feed` (time t, position from `x_cmd`,
//! velocity v = feed·direction) are predicted by
//!
//! ```text
//! a_i = o_ch + v²·u·[Ē''(x_{i−1}, x_i) + ε̄''(x_{i−1}, x_i) × r] + g·τ_s(x_i) + a_mode,i
//! ```
//!
//! - o_ch: an offset per (run, sensor) (bias, gravity through the mounting tilt).
//! - The guideway's own acceleration of the measuring point, d²/dt² u·(E + ε × r) at constant v:
//!   the error motions' second derivatives averaged over the sample interval, Ē''(a, b) =
//!   (E'(b) − E'(a))/(b − a) with x_{i−1} = x_i − v·Δt_i, because the simulator's reading is the
//!   difference of the point velocities at successive samples over Δt (`vmt_sim::sensors`). The
//!   sensitivities are a laser's (u_i for translations, (r × u)_i for angles) times v². Given error
//!   motions use their profiles' slopes (Ē'' as `Profile::mean_second_derivative` computes it:
//!   polynomials, harmonics and random profiles by their analytic slopes, a table by its
//!   piecewise-constant slope, i.e. the slope jumps at its knots); fitted ones (c_k·x^k) give the columns v²·s·k·(x_i^{k−1} −
//!   x_{i−1}^{k−1})/(x_i − x_{i−1}) ≈ v²·s·k(k−1)·x^{k−2}, with the same coefficients c_k as the
//!   lasers' columns (one unknown per coefficient shared by lasers and accelerometers).
//! - g·τ_s(x): gravity seen through the tilt of sensor s's sensitive axis (`gravity_tilt`; the
//!   simulator's reading (R·u)·(a + g ẑ) gives τ = u_y·EAX(x) − u_x·EBX(x) to first order; fitted
//!   as a polynomial Σ c_k·x^k, k = 1..3, per sensor, shared by its runs). The error-motion columns
//!   leave gravity out: a given roll or pitch does not predict its g·τ (add `gravity_tilt`).
//! - a_mode: a `resonance`, a structural mode q̈ + 2ζω·q̇ + ω²·q = −u·a_ref(t) driven by the
//!   acceleration of the axis reference point (the simulator's base excitation, `StructuralMode`),
//!   read as φ·q̈ (φ the mode shape at the sensor). Where the model predicts that excitation on a
//!   channel (given translation error motions: a_ref = v²·E''(x(t)), x between samples at v), the
//!   mode is the forced response to it (integrated exactly with the input held at its mean over
//!   0.1 ms steps) from rest at the sample before the first, with a gain φ per sensor, plus the free
//!   vibration from the unknown state at that instant (two columns per channel); f (5–200 Hz, 1 Hz grid,
//!   below 0.4× the slowest sampling rate) and ζ (0.5–10 %) are searched. Where it does not
//!   (no given straightness: the excitation is an unknown random profile), the mode is a narrow-band
//!   random process: sin/cos of 2πf·t with amplitude and phase free per segment of
//!   [`RESONANCE_SEGMENT`] s of each channel; ζ is then not resolved (held at its start, 2 %).
//!   Fitted error motions do not enter the excitation: a polynomial's acceleration varies far
//!   slower than a mode, whose response to it is quasi-static (q ≈ −a/ω², q̈ ≈ 0).
//!
//! Not predicted in phase 3: the carriage's own dynamics on its bearing blocks (it follows the
//! geometry only quasi-statically, with a relative error ≈ (f/f_b)² at frequency f below its
//! bearing mode f_b: a normalised RMS far above 1 when the guideway's band reaches f_b, and when it
//! comes within ≈ f_b/5 diagnose already reports these dynamics as a `resonance` near the band's
//! top, see tests/model_check.rs `guideway_scenario`), the servo's ripple, the excitation by fitted error motions, gravity through given
//! angles, and a guideway that the model does not give (its broadband acceleration stays in the
//! residual, normalised by the manifest's σ or σ estimated from successive differences; a strong
//! line of it can then win the resonance search).
//!
//! Not predicted: LuGre, squareness (needs two axes), servo lag (no effect on settled readings).
//! They are listed in the report's `notes`. Error motions fitted with any `basis` use a polynomial of
//! degree `order` (default 3) without its constant term (the offsets carry it).

use crate::error::{fmt_num, VmtError};
use crate::measurement::{write_file_atomic, MeasurementSet, Procedure, RunData, SensorKind};
use crate::model::{Model, ModelEffect};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::f64::consts::TAU as TWO_PI;
use std::path::{Path, PathBuf};
use vmt_estimators::modelcheck::{
    autocorrelation, bin_by_edges, bin_by_label, estimate_noise_sigma, fit_percent, fit_signature, frequency_grid,
    ljung_box, ls_periodogram, rank_candidates, uniform_edges, Candidate, DiagnoseConfig, HyperParameter, RankingEntry,
    Sigma, Verdict,
};
use vmt_sim::axis_sim::GRAVITY;
use vmt_sim::effects::{Effect, EffectName, EffectParams};
use vmt_sim::profile::{Profile, Term};

/// Default polynomial degree of a fitted error motion (FORMAT.md §2 `order`).
pub const DEFAULT_ORDER: u32 = 3;
/// Starting α of a thermal expansion when the model gives none, 1/K (steel).
const ALPHA_STEEL: f64 = 11.5e-6;

// ------------------------------------------------------------------------------------------
// Channels.

/// One predicted channel: a deviation column of a point-table run, with the geometry of its sensor.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Channel {
    /// Run name.
    pub run: String,
    /// Sensor (column) name.
    pub sensor: String,
    /// Sensor kind.
    pub kind: SensorKind,
    /// Sensitive direction in the axis frame (unit vector).
    pub u: [f64; 3],
    /// Measuring point, axis frame, m.
    pub r: [f64; 3],
    /// Target positions x, m.
    pub x: Vec<f64>,
    /// Approach directions d = ±1.
    pub d: Vec<f64>,
    /// Run numbers (1..n).
    pub cycle: Vec<u32>,
    /// Times t, s since the start of the session (run start_time + the table's `t`).
    pub t: Vec<f64>,
    /// Velocity, m/s (the run's feed × direction for time series; 0 in point tables).
    pub v: Vec<f64>,
    /// Measured values: deviations (m) in point tables, motor force (N) in time series.
    pub y: Vec<f64>,
    /// 1σ noise from the manifest (None or 0 → estimated).
    pub sigma: Option<f64>,
}

impl Channel {
    /// Sensitivity to the drive terms (backlash, cyclic lead): u·axis for a laser, 1 for a linear
    /// scale, 0 for a rotary encoder.
    fn s_drive(&self) -> f64 {
        match self.kind {
            SensorKind::EncoderLinear => 1.0,
            _ if self.is_laser() => self.u[0],
            _ => 0.0,
        }
    }

    /// 1 for a motor-force channel (friction acts on it), 0 otherwise.
    fn s_force(&self) -> f64 {
        if self.kind == SensorKind::MotorForce {
            1.0
        } else {
            0.0
        }
    }

    /// Sensitivity to the feedback-chain terms (scale error, thermal, interpolation): u·axis for a
    /// laser, 0 for encoders (they read the chain itself).
    fn s_chain(&self) -> f64 {
        if self.is_laser() {
            self.u[0]
        } else {
            0.0
        }
    }

    fn is_accel(&self) -> bool {
        self.kind == SensorKind::Accelerometer
    }

    fn is_laser(&self) -> bool {
        matches!(self.kind, SensorKind::LaserLinear | SensorKind::LaserStraightness | SensorKind::LaserVector)
    }

    /// Sensitivity to error motion `name`: u_i for translations, (r × u)_i for rotations
    /// (u·(ε × r) = ε·(r × u)), for lasers (to the motion itself) and accelerometers (to its mean
    /// second derivative, see [`Channel::motion_response`]); 0 for encoders and motor forces.
    fn s_motion(&self, name: EffectName) -> f64 {
        if !self.is_laser() && !self.is_accel() {
            return 0.0;
        }
        let [ux, uy, uz] = self.u;
        let [rx, ry, rz] = self.r;
        let rxu = [ry * uz - rz * uy, rz * ux - rx * uz, rx * uy - ry * ux];
        match name {
            EffectName::Positioning => ux,
            EffectName::StraightnessY => uy,
            EffectName::StraightnessZ => uz,
            EffectName::Roll => rxu[0],
            EffectName::Pitch => rxu[1],
            EffectName::Yaw => rxu[2],
            _ => 0.0,
        }
    }
}

impl Channel {
    /// Response of sample `i` to an error motion `name` whose profile has value `value(x)` and slope
    /// `slope(x)` (first derivative in position):
    ///
    /// ```text
    /// laser:          s·P(x_i)
    /// accelerometer:  s·v_i·(P'(x_i) − P'(x_i − v_i·Δt_i))/Δt_i = s·v_i²·P̄''(x_i − v_i·Δt_i, x_i)
    /// ```
    ///
    /// with s = [`Channel::s_motion`] (u_i or (r × u)_i). The accelerometer term is the guideway's
    /// acceleration of the measuring point at constant velocity v, d²/dt² u·(E + ε × r) = v²·u·(E'' +
    /// ε'' × r), averaged over the sample interval Δt_i (t_i − t_{i−1}; the first sample takes the
    /// second's) as the simulator's reading is (difference of point velocities at successive
    /// samples, `vmt_sim::sensors::true_readings`). Gravity through the angles (g·tilt) is not in
    /// it: that is the `gravity_tilt` effect.
    fn motion_response(
        &self,
        i: usize,
        name: EffectName,
        value: impl Fn(f64) -> f64,
        slope: impl Fn(f64) -> f64,
    ) -> f64 {
        let s = self.s_motion(name);
        if s == 0.0 {
            return 0.0;
        }
        if self.is_laser() {
            return s * value(self.x[i]);
        }
        let dt = sample_interval(self, i);
        let v = self.v[i];
        if !(dt > 0.0) || v == 0.0 {
            return 0.0;
        }
        let xb = self.x[i];
        let xa = xb - v * dt;
        s * v * (slope(xb) - slope(xa)) / dt
    }
}

/// A machine-frame direction in the axis frame of axis `axis` (the inverse of the simulator's
/// rotation taking X onto the axis: y → (u_y, −u_x, u_z), z → (u_z, u_y, −u_x)).
fn to_axis_frame(u: [f64; 3], axis: char) -> [f64; 3] {
    match axis {
        'y' => [u[1], -u[0], u[2]],
        'z' => [u[2], u[1], -u[0]],
        _ => u,
    }
}

/// The channels of `set` that phase 1 predicts for axis `axis`: every deviation column of every
/// positioning point table of that axis whose sensor is a laser (linear, straightness, vector) or
/// an encoder. Returns the channels and notes on what was skipped.
pub fn channels(set: &MeasurementSet, axis: char) -> (Vec<Channel>, Vec<String>) {
    let mut out: Vec<Channel> = Vec::new();
    let mut notes: Vec<String> = Vec::new();
    for run in &set.runs {
        if run.axis != axis {
            notes.push(format!("run `{}` moves axis {}, the model's axis is {axis}", run.name, run.axis));
            continue;
        }
        let RunData::PointTable { target, run: cyc, direction, t, columns } = &run.data else {
            time_series_channels(set, run, &mut out, &mut notes);
            continue;
        };
        let t0 = run.start_time.unwrap_or(0.0);
        let times: Vec<f64> = match t {
            Some(t) => t.iter().map(|v| t0 + v).collect(),
            None => vec![t0; target.len()],
        };
        for (name, values) in columns {
            let Some(s) = set.sensor(name) else { continue };
            let ok = matches!(
                s.kind,
                SensorKind::LaserLinear
                    | SensorKind::LaserStraightness
                    | SensorKind::LaserVector
                    | SensorKind::EncoderLinear
                    | SensorKind::EncoderRotary
            );
            if !ok {
                notes.push(format!("run `{}`, sensor `{name}` ({}): not predicted", run.name, s.kind.as_str()));
                continue;
            }
            out.push(Channel {
                run: run.name.clone(),
                sensor: name.clone(),
                kind: s.kind,
                u: to_axis_frame(s.direction, axis),
                r: s.position,
                x: target.clone(),
                d: direction.iter().map(|&v| f64::from(v)).collect(),
                cycle: cyc.clone(),
                t: times.clone(),
                v: vec![0.0; target.len()],
                y: values.clone(),
                sigma: s.sigma.filter(|v| *v > 0.0),
            });
        }
    }
    (out, notes)
}

/// The motor-force channels of a constant-velocity or friction-sweep time series (phase 2): every
/// sample at the run's steady velocity v = feed·direction (the procedures sample only the cruise),
/// position from `x_cmd`. Other time-series channels are listed in `notes` as not predicted.
fn time_series_channels(
    set: &MeasurementSet,
    run: &crate::measurement::Run,
    out: &mut Vec<Channel>,
    notes: &mut Vec<String>,
) {
    let RunData::TimeSeries { t, columns } = &run.data else { return };
    let steady = matches!(run.procedure, Procedure::FrictionSweep | Procedure::ConstantVelocity);
    let x: Vec<f64> = run.data.column("x_cmd").map(<[f64]>::to_vec).unwrap_or_else(|| vec![0.0; t.len()]);
    for (name, values) in columns {
        if name == "x_cmd" {
            continue;
        }
        let Some(s) = set.sensor(name) else { continue };
        match (s.kind, steady, run.feed) {
            (SensorKind::Accelerometer, _, Some(feed)) if run.procedure == Procedure::ConstantVelocity => {
                out.push(steady_channel(
                    run,
                    name,
                    s,
                    to_axis_frame(s.direction, run.axis),
                    s.position,
                    &x,
                    t,
                    feed,
                    values,
                ));
            }
            (SensorKind::MotorForce, true, Some(feed)) => {
                out.push(steady_channel(run, name, s, [1.0, 0.0, 0.0], [0.0; 3], &x, t, feed, values));
            }
            _ => notes.push(format!(
                "run `{}` ({}), sensor `{name}` ({}): not predicted (time series: only the motor force of \
                 constant-velocity and friction-sweep runs with a `feed`)",
                run.name,
                run.procedure.as_str(),
                s.kind.as_str()
            )),
        }
    }
}

/// A channel of a constant-feed time-series run: every sample at the run's signed feed, cycle 1, times
/// offset by the run's start time; `u`, `r` the sensor's direction and point in the axis frame.
#[allow(clippy::too_many_arguments)]
fn steady_channel(
    run: &crate::measurement::Run,
    name: &str,
    s: &crate::measurement::Sensor,
    u: [f64; 3],
    r: [f64; 3],
    x: &[f64],
    t: &[f64],
    feed: f64,
    values: &[f64],
) -> Channel {
    let dir = f64::from(run.direction.unwrap_or(1));
    let t0 = run.start_time.unwrap_or(0.0);
    Channel {
        run: run.name.clone(),
        sensor: name.to_string(),
        kind: s.kind,
        u,
        r,
        x: x.to_vec(),
        d: vec![dir; t.len()],
        cycle: vec![1; t.len()],
        t: t.iter().map(|v| t0 + v).collect(),
        v: vec![feed * dir; t.len()],
        y: values.to_vec(),
        sigma: s.sigma.filter(|v| *v > 0.0),
    }
}

// ------------------------------------------------------------------------------------------
// Signatures of the effects on the stacked samples.

// 1 − exp(−t/τ) for t > 0 (a step for τ = 0), 0 before t = 0: the simulator's thermal rise.
use vmt_sim::effects::rise;

/// The stacked samples of all channels, with per-sample sensitivities.
struct Stack<'a> {
    chans: &'a [Channel],
    n: usize,
    /// Offset group of each channel: one per (run, sensor) for deviations (the instrument is zeroed
    /// per run), one per sensor for motor forces (a force bias, e.g. weight on an inclined axis,
    /// does not change from run to run).
    group: Vec<usize>,
    n_groups: usize,
    /// Per channel: the base excitation of a structural mode predicted by the model (accelerometer
    /// channels only; None where the model predicts none), see [`Excitation`].
    excitation: Vec<Option<Excitation>>,
}

/// Time step of the mode integration, s: at most this long (and at least 4 steps per sample
/// interval). The input is held at its mean over each step, so that its impulse (the velocity it
/// gives) is exact; the hold's error on a sinusoid of the guideway's band (≤ 100 Hz) is
/// ≈ (ωh)²/24 ≈ 2·10⁻⁵ of it.
const MODE_STEP: f64 = 1e-4;

/// The base acceleration that drives a structural mode, as the model predicts it on one
/// accelerometer channel: u·a_ref(τ) = v²·u·E''(x(τ)), the guideway acceleration of the axis
/// reference point (r = 0: the angles do not move it) from the model's given error motions, with
/// x(τ) = x_i + v·(τ − t_i) between samples. It is tabulated from t_{−1} = t_0 − Δt_0 (the sample
/// before the first, whose velocity the first reading is differenced against): interval i
/// (t_{i−1} → t_i) holds `steps[i]` steps of length Δt_i/steps[i] and the input's mean over each
/// step, v²·u·Ē''(x_k, x_{k+1}) (`Profile::mean_second_derivative`: a table's slope jumps count).
#[derive(Clone, Debug)]
struct Excitation {
    steps: Vec<usize>,
    input: Vec<Vec<f64>>,
}

/// Sample interval before sample i of a channel, s (the first sample takes the second's).
fn sample_interval(c: &Channel, i: usize) -> f64 {
    match i {
        0 if c.t.len() > 1 => c.t[1] - c.t[0],
        0 => 0.0,
        _ => c.t[i] - c.t[i - 1],
    }
}

/// Number of mode-integration steps over a sample interval `dt` (s).
fn mode_steps(dt: f64) -> usize {
    ((dt / MODE_STEP).ceil() as usize).max(4)
}

impl Excitation {
    /// The excitation of channel `c` by the given (not fitted) translation error motions of
    /// `model` (EXX, EYX, EZX with their profiles); None for a non-accelerometer channel, a channel
    /// without velocity or a non-increasing time, or when no given translation reaches u.
    fn of(c: &Channel, model: &Model) -> Option<Excitation> {
        if !c.is_accel() || c.t.len() < 2 {
            return None;
        }
        let motions: Vec<(f64, &Profile)> = model
            .effects
            .iter()
            .filter(|m| !m.fit && m.effect.axis == model.axis)
            .filter_map(|m| match (&m.effect.params, m.effect.name) {
                (EffectParams::ErrorMotion(p), n)
                    if matches!(n, EffectName::Positioning | EffectName::StraightnessY | EffectName::StraightnessZ) =>
                {
                    let s = c.s_motion(n);
                    (s != 0.0 && !p.is_zero()).then_some((s, p))
                }
                _ => None,
            })
            .collect();
        if motions.is_empty() {
            return None;
        }
        let mut steps = Vec::with_capacity(c.t.len());
        let mut input = Vec::with_capacity(c.t.len());
        for i in 0..c.t.len() {
            let dt = sample_interval(c, i);
            let v = c.v[i];
            if !(dt > 0.0) || !dt.is_finite() || v == 0.0 {
                return None;
            }
            let m = mode_steps(dt);
            let x = |k: usize| c.x[i] - v * dt * (1.0 - k as f64 / m as f64);
            let vals: Vec<f64> = (0..m)
                .map(|k| v * v * motions.iter().map(|(s, p)| s * p.mean_second_derivative(x(k), x(k + 1))).sum::<f64>())
                .collect();
            steps.push(m);
            input.push(vals);
        }
        Some(Excitation { steps, input })
    }
}

/// The exact one-step map of the mode q̈ + 2ζω·q̇ + ω²·q = −a(τ) over a step h with a linear
/// input from a₀ to a₁: (q, q̇)(h) = Φ·(q, q̇)(0) + g₀·a₀ + g₁·a₁. Φ, g₀ and g₁ are the responses to
/// the unit states and to the inputs 1 − τ/h and τ/h, integrated by classical RK4 in 32 sub-steps
/// (ωh/32 ≤ 0.004 at 200 Hz and h = 0.1 ms: error ≈ 10⁻¹⁴).
#[derive(Clone, Copy, Debug)]
struct StepMap {
    h: f64,
    phi: [[f64; 2]; 2],
    g0: [f64; 2],
    g1: [f64; 2],
}

impl StepMap {
    fn new(f: f64, zeta: f64, h: f64) -> StepMap {
        let w = TWO_PI * f;
        let n = 32;
        let hs = h / n as f64;
        let run = |x0: [f64; 2], a: &dyn Fn(f64) -> f64| -> [f64; 2] {
            let d = |tau: f64, x: [f64; 2]| [x[1], -a(tau) - 2.0 * zeta * w * x[1] - w * w * x[0]];
            let mut x = x0;
            for k in 0..n {
                let tau = k as f64 * hs;
                let k1 = d(tau, x);
                let k2 = d(tau + 0.5 * hs, [x[0] + 0.5 * hs * k1[0], x[1] + 0.5 * hs * k1[1]]);
                let k3 = d(tau + 0.5 * hs, [x[0] + 0.5 * hs * k2[0], x[1] + 0.5 * hs * k2[1]]);
                let k4 = d(tau + hs, [x[0] + hs * k3[0], x[1] + hs * k3[1]]);
                for j in 0..2 {
                    x[j] += hs / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
                }
            }
            x
        };
        let c0 = run([1.0, 0.0], &|_| 0.0);
        let c1 = run([0.0, 1.0], &|_| 0.0);
        StepMap {
            h,
            phi: [[c0[0], c1[0]], [c0[1], c1[1]]],
            g0: run([0.0, 0.0], &|tau| 1.0 - tau / h),
            g1: run([0.0, 0.0], &|tau| tau / h),
        }
    }

    fn step(&self, x: [f64; 2], a0: f64, a1: f64) -> [f64; 2] {
        [
            self.phi[0][0] * x[0] + self.phi[0][1] * x[1] + self.g0[0] * a0 + self.g1[0] * a1,
            self.phi[1][0] * x[0] + self.phi[1][1] * x[1] + self.g0[1] * a0 + self.g1[1] * a1,
        ]
    }
}

/// Interval means of q̈ of a mode q̈ + 2ζω·q̇ + ω²·q = −a(τ) over each sample interval of channel
/// `c`, (q̇_i − q̇_{i−1})/Δt_i (what the simulator's accelerometer reads of a point moving by q), from
/// the state (q, q̇) = `start` at t_{−1}, with the input a from `ex` (None: free vibration) held at
/// its mean over each step ([`StepMap`], [`MODE_STEP`]). ω = 2πf, f in Hz.
fn mode_response(c: &Channel, ex: Option<&Excitation>, f: f64, zeta: f64, start: (f64, f64)) -> Vec<f64> {
    let mut x = [start.0, start.1];
    let mut map: Option<StepMap> = None;
    let mut out = Vec::with_capacity(c.t.len());
    for i in 0..c.t.len() {
        let dt = sample_interval(c, i);
        if !(dt > 0.0) {
            out.push(0.0);
            continue;
        }
        let m = ex.map_or(mode_steps(dt), |e| e.steps[i]);
        let h = dt / m as f64;
        // Sample intervals repeat: the map is rebuilt only when the step changes (≥ 1 ppb).
        let mp = match map {
            Some(mp) if (mp.h - h).abs() <= 1e-9 * h => mp,
            _ => *map.insert(StepMap::new(f, zeta, h)),
        };
        let v0 = x[1];
        for k in 0..m {
            let a = ex.map_or(0.0, |e| e.input[i][k]);
            x = mp.step(x, a, a);
        }
        out.push((x[1] - v0) / dt);
    }
    out
}

impl<'a> Stack<'a> {
    /// The stack of `chans` with the structural-mode excitation the model `model` predicts.
    fn with_model(chans: &'a [Channel], model: &Model) -> Stack<'a> {
        let mut st = Stack::new(chans);
        st.excitation = chans.iter().map(|c| Excitation::of(c, model)).collect();
        st
    }

    fn new(chans: &'a [Channel]) -> Stack<'a> {
        let mut keys: Vec<String> = Vec::new();
        let mut group = Vec::with_capacity(chans.len());
        for c in chans {
            let key = if c.kind == SensorKind::MotorForce {
                format!("force/{}", c.sensor)
            } else {
                format!("{}/{}", c.run, c.sensor)
            };
            let g = keys.iter().position(|k| *k == key).unwrap_or_else(|| {
                keys.push(key);
                keys.len() - 1
            });
            group.push(g);
        }
        Stack {
            chans,
            n: chans.iter().map(|c| c.y.len()).sum(),
            group,
            n_groups: keys.len(),
            excitation: vec![None; chans.len()],
        }
    }

    /// One column: f(channel, sample index) over all samples.
    fn col(&self, f: impl Fn(&Channel, usize) -> f64) -> Vec<f64> {
        let mut v = Vec::with_capacity(self.n);
        for c in self.chans {
            for i in 0..c.y.len() {
                v.push(f(c, i));
            }
        }
        v
    }

    /// One column: f(channel, sample index, channel index) over all samples.
    fn col_j(&self, f: impl Fn(&Channel, usize, usize) -> f64) -> Vec<f64> {
        let mut v = Vec::with_capacity(self.n);
        for (j, c) in self.chans.iter().enumerate() {
            for i in 0..c.y.len() {
                v.push(f(c, i, j));
            }
        }
        v
    }

    fn y(&self) -> Vec<f64> {
        self.col(|c, i| c.y[i])
    }

    /// Offset columns, one per offset group.
    fn offsets(&self) -> Vec<Vec<f64>> {
        (0..self.n_groups)
            .map(|k| {
                let mut v = Vec::with_capacity(self.n);
                for (j, c) in self.chans.iter().enumerate() {
                    v.extend(std::iter::repeat(if self.group[j] == k { 1.0 } else { 0.0 }).take(c.y.len()));
                }
                v
            })
            .collect()
    }

    fn t_span(&self) -> (f64, f64) {
        let ts = self.col(|c, i| c.t[i]);
        let lo = ts.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ts.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    }
}

/// How an effect's signature is parameterised: names of its linear coefficients and of its
/// nonlinear hyper-parameters (periods, time constants).
#[derive(Clone, Debug, PartialEq)]
struct Shape {
    coefs: Vec<String>,
    hypers: Vec<&'static str>,
    /// Lowest power of a polynomial error motion (1 in a model; 2 for the positioning candidate,
    /// whose linear term is the scale error's signature).
    first_power: u32,
    order: u32,
    /// Stribeck only: also fit the Coulomb level (the model has no `coulomb` effect).
    with_fc: bool,
}

/// True for the effects phase 1 can predict in a point table.
pub fn predicts(name: EffectName) -> bool {
    name.is_error_motion()
        || matches!(
            name,
            EffectName::Backlash
                | EffectName::CyclicLead
                | EffectName::ScaleError
                | EffectName::ThermalExpansion
                | EffectName::ThermalDrift
                | EffectName::InterpolationError
                | EffectName::Coulomb
                | EffectName::Viscous
                | EffectName::Stribeck
                | EffectName::Resonance
                | EffectName::GravityTilt
        )
}

/// Length of the segments over which a resonance's amplitude and phase are held, s. A base-excited
/// mode driven by a random guideway profile is a narrow-band random process whose amplitude and
/// phase wander over its correlation time 1/(ζ·2πf) (0.18 s at 45 Hz, ζ = 0.02): piecewise
/// sin/cos with amplitudes per segment follow it.
const RESONANCE_SEGMENT: f64 = 0.2;

/// The resonance segments of the accelerometer channels without a predicted mode excitation
/// (module doc): (channel index, segment number, start time, end time), s. A channel is cut into ⌈T/`RESONANCE_SEGMENT`⌉ equal segments of its time span
/// (a segment needs ≥ 8 samples, else the channel is one segment).
fn resonance_segments(st: &Stack) -> Vec<(usize, usize, f64, f64)> {
    let mut out = Vec::new();
    for (j, c) in st.chans.iter().enumerate() {
        if !c.is_accel() || c.t.len() < 8 || st.excitation[j].is_some() {
            continue;
        }
        let lo = c.t.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = c.t.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let span = hi - lo;
        let mut m = ((span / RESONANCE_SEGMENT).ceil() as usize).max(1);
        if c.t.len() / m < 8 {
            m = (c.t.len() / 8).max(1);
        }
        for k in 0..m {
            let a = lo + span * k as f64 / m as f64;
            // The last segment's end lies just past the last sample (half-open intervals).
            let b = if k + 1 == m { hi + 1.0 } else { lo + span * (k + 1) as f64 / m as f64 };
            out.push((j, k, a, b));
        }
    }
    out
}

/// Names of the accelerometer sensors among the channels, in order of appearance.
fn accel_sensors(st: &Stack) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for c in st.chans.iter().filter(|c| c.is_accel()) {
        if !out.contains(&c.sensor) {
            out.push(c.sensor.clone());
        }
    }
    out
}

/// Names of the accelerometer sensors with a predicted mode excitation on some channel, in order
/// of appearance.
fn excited_sensors(st: &Stack) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for (c, _) in st.chans.iter().zip(&st.excitation).filter(|(_, e)| e.is_some()) {
        if !out.contains(&c.sensor) {
            out.push(c.sensor.clone());
        }
    }
    out
}

/// Sampling rate of the slowest accelerometer channel, Hz (median sample interval); None without one.
fn accel_min_rate(st: &Stack) -> Option<f64> {
    st.chans
        .iter()
        .filter(|c| c.is_accel() && c.t.len() > 2)
        .map(|c| {
            let mut dt: Vec<f64> = c.t.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
            dt.sort_by(f64::total_cmp);
            if dt.is_empty() {
                0.0
            } else {
                1.0 / dt[dt.len() / 2]
            }
        })
        .filter(|f| *f > 0.0)
        .reduce(f64::min)
}

fn shape(st: &Stack, name: EffectName, first_power: u32, order: u32, with_fc: bool) -> Shape {
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<String>>();
    let (coefs, hypers): (Vec<String>, Vec<&'static str>) = match name {
        n if n.is_error_motion() => ((first_power..=order).map(|k| format!("c{k}")).collect(), vec![]),
        EffectName::Backlash | EffectName::ScaleError => (s(&["value"]), vec![]),
        EffectName::CyclicLead | EffectName::InterpolationError => (s(&["a_sin", "a_cos"]), vec!["period"]),
        EffectName::ThermalExpansion => (s(&["alpha_delta_t"]), vec!["tau"]),
        EffectName::ThermalDrift => (s(&["value"]), vec!["tau"]),
        EffectName::Coulomb => (s(&["fc"]), vec![]),
        EffectName::Viscous => (s(&["fv"]), vec![]),
        EffectName::Stribeck if with_fc => (s(&["fs_minus_fc", "fc"]), vec!["vs"]),
        EffectName::Stribeck => (s(&["fs_minus_fc"]), vec!["vs"]),
        EffectName::Resonance => {
            let mut names: Vec<String> = excited_sensors(st).iter().map(|a| format!("gain_{a}")).collect();
            for (j, _) in st.excitation.iter().enumerate().filter(|(_, e)| e.is_some()) {
                names.push(format!("free_q_{j}"));
                names.push(format!("free_v_{j}"));
            }
            names.extend(
                resonance_segments(st).iter().flat_map(|(j, k, _, _)| [format!("sin_{j}_{k}"), format!("cos_{j}_{k}")]),
            );
            (names, vec!["frequency", "damping"])
        }
        EffectName::GravityTilt => {
            (accel_sensors(st).iter().flat_map(|a| (1..=order).map(move |k| format!("{a}_c{k}"))).collect(), vec![])
        }
        _ => (vec![], vec![]),
    };
    Shape { coefs, hypers, first_power, order, with_fc }
}

/// Design columns of effect `name` at hyper-parameters `h` (in the order of [`shape`]).
fn columns(st: &Stack, name: EffectName, sh: &Shape, h: &[f64]) -> Vec<Vec<f64>> {
    match name {
        n if n.is_error_motion() => {
            // c_k·x^k: the same coefficient for lasers (x^k) and accelerometers (slope k·x^(k−1)).
            (sh.first_power..=sh.order)
                .map(|k| {
                    let kf = k as f64;
                    st.col(|c, i| c.motion_response(i, n, |x| x.powi(k as i32), |x| kf * x.powi(k as i32 - 1)))
                })
                .collect()
        }
        EffectName::Backlash => vec![st.col(|c, i| -0.5 * c.d[i] * c.s_drive())],
        EffectName::ScaleError => vec![st.col(|c, i| c.x[i] * c.s_chain())],
        EffectName::CyclicLead | EffectName::InterpolationError => {
            let p = h[0];
            if !phases_spread(st, p) {
                return vec![vec![0.0; st.n], vec![0.0; st.n]];
            }
            let drive = name == EffectName::CyclicLead;
            let s = move |c: &Channel| if drive { c.s_drive() } else { c.s_chain() };
            vec![st.col(|c, i| s(c) * (TWO_PI * c.x[i] / p).sin()), st.col(|c, i| s(c) * (TWO_PI * c.x[i] / p).cos())]
        }
        EffectName::ThermalExpansion => vec![st.col(|c, i| c.s_chain() * c.x[i] * rise(c.t[i], h[0]))],
        EffectName::ThermalDrift => vec![st.col(|c, i| c.s_chain() * rise(c.t[i], h[0]))],
        EffectName::Coulomb => vec![st.col(|c, i| c.s_force() * c.v[i].signum())],
        EffectName::Viscous => vec![st.col(|c, i| c.s_force() * c.v[i])],
        EffectName::Stribeck => {
            // F = Fc·sgn v + (Fs − Fc)·sgn v·exp(−|v/vs|^δ), δ = 2 (the catalogue's default shape).
            let vs = h[0];
            let mut cols = vec![st.col(|c, i| c.s_force() * c.v[i].signum() * (-(c.v[i] / vs).abs().powi(2)).exp())];
            if sh.with_fc {
                cols.push(st.col(|c, i| c.s_force() * c.v[i].signum()));
            }
            cols
        }
        EffectName::Resonance => {
            let (f, zeta) = (h[0], h[1]);
            let mut cols = Vec::new();
            // Forced response to the predicted base acceleration, gain φ (the mode shape at the
            // sensor) per sensor: φ·mean q̈ with q driven by −u·a_ref from rest at t_{−1}.
            let responses: Vec<Option<Vec<f64>>> = st
                .chans
                .iter()
                .zip(&st.excitation)
                .map(|(c, e)| e.as_ref().map(|e| mode_response(c, Some(e), f, zeta, (0.0, 0.0))))
                .collect();
            for a in excited_sensors(st) {
                cols.push(st.col_j(|c, i, j| match &responses[j] {
                    Some(r) if c.sensor == a => r[i],
                    _ => 0.0,
                }));
            }
            // Free vibration from the unknown state at t_{−1} (q₀ = 1/ω², q̇₀ = 1/ω: unit scale),
            // per excited channel.
            let w = TWO_PI * f;
            for (j, c) in st.chans.iter().enumerate() {
                if st.excitation[j].is_none() {
                    continue;
                }
                for start in [(1.0 / (w * w), 0.0), (0.0, 1.0 / w)] {
                    let r = mode_response(c, None, f, zeta, start);
                    cols.push(st.col_j(|_, i, jj| if jj == j { r[i] } else { 0.0 }));
                }
            }
            // Channels without a predicted excitation: narrow band at the temporal frequency f,
            // sin/cos of 2πf·t per segment.
            for (j, _, a, b) in resonance_segments(st) {
                let inside = move |c: &Channel, i: usize, jj: usize| jj == j && c.t[i] >= a && c.t[i] < b;
                cols.push(st.col_j(|c, i, jj| if inside(c, i, jj) { (TWO_PI * f * c.t[i]).sin() } else { 0.0 }));
                cols.push(st.col_j(|c, i, jj| if inside(c, i, jj) { (TWO_PI * f * c.t[i]).cos() } else { 0.0 }));
            }
            cols
        }
        EffectName::GravityTilt => {
            // g·tilt(x) of each accelerometer's sensitive axis, a polynomial in x shared by its runs.
            let mut cols = Vec::new();
            for a in accel_sensors(st) {
                for k in 1..=sh.order {
                    cols.push(st.col(|c, i| {
                        if c.sensor == a && c.is_accel() {
                            GRAVITY * c.x[i].powi(k as i32)
                        } else {
                            0.0
                        }
                    }));
                }
            }
            cols
        }
        _ => vec![],
    }
}

/// True when the phases 2πx/p of the distinct targets spread around the circle (mean resultant
/// length R = |mean e^{iθ}| ≤ 0.5, and 0.1 ≤ mean sin²θ ≤ 0.9 so both quadratures vary), so that a sinusoid of period p is distinguishable from a
/// constant on these targets; false at an alias (targets a whole number of periods apart).
fn phases_spread(st: &Stack, p: f64) -> bool {
    let mut xs: Vec<f64> = st.chans.iter().flat_map(|c| c.x.iter().copied()).collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    if xs.len() < 3 || !(p > 0.0) {
        return false;
    }
    let m = xs.len() as f64;
    let (sc, cc) = xs.iter().fold((0.0, 0.0), |(a, b), x| (a + (TWO_PI * x / p).sin(), b + (TWO_PI * x / p).cos()));
    // Both quadratures must vary: at p = 2 µm on targets rounded to 1 µm the sine vanishes.
    let s2: f64 = xs.iter().map(|x| (TWO_PI * x / p).sin().powi(2)).sum::<f64>() / m;
    (sc * sc + cc * cc).sqrt() / m <= 0.5 && (0.1..=0.9).contains(&s2)
}

/// The prediction of a known (not fitted) effect at every sample.
fn known_prediction(st: &Stack, e: &Effect) -> Vec<f64> {
    match (&e.params, e.name) {
        (EffectParams::ErrorMotion(prof), n) => {
            st.col(|c, i| c.motion_response(i, n, |x| prof.value(x), |x| prof.eval3(x)[1]))
        }
        (EffectParams::Backlash(b), _) => st.col(|c, i| -0.5 * c.d[i] * c.s_drive() * b.value),
        (EffectParams::ScaleError(s), _) => st.col(|c, i| c.s_chain() * s.value * c.x[i]),
        (EffectParams::CyclicLead(l), _) => st.col(|c, i| c.s_drive() * l.value(c.x[i])),
        (EffectParams::InterpolationError(ie), _) => st.col(|c, i| c.s_chain() * ie.value(c.x[i])),
        (EffectParams::ThermalExpansion(th), _) => st.col(|c, i| c.s_chain() * th.value(c.x[i], c.t[i])),
        (EffectParams::ThermalDrift(dr), _) => st.col(|c, i| c.s_chain() * dr.value_at(c.t[i])),
        (EffectParams::Coulomb(f), _) => st.col(|c, i| c.s_force() * f.fc * c.v[i].signum()),
        (EffectParams::Viscous(f), _) => st.col(|c, i| c.s_force() * f.fv * c.v[i]),
        (EffectParams::Stribeck(f), _) => {
            // The Coulomb part belongs to the `coulomb` effect unless `fc` is given here.
            let fc = f.fc.unwrap_or(0.0);
            st.col(|c, i| {
                let v = c.v[i];
                c.s_force()
                    * v.signum()
                    * (fc * (1.0 - (-(v / f.vs).abs().powf(f.shape)).exp())
                        + f.fs * (-(v / f.vs).abs().powf(f.shape)).exp())
            })
        }
        _ => vec![0.0; st.n],
    }
}

/// Log-spaced grid of `n` values from `lo` to `hi`.
fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..n).map(|k| (a + (b - a) * k as f64 / (n - 1).max(1) as f64).exp()).collect()
}

/// Search grid of a hyper-parameter on these data: time constants from a quarter of the time span
/// to ten times it (a faster process looks like a constant, which the offsets and the scale error
/// already carry); screw leads 2–60 mm; encoder signal periods from the common scale gratings.
fn hyper_grid(st: &Stack, name: EffectName, hyper: &str) -> (Vec<f64>, bool) {
    match (name, hyper) {
        (_, "tau") => {
            let (lo, hi) = st.t_span();
            let span = (hi - lo).max(1.0);
            (log_grid(span / 4.0, span * 10.0, 40), true)
        }
        (EffectName::CyclicLead, _) => (log_grid(2e-3, 60e-3, 120), true),
        // Stribeck velocities of machine-tool guideways: 10 µm/s to 100 mm/s.
        (_, "vs") => (log_grid(1e-5, 0.1, 41), true),
        // Structural modes of machine-tool columns and frames: 5–200 Hz, capped at 0.4× the slowest
        // accelerometer rate (below Nyquist), in steps of 1 Hz (five points across the 1/0.2 s =
        // 5 Hz resolution of a segment), refined by golden section.
        (_, "frequency") => {
            let hi = accel_min_rate(st).map_or(200.0, |f| (0.4 * f).min(200.0)).max(6.0);
            let n = (hi - 5.0).floor() as usize + 1;
            ((0..n).map(|k| 5.0 + k as f64).collect(), true)
        }
        // Damping ratios of machine-tool structural modes, 0.5–10 % (bolted and welded frames; a
        // column's first bending mode is typically 2–5 %); only the forced response resolves it,
        // so without a predicted excitation it is held at 2 % (not searched).
        (_, "damping") => {
            if st.excitation.iter().any(|e| e.is_some()) {
                (log_grid(0.005, 0.1, 6), true)
            } else {
                (vec![0.02], false)
            }
        }
        // Signal periods of common linear and rotary scales (Heidenhain, Renishaw): 2–200 µm.
        _ => (vec![2e-6, 4e-6, 8e-6, 10e-6, 20e-6, 40e-6, 100e-6, 200e-6], false),
    }
}

// ------------------------------------------------------------------------------------------
// Fitting a model.

/// A fitted effect of the model: its shape, hyper-parameters and where its columns sit.
#[derive(Clone, Debug)]
struct FitTerm {
    index: usize,
    name: EffectName,
    shape: Shape,
    /// Hyper-parameter values and whether each is searched (not given).
    hyper: Vec<f64>,
    searched: Vec<bool>,
}

/// The result of fitting a model to the channels.
struct FitState {
    terms: Vec<FitTerm>,
    /// All linear columns: offsets first, then each term's.
    cols: Vec<Vec<f64>>,
    coefs: Vec<f64>,
    residual: Vec<f64>,
    n_offsets: usize,
}

fn design(st: &Stack, terms: &[FitTerm]) -> Vec<Vec<f64>> {
    let mut cols = st.offsets();
    for t in terms {
        cols.extend(columns(st, t.name, &t.shape, &t.hyper));
    }
    cols
}

/// Drops columns that are all zero (an effect no channel sees) so the solver sees a clean design;
/// returns the kept indices.
fn solve(r: &[f64], cols: &[Vec<f64>], sigma: &Sigma) -> Result<(Vec<f64>, Vec<f64>), String> {
    let keep: Vec<usize> = (0..cols.len()).filter(|&j| cols[j].iter().any(|v| *v != 0.0)).collect();
    let sub: Vec<Vec<f64>> = keep.iter().map(|&j| cols[j].clone()).collect();
    if sub.is_empty() {
        return Ok((vec![0.0; cols.len()], r.to_vec()));
    }
    let fit = fit_signature(r, &sub, sigma).map_err(|e| e.to_string())?;
    let mut beta = vec![0.0; cols.len()];
    for (k, &j) in keep.iter().enumerate() {
        beta[j] = if fit.coefficients[k].is_finite() { fit.coefficients[k] } else { 0.0 };
    }
    Ok((beta, fit.residual))
}

fn weighted_ss(r: &[f64], w: &[f64]) -> f64 {
    r.iter().zip(w).map(|(a, b)| (a * b).powi(2)).sum()
}

/// Golden-section minimum of f on [a, b] (log scale), `iters` iterations.
fn golden(a: f64, b: f64, iters: usize, f: &mut dyn FnMut(f64) -> f64) -> f64 {
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut la, mut lb) = (a.ln(), b.ln());
    let mut c = lb - g * (lb - la);
    let mut d = la + g * (lb - la);
    let (mut fc, mut fd) = (f(c.exp()), f(d.exp()));
    for _ in 0..iters {
        if fc < fd {
            lb = d;
            d = c;
            fd = fc;
            c = lb - g * (lb - la);
            fc = f(c.exp());
        } else {
            la = c;
            c = d;
            fc = fd;
            d = la + g * (lb - la);
            fd = f(d.exp());
        }
    }
    0.5 * (la.exp() + lb.exp())
}

fn fit_model_on(st: &Stack, model: &Model, sigma: &Sigma, w: &[f64]) -> Result<FitState, String> {
    let mut known = vec![0.0; st.n];
    let mut terms: Vec<FitTerm> = Vec::new();
    for (index, me) in model.effects.iter().enumerate() {
        if me.effect.axis != model.axis || !predicts(me.effect.name) {
            continue;
        }
        if !me.fit {
            let mut e = me.effect.clone();
            if let EffectParams::Stribeck(sp) = &mut e.params {
                // The simulator's law: stribeck.fc unset takes the coulomb level.
                if sp.fc.is_none() {
                    sp.fc = model.get(EffectName::Coulomb, model.axis).and_then(|c| c.effect.params.get("fc"));
                }
            }
            for (k, v) in known_prediction(st, &e).into_iter().enumerate() {
                known[k] += v;
            }
            continue;
        }
        let sh = shape(st, me.effect.name, 1, me.order.unwrap_or(DEFAULT_ORDER), lacks_coulomb(model));
        let mut hyper = Vec::new();
        let mut searched = Vec::new();
        for h in &sh.hypers {
            let given = me.given.iter().any(|g| g == h);
            let start = me.effect.params.get(h).unwrap_or(1.0);
            // A given period (screw lead, signal period) is held; a given τ is a starting value.
            // A damping that these data cannot resolve (no predicted excitation) is held.
            let resolvable = *h != "damping" || hyper_grid(st, me.effect.name, h).1;
            hyper.push(if given || !resolvable { start } else { f64::NAN });
            searched.push(!(given && *h == "period") && resolvable);
            let _ = st;
        }
        terms.push(FitTerm { index, name: me.effect.name, shape: sh, hyper, searched });
    }
    let y = st.y();
    let r0: Vec<f64> = y.iter().zip(&known).map(|(a, b)| a - b).collect();
    // Start every searched hyper-parameter in the middle of its grid (or at its given value), then
    // sweep: per hyper-parameter a grid search and a golden-section refinement, the others held.
    let grids: Vec<Vec<(Vec<f64>, bool)>> = terms
        .iter()
        .map(|t| {
            (0..t.hyper.len())
                .map(|hi| {
                    let v = t.hyper[hi];
                    if v.is_finite() && t.shape.hypers[hi] == "frequency" {
                        // A given mode frequency is a starting value: ±5 % in 41 steps.
                        ((0..41).map(|k| v * (0.95 + 0.0025 * k as f64)).collect(), true)
                    } else if v.is_finite() {
                        (log_grid(v / 10.0, v * 10.0, 21), true)
                    } else {
                        hyper_grid(st, t.name, t.shape.hypers[hi])
                    }
                })
                .collect()
        })
        .collect();
    for (t, g) in terms.iter_mut().zip(&grids) {
        for (hi, (grid, _)) in g.iter().enumerate() {
            if t.hyper[hi].is_nan() {
                t.hyper[hi] = grid[grid.len() / 2];
            }
        }
    }
    let n_searched: usize = terms.iter().map(|t| t.searched.iter().filter(|s| **s).count()).sum();
    let sweeps = if n_searched > 1 { 2 } else { 1 };
    for _ in 0..sweeps {
        for ti in 0..terms.len() {
            for hi in 0..terms[ti].hyper.len() {
                if !terms[ti].searched[hi] {
                    continue;
                }
                let (grid, refine) = &grids[ti][hi];
                let eval = |v: f64, terms: &mut Vec<FitTerm>| -> f64 {
                    terms[ti].hyper[hi] = v;
                    match solve(&r0, &design(st, terms), sigma) {
                        Ok((_, r)) => weighted_ss(&r, w),
                        Err(_) => f64::INFINITY,
                    }
                };
                let mut best = (f64::INFINITY, grid[0]);
                for &g in grid {
                    let s = eval(g, &mut terms);
                    if s < best.0 {
                        best = (s, g);
                    }
                }
                let mut v = best.1;
                if *refine && grid.len() > 1 {
                    let k = grid.iter().position(|g| *g == best.1).unwrap_or(0);
                    let a = grid[k.saturating_sub(1)];
                    let b = grid[(k + 1).min(grid.len() - 1)];
                    let mut tt = terms.clone();
                    v = golden(a, b, 40, &mut |x| eval(x, &mut tt));
                    if eval(v, &mut terms) > best.0 {
                        v = best.1;
                    }
                }
                terms[ti].hyper[hi] = v;
            }
        }
    }
    let cols = design(st, &terms);
    let (coefs, residual) = solve(&r0, &cols, sigma)?;
    Ok(FitState { terms, cols, coefs, residual, n_offsets: st.n_groups })
}

/// The fitted parameters of each term as effect parameters (FORMAT.md §2 keys).
fn term_params(fs: &FitState, model: &Model) -> BTreeMap<String, BTreeMap<String, f64>> {
    let mut out = BTreeMap::new();
    let mut j = fs.n_offsets;
    for t in &fs.terms {
        let k = t.shape.coefs.len();
        let c = &fs.coefs[j..j + k];
        j += k;
        let me = &model.effects[t.index];
        out.insert(t.name.as_str().to_string(), describe(t.name, &t.shape, c, &t.hyper, &me.effect.params));
    }
    // A Stribeck term without its own Fc rides on the model's Coulomb level: fs = Fc + (Fs − Fc).
    if let Some(t) = fs.terms.iter().find(|t| t.name == EffectName::Stribeck && !t.shape.with_fc) {
        let own = model.effects[t.index].effect.params.get("fc").unwrap_or(0.0);
        let fc = coulomb_level(model, &out) - own;
        if let Some(v) = out.get_mut("stribeck").and_then(|m| m.get_mut("fs")) {
            *v += fc;
        }
    }
    out
}

/// Linear coefficients + hyper-parameters → the effect's parameters by FORMAT.md §2 key.
fn describe(name: EffectName, sh: &Shape, c: &[f64], h: &[f64], start: &EffectParams) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    match name {
        n if n.is_error_motion() => {
            for (k, v) in c.iter().enumerate() {
                m.insert(format!("c{}", sh.first_power as usize + k), *v);
            }
        }
        EffectName::CyclicLead | EffectName::InterpolationError => {
            m.insert("period".into(), h[0]);
            m.insert("amplitude".into(), c[0].hypot(c[1]));
            m.insert("phase".into(), c[1].atan2(c[0]));
        }
        EffectName::ThermalExpansion => {
            let alpha = start.get("alpha").filter(|a| *a != 0.0).unwrap_or(ALPHA_STEEL);
            m.insert("alpha".into(), alpha);
            m.insert("delta_t".into(), c[0] / alpha);
            m.insert("tau".into(), h[0]);
        }
        EffectName::ThermalDrift => {
            m.insert("value".into(), c[0]);
            m.insert("tau".into(), h[0]);
        }
        EffectName::Coulomb => {
            m.insert("fc".into(), c[0]);
        }
        EffectName::Viscous => {
            m.insert("fv".into(), c[0]);
        }
        EffectName::Stribeck => {
            // fs = Fc + (Fs − Fc); Fc is this fit's own (with_fc) or the model's coulomb level.
            let fc = if sh.with_fc { c[1] } else { start.get("fc").unwrap_or(0.0) };
            if sh.with_fc {
                m.insert("fc".into(), fc);
            }
            m.insert("fs".into(), fc + c[0]);
            m.insert("vs".into(), h[0]);
            m.insert("shape".into(), 2.0);
        }
        EffectName::Resonance => {
            // Frequency and damping; the forced response's gain per sensor (the mode shape φ at
            // the sensor, dimensionless); the RMS amplitude of the narrow-band segments, m/s².
            m.insert("frequency".into(), h[0]);
            m.insert("damping".into(), h[1]);
            let mut seg: Vec<f64> = Vec::new();
            for (k, v) in sh.coefs.iter().zip(c) {
                if k.starts_with("gain_") {
                    m.insert(k.clone(), *v);
                } else if k.starts_with("sin_") || k.starts_with("cos_") {
                    seg.push(*v);
                }
            }
            if !seg.is_empty() {
                let rms = (seg.iter().map(|v| v * v).sum::<f64>() / seg.len() as f64).sqrt();
                m.insert("amplitude_rms".into(), rms * std::f64::consts::SQRT_2 / 2.0);
            }
            let _ = start;
        }
        EffectName::GravityTilt => {
            // Tilt of each sensor's sensitive axis, rad: Σ_k c_k·x^k (x in m), by sensor.
            for (k, v) in sh.coefs.iter().zip(c) {
                m.insert(format!("tilt_{k}"), *v);
            }
        }
        _ => {
            m.insert("value".into(), c[0]);
        }
    }
    m
}

// ------------------------------------------------------------------------------------------
// Reports.

/// One channel of `vmt compare` (FORMAT.md §4 `channels[]`, plus details).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChannelReport {
    /// Run name.
    pub run: String,
    /// SI unit of the channel's values (`m` for deviations, `N` for motor forces).
    pub unit: String,
    /// Sensor name.
    pub sensor: String,
    /// RMS of the residual, SI unit of the channel (m).
    pub rms: f64,
    /// RMS of residual/σ.
    pub normalized_rms: f64,
    /// NRMSE fit, % : 100·(1 − ‖y − ŷ‖/‖y − ȳ‖).
    pub fit_percent: f64,
    /// The σ used, m.
    pub sigma: f64,
    /// True when σ was estimated from the residual (the manifest gives none).
    pub sigma_estimated: bool,
    /// Fitted offset (instrument zero), m.
    pub offset: f64,
    /// Fraction of autocorrelation lags outside ±1.96/√n (white: about 5 %).
    pub acf_fraction_outside: Option<f64>,
    /// Ljung–Box p-value of the residual in acquisition order (small: not white).
    pub ljung_box_p: Option<f64>,
    /// Residual by approach direction: (direction, mean, rms).
    pub by_direction: Vec<(i8, f64, f64)>,
    /// Residual by run number (cycle): (cycle, mean, rms).
    pub by_cycle: Vec<(u32, f64, f64)>,
    /// Residual by position bin: (lower, upper, mean, rms), m.
    pub by_position: Vec<(f64, f64, f64, f64)>,
    /// Residual by time bin: (lower, upper, mean, rms), s.
    pub by_time: Vec<(f64, f64, f64, f64)>,
    /// Strongest spatial periods of the residual: (wavelength m, amplitude m), from a
    /// least-squares periodogram over position.
    pub spectrum_peaks: Vec<(f64, f64)>,
}

/// One iteration of the loop, as kept in `history.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HistoryEntry {
    /// Model file.
    pub model: String,
    /// Data it was compared with.
    pub data: String,
    /// Effect added to reach it (empty for the starting model).
    pub added: String,
    /// Normalised RMS of the residual.
    pub normalized_rms: f64,
}

/// `vmt compare` (FORMAT.md §4; extra keys allowed).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompareReport {
    /// Model file.
    pub model: String,
    /// Data directory.
    pub data: String,
    /// Per channel.
    pub channels: Vec<ChannelReport>,
    /// RMS of residual/σ over all samples of all channels.
    pub normalized_rms: f64,
    /// Fitted parameters by effect.
    pub fitted: BTreeMap<String, BTreeMap<String, f64>>,
    /// Number of samples.
    pub n: usize,
    /// Number of fitted parameters (offsets included).
    pub n_params: usize,
    /// What was skipped or estimated.
    pub notes: Vec<String>,
    /// Iterations so far (history.json beside the model), if any.
    pub history: Vec<HistoryEntry>,
}

/// `vmt diagnose` (FORMAT.md §4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiagnoseReport {
    /// Normalised RMS of the model's residual.
    pub normalized_rms: f64,
    /// Candidates, best first.
    pub ranking: Vec<RankingEntry>,
    /// What to do next.
    pub advice: String,
    /// Notes (skipped channels, estimated σ).
    pub notes: Vec<String>,
}

/// Everything a compare computes, for diagnose to build on.
struct Fitted<'a> {
    st: Stack<'a>,
    fs: FitState,
    sig: Vec<f64>,
    est: Vec<bool>,
    notes: Vec<String>,
}

fn fit_all<'a>(model: &Model, chans: &'a [Channel], data: &Path) -> Result<Fitted<'a>, VmtError> {
    let st = Stack::with_model(chans, model);
    let bad = |m: String| VmtError::bad(data, "", m);
    // Every fitted effect must be seen by some channel.
    for me in model.effects.iter().filter(|m| m.fit && m.effect.axis == model.axis && predicts(m.effect.name)) {
        let sh = shape(&st, me.effect.name, 1, me.order.unwrap_or(DEFAULT_ORDER), lacks_coulomb(model));
        let period = me.given.iter().any(|g| g == "period").then(|| me.effect.params.get("period")).flatten();
        if !visible(&st, me.effect.name, &sh, period) {
            return Err(bad(format!(
                "the model fits `{}` on axis {}, but no channel of the data sees it: {}",
                me.effect.name,
                me.effect.axis,
                needs(me.effect.name)
            )));
        }
    }
    let mut notes = Vec::new();
    // Pass 1: weights from the known σ (1 where unknown); estimate the unknown σ from the residual.
    let mut sig: Vec<f64> = chans.iter().map(|c| c.sigma.unwrap_or(f64::NAN)).collect();
    let est: Vec<bool> = sig.iter().map(|s| s.is_nan()).collect();
    for pass in 0..2 {
        let per = st_sigma(&st, &sig);
        let w: Vec<f64> = per.iter().map(|s| 1.0 / s).collect();
        let sigma = Sigma::PerSample(per);
        let fs = fit_model_on(&st, model, &sigma, &w).map_err(|m| bad(format!("fitting the model: {m}")))?;
        if pass == 0 && est.iter().any(|e| *e) {
            let mut k0 = 0;
            for (j, c) in chans.iter().enumerate() {
                let r = &fs.residual[k0..k0 + c.y.len()];
                k0 += c.y.len();
                if est[j] {
                    let (s, how) = match repeatability_sigma(c, r) {
                        Some(s) => (s, "pooled spread of repeated readings at each target and direction"),
                        None => (
                            estimate_noise_sigma(r).map_err(|e| {
                                bad(format!(
                                    "sensor `{}` in run `{}` has no sigma in the manifest and its {} readings are \
                                     too few to estimate it ({e}); give `sigma` for the sensor",
                                    c.sensor,
                                    c.run,
                                    c.y.len()
                                ))
                            })?,
                            "successive differences of the residual",
                        ),
                    };
                    sig[j] = s;
                    notes.push(format!(
                        "sigma of `{}` in run `{}` estimated from the data ({how}): {} m",
                        c.sensor,
                        c.run,
                        fmt_num(s)
                    ));
                }
            }
            continue;
        }
        return Ok(Fitted { st, fs, sig, est, notes });
    }
    Err(VmtError::Internal("fit loop ended".into()))
}

/// Minimum degrees of freedom of the repeatability estimate of σ (relative error ≈ 1/√(2·dof) ≤ 22 %).
const MIN_REPEAT_DOF: usize = 10;

/// σ of one reading from repeated approaches (ISO 230-2 repeatability): the residual grouped by
/// (target, direction), σ̂² = Σ (r − r̄_group)² / (N − G); None with fewer than
/// [`MIN_REPEAT_DOF`] degrees of freedom or a zero spread.
fn repeatability_sigma(c: &Channel, r: &[f64]) -> Option<f64> {
    let mut groups: BTreeMap<(u64, i8), Vec<f64>> = BTreeMap::new();
    for i in 0..r.len() {
        groups.entry((c.x[i].to_bits(), if c.d[i] > 0.0 { 1 } else { -1 })).or_default().push(r[i]);
    }
    let dof = r.len().checked_sub(groups.len())?;
    if dof < MIN_REPEAT_DOF {
        return None;
    }
    let ss: f64 = groups
        .values()
        .map(|g| {
            let m = g.iter().sum::<f64>() / g.len() as f64;
            g.iter().map(|v| (v - m).powi(2)).sum::<f64>()
        })
        .sum();
    let s = (ss / dof as f64).sqrt();
    (s > 0.0).then_some(s)
}

/// Per-sample σ from per-channel σ (NaN → 1: unweighted first pass).
fn st_sigma(st: &Stack, sig: &[f64]) -> Vec<f64> {
    let mut v = Vec::with_capacity(st.n);
    for (c, s) in st.chans.iter().zip(sig) {
        v.extend(std::iter::repeat(if s.is_finite() { *s } else { 1.0 }).take(c.y.len()));
    }
    v
}

/// True when some channel sees effect `name` (a non-zero column) at the hyper-parameter `fixed`, or
/// at some value of its search grid.
fn visible(st: &Stack, name: EffectName, sh: &Shape, fixed: Option<f64>) -> bool {
    if name == EffectName::Resonance {
        // Any excited channel or any narrow-band segment (sin/cos are never both zero).
        return st.excitation.iter().any(|e| e.is_some()) || !resonance_segments(st).is_empty();
    }
    let grid: Vec<f64> = match (fixed, sh.hypers.first()) {
        (Some(v), _) => vec![v],
        (None, Some(h)) => hyper_grid(st, name, h).0,
        (None, None) => vec![1.0],
    };
    grid.iter().any(|g| {
        let h: Vec<f64> = sh.hypers.iter().map(|_| *g).collect();
        columns(st, name, sh, &h).iter().any(|c| c.iter().any(|v| *v != 0.0))
    })
}

/// What data shows an effect (for the "missing channel" message and the advice).
fn needs(name: EffectName) -> &'static str {
    match name {
        EffectName::Positioning => "needs a laser_linear along the axis in a positioning run",
        EffectName::StraightnessY | EffectName::StraightnessZ => {
            "needs a laser_straightness across the axis in a positioning run, or an accelerometer across the axis \
             in a constant-velocity run"
        }
        EffectName::Roll | EffectName::Pitch | EffectName::Yaw => {
            "needs a laser whose measuring point is offset from the axis (an Abbe offset) across its direction"
        }
        EffectName::Backlash | EffectName::CyclicLead => "needs a laser_linear or a linear scale in a positioning run",
        _ => "needs a laser_linear along the axis in a positioning run",
    }
}

fn load_channels(model: &Model, set: &MeasurementSet, data: &Path) -> Result<(Vec<Channel>, Vec<String>), VmtError> {
    let (chans, mut notes) = channels(set, model.axis);
    if chans.is_empty() {
        return Err(VmtError::bad(
            data,
            "runs",
            format!(
                "no channel the model can be compared with: expected a positioning point table of axis {} with a \
                 laser or encoder deviation column, or a constant-velocity or friction-sweep time series with a \
                 `feed` and a motor_force or accelerometer column",
                model.axis
            ),
        ));
    }
    for me in model.effects.iter().filter(|m| !predicts(m.effect.name)) {
        notes.push(format!("effect `{}` is not predicted (module doc): left out", me.effect.name));
    }
    Ok((chans, notes))
}

/// `vmt compare` on in-memory inputs: fits the model's free parameters to the point-table channels
/// of `set` and reports residual statistics per channel and overall (module doc for the model;
/// FORMAT.md §4 for the keys). `data` names the data in messages and the report.
pub fn compare(model: &Model, set: &MeasurementSet, data: &Path) -> Result<CompareReport, VmtError> {
    let (chans, mut notes) = load_channels(model, set, data)?;
    let f = fit_all(model, &chans, data)?;
    notes.extend(f.notes.iter().cloned());
    let pred_total: Vec<f64> = f.st.y().iter().zip(&f.fs.residual).map(|(y, r)| y - r).collect();
    let mut out = Vec::new();
    let mut k0 = 0;
    let mut sum_sq = 0.0;
    for (j, c) in chans.iter().enumerate() {
        let m = c.y.len();
        let r = &f.fs.residual[k0..k0 + m];
        let p = &pred_total[k0..k0 + m];
        k0 += m;
        let s = f.sig[j];
        sum_sq += r.iter().map(|v| (v / s).powi(2)).sum::<f64>();
        out.push(channel_report(c, r, p, s, f.est[j], f.fs.coefs[f.st.group[j]]));
    }
    let n = f.st.n;
    Ok(CompareReport {
        model: model.source.display().to_string(),
        data: data.display().to_string(),
        channels: out,
        normalized_rms: (sum_sq / n as f64).sqrt(),
        fitted: term_params(&f.fs, model),
        n,
        n_params: f.fs.cols.len(),
        notes,
        history: read_history(&history_path(&model.source)).unwrap_or_default(),
    })
}

fn channel_report(c: &Channel, r: &[f64], p: &[f64], s: f64, est: bool, offset: f64) -> ChannelReport {
    let m = r.len();
    let rms = (r.iter().map(|v| v * v).sum::<f64>() / m as f64).sqrt();
    let lag = (m / 4).clamp(1, 20);
    let acf = autocorrelation(r, lag).ok().map(|a| a.fraction_outside);
    let lb = ljung_box(r, lag, 0).ok().map(|l| l.p_value);
    let labels: Vec<i8> = c.d.iter().map(|d| if *d > 0.0 { 1 } else { -1 }).collect();
    let by_direction =
        bin_by_label(r, &labels).map(|b| b.into_iter().map(|x| (x.key, x.mean, x.rms)).collect()).unwrap_or_default();
    let by_cycle =
        bin_by_label(r, &c.cycle).map(|b| b.into_iter().map(|x| (x.key, x.mean, x.rms)).collect()).unwrap_or_default();
    let ranged = |keys: &[f64]| -> Vec<(f64, f64, f64, f64)> {
        let lo = keys.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = keys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if hi <= lo {
            return Vec::new();
        }
        let edges = match uniform_edges(lo, hi + 1e-12 * (hi - lo).abs().max(1.0), 5) {
            Ok(e) => e,
            Err(_) => return Vec::new(),
        };
        bin_by_edges(r, keys, &edges)
            .map(|b| {
                b.bins
                    .into_iter()
                    .filter_map(|x| Some((x.lower, x.upper, x.mean?, x.rms?)))
                    .collect::<Vec<(f64, f64, f64, f64)>>()
            })
            .unwrap_or_default()
    };
    let spectrum_peaks = frequency_grid(&c.x, 5.0, None)
        .ok()
        .and_then(|g| ls_periodogram(&c.x, r, &Sigma::Unknown, &g).ok())
        .map(|pg| {
            let mut idx: Vec<usize> = (0..pg.frequency.len()).collect();
            idx.sort_by(|a, b| pg.amplitude[*b].total_cmp(&pg.amplitude[*a]));
            idx.into_iter().take(3).map(|i| (1.0 / pg.frequency[i], pg.amplitude[i])).collect()
        })
        .unwrap_or_default();
    ChannelReport {
        run: c.run.clone(),
        unit: match c.kind {
            SensorKind::MotorForce => "N".into(),
            SensorKind::Accelerometer => "m/s²".into(),
            _ => "m".into(),
        },
        sensor: c.sensor.clone(),
        rms,
        normalized_rms: rms / s,
        fit_percent: fit_percent(&c.y, p).unwrap_or(f64::NAN),
        sigma: s,
        sigma_estimated: est,
        offset,
        acf_fraction_outside: acf,
        ljung_box_p: lb,
        by_direction,
        by_cycle,
        by_position: ranged(&c.x),
        by_time: ranged(&c.t),
        spectrum_peaks,
    }
}

/// The candidates for effects the model lacks that phase 1 can express, each with its shape.
fn candidate_names(model: &Model, st: &Stack) -> Vec<EffectName> {
    EffectName::ALL
        .iter()
        .copied()
        .filter(|n| predicts(*n) && model.get(*n, model.axis).is_none())
        .filter(|n| visible(st, *n, &candidate_shape(st, *n, lacks_coulomb(model)), None))
        .collect()
}

/// A candidate's shape: error motions as a cubic without constant term; the positioning candidate
/// without its linear term as well (a linear positioning error is the scale error's signature).
fn candidate_shape(st: &Stack, n: EffectName, with_fc: bool) -> Shape {
    shape(st, n, if n == EffectName::Positioning { 2 } else { 1 }, DEFAULT_ORDER, with_fc)
}

/// True when the model has no `coulomb` effect on its axis (a Stribeck term then fits its own Fc).
fn lacks_coulomb(model: &Model) -> bool {
    model.get(EffectName::Coulomb, model.axis).is_none()
}

/// The model's Coulomb level: fitted (`fitted`) or known, 0 without one, N.
fn coulomb_level(model: &Model, fitted: &BTreeMap<String, BTreeMap<String, f64>>) -> f64 {
    fitted
        .get("coulomb")
        .and_then(|m| m.get("fc").copied())
        .or_else(|| model.get(EffectName::Coulomb, model.axis).and_then(|m| m.effect.params.get("fc")))
        .unwrap_or(0.0)
}

/// `vmt diagnose` on in-memory inputs: fits the model, then every catalogue effect the model lacks
/// that these channels can show is fitted to the weighted residual together with the model's own
/// linear columns, ranked by ΔBIC with verdicts (`vmt_estimators::modelcheck::rank_candidates`).
pub fn diagnose(model: &Model, set: &MeasurementSet, data: &Path) -> Result<DiagnoseReport, VmtError> {
    let (chans, mut notes) = load_channels(model, set, data)?;
    let f = fit_all(model, &chans, data)?;
    notes.extend(f.notes.iter().cloned());
    let per = st_sigma(&f.st, &f.sig);
    let nrms = (f.fs.residual.iter().zip(&per).map(|(r, s)| (r / s).powi(2)).sum::<f64>() / f.st.n as f64).sqrt();
    let names = candidate_names(model, &f.st);
    let fc_ref = coulomb_level(model, &term_params(&f.fs, model));
    let st = &f.st;
    let cands: Vec<Candidate> = names
        .iter()
        .map(|&n| {
            let sh = candidate_shape(st, n, lacks_coulomb(model));
            let sh2 = sh.clone();
            let coef: Vec<&str> = sh.coefs.iter().map(|s| s.as_str()).collect();
            let mut c = Candidate::new(n.as_str(), &coef, move |h: &[f64]| {
                let cols = columns(st, n, &sh2, h);
                if cols.iter().all(|c| c.iter().all(|v| *v == 0.0)) {
                    Err("the signature vanishes on these samples (an alias of a constant)".to_string())
                } else {
                    Ok(cols)
                }
            });
            for hname in &sh.hypers {
                let (grid, refine) = hyper_grid(st, n, hname);
                c.hyper_parameters.push(HyperParameter { name: hname.to_string(), grid, refine });
            }
            let sh3 = sh.clone();
            let mut start = EffectParams::default_for(n);
            if n == EffectName::Stribeck {
                start.set("fc", fc_ref);
            }
            c.with_describe(move |coefs: &[f64], h: &[f64]| describe(n, &sh3, coefs, h, &start))
        })
        .collect();
    let mut ranking: Vec<RankingEntry> = Vec::new();
    if !cands.is_empty() {
        let sigma = Sigma::PerSample(per.clone());
        let base: Vec<Vec<f64>> = f.fs.cols.iter().filter(|c| c.iter().any(|v| *v != 0.0)).cloned().collect();
        let input =
            vmt_estimators::modelcheck::ResidualInput { residual: &f.fs.residual, sigma: &sigma, base_columns: &base };
        match rank_candidates(&input, &cands, &DiagnoseConfig::default()) {
            Ok(d) => ranking = d.ranking,
            Err(vmt_estimators::modelcheck::ModelCheckError::NothingToExplain) => {
                notes.push("the model explains the data exactly: nothing to diagnose".into())
            }
            Err(e) => return Err(VmtError::bad(data, "", format!("diagnose: {e}"))),
        }
    }
    let advice = advice(&ranking, nrms);
    Ok(DiagnoseReport { normalized_rms: nrms, ranking, advice, notes })
}

/// What measurement separates two effects that fit the same signature on these data.
pub fn separating_measurement(a: &str, b: &str) -> String {
    let pair = |x: &str, y: &str| (a == x && b == y) || (a == y && b == x);
    let angular = |e: &str| matches!(e, "roll" | "pitch" | "yaw");
    let linear = |e: &str| matches!(e, "positioning" | "straightness_y" | "straightness_z" | "scale_error");
    if pair("thermal_expansion", "scale_error") || pair("thermal_expansion", "positioning") {
        "repeat the positioning test later, when the machine is warm (runs at different times): thermal expansion \
         grows with time, a scale error does not"
            .into()
    } else if a == "thermal_drift" || b == "thermal_drift" {
        "record the readings over a longer time, or repeat the test after a pause: a drift grows with time".into()
    } else if (angular(a) && linear(b)) || (angular(b) && linear(a)) || (angular(a) && angular(b)) {
        "measure with a second laser at another height or lateral offset (a different Abbe offset), or with an \
         angular laser: an angular error motion scales with the offset, a translation does not"
            .into()
    } else if pair("cyclic_lead", "interpolation_error") {
        "measure at target spacings finer than the screw lead and than the scale's signal period".into()
    } else if a == "backlash" || b == "backlash" {
        "approach every target from both directions (bidirectional ISO 230-2 cycle)".into()
    } else {
        "measure at more positions, at other times or with a sensor at another offset, so that the two \
         signatures differ"
            .into()
    }
}

/// The advice text of a diagnosis.
fn advice(ranking: &[RankingEntry], nrms: f64) -> String {
    let mut parts: Vec<String> = Vec::new();
    let sig: Vec<&RankingEntry> = ranking.iter().filter(|r| r.verdict == Verdict::Significant).collect();
    for r in &sig {
        parts.push(format!(
            "`{}` is significant (ΔBIC {:.1}, explains {:.0} % of the residual): add it with \
             `vmt add --effect {} --from-diagnosis`.",
            r.effect,
            r.delta_bic,
            100.0 * r.explained,
            r.effect
        ));
    }
    let mut seen: Vec<(String, String)> = Vec::new();
    for r in ranking.iter().filter(|r| r.verdict == Verdict::Inseparable) {
        for o in &r.confused_with {
            let key = if r.effect < *o { (r.effect.clone(), o.clone()) } else { (o.clone(), r.effect.clone()) };
            if seen.contains(&key) {
                continue;
            }
            parts.push(format!(
                "`{}` and `{}` explain the residual equally well on these data and cannot be told apart: {}.",
                key.0,
                key.1,
                separating_measurement(&key.0, &key.1)
            ));
            seen.push(key);
        }
    }
    if parts.is_empty() {
        parts.push(format!("no missing effect is significant at this noise level (normalised RMS {nrms:.2})."));
        if nrms > 1.5 {
            parts.push(
                "The residual is above the noise but no catalogue effect explains it: look at the residual by \
                 position, direction and time in `vmt compare`, or fit an error motion with a richer basis."
                    .into(),
            );
        }
    }
    parts.join(" ")
}

// ------------------------------------------------------------------------------------------
// vmt add and the history.

/// The model with effect `name` (on the model's axis) added, `fit = true`; with `from` (a ranking
/// entry of a diagnosis) its parameters are the starting values: error-motion polynomial
/// coefficients `cK`, or the scalar parameters by key.
pub fn add_effect(model: &Model, name: EffectName, from: Option<&RankingEntry>) -> Result<Model, String> {
    if model.get(name, model.axis).is_some() {
        return Err(format!("the model already has `{name}` on axis {}", model.axis));
    }
    let mut effect = Effect { name, axis: model.axis, params: EffectParams::default_for(name) };
    let mut given: Vec<String> = Vec::new();
    if let Some(r) = from {
        if name.is_error_motion() {
            let deg = r.params.keys().filter_map(|k| k.strip_prefix('c')?.parse::<usize>().ok()).max().unwrap_or(0);
            let mut c = vec![0.0; deg + 1];
            for (k, v) in &r.params {
                if let Some(i) = k.strip_prefix('c').and_then(|s| s.parse::<usize>().ok()) {
                    c[i] = *v;
                }
            }
            effect.params = EffectParams::ErrorMotion(Profile { terms: vec![Term::Poly(c)] });
            given.push("poly".into());
        } else {
            for (k, v) in &r.params {
                if effect.params.set(k, *v) {
                    given.push(k.clone());
                }
            }
            // Amplitudes are ≥ 0 by the catalogue's ranges: fold a negative one into the phase.
            if matches!(name, EffectName::Backlash) && effect.params.get("value").is_some_and(|v| v < 0.0) {
                let v = effect.params.get("value").unwrap_or(0.0);
                effect.params.set("value", v.abs());
            }
            if matches!(name, EffectName::ThermalDrift | EffectName::ThermalExpansion) {
                if let Some(t) = effect.params.get("tau") {
                    effect.params.set("tau", t.max(0.0));
                }
            }
        }
    }
    if let Some(p) = effect.validate().into_iter().next() {
        return Err(format!("{}: {}", p.key, p.message));
    }
    let mut m = model.clone();
    m.insert(ModelEffect { effect, fit: true, basis: None, order: None, given });
    Ok(m)
}

/// `history.json` beside a model file.
pub fn history_path(model_path: &Path) -> PathBuf {
    model_path.parent().map(|p| p.join("history.json")).unwrap_or_else(|| PathBuf::from("history.json"))
}

/// Reads a history file (an array of [`HistoryEntry`]); None if absent or unreadable.
pub fn read_history(path: &Path) -> Option<Vec<HistoryEntry>> {
    let text = std::fs::read_to_string(path).ok()?;
    serde_json::from_str(&text).ok()
}

/// Appends entries to a history file (written atomically).
pub fn append_history(path: &Path, entries: &[HistoryEntry]) -> Result<(), VmtError> {
    let mut h = read_history(path).unwrap_or_default();
    h.extend(entries.iter().cloned());
    let text = serde_json::to_string_pretty(&h).map_err(|e| VmtError::Internal(e.to_string()))?;
    write_file_atomic(path, text.as_bytes())
}

// ------------------------------------------------------------------------------------------
// Human-readable output.

/// The text report of a compare.
pub fn compare_text(r: &CompareReport) -> String {
    let mut s = format!("vmt compare: model {} against {}\n", r.model, r.data);
    s += &format!(
        "{:<12} {:<14} {:>12} {:>10} {:>8} {:>12} {:>8}\n",
        "run", "sensor", "rms", "rms/σ", "fit %", "σ", "LB p"
    );
    for c in &r.channels {
        // Deviations in µm, forces in N.
        let (k, u) = match c.unit.as_str() {
            "N" => (1.0, "N"),
            "m/s²" => (1.0, "m/s²"),
            _ => (1e6, "µm"),
        };
        s += &format!(
            "{:<12} {:<14} {:>9.4} {u:<2} {:>10.2} {:>8.1} {:>9.4} {u:<2}{} {:>8}\n",
            c.run,
            c.sensor,
            c.rms * k,
            c.normalized_rms,
            c.fit_percent,
            c.sigma * k,
            if c.sigma_estimated { "*" } else { " " },
            c.ljung_box_p.map_or("-".to_string(), |p| format!("{p:.3}"))
        );
        let dir: Vec<String> = c.by_direction.iter().map(|(d, m, _)| format!("{d:+}: {:.3}", m * k)).collect();
        s += &format!("    mean residual by direction ({u}): {}\n", dir.join(", "));
        let pos: Vec<String> =
            c.by_position.iter().map(|(a, b, m, _)| format!("{:.0}–{:.0} mm {:.3}", a * 1e3, b * 1e3, m * k)).collect();
        s += &format!("    by position: {}\n", pos.join("; "));
        if let Some((wl, a)) = c.spectrum_peaks.first() {
            s += &format!("    strongest spatial period: {:.2} mm, amplitude {:.3} {u}\n", wl * 1e3, a * k);
        }
    }
    s += &format!("normalised RMS (all samples): {:.3}   (1.0 = noise level; * σ estimated)\n", r.normalized_rms);
    for (e, p) in &r.fitted {
        let kv: Vec<String> = p.iter().map(|(k, v)| format!("{k} = {}", fmt_num(*v))).collect();
        s += &format!("fitted {e}: {}\n", kv.join(", "));
    }
    for n in &r.notes {
        s += &format!("note: {n}\n");
    }
    if !r.history.is_empty() {
        s += "iterations (normalised RMS):\n";
        let max = r.history.iter().map(|h| h.normalized_rms).fold(0.0, f64::max).max(1e-300);
        for (i, h) in r.history.iter().enumerate() {
            let bar = "#".repeat(((h.normalized_rms / max) * 40.0).round() as usize);
            s += &format!("  {i:>2} {:>10.3} {bar} {} {}\n", h.normalized_rms, h.model, h.added);
        }
    }
    s
}

/// The text report of a diagnosis.
pub fn diagnose_text(r: &DiagnoseReport) -> String {
    let mut s = format!("vmt diagnose: normalised RMS {:.3}\n", r.normalized_rms);
    s += &format!("{:<22} {:>12} {:>10} {:<12} params\n", "effect", "ΔBIC", "explained", "verdict");
    for e in &r.ranking {
        let kv: Vec<String> = e.params.iter().map(|(k, v)| format!("{k}={}", fmt_num(*v))).collect();
        let v = match e.verdict {
            Verdict::Significant => "significant",
            Verdict::Noise => "noise",
            Verdict::Inseparable => "inseparable",
        };
        s += &format!("{:<22} {:>12.1} {:>10.3} {:<12} {}", e.effect, e.delta_bic, e.explained, v, kv.join(" "));
        if !e.confused_with.is_empty() {
            s += &format!("  (confused with {})", e.confused_with.join(", "));
        }
        s += "\n";
    }
    s += &format!("advice: {}\n", r.advice);
    for n in &r.notes {
        s += &format!("note: {n}\n");
    }
    s
}

/// True for a positioning procedure (used by callers that build sets).
pub fn is_positioning(p: Procedure) -> bool {
    p == Procedure::Positioning
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An accelerometer channel of `m` samples at 100 Hz from t = 0, x = 0.1·t.
    fn accel(run: &str, m: usize) -> Channel {
        let t: Vec<f64> = (0..m).map(|i| i as f64 / 100.0).collect();
        Channel {
            run: run.into(),
            sensor: "acc".into(),
            kind: SensorKind::Accelerometer,
            u: [0.0, 1.0, 0.0],
            r: [0.0; 3],
            x: t.iter().map(|t| 0.1 * t).collect(),
            d: vec![1.0; m],
            cycle: vec![1; m],
            t: t.clone(),
            v: vec![0.1; m],
            y: vec![0.0; m],
            sigma: Some(1e-3),
        }
    }

    /// 100 samples over 0.99 s → ⌈0.99/0.2⌉ = 5 segments; every sample falls in exactly one, and
    /// each resonance column pair is non-zero only on its own segment.
    #[test]
    fn resonance_segments_cover_every_sample_once() {
        let chans = vec![accel("a", 100), accel("b", 20)];
        let st = Stack::new(&chans);
        let segs = resonance_segments(&st);
        // Run b: 20 samples over 0.19 s → 1 segment.
        assert_eq!(segs.iter().filter(|s| s.0 == 0).count(), 5);
        assert_eq!(segs.iter().filter(|s| s.0 == 1).count(), 1);
        let sh = shape(&st, EffectName::Resonance, 1, DEFAULT_ORDER, false);
        assert_eq!(sh.coefs.len(), 12);
        let cols = columns(&st, EffectName::Resonance, &sh, &[45.0, 0.02]);
        for k in 0..st.n {
            // sin² + cos² = 1 on the one segment holding sample k, 0 elsewhere.
            let s: f64 = cols.iter().map(|c| c[k] * c[k]).sum();
            assert!((s - 1.0).abs() < 1e-12, "sample {k}: {s}");
        }
    }

    /// A y accelerometer at 0.1 m/s sampled at 100 Hz over a straightness EYX = 3e-6·x² (1/m):
    /// E'' = 6e-6 /m everywhere, so each reading is v²·E'' = 0.01·6e-6 = 6e-8 m/s², and a pitch
    /// (r = 0: r × u = 0) gives nothing. A laser sees the profile itself.
    #[test]
    fn guideway_acceleration_of_a_parabola_is_v2_times_its_curvature() {
        let c = accel("a", 10);
        let p = Profile::poly(vec![0.0, 0.0, 3e-6]);
        for i in 0..10 {
            let a = c.motion_response(i, EffectName::StraightnessY, |x| p.value(x), |x| p.eval3(x)[1]);
            assert!((a - 6e-8).abs() < 1e-20, "sample {i}: {a}");
            assert_eq!(c.motion_response(i, EffectName::Pitch, |x| p.value(x), |x| p.eval3(x)[1]), 0.0);
        }
        let mut l = accel("l", 3);
        l.kind = SensorKind::LaserStraightness;
        assert_eq!(l.motion_response(2, EffectName::StraightnessY, |x| p.value(x), |x| p.eval3(x)[1]), p.value(0.002));
    }

    /// Fitted straightness c_k·x^k on an accelerometer (u = y, v = 0.1 m/s, Δt = 0.01 s, so
    /// x_{i−1} = x_i − 1 mm): the c1 column is 0 (a slope has no acceleration), c2 is v²·2 = 0.02,
    /// c3 is v²·3·(x_i² − x_{i−1}²)/(x_i − x_{i−1}) = 0.03·(x_i + x_{i−1}) m/s² per unit c_k.
    #[test]
    fn fitted_straightness_columns_on_an_accelerometer_are_mean_curvatures_times_v2() {
        let chans = vec![accel("a", 10)];
        let st = Stack::new(&chans);
        let sh = shape(&st, EffectName::StraightnessY, 1, 3, false);
        let cols = columns(&st, EffectName::StraightnessY, &sh, &[]);
        for i in 0..10 {
            let x = chans[0].x[i];
            assert_eq!(cols[0][i], 0.0);
            assert!((cols[1][i] - 0.02).abs() < 1e-14, "{}", cols[1][i]);
            assert!((cols[2][i] - 0.03 * (2.0 * x - 0.001)).abs() < 1e-14, "{}", cols[2][i]);
        }
    }

    /// Free vibration from (q, q̇) = (1, 0): q̇(t) = −(ω²/ω_d)·e^{−ζωt}·sin(ω_d·t), ω_d = ω·√(1 − ζ²);
    /// the reading is (q̇_i − q̇_{i−1})/Δt from t_{−1} = −Δt (the sample times start at 0 and t_{−1}
    /// is the integration's zero). Agreement to 1e-9 of ω² (the step map's RK4 error is ≈ 1e-14).
    #[test]
    fn free_mode_response_matches_the_damped_oscillator() {
        let c = accel("a", 100);
        let (f, z): (f64, f64) = (12.0, 0.05);
        let w = TWO_PI * f;
        let wd = w * (1.0 - z * z).sqrt();
        let qd = |t: f64| -(w * w / wd) * (-z * w * t).exp() * (wd * t).sin();
        let r = mode_response(&c, None, f, z, (1.0, 0.0));
        for i in 0..100 {
            let (t1, t0) = (c.t[i] + 0.01, c.t[i]);
            let want = (qd(t1) - qd(t0)) / 0.01;
            assert!((r[i] - want).abs() < 1e-9 * w * w, "sample {i}: {} {want}", r[i]);
        }
    }

    /// Forced at resonance by a(τ) = A·sin(ωτ) with ζ = 0.2: after the transient (e^{−ζω·2 s} ≈
    /// e^{−25}) q̈ = −A·cos(ωτ)/(2ζ) (|H| = 1/(2ζω²) at ω, q = A·cos(ωτ)/(2ζω²)), read as the mean
    /// of q̈ over each 10 ms interval: the exact mean of that cosine, to 1e-5 of A/(2ζ) (the input
    /// is held at its mean over 0.1 ms steps, which shrinks a sinusoid by ≈ (ωh)²/24 = 1.6e-6 at
    /// 10 Hz).
    #[test]
    fn forced_mode_response_at_resonance_has_gain_one_over_two_zeta() {
        let c = accel("a", 300);
        let (f, z, amp): (f64, f64, f64) = (10.0, 0.2, 1.0);
        let w = TWO_PI * f;
        let (steps, input): (Vec<usize>, Vec<Vec<f64>>) = (0..300)
            .map(|i| {
                let m = mode_steps(0.01);
                // τ counts from t_{−1} = −Δt: interval i (t_i − Δt → t_i) starts at τ = t_i.
                let t0 = c.t[i];
                // The mean of A·sin(ωτ) over each step.
                let tk = |k: usize| t0 + 0.01 * k as f64 / m as f64;
                let vals = (0..m)
                    .map(|k| amp * ((w * tk(k)).cos() - (w * tk(k + 1)).cos()) / (w * (tk(k + 1) - tk(k))))
                    .collect();
                (m, vals)
            })
            .unzip();
        let ex = Excitation { steps, input };
        let r = mode_response(&c, Some(&ex), f, z, (0.0, 0.0));
        for i in 200..300 {
            // Interval i runs from τ = t_i to t_i + Δt (τ from t_{−1}); mean of −A·cos(ωτ)/(2ζ).
            let (a, b) = (c.t[i], c.t[i] + 0.01);
            let want = -amp / (2.0 * z) * ((w * b).sin() - (w * a).sin()) / (w * 0.01);
            assert!((r[i] - want).abs() < 1e-5 * amp / (2.0 * z), "sample {i}: {} {want}", r[i]);
        }
    }

    /// The gravity-tilt column of x^k on an accelerometer is g·x^k (g = 9.80665 m/s²), shared by the
    /// sensor's runs; a laser channel gets 0.
    #[test]
    fn gravity_tilt_columns_are_g_times_powers_of_x() {
        let mut laser = accel("c", 3);
        laser.kind = SensorKind::LaserLinear;
        laser.sensor = "laser".into();
        let chans = vec![accel("a", 10), accel("b", 10), laser];
        let st = Stack::new(&chans);
        let sh = shape(&st, EffectName::GravityTilt, 1, 3, false);
        assert_eq!(sh.coefs, vec!["acc_c1", "acc_c2", "acc_c3"]);
        let cols = columns(&st, EffectName::GravityTilt, &sh, &[]);
        // Sample 5 of run b: x = 0.1·0.05 = 0.005 m; c2 column = g·x².
        assert!((cols[1][15] - GRAVITY * 0.005f64.powi(2)).abs() < 1e-15);
        assert!(cols.iter().all(|c| c[20..].iter().all(|v| *v == 0.0)));
    }
}
