//! Signatures of the effects on the stacked samples.

use super::*;
use rayon::prelude::*;
use vmt_estimators::cpu::clear_upper_state;

// ------------------------------------------------------------------------------------------
// Signatures of the effects on the stacked samples.

// 1 − exp(−t/τ) for t > 0 (a step for τ = 0), 0 before t = 0: the simulator's thermal rise.
use vmt_sim::effects::{rise, InterpolationError};
use vmt_sim::friction::stribeck_weight;

/// The stacked samples of all channels, with per-sample sensitivities.
pub(crate) struct Stack<'a> {
    pub(crate) chans: &'a [Channel],
    pub(crate) n: usize,
    /// Offset group of each channel: one per (run, sensor) for deviations (the instrument is zeroed
    /// per run), one per sensor for motor forces (a force bias, e.g. weight on an inclined axis,
    /// does not change from run to run).
    pub(crate) group: Vec<usize>,
    pub(crate) n_groups: usize,
    /// Per channel: the base excitations of a structural mode predicted by the model, one per
    /// input (accelerometer channels only; empty where the model predicts none), see
    /// [`Excitation`]: the given translations' projection on the sensor (one input), or each
    /// fitted translation after a first fit ([`Stack::with_excitation`]).
    pub(crate) excitation: Vec<Vec<Excitation>>,
    /// Position-loop gain kv (1/s) through which a closed loop's transmission reaches its
    /// following channels ([`close_loop`]); ∞ (the identity) when the model has no servo_lag.
    pub(crate) loop_kv: f64,
    /// Gain g with which a closed loop passes its transmission T to the following channels,
    /// −[T + g·(L_kv[T] − T)] ([`close_loop`]): 1 for a continuous loop; a loop sampled every h
    /// (zero-order hold) follows its input as a continuous one with the decay rate kv and the lag
    /// scaled by g = kv·h/(1 − e^{−kv·h}) ≈ 1 + kv·h/2 (module doc of `encoder`). Fitted from the
    /// data ([`loop_gain_step`]).
    pub(crate) loop_gain: f64,
    /// The servo's sampling period h (s) where the data fix it ([`choose_servo_period`]), else
    /// NaN: a wave faster than the servo's Nyquist rate (an interpolation error at speed) reaches
    /// the motor as the servo samples it, aliased ([`wave_lag_sampled`]); every other column passes
    /// the loop by the continuous law with [`Stack::loop_gain`].
    pub(crate) servo_period: f64,
    /// The distinct sample positions of all channels, sorted (m): computed on first use and
    /// shared by the stacks derived from this one (their channels are the same).
    distinct: std::sync::Arc<std::sync::OnceLock<Vec<f64>>>,
    /// The scale's interpolation error I(x_t) at the table's position x_t, per sample in stack
    /// order (m; empty: none): the feedback chain reads s = x_t + I(x_t) where a channel's `x` is
    /// the scale's reading, so an interpolation error is a function of x − shift, not of x
    /// ([`interpolation_shift`], [`Stack::with_interpolation_shift`]).
    pub(crate) interp_shift: std::sync::Arc<Vec<f64>>,
}

/// Time step of the mode integration, s: at most this long (and at least 4 steps per sample
/// interval). The input is held at its mean over each step, so that its impulse (the velocity it
/// gives) is exact; the hold's error on a sinusoid of the guideway's band (≤ 100 Hz) is
/// ≈ (ωh)²/24 ≈ 2·10⁻⁵ of it.
pub(crate) const MODE_STEP: f64 = 1e-4;

/// The base acceleration that drives a structural mode, as the model predicts it on one
/// accelerometer channel: u·a_ref(τ) = v²·u·E''(x(τ)), the guideway acceleration of the axis
/// reference point (r = 0: the angles do not move it) from the model's given error motions, with
/// x(τ) = x_i + v·(τ − t_i) between samples. It is tabulated from t_{−1} = t_0 − Δt_0 (the sample
/// before the first, whose velocity the first reading is differenced against): interval i
/// (t_{i−1} → t_i) holds `steps[i]` steps of length Δt_i/steps[i] and the input's mean over each
/// step, v²·u·Ē''(x_k, x_{k+1}) (`Profile::mean_second_derivative`: a table's slope jumps count).
/// At a gap ([`sample_span`]) the lost stretch's steps come first, then the window's, each part
/// in steps of its own length.
///
/// The tables are shared (a clone is another handle on the same tables): the sensors of one pass
/// are driven by the same tables ([`Excitation::shares`]).
#[derive(Clone, Debug)]
pub(crate) struct Excitation {
    pub(crate) steps: std::sync::Arc<Vec<usize>>,
    pub(crate) input: std::sync::Arc<Vec<Vec<f64>>>,
}

/// Sample interval before sample i of a channel, s (the first sample takes the second's).
pub(crate) fn sample_interval(c: &Channel, i: usize) -> f64 {
    match i {
        0 if c.t.len() > 1 => c.t[1] - c.t[0],
        0 => 0.0,
        _ => c.t[i] - c.t[i - 1],
    }
}

/// An interval longer than this many times the shorter of its neighbours is a gap: samples the
/// logger lost (a wireless or USB logger drops packets), not a longer average. A jittered or
/// rounded clock moves intervals by far less; a rate that changes does so between runs, which
/// are channels of their own.
pub(crate) const GAP_FACTOR: f64 = 1.5;

/// The time sample i of an accelerometer channel averages over, s: its interval
/// ([`sample_interval`]), or at a gap ([`GAP_FACTOR`]) the shorter neighbouring interval, the
/// logger's own interval (a sample averages over its own interval, whatever was lost before it).
/// With 2 % of the samples of a complete model's generator draw dropped, averaging over the whole
/// gap made the normalised RMS 7.2 and a `resonance` significant.
pub(crate) fn sample_window(c: &Channel, i: usize) -> f64 {
    let dt = sample_interval(c, i);
    let n = c.t.len();
    // The interval index (sample 0 takes sample 1's) and its neighbours.
    let j = i.max(1);
    let interval = |k: usize| (k >= 1 && k < n).then(|| c.t[k] - c.t[k - 1]).filter(|d| *d > 0.0);
    let near =
        [j.checked_sub(1).and_then(interval), interval(j + 1)].into_iter().flatten().fold(f64::INFINITY, f64::min);
    if dt > GAP_FACTOR * near {
        near
    } else {
        dt
    }
}

/// How sample i's interval is integrated: the stretch lost before its window at a gap (its
/// length in s and steps; None when the window is the whole interval) and the window
/// ([`sample_window`]: its length and steps), each part in [`mode_steps`] equal steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SampleSpan {
    pub(crate) lost: Option<(f64, usize)>,
    pub(crate) window: (f64, usize),
}

/// [`SampleSpan`] of sample i of channel `c` (a non-positive interval: a window of it, none lost).
pub(crate) fn sample_span(c: &Channel, i: usize) -> SampleSpan {
    let dt = sample_interval(c, i);
    let w = sample_window(c, i);
    if w < dt {
        SampleSpan { lost: Some((dt - w, mode_steps(dt - w))), window: (w, mode_steps(w)) }
    } else {
        SampleSpan { lost: None, window: (dt, mode_steps(dt)) }
    }
}

/// Number of mode-integration steps over a sample interval `dt` (s): steps of [`MODE_STEP`], at
/// least 4 and at most [`MODE_STEPS_MAX`] (a gap in a log longer than 0.4 s is integrated in longer
/// steps: the hold of the mean input over each step stays exact for a constant input, and a mode
/// of the guideway's band has decayed over such a gap). An interval within [`MODE_STEPS_WHOLE`] of
/// a whole number of steps takes that number: a log at a round rate (1 kHz: Δt = 10 steps) has
/// intervals a few ulps either side of it, which would otherwise take 10 and 11 steps in turn,
/// and each change builds a new step map ([`StepMap`]; diagnose on the benchmark's mode set
/// re-timed at 1 kHz: 15.4 s against 6.5 s).
pub(crate) fn mode_steps(dt: f64) -> usize {
    // index: bounded to [4, MODE_STEPS_MAX] before the cast (a NaN dt fails the comparison: 4).
    let steps = (dt / MODE_STEP * (1.0 - MODE_STEPS_WHOLE)).ceil();
    if steps >= 4.0 {
        steps.min(MODE_STEPS_MAX as f64) as usize
    } else {
        4
    }
}

/// Relative slack of [`mode_steps`]: an interval at most this fraction above a whole number of
/// steps takes that number (the steps are then longer by at most this fraction; a clock's rounding
/// is about 10⁻¹⁶ of an interval).
pub(crate) const MODE_STEPS_WHOLE: f64 = 1e-9;

/// The most mode-integration steps over one sample interval ([`mode_steps`]): a log's gap between
/// two samples cannot size the input table beyond this.
pub(crate) const MODE_STEPS_MAX: usize = 4096;

impl Excitation {
    /// The tables `steps` (steps per sample interval) and `input` (the input's mean over each).
    pub(crate) fn new(steps: Vec<usize>, input: Vec<Vec<f64>>) -> Excitation {
        Excitation { steps: std::sync::Arc::new(steps), input: std::sync::Arc::new(input) }
    }

    /// The same tables as `other` (a clone of it, not equal values).
    pub(crate) fn shares(&self, other: &Excitation) -> bool {
        std::sync::Arc::ptr_eq(&self.steps, &other.steps) && std::sync::Arc::ptr_eq(&self.input, &other.input)
    }

    /// The excitation of channel `c` by the given (not fitted) translation error motions of
    /// `model` (EXX, EYX, EZX with their profiles); None for a non-accelerometer channel, a channel
    /// without velocity or a non-increasing time, or when no given translation reaches u.
    pub(crate) fn of(c: &Channel, model: &Model) -> Option<Excitation> {
        if !c.is_accel() || c.t.len() < 2 {
            return None;
        }
        let motions: Vec<(f64, &Profile)> = model
            .effects
            .iter()
            .filter(|m| !m.fit && m.effect.axis == model.axis)
            .filter_map(|m| {
                let n = m.effect.name;
                let p = m.effect.params.profile().filter(|_| n.is_translational())?;
                let s = c.s_motion(n);
                (s != 0.0 && !p.is_zero()).then_some((s, p))
            })
            .collect();
        if motions.is_empty() {
            return None;
        }
        Excitation::tabulate(c, |a, b| motions.iter().map(|(s, p)| s * p.mean_second_derivative(a, b)).sum::<f64>())
    }

    /// The excitation of accelerometer channel `c` by one fitted translation error motion E (its
    /// Legendre shape `sh` and coefficients `coef`, [`columns`]): the reference point's
    /// acceleration v²·Ē''(x_k, x_{k+1}) in that direction, Ē'' = (E'(x_{k+1}) − E'(x_k))/(x_{k+1} −
    /// x_k), E'(x) = Σ c_k·P'_k(u)·2/(b − a). Not projected on the sensor's direction: the mode is
    /// driven by every component of the reference point's acceleration, and its gains per sensor
    /// and component are fitted. None as for [`Excitation::of`] or for a shape without coefficients.
    pub(crate) fn of_fitted(c: &Channel, sh: &Shape, coef: &[f64]) -> Option<Excitation> {
        if !c.is_accel() || c.t.len() < 2 || coef.iter().all(|v| *v == 0.0) {
            return None;
        }
        // E'(x); the step boundaries come in order (x_k, x_{k+1}), (x_{k+1}, x_{k+2}), …: the last
        // boundary's slope is kept.
        let last = std::cell::Cell::new((f64::NAN, 0.0));
        let ks = sh.ks();
        let slope = |x: f64| -> f64 {
            if last.get().0 == x {
                return last.get().1;
            }
            let v = sh.slope_sum(x, &ks, coef);
            last.set((x, v));
            v
        };
        Excitation::tabulate(c, |xa, xb| {
            let sa = slope(xa);
            (slope(xb) - sa) / (xb - xa)
        })
    }

    /// The input table of channel `c` for a profile's mean second derivative `mean_e2(x_a, x_b)`
    /// (1/m) over each integration step: v²·Ē'' at x(τ) = x_i + v·(τ − t_i) (see [`Excitation`]).
    fn tabulate(c: &Channel, mean_e2: impl Fn(f64, f64) -> f64) -> Option<Excitation> {
        let mut steps = Vec::with_capacity(c.t.len());
        let mut input = Vec::with_capacity(c.t.len());
        for i in 0..c.t.len() {
            let dt = sample_interval(c, i);
            let v = c.v[i];
            if !(dt > 0.0) || !dt.is_finite() || v == 0.0 {
                return None;
            }
            let span = sample_span(c, i);
            let (m, vals) = match span.lost {
                None => {
                    let (_, m) = span.window;
                    let x = |k: usize| c.x[i] - v * dt * (1.0 - k as f64 / m as f64);
                    (m, (0..m).map(|k| v * v * mean_e2(x(k), x(k + 1))).collect::<Vec<f64>>())
                }
                // A gap: the lost stretch's steps, then the window's.
                Some((lost, ma)) => {
                    let (w, mb) = span.window;
                    let xa = |k: usize| c.x[i] - v * dt + v * lost * k as f64 / ma as f64;
                    let xb = |k: usize| c.x[i] - v * w + v * w * k as f64 / mb as f64;
                    let vals = (0..ma)
                        .map(|k| v * v * mean_e2(xa(k), xa(k + 1)))
                        .chain((0..mb).map(|k| v * v * mean_e2(xb(k), xb(k + 1))))
                        .collect();
                    (ma + mb, vals)
                }
            };
            steps.push(m);
            input.push(vals);
        }
        Some(Excitation::new(steps, input))
    }
}

/// The exact one-step map of the mode q̈ + 2ζω·q̇ + ω²·q = −a(τ) over a step h with a linear
/// input from a₀ to a₁: (q, q̇)(h) = Φ·(q, q̇)(0) + g₀·a₀ + g₁·a₁. Φ, g₀ and g₁ are the responses to
/// the unit states and to the inputs 1 − τ/h and τ/h, integrated by classical RK4 in 32 sub-steps
/// (ωh/32 ≤ 0.004 at 200 Hz and h = 0.1 ms: error ≈ 10⁻¹⁴).
#[derive(Clone, Copy, Debug)]
pub(crate) struct StepMap {
    pub(crate) phi: [[f64; 2]; 2],
    pub(crate) g0: [f64; 2],
    pub(crate) g1: [f64; 2],
}

impl StepMap {
    pub(crate) fn new(f: f64, zeta: f64, h: f64) -> StepMap {
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
            phi: [[c0[0], c1[0]], [c0[1], c1[1]]],
            g0: run([0.0, 0.0], &|tau| 1.0 - tau / h),
            g1: run([0.0, 0.0], &|tau| tau / h),
        }
    }
}

/// The exact map of one mode step with the input held over it, x ← Φ·x + g·a (x = (q, q̇); Φ and
/// g = g₀ + g₁ of a [`StepMap`], the response to a unit input held over the step).
#[derive(Clone, Copy, Debug)]
struct HeldStep {
    phi: [[f64; 2]; 2],
    g: [f64; 2],
}

impl HeldStep {
    /// From the step map over `h` (s) of the mode (`f` in Hz, `zeta`).
    fn new(f: f64, zeta: f64, h: f64) -> HeldStep {
        let mp = StepMap::new(f, zeta, h);
        HeldStep { phi: mp.phi, g: [mp.g0[0] + mp.g1[0], mp.g0[1] + mp.g1[1]] }
    }
}

/// The map of one sample interval of m held steps of `h` (s): x ← Φᵐ·x + Σ_k gk[k]·a_k with
/// gk[k] = Φ^{m−1−k}·g ([`HeldStep`]) and a_k the input's mean over step k.
#[derive(Clone, Debug)]
struct IntervalMap {
    h: f64,
    phi_m: [[f64; 2]; 2],
    gk: Vec<[f64; 2]>,
}

/// An [`IntervalMap`] built over its own step h₀, with the Taylor tables that give the map of the
/// same m steps over a near step h = h₀ + δ without building it (a jittered clock has an
/// interval of its own at every sample):
///
/// ```text
/// gk[k](h) = F((j+1)·h) − F(j·h),   F(t) = ∫₀ᵗ e^{As}·b ds,   j = m − 1 − k,
/// gk[k](h₀ + δ) = Σ_p δᵖ·D_p[k],   D_p[k] = A^{p−1}·((j+1)ᵖ·u_{j+1} − jᵖ·u_j)/p!  (p ≥ 1),
/// Φᵐ(h₀ + δ) = Σ_p δᵖ·P_p,          P_p = Φᵐ(h₀)·(m·A)ᵖ/p!,
/// u_j = e^{A·j·h₀}·b,   A = [[0, 1], [−ω², −2ζω]],   b = (0, −1)
/// ```
///
/// to p = P = [`NEAR_ORDER`] (F^{(p)}(t) = A^{p−1}·e^{At}·b; D₀ and P₀ are the built map). With
/// ρ = ω·(1 + 2ζ), which bounds A's eigenvalues, r = ρ·m·h₀ and e = |δ|/h₀, the first term left
/// out is at most e·(r·e)^P/P!·(1 + r/(P + 1)) of a gain and (r·e)^{P+1}/(P+1)! of Φᵐ;
/// [`BaseMap::serves`] holds r·e ≤ [`NEAR_PHASE`] and e ≤ [`STEP_NEAR`], which keeps both below
/// 3·10⁻¹⁹.
#[derive(Clone, Debug)]
struct BaseMap {
    /// h₀, s.
    h: f64,
    /// ρ = ω·(1 + 2ζ), 1/s.
    rate: f64,
    /// P_p, p = 0..=[`NEAR_ORDER`].
    phi_terms: [[[f64; 2]; 2]; NEAR_ORDER + 1],
    /// D_p[k] for each step k of the interval, p = 0..=[`NEAR_ORDER`].
    g_terms: Vec<[[f64; 2]; NEAR_ORDER + 1]>,
}

impl BaseMap {
    /// The map of `m` held steps of `h` (s) of the mode (`f` in Hz, `zeta`) and its tables.
    fn new(f: f64, zeta: f64, h: f64, m: usize) -> BaseMap {
        let step = HeldStep::new(f, zeta, h);
        // The built map: D₀[k] = Φ^{m−1−k}·g and P₀ = Φᵐ.
        let mut g_terms = vec![[[0.0; 2]; NEAR_ORDER + 1]; m];
        let mut g = step.g;
        let mut phi_m = [[1.0, 0.0], [0.0, 1.0]];
        for k in (0..m).rev() {
            // index: k < m, g_terms' length.
            g_terms[k][0] = g;
            g = mat2_times(step.phi, g);
            phi_m = mat2(step.phi, phi_m);
        }
        let w = TWO_PI * f;
        let a = [[0.0, 1.0], [-w * w, -2.0 * zeta * w]];
        let ma = a.map(|row| row.map(|v| v * m as f64));
        let mut phi_terms = [phi_m; NEAR_ORDER + 1];
        for p in 1..=NEAR_ORDER {
            // index: p − 1 < p ≤ NEAR_ORDER.
            phi_terms[p] = mat2(phi_terms[p - 1], ma).map(|row| row.map(|v| v / p as f64));
        }
        // u_j = Φʲ·b, j = 0..=m.
        let u: Vec<[f64; 2]> =
            std::iter::successors(Some([0.0, -1.0]), |x| Some(mat2_times(step.phi, *x))).take(m + 1).collect();
        for (k, t) in g_terms.iter_mut().enumerate() {
            let j = m - 1 - k;
            let (mut cj1, mut cj, mut fact) = (1.0, 1.0, 1.0);
            for (p, tp) in t.iter_mut().enumerate().skip(1) {
                cj1 *= (j + 1) as f64;
                cj *= j as f64;
                fact *= p as f64;
                // index: j + 1 ≤ m, u's last.
                let (u1, u0) = (u[j + 1], u[j]);
                let mut v = [(cj1 * u1[0] - cj * u0[0]) / fact, (cj1 * u1[1] - cj * u0[1]) / fact];
                for _ in 1..p {
                    v = mat2_times(a, v);
                }
                *tp = v;
            }
        }
        BaseMap { h, rate: w * (1.0 + 2.0 * zeta), phi_terms, g_terms }
    }

    /// Whether the tables give the map of `m` steps of `h` (s) to rounding: the same m, and
    /// ρ·m·|δ| ≤ [`NEAR_PHASE`] and |δ| ≤ [`STEP_NEAR`]·h₀ (δ = h − h₀).
    fn serves(&self, h: f64, m: usize) -> bool {
        let d = (h - self.h).abs();
        self.g_terms.len() == m && self.rate * m as f64 * d <= NEAR_PHASE && d <= STEP_NEAR * self.h
    }

    /// The map of the same m steps over `h` (s) from the first `P` + 1 terms of the tables
    /// (Horner in δ = h − h₀), written to `out`.
    fn interval_at<const P: usize>(&self, h: f64, out: &mut IntervalMap) {
        let d = h - self.h;
        // index: P ≤ NEAR_ORDER, the tables' last term (every caller's constant).
        let mut phi = self.phi_terms[P];
        for t in self.phi_terms[..P].iter().rev() {
            phi = [
                [phi[0][0] * d + t[0][0], phi[0][1] * d + t[0][1]],
                [phi[1][0] * d + t[1][0], phi[1][1] * d + t[1][1]],
            ];
        }
        out.h = h;
        out.phi_m = phi;
        out.gk.clear();
        out.gk.extend(self.g_terms.iter().map(|t| {
            // index: P ≤ NEAR_ORDER, as above.
            let mut g = t[P];
            for tp in t[..P].iter().rev() {
                g = [g[0] * d + tp[0], g[1] * d + tp[1]];
            }
            g
        }));
    }
}

/// Relative distance of a step within which a [`BaseMap`]'s tables give its interval's map
/// (with [`NEAR_PHASE`]): a jittered clock's intervals stay well within it (0.5 µs of jitter on
/// 666 µs: a few 10⁻³).
const STEP_NEAR: f64 = 1e-2;
/// The largest change ρ·m·|δ| of an interval, in radians of the mode, that a [`BaseMap`]'s tables
/// serve (0.5 µs on a 666 µs interval at 80 Hz: 2.5·10⁻⁴).
const NEAR_PHASE: f64 = 5e-3;
/// Terms of a [`BaseMap`]'s Taylor tables beyond the first.
const NEAR_ORDER: usize = 6;

/// The product m·x of a 2 × 2 matrix and a 2-vector.
fn mat2_times(m: [[f64; 2]; 2], x: [f64; 2]) -> [f64; 2] {
    [m[0][0] * x[0] + m[0][1] * x[1], m[1][0] * x[0] + m[1][1] * x[1]]
}

/// The 2 × 2 product a·b.
fn mat2(a: [[f64; 2]; 2], b: [[f64; 2]; 2]) -> [[f64; 2]; 2] {
    [
        [a[0][0] * b[0][0] + a[0][1] * b[1][0], a[0][0] * b[0][1] + a[0][1] * b[1][1]],
        [a[1][0] * b[0][0] + a[1][1] * b[1][0], a[1][0] * b[0][1] + a[1][1] * b[1][1]],
    ]
}

/// The exact state map of the free, underdamped mode q̈ + 2ζω·q̇ + ω²·q = 0 (ζ < 1, ω = 2πf) over
/// a time h: (q, q̇)(h) = Φ·(q, q̇)(0), with ω_d = ω·√(1 − ζ²) and
/// Φ = e^{−ζωh}·[[c + (ζω/ω_d)·s, s/ω_d], [−(ω²/ω_d)·s, c − (ζω/ω_d)·s]], c = cos ω_d h, s = sin ω_d h.
pub(crate) fn free_map(f: f64, zeta: f64, h: f64) -> [[f64; 2]; 2] {
    let w = TWO_PI * f;
    let wd = w * (1.0 - zeta * zeta).sqrt();
    let e = (-zeta * w * h).exp();
    let (s, c) = (wd * h).sin_cos();
    let zw = zeta * w;
    [[e * (c + zw / wd * s), e * s / wd], [-e * w * w / wd * s, e * (c - zw / wd * s)]]
}

/// The two free-vibration responses of a mode on channel `c` ([`mode_response`] without input)
/// from the unit-scaled states at t_{−1}, (q₀, q̇₀) = (1/ω², 0) and (0, 1/ω), ω = 2πf: the
/// columns of an unknown starting state.
pub(crate) fn free_vibration(c: &Channel, f: f64, zeta: f64) -> [Vec<f64>; 2] {
    let w = TWO_PI * f;
    let lanes = [(1.0 / (w * w), 0.0), (0.0, 1.0 / w)].map(|start| Lane { start, input: None });
    let mut both = mode_lanes(c, &lanes, f, zeta).into_iter();
    [both.next().unwrap_or_default(), both.next().unwrap_or_default()]
}

/// Interval means of q̈ of a mode q̈ + 2ζω·q̇ + ω²·q = −a(τ) over each sample interval of channel
/// `c`, (q̇_i − q̇_{i−1})/Δt_i (what the simulator's accelerometer reads of a point moving by q), from
/// the state (q, q̇) = `start` at t_{−1}, with the input a from `ex` (None: free vibration) held at
/// its mean over each step ([`StepMap`], [`MODE_STEP`]). ω = 2πf, f in Hz.
pub(crate) fn mode_response(c: &Channel, ex: Option<&Excitation>, f: f64, zeta: f64, start: (f64, f64)) -> Vec<f64> {
    mode_lanes(c, &[Lane { start, input: ex }], f, zeta).pop().unwrap_or_default()
}

/// [`mode_response`] of each excitation in `exs` from rest: the same values, to the bit, as one
/// call per excitation. Excitations with the same steps per sample run together ([`mode_lanes`]).
pub(crate) fn mode_responses(c: &Channel, exs: &[Excitation], f: f64, zeta: f64) -> Vec<Vec<f64>> {
    let Some(first) = exs.first() else { return Vec::new() };
    if exs.iter().all(|e| e.steps == first.steps) {
        let lanes: Vec<Lane> = exs.iter().map(|e| Lane { start: (0.0, 0.0), input: Some(e) }).collect();
        mode_lanes(c, &lanes, f, zeta)
    } else {
        exs.iter().map(|e| mode_response(c, Some(e), f, zeta, (0.0, 0.0))).collect()
    }
}

/// One run of [`mode_lanes`]: the state (q, q̇) at t_{−1} and the input (None: none).
#[derive(Clone, Copy)]
struct Lane<'a> {
    start: (f64, f64),
    input: Option<&'a Excitation>,
}

/// The recursion of [`mode_response`] for several lanes at once. The lanes with an input must have
/// the same steps per sample (the caller's check, [`mode_responses`]): the first's are used. When
/// no lane has one and ζ < 1, each sample interval is one exact free step; otherwise a lane
/// without an input has none over the steps. Up to [`MODE_LANES`] lanes run together
/// ([`mode_lanes_of`]), more in groups of that many.
fn mode_lanes(c: &Channel, lanes: &[Lane], f: f64, zeta: f64) -> Vec<Vec<f64>> {
    clear_upper_state();
    let free = lanes.iter().all(|l| l.input.is_none()) && zeta < 1.0;
    let steps = lanes.iter().find_map(|l| l.input).map(|e| e.steps.as_slice());
    let mut outs = Vec::with_capacity(lanes.len());
    for group in lanes.chunks(MODE_LANES) {
        outs.extend(match group.len() {
            1 => mode_lanes_of::<1>(c, group, steps, free, f, zeta),
            2 => mode_lanes_of::<2>(c, group, steps, free, f, zeta),
            3 => mode_lanes_of::<3>(c, group, steps, free, f, zeta),
            _ => mode_lanes_of::<MODE_LANES>(c, group, steps, free, f, zeta),
        });
    }
    outs
}

/// Interval maps [`mode_lanes_of`] keeps: a log whose clock rounds its times (to µs, say) has a
/// few distinct intervals in turn, each with its own map (the benchmark's res15000 with its times
/// rounded to 1 µs: intervals of 665 and 666 µs).
const STEP_MAPS_KEPT: usize = 8;

/// Built maps with their tables ([`BaseMap`]) [`mode_lanes_of`] keeps: a gap's lost stretch has
/// steps of its own, and the window's map is had from the same base after it.
const STEP_BASES_KEPT: usize = 4;

/// Lanes [`mode_lanes`] runs together at most.
const MODE_LANES: usize = 4;

/// [`mode_lanes`] for the L lanes of `lanes` (L of them; `steps` the steps per sample of their
/// inputs, `free` the exact free steps): the lanes' states are held in registers and their
/// recursions, independent chains of additions, run side by side so that the processor overlaps
/// them. Each lane's arithmetic, in its order, is that of a run alone. Each lane's change of q̇
/// over an interval is divided by the interval after the recursion, in one pass (the same
/// quotients, off the recursion's path).
fn mode_lanes_of<const L: usize>(
    c: &Channel,
    lanes: &[Lane],
    steps: Option<&[usize]>,
    free_steps: bool,
    f: f64,
    zeta: f64,
) -> Vec<Vec<f64>> {
    let n = c.t.len();
    let mut xs = [[0.0; 2]; L];
    for (x, l) in xs.iter_mut().zip(lanes) {
        *x = [l.start.0, l.start.1];
    }
    let ins: [Option<&Excitation>; L] = std::array::from_fn(|l| lanes.get(l).and_then(|l| l.input));
    // The interval maps made (each with Φᵐ and the m input gains), the one in use last, and the
    // maps built with their tables that they were had from ([`use_map`]); at most
    // [`STEP_MAPS_KEPT`] and [`STEP_BASES_KEPT`], the least recently used dropped first.
    let mut maps: Vec<IntervalMap> = Vec::new();
    let mut bases: Vec<BaseMap> = Vec::new();
    // The (interval's bits, steps) the last map was found good for: an interval the same to the
    // bit as the one before needs no new check.
    let mut checked: Option<(u64, usize)> = None;
    let mut outs: Vec<Vec<f64>> = (0..L.min(lanes.len())).map(|_| vec![0.0; n]).collect();
    // Free vibration of an underdamped mode: one exact step per sample interval.
    let mut free: Option<(f64, [[f64; 2]; 2])> = None;
    for i in 0..n {
        let dt = sample_interval(c, i);
        if !(dt > 0.0) {
            continue;
        }
        let span = sample_span(c, i);
        if let Some(lost) = span.lost {
            // A gap: the state carried over the lost stretch, then over the window, whose change
            // of q̇ is the sample; each part's map from the kept ones ([`use_map`]).
            // index: sample i of each input (one entry per sample, as its steps).
            let a: [&[f64]; L] = std::array::from_fn(|l| ins[l].map_or(&[][..], |e| e.input[i].as_slice()));
            let mut before = [0.0; L];
            for (part, (len, m)) in [lost, span.window].into_iter().enumerate() {
                before = std::array::from_fn(|l| xs[l][1]);
                if free_steps {
                    let phi = free_map(f, zeta, len);
                    xs.iter_mut().for_each(|x| *x = mat2_times(phi, *x));
                    continue;
                }
                use_map(&mut maps, &mut bases, f, zeta, len, m);
                let Some(IntervalMap { phi_m, gk, .. }) = maps.last() else { continue };
                // index: the lost stretch's inputs come first, then the window's (`sample_span`).
                let own: [&[f64]; L] = std::array::from_fn(|l| {
                    let (lo, hi) = if part == 0 { (0, lost.1) } else { (lost.1, a[l].len()) };
                    a[l].get(lo.min(hi)..hi).unwrap_or(&[])
                });
                advance(&mut xs, *phi_m, gk, &own);
            }
            for ((x, v), out) in xs.iter().zip(&before).zip(outs.iter_mut()) {
                // index: i < n, the length of each output.
                out[i] = x[1] - v;
            }
            // The last map is a part's now: the next interval looks its own up.
            checked = None;
            continue;
        }
        if free_steps {
            let phi = match free {
                Some((h, phi)) if (h - dt).abs() <= 1e-9 * dt => phi,
                _ => free.insert((dt, free_map(f, zeta, dt))).1,
            };
            for (x, out) in xs.iter_mut().zip(outs.iter_mut()) {
                let v0 = x[1];
                *x = mat2_times(phi, *x);
                // index: i < n, the length of each output.
                out[i] = x[1] - v0;
            }
            continue;
        }
        // index: the lanes share their steps (the caller's check), so the first lane's is every lane's.
        let m = steps.map_or(mode_steps(dt), |s| s[i]);
        // Sample intervals repeat: the map is rebuilt only when the step changes (≥ 1 ppb). The m
        // steps of an interval compose to x ← Φᵐ·x + Σ_k Φ^{m−1−k}·(g₀ + g₁)·a_k.
        if checked != Some((dt.to_bits(), m)) {
            use_map(&mut maps, &mut bases, f, zeta, dt, m);
        }
        let Some(IntervalMap { phi_m, gk, .. }) = maps.last() else { continue };
        checked = Some((dt.to_bits(), m));
        let before: [f64; L] = std::array::from_fn(|l| xs[l][1]);
        // index: sample i of each input (one entry per sample, as its steps; none without steps).
        let a: [&[f64]; L] = std::array::from_fn(|l| match steps {
            Some(_) => ins[l].map_or(&[][..], |e| e.input[i].as_slice()),
            None => &[][..],
        });
        advance(&mut xs, *phi_m, gk, &a);
        for ((x, v), out) in xs.iter().zip(&before).zip(outs.iter_mut()) {
            // index: i < n, the length of each output.
            out[i] = x[1] - v;
        }
    }
    // (q̇_i − q̇_{i−1})/Δt_i where the interval is positive (zero stays zero elsewhere: ÷ 1).
    let divisor: Vec<f64> = (0..n).map(|i| sample_window(c, i)).map(|d| if d > 0.0 { d } else { 1.0 }).collect();
    for out in outs.iter_mut() {
        out.iter_mut().zip(&divisor).for_each(|(y, d)| *y /= d);
    }
    outs
}

/// Makes the last of the kept interval maps `maps` the map of `m` steps over `dt` (s) for the
/// mode (`f` in Hz, `zeta`). A map is good for steps within 1 ppb of its own: the last one, else
/// the most recent kept one (a clock that rounds to µs alternates between a few intervals), else
/// one from the tables of the most recent kept [`BaseMap`] that serves it (a jittered clock), else
/// a new base's; at most [`STEP_MAPS_KEPT`] maps and [`STEP_BASES_KEPT`] bases kept, the least
/// recently used dropped first.
fn use_map(maps: &mut Vec<IntervalMap>, bases: &mut Vec<BaseMap>, f: f64, zeta: f64, dt: f64, m: usize) {
    let h = dt / m as f64;
    let good = |e: &IntervalMap| (e.h - h).abs() <= 1e-9 * h && e.gk.len() == m;
    if maps.last().is_some_and(good) {
        return;
    }
    if let Some(at) = maps.iter().rposition(good) {
        let e = maps.remove(at);
        maps.push(e);
        return;
    }
    // The base that serves, or a new one (the least recently used dropped when they are full).
    let base = match bases.iter().rposition(|b| b.serves(h, m)) {
        Some(at) => bases.remove(at),
        None => {
            if bases.len() >= STEP_BASES_KEPT {
                bases.remove(0);
            }
            BaseMap::new(f, zeta, h, m)
        }
    };
    // The least recently used map dropped when the kept ones are full, its gains' buffer reused
    // (a jittered clock makes a map per sample).
    let mut e = match maps.len() >= STEP_MAPS_KEPT {
        true => maps.remove(0),
        false => IntervalMap { h, phi_m: [[1.0, 0.0], [0.0, 1.0]], gk: Vec::with_capacity(m) },
    };
    base.interval_at::<NEAR_ORDER>(h, &mut e);
    bases.push(base);
    maps.push(e);
}

/// The lanes' states `xs` over one interval's map (Φᵐ `phi_m` and the input gains `gk`,
/// [`use_map`]): x ← Φᵐ·x + Σ_k gk[k]·a_k with each lane's inputs `a` (its means over the steps;
/// empty: none), the lanes' sums side by side, each in its own order over the steps.
#[inline]
fn advance<const L: usize>(xs: &mut [[f64; 2]; L], phi_m: [[f64; 2]; 2], gk: &[[f64; 2]], a: &[&[f64]; L]) {
    for x in xs.iter_mut() {
        *x = mat2_times(phi_m, *x);
    }
    if a.iter().all(|a| a.is_empty()) {
        return;
    }
    for (k, g) in gk.iter().enumerate() {
        for (x, a) in xs.iter_mut().zip(a) {
            if let Some(&a) = a.get(k) {
                x[0] += g[0] * a;
                x[1] += g[1] * a;
            }
        }
    }
}

impl<'a> Stack<'a> {
    /// The stack of `chans` with the structural-mode excitation the model `model` predicts.
    pub(crate) fn with_model(chans: &'a [Channel], model: &Model) -> Stack<'a> {
        let mut st = Stack::new(chans);
        st.excitation = chans.iter().map(|c| Excitation::of(c, model).into_iter().collect()).collect();
        // The model's servo_lag gain (given, or the start of its search) until a fit sets it.
        st.loop_kv = match model.get(EffectName::ServoLag, model.axis).map(|m| &m.effect.params) {
            Some(EffectParams::ServoLag(s)) if s.kv > 0.0 => s.kv,
            _ => f64::INFINITY,
        };
        st
    }

    /// The first row of each channel in the stack's order.
    pub(crate) fn channel_starts(&self) -> Vec<usize> {
        self.chans.iter().scan(0, |k, c| Some(std::mem::replace(k, *k + c.y.len()))).collect()
    }

    /// The same stack with these mode excitations (one list per channel).
    pub(crate) fn with_excitation(&self, excitation: Vec<Vec<Excitation>>) -> Stack<'a> {
        Stack {
            excitation,
            group: self.group.clone(),
            distinct: self.distinct.clone(),
            interp_shift: self.interp_shift.clone(),
            ..*self
        }
    }

    /// The same stack with the servo's sampling period `h` (s, [`Stack::servo_period`]).
    pub(crate) fn with_servo_period(&self, h: f64) -> Stack<'a> {
        Stack {
            servo_period: h,
            excitation: self.excitation.clone(),
            group: self.group.clone(),
            distinct: self.distinct.clone(),
            interp_shift: self.interp_shift.clone(),
            ..*self
        }
    }

    /// The same stack with the interpolation error `shift` at the table's position on each sample
    /// ([`Stack::interp_shift`]).
    pub(crate) fn with_interpolation_shift(&self, shift: Vec<f64>) -> Stack<'a> {
        Stack {
            interp_shift: std::sync::Arc::new(shift),
            excitation: self.excitation.clone(),
            group: self.group.clone(),
            distinct: self.distinct.clone(),
            ..*self
        }
    }

    /// The same stack with the position-loop gain `kv` (1/s, [`Stack::loop_kv`]) and the gain `g`
    /// of its transmission path ([`Stack::loop_gain`]).
    pub(crate) fn with_loop(&self, kv: f64, g: f64) -> Stack<'a> {
        Stack {
            loop_kv: kv,
            loop_gain: g,
            group: self.group.clone(),
            excitation: self.excitation.clone(),
            distinct: self.distinct.clone(),
            interp_shift: self.interp_shift.clone(),
            ..*self
        }
    }

    pub(crate) fn new(chans: &'a [Channel]) -> Stack<'a> {
        let mut keys: Vec<String> = Vec::new();
        let mut group = Vec::with_capacity(chans.len());
        for c in chans {
            // Encoders are homed once: one offset per encoder channel over all runs (so the
            // passes both ways show the backlash and the lead error is one shape).
            let key = if c.kind == SensorKind::MotorForce {
                format!("force/{}", c.sensor)
            } else if c.encoder.is_some() {
                format!("encoder/{}", c.sensor)
            } else {
                format!("{}/{}", c.run, c.sensor)
            };
            let g = keys.iter().position(|k| *k == key).unwrap_or_else(|| {
                keys.push(key);
                // index: `keys` has just been pushed to.
                keys.len() - 1
            });
            group.push(g);
        }
        Stack {
            chans,
            n: chans.iter().map(|c| c.y.len()).sum(),
            group,
            n_groups: keys.len(),
            excitation: vec![Vec::new(); chans.len()],
            loop_kv: f64::INFINITY,
            loop_gain: 1.0,
            servo_period: f64::NAN,
            distinct: Default::default(),
            interp_shift: Default::default(),
        }
    }

    /// `k` columns over all samples, a row per sample: f(channel, sample index, row) writes the
    /// sample's k values into `row` (zeroed before each call). In blocks of [`ROWS_PER_TASK`]
    /// samples of one channel, side by side (rayon, [`Stack::col_blocks`]); a sample's values
    /// depend on it alone, so the columns are the same bits on any number of threads as one sample
    /// after another.
    pub(crate) fn col_rows(&self, k: usize, f: impl Fn(&Channel, usize, &mut [f64]) + Sync) -> Vec<Vec<f64>> {
        self.col_blocks(k, |c, i0, len, mine| {
            let mut row = vec![0.0; k];
            for r in 0..len {
                row.fill(0.0);
                f(c, i0 + r, &mut row);
                for (col, v) in mine.iter_mut().zip(&row) {
                    col[r] = *v;
                }
            }
        })
    }

    /// `k` columns over all samples (zeros before), a block of rows at a time: f(channel, first
    /// sample index, samples, the k columns' rows of the block) for blocks of [`ROWS_PER_TASK`]
    /// samples of one channel, side by side (rayon). A block's values must depend on its samples
    /// alone: then the columns are the same bits on any number of threads.
    pub(crate) fn col_blocks(
        &self,
        k: usize,
        f: impl Fn(&Channel, usize, usize, &mut [&mut [f64]]) + Sync,
    ) -> Vec<Vec<f64>> {
        let mut cols = vec![vec![0.0; self.n]; k];
        // Per block: its channel, first sample, number of samples, and each column's rows of it.
        let mut blocks: Vec<(&Channel, usize, usize, Vec<&mut [f64]>)> = Vec::new();
        let mut rest: Vec<&mut [f64]> = cols.iter_mut().map(|c| c.as_mut_slice()).collect();
        for c in self.chans {
            let mut i0 = 0;
            while i0 < c.y.len() {
                // index: i0 < the channel's length, and the columns hold the stack's n = Σ lengths.
                let len = ROWS_PER_TASK.min(c.y.len() - i0);
                let mine = rest
                    .iter_mut()
                    .map(|r| {
                        let (a, b) = std::mem::take(r).split_at_mut(len);
                        *r = b;
                        a
                    })
                    .collect();
                blocks.push((c, i0, len, mine));
                i0 += len;
            }
        }
        blocks.into_par_iter().for_each(|(c, i0, len, mut mine)| {
            clear_upper_state();
            f(c, i0, len, &mut mine);
        });
        cols
    }

    /// One column: f(channel, sample index) over all samples.
    pub(crate) fn col(&self, f: impl Fn(&Channel, usize) -> f64) -> Vec<f64> {
        clear_upper_state();
        let mut v = Vec::with_capacity(self.n);
        for c in self.chans {
            for i in 0..c.y.len() {
                v.push(f(c, i));
            }
        }
        v
    }

    /// Two columns from one pass: f(channel, sample index, stack index) = (first, second) over all
    /// samples (a sine and a cosine from one `sin_cos`).
    pub(crate) fn col_pair(&self, f: impl Fn(&Channel, usize, usize) -> (f64, f64)) -> (Vec<f64>, Vec<f64>) {
        clear_upper_state();
        let (mut a, mut b) = (Vec::with_capacity(self.n), Vec::with_capacity(self.n));
        for c in self.chans {
            for i in 0..c.y.len() {
                let (u, v) = f(c, i, a.len());
                a.push(u);
                b.push(v);
            }
        }
        (a, b)
    }

    /// One column: f(channel, sample index, channel index) over all samples.
    pub(crate) fn col_j(&self, f: impl Fn(&Channel, usize, usize) -> f64) -> Vec<f64> {
        clear_upper_state();
        let mut v = Vec::with_capacity(self.n);
        for (j, c) in self.chans.iter().enumerate() {
            for i in 0..c.y.len() {
                v.push(f(c, i, j));
            }
        }
        v
    }

    pub(crate) fn y(&self) -> Vec<f64> {
        self.col(|c, i| c.y[i])
    }

    /// Offset columns, one per offset group.
    pub(crate) fn offsets(&self) -> Vec<Vec<f64>> {
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

    pub(crate) fn t_span(&self) -> (f64, f64) {
        let ts = self.col(|c, i| c.t[i]);
        let lo = ts.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ts.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    }
}

/// Samples of one channel per task of [`Stack::col_rows`].
const ROWS_PER_TASK: usize = 1024;

/// How an effect's signature is parameterised: names of its linear coefficients and of its
/// nonlinear hyper-parameters (periods, time constants).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Shape {
    pub(crate) coefs: Vec<String>,
    pub(crate) hypers: Vec<Hyper>,
    /// Lowest degree of an error motion's Legendre series (1 in a model; 2 for the positioning
    /// candidate, whose linear term is the scale error's signature).
    pub(crate) first_power: u32,
    pub(crate) order: u32,
    /// Error motions: the position range [a, b] (m) mapped onto u ∈ [−1, 1] by the Legendre basis.
    pub(crate) range: (f64, f64),
    /// Stribeck only: also fit the Coulomb level (the model has no `coulomb` effect).
    pub(crate) with_fc: bool,
    /// Error motions: the series' basis.
    pub(crate) basis: ShapeBasis,
    /// Error motions: the basis orders used, when a sparse selection of first_power..=order
    /// (`fit_orders_nested` on a cosine series: the terms chosen by their explained χ²); None: all.
    pub(crate) select: Option<Vec<u32>>,
    /// [`ShapeBasis::Table`]: the positions (m) of its values, ascending; empty otherwise.
    pub(crate) knots: Vec<f64>,
    /// `gravity_tilt`: each accelerometer's Legendre degree, in [`accel_sensors`] order (0: no
    /// tilt on that sensor); empty: every accelerometer at `order`.
    pub(crate) tilt_orders: Vec<u32>,
}

vmt_core::named_enum! {
    /// A nonlinear hyper-parameter of a signature, searched on a grid ([`hyper_grid`]); named as the
    /// effect's parameter it fits (FORMAT.md §2), except the encoder play; written by that name
    /// ([`Hyper::as_str`]) in reports' `at_bound`.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
    pub enum Hyper {
        /// A periodic effect's period p, m (`cyclic_lead`, `interpolation_error`).
        Period = "period",
        /// A thermal time constant τ, s.
        Tau = "tau",
        /// The position-loop gain kv of the servo lag, 1/s.
        Kv = "kv",
        /// The play b of a backlash on encoder time series, m.
        Play = "play",
        /// The Stribeck velocity vs, m/s.
        Vs = "vs",
        /// The Stribeck shape exponent δ (dimensionless).
        Shape = "shape",
        /// A structural mode's natural frequency f, Hz.
        Frequency = "frequency",
        /// A structural mode's damping ratio ζ (dimensionless).
        Damping = "damping",
    }
}

impl Hyper {
    /// The hyper-parameter named `name` ([`Hyper::as_str`], the name in reports and candidates,
    /// the effect's parameter key: `period`, `tau`, …), if any.
    pub fn named(name: &str) -> Option<Hyper> {
        Hyper::ALL.into_iter().find(|h| h.as_str() == name)
    }
}

vmt_core::named_enum! {
    /// The basis of a fitted error motion's series (over the range [a, b] of the sample positions),
    /// reported by its name ([`ShapeBasis::as_str`]) in `shapes` (FORMAT.md §4).
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
    pub enum ShapeBasis {
        /// Legendre polynomials P_k(u), u = (2x − a − b)/(b − a): lasers and encoders (point tables).
        Legendre = "legendre",
        /// P_3, P_4, then pairs cos(jπ(x − a)/(b − a)), sin(jπ(x − a)/(b − a)) (`Shape::basis_at`): a
        /// motion seen only by accelerometers. They see E'' alone,
        /// and the cosine series of E'' converges on any smooth profile (its even extension is
        /// continuous) with columns that stay independent to hundreds of terms (wavelengths 2(b − a)/k
        /// down to the rail waviness), where Legendre columns of the sampled accelerations become
        /// dependent (to 1e-9) near order 270 on 3 500 samples while the waviness needs more.
        Cosine = "cosine",
        /// `basis = "bspline"`: N clamped B-splines of degree min(3, N − 1) on N − degree − 1 uniform
        /// interior knots over [a, b] (de Boor 1978, Cox–de Boor recursion); index k = 0..N − 1, the
        /// first left out (Σ B_k = 1: the offsets carry the constant). `order` = N.
        Bspline = "bspline",
        /// `basis = "harmonics"`: a slope and H harmonics of the fundamental wavelength 2(b − a):
        /// index 1 = x − a (m), 2h = sin(2πx/λ_h), 2h + 1 = cos(2πx/λ_h), λ_h = 2(b − a)/h, h = 1..H
        /// (of x itself, so that the fitted terms are FORMAT.md §2 `poly = [0, slope]` and
        /// `harmonics` entries A·sin(2πx/λ + φ)). The slope: without it a machine's linear positioning
        /// error (the commonest part) needs many harmonics (its half-range series converges as 1/h).
        /// `order` = H.
        Harmonics = "harmonics",
        /// `basis = "table"`: values at N positions (`Shape::knots`: the distinct targets when N is
        /// their number, else N uniform points over [a, b]) joined by straight lines (hat functions,
        /// a linear B-spline), the first value left out (the offsets carry the constant). `order` = N.
        Table = "table",
    }
}

impl ShapeBasis {
    /// The highest column index of a series of user order `order` (FORMAT.md §2 `order`:
    /// the Legendre degree, B-splines or table values N, harmonics H).
    pub(crate) fn top_index(self, order: u32) -> u32 {
        match self {
            ShapeBasis::Legendre | ShapeBasis::Cosine => order,
            ShapeBasis::Bspline | ShapeBasis::Table => order.saturating_sub(1),
            ShapeBasis::Harmonics => 2 * order + 1,
        }
    }

    /// The user order of a series whose highest column index is `top` (inverse of [`Self::top_index`]).
    pub(crate) fn user_order(self, top: u32) -> u32 {
        match self {
            ShapeBasis::Legendre | ShapeBasis::Cosine => top,
            ShapeBasis::Bspline | ShapeBasis::Table => top + 1,
            ShapeBasis::Harmonics => top.saturating_sub(1) / 2,
        }
    }

    /// The shortest wavelength (m) a series of user order `order` represents on a range of length
    /// `span` (m): Legendre P_K has K zeros on the range, ≈ 2L/K; harmonic H is 2L/H; cubic
    /// B-splines resolve about two knot intervals, 2L/(N − 3); a table, two of its N − 1
    /// intervals, 2L/(N − 1). The cosine series (accelerometers): 2L/(K − 2).
    pub(crate) fn shortest_wavelength(self, span: f64, order: u32) -> f64 {
        let per = match self {
            ShapeBasis::Legendre | ShapeBasis::Harmonics => order as f64,
            ShapeBasis::Bspline => order.saturating_sub(3).max(1) as f64,
            ShapeBasis::Table => order.saturating_sub(1).max(1) as f64,
            ShapeBasis::Cosine => order.saturating_sub(2).max(1) as f64,
        };
        2.0 * span / per
    }
}

/// Values and derivatives of the N clamped B-splines of degree p = min(3, N − 1) with uniform
/// interior knots on [a, b] at x (Cox–de Boor: B_{i,0} = 1 on [t_i, t_{i+1}), B_{i,q} =
/// (x − t_i)/(t_{i+q} − t_i)·B_{i,q−1} + (t_{i+q+1} − x)/(t_{i+q+1} − t_{i+1})·B_{i+1,q−1};
/// B'_{i,p} = p·[B_{i,p−1}/(t_{i+p} − t_i) − B_{i+1,p−1}/(t_{i+p+1} − t_{i+1})]; de Boor 1978).
/// x = b belongs to the last interval.
pub(crate) fn bspline_basis(x: f64, n: usize, (a, b): (f64, f64)) -> (Vec<f64>, Vec<f64>) {
    let p = n.saturating_sub(1).min(3);
    let inner = n - p - 1;
    let mut t: Vec<f64> = vec![a; p + 1];
    t.extend((1..=inner).map(|k| a + (b - a) * k as f64 / (inner + 1) as f64));
    t.extend(std::iter::repeat(b).take(p + 1));
    // clamp: a ≤ b, the least and greatest sample position of the motion's channels.
    let x = x.clamp(a, b);
    // Degree 0: the one knot interval holding x (the last non-empty one for x = b).
    let span = (0..t.len() - 1).rev().find(|&i| t[i] <= x && t[i] < t[i + 1]).unwrap_or(0);
    let mut lower: Vec<f64> = (0..t.len() - 1).map(|i| if i == span { 1.0 } else { 0.0 }).collect();
    let ratio = |num: f64, den: f64| if den > 0.0 { num / den } else { 0.0 };
    let mut prev = lower.clone();
    for q in 1..=p {
        prev = lower.clone();
        lower = (0..t.len() - 1 - q)
            .map(|i| {
                ratio(x - t[i], t[i + q] - t[i]) * prev[i]
                    + ratio(t[i + q + 1] - x, t[i + q + 1] - t[i + 1]) * prev[i + 1]
            })
            .collect();
    }
    let deriv: Vec<f64> = (0..n)
        .map(|i| {
            if p == 0 {
                return 0.0;
            }
            let pf = p as f64;
            pf * (ratio(prev[i], t[i + p] - t[i]) - ratio(prev[i + 1], t[i + p + 1] - t[i + 1]))
        })
        .collect();
    (lower[..n].to_vec(), deriv)
}

/// Values and slopes of the hat functions on `knots` (ascending) at x: 1 at its knot, linear to
/// 0 at the neighbours (constant beyond the ends).
pub(crate) fn hat_basis(x: f64, knots: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n = knots.len();
    let (mut v, mut d) = (vec![0.0; n], vec![0.0; n]);
    if n == 1 {
        v[0] = 1.0;
        return (v, d);
    }
    if x <= knots[0] {
        v[0] = 1.0;
        return (v, d);
    }
    if x >= knots[n - 1] {
        v[n - 1] = 1.0;
        return (v, d);
    }
    let i = knots.partition_point(|k| *k <= x).saturating_sub(1).min(n - 2);
    let h = knots[i + 1] - knots[i];
    let f = (x - knots[i]) / h;
    v[i] = 1.0 - f;
    v[i + 1] = f;
    d[i] = -1.0 / h;
    d[i + 1] = 1.0 / h;
    (v, d)
}

impl Shape {
    /// The basis orders of an error motion's series, one per coefficient: `select`, else
    /// first_power..=order.
    pub(crate) fn ks(&self) -> Vec<usize> {
        // index: orders and powers are u32 the shape was built with, bounded by `check_basis` and
        // `resolvable_order` (≤ the data's distinct positions); widened, not computed from floats.
        match &self.select {
            Some(sel) => sel.iter().map(|k| *k as usize).collect(),
            None => (self.first_power as usize..=self.order as usize).collect(),
        }
    }

    /// The same series restricted to the basis orders `sel` (ascending, within first_power..=order).
    pub(crate) fn selected(mut self, sel: Vec<u32>) -> Shape {
        self.coefs = sel.iter().map(|k| format!("c{k}")).collect();
        self.select = Some(sel);
        self
    }

    /// A `gravity_tilt` with each accelerometer of `sensors` ([`accel_sensors`]) at its own degree
    /// `orders` (0: no tilt on it); `order` becomes the highest.
    pub(crate) fn with_tilt_orders(mut self, sensors: &[String], orders: Vec<u32>) -> Shape {
        self.order = orders.iter().copied().max().unwrap_or(0);
        self.coefs = tilt_coefs(sensors, &orders, self.order);
        self.tilt_orders = orders;
        self
    }

    /// A `gravity_tilt`'s degree on accelerometer `s` (in [`accel_sensors`] order).
    pub(crate) fn tilt_order(&self, s: usize) -> u32 {
        self.tilt_orders.get(s).copied().unwrap_or(self.order)
    }

    /// Values and slopes (d/dx, 1/m) of the basis functions of orders 0..=`order` at x (m).
    pub(crate) fn basis_at(&self, x: f64) -> (Vec<f64>, Vec<f64>) {
        let (a, b) = self.range;
        // index: the shape's order, a u32 bounded by `check_basis`/`resolvable_order`, widened.
        let top = self.order as usize;
        match self.basis {
            ShapeBasis::Legendre => {
                let (p, d) = legendre((2.0 * x - a - b) / (b - a), top);
                let slope = d.iter().map(|dk| dk * 2.0 / (b - a)).collect();
                (p, slope)
            }
            // The series' terms one by one ([`Shape::cosine_basis`]).
            ShapeBasis::Cosine => self.cosine_basis(x, top),
            ShapeBasis::Bspline => bspline_basis(x, top + 1, (a, b)),
            ShapeBasis::Table => hat_basis(x, &self.knots),
            ShapeBasis::Harmonics => {
                let (mut vals, mut slopes) = (vec![1.0, x - a], vec![0.0, 1.0]);
                for h in 1..=top.saturating_sub(1) / 2 {
                    let k = TWO_PI * h as f64 / (2.0 * (b - a));
                    let (sn, cs) = (k * x).sin_cos();
                    vals.extend([sn, cs]);
                    slopes.extend([k * cs, -k * sn]);
                }
                (vals, slopes)
            }
        }
    }

    /// E'(x) = Σ_j coef_j·φ'_{ks_j}(x) (1/m times the coefficients' unit): the slopes of
    /// [`Shape::terms_at`] (the same bits as [`Shape::basis_at`]'s) summed in the order of `ks`.
    pub(crate) fn slope_sum(&self, x: f64, ks: &[usize], coef: &[f64]) -> f64 {
        coef.iter().zip(&self.terms_at(x, ks).1).map(|(ck, slope)| ck * slope).sum()
    }

    /// (values, slopes d/dx in 1/m) of the basis indices `ks` at x: [`Shape::basis_at`]'s entries
    /// at `ks`, the same bits. A cosine series with `ks` ascending walks its recurrence once up to
    /// the last of `ks` without tabulating the others ([`CosineAt::walk`]).
    pub(crate) fn terms_at(&self, x: f64, ks: &[usize]) -> (Vec<f64>, Vec<f64>) {
        let ascending = ks.windows(2).all(|w| w[0] < w[1]);
        if self.basis != ShapeBasis::Cosine || !ascending {
            let (p, d) = self.basis_at(x);
            // index: each of `ks` is a basis index of this shape, at most its order.
            return ks.iter().map(|&k| (p[k], d[k])).unzip();
        }
        CosineAt::new(self.range, x).walk(ks.iter().copied()).unzip()
    }

    /// The slopes d/dx (1/m) at two positions x0 and x1: of the basis indices `ks`
    /// ([`Shape::terms_at`]) or, with None, of every index of [`Shape::basis_at`]; the same bits as
    /// those, position by position. A cosine series (with `ks` ascending) walks the two positions'
    /// recurrences side by side ([`CosineAt::walk_at`]).
    pub(crate) fn slopes_at_two(&self, x0: f64, x1: f64, ks: Option<&[usize]>) -> (Vec<f64>, Vec<f64>) {
        let ascending = ks.is_none_or(|ks| ks.windows(2).all(|w| w[0] < w[1]));
        if self.basis != ShapeBasis::Cosine || !ascending {
            return match ks {
                Some(ks) => (self.terms_at(x0, ks).1, self.terms_at(x1, ks).1),
                None => (self.basis_at(x0).1, self.basis_at(x1).1),
            };
        }
        let (a, b) = (CosineAt::new(self.range, x0), CosineAt::new(self.range, x1));
        // index: the shape's order, a u32 bounded by `check_basis`/`resolvable_order`, widened.
        let all: Vec<usize> = if ks.is_none() { (0..=self.order as usize).collect() } else { Vec::new() };
        let ks = ks.unwrap_or(&all);
        CosineAt::walk_at([&a, &b], ks.iter().copied()).map(|[p, q]| (p.1, q.1)).unzip()
    }

    /// (value, slope d/dx in 1/m) of the cosine series' basis functions 0..=`top` at x, index by
    /// index ([`ShapeBasis::Cosine`]): φ_0 = 1, φ_1 = P_3, φ_2 = P_4 (their E'' = P_3'', P_4''
    /// carry the profile's third derivative at the ends, where a cosine series of E'' converges
    /// slowly), then the pairs φ_{2j+1} = cos(jπ(x − a)/(b − a)), φ_{2j+2} = sin(jπ(x − a)/(b − a)),
    /// j ≥ 1: sine and cosine of period 2(b − a)/j, so that a wave of any wavelength and phase
    /// (rail waviness between two of these frequencies) is a few neighbouring pairs (the family is
    /// overcomplete on [a, b]: a smooth periodic extension exists). cos(jθ), sin(jθ) by the
    /// angle-addition recurrence (rounding grows ≈ j·ε; [`CosineAt`]).
    fn cosine_basis(&self, x: f64, top: usize) -> (Vec<f64>, Vec<f64>) {
        CosineAt::new(self.range, x).walk(0..=top).unzip()
    }

    /// This shape (an error motion's, from [`shape`]) in `basis` with user order `order`
    /// ([`ShapeBasis::top_index`]); a table's positions are the distinct sample positions when
    /// `order` is their number, else `order` uniform points over the range.
    pub(crate) fn in_basis(mut self, st: &Stack, basis: ShapeBasis, order: u32) -> Shape {
        self.basis = basis;
        self.order = basis.top_index(order);
        let (a, b) = self.range;
        self.knots = match basis {
            ShapeBasis::Table => {
                let xs = distinct_positions(st);
                // index: a u32 order widened for a comparison.
                if xs.len() == order as usize {
                    xs.to_vec()
                } else {
                    (0..order).map(|k| a + (b - a) * k as f64 / (order.max(2) - 1) as f64).collect()
                }
            }
            ShapeBasis::Legendre | ShapeBasis::Cosine | ShapeBasis::Bspline | ShapeBasis::Harmonics => vec![],
        };
        let prefix = match basis {
            ShapeBasis::Legendre | ShapeBasis::Cosine => "c",
            ShapeBasis::Bspline => "b",
            ShapeBasis::Harmonics => "h",
            ShapeBasis::Table => "v",
        };
        self.coefs = (self.first_power..=self.order).map(|k| format!("{prefix}{k}")).collect();
        self
    }
}

/// True for the effects phase 1 can predict in a point table (the model check's catalogue row of the effect).
pub fn predicts(name: EffectName) -> bool {
    catalogue_row(name).predicts
}

/// What the model check knows of one catalogue effect besides its signature ([`shape`], [`columns`],
/// the known prediction) and the reading back of its fitted coefficients: whether phase 1 predicts
/// it, what data shows it, and a periodic effect's period range. [`catalogue_row`] has one arm per
/// effect and no wildcard, so the compiler names it for a new effect (issue 12).
pub(crate) struct CatalogueRow {
    /// Phase 1 can predict it (it has a signature on the stacked samples); the others are neither
    /// fitted nor searched as candidates.
    pub(crate) predicts: bool,
    /// What data shows it, for the "no channel sees it" message.
    pub(crate) needs: &'static str,
    /// A periodic effect's period (its catalogue range and search grid); None for the others.
    pub(crate) period: Option<PeriodRange>,
}

/// The catalogue range of a periodic effect's period, m, and the grid `diagnose` searches it on.
pub(crate) struct PeriodRange {
    /// Shortest period of the catalogue range, m.
    pub(crate) lo: f64,
    /// Longest period of the catalogue range, m.
    pub(crate) hi: f64,
    /// The range as a note reads it, e.g. "2–60 mm (screw leads)".
    pub(crate) text: &'static str,
    /// The periods searched before any refinement.
    pub(crate) grid: PeriodGrid,
    /// Where the wave enters a channel's reading.
    pub(crate) path: WavePath,
}

/// Where a periodic effect's wave sin(2πx/p + φ) enters a channel's reading (module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum WavePath {
    /// In the drive, at the screw's position (a cyclic lead): [`Channel::s_drive`], [`Channel::screw_x`].
    Drive,
    /// In the feedback chain, at the scale's reading (an interpolation error): [`Channel::s_chain`], `x`.
    Chain,
}

impl WavePath {
    /// Sensitivity of channel `c` to a wave on this path (0: it does not see it).
    pub(crate) fn sensitivity(self, c: &Channel) -> f64 {
        match self {
            WavePath::Drive => c.s_drive(),
            WavePath::Chain => c.s_chain(),
        }
    }

    /// (sensitivity, position the wave is a function of in m) of channel `c` at sample `i`.
    pub(crate) fn read(self, c: &Channel, i: usize) -> (f64, f64) {
        match self {
            WavePath::Drive => (c.s_drive(), c.screw_x(i)),
            WavePath::Chain => (c.s_chain(), c.x[i]),
        }
    }
}

/// How the periods of a [`PeriodRange`] are searched.
pub(crate) enum PeriodGrid {
    /// `n` log-spaced periods from `lo` to `hi`, refined by golden section.
    Log(usize),
    /// These periods (m), not refined.
    List(&'static [f64]),
}

impl PeriodRange {
    /// The search grid on these data: the periods of [`PeriodRange::grid`] that the sample positions
    /// resolve (never an alias), and whether the best is refined.
    fn search_grid(&self, st: &Stack) -> (Vec<f64>, bool) {
        match self.grid {
            PeriodGrid::Log(n) => (resolvable_only(st, log_grid(self.lo, self.hi, n)), true),
            PeriodGrid::List(periods) => (resolvable_only(st, periods.to_vec()), false),
        }
    }
}

/// The model check's row of effect `name` ([`CatalogueRow`]).
pub(crate) fn catalogue_row(name: EffectName) -> CatalogueRow {
    const LASER_LINEAR: &str = "needs a laser_linear along the axis in a positioning run";
    const SCREW: &str = "needs a laser_linear or a linear scale in a positioning run, or a linear scale and a motor \
                         encoder logged against x_cmd in a time series";
    let row = |predicts: bool, needs: &'static str| CatalogueRow { predicts, needs, period: None };
    match name {
        EffectName::Positioning => row(true, LASER_LINEAR),
        EffectName::StraightnessY | EffectName::StraightnessZ => row(
            true,
            "needs a laser_straightness across the axis in a positioning run, or an accelerometer across the axis \
             in a constant-velocity run",
        ),
        EffectName::Roll | EffectName::Pitch | EffectName::Yaw => row(
            true,
            "needs a laser whose measuring point is offset from the axis (an Abbe offset) across its direction",
        ),
        // A squareness joins the axes of a chain: not predicted on one axis.
        EffectName::SquarenessXy | EffectName::SquarenessXz | EffectName::SquarenessYz => row(false, LASER_LINEAR),
        EffectName::Backlash => row(true, SCREW),
        // Screw leads 2–60 mm.
        EffectName::CyclicLead => CatalogueRow {
            predicts: true,
            needs: SCREW,
            period: Some(PeriodRange {
                lo: 2e-3,
                hi: 60e-3,
                text: "2–60 mm (screw leads)",
                grid: PeriodGrid::Log(120),
                path: WavePath::Drive,
            }),
        },
        EffectName::ScaleError | EffectName::ThermalExpansion | EffectName::ThermalDrift => row(true, LASER_LINEAR),
        // Signal periods of common linear and rotary scales (Heidenhain, Renishaw): 2–200 µm.
        EffectName::InterpolationError => CatalogueRow {
            predicts: true,
            needs: LASER_LINEAR,
            period: Some(PeriodRange {
                lo: 2e-6,
                hi: 200e-6,
                text: "2–200 µm (scale signal periods)",
                grid: PeriodGrid::List(&[2e-6, 4e-6, 8e-6, 10e-6, 20e-6, 40e-6, 100e-6, 200e-6]),
                path: WavePath::Chain,
            }),
        },
        EffectName::Coulomb | EffectName::Viscous | EffectName::Stribeck => row(true, LASER_LINEAR),
        // LuGre's bristle state has no signature in phase 1 (its steady state is the Stribeck curve).
        EffectName::Lugre => row(false, LASER_LINEAR),
        EffectName::ServoLag => row(true, "needs an encoder logged against the command (x_cmd) in a time series"),
        EffectName::Resonance | EffectName::GravityTilt => row(true, LASER_LINEAR),
        // A random walk of an accelerometer's bias: not predicted (the offsets carry its mean).
        EffectName::AccelBiasDrift => row(false, LASER_LINEAR),
    }
}

/// The effects without a signature of their own on the stacked samples, as a pattern in a `match`
/// over [`EffectName`] (`no_own_signature!() => …`): the error motions (fitted as shapes, [`Shape`]),
/// the squarenesses (they join the axes of a chain), LuGre (its bristle state has no signature in
/// phase 1; its steady state is the Stribeck curve) and the accelerometer bias drift (the offsets
/// carry its mean). The one list of them for [`shape`], [`columns`] and the reading back of fitted
/// coefficients; those matches stay exhaustive, so the compiler names each for a new effect.
macro_rules! no_own_signature {
    () => {
        vmt_sim::error_motions!()
            | EffectName::SquarenessXy
            | EffectName::SquarenessXz
            | EffectName::SquarenessYz
            | EffectName::Lugre
            | EffectName::AccelBiasDrift
    };
}
pub(crate) use no_own_signature;

/// Length of the segments over which a resonance's amplitude and phase are held, s. A base-excited
/// mode driven by a random guideway profile is a narrow-band random process whose amplitude and
/// phase wander over its correlation time 1/(ζ·2πf) (0.18 s at 45 Hz, ζ = 0.02): piecewise
/// sin/cos with amplitudes per segment follow it.
pub(crate) const RESONANCE_SEGMENT: f64 = 0.2;

/// The resonance segments of the accelerometer channels without a predicted mode excitation
/// (module doc): (channel index, segment number, start time, end time), s. A channel is cut into ⌈T/`RESONANCE_SEGMENT`⌉ equal segments of its time span
/// (a segment needs ≥ 8 samples, else the channel is one segment).
pub(crate) fn resonance_segments(st: &Stack) -> Vec<(usize, usize, f64, f64)> {
    let mut out = Vec::new();
    for (j, c) in st.chans.iter().enumerate() {
        if !c.is_accel() || c.t.len() < 8 || !st.excitation[j].is_empty() {
            continue;
        }
        let lo = c.t.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = c.t.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let span = hi - lo;
        // index: a saturating float → count; then m ≤ samples/8 (below), so a huge span cannot size anything.
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

/// Names of the accelerometer sensors among the channels, in order of appearance. (Each gets the
/// gravity-tilt columns: a sensor gravity cannot reach through a tilt, one along the machine's
/// vertical, would need the axis frame's vertical, which the stack does not carry — `Channel::u`
/// is in the axis frame, where the vertical is z for X and Y axes but x for a Z axis.)
pub(crate) fn accel_sensors(st: &Stack) -> Vec<String> {
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
pub(crate) fn excited_sensors(st: &Stack) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for (c, _) in st.chans.iter().zip(&st.excitation).filter(|(_, e)| !e.is_empty()) {
        if !out.contains(&c.sensor) {
            out.push(c.sensor.clone());
        }
    }
    out
}

/// The forced-response gains of a resonance: (sensor, input index) for every input of every excited
/// sensor, named `gain_SENSOR` for the first input and `gain_SENSOR_K` for input K ≥ 1.
pub(crate) fn resonance_gains(st: &Stack) -> Vec<(String, usize, String)> {
    let mut out = Vec::new();
    for a in excited_sensors(st) {
        let k_max = st.chans.iter().zip(&st.excitation).filter(|(c, _)| c.sensor == a).map(|(_, e)| e.len()).max();
        for k in 0..k_max.unwrap_or(0) {
            let name = if k == 0 { format!("gain_{a}") } else { format!("gain_{a}_{k}") };
            out.push((a.clone(), k, name));
        }
    }
    out
}

/// The columns of a structural mode at frequency `f` (Hz) and damping ratio `zeta` as runs of rows
/// ([`SparseColumn`]; [`open_loop_columns`] places them in full columns): each lives on a few
/// channels of the stack, so a search over (f, ζ) need not write or read the zeros
/// ([`vmt_estimators::modelcheck::Candidate::with_sparse`]).
///
/// - Forced response to each predicted base acceleration, gain φ (the mode shape at the sensor,
///   times the input's share of the drive) per sensor and input: φ·mean q̈ with q driven by −a_ref
///   from rest at t_{−1}, a run on each of the sensor's channels that the input reaches.
/// - Free vibration from the unknown state at t_{−1}, two columns per excited channel (one run on
///   its rows).
/// - Channels without a predicted excitation: a narrow band at the temporal frequency f, sin/cos of
///   2πf·t per segment ([`resonance_segments`]), a run per stretch of the segment's rows.
pub(crate) fn resonance_runs(st: &Stack, f: f64, zeta: f64) -> Vec<SparseColumn> {
    clear_upper_state();
    let mut cols = Vec::new();
    let starts = st.channel_starts();
    // The sensors of one pass (the same times, the same tables) share their responses.
    let same = |k: usize, j: usize| {
        let (ek, ej) = (&st.excitation[k], &st.excitation[j]);
        ek.len() == ej.len() && ek.iter().zip(ej).all(|(a, b)| a.shares(b)) && st.chans[k].t == st.chans[j].t
    };
    let mut responses: Vec<std::sync::Arc<Vec<Vec<f64>>>> = Vec::with_capacity(st.chans.len());
    for (j, (c, es)) in st.chans.iter().zip(&st.excitation).enumerate() {
        let r = match (0..j).find(|&k| !es.is_empty() && same(k, j)) {
            Some(k) => responses[k].clone(),
            None => std::sync::Arc::new(mode_responses(c, es, f, zeta)),
        };
        responses.push(r);
    }
    for (a, k, _) in resonance_gains(st) {
        // Sensor `a`'s response to input k on each of its channels.
        let runs = st
            .chans
            .iter()
            .zip(&responses)
            .zip(&starts)
            .filter(|((c, _), _)| c.sensor == a)
            .filter_map(|((_, r), &s0)| r.get(k).map(|r| (s0, r.clone())))
            .collect();
        cols.push(SparseColumn { runs });
    }
    let mut free: Vec<(usize, std::sync::Arc<[Vec<f64>; 2]>)> = Vec::new();
    for (j, c) in st.chans.iter().enumerate() {
        if st.excitation[j].is_empty() {
            continue;
        }
        // Channels with the same times share it.
        let rs = match free.iter().find(|(k, _)| st.chans[*k].t == c.t) {
            Some((_, rs)) => rs.clone(),
            None => std::sync::Arc::new(free_vibration(c, f, zeta)),
        };
        for r in rs.iter() {
            cols.push(SparseColumn { runs: vec![(starts[j], r.clone())] });
        }
        free.push((j, rs));
    }
    for (j, _, a, b) in resonance_segments(st) {
        let c = &st.chans[j];
        let inside = |i: usize| c.t[i] >= a && c.t[i] < b;
        let (mut sin, mut cos) = (SparseColumn::default(), SparseColumn::default());
        let mut i = 0;
        while i < c.t.len() {
            if !inside(i) {
                i += 1;
                continue;
            }
            let i0 = i;
            while i < c.t.len() && inside(i) {
                i += 1;
            }
            let (s, co): (Vec<f64>, Vec<f64>) = (i0..i).map(|i| (TWO_PI * f * c.t[i]).sin_cos()).unzip();
            sin.runs.push((starts[j] + i0, s));
            cos.runs.push((starts[j] + i0, co));
        }
        cols.push(sin);
        cols.push(cos);
    }
    cols
}

/// Sampling rate of the slowest accelerometer channel, Hz (median sample interval); None without one.
pub(crate) fn accel_min_rate(st: &Stack) -> Option<f64> {
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

pub(crate) fn shape(st: &Stack, name: EffectName, first_power: u32, order: u32, with_fc: bool) -> Shape {
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<String>>();
    let (coefs, hypers): (Vec<String>, Vec<Hyper>) = match name {
        n if n.is_error_motion() => ((first_power..=order).map(|k| format!("c{k}")).collect(), vec![]),
        // On encoder time series the backlash is a play whose take-up at a reversal depends on it.
        EffectName::Backlash if st.chans.iter().any(|c| c.encoder.is_some()) => (s(&["value"]), vec![Hyper::Play]),
        EffectName::Backlash | EffectName::ScaleError => (s(&["value"]), vec![]),
        EffectName::ServoLag => {
            // The gain, and per following channel the decay of its unknown starting state.
            let mut names = s(&["gain"]);
            names.extend(following_channels(st).map(|j| format!("start_{j}")));
            (names, vec![Hyper::Kv])
        }
        EffectName::CyclicLead | EffectName::InterpolationError => (s(&["a_sin", "a_cos"]), vec![Hyper::Period]),
        EffectName::ThermalExpansion => (s(&["alpha_delta_t"]), vec![Hyper::Tau]),
        EffectName::ThermalDrift => (s(&["value"]), vec![Hyper::Tau]),
        EffectName::Coulomb => (s(&["fc"]), vec![]),
        EffectName::Viscous => (s(&["fv"]), vec![]),
        EffectName::Stribeck if with_fc => (s(&["fs_minus_fc", "fc"]), vec![Hyper::Vs, Hyper::Shape]),
        EffectName::Stribeck => (s(&["fs_minus_fc"]), vec![Hyper::Vs, Hyper::Shape]),
        EffectName::Resonance => {
            let mut names: Vec<String> = resonance_gains(st).into_iter().map(|g| g.2).collect();
            for (j, _) in st.excitation.iter().enumerate().filter(|(_, e)| !e.is_empty()) {
                names.push(format!("free_q_{j}"));
                names.push(format!("free_v_{j}"));
            }
            names.extend(
                resonance_segments(st).iter().flat_map(|(j, k, _, _)| [format!("sin_{j}_{k}"), format!("cos_{j}_{k}")]),
            );
            (names, vec![Hyper::Frequency, Hyper::Damping])
        }
        EffectName::GravityTilt => (tilt_coefs(&accel_sensors(st), &[], order), vec![]),
        no_own_signature!() => (vec![], vec![]),
    };
    let range = match distinct_positions(st) {
        xs if xs.len() >= 2 => (xs[0], xs[xs.len() - 1]),
        xs => xs.first().map_or((0.0, 1.0), |x| (x - 0.5, x + 0.5)),
    };
    // A motion seen only through accelerometers: a cosine series ([`ShapeBasis::Cosine`]).
    let seeing: Vec<&Channel> = st.chans.iter().filter(|c| c.s_motion(name) != 0.0).collect();
    let basis = if name.is_error_motion() && !seeing.is_empty() && seeing.iter().all(|c| c.is_accel()) {
        ShapeBasis::Cosine
    } else {
        ShapeBasis::Legendre
    };
    Shape { coefs, hypers, first_power, order, with_fc, range, basis, select: None, knots: vec![], tilt_orders: vec![] }
}

/// The coefficient names of a `gravity_tilt` over the accelerometers `sensors`: `{sensor}_p{k}`,
/// k = 1..its degree (`orders[s]`, else `order`).
fn tilt_coefs(sensors: &[String], orders: &[u32], order: u32) -> Vec<String> {
    sensors
        .iter()
        .enumerate()
        .flat_map(|(s, a)| (1..=orders.get(s).copied().unwrap_or(order)).map(move |k| format!("{a}_p{k}")))
        .collect()
}

/// Legendre polynomials P_0..P_n at u and their derivatives dP_k/du, by Bonnet's recurrence
/// (k+1)·P_{k+1} = (2k+1)·u·P_k − k·P_{k−1} and P'_{k+1} = P'_{k−1} + (2k+1)·P_k
/// (Abramowitz & Stegun 22.7.10, 22.8.5). Orthogonal on [−1, 1], |P_k| ≤ 1 there: a fitted
/// error motion's columns stay well conditioned at high order, unlike monomials.
pub(crate) fn legendre(u: f64, n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut p = vec![0.0; n + 1];
    let mut d = vec![0.0; n + 1];
    p[0] = 1.0;
    if n >= 1 {
        p[1] = u;
        d[1] = 1.0;
    }
    for k in 1..n {
        p[k + 1] = bonnet(k, u, p[k], p[k - 1]);
        d[k + 1] = d[k - 1] + (2.0 * k as f64 + 1.0) * p[k];
    }
    (p, d)
}

/// One step of Bonnet's recurrence: P_{k+1}(u) = ((2k+1)·u·P_k − k·P_{k−1})/(k+1) from P_k =
/// `pk` and P_{k−1} = `pk1` ([`legendre`], [`legendre_value_block`]: one expression, so both give
/// the same bits).
#[inline(always)]
fn bonnet(k: usize, u: f64, pk: f64, pk1: f64) -> f64 {
    let kf = k as f64;
    ((2.0 * kf + 1.0) * u * pk - kf * pk1) / (kf + 1.0)
}

/// A block of [`Shape::terms_at`]'s Legendre values times the reading's sensitivity, s·P_k(u(x_i)),
/// for the basis indices `ks` of `sh` (a Legendre series) at samples i0..i0 + len of channel `c`
/// reading motion `name` as a value ([`Channel::motion_read`]: 0 where it is blind), written into
/// `out` (one slice per index of `ks`). Bonnet's recurrence runs order by order over the block's
/// samples — [`bonnet`], as in [`legendre`], so the same bits as one sample at a time, without
/// its chain of divisions from one order to the next in one sample (the samples' recurrences
/// are independent) and without the slopes.
fn legendre_value_block(
    sh: &Shape,
    ks: &[usize],
    c: &Channel,
    name: EffectName,
    i0: usize,
    len: usize,
    out: &mut [&mut [f64]],
) {
    let s = c.s_motion(name);
    if s == 0.0 {
        return;
    }
    let (a, b) = sh.range;
    // index: samples i0..i0 + len of the channel (`Stack::col_blocks`).
    let u: Vec<f64> = c.x[i0..i0 + len].iter().map(|x| (2.0 * x - a - b) / (b - a)).collect();
    let top = ks.iter().copied().max().unwrap_or(0);
    // Where each order is written: its slots in `out` (ks may repeat an order).
    let mut slots: Vec<Vec<usize>> = vec![Vec::new(); top + 1];
    ks.iter().enumerate().for_each(|(j, &k)| slots[k].push(j));
    let put = |k: usize, p: &[f64], out: &mut [&mut [f64]]| {
        for &j in &slots[k] {
            out[j].iter_mut().zip(p).for_each(|(o, pk)| *o = s * pk);
        }
    };
    let mut before = vec![1.0; len];
    put(0, &before, out);
    if top == 0 {
        return;
    }
    let mut now = u.clone();
    put(1, &now, out);
    let mut next = vec![0.0; len];
    for k in 1..top {
        for i in 0..len {
            next[i] = bonnet(k, u[i], now[i], before[i]);
        }
        // (before, now, next) ← (now, next, before): P_{k}, P_{k+1}, and a buffer.
        std::mem::swap(&mut before, &mut now);
        std::mem::swap(&mut now, &mut next);
        put(k + 1, &now, out);
    }
}

/// Monomial coefficients m_j (x in m, j = 0..=n) of Σ_k c_k·P_k(u(x)), k = first..first + c.len() − 1,
/// u = α·x + β with α = 2/(b − a), β = −(a + b)/(b − a): the Legendre series of a fitted error
/// motion written as FORMAT.md §2 `c_j` (for reading; the fit itself stays in the Legendre basis).
pub(crate) fn legendre_to_monomials(first: u32, c: &[f64], range: (f64, f64)) -> Vec<f64> {
    // index: `first` is a shape's first power (0, 1 or 2), a u32 widened; `c` one coefficient per order.
    let n = first as usize + c.len();
    // Coefficients of P_k in powers of u, by the same recurrence.
    let mut pu: Vec<Vec<f64>> = vec![vec![1.0]];
    if n > 1 {
        pu.push(vec![0.0, 1.0]);
    }
    for k in 1..n.saturating_sub(1) {
        let kf = k as f64;
        let mut next = vec![0.0; k + 2];
        for (j, v) in pu[k].iter().enumerate() {
            next[j + 1] += (2.0 * kf + 1.0) * v / (kf + 1.0);
        }
        for (j, v) in pu[k - 1].iter().enumerate() {
            next[j] -= kf * v / (kf + 1.0);
        }
        pu.push(next);
    }
    let (a, b) = range;
    let (al, be) = (2.0 / (b - a), -(a + b) / (b - a));
    // Powers of u in x: (αx + β)^j by the binomial theorem.
    let mut out = vec![0.0; n];
    for (i, ck) in c.iter().enumerate() {
        let k = first as usize + i;
        for (j, pj) in pu[k].iter().enumerate() {
            let mut binom = 1.0;
            for q in 0..=j {
                // C(j, q)·α^q·β^(j−q)
                out[q] += ck * pj * binom * al.powi(q as i32) * be.powi((j - q) as i32);
                binom = binom * (j - q) as f64 / (q + 1) as f64;
            }
        }
    }
    out
}

/// Design columns of effect `name` at hyper-parameters `h` (in the order of [`shape`]), each
/// passed through a closed position loop onto its following channels ([`close_loop`]).
pub(crate) fn columns(st: &Stack, name: EffectName, sh: &Shape, h: &[f64]) -> Vec<Vec<f64>> {
    columns_each(st, name, sh, &[h]).pop().unwrap_or_default()
}

/// [`columns`] at each of the hyper-parameter values `hs`: every value's columns on each channel
/// alone, then all of them through a closed loop together, in blocks of [`LOOP_COLUMNS`] side by
/// side (rayon), each block's lags in one pass over the samples ([`close_loop_each`]). The same
/// bits as [`columns`] at each value, on any number of threads.
pub(crate) fn columns_each(st: &Stack, name: EffectName, sh: &Shape, hs: &[&[f64]]) -> Vec<Vec<Vec<f64>>> {
    clear_upper_state();
    let mut sets: Vec<Vec<Vec<f64>>> = hs.iter().map(|h| open_loop_columns(st, name, sh, h)).collect();
    if !has_closed_loop(st.chans) {
        return sets;
    }
    let mut through: Vec<&mut Vec<f64>> = Vec::new();
    for (set, h) in sets.iter_mut().zip(hs) {
        match set.as_mut_slice() {
            // A wave in the scale's reading, faster than the log samples it (`close_loop_wave`).
            // (A cyclic lead, 2–60 mm, is sampled densely and takes `close_loop`: passed as a wave
            // it was no longer found against a flexible positioning shape, draw 2007.)
            [sin, cos] if name == EffectName::InterpolationError => {
                close_loop_wave(st, h[0], &st.interp_shift, sin, cos)
            }
            cols => through.extend(cols.iter_mut()),
        }
    }
    through.par_chunks_mut(LOOP_COLUMNS).for_each(|block| close_loop_each(st, block));
    sets
}

/// The columns of [`columns`] on each channel alone, before the loop couples them.
fn open_loop_columns(st: &Stack, name: EffectName, sh: &Shape, h: &[f64]) -> Vec<Vec<f64>> {
    match name {
        n if n.is_error_motion() => {
            // c_k·P_k(u(x)): the same coefficient for lasers (P_k) and accelerometers (its slope
            // P'_k·2/(b − a), differenced over the sample interval); every order at once per
            // position ([`Shape::terms_at`]; cosines for a motion only accelerometers see).
            let ks = sh.ks();
            // Values only (encoders, lasers) of a Legendre series: order by order over a block's
            // samples ([`legendre_value_block`]), the same bits as sample by sample.
            let values_only = st.chans.iter().all(|c| c.s_motion(n) == 0.0 || c.reads_values());
            if sh.basis == ShapeBasis::Legendre && values_only {
                return st.col_blocks(ks.len(), |c, i0, len, mine| legendre_value_block(sh, &ks, c, n, i0, len, mine));
            }
            st.col_rows(ks.len(), |c, i, row| match c.motion_read(i, n) {
                MotionRead::Blind => {}
                MotionRead::Value { s, x } => {
                    let (p, _) = sh.terms_at(x, &ks);
                    row.iter_mut().zip(&p).for_each(|(o, pk)| *o = s * pk);
                }
                MotionRead::SlopeDifference { s, v, dt, xa, xb } => {
                    let (d1, d0) = sh.slopes_at_two(xb, xa, Some(&ks));
                    row.iter_mut().zip(d1.iter().zip(&d0)).for_each(|(o, (b, a))| *o = s * v * (b - a) / dt);
                }
            })
        }
        EffectName::Backlash => {
            // Encoder time series: the play p(t; b)/b (take-up b/|v| at a reversal); point tables: −d/2.
            let b = h.first().copied().unwrap_or(0.0);
            let mut col = Vec::with_capacity(st.n);
            for c in st.chans {
                match play_signature(c, b).filter(|_| b > 0.0) {
                    Some(p) => col.extend(p),
                    None => col.extend((0..c.y.len()).map(|i| -0.5 * c.d[i] * c.s_drive())),
                }
            }
            vec![col]
        }
        EffectName::ServoLag => {
            // Following error of a first-order loop, L_kv[input] − command, on following channels;
            // the coefficient is 1 − the velocity feed-forward fraction.
            let mut col = Vec::with_capacity(st.n);
            for c in st.chans {
                col.extend(following_error(c, h[0]));
            }
            // A log starts a finite time after the last change of speed: the loop's state then
            // decays as e^{−kv·(t − t₀)} from an unknown start, one column per following channel.
            let mut cols = vec![col];
            for j in following_channels(st) {
                let t0 = st.chans[j].t.first().copied().unwrap_or(0.0);
                cols.push(st.col_j(|c, i, jj| if jj == j { (-h[0] * (c.t[i] - t0)).exp() } else { 0.0 }));
            }
            cols
        }
        EffectName::ScaleError => vec![st.col(|c, i| c.x[i] * c.s_chain())],
        EffectName::CyclicLead | EffectName::InterpolationError => {
            let p = h[0];
            // A cyclic lead at the screw's position, an interpolation error at the scale's reading.
            // (Both have a period row: the `else` is not taken.)
            let Some(path) = catalogue_row(name).period.map(|r| r.path) else { return vec![] };
            if !phases_spread(st, p) || !period_resolvable(st, p) {
                return vec![vec![0.0; st.n], vec![0.0; st.n]];
            }
            // A chain's wave at the table's position x − I(x_t) where a shift is known.
            let shifted = path == WavePath::Chain && st.interp_shift.len() == st.n;
            let (sin, cos) = st.col_pair(|c, i, k| {
                let (s, x) = path.read(c, i);
                let x = if shifted { x - st.interp_shift[k] } else { x };
                let (a, b) = (TWO_PI * x / p).sin_cos();
                (s * a, s * b)
            });
            vec![sin, cos]
        }
        EffectName::ThermalExpansion => vec![st.col(|c, i| c.s_chain() * c.x[i] * rise(c.t[i], h[0]))],
        EffectName::ThermalDrift => vec![st.col(|c, i| c.s_chain() * rise(c.t[i], h[0]))],
        EffectName::Coulomb => vec![st.col(|c, i| c.s_force() * c.v[i].signum())],
        EffectName::Viscous => vec![st.col(|c, i| c.s_force() * c.v[i])],
        EffectName::Stribeck => {
            // F = Fc·sgn v + (Fs − Fc)·sgn v·exp(−|v/vs|^δ): vs = h[0] (m/s), δ = h[1] (the shape
            // exponent, 2 when absent).
            let (vs, delta) = (h[0], h.get(1).copied().unwrap_or(2.0));
            let mut cols = vec![st.col(|c, i| c.s_force() * c.v[i].signum() * stribeck_weight(c.v[i], vs, delta))];
            if sh.with_fc {
                cols.push(st.col(|c, i| c.s_force() * c.v[i].signum()));
            }
            cols
        }
        EffectName::Resonance => resonance_runs(st, h[0], h[1]).iter().map(|c| c.dense(st.n)).collect(),
        EffectName::GravityTilt => {
            // g·tilt(x) of each accelerometer's sensitive axis, a Legendre series
            // Σ_k p_k·P_k(u), u = (2x − a − b)/(b − a), k = 1..its degree, shared by its runs.
            let (a, b) = sh.range;
            let mut cols = Vec::new();
            for (s, name) in accel_sensors(st).iter().enumerate() {
                // index: a degree the shape was built with (≤ TILT_MAX_ORDER, or DEFAULT_ORDER),
                // widened; `row + i` runs over this channel's rows of the stack (< st.n).
                let top = sh.tilt_order(s) as usize;
                let mut own = vec![vec![0.0; st.n]; top];
                let mut row = 0;
                for c in st.chans {
                    if c.sensor == *name && c.is_accel() {
                        for (i, &x) in c.x.iter().take(c.y.len()).enumerate() {
                            let (p, _) = legendre((2.0 * x - a - b) / (b - a), top);
                            for (col, pk) in own.iter_mut().zip(&p[1..]) {
                                col[row + i] = GRAVITY * pk;
                            }
                        }
                    }
                    row += c.y.len();
                }
                cols.extend(own);
            }
            cols
        }
        no_own_signature!() => vec![],
    }
}

/// True when the phases 2πx/p of the distinct targets spread around the circle (mean resultant
/// length R = |mean e^{iθ}| ≤ 0.5, and 0.1 ≤ mean sin²θ ≤ 0.9 so both quadratures vary), so that a
/// sinusoid of period p is distinguishable from a constant on these targets; false at an alias
/// (targets a whole number of periods apart). The sums come from [`phase_sums_fast`] where its
/// bound settles both tests, else from libm's `sin_cos` (a period scan calls this once per period,
/// over every distinct position of a log: libm's calls were a third of a cyclic lead's scan).
pub(crate) fn phases_spread(st: &Stack, p: f64) -> bool {
    let xs = distinct_positions(st);
    if xs.len() < 3 || !(p > 0.0) {
        return false;
    }
    let m = xs.len() as f64;
    // Both quadratures must vary: at p = 2 µm on targets rounded to 1 µm the sine vanishes.
    let spread =
        |(sc, cc, s2): (f64, f64, f64)| (sc * sc + cc * cc).sqrt() / m <= 0.5 && (0.1..=0.9).contains(&(s2 / m));
    if let Some((sc, cc, s2)) = phase_sums_fast(xs, p) {
        // Settled unless a statistic lies within the sums' bound of its threshold.
        let off = PHASE_SUMS_BOUND * m;
        let r = (sc * sc + cc * cc).sqrt();
        let near = |v: f64, at: f64| (v - at * m).abs() <= 2.0 * off;
        if !near(r, 0.5) && !near(s2, 0.1) && !near(s2, 0.9) {
            return spread((sc, cc, s2));
        }
    }
    clear_upper_state();
    spread(xs.iter().fold((0.0, 0.0, 0.0), |(a, b, q), x| {
        let (s, c) = (TWO_PI * x / p).sin_cos();
        (a + s, b + c, q + s * s)
    }))
}

/// Largest |θ| (rad) [`phase_sums_fast`] reduces: 10⁶, where k·π/2 with k < 2²⁰ keeps the
/// two-part reduction exact to 10⁻¹⁶ rad and θ's own rounding is below 3·10⁻¹⁰ rad.
const PHASE_FAST_MAX: f64 = 1e6;

/// Bound on |fast − libm| of each sum of [`phase_sums_fast`] per position (dimensionless): 10⁻⁸,
/// above the per-term difference (≤ 3·10⁻¹⁰ from θ = x·(2π/p) against libm's caller's 2πx/p, and
/// 10⁻¹¹ from the polynomials' truncation) plus the sums' rounding (≤ m·ε per term, m ≤ 10⁵).
const PHASE_SUMS_BOUND: f64 = 1e-8;

/// (Σ sin θ, Σ cos θ, Σ sin² θ) over θ = 2πx/p for the positions `xs` (m) and the period `p` (m),
/// each term within 10⁻⁹ of libm's ([`reduced_sin_cos`]), in four interleaved sums (independent
/// chains, several times faster than `sin_cos`); None when some |θ| > [`PHASE_FAST_MAX`].
fn phase_sums_fast(xs: &[f64], p: f64) -> Option<(f64, f64, f64)> {
    const LANES: usize = 4;
    let omega = TWO_PI / p;
    let mut acc = [[0.0; LANES]; 3];
    let mut largest = [0.0_f64; LANES];
    let mut add = |lane: usize, x: f64| {
        let theta = omega * x;
        largest[lane] = largest[lane].max(theta.abs());
        let (s, c) = reduced_sin_cos(theta);
        acc[0][lane] += s;
        acc[1][lane] += c;
        acc[2][lane] += s * s;
    };
    let chunks = xs.chunks_exact(LANES);
    let rest = chunks.remainder();
    for chunk in chunks {
        for (lane, x) in chunk.iter().enumerate() {
            add(lane, *x);
        }
    }
    for x in rest {
        add(0, *x);
    }
    let total = |a: [f64; LANES]| (a[0] + a[1]) + (a[2] + a[3]);
    (largest.iter().all(|l| *l <= PHASE_FAST_MAX)).then(|| (total(acc[0]), total(acc[1]), total(acc[2])))
}

/// sin θ and cos θ to 10⁻¹¹ for |θ| ≤ [`PHASE_FAST_MAX`] ([`phase_sums_fast`]): r = θ − k·π/2 with
/// k = round(2θ/π) and a two-part π/2 (the high part with 33 significant bits, so k·PIO2_HI is
/// exact for k < 2²⁰), sin r and cos r by their Taylor series to degree 11 and 12 on |r| ≤ π/4
/// (truncation below 10⁻¹¹), then the quadrant k mod 4.
#[inline(always)]
fn reduced_sin_cos(theta: f64) -> (f64, f64) {
    const PIO2_HI: f64 = 1.570_796_326_734_125_614_166_259_765_625;
    const PIO2_LO: f64 = 6.077_100_506_506_192e-11;
    let k = (theta * std::f64::consts::FRAC_2_PI).round();
    let r = (theta - k * PIO2_HI) - k * PIO2_LO;
    let z = r * r;
    let sr = r
        * (1.0
            + z * (-1.0 / 6.0
                + z * (1.0 / 120.0 + z * (-1.0 / 5040.0 + z * (1.0 / 362_880.0 + z * (-1.0 / 39_916_800.0))))));
    let cr = 1.0
        + z * (-0.5
            + z * (1.0 / 24.0
                + z * (-1.0 / 720.0 + z * (1.0 / 40_320.0 + z * (-1.0 / 3_628_800.0 + z * (1.0 / 479_001_600.0))))));
    // Quadrant k mod 4: (sin, cos) = (s, c), (c, −s), (−s, −c), (−c, s). (A saturating cast
    // beyond the range only makes a wrong term, which the caller then refuses.)
    let quadrant = (k as i64) & 3;
    let (s, c) = if quadrant & 1 == 1 { (cr, -sr) } else { (sr, cr) };
    if quadrant & 2 == 2 {
        (-s, -c)
    } else {
        (s, c)
    }
}

/// The distinct sample positions of all channels, sorted (m).
pub(crate) fn distinct_positions<'s>(st: &'s Stack) -> &'s [f64] {
    st.distinct.get_or_init(|| {
        let mut xs: Vec<f64> = st.chans.iter().flat_map(|c| c.x.iter().copied()).collect();
        xs.sort_by(f64::total_cmp);
        xs.dedup();
        xs
    })
}

/// True when the sample positions can resolve a wave of period `p` (m) rather than one of its
/// aliases: somewhere the positions sample it at least twice per period (every gap between
/// neighbouring distinct positions ≤ p/2, the Nyquist condition in position) over a stretch at
/// least one period long. On a regular grid of spacing Δ this is p ≥ 2Δ (and p ≤ the travel):
/// a shorter period is one of infinitely many aliases p' with 1/p' = |1/p − k/Δ| that fit the
/// targets equally well; on an irregular layout without such a dense stretch the phase at each
/// target is unrelated to its neighbours' and the search would fit per-target misfit.
pub(crate) fn period_resolvable(st: &Stack, p: f64) -> bool {
    resolvable_on(distinct_positions(st), p)
}

fn resolvable_on(xs: &[f64], p: f64) -> bool {
    if !(p > 0.0) || xs.len() < 3 {
        return false;
    }
    let mut start = xs[0];
    for w in xs.windows(2) {
        if w[1] - w[0] > 0.5 * p {
            start = w[1];
        } else if w[1] - start >= p {
            return true;
        }
    }
    false
}

/// The periods q (m, within `range`, the candidate's catalogue range, differing from `p` by more than 10 %) whose sine and cosine
/// on these sample positions reproduce those of period `p` (each with R² ≥ 0.99 by a 2-column
/// least-squares fit), i.e. fit any data exactly as well. On positions that lie on a lattice of
/// spacing Δ (the smallest gap) these are 1/q = |1/p − k/Δ|, k = ±1, ±2, … (spatial aliasing).
pub(crate) fn period_aliases(st: &Stack, p: f64, range: (f64, f64)) -> Vec<f64> {
    clear_upper_state();
    let xs = distinct_positions(st);
    let delta = xs.windows(2).map(|w| w[1] - w[0]).filter(|g| *g > 0.0).fold(f64::INFINITY, f64::min);
    if !(p > 0.0) || !delta.is_finite() || xs.len() < 3 {
        return vec![];
    }
    let wave = |q: f64| -> [Vec<f64>; 2] {
        [xs.iter().map(|x| (TWO_PI * x / q).sin()).collect(), xs.iter().map(|x| (TWO_PI * x / q).cos()).collect()]
    };
    let target = wave(p);
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let reproduces = |q: f64| {
        let [u, v] = wave(q);
        let (uu, uv, vv) = (dot(&u, &u), dot(&u, &v), dot(&v, &v));
        let det = uu * vv - uv * uv;
        det > 1e-9 * uu * vv
            && target.iter().all(|a| {
                let (au, av) = (dot(a, &u), dot(a, &v));
                let (cu, cv) = ((vv * au - uv * av) / det, (uu * av - uv * au) / det);
                let explained = cu * au + cv * av;
                let aa = dot(a, a);
                aa <= 0.0 || explained >= 0.99 * aa
            })
    };
    let mut out: Vec<f64> = Vec::new();
    for k in 1..=400 {
        for f in [1.0 / p + k as f64 / delta, (1.0 / p - k as f64 / delta).abs()] {
            let q = 1.0 / f;
            if (range.0..=range.1).contains(&q)
                && (q / p - 1.0).abs() > 0.1
                && !out.iter().any(|o| (o / q - 1.0).abs() < 1e-6)
                && reproduces(q)
            {
                out.push(q);
            }
        }
    }
    out.sort_by(f64::total_cmp);
    out
}

/// The signal periods (m) at which `diagnose` evaluates an interpolation-error candidate, chosen
/// from the weighted residual `r` (weights `w` = 1/σ) of the channels that see it, with the number
/// of independent periods of the catalogue range they were chosen from (the look-elsewhere count).
/// At speed a log samples a 2–200 µm signal period far below its Nyquist rate, so a fixed grid of
/// catalogue periods cannot hit its likelihood peak (about p/(travel) wide: 1/40 000 for 10 µm on
/// 0.4 m): the period is found where crawls and reversals sample it densely, then refined over
/// every sample (`vmt_estimators::modelcheck::sparse_frequency_scan`), at the scale's reading. None
/// when no stretch of the data samples any period of the range densely.
pub(crate) fn interpolation_periods(st: &Stack, r: &[f64], w: &[f64]) -> Option<(Vec<f64>, usize)> {
    let (lo, hi) = period_range(EffectName::InterpolationError)?;
    let (mut x, mut rs, mut ws, mut segments) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut k = 0;
    for c in st.chans {
        let n = c.y.len();
        if c.s_chain() != 0.0 && k + n <= r.len() && k + n <= w.len() {
            let a = x.len();
            x.extend_from_slice(&c.x);
            rs.extend_from_slice(&r[k..k + n]);
            ws.extend_from_slice(&w[k..k + n]);
            segments.push((a, x.len()));
        }
        k += n;
    }
    let scan = sparse_frequency_scan(&x, &rs, &ws, &segments, (1.0 / hi, 1.0 / lo))?;
    let mut periods: Vec<f64> = scan.frequencies.iter().map(|f| 1.0 / f).collect();
    periods.sort_by(f64::total_cmp);
    (!periods.is_empty()).then_some((periods, scan.independent))
}

/// The shortest period (m) these positions resolve ([`period_resolvable`]), to name in a note and
/// in the advice; None when no stretch holds three positions.
pub(crate) fn shortest_resolvable_period(st: &Stack) -> Option<f64> {
    let xs = distinct_positions(st);
    // Resolvable periods from the rule: p ≥ 2·(largest gap in a stretch) and p ≤ its length; the
    // smallest such p over all stretches is found by trying p = 2·gap for every gap (sorted).
    let mut gaps: Vec<f64> = xs.windows(2).map(|w| w[1] - w[0]).filter(|g| *g > 0.0).collect();
    gaps.sort_by(f64::total_cmp);
    gaps.into_iter().map(|g| 2.0 * g).find(|p| resolvable_on(xs, *p))
}

/// Fixed-point iterations of [`table_position`] at most: each shrinks the error by the slope
/// 2πA/p of the interpolation error (below 0.25 for A ≤ p/25, a coarse scale's error; the
/// iteration stops at 1e-15 m, well before this on any such scale).
pub const TABLE_POSITION_ITERATIONS: usize = 60;

/// The table's position x_t (m) of a scale reading s (m) that carries the interpolation error `ie`
/// at the table's own position, s = x_t + I(x_t), I(x) = A·sin(2πx/p + φ): the fixed point
/// x ← s − I(x) from x = s, which contracts where the slope 2πA/p < 1 (a reading that rises with
/// position). Read at s itself, I would carry the spurious second harmonic
/// I(s) − I(x_t) ≈ I'·I = (πA²/p)·sin(2(2πx_t/p + φ)): 17.5 nm on generator draw 2008
/// (A = 249 nm, p = 11.12 µm), which left normalised RMS 1.54 after `add`.
pub(crate) fn table_position(ie: &InterpolationError, s: f64) -> f64 {
    let mut x = s;
    for _ in 0..TABLE_POSITION_ITERATIONS {
        let next = s - ie.value(x);
        let moved = (next - x).abs();
        x = next;
        if moved <= 1e-15 {
            break;
        }
    }
    x
}

/// The interpolation error at the table's position, I(x_t), on every sample that reads the
/// feedback chain (0 elsewhere), m: the shift of [`Stack::interp_shift`] for `ie`.
pub(crate) fn interpolation_shift(st: &Stack, ie: &InterpolationError) -> Vec<f64> {
    st.col(|c, i| if c.s_chain() != 0.0 { c.x[i] - table_position(ie, c.x[i]) } else { 0.0 })
}

/// The prediction of a known (not fitted) effect at every sample, passed through a closed
/// position loop onto its following channels ([`close_loop`]).
pub(crate) fn known_prediction(st: &Stack, e: &Effect) -> Vec<f64> {
    clear_upper_state();
    if let (EffectParams::InterpolationError(ie), true) = (&e.params, has_closed_loop(st.chans)) {
        // A·sin(θ + φ) = A·cos φ·sin θ + A·sin φ·cos θ, through the loop as a wave (`close_loop_wave`).
        // At the table's position (`interpolation_shift`) where the channel reads the chain.
        let shift = interpolation_shift(st, ie);
        let (mut sin, mut cos) = st.col_pair(|c, i, k| {
            let (a, b) = (TWO_PI * (c.x[i] - shift[k]) / ie.period).sin_cos();
            (c.s_chain() * a, c.s_chain() * b)
        });
        close_loop_wave(st, ie.period, &shift, &mut sin, &mut cos);
        let (sp, cp) = ie.phase.sin_cos();
        return sin.iter().zip(&cos).map(|(a, b)| ie.amplitude * (cp * a + sp * b)).collect();
    }
    let mut col = open_loop_prediction(st, e);
    if has_closed_loop(st.chans) {
        close_loop(st, &mut col);
    }
    col
}

/// The prediction of [`known_prediction`] on each channel alone.
fn open_loop_prediction(st: &Stack, e: &Effect) -> Vec<f64> {
    match (&e.params, e.name) {
        (EffectParams::ErrorMotion(prof), n) => {
            st.col(|c, i| c.motion_response(i, n, |x| prof.value(x), |x| prof.eval3(x)[1]))
        }
        (EffectParams::Backlash(b), _) => {
            let mut col = Vec::with_capacity(st.n);
            for c in st.chans {
                match play_signature(c, b.value).filter(|_| b.value > 0.0) {
                    Some(p) => col.extend(p.iter().map(|p| p * b.value)),
                    None => col.extend((0..c.y.len()).map(|i| -0.5 * c.d[i] * c.s_drive() * b.value)),
                }
            }
            col
        }
        (EffectParams::ServoLag(s), _) => {
            let mut col = Vec::with_capacity(st.n);
            for c in st.chans {
                col.extend(following_error(c, s.kv));
            }
            col
        }
        (EffectParams::ScaleError(s), _) => st.col(|c, i| c.s_chain() * s.value * c.x[i]),
        (EffectParams::CyclicLead(l), _) => st.col(|c, i| c.s_drive() * l.value(c.screw_x(i))),
        (EffectParams::InterpolationError(ie), _) => {
            st.col(|c, i| if c.s_chain() != 0.0 { c.s_chain() * ie.value(table_position(ie, c.x[i])) } else { 0.0 })
        }
        (EffectParams::ThermalExpansion(th), _) => st.col(|c, i| c.s_chain() * th.value(c.x[i], c.t[i])),
        (EffectParams::ThermalDrift(dr), _) => st.col(|c, i| c.s_chain() * dr.value_at(c.t[i])),
        (EffectParams::Coulomb(f), _) => st.col(|c, i| c.s_force() * f.fc * c.v[i].signum()),
        (EffectParams::Viscous(f), _) => st.col(|c, i| c.s_force() * f.fv * c.v[i]),
        (EffectParams::Stribeck(f), _) => {
            // The Coulomb part belongs to the `coulomb` effect unless `fc` is given here.
            let fc = f.fc.unwrap_or(0.0);
            st.col(|c, i| {
                let (v, w) = (c.v[i], stribeck_weight(c.v[i], f.vs, f.shape));
                c.s_force() * v.signum() * (fc * (1.0 - w) + f.fs * w)
            })
        }
        // No known-value column: a squareness needs a chain and LuGre, accel_bias_drift are not among the
        // effects `predicts` lets through; a given resonance or gravity_tilt has linear parts no model
        // states, so `fit_model_fixed` fits them and never asks here. Listed by name so that the
        // compiler names this place for a new effect (issue 12).
        (
            EffectParams::Squareness(_)
            | EffectParams::Lugre(_)
            | EffectParams::Resonance(_)
            | EffectParams::GravityTilt
            | EffectParams::AccelBiasDrift(_),
            _,
        ) => vec![0.0; st.n],
    }
}

/// Log-spaced grid of `n` values from `lo` to `hi`.
pub(crate) fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..n).map(|k| (a + (b - a) * k as f64 / (n - 1).max(1) as f64).exp()).collect()
}

/// Time constants searched per decade ([`tau_range`]).
pub(crate) const TAU_PER_DECADE: f64 = 10.0;

/// The range (s) of a searched time constant: from [`TAU_MIN_INTERVALS`] median sample intervals
/// (a faster process has settled after a few readings: it is a constant, which the offsets and
/// the scale error carry) to [`TAU_MAX_RECORDS`] times the record (a slower one is a straight
/// line in time over the record).
pub(crate) fn tau_range(st: &Stack) -> (f64, f64) {
    let (lo, hi) = st.t_span();
    let span = (hi - lo).max(1.0);
    let mut ts: Vec<f64> = st.chans.iter().flat_map(|c| c.t.iter().copied()).collect();
    ts.sort_by(f64::total_cmp);
    let mut dt: Vec<f64> = ts.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
    dt.sort_by(f64::total_cmp);
    let interval = dt.get(dt.len() / 2).copied().unwrap_or(span / 4.0);
    ((TAU_MIN_INTERVALS * interval).min(span / 4.0), TAU_MAX_RECORDS * span)
}

/// Shortest searched time constant, in median sample intervals ([`tau_range`]).
pub(crate) const TAU_MIN_INTERVALS: f64 = 3.0;
/// Longest searched time constant, in records ([`tau_range`]).
pub(crate) const TAU_MAX_RECORDS: f64 = 30.0;

/// Search grid of a hyper-parameter on these data: time constants over [`tau_range`] on a log
/// grid of [`TAU_PER_DECADE`] per decade; screw leads 2–60 mm; Stribeck velocities and shape
/// exponents; encoder signal periods from the common scale gratings.
pub(crate) fn hyper_grid(st: &Stack, name: EffectName, hyper: Hyper) -> (Vec<f64>, bool) {
    match hyper {
        Hyper::Tau => {
            let (lo, hi) = tau_range(st);
            // index: the log of a ratio of two finite positive f64 is ≤ 616 decades: ≤ 6 161 points.
            let n = ((hi / lo).log10() * TAU_PER_DECADE).ceil().max(2.0) as usize + 1;
            (log_grid(lo, hi, n), true)
        }
        // Stribeck shape exponents δ of lubricated guideways, 0.5–3 (Armstrong-Hélouvry 1994:
        // 0.5–2; δ = 2 the Gaussian law).
        Hyper::Shape => (log_grid(0.5, 3.0, 9), true),
        // A periodic effect's periods ([`catalogue_row`]), only those these positions resolve.
        Hyper::Period => catalogue_row(name).period.map_or((Vec::new(), false), |p| p.search_grid(st)),
        // Position-loop gains of machine tools, 2–500 1/s.
        Hyper::Kv => (log_grid(2.0, 500.0, 41), true),
        // Play of a ball-screw transmission, 0.1–100 µm.
        Hyper::Play => (log_grid(0.1e-6, 100e-6, 31), true),
        // Stribeck velocities of machine-tool guideways: 10 µm/s to 100 mm/s.
        Hyper::Vs => (log_grid(1e-5, 0.1, 41), true),
        // Structural modes of machine-tool columns and frames: 5–200 Hz, capped at 0.4× the slowest
        // accelerometer rate (below Nyquist), in steps of 1 Hz (five points across the 1/0.2 s =
        // 5 Hz resolution of a segment), refined by golden section.
        Hyper::Frequency => {
            let hi = accel_min_rate(st).map_or(200.0, |f| (0.4 * f).min(200.0)).max(6.0);
            // index: hi ≤ 200 Hz (clamped above): ≤ 196 frequencies.
            let n = (hi - 5.0).floor() as usize + 1;
            ((0..n).map(|k| 5.0 + k as f64).collect(), true)
        }
        // Damping ratios of machine-tool structural modes, 0.5–10 % (bolted and welded frames; a
        // column's first bending mode is typically 2–5 %); only the forced response resolves it,
        // so without a predicted excitation it is held at 2 % (not searched).
        Hyper::Damping => {
            if st.excitation.iter().any(|e| !e.is_empty()) {
                (log_grid(0.005, 0.1, 6), true)
            } else {
                (vec![0.02], false)
            }
        }
    }
}

/// The catalogue range (m) of a periodic candidate's period: screw leads, scale signal periods
/// ([`catalogue_row`]).
pub(crate) fn period_range(name: EffectName) -> Option<(f64, f64)> {
    catalogue_row(name).period.map(|p| (p.lo, p.hi))
}

/// The periods of `grid` that the sample positions resolve (never search an alias).
fn resolvable_only(st: &Stack, grid: Vec<f64>) -> Vec<f64> {
    let xs = distinct_positions(st);
    grid.into_iter().filter(|p| resolvable_on(xs, *p)).collect()
}

#[cfg(test)]
mod resolvability_tests {
    use super::resolvable_on;

    /// A regular 5 mm grid over 40 mm resolves periods from 2 × 5 = 10 mm to the 40 mm travel and
    /// none below (every shorter period has an alias above 10 mm); an ISO-style irregular layout with
    /// gaps of 40–60 mm resolves nothing in the cyclic-lead (≤ 60 mm) or interpolation ranges; a
    /// dense run of 1 mm steps over 19 mm added to it resolves 2–19 mm.
    #[test]
    fn periods_resolvable_only_with_two_samples_per_period_over_a_period() {
        let grid: Vec<f64> = (0..9).map(|k| k as f64 * 5e-3).collect();
        assert!(!resolvable_on(&grid, 3.97e-3) && !resolvable_on(&grid, 9.9e-3));
        assert!(resolvable_on(&grid, 10.1e-3) && resolvable_on(&grid, 40e-3) && !resolvable_on(&grid, 41e-3));
        let iso = [0.0, 0.047, 0.101, 0.143, 0.2, 0.259, 0.3];
        assert!(!resolvable_on(&iso, 60e-3) && !resolvable_on(&iso, 20e-6));
        let mut dense: Vec<f64> = iso.to_vec();
        dense.extend((1..20).map(|k| 0.101 + k as f64 * 1e-3));
        dense.sort_by(f64::total_cmp);
        assert!(resolvable_on(&dense, 2.1e-3) && resolvable_on(&dense, 19e-3) && !resolvable_on(&dense, 1.9e-3));
    }
}

/// The cosine series ([`Shape::cosine_basis`]) at one position x of range (a, b): θ = π(x − a)/(b − a),
/// its sine and cosine, and P_3, P_4 with their slopes.
struct CosineAt {
    /// π/(b − a), 1/m: the slope of θ.
    kx: f64,
    /// sin θ, cos θ.
    s1: f64,
    c1: f64,
    /// b − a, m (u = (2x − a − b)/(b − a) has the slope 2/(b − a)).
    span: f64,
    /// P_0..P_4 at u and their slopes in u.
    p: Vec<f64>,
    d: Vec<f64>,
}

impl CosineAt {
    fn new(range: (f64, f64), x: f64) -> CosineAt {
        let (a, b) = range;
        let th = std::f64::consts::PI * (x - a) / (b - a);
        let (p, d) = legendre((2.0 * x - a - b) / (b - a), 4);
        let (s1, c1) = th.sin_cos();
        CosineAt { kx: std::f64::consts::PI / (b - a), s1, c1, span: b - a, p, d }
    }

    /// (value, slope) of basis index k < 3: 1, P_3, P_4.
    fn low(&self, k: usize) -> (f64, f64) {
        match k {
            0 => (1.0, 0.0),
            // index: k is 1 or 2, so k + 2 ≤ 4, the last Legendre order computed.
            _ => (self.p[k + 2], self.d[k + 2] * 2.0 / self.span),
        }
    }

    /// (value, slope) of basis index k ≥ 3, of pair j, from (sin jθ, cos jθ): cos jθ and its
    /// slope −j·kx·sin jθ at even k − 3, sin jθ and j·kx·cos jθ at odd.
    fn pair(&self, k: usize, j: f64, (sm, cm): (f64, f64)) -> (f64, f64) {
        if (k - 3).is_multiple_of(2) {
            (cm, -j * self.kx * sm)
        } else {
            (sm, j * self.kx * cm)
        }
    }

    /// (value, slope) of each of the basis indices `ks` (ascending) in turn, the recurrence
    /// turned only as far as the last: the same bits as [`Shape::cosine_basis`]'s entries.
    fn walk<'k>(&'k self, ks: impl Iterator<Item = usize> + 'k) -> impl Iterator<Item = (f64, f64)> + 'k {
        CosineAt::walk_at([self], ks).map(|[v]| v)
    }

    /// [`CosineAt::walk`] at N positions side by side (one index's (value, slope) at each position
    /// at a time): each position's values the same bits as its walk alone, the N recurrences
    /// independent chains the processor overlaps.
    fn walk_at<'k, const N: usize>(
        ats: [&'k CosineAt; N],
        ks: impl Iterator<Item = usize> + 'k,
    ) -> impl Iterator<Item = [(f64, f64); N]> + 'k {
        // The walk's pair j (its sine and cosine at jθ, at each position).
        let (mut j, mut sc) = (1, ats.map(|a| (a.s1, a.c1)));
        ks.map(move |k| {
            if k < 3 {
                return ats.map(|a| a.low(k));
            }
            let jk = (k - 3) / 2 + 1;
            while j < jk {
                sc = std::array::from_fn(|p| ats[p].turn(sc[p]));
                j += 1;
            }
            std::array::from_fn(|p| ats[p].pair(k, jk as f64, sc[p]))
        })
    }

    /// (sin (j+1)θ, cos (j+1)θ) from (sin jθ, cos jθ) by angle addition.
    fn turn(&self, (sm, cm): (f64, f64)) -> (f64, f64) {
        (sm * self.c1 + cm * self.s1, cm * self.c1 - sm * self.s1)
    }
}

#[cfg(test)]
mod slope_tests {
    use super::{Shape, ShapeBasis};
    use rand::{Rng, SeedableRng};

    /// [`Shape::slope_sum`] gives the same bits as the sum over [`Shape::basis_at`]'s tabulated
    /// slopes, and [`Shape::slopes_at_two`] the same bits as its slopes at each of two positions,
    /// for cosine series (its one-pass recurrence) and Legendre series (tabulated), over 200
    /// random ranges, orders up to 1 200, sparse ascending selections, coefficients and positions.
    #[test]
    fn slope_sum_is_the_tabulated_sum_to_the_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(19);
        for draw in 0..200 {
            let a = rng.gen_range(-0.5..0.2);
            let b = a + rng.gen_range(0.05..1.5);
            let order: u32 = rng.gen_range(3..1200);
            let basis = if draw % 4 == 3 { ShapeBasis::Legendre } else { ShapeBasis::Cosine };
            let order = if basis == ShapeBasis::Legendre { order.min(40) } else { order };
            let sel: Vec<u32> = (1..=order).filter(|_| rng.gen_bool(0.2)).collect();
            let sh = Shape {
                coefs: vec![],
                hypers: vec![],
                first_power: 1,
                order,
                range: (a, b),
                with_fc: false,
                basis,
                select: Some(sel.clone()),
                knots: vec![],
                tilt_orders: vec![],
            };
            let ks = sh.ks();
            let coef: Vec<f64> = ks.iter().map(|_| rng.gen_range(-1e-6..1e-6)).collect();
            for _ in 0..5 {
                let x = rng.gen_range(a..b);
                let (_, d) = sh.basis_at(x);
                let want: f64 = coef.iter().zip(&ks).map(|(c, k)| c * d[*k]).sum();
                let got = sh.slope_sum(x, &ks, &coef);
                assert_eq!(got.to_bits(), want.to_bits(), "draw {draw} x {x}: {got} vs {want}");
                // Two positions walked side by side: each the tabulated slopes, to the bit.
                let x1 = rng.gen_range(a..b);
                let (_, d1) = sh.basis_at(x1);
                let bits = |v: &[f64]| v.iter().map(|s| s.to_bits()).collect::<Vec<u64>>();
                let (s0, s1) = sh.slopes_at_two(x, x1, Some(&ks));
                let picked = |d: &[f64]| ks.iter().map(|&k| d[k]).collect::<Vec<f64>>();
                assert_eq!((bits(&s0), bits(&s1)), (bits(&picked(&d)), bits(&picked(&d1))), "draw {draw}");
                let (a0, a1) = sh.slopes_at_two(x, x1, None);
                assert_eq!((bits(&a0), bits(&a1)), (bits(&d), bits(&d1)), "draw {draw}, every index");
            }
        }
    }
}

#[cfg(test)]
mod step_tests {
    use super::{BaseMap, IntervalMap, MODE_STEP, NEAR_ORDER, NEAR_PHASE, STEP_NEAR};
    use rand::{Rng, SeedableRng};

    /// The largest difference between two interval maps' entries, over the largest entry of `b`
    /// (Φᵐ and the gains each on their own scale).
    fn difference(a: &IntervalMap, b: &IntervalMap) -> f64 {
        let phi = |m: &IntervalMap| m.phi_m.into_iter().flatten().collect::<Vec<f64>>();
        let gains = |m: &IntervalMap| m.gk.iter().flatten().copied().collect::<Vec<f64>>();
        [(phi(a), phi(b)), (gains(a), gains(b))]
            .iter()
            .map(|(x, y)| {
                let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                x.iter().zip(y).fold(0.0f64, |m, (p, q)| m.max((p - q).abs() / scale))
            })
            .fold(0.0, f64::max)
    }

    /// An interval map had from a built one's Taylor tables ([`BaseMap::interval_at`]) is the map
    /// built over its own step (RK4, 10⁻¹⁴): over 500 random modes (1–200 Hz, ζ 0.001–0.3), steps
    /// around [`MODE_STEP`] (0.3–1 ×), 4–4 096 steps per interval (up to [`super::MODE_STEPS_MAX`]: a
    /// gap) and distances up to the tables' reach either way ([`BaseMap::serves`]), Φᵐ and the
    /// gains agree to 10⁻¹² + 10⁻¹⁵·m of their largest entry: RK4's error and the rounding both
    /// carry from m products of 2 × 2 matrices (measured: at most 2·10⁻¹², at m = 3 551, all in
    /// Φᵐ). Tables cut after their first term miss by about (ρmδ)²/2, up to 3·10⁻⁵: they fail.
    #[test]
    fn a_map_had_from_the_tables_is_the_map_built() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(23);
        let (mut worst, mut worst_first) = (0.0f64, 0.0f64);
        for _ in 0..500 {
            let f = 10f64.powf(rng.gen_range(0.0..2.3));
            let zeta = 10f64.powf(rng.gen_range(-3.0..-0.53));
            let h0 = MODE_STEP * rng.gen_range(0.3..1.0);
            let m = 10f64.powf(rng.gen_range(0.6..3.61)).round() as usize;
            let base = BaseMap::new(f, zeta, h0, m);
            let reach = (NEAR_PHASE / (base.rate * m as f64)).min(STEP_NEAR * h0);
            let h = h0 + reach * rng.gen_range(-1.0..1.0);
            assert!(base.serves(h, m));
            let mut built = IntervalMap { h: 0.0, phi_m: [[0.0; 2]; 2], gk: Vec::new() };
            BaseMap::new(f, zeta, h, m).interval_at::<NEAR_ORDER>(h, &mut built);
            let mut had = built.clone();
            base.interval_at::<NEAR_ORDER>(h, &mut had);
            // Relative to the rounding both maps carry: m products of 2 × 2 matrices (10⁻¹⁵ each).
            let carried = 1e-12 + 1e-15 * m as f64;
            worst = worst.max(difference(&had, &built) / carried);
            base.interval_at::<1>(h, &mut had);
            worst_first = worst_first.max(difference(&had, &built) / carried);
        }
        eprintln!(
            "largest difference: {worst:.2} of 1e-12 + 1e-15·m of the largest entry ({worst_first:.2e} with the first term)"
        );
        assert!(worst < 1.0, "largest difference {worst:.2} of the rounding carried");
        assert!(worst_first > 1e3, "the first term alone: {worst_first:.2e} of the rounding carried");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Legendre series' value columns order by order over blocks of samples
    /// ([`legendre_value_block`], through `columns`) are the bits of [`Shape::terms_at`] sample by
    /// sample times the reading's sensitivity: two encoder channels (transmission and following,
    /// 2 500 and 1 300 samples: several blocks, one short), order 40 and a selection of orders
    /// (1, 2, 7, 33, 40).
    #[test]
    fn legendre_value_columns_by_blocks_are_the_bits_of_terms_at() {
        let chan = |n: usize, role: EncoderRole| {
            let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
            Channel {
                run: "r".into(),
                sensor: "s".into(),
                kind: SensorKind::EncoderLinear,
                u: [1.0, 0.0, 0.0],
                r: [0.0; 3],
                x: t.iter().map(|t| 0.013 + 0.2 * (0.7 * t).sin()).collect(),
                d: vec![1.0; n],
                cycle: vec![1; n],
                v: vec![0.05; n],
                y: vec![0.0; n],
                sigma: None,
                encoder: Some(role),
                t,
            }
        };
        let following = EncoderRole::Following {
            command: vec![0.0; 1300],
            command_sigma: Vec::new(),
            s_transmission: -1.0,
            closed: false,
        };
        let chans = vec![chan(2500, EncoderRole::Transmission { drive: vec![0.0; 2500] }), chan(1300, following)];
        let st = Stack::new(&chans);
        let whole = shape(&st, EffectName::Positioning, 1, 40, false);
        for sh in [whole.clone(), whole.selected(vec![1, 2, 7, 33, 40])] {
            let ks = sh.ks();
            let cols = open_loop_columns(&st, EffectName::Positioning, &sh, &[]);
            let mut at = 0;
            for c in &chans {
                let s = c.s_motion(EffectName::Positioning);
                for i in 0..c.y.len() {
                    let (p, _) = sh.terms_at(c.x[i], &ks);
                    for (j, pk) in p.iter().enumerate() {
                        assert_eq!(cols[j][at].to_bits(), (s * pk).to_bits(), "sample {at}, index {}", ks[j]);
                    }
                    at += 1;
                }
            }
        }
    }

    /// Every term of [`reduced_sin_cos`] is within 2·10⁻¹¹ of libm's `sin_cos` on positions and
    /// periods spread over the ranges a scan meets (θ up to 7·10⁵ rad, both signs), and the sums of
    /// [`phase_sums_fast`] within [`PHASE_SUMS_BOUND`] per position of libm's (500 positions, 200
    /// periods from 2 µm to 20 mm); beyond [`PHASE_FAST_MAX`] the fast sums are refused.
    #[test]
    fn fast_phase_sums_agree_with_libm() {
        let mut worst = 0.0_f64;
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut uniform = || rng.gen::<f64>();
        for _ in 0..200 {
            let p = 2e-6 * (1e4_f64).powf(uniform());
            let span = (PHASE_FAST_MAX * p / TWO_PI).min(2.0);
            let xs: Vec<f64> = (0..500).map(|_| (uniform() - 0.3) * span).collect();
            let (sa, ca, qa) = phase_sums_fast(&xs, p).expect("within range");
            let (mut sb, mut cb, mut qb) = (0.0, 0.0, 0.0);
            for x in &xs {
                let theta = TWO_PI * x / p;
                let (s, c) = reduced_sin_cos(theta);
                let (sl, cl) = theta.sin_cos();
                worst = worst.max((s - sl).abs()).max((c - cl).abs());
                sb += sl;
                cb += cl;
                qb += sl * sl;
            }
            let m = xs.len() as f64;
            for (fast, exact) in [(sa, sb), (ca, cb), (qa, qb)] {
                assert!((fast - exact).abs() <= PHASE_SUMS_BOUND * m, "{fast} vs {exact}");
            }
        }
        assert!(worst <= 2e-11, "largest term difference {worst:e}");
        assert!(phase_sums_fast(&[0.0, 1.0], 1e-6).is_none());
    }
}
