//! Spectra of a residual (DESIGN.md §8, "where it fails": spatial and temporal spectrum).
//!
//! - [`amplitude_spectrum`]: one-sided amplitude spectrum of a uniformly sampled residual (realfft);
//! - [`ls_periodogram`]: least-squares periodogram for irregular sampling — the generalised
//!   Lomb–Scargle periodogram with a floating mean and weights (Zechmeister & Kürster 2009,
//!   A&A 496:577), evaluated by an explicit sine + cosine + offset fit at each frequency;
//! - [`frequency_grid`]: a frequency grid for it, spaced finely enough not to miss a peak.
//!
//! "Frequency" is in cycles per unit of the sampling coordinate: Hz for time, 1/m for position
//! (a spatial frequency; the wavelength is its inverse).

use super::lsq::small_lstsq;
use super::{check_finite, check_len, check_min, ModelCheckError, Sigma};
use realfft::RealFftPlanner;
use serde::{Deserialize, Serialize};

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
/// [`ls_periodogram`] (the others by rotation).
const RESEED: usize = 64;

/// Generalised Lomb–Scargle periodogram (Zechmeister & Kürster 2009): at each trial frequency f
/// fit r_i ≈ c + a·cos(2πf x_i) + b·sin(2πf x_i) by weighted least squares (weights 1/σ_i²) and
/// report the amplitude √(a² + b²) and the power p(f) = 1 − χ²(f)/χ²₀, χ²₀ = Σ ((r_i − r̄_w)/σ_i)².
///
/// `x` are the sample coordinates (time in s or position in m, any order, need not be uniform).
/// At a frequency where sine or cosine is degenerate on these samples (e.g. an alias of 0) the
/// degenerate column is dropped and its coefficient is 0.
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
    let mut amplitude = Vec::with_capacity(frequencies.len());
    let mut power = Vec::with_capacity(frequencies.len());
    let mut c = vec![0.0; n];
    let mut s = vec![0.0; n];
    // On an evenly spaced grid (as [`frequency_grid`] makes) each sample's cos/sin at the next
    // frequency is a rotation of the last by Δω·x_i (angle addition), evaluated afresh every
    // [`RESEED`] frequencies so that the rounding (≈ k·ε after k rotations) stays below 1e-13.
    let tau = 2.0 * std::f64::consts::PI;
    let step = match frequencies {
        [f0, f1, ..]
            if frequencies
                .iter()
                .enumerate()
                .all(|(k, f)| (f - (f0 + k as f64 * (f1 - f0))).abs() <= 1e-12 * f.abs()) =>
        {
            Some(f1 - f0)
        }
        _ => None,
    };
    let rot: Vec<(f64, f64)> = match step {
        Some(df) => x.iter().map(|xi| (tau * df * xi).sin_cos()).collect(),
        None => Vec::new(),
    };
    for (k, &f) in frequencies.iter().enumerate() {
        if step.is_none() || k % RESEED == 0 {
            let om = tau * f;
            for i in 0..n {
                let (si, ci) = (om * x[i]).sin_cos();
                c[i] = ci;
                s[i] = si;
            }
        } else {
            for i in 0..n {
                let (sd, cd) = rot[i];
                (s[i], c[i]) = (s[i] * cd + c[i] * sd, c[i] * cd - s[i] * sd);
            }
        }
        let (beta, chi) = small_lstsq(&[ones.as_slice(), c.as_slice(), s.as_slice()], residual, &w);
        amplitude.push(beta[1].hypot(beta[2]));
        power.push((1.0 - chi / chi0).clamp(0.0, 1.0));
    }
    Ok(Periodogram { frequency: frequencies.to_vec(), amplitude, power })
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
}
