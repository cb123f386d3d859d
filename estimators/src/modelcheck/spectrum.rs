//! Spectra of a residual (DESIGN.md §8, "where it fails": spatial and temporal spectrum).
//!
//! - [`amplitude_spectrum`]: one-sided amplitude spectrum of a uniformly sampled residual (realfft);
//! - [`ls_periodogram`]: least-squares periodogram for irregular sampling — the generalised
//!   Lomb–Scargle periodogram with a floating mean and weights (Zechmeister & Kürster 2009,
//!   A&A 496:577): on an evenly spaced frequency grid from the Fourier sums of [`fourier_sums`]
//!   (O(n + m log m)), elsewhere by an explicit sine + cosine + offset fit at each frequency;
//! - [`fourier_sums`]: Σ a_i·e^{−2πi f x_i} on an evenly spaced grid of f for any sample
//!   coordinates (a type-1 non-uniform discrete Fourier transform by FFT);
//! - [`frequency_grid`]: a frequency grid for it, spaced finely enough not to miss a peak.
//!
//! "Frequency" is in cycles per unit of the sampling coordinate: Hz for time, 1/m for position
//! (a spatial frequency; the wavelength is its inverse).

use super::lsq::small_lstsq;
use super::{check_finite, check_len, check_min, ModelCheckError, Sigma};
use crate::cpu::clear_upper_state;
use realfft::num_complex::Complex64;
use realfft::RealFftPlanner;
use serde::{Deserialize, Serialize};
#[cfg(test)]
use std::f64::consts::TAU;

/// A one-sided amplitude spectrum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AmplitudeSpectrum {
    /// Frequencies f_k = k/(N·Δ), k = 0..=N/2, in cycles per unit of the sample coordinate.
    pub frequency: Vec<f64>,
    /// Amplitude of the sinusoid at f_k, in the residual's unit.
    pub amplitude: Vec<f64>,
}

/// One-sided amplitude spectrum of a uniformly sampled residual (real FFT):
/// X_k = Σ_{n=0}^{N−1} r_n e^{−2πi kn/N}, A_0 = |X_0|/N (the mean), A_k = 2|X_k|/N for
/// 0 < k < N/2, and A_{N/2} = |X_{N/2}|/N for even N; f_k = k/(N·Δ) with Δ the sample interval
/// (s or m). A sinusoid a·cos(2π f_k n Δ + φ) at a bin frequency shows as A_k = a. No window:
/// apply one before if leakage matters.
pub fn amplitude_spectrum(residual: &[f64], sample_interval: f64) -> Result<AmplitudeSpectrum, ModelCheckError> {
    check_min("amplitude_spectrum", 2, residual.len())?;
    check_finite("residual", residual)?;
    if !(sample_interval.is_finite() && sample_interval > 0.0) {
        return Err(ModelCheckError::Invalid(format!(
            "amplitude_spectrum: the sample interval must be positive and finite, got {sample_interval}"
        )));
    }
    let n = residual.len();
    let mut planner = RealFftPlanner::<f64>::new();
    let r2c = planner.plan_fft_forward(n);
    let mut input = residual.to_vec();
    let mut out = r2c.make_output_vec();
    r2c.process(&mut input, &mut out).map_err(|e| ModelCheckError::Numerical(format!("real FFT failed: {e}")))?;
    let nf = n as f64;
    let amplitude = out
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let a = c.norm() / nf;
            if k == 0 || (n.is_multiple_of(2) && k == n / 2) {
                a
            } else {
                2.0 * a
            }
        })
        .collect();
    let frequency = (0..out.len()).map(|k| k as f64 / (nf * sample_interval)).collect();
    Ok(AmplitudeSpectrum { frequency, amplitude })
}

/// A least-squares periodogram of an irregularly sampled residual.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Periodogram {
    /// Trial frequencies, in cycles per unit of the sample coordinate.
    pub frequency: Vec<f64>,
    /// Fitted amplitude √(a² + b²) at each frequency, in the residual's unit.
    pub amplitude: Vec<f64>,
    /// Normalised power p(f) = 1 − χ²(f)/χ²₀ ∈ [0, 1]: the fraction of the (weighted) variance
    /// about the mean that the sinusoid explains.
    pub power: Vec<f64>,
}

/// Frequencies of an evenly spaced grid between fresh evaluations of the sines and cosines in
/// [`sinusoid_reductions`] (the others by rotation).
pub const RESEED: usize = 64;

/// Generalised Lomb–Scargle periodogram (Zechmeister & Kürster 2009): at each trial frequency f
/// fit r_i ≈ c + a·cos(2πf x_i) + b·sin(2πf x_i) by weighted least squares (weights 1/σ_i²) and
/// report the amplitude √(a² + b²) and the power p(f) = 1 − χ²(f)/χ²₀, χ²₀ = Σ ((r_i − r̄_w)/σ_i)².
///
/// `x` are the sample coordinates (time in s or position in m, any order, need not be uniform).
/// At a frequency where sine or cosine is degenerate on these samples (e.g. an alias of 0) the
/// degenerate column is dropped and its coefficient is 0.
///
/// On an evenly spaced grid of frequencies (as [`frequency_grid`] makes) the sums come from
/// [`fourier_sums`] in O(n + m·log m) for m frequencies (`ls_periodogram_even`); elsewhere each
/// frequency is an explicit fit, O(n·m). The two agree to about 1e-9 of the amplitude away from
/// the degenerate frequencies (unit test `even_grid_periodogram_equals_the_explicit_fit`).
pub fn ls_periodogram(
    x: &[f64],
    residual: &[f64],
    sigma: &Sigma,
    frequencies: &[f64],
) -> Result<Periodogram, ModelCheckError> {
    let n = residual.len();
    check_min("ls_periodogram", 4, n)?;
    check_len("x", n, x.len())?;
    check_finite("x", x)?;
    check_finite("residual", residual)?;
    check_finite("frequencies", frequencies)?;
    if let Some(f) = frequencies.iter().find(|f| **f <= 0.0) {
        return Err(ModelCheckError::Invalid(format!("ls_periodogram: frequencies must be positive, got {f}")));
    }
    let w = sigma.weights(n)?;
    let ones = vec![1.0; n];
    let (_, chi0) = small_lstsq(&[ones.as_slice()], residual, &w);
    if chi0 == 0.0 {
        return Err(ModelCheckError::Invalid(
            "ls_periodogram: the residual is constant, its periodogram is zero".into(),
        ));
    }
    Ok(match even_step(frequencies) {
        Some(df) => ls_periodogram_even(x, residual, &w, chi0, frequencies, df),
        None => ls_periodogram_direct(x, residual, &w, chi0, frequencies),
    })
}

/// [`ls_periodogram`] at any frequencies by the explicit weighted fit of mean + cosine + sine at
/// each (O(n) per frequency).
fn ls_periodogram_direct(x: &[f64], r: &[f64], w: &[f64], chi0: f64, frequencies: &[f64]) -> Periodogram {
    clear_upper_state();
    let n = r.len();
    let ones = vec![1.0; n];
    let mut amplitude = Vec::with_capacity(frequencies.len());
    let mut power = Vec::with_capacity(frequencies.len());
    let mut c = vec![0.0; n];
    let mut s = vec![0.0; n];
    let tau = 2.0 * std::f64::consts::PI;
    for &f in frequencies {
        let om = tau * f;
        for i in 0..n {
            let (si, ci) = (om * x[i]).sin_cos();
            c[i] = ci;
            s[i] = si;
        }
        let (beta, chi) = small_lstsq(&[ones.as_slice(), c.as_slice(), s.as_slice()], r, w);
        amplitude.push(beta[1].hypot(beta[2]));
        power.push((1.0 - chi / chi0).clamp(0.0, 1.0));
    }
    Periodogram { frequency: frequencies.to_vec(), amplitude, power }
}

/// The step Δf of `frequencies` when they are evenly spaced, f_k = f₀ + k·Δf to 1e-12 of each
/// (as [`frequency_grid`] makes them), with at least two of them and Δf > 0.
fn even_step(frequencies: &[f64]) -> Option<f64> {
    match frequencies {
        [f0, f1, ..]
            if f1 > f0
                && frequencies
                    .iter()
                    .enumerate()
                    .all(|(k, f)| (f - (f0 + k as f64 * (f1 - f0))).abs() <= 1e-12 * f.abs()) =>
        {
            Some(f1 - f0)
        }
        _ => None,
    }
}

/// A column of the periodogram's fit is dropped as degenerate on the samples (an alias of 0)
/// when the part of its weighted squared norm outside the earlier columns is at most this
/// fraction of the whole. From normal equations, a degenerate column's part is rounding of order
/// 1e-16 of the norm; an explicit fit (Gram–Schmidt) sees it at 1e-18 or below.
const DEGENERATE_PART: f64 = 1e-10;

/// [`ls_periodogram`] on an evenly spaced grid f_k = f₀ + k·Δf, from the weighted Fourier sums
/// ([`fourier_sums`], q_i = w_i²): with C(f) = Σ q·cos 2πf x, S(f) = Σ q·sin 2πf x, the 3 × 3
/// normal equations of mean + cosine + sine take Σ q·cos² = (Σq + C(2f))/2, Σ q·sin² =
/// (Σq − C(2f))/2, Σ q·cos·sin = S(2f)/2 and Σ q·r·cos, Σ q·r·sin from the sums of q·r. The mean
/// is projected out, the 2 × 2 system solved for (a, b), and χ²(f) = χ²₀ − (a·Σ q·r̃·cos +
/// b·Σ q·r̃·sin). A degenerate cosine or sine ([`DEGENERATE_PART`]) is dropped (coefficient 0), in
/// that order, as the explicit fit drops it.
fn ls_periodogram_even(x: &[f64], r: &[f64], w: &[f64], chi0: f64, frequencies: &[f64], df: f64) -> Periodogram {
    let m = frequencies.len();
    let f0 = frequencies[0];
    let q: Vec<f64> = w.iter().map(|v| v * v).collect();
    let sw: f64 = q.iter().sum();
    let ry: f64 = q.iter().zip(r).map(|(a, b)| a * b).sum();
    let qr: Vec<Complex64> = q.iter().zip(r).map(|(a, b)| Complex64::new(a * b, 0.0)).collect();
    let qc: Vec<Complex64> = q.iter().map(|a| Complex64::new(*a, 0.0)).collect();
    // e^{−iθ}: the real part is the cosine sum, minus the imaginary part the sine sum.
    let sum_r = fourier_sums(x, &qr, f0, df, m);
    let sum_1 = fourier_sums(x, &qc, f0, df, m);
    let sum_2 = fourier_sums(x, &qc, 2.0 * f0, 2.0 * df, m);
    let mut amplitude = Vec::with_capacity(m);
    let mut power = Vec::with_capacity(m);
    for k in 0..m {
        let (s_c, s_s) = (sum_1[k].re, -sum_1[k].im);
        let (c2, s2) = (sum_2[k].re, -sum_2[k].im);
        let (s_cc, s_ss, s_cs) = (0.5 * (sw + c2), 0.5 * (sw - c2), 0.5 * s2);
        let (r_c, r_s) = (sum_r[k].re, -sum_r[k].im);
        // Centred (the mean's column projected out).
        let (ccc, ccs, css) = (s_cc - s_c * s_c / sw, s_cs - s_c * s_s / sw, s_ss - s_s * s_s / sw);
        let (yc, ys) = (r_c - ry * s_c / sw, r_s - ry * s_s / sw);
        let cos_kept = ccc > DEGENERATE_PART * s_cc;
        let (a, b) = if cos_kept {
            let sin_part = css - ccs * ccs / ccc;
            if sin_part > DEGENERATE_PART * s_ss {
                let det = ccc * css - ccs * ccs;
                ((css * yc - ccs * ys) / det, (ccc * ys - ccs * yc) / det)
            } else {
                (yc / ccc, 0.0)
            }
        } else if css > DEGENERATE_PART * s_ss {
            (0.0, ys / css)
        } else {
            (0.0, 0.0)
        };
        amplitude.push(a.hypot(b));
        power.push(((a * yc + b * ys) / chi0).clamp(0.0, 1.0));
    }
    Periodogram { frequency: frequencies.to_vec(), amplitude, power }
}

/// Terms of the Taylor series of [`fourier_sums`] are added until the next one's bound
/// (π·m/L)^p/p! falls below this (relative to Σ|a_i|).
pub const FOURIER_SUM_TOLERANCE: f64 = 1e-17;

/// Fourier sums of values a_i at any sample coordinates x_i on an evenly spaced grid of
/// frequencies (a type-1 non-uniform discrete Fourier transform):
///
/// ```text
/// F_k = Σ_i a_i·e^{−2πi·(f₀ + k·Δf)·x_i},   k = 0 … m − 1
/// ```
///
/// (f in cycles per unit of x). Direct evaluation costs n·m; here each sample goes to the
/// nearest node g_i of a grid of L ≥ 4m nodes of spacing h = 1/(L·Δf), x_i − x_min = (g_i + δ_i)·h
/// with |δ_i| ≤ ½, and e^{−2πi k δ_i/L} is expanded in its Taylor series, so that
///
/// ```text
/// F_k = e^{−2πi k Δf x_min} · Σ_p (−2πi k/L)^p/p! · FFT_L[Σ_{g_i = g} b_i·δ_i^p](k),   b_i = a_i·e^{−2πi f₀ x_i}
/// ```
///
/// (g taken modulo L: the grid's phases repeat with period L). With k/L ≤ ¼ the p-th term is
/// bounded by (π/4)^p/p! of Σ|a_i|, so 18 terms reach [`FOURIER_SUM_TOLERANCE`]: about 18 FFTs
/// of length L, O(n + m·log m) in all. The same FFT-on-a-grid idea, with other kernels, is the
/// non-uniform FFT of Dutt & Rokhlin (1993) and of Press & Rybicki (1989) for the Lomb–Scargle
/// periodogram.
pub fn fourier_sums(x: &[f64], a: &[Complex64], f0: f64, df: f64, m: usize) -> Vec<Complex64> {
    clear_upper_state();
    let tau = 2.0 * std::f64::consts::PI;
    if m == 0 || x.is_empty() {
        return vec![Complex64::new(0.0, 0.0); m];
    }
    let x_min = x.iter().copied().fold(f64::INFINITY, f64::min);
    let l = (4 * m).max(16).next_power_of_two();
    let lf = l as f64;
    // Node and offset of each sample.
    let (node, delta): (Vec<usize>, Vec<f64>) = x
        .iter()
        .map(|&xi| {
            let t = (xi - x_min) * df * lf;
            let g = t.round();
            // index: t ≥ 0 and finite (x finite, df > 0); the node is taken modulo L.
            ((g.rem_euclid(lf)) as usize % l, t - g)
        })
        .unzip();
    let b: Vec<Complex64> = a
        .iter()
        .zip(x)
        .map(|(ai, &xi)| {
            let (s, c) = (tau * f0 * xi).sin_cos();
            ai * Complex64::new(c, -s)
        })
        .collect();
    let scale: f64 = b.iter().map(|v| v.norm()).sum();
    let mut planner = rustfft::FftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(l);
    let mut out = vec![Complex64::new(0.0, 0.0); m];
    // z_k^p/p!, z_k = −2πi·k/L, per k.
    let mut coef = vec![Complex64::new(1.0, 0.0); m];
    let mut grid = vec![Complex64::new(0.0, 0.0); l];
    let mut bd = b.clone();
    let ratio = std::f64::consts::PI * m as f64 / lf;
    let mut bound = 1.0;
    let mut p = 0usize;
    loop {
        grid.fill(Complex64::new(0.0, 0.0));
        for (&g, v) in node.iter().zip(&bd) {
            grid[g] += v;
        }
        fft.process(&mut grid);
        for (k, (o, c)) in out.iter_mut().zip(&coef).enumerate() {
            *o += c * grid[k];
        }
        p += 1;
        bound *= ratio / p as f64;
        if bound <= FOURIER_SUM_TOLERANCE || scale == 0.0 {
            break;
        }
        for (k, c) in coef.iter_mut().enumerate() {
            *c *= Complex64::new(0.0, -tau * k as f64 / lf) / p as f64;
        }
        bd.iter_mut().zip(&delta).for_each(|(v, d)| *v *= d);
    }
    for (k, o) in out.iter_mut().enumerate() {
        let (s, c) = (tau * df * k as f64 * x_min).sin_cos();
        *o *= Complex64::new(c, -s);
    }
    out
}

/// Trial frequencies for [`ls_periodogram`]: from f_min = 1/span to f_max in steps of
/// Δf = 1/(oversample·span), span = max x − min x. The peak of a sinusoid has a width of about
/// 1/span, so an oversampling of 5–10 does not miss it. `f_max` defaults to the pseudo-Nyquist
/// frequency 1/(2·median spacing of the sorted x).
///
/// Errors when the grid would exceed 1 000 000 frequencies.
pub fn frequency_grid(x: &[f64], oversample: f64, f_max: Option<f64>) -> Result<Vec<f64>, ModelCheckError> {
    check_min("frequency_grid", 3, x.len())?;
    check_finite("x", x)?;
    if !(oversample.is_finite() && oversample >= 1.0) {
        return Err(ModelCheckError::Invalid(format!("frequency_grid: oversample must be ≥ 1, got {oversample}")));
    }
    let mut xs = x.to_vec();
    xs.sort_by(|a, b| a.total_cmp(b));
    let span = xs[xs.len() - 1] - xs[0];
    if span <= 0.0 {
        return Err(ModelCheckError::Invalid("frequency_grid: all sample coordinates are equal".into()));
    }
    let f_max = match f_max {
        Some(f) if f.is_finite() && f > 0.0 => f,
        Some(f) => {
            return Err(ModelCheckError::Invalid(format!("frequency_grid: f_max must be positive and finite, got {f}")))
        }
        None => {
            let mut d: Vec<f64> = xs.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
            d.sort_by(|a, b| a.total_cmp(b));
            0.5 / d[d.len() / 2]
        }
    };
    let df = 1.0 / (oversample * span);
    let f_min = 1.0 / span;
    if f_max < f_min {
        return Err(ModelCheckError::Invalid(format!(
            "frequency_grid: f_max = {f_max} is below the lowest resolvable frequency 1/span = {f_min}"
        )));
    }
    // index: f_max and span are finite and positive (checked above); m ≤ 1e6 is checked below before any allocation.
    let m = ((f_max - f_min) / df).floor() as usize + 1;
    if m > 1_000_000 {
        return Err(ModelCheckError::Invalid(format!(
            "frequency_grid: {m} frequencies requested, at most 1000000 allowed; lower f_max or oversample"
        )));
    }
    Ok((0..m).map(|k| f_min + df * k as f64).collect())
}

/// The weighted χ² reduction of a sinusoid fitted beside a mean, on an evenly spaced grid of
/// frequencies f_k = f₀ + k·Δf (k < m): Δχ²(f) = χ²₀ − χ²(f), where χ²(f) is the minimum of
/// Σ w_i²·(r_i − c − a·cos 2πf x_i − b·sin 2πf x_i)² and χ²₀ that of the mean alone (the
/// generalised Lomb–Scargle periodogram of Zechmeister & Kürster 2009 before its normalisation,
/// from the 3 × 3 normal equations). `w` are weights 1/σ_i: with σ_i the noise, Δχ² of pure noise
/// is χ²₂ at each frequency (mean 2). Each sample's cos/sin at the next frequency is a rotation of
/// the last by 2πΔf·x_i, evaluated afresh every [`RESEED`] frequencies. A frequency at which the
/// sine or cosine is degenerate on these samples (an alias of 0) reduces by the other alone.
pub fn sinusoid_reductions(x: &[f64], r: &[f64], w: &[f64], f0: f64, df: f64, m: usize) -> Vec<f64> {
    clear_upper_state();
    let tau = 2.0 * std::f64::consts::PI;
    let ww: Vec<f64> = w.iter().map(|v| v * v).collect();
    let sw: f64 = ww.iter().sum();
    let ry: f64 = ww.iter().zip(r).map(|(a, b)| a * b).sum();
    let rot: Vec<(f64, f64)> = x.iter().map(|xi| (tau * df * xi).sin_cos()).collect();
    let mut sc: Vec<(f64, f64)> = vec![(0.0, 1.0); x.len()];
    let mut out = Vec::with_capacity(m);
    if !(sw > 0.0) {
        return vec![0.0; m];
    }
    for k in 0..m {
        if k % RESEED == 0 {
            let om = tau * (f0 + k as f64 * df);
            sc.iter_mut().zip(x).for_each(|(p, xi)| *p = (om * xi).sin_cos());
        } else {
            sc.iter_mut().zip(&rot).for_each(|((s, c), (sd, cd))| (*s, *c) = (*s * cd + *c * sd, *c * cd - *s * sd));
        }
        let (mut s_c, mut s_s, mut s_cc, mut s_cs, mut s_ss, mut r_c, mut r_s) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for ((&(s, c), &q), &y) in sc.iter().zip(&ww).zip(r) {
            let (qc, qs) = (q * c, q * s);
            s_c += qc;
            s_s += qs;
            s_cc += qc * c;
            s_cs += qc * s;
            s_ss += qs * s;
            r_c += qc * y;
            r_s += qs * y;
        }
        // Centred (the mean's column projected out).
        let (ccc, ccs, css) = (s_cc - s_c * s_c / sw, s_cs - s_c * s_s / sw, s_ss - s_s * s_s / sw);
        let (yc, ys) = (r_c - ry * s_c / sw, r_s - ry * s_s / sw);
        let det = ccc * css - ccs * ccs;
        let red = if det > 1e-10 * ccc * css && ccc > 0.0 && css > 0.0 {
            (css * yc * yc - 2.0 * ccs * yc * ys + ccc * ys * ys) / det
        } else {
            let a = if ccc > 1e-10 * sw { yc * yc / ccc } else { 0.0 };
            let b = if css > 1e-10 * sw { ys * ys / css } else { 0.0 };
            a.max(b)
        };
        out.push(red.max(0.0));
    }
    out
}

/// Result of [`sparse_frequency_scan`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrequencyScan {
    /// The frequencies to evaluate exactly (ascending): each of the coherent search's best peaks
    /// with its two neighbours on the fine grid (the bracket of a refinement).
    pub frequencies: Vec<f64>,
    /// Step of the fine grid, cycles per unit of x: 1/(4·span of x).
    pub fine_step: f64,
    /// The number of independent frequencies the search chose from, span·(f_top − f_lo) (the
    /// look-elsewhere count of a significance test).
    pub independent: usize,
    /// Highest frequency searched: the lower of f_hi and the Nyquist frequency 1/(2·gap) of the
    /// most finely sampled piece.
    pub f_top: f64,
    /// Pieces that sample some searched frequency densely.
    pub pieces: usize,
}

/// Span of a piece of [`sparse_frequency_scan`]'s coarse stage, in units of x: its frequency
/// resolution is 1/span (200 /m at 5 mm), so that the coarse grid stays at a few thousand
/// frequencies over a decade of spatial frequencies near 10⁵ /m.
pub const SCAN_PIECE_SPAN: f64 = 5e-3;
/// Peaks of the coarse stage whose neighbourhoods the fine stage searches.
pub const SCAN_COARSE_PEAKS: usize = 3;
/// Peaks of the fine stage returned for exact evaluation.
pub const SCAN_FINE_PEAKS: usize = 4;
/// Largest number of frequencies of either stage.
pub const SCAN_MAX_FREQUENCIES: usize = 200_000;
/// Fewest samples of a piece.
pub const SCAN_MIN_PIECE: usize = 8;

/// A sinusoid of spatial frequency f ∈ [f_lo, f_hi] (say a scale's interpolation error, period
/// 2–200 µm) in a residual r sampled at positions x that resolve f only in places: a log at
/// speed samples such a period far below the Nyquist rate (its samples are consistent with
/// thousands of aliases), a crawl or a reversal samples it densely over a few millimetres.
/// `segments` are index ranges [start, end) of consecutive samples (one per channel or run, in
/// time order); `w` the weights 1/σ_i.
///
/// Two stages:
/// 1. **Coarse, incoherent, alias-free.** Every segment is cut into pieces of consecutive samples
///    with gaps ≤ 1/(2 f_lo) and span ≤ [`SCAN_PIECE_SPAN`]. A piece contributes at the
///    frequencies it samples at or above the Nyquist rate (its largest gap ≤ 1/(2f)) over at least
///    one period (span ≥ 1/f): there it has no alias. The contributions Δχ²_piece(f) − 2 (excess
///    over the mean of pure noise, [`sinusoid_reductions`]) are summed over pieces on a grid of
///    step 1/(4·largest span), and scored as z = Σ(Δχ² − 2)/√(4·count).
/// 2. **Fine, coherent, over all samples.** Around each of the [`SCAN_COARSE_PEAKS`] best coarse
///    peaks (± the piece's resolution 1/span) the reduction of one sinusoid over every sample is
///    evaluated on a grid of step 1/(4·span of x) (a phase error of π/4 at the ends); the best
///    [`SCAN_FINE_PEAKS`] local maxima are returned with their neighbours.
///
/// None when no piece samples any frequency of the range densely (the data cannot tell the
/// period from its aliases) or the grids would exceed [`SCAN_MAX_FREQUENCIES`].
pub fn sparse_frequency_scan(
    x: &[f64],
    r: &[f64],
    w: &[f64],
    segments: &[(usize, usize)],
    (f_lo, f_hi): (f64, f64),
) -> Option<FrequencyScan> {
    if !(f_lo > 0.0 && f_hi > f_lo) || x.len() != r.len() || x.len() != w.len() {
        return None;
    }
    // Pieces: (start, end, largest gap, span).
    let mut pieces: Vec<(usize, usize, f64, f64)> = Vec::new();
    let max_gap = 0.5 / f_lo;
    for &(a, b) in segments {
        let b = b.min(x.len());
        let mut start = a;
        let mut gap: f64 = 0.0;
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for i in a..b {
            let g = if i > start { (x[i] - x[i - 1]).abs() } else { 0.0 };
            let (nlo, nhi) = (lo.min(x[i]), hi.max(x[i]));
            if i > start && (g > max_gap || nhi - nlo > SCAN_PIECE_SPAN) {
                if i - start >= SCAN_MIN_PIECE {
                    pieces.push((start, i, gap, hi - lo));
                }
                (start, gap, lo, hi) = (i, 0.0, x[i], x[i]);
            } else {
                (gap, lo, hi) = (gap.max(g), nlo, nhi);
            }
        }
        if b > start && b - start >= SCAN_MIN_PIECE {
            pieces.push((start, b, gap, hi - lo));
        }
    }
    pieces.retain(|p| p.2 > 0.0 && p.3 > 0.0 && 0.5 / p.2 >= f_lo && p.3 * f_hi >= 1.0);
    let f_top = pieces.iter().map(|p| 0.5 / p.2).fold(0.0, f64::max).min(f_hi);
    let span_max = pieces.iter().map(|p| p.3).fold(0.0, f64::max);
    if pieces.is_empty() || !(f_top > f_lo) {
        return None;
    }
    let dfc = 0.25 / span_max;
    let mc = ((f_top - f_lo) / dfc).ceil() as usize + 1;
    if mc > SCAN_MAX_FREQUENCIES {
        return None;
    }
    let mut excess = vec![0.0; mc];
    let mut count = vec![0usize; mc];
    for &(a, b, gap, span) in &pieces {
        // The frequencies this piece resolves: f ≤ 1/(2·gap) and f ≥ 1/span.
        let k_lo = (((1.0 / span).max(f_lo) - f_lo) / dfc).ceil().max(0.0) as usize;
        let k_hi = ((((0.5 / gap).min(f_top)) - f_lo) / dfc).floor().max(-1.0);
        if k_hi < k_lo as f64 {
            continue;
        }
        let k_hi = (k_hi as usize).min(mc - 1);
        let red = sinusoid_reductions(&x[a..b], &r[a..b], &w[a..b], f_lo + k_lo as f64 * dfc, dfc, k_hi - k_lo + 1);
        for (k, v) in (k_lo..=k_hi).zip(red) {
            excess[k] += v - 2.0;
            count[k] += 1;
        }
    }
    let z: Vec<f64> = excess
        .iter()
        .zip(&count)
        .map(|(e, c)| if *c > 0 { e / (4.0 * *c as f64).sqrt() } else { f64::NEG_INFINITY })
        .collect();
    let coarse = local_maxima(&z, SCAN_COARSE_PEAKS);
    // Fine stage over every sample.
    let idx: Vec<usize> = segments.iter().flat_map(|&(a, b)| a..b.min(x.len())).collect();
    let (xs, rs, ws): (Vec<f64>, Vec<f64>, Vec<f64>) =
        (idx.iter().map(|&i| x[i]).collect(), idx.iter().map(|&i| r[i]).collect(), idx.iter().map(|&i| w[i]).collect());
    let span = xs.iter().fold(f64::NEG_INFINITY, |a, b| a.max(*b)) - xs.iter().fold(f64::INFINITY, |a, b| a.min(*b));
    if !(span > 0.0) {
        return None;
    }
    let dff = 0.25 / span;
    let half = (1.0 / span_max / dff).ceil() as usize;
    if coarse.len() * (2 * half + 1) > SCAN_MAX_FREQUENCIES {
        return None;
    }
    let mut fine: Vec<(f64, f64)> = Vec::new();
    for &kc in &coarse {
        let fc = f_lo + kc as f64 * dfc;
        let f0 = fc - half as f64 * dff;
        let red = sinusoid_reductions(&xs, &rs, &ws, f0, dff, 2 * half + 1);
        let peaks = local_maxima(&red, SCAN_FINE_PEAKS);
        fine.extend(peaks.into_iter().map(|k| (f0 + k as f64 * dff, red[k])));
    }
    fine.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.total_cmp(&b.0)));
    fine.truncate(SCAN_FINE_PEAKS);
    let mut frequencies: Vec<f64> =
        fine.iter().flat_map(|(f, _)| [f - dff, *f, f + dff]).filter(|f| (f_lo..=f_hi).contains(f)).collect();
    frequencies.sort_by(f64::total_cmp);
    frequencies.dedup_by(|a, b| (*a - *b).abs() < 0.5 * dff);
    Some(FrequencyScan {
        frequencies,
        fine_step: dff,
        independent: (span * (f_top - f_lo)).ceil().max(1.0) as usize,
        f_top,
        pieces: pieces.len(),
    })
}

/// Indices of the `n` largest local maxima of `v` (ends count), largest first (ties: lower index).
fn local_maxima(v: &[f64], n: usize) -> Vec<usize> {
    let mut m: Vec<usize> = (0..v.len())
        .filter(|&i| v[i].is_finite() && (i == 0 || v[i] >= v[i - 1]) && (i + 1 == v.len() || v[i] >= v[i + 1]))
        .collect();
    m.sort_by(|a, b| v[*b].total_cmp(&v[*a]).then(a.cmp(b)));
    m.truncate(n);
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fft_amplitude_of_a_bin_sinusoid() {
        // 64 samples at Δ = 1 mm, 3 µm cosine at bin 8 (f = 8/64 mm⁻¹ = 125 m⁻¹) + 1 µm offset.
        let n = 64;
        let dx = 1e-3;
        let r: Vec<f64> = (0..n)
            .map(|i| 1e-6 + 3e-6 * (2.0 * std::f64::consts::PI * 8.0 * i as f64 / n as f64 + 0.3).cos())
            .collect();
        let s = amplitude_spectrum(&r, dx).unwrap();
        assert_eq!(s.frequency.len(), 33);
        // Exact bin: amplitude is exact up to FFT rounding (~1e-16 relative of 3e-6).
        assert!((s.frequency[8] - 125.0).abs() < 1e-9);
        assert!((s.amplitude[8] - 3e-6).abs() < 1e-18);
        assert!((s.amplitude[0] - 1e-6).abs() < 1e-18);
        assert!(s.amplitude[5] < 1e-18);
    }

    #[test]
    fn ls_periodogram_finds_period_on_irregular_positions() {
        // Irregular positions (deterministic quasi-random jitter), period 25 mm, amplitude 2 µm.
        let x: Vec<f64> = (0..80).map(|i| i as f64 * 0.0125 + 0.004 * ((i as f64 * 0.7548776).fract() - 0.5)).collect();
        let r: Vec<f64> = x.iter().map(|x| 2e-6 * (2.0 * std::f64::consts::PI * x / 0.025).sin() + 5e-7).collect();
        let f = frequency_grid(&x, 10.0, None).unwrap();
        let p = ls_periodogram(&x, &r, &Sigma::Unknown, &f).unwrap();
        let (k, _) = p.power.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).unwrap();
        // Grid step 1/(10·span) ≈ 0.1 m⁻¹ around 40 m⁻¹: the peak lies within one step.
        assert!((p.frequency[k] - 40.0).abs() < 0.11, "{}", p.frequency[k]);
        // Noise-free: the only error is the grid offset δ ≤ Δf/2, which lowers the fitted
        // amplitude by about (πδ·span)²/6 ≤ (π/20)²/6 = 0.4 %; allow 0.5 %.
        assert!((p.amplitude[k] - 2e-6).abs() < 1e-8, "{}", p.amplitude[k]);
        assert!(p.power[k] > 0.999);
    }

    /// A small deterministic generator for the tests below (uniform on [0, 1)).
    fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// `fourier_sums` against the direct sums Σ a_i·e^{−2πi f x_i} on 40 random draws: irregular
    /// coordinates (offset, span and jitter random, some spanning many grid periods 1/Δf so that
    /// the nodes wrap), complex values, f₀, Δf and m random. Error ≤ 1e-12·Σ|a_i| (the series is
    /// cut at 1e-17, the FFTs' rounding is about log₂L·ε) plus 8ε·Σ|a_i|·2πf·|x_i|: a phase 2πf·x
    /// is known only to a few ε of itself in either method (x itself is rounded to ε·|x|).
    #[test]
    fn fourier_sums_equal_the_direct_sums() {
        let mut u = uniform(777);
        for draw in 0..40 {
            let n = 20 + (u() * 400.0) as usize;
            let (x0, span) = (u() * 50.0 - 10.0, 0.01 + u() * 5.0);
            let mut x: Vec<f64> = (0..n).map(|i| x0 + span * (i as f64 + 0.9 * (u() - 0.5)) / n as f64).collect();
            if draw % 3 == 0 {
                x.reverse();
            }
            let a: Vec<Complex64> = (0..n).map(|_| Complex64::new(u() - 0.5, u() - 0.5)).collect();
            let m = 1 + (u() * 300.0) as usize;
            let df = if draw % 4 == 0 { 3.0 / span } else { (0.05 + u()) / span };
            let f0 = u() * 20.0 / span;
            let fast = fourier_sums(&x, &a, f0, df, m);
            let scale: f64 = a.iter().map(|v| v.norm()).sum();
            for k in 0..m {
                let f = f0 + k as f64 * df;
                let direct: Complex64 = x
                    .iter()
                    .zip(&a)
                    .map(|(xi, ai)| {
                        let (s, c) = (TAU * f * xi).sin_cos();
                        ai * Complex64::new(c, -s)
                    })
                    .sum();
                // The phases' own rounding: 2π·f·x_i is known to a few ε of itself in either method.
                let phase: f64 = x.iter().zip(&a).map(|(xi, ai)| ai.norm() * TAU * f * xi.abs()).sum();
                let tol = 1e-12 * scale + 8.0 * f64::EPSILON * phase;
                assert!((fast[k] - direct).norm() <= tol, "draw {draw}, k {k}: {} vs {}", fast[k], direct);
            }
        }
    }

    /// The periodogram on an evenly spaced grid (from `fourier_sums`) equals the explicit fit at
    /// each frequency on 30 random draws (irregular or uniform coordinates, weights, a sinusoid
    /// in noise, `frequency_grid` up to the pseudo-Nyquist frequency): amplitude and power within
    /// 1e-9 of their largest values, except at frequencies where the explicit fit's sine or
    /// cosine is nearly degenerate (within 1e-6 of a multiple of 1/(2Δ) on uniform coordinates),
    /// where the two drop a column at different thresholds.
    #[test]
    fn even_grid_periodogram_equals_the_explicit_fit() {
        let mut u = uniform(4242);
        for draw in 0..30 {
            let n = 30 + (u() * 300.0) as usize;
            let dx = 1e-3 * (0.5 + u());
            let jitter = if draw % 2 == 0 { 0.8 } else { 0.0 };
            let x: Vec<f64> = (0..n).map(|i| 0.1 + dx * (i as f64 + jitter * (u() - 0.5))).collect();
            let period = dx * (2.5 + 40.0 * u());
            let r: Vec<f64> =
                x.iter().map(|x| (TAU * x / period + 6.0 * u()).sin() + 0.5 * (u() - 0.5) + 0.2).collect();
            let sigma =
                if draw % 3 == 0 { Sigma::PerSample((0..n).map(|_| 0.5 + u()).collect()) } else { Sigma::Unknown };
            let f = frequency_grid(&x, 5.0, None).unwrap();
            let w = sigma.weights(n).unwrap();
            let ones = vec![1.0; n];
            let (_, chi0) = small_lstsq(&[ones.as_slice()], &r, &w);
            let fast = ls_periodogram(&x, &r, &sigma, &f).unwrap();
            let direct = ls_periodogram_direct(&x, &r, &w, chi0, &f);
            let top = direct.amplitude.iter().fold(0.0_f64, |a, v| a.max(*v));
            for k in 0..f.len() {
                let near_alias = jitter == 0.0 && {
                    let t = f[k] * 2.0 * dx;
                    (t - t.round()).abs() < 1e-6
                };
                if near_alias {
                    continue;
                }
                assert!(
                    (fast.amplitude[k] - direct.amplitude[k]).abs() <= 1e-9 * top,
                    "draw {draw}, f {}: {} vs {}",
                    f[k],
                    fast.amplitude[k],
                    direct.amplitude[k]
                );
                assert!((fast.power[k] - direct.power[k]).abs() <= 1e-9, "draw {draw}, f {}", f[k]);
            }
        }
    }

    /// The reductions on an evenly spaced grid (rotation) equal the explicit weighted fit of
    /// mean + cosine + sine at each frequency (`ls_periodogram`'s power times χ²₀) to 1e-9.
    #[test]
    fn sinusoid_reductions_match_the_explicit_fit() {
        let x: Vec<f64> = (0..300).map(|i| i as f64 * 7.3e-6 + 2e-6 * ((i as f64 * 0.618).fract() - 0.5)).collect();
        let r: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, x)| (TAU * x / 23e-6).sin() + 0.3 * ((i as f64 * 0.37).fract() - 0.5))
            .collect();
        let w: Vec<f64> = (0..300).map(|i| 1.0 + 0.5 * ((i as f64 * 0.71).fract())).collect();
        let (f0, df, m) = (20_000.0, 37.0, 150);
        let red = sinusoid_reductions(&x, &r, &w, f0, df, m);
        let sigma = Sigma::PerSample(w.iter().map(|w| 1.0 / w).collect());
        let f: Vec<f64> = (0..m).map(|k| f0 + k as f64 * df).collect();
        let p = ls_periodogram(&x, &r, &sigma, &f).unwrap();
        let ww: Vec<f64> = w.iter().map(|w| w * w).collect();
        let mean = ww.iter().zip(&r).map(|(a, b)| a * b).sum::<f64>() / ww.iter().sum::<f64>();
        let chi0: f64 = ww.iter().zip(&r).map(|(a, b)| a * (b - mean).powi(2)).sum();
        for k in 0..m {
            assert!((red[k] - p.power[k] * chi0).abs() <= 1e-9 * chi0, "{k}: {} vs {}", red[k], p.power[k] * chi0);
        }
    }

    /// A 10–60 µm sinusoid sampled at 0.2 mm steps over 0.4 m (a log at speed: thousands of
    /// aliases) plus a 2 mm crawl at 1 µm steps: the scan brackets the true frequency within one
    /// fine step (1/(4·0.4 m)) on 20 random periods, with noise at 1/5 of the amplitude.
    #[test]
    fn sparse_scan_finds_a_short_period_from_a_crawl_and_sparse_passes() {
        let mut u = uniform(12345);
        for _ in 0..20 {
            let p = 10e-6 * 6f64.powf(u());
            let phi = TAU * u();
            let mut x: Vec<f64> = (0..2000).map(|i| 0.01 + i as f64 * 2e-4 + 1e-6 * u()).collect();
            let a = x.len();
            x.extend((0..2000).map(|i| 0.2 + i as f64 * 1e-6));
            let noise = |u: &mut dyn FnMut() -> f64| 0.2 * (u() + u() + u() - 1.5) * 2.0;
            let r: Vec<f64> = x.iter().map(|x| (TAU * x / p + phi).sin() + noise(&mut u)).collect();
            let w = vec![1.0; x.len()];
            let scan = sparse_frequency_scan(&x, &r, &w, &[(0, a), (a, x.len())], (1.0 / 200e-6, 1.0 / 2e-6)).unwrap();
            let f = 1.0 / p;
            assert!(
                scan.frequencies.iter().any(|g| (g - f).abs() <= scan.fine_step),
                "p = {p:e}: {:?} (step {})",
                scan.frequencies.iter().map(|g| 1.0 / g).collect::<Vec<_>>(),
                scan.fine_step
            );
        }
    }
}
