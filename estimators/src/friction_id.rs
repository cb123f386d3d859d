//! Friction identification (DESIGN.md §7): Stribeck parameters by nonlinear least squares from a
//! friction sweep or from a move with known mass, and the static LuGre parameters where the data
//! allow.
//!
//! Models (forces in N, velocities in m/s), both odd in v:
//! - [`StribeckShape::Exponential`] (Armstrong-Hélouvry; the LuGre steady state of Canudas de Wit
//!   et al. 1995 with δ = 2): F = sgn(v)·[Fc + (Fs − Fc)·exp(−|v/vs|^δ)] + Fv·v;
//! - [`StribeckShape::Mnich`], the shape of K. Mnich's rack-and-pinion identification
//!   (github KonradMnich/friction-identification, `friction_model.m`):
//!   F = sgn(v)·[Fc + |v|·(Fs − Fc)·e/vs·exp(−|v|/vs)] + Fv·v. Here F(0⁺) = Fc and the dry part
//!   peaks at |v| = vs with value Fs (so Fs is the author's "Fmax" c3, Fc his "dry" c1, Fv his c2,
//!   vs his c4). It is a different curve from the exponential one: friction RISES from Fc to a
//!   peak instead of falling from Fs.
//!
//! Fit: the model is linear in (Fc, Fs, Fv) for fixed (vs, δ), so the start values come from a grid
//! over (vs, δ) with a linear least-squares solve at each node (variable projection); then a
//! box-constrained Levenberg–Marquardt (Marquardt 1963, column-scaled, bound-active parameters held)
//! polishes all parameters. Standard errors from the Jacobian at the solution:
//! cov = s²·(JᵀJ)⁻¹, s² = Σr²/(n − p) over the free parameters (those not on a bound).
//! Both directions: one symmetric parameter set for the odd model ([`SweepDirection::Both`]), or one
//! direction only ([`SweepDirection::Positive`] / [`SweepDirection::Negative`]): call twice to get
//! the two branches of an asymmetric axis.
//!
//! LuGre (Canudas de Wit et al. 1995): its static parameters are the exponential Stribeck fit
//! (Fc, Fs, vs, δ, and σ2 = Fv) plus the bristle stiffness σ0, which needs a pre-sliding segment
//! (force rising at µm displacements before break-away): [`lugre_sigma0_from_presliding`], which
//! says `NotIdentifiable` when the data hold no such segment. σ1 (micro-damping) needs dynamic
//! pre-sliding data and is not identified here.

use faer::Mat;
use serde::{Deserialize, Serialize};

/// The Stribeck coefficients Fc (N), Fs (N), vs (m/s), δ (–), Fv (N·s/m) that [`fit_stribeck`] fits: vmt's
/// one friction law (crate `vmt-core`, which the simulator integrates too). For [`StribeckShape::Mnich`]
/// Fs is the peak of the dry part (at |v| = vs) and δ is unused (reported as 1).
pub use vmt_core::friction::StribeckLaw;

/// Errors of the friction identification.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrictionIdError {
    /// Input arrays or options are malformed.
    #[error("friction identification: {0}")]
    BadInput(String),
    /// The data do not determine the requested parameter.
    #[error("friction identification: not identifiable: {0}")]
    NotIdentifiable(String),
}

fn bad<T>(msg: String) -> Result<T, FrictionIdError> {
    Err(FrictionIdError::BadInput(msg))
}

fn check_series(name: &str, x: &[f64], min_len: usize) -> Result<(), FrictionIdError> {
    if x.len() < min_len {
        return bad(format!("{name} needs at least {min_len} samples, got {}", x.len()));
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return bad(format!("{name} must be finite, got {} at index {i}", x[i]));
    }
    Ok(())
}

fn check_pos(name: &str, x: f64) -> Result<(), FrictionIdError> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        bad(format!("{name} must be finite and > 0, got {x}"))
    }
}

/// Shape of the Stribeck part of the friction curve (see the module doc for the equations).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum StribeckShape {
    /// F = sgn(v)·[Fc + (Fs − Fc)·exp(−|v/vs|^δ)] + Fv·v (DESIGN.md §4).
    Exponential,
    /// F = sgn(v)·[Fc + |v|·(Fs − Fc)·e/vs·exp(−|v|/vs)] + Fv·v (K. Mnich, rack-and-pinion data);
    /// δ is not used.
    Mnich,
}

/// Which samples of a sweep are fitted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum SweepDirection {
    /// All samples, one parameter set for the odd model F(−v) = −F(v).
    Both,
    /// Only v > 0.
    Positive,
    /// Only v < 0 (parameters describe the magnitude of the negative branch).
    Negative,
}

const NAMES: [&str; 5] = vmt_core::friction::PARAMETER_NAMES;

/// Standard errors of [`StribeckLaw`] (same units); `None` for a parameter that was held
/// fixed or ended on a bound (its uncertainty is not given by the Jacobian).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StribeckStdErrors {
    /// σ(Fc), N.
    pub fc: Option<f64>,
    /// σ(Fs), N.
    pub fs: Option<f64>,
    /// σ(vs), m/s.
    pub vs: Option<f64>,
    /// σ(δ).
    pub delta: Option<f64>,
    /// σ(Fv), N·s/m.
    pub fv: Option<f64>,
}

/// Options of [`fit_stribeck`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StribeckFitOptions {
    /// Curve shape.
    pub shape: StribeckShape,
    /// Which samples are used.
    pub direction: SweepDirection,
    /// Hold δ at this value (Exponential only); `None` fits δ.
    pub fixed_delta: Option<f64>,
    /// Lower bounds (default: Fc, Fs, Fv ≥ 0; vs ≥ 1e-9 m/s; δ ≥ 0.2).
    pub lower: StribeckLaw,
    /// Upper bounds (default: none except δ ≤ 5).
    pub upper: StribeckLaw,
    /// Maximum Levenberg–Marquardt iterations (default 200).
    pub max_iterations: usize,
}

impl Default for StribeckFitOptions {
    fn default() -> Self {
        StribeckFitOptions {
            shape: StribeckShape::Exponential,
            direction: SweepDirection::Both,
            fixed_delta: None,
            lower: StribeckLaw { fc: 0.0, fs: 0.0, vs: 1e-9, delta: 0.2, fv: 0.0 },
            upper: StribeckLaw {
                fc: f64::INFINITY,
                fs: f64::INFINITY,
                vs: f64::INFINITY,
                delta: 5.0,
                fv: f64::INFINITY,
            },
            max_iterations: 200,
        }
    }
}

/// Result of [`fit_stribeck`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StribeckFit {
    /// Shape fitted.
    pub shape: StribeckShape,
    /// Samples used.
    pub direction: SweepDirection,
    /// Estimated coefficients.
    pub coefficients: StribeckLaw,
    /// Standard errors from the Jacobian at the solution.
    pub std_errors: StribeckStdErrors,
    /// Names of the parameters that ended on a bound.
    pub at_bound: Vec<String>,
    /// Residual RMS, N: √(Σ(F − F̂)²/n).
    pub residual_rms: f64,
    /// Number of samples used.
    pub n_points: usize,
    /// Levenberg–Marquardt iterations taken.
    pub iterations: usize,
    /// True if the iteration stopped on its tolerance rather than the iteration limit.
    pub converged: bool,
}

/// The friction curve F(v), N, of the given shape at velocity v (m/s) (equations in the module
/// doc). F(0) = 0 (the static force at rest is undetermined in [−Fs, Fs]).
pub fn stribeck_curve(shape: StribeckShape, c: &StribeckLaw, v: f64) -> f64 {
    model(shape, &c.to_array(), v, None)
}

/// Model value and (optionally) its gradient in θ = [fc, fs, vs, δ, fv].
fn model(shape: StribeckShape, th: &[f64; 5], v: f64, grad: Option<&mut [f64; 5]>) -> f64 {
    match shape {
        StribeckShape::Exponential => {
            let (f, g) = StribeckLaw::from_array(*th).force_and_gradient(v);
            if let Some(out) = grad {
                *out = g;
            }
            f
        }
        StribeckShape::Mnich => {
            let [fc, fs, vs, _, fv] = *th;
            let s = vmt_core::friction::sign(v);
            let u = v.abs() / vs;
            let eu = (-u).exp();
            let w = std::f64::consts::E * u * eu;
            if let Some(g) = grad {
                g[0] = s * (1.0 - w);
                g[1] = s * w;
                g[2] = s * (fs - fc) * std::f64::consts::E * eu * u * (u - 1.0) / vs;
                g[3] = 0.0;
                g[4] = v;
            }
            s * (fc + (fs - fc) * w) + fv * v
        }
    }
}

fn sse(shape: StribeckShape, th: &[f64; 5], v: &[f64], f: &[f64]) -> f64 {
    v.iter()
        .zip(f)
        .map(|(&vi, &fi)| {
            let r = model(shape, th, vi, None) - fi;
            r * r
        })
        .sum()
}

/// (U, singular values, V) of a thin SVD.
type ThinSvd = (Mat<f64>, Vec<f64>, Mat<f64>);

/// Thin SVD of an n×p matrix (p ≤ 5): returns (U, singular values, V).
fn svd(a: &Mat<f64>) -> Result<ThinSvd, FrictionIdError> {
    let s = a.thin_svd().map_err(|e| FrictionIdError::BadInput(format!("SVD did not converge: {e:?}")))?;
    let sv: Vec<f64> = (0..a.ncols()).map(|i| s.S()[i]).collect();
    Ok((s.U().to_owned(), sv, s.V().to_owned()))
}

/// Linear least squares min‖A x − b‖ via the thin SVD (pseudo-inverse, tiny singular values
/// dropped); returns (x, Σ residual²).
fn linear_lstsq(a: &Mat<f64>, b: &[f64]) -> Result<(Vec<f64>, f64), FrictionIdError> {
    let (u, s, vm) = svd(a)?;
    let p = a.ncols();
    let smax = s.iter().cloned().fold(0.0, f64::max);
    let mut x = vec![0.0; p];
    for k in 0..p {
        if s[k] <= 1e-12 * smax || s[k] == 0.0 {
            continue;
        }
        let utb: f64 = (0..a.nrows()).map(|i| u[(i, k)] * b[i]).sum();
        for (j, xj) in x.iter_mut().enumerate() {
            *xj += vm[(j, k)] * utb / s[k];
        }
    }
    let r2 = (0..a.nrows())
        .map(|i| {
            let r: f64 = (0..p).map(|j| a[(i, j)] * x[j]).sum::<f64>() - b[i];
            r * r
        })
        .sum();
    Ok((x, r2))
}

/// Fits the Stribeck curve to pairs (v, F) (m/s, N) — a friction sweep (constant velocities over
/// decades, both directions) or the (v, F_friction) pairs of a move ([`friction_from_motion`]) —
/// by bounded nonlinear least squares (module doc: variable-projection grid start, then
/// Levenberg–Marquardt). Velocities must be nonzero (friction at rest is undetermined in
/// [−Fs, Fs]). Returns coefficients, standard errors (Jacobian at the solution) and residual RMS.
///
/// # Example
///
/// A velocity sweep of ±0.5 … ±50 mm/s whose friction force follows the exponential law exactly: the
/// fit returns the coefficients it was made with.
///
/// ```rust
/// use vmt_estimators::friction_id::{fit_stribeck, stribeck_curve, StribeckLaw, StribeckFitOptions, StribeckShape};
/// // Fc, Fs (N), vs (m/s), δ, Fv (N·s/m)
/// let truth = StribeckLaw { fc: 10.0, fs: 15.0, vs: 5e-3, delta: 1.0, fv: 40.0 };
/// let v: Vec<f64> = (1..=100).flat_map(|k| [5e-4 * k as f64, -5e-4 * k as f64]).collect(); // m/s
/// let f: Vec<f64> = v.iter().map(|&v| stribeck_curve(StribeckShape::Exponential, &truth, v)).collect(); // N
/// let fit = fit_stribeck(&v, &f, &StribeckFitOptions::default()).unwrap();
/// let c = fit.coefficients;
/// assert!((c.fc - 10.0).abs() < 1e-3 && (c.fs - 15.0).abs() < 1e-3 && (c.fv - 40.0).abs() < 1e-2);
/// assert!((c.vs - 5e-3).abs() < 1e-6 && fit.residual_rms < 1e-6);
/// ```
pub fn fit_stribeck(v: &[f64], f: &[f64], opts: &StribeckFitOptions) -> Result<StribeckFit, FrictionIdError> {
    if v.len() != f.len() {
        return bad(format!("v and F must have the same length, got {} and {}", v.len(), f.len()));
    }
    check_series("v", v, 1)?;
    check_series("F", f, 1)?;
    let lo = opts.lower.to_array();
    let hi = opts.upper.to_array();
    for k in 0..5 {
        if lo[k].is_nan() || hi[k].is_nan() || lo[k] > hi[k] {
            return bad(format!("bounds of {} must satisfy lower <= upper, got [{}, {}]", NAMES[k], lo[k], hi[k]));
        }
    }
    if lo[2] <= 0.0 {
        return bad(format!("lower bound of vs must be > 0, got {}", lo[2]));
    }
    if let Some(d) = opts.fixed_delta {
        check_pos("fixed_delta", d)?;
    }
    if let Some(i) = v.iter().position(|&x| x == 0.0) {
        return bad(format!("velocities must be nonzero (friction at rest is undetermined), got 0 at index {i}"));
    }
    let keep = |x: f64| match opts.direction {
        SweepDirection::Both => true,
        SweepDirection::Positive => x > 0.0,
        SweepDirection::Negative => x < 0.0,
    };
    let (vv, ff): (Vec<f64>, Vec<f64>) = v.iter().zip(f).filter(|(x, _)| keep(**x)).map(|(a, b)| (*a, *b)).unzip();
    // Free parameters.
    let mut free = [true; 5];
    let delta_fixed = match (opts.shape, opts.fixed_delta) {
        (StribeckShape::Mnich, _) => Some(1.0),
        (StribeckShape::Exponential, d) => d,
    };
    if delta_fixed.is_some() {
        free[3] = false;
    }
    for k in 0..5 {
        if lo[k] == hi[k] {
            free[k] = false;
        }
    }
    let p_free = free.iter().filter(|x| **x).count();
    if vv.len() <= p_free {
        return bad(format!(
            "need more samples than free parameters ({p_free}) in direction {:?}, got {}",
            opts.direction,
            vv.len()
        ));
    }
    let n = vv.len();
    let vmin = vv.iter().map(|x| x.abs()).fold(f64::INFINITY, f64::min);
    let vmax = vv.iter().map(|x| x.abs()).fold(0.0, f64::max);

    // --- Start: grid over (vs, δ), linear LS in (Fc, Fs, Fv). ---
    let deltas: Vec<f64> = match delta_fixed {
        Some(d) => vec![d],
        None => vec![0.5, 0.75, 1.0, 1.5, 2.0, 3.0],
    };
    let n_vs = 41;
    let (l0, l1) = ((vmin / 3.0).ln(), (vmax * 3.0).ln());
    let mut best: Option<(f64, [f64; 5])> = None;
    for i in 0..n_vs {
        let vs = (l0 + (l1 - l0) * i as f64 / (n_vs - 1) as f64).exp();
        for &d in &deltas {
            let mut a = Mat::<f64>::zeros(n, 3);
            let mut g = [0.0; 5];
            let th = [0.0, 0.0, vs, d, 0.0];
            for (r, &x) in vv.iter().enumerate() {
                model(opts.shape, &th, x, Some(&mut g));
                a[(r, 0)] = g[0];
                a[(r, 1)] = g[1];
                a[(r, 2)] = g[4];
            }
            let (x, _) = linear_lstsq(&a, &ff)?;
            let mut th = [x[0], x[1], vs, d, x[2]];
            for k in 0..5 {
                if !free[k] && k != 3 {
                    th[k] = lo[k];
                }
                // clamp: lo[k] ≤ hi[k], neither NaN (checked at the top of fit_stribeck).
                th[k] = th[k].clamp(lo[k], hi[k]);
            }
            if let Some(dfix) = delta_fixed {
                th[3] = dfix;
            }
            let c = sse(opts.shape, &th, &vv, &ff);
            if best.is_none_or(|(b, _)| c < b) {
                best = Some((c, th));
            }
        }
    }
    let (mut cost, mut th) = best.expect("grid is not empty");

    // --- Box-constrained Levenberg–Marquardt. ---
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut converged = false;
    let mut g = [0.0; 5];
    let jac = |th: &[f64; 5], g: &mut [f64; 5]| -> (Vec<[f64; 5]>, Vec<f64>) {
        let mut rows = Vec::with_capacity(n);
        let mut res = Vec::with_capacity(n);
        for (&x, &y) in vv.iter().zip(&ff) {
            let m = model(opts.shape, th, x, Some(g));
            rows.push(*g);
            res.push(m - y);
        }
        (rows, res)
    };
    while iterations < opts.max_iterations {
        iterations += 1;
        let (rows, res) = jac(&th, &mut g);
        // Gradient of ½Σr²: Jᵀr; hold parameters on a bound whose descent points outward.
        let mut act = Vec::new();
        for k in 0..5 {
            if !free[k] {
                continue;
            }
            let grad: f64 = rows.iter().zip(&res).map(|(j, r)| j[k] * r).sum();
            let at_lo = th[k] <= lo[k] && grad > 0.0;
            let at_hi = th[k] >= hi[k] && grad < 0.0;
            if !(at_lo || at_hi) {
                act.push(k);
            }
        }
        if act.is_empty() {
            converged = true;
            break;
        }
        let mut a = Mat::<f64>::zeros(n, act.len());
        let mut scale = vec![0.0; act.len()];
        for (c, &k) in act.iter().enumerate() {
            let nrm = rows.iter().map(|j| j[k] * j[k]).sum::<f64>().sqrt();
            scale[c] = if nrm > 0.0 { nrm } else { 1.0 };
            for (r, j) in rows.iter().enumerate() {
                a[(r, c)] = j[k] / scale[c];
            }
        }
        let (u, s, vm) = svd(&a)?;
        let utr: Vec<f64> = (0..act.len()).map(|k| (0..n).map(|i| u[(i, k)] * res[i]).sum()).collect();
        let mut improved = false;
        while lambda < 1e16 {
            let mut step = vec![0.0; act.len()];
            for k in 0..act.len() {
                let w = s[k] / (s[k] * s[k] + lambda);
                for (j, sj) in step.iter_mut().enumerate() {
                    *sj -= vm[(j, k)] * w * utr[k];
                }
            }
            let mut cand = th;
            for (c, &k) in act.iter().enumerate() {
                // clamp: lo[k] ≤ hi[k], neither NaN (checked at the top of fit_stribeck).
                cand[k] = (th[k] + step[c] / scale[c]).clamp(lo[k], hi[k]);
            }
            let c_new = sse(opts.shape, &cand, &vv, &ff);
            if c_new < cost {
                let rel = (cost - c_new) / cost.max(f64::MIN_POSITIVE);
                let moved = act.iter().map(|&k| ((cand[k] - th[k]) / th[k].abs().max(1e-12)).abs()).fold(0.0, f64::max);
                th = cand;
                cost = c_new;
                lambda = (lambda / 3.0).max(1e-12);
                improved = true;
                if rel < 1e-14 || moved < 1e-12 {
                    converged = true;
                }
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            // No decrease at any damping: a (bound-constrained) minimum to machine precision.
            converged = true;
        }
        if converged {
            break;
        }
    }

    // --- Standard errors at the solution. ---
    let (rows, res) = jac(&th, &mut g);
    let mut at_bound = Vec::new();
    let mut est: Vec<usize> = Vec::new();
    for k in 0..5 {
        if !free[k] {
            continue;
        }
        if th[k] <= lo[k] || th[k] >= hi[k] {
            at_bound.push(NAMES[k].to_string());
        } else {
            est.push(k);
        }
    }
    let mut se = [None; 5];
    let dof = n - est.len();
    if !est.is_empty() && dof > 0 {
        let s2 = cost / dof as f64;
        let mut a = Mat::<f64>::zeros(n, est.len());
        let mut scale = vec![0.0; est.len()];
        for (c, &k) in est.iter().enumerate() {
            let nrm = rows.iter().map(|j| j[k] * j[k]).sum::<f64>().sqrt();
            scale[c] = if nrm > 0.0 { nrm } else { 1.0 };
            for (r, j) in rows.iter().enumerate() {
                a[(r, c)] = j[k] / scale[c];
            }
        }
        let (_, s, vm) = svd(&a)?;
        let smax = s.iter().cloned().fold(0.0, f64::max);
        if s.iter().all(|&x| x > 1e-12 * smax) {
            for (c, &k) in est.iter().enumerate() {
                let var: f64 = (0..est.len()).map(|m| (vm[(c, m)] / s[m]).powi(2)).sum::<f64>() * s2;
                se[k] = Some(var.sqrt() / scale[c]);
            }
        }
    }
    let _ = res;
    let mut coeffs = StribeckLaw::from_array(th);
    if opts.shape == StribeckShape::Mnich {
        coeffs.delta = 1.0;
    }
    Ok(StribeckFit {
        shape: opts.shape,
        direction: opts.direction,
        coefficients: coeffs,
        std_errors: StribeckStdErrors { fc: se[0], fs: se[1], vs: se[2], delta: se[3], fv: se[4] },
        at_bound,
        residual_rms: (cost / n as f64).sqrt(),
        n_points: n,
        iterations,
        converged,
    })
}

/// Causal or zero-phase application of a filter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum FilterMode {
    /// One forward pass (delays the signal; what a real-time controller or MATLAB `filter` does).
    Causal,
    /// Forward and backward pass (scipy `filtfilt` / MATLAB `filtfilt`): no phase lag, squared
    /// magnitude response (−6 dB at the cutoff), order doubled.
    ZeroPhase,
}

/// Second-order Butterworth low-pass, cutoff `cutoff_hz` (Hz), sample interval dt (s), designed by
/// the bilinear transform with frequency pre-warping (K = tan(π·fc·dt)):
/// b = [K², 2K², K²]/(1 + √2K + K²), a = [1, 2(K² − 1), 1 − √2K + K²]/(1 + √2K + K²),
/// `y[n] = b0·x[n] + b1·x[n−1] + b2·x[n−2] − a1·y[n−1] − a2·y[n−2]`.
/// The filter starts in the steady state of the first sample (no start-up transient for a signal
/// that starts constant). `ZeroPhase` runs it forward then backward over the signal extended at
/// both ends by odd reflection (as scipy `filtfilt`) by one cutoff period (at most n − 1 samples).
/// Needs cutoff < Nyquist (fc·dt < 0.5) and at least 3 samples.
pub fn butterworth2_lowpass(x: &[f64], dt: f64, cutoff_hz: f64, mode: FilterMode) -> Result<Vec<f64>, FrictionIdError> {
    check_series("signal", x, 3)?;
    check_pos("dt", dt)?;
    check_pos("cutoff_hz", cutoff_hz)?;
    if cutoff_hz * dt >= 0.5 {
        return bad(format!("cutoff must be below the Nyquist frequency {} Hz, got {cutoff_hz} Hz", 0.5 / dt));
    }
    let k = (std::f64::consts::PI * cutoff_hz * dt).tan();
    let sq2 = std::f64::consts::SQRT_2;
    let norm = 1.0 / (1.0 + sq2 * k + k * k);
    let b0 = k * k * norm;
    let (b1, b2) = (2.0 * b0, b0);
    let a1 = 2.0 * (k * k - 1.0) * norm;
    let a2 = (1.0 - sq2 * k + k * k) * norm;
    // Direct form II transposed with steady-state initial conditions for input x0:
    // y = x0 (DC gain 1), s1 = y − b0·x0, s2 = b2·x0 − a2·y.
    let run = |sig: &[f64]| -> Vec<f64> {
        let x0 = sig[0];
        let mut s2 = b2 * x0 - a2 * x0;
        let mut s1 = x0 - b0 * x0;
        sig.iter()
            .map(|&xi| {
                let y = b0 * xi + s1;
                s1 = b1 * xi - a1 * y + s2;
                s2 = b2 * xi - a2 * y;
                y
            })
            .collect()
    };
    match mode {
        FilterMode::Causal => Ok(run(x)),
        FilterMode::ZeroPhase => {
            let n = x.len();
            // clamp: n ≥ 3 (check_series above), so 1 ≤ n − 1.
            // index: the clamp keeps the pad in 1..=n − 1 whatever the cast gives (n ≥ 3).
            let pad = ((1.0 / (cutoff_hz * dt)).ceil() as usize).clamp(1, n - 1);
            let mut ext = Vec::with_capacity(n + 2 * pad);
            for i in (1..=pad).rev() {
                ext.push(2.0 * x[0] - x[i]);
            }
            ext.extend_from_slice(x);
            for i in 1..=pad {
                ext.push(2.0 * x[n - 1] - x[n - 1 - i]);
            }
            let mut y = run(&ext);
            y.reverse();
            let mut y = run(&y);
            y.reverse();
            Ok(y[pad..pad + n].to_vec())
        }
    }
}

/// Derivative of a uniformly sampled signal (interval dt, s) by central differences,
/// `d[i] = (x[i+1] − x[i−1])/(2·dt)`, and second-order one-sided differences at the ends,
/// `d[0] = (−3x0 + 4x1 − x2)/(2dt)`, `d[n−1] = (3x[n−1] − 4x[n−2] + x[n−3])/(2dt)`: exact for
/// quadratics. Needs at least 3 samples.
pub fn central_difference(x: &[f64], dt: f64) -> Result<Vec<f64>, FrictionIdError> {
    check_series("signal", x, 3)?;
    check_pos("dt", dt)?;
    let n = x.len();
    let h = 2.0 * dt;
    let mut d = Vec::with_capacity(n);
    d.push((-3.0 * x[0] + 4.0 * x[1] - x[2]) / h);
    for i in 1..n - 1 {
        d.push((x[i + 1] - x[i - 1]) / h);
    }
    d.push((3.0 * x[n - 1] - 4.0 * x[n - 2] + x[n - 3]) / h);
    Ok(d)
}

/// Friction extracted from a move with known mass (the rigid-body balance along the axis):
/// F_friction = F − m·a, with v and F low-passed by the same filter and a = dv/dt by central
/// differences of the filtered velocity.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MotionFriction {
    /// Filtered velocity, m/s.
    pub v: Vec<f64>,
    /// Acceleration of the filtered velocity, m/s².
    pub a: Vec<f64>,
    /// Filtered drive force, N.
    pub force: Vec<f64>,
    /// Friction force F − m·a, N (positive opposing positive motion).
    pub friction: Vec<f64>,
}

/// Preprocesses a move with known mass `mass` (kg): velocity v (m/s) and drive force F (N) sampled
/// every dt (s) → filtered v, a = dv/dt, and F_friction = F − m·a (DESIGN.md §7). Both signals go
/// through the same 2nd-order Butterworth low-pass ([`butterworth2_lowpass`], cutoff `cutoff_hz`,
/// causal or zero-phase) so their delays match; `None` skips filtering. Select the window to fit
/// (e.g. the constant-acceleration phase) and pass (v, friction) to [`fit_stribeck`].
pub fn friction_from_motion(
    v: &[f64],
    force: &[f64],
    mass: f64,
    dt: f64,
    cutoff_hz: Option<f64>,
    mode: FilterMode,
) -> Result<MotionFriction, FrictionIdError> {
    if v.len() != force.len() {
        return bad(format!("v and F must have the same length, got {} and {}", v.len(), force.len()));
    }
    check_series("v", v, 3)?;
    check_series("F", force, 3)?;
    check_pos("mass", mass)?;
    check_pos("dt", dt)?;
    let (vf, ff) = match cutoff_hz {
        Some(fc) => (butterworth2_lowpass(v, dt, fc, mode)?, butterworth2_lowpass(force, dt, fc, mode)?),
        None => (v.to_vec(), force.to_vec()),
    };
    let a = central_difference(&vf, dt)?;
    let friction = ff.iter().zip(&a).map(|(f, ai)| f - mass * ai).collect();
    Ok(MotionFriction { v: vf, a, force: ff, friction })
}

/// LuGre bristle stiffness σ0 from a pre-sliding (break-away) segment.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Sigma0Fit {
    /// σ0, N/m.
    pub sigma0: f64,
    /// Standard error of σ0, N/m.
    pub sigma0_se: f64,
    /// Samples used (|F − F0| ≤ 0.5·Fs before the first exceedance).
    pub n_points: usize,
    /// Residual RMS of the linearised fit, N.
    pub residual_rms: f64,
}

/// σ0 (N/m) of the LuGre model from displacement x (m) and friction force F (N) recorded from rest
/// up to break-away (Canudas de Wit et al. 1995: at |v| ≪ vs, g ≈ Fs and σ1·dz/dt is small, so
/// dF/dx = σ0·(1 − F/Fs), i.e. F = Fs·(1 − exp(−σ0·(x − x0)/Fs)) for a monotone ramp from rest).
/// Linearised: y = −Fs·ln(1 − (F − F0)/Fs) = σ0·(x − x0), fitted with an intercept by least squares
/// on the samples from the start until |F − F0| first exceeds Fs/2 (`F0 = F[0]`, the force at rest).
/// Pass only the stick segment: from rest up to the break-away (before gross sliding is detected).
/// `fs` (N) is the static level from a Stribeck fit. Returns `NotIdentifiable` if fewer than 5
/// samples qualify, if the force rises by less than 10 % of Fs over them (no pre-sliding ramp in
/// the data), or if the displacement does not change over them (e.g. an encoder that does not
/// resolve the pre-sliding motion of a few µm).
pub fn lugre_sigma0_from_presliding(x: &[f64], f: &[f64], fs: f64) -> Result<Sigma0Fit, FrictionIdError> {
    if x.len() != f.len() {
        return bad(format!("x and F must have the same length, got {} and {}", x.len(), f.len()));
    }
    check_series("x", x, 2)?;
    check_series("F", f, 2)?;
    check_pos("fs", fs)?;
    let f0 = f[0];
    let end = f.iter().position(|fi| (fi - f0).abs() > 0.5 * fs).unwrap_or(f.len());
    if end < 5 {
        return Err(FrictionIdError::NotIdentifiable(format!(
            "sigma0 needs >= 5 samples of pre-sliding (|F - F0| <= Fs/2) before break-away, got {end}"
        )));
    }
    let f_span = f[..end].iter().map(|fi| (fi - f0).abs()).fold(0.0, f64::max);
    if f_span < 0.1 * fs {
        return Err(FrictionIdError::NotIdentifiable(format!(
            "sigma0: the force changes by only {f_span:.3} N (< 10 % of Fs = {fs} N) over the {end} samples given: no pre-sliding ramp before break-away in the data"
        )));
    }
    let xs = &x[..end];
    let ys: Vec<f64> = f[..end]
        .iter()
        .map(|fi| {
            let df = (fi - f0).abs();
            -fs * (1.0 - df / fs).ln() * (fi - f0).signum()
        })
        .collect();
    let xr = xs.iter().cloned().fold(f64::MIN, f64::max) - xs.iter().cloned().fold(f64::MAX, f64::min);
    if xr <= 0.0 {
        return Err(FrictionIdError::NotIdentifiable(format!(
            "sigma0: the displacement does not change over the {end} pre-sliding samples (force rose by up to {:.3} N at constant x): the position sensor does not resolve pre-sliding",
            f[..end].iter().map(|fi| (fi - f0).abs()).fold(0.0, f64::max)
        )));
    }
    let n = end as f64;
    let mx = xs.iter().sum::<f64>() / n;
    let my = ys.iter().sum::<f64>() / n;
    let sxx: f64 = xs.iter().map(|xi| (xi - mx).powi(2)).sum();
    let sxy: f64 = xs.iter().zip(&ys).map(|(xi, yi)| (xi - mx) * (yi - my)).sum();
    let slope = sxy / sxx;
    let ssr: f64 = xs.iter().zip(&ys).map(|(xi, yi)| (yi - my - slope * (xi - mx)).powi(2)).sum();
    let s2 = if end > 2 { ssr / (n - 2.0) } else { 0.0 };
    Ok(Sigma0Fit { sigma0: slope, sigma0_se: (s2 / sxx).sqrt(), n_points: end, residual_rms: (ssr / n).sqrt() })
}

#[cfg(test)]
mod tests {
    use super::*;

    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// A friction sweep: 6 speeds per decade from 1e-5 to 0.3 m/s, both directions, each point the
    /// mean force of one constant-velocity segment with N(0, σ²) noise.
    fn synthetic_sweep(truth: &StribeckLaw, sigma: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        let mut v = Vec::new();
        let mut f = Vec::new();
        let n = (6.0 * (0.3f64 / 1e-5).log10()).round() as usize;
        for i in 0..=n {
            let speed = 1e-5 * (0.3f64 / 1e-5).powf(i as f64 / n as f64);
            for dir in [1.0, -1.0] {
                let x = dir * speed;
                v.push(x);
                f.push(stribeck_curve(StribeckShape::Exponential, truth, x) + noise.sample(&mut rng));
            }
        }
        (v, f)
    }

    const SWEEP_TRUTH: StribeckLaw = StribeckLaw { fc: 10.0, fs: 15.0, vs: 5e-3, delta: 1.2, fv: 40.0 };

    #[test]
    fn friction_sweep_recovers_each_stribeck_parameter_within_5_percent() {
        // Noise 0.05 N per sweep point (0.5 % of Fc: a load cell averaged over a constant-velocity
        // segment). With this design the Jacobian gives relative standard errors ≤ ~1.5 % (printed),
        // so 5 % is > 3σ for every parameter; the test also checks the error against 4·SE so a wrong
        // standard error fails too.
        let (v, f) = synthetic_sweep(&SWEEP_TRUTH, 0.05, 7);
        let fit = fit_stribeck(&v, &f, &StribeckFitOptions::default()).unwrap();
        println!("{}", serde_json_like(&fit));
        assert!(fit.converged && fit.at_bound.is_empty(), "{fit:?}");
        let c = fit.coefficients;
        let se = fit.std_errors;
        for (name, est, tru, s) in [
            ("fc", c.fc, SWEEP_TRUTH.fc, se.fc),
            ("fs", c.fs, SWEEP_TRUTH.fs, se.fs),
            ("vs", c.vs, SWEEP_TRUTH.vs, se.vs),
            ("delta", c.delta, SWEEP_TRUTH.delta, se.delta),
            ("fv", c.fv, SWEEP_TRUTH.fv, se.fv),
        ] {
            let s = s.expect("standard error");
            assert!((est / tru - 1.0).abs() < 0.05, "{name}: {est} vs {tru}");
            assert!((est - tru).abs() < 4.0 * s, "{name}: {est} vs {tru}, se {s}");
            assert!(s / tru < 0.02, "{name}: relative SE {} too large for the design", s / tru);
        }
        // Residual RMS ≈ noise σ·√((n − p)/n) (n = 56, p = 5): within ±30 % (χ² with 51 dof: 3σ ≈ 30 %).
        assert!((fit.residual_rms / 0.05 - 1.0).abs() < 0.3, "rms {}", fit.residual_rms);
    }

    #[test]
    fn friction_sweep_standard_errors_are_calibrated() {
        // Monte Carlo over 40 seeds: the fraction of |error| < 2·SE should be ≈ 95 %; with 40 trials
        // × 5 parameters the binomial 3σ band around 0.95 is ±0.046, so require > 0.88.
        let mut inside = 0;
        let mut total = 0;
        for seed in 100..140 {
            let (v, f) = synthetic_sweep(&SWEEP_TRUTH, 0.05, seed);
            let fit = fit_stribeck(&v, &f, &StribeckFitOptions::default()).unwrap();
            let c = fit.coefficients;
            let se = fit.std_errors;
            for (est, tru, s) in [
                (c.fc, SWEEP_TRUTH.fc, se.fc),
                (c.fs, SWEEP_TRUTH.fs, se.fs),
                (c.vs, SWEEP_TRUTH.vs, se.vs),
                (c.delta, SWEEP_TRUTH.delta, se.delta),
                (c.fv, SWEEP_TRUTH.fv, se.fv),
            ] {
                total += 1;
                if let Some(s) = s {
                    if (est - tru).abs() < 2.0 * s {
                        inside += 1;
                    }
                }
            }
        }
        let frac = inside as f64 / total as f64;
        println!("fraction within 2 SE: {frac}");
        assert!(frac > 0.88, "{frac}");
    }

    #[test]
    fn one_direction_fits_its_own_branch() {
        // Asymmetric axis: negative branch has Fc = 12 N. Fitting each direction separately
        // recovers each branch (noise 0.05 N as above; tolerance 5 % as above).
        let (mut v, mut f) = synthetic_sweep(&SWEEP_TRUTH, 0.05, 11);
        let neg = StribeckLaw { fc: 12.0, ..SWEEP_TRUTH };
        for (x, y) in v.iter().zip(f.iter_mut()) {
            if *x < 0.0 {
                *y += stribeck_curve(StribeckShape::Exponential, &neg, *x)
                    - stribeck_curve(StribeckShape::Exponential, &SWEEP_TRUTH, *x);
            }
        }
        let pos =
            fit_stribeck(&v, &f, &StribeckFitOptions { direction: SweepDirection::Positive, ..Default::default() })
                .unwrap();
        let negf =
            fit_stribeck(&v, &f, &StribeckFitOptions { direction: SweepDirection::Negative, ..Default::default() })
                .unwrap();
        assert_eq!(pos.n_points, v.len() / 2);
        assert!((pos.coefficients.fc / 10.0 - 1.0).abs() < 0.05, "{pos:?}");
        assert!((negf.coefficients.fc / 12.0 - 1.0).abs() < 0.05, "{negf:?}");
        v.truncate(0);
    }

    #[test]
    fn move_with_known_mass_recovers_the_stribeck_curve() {
        // A 25 kg carriage accelerates at 1 m/s² from rest to 0.5 m/s, cruises, decelerates
        // (trapezoid, 2 kHz). Drive force F = m·a + F_friction(v) with the exponential Stribeck
        // truth; encoder velocity noise 1e-4 m/s and load-cell noise 0.5 N (white, per sample).
        let truth = StribeckLaw { fc: 10.0, fs: 20.0, vs: 0.02, delta: 1.0, fv: 60.0 };
        let (m, dt, acc, vmax) = (25.0, 5e-4, 1.0, 0.5);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let nv = Normal::new(0.0, 1e-4).unwrap();
        let nf = Normal::new(0.0, 0.5).unwrap();
        let (t_acc, t_cruise) = (vmax / acc, 0.3);
        let n = ((0.05 + 2.0 * t_acc + t_cruise + 0.05) / dt) as usize;
        let (mut vm, mut fm, mut vt) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..n {
            let t = i as f64 * dt - 0.05;
            let (v, a) = if t < 0.0 {
                (0.0, 0.0)
            } else if t < t_acc {
                (acc * t, acc)
            } else if t < t_acc + t_cruise {
                (vmax, 0.0)
            } else if t < 2.0 * t_acc + t_cruise {
                (vmax - acc * (t - t_acc - t_cruise), -acc)
            } else {
                (0.0, 0.0)
            };
            // At rest the carriage sticks: friction equals the drive force, which the servo ramps
            // up to the break-away level Fs over the 20 ms before motion starts.
            let ff = if v > 0.0 {
                stribeck_curve(StribeckShape::Exponential, &truth, v)
            } else if t < 0.0 {
                truth.fs * ((t + 0.02) / 0.02).clamp(0.0, 1.0)
            } else {
                0.0
            };
            vt.push(v);
            vm.push(v + nv.sample(&mut rng));
            fm.push(m * a + ff + nf.sample(&mut rng));
        }
        // Zero-phase 50 Hz low-pass: passes the friction transient (vs/acc = 20 ms) with little
        // blur while cutting the differentiated velocity noise.
        let mf = friction_from_motion(&vm, &fm, m, dt, Some(50.0), FilterMode::ZeroPhase).unwrap();
        // Window: acceleration phase (true a = +1), v ≥ 1 mm/s.
        let (mut v, mut f) = (Vec::new(), Vec::new());
        for i in 0..n {
            let t = i as f64 * dt - 0.05;
            if t > 0.0 && t < t_acc - 0.02 && mf.v[i] > 1e-3 {
                v.push(mf.v[i]);
                f.push(mf.friction[i]);
            }
        }
        let fit = fit_stribeck(&v, &f, &StribeckFitOptions::default()).unwrap();
        println!("{}", serde_json_like(&fit));
        let c = fit.coefficients;
        // Tolerance 10 %: the filter still blurs the Stribeck drop (its ~6 ms impulse response
        // spans 6 mm/s of the 20 mm/s transition) and correlates neighbouring samples, which the
        // white-noise standard errors ignore.
        for (name, est, tru) in [
            ("fc", c.fc, truth.fc),
            ("fs", c.fs, truth.fs),
            ("vs", c.vs, truth.vs),
            ("delta", c.delta, truth.delta),
            ("fv", c.fv, truth.fv),
        ] {
            assert!((est / tru - 1.0).abs() < 0.10, "{name}: {est} vs {tru}");
        }
    }

    fn serde_json_like(fit: &StribeckFit) -> String {
        format!(
            "coeffs {:?}\nse {:?}\nrms {} n {} iters {} converged {} at_bound {:?}",
            fit.coefficients,
            fit.std_errors,
            fit.residual_rms,
            fit.n_points,
            fit.iterations,
            fit.converged,
            fit.at_bound
        )
    }

    #[test]
    fn central_difference_is_exact_for_a_quadratic() {
        // x = 3t² − t + 2 sampled at dt = 0.1 → x' = 6t − 1 (hand-worked), exact to rounding.
        let dt = 0.1;
        let x: Vec<f64> = (0..10)
            .map(|i| {
                let t = i as f64 * dt;
                3.0 * t * t - t + 2.0
            })
            .collect();
        let d = central_difference(&x, dt).unwrap();
        for (i, di) in d.iter().enumerate() {
            assert!((di - (6.0 * i as f64 * dt - 1.0)).abs() < 1e-12, "{i}: {di}");
        }
    }

    #[test]
    fn zero_phase_butterworth_keeps_a_slow_sine_and_kills_a_fast_one() {
        let dt = 1e-3;
        let t: Vec<f64> = (0..4000).map(|i| i as f64 * dt).collect();
        let slow: Vec<f64> = t.iter().map(|t| (std::f64::consts::TAU * 2.0 * t).sin()).collect();
        let fast: Vec<f64> = t.iter().map(|t| (std::f64::consts::TAU * 200.0 * t).sin()).collect();
        let ys = butterworth2_lowpass(&slow, dt, 30.0, FilterMode::ZeroPhase).unwrap();
        let yf = butterworth2_lowpass(&fast, dt, 30.0, FilterMode::ZeroPhase).unwrap();
        // |H(2 Hz)|² = 1/(1 + (2/30)⁴) ≈ 0.99998 and no phase lag: the error in the interior is
        // below 1e-3 (tolerance covers the prewarp and the 2e-5 gain loss).
        for i in 500..3500 {
            assert!((ys[i] - slow[i]).abs() < 1e-3, "slow at {i}: {} vs {}", ys[i], slow[i]);
        }
        // |H(200 Hz)|² with prewarp ≈ 1/(1 + (tan(0.2π)/tan(0.03π))⁴) ≈ 1.6e-4: below 1e-3.
        for (i, y) in yf.iter().enumerate().take(3500).skip(500) {
            assert!(y.abs() < 1e-3, "fast at {i}: {y}");
        }
        // The causal filter lags: at 2 Hz the phase lag of a 2nd-order Butterworth at fc = 30 Hz is
        // atan(√2·r/(1 − r²)), r = 2/30 → 0.0947 rad; the output trails by about 0.0947/(2π·2) s.
        let yc = butterworth2_lowpass(&slow, dt, 30.0, FilterMode::Causal).unwrap();
        let lag = 0.0947 / (std::f64::consts::TAU * 2.0);
        for i in 1000..3000 {
            let expect = (std::f64::consts::TAU * 2.0 * (t[i] - lag)).sin();
            assert!((yc[i] - expect).abs() < 2e-3, "causal at {i}");
        }
    }

    #[test]
    fn bad_input_is_rejected_with_a_message() {
        let o = StribeckFitOptions::default();
        let e = fit_stribeck(&[0.1, 0.2], &[1.0], &o).unwrap_err().to_string();
        assert!(e.contains("same length"), "{e}");
        let e = fit_stribeck(&[0.1, f64::NAN], &[1.0, 2.0], &o).unwrap_err().to_string();
        assert!(e.contains("finite") && e.contains("index 1"), "{e}");
        let e = fit_stribeck(&[0.1, 0.0, 0.3], &[1.0, 2.0, 3.0], &o).unwrap_err().to_string();
        assert!(e.contains("nonzero"), "{e}");
        assert!(butterworth2_lowpass(&[1.0, 2.0, 3.0], 1e-3, 600.0, FilterMode::Causal).is_err());
        assert!(central_difference(&[1.0, 2.0], 1e-3).is_err());
    }

    #[test]
    fn noise_free_mnich_curve_is_recovered_exactly() {
        // Author's coefficients as truth (hand-checkable: peak of the dry part at v = vs is Fs).
        let truth = StribeckLaw { fc: 10.0, fs: 29.6, vs: 0.0135, delta: 1.0, fv: 67.4 };
        assert!((stribeck_curve(StribeckShape::Mnich, &truth, 0.0135) - (29.6 + 67.4 * 0.0135)).abs() < 1e-12);
        let v: Vec<f64> = (1..200).map(|i| i as f64 * 0.003).collect();
        let f: Vec<f64> = v.iter().map(|&x| stribeck_curve(StribeckShape::Mnich, &truth, x)).collect();
        let o = StribeckFitOptions { shape: StribeckShape::Mnich, ..Default::default() };
        let fit = fit_stribeck(&v, &f, &o).unwrap();
        let c = fit.coefficients;
        // Noise-free: only the solver's tolerance remains (1e-6 relative).
        for (a, b) in [(c.fc, 10.0), (c.fs, 29.6), (c.vs, 0.0135), (c.fv, 67.4)] {
            assert!((a / b - 1.0).abs() < 1e-6, "{fit:?}");
        }
    }

    #[test]
    fn sigma0_from_a_synthetic_presliding_ramp() {
        // F = Fs·(1 − exp(−σ0·x/Fs)) sampled on x ∈ [0, 8 µm], σ0 = 1e5 N/m, Fs = 1.5 N: exact
        // model → σ0 recovered to rounding (1e-9 relative).
        let (s0, fs) = (1e5, 1.5);
        let x: Vec<f64> = (0..100).map(|i| i as f64 * 8e-8).collect();
        let f: Vec<f64> = x.iter().map(|x| fs * (1.0 - (-s0 * x / fs).exp())).collect();
        let r = lugre_sigma0_from_presliding(&x, &f, fs).unwrap();
        assert!((r.sigma0 / s0 - 1.0).abs() < 1e-9, "{r:?}");
        // Force rising at constant displacement: not identifiable.
        let x0 = vec![0.0; 100];
        let e = lugre_sigma0_from_presliding(&x0, &f, fs).unwrap_err();
        assert!(matches!(e, FrictionIdError::NotIdentifiable(_)), "{e}");
    }
}
