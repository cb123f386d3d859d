//! Residual statistics of `vmt compare` (DESIGN.md §8): RMS, noise-normalised RMS, NRMSE fit
//! percentage, autocorrelation with white-noise bounds, Ljung–Box, binned residuals, and a
//! noise-sigma estimate from the data.
//!
//! References: Box, Jenkins & Reinsel, *Time Series Analysis* (sample autocorrelation and its
//! ±1.96/√N bounds); Ljung & Box (1978), Biometrika 65(2):297–303; Ljung, *System
//! Identification* (NRMSE "fit" as in MATLAB `compare`); Rousseeuw & Croux (1993) (MAD
//! consistency factor 1.4826); Numerical Recipes §6.1–6.2 (ln Γ and the incomplete gamma).

use super::{check_finite, check_len, check_min, ModelCheckError};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Root mean square of the residual: RMS = √( (1/N) Σ r_i² ), in the residual's unit.
pub fn rms(residual: &[f64]) -> Result<f64, ModelCheckError> {
    check_min("rms", 1, residual.len())?;
    check_finite("residual", residual)?;
    Ok((residual.iter().map(|r| r * r).sum::<f64>() / residual.len() as f64).sqrt())
}

/// Noise-normalised RMS: √( (1/N) Σ (r_i/σ_i)² ), dimensionless; 1.0 means the residual is at
/// the noise level (FORMAT.md §4 `normalized_rms`).
///
/// `sigma` holds one σ per sample, or a single value used for all samples; every σ must be
/// positive and finite.
pub fn normalized_rms(residual: &[f64], sigma: &[f64]) -> Result<f64, ModelCheckError> {
    check_min("normalized_rms", 1, residual.len())?;
    check_finite("residual", residual)?;
    let w = if sigma.len() == 1 {
        super::Sigma::Constant(sigma[0]).weights(residual.len())?
    } else {
        super::Sigma::PerSample(sigma.to_vec()).weights(residual.len())?
    };
    let s: f64 = residual.iter().zip(&w).map(|(r, w)| (r * w).powi(2)).sum();
    Ok((s / residual.len() as f64).sqrt())
}

/// NRMSE fit percentage (Ljung, *System Identification*; MATLAB `compare`):
/// fit = 100 · (1 − ‖y − ŷ‖₂ / ‖y − ȳ‖₂), in percent; 100 is a perfect prediction, 0 is no
/// better than the mean, negative is worse than the mean.
///
/// Errors when the measured `y` is constant (the fit is undefined).
pub fn fit_percent(measured: &[f64], predicted: &[f64]) -> Result<f64, ModelCheckError> {
    check_min("fit_percent", 2, measured.len())?;
    check_len("predicted", measured.len(), predicted.len())?;
    check_finite("measured", measured)?;
    check_finite("predicted", predicted)?;
    let mean = measured.iter().sum::<f64>() / measured.len() as f64;
    let num: f64 = measured.iter().zip(predicted).map(|(y, p)| (y - p).powi(2)).sum::<f64>().sqrt();
    let den: f64 = measured.iter().map(|y| (y - mean).powi(2)).sum::<f64>().sqrt();
    if den == 0.0 {
        return Err(ModelCheckError::Invalid(
            "fit_percent: the measured values are constant, so ‖y − mean y‖ = 0 and the fit \
             percentage is undefined"
                .into(),
        ));
    }
    Ok(100.0 * (1.0 - num / den))
}

/// Sample autocorrelation of a residual with its white-noise bounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Autocorrelation {
    /// ρ_k for k = 0..=max_lag (ρ_0 = 1), dimensionless.
    pub rho: Vec<f64>,
    /// The 95 % white-noise bound ±1.96/√N.
    pub bound: f64,
    /// Fraction of the lags 1..=max_lag with |ρ_k| > bound (about 0.05 for white noise).
    pub fraction_outside: f64,
    /// Number of samples N.
    pub n: usize,
}

/// Sample autocorrelation (Box–Jenkins):
/// ρ_k = Σ_{t=1}^{N−k} (r_t − r̄)(r_{t+k} − r̄) / Σ_{t=1}^{N} (r_t − r̄)², k = 0..=K,
/// with the large-sample white-noise bounds ±1.96/√N and the fraction of lags 1..=K outside.
///
/// Needs 1 ≤ K < N and a residual that is not constant.
pub fn autocorrelation(residual: &[f64], max_lag: usize) -> Result<Autocorrelation, ModelCheckError> {
    let n = residual.len();
    if max_lag == 0 {
        return Err(ModelCheckError::Invalid("autocorrelation: max_lag must be at least 1, got 0".into()));
    }
    check_min("autocorrelation (max_lag + 1)", max_lag + 1, n)?;
    check_finite("residual", residual)?;
    let mean = residual.iter().sum::<f64>() / n as f64;
    let d: Vec<f64> = residual.iter().map(|r| r - mean).collect();
    let c0: f64 = d.iter().map(|x| x * x).sum();
    if c0 == 0.0 {
        return Err(ModelCheckError::Invalid(
            "autocorrelation: the residual is constant, its autocorrelation is undefined".into(),
        ));
    }
    let rho: Vec<f64> =
        (0..=max_lag).map(|k| d[..n - k].iter().zip(&d[k..]).map(|(a, b)| a * b).sum::<f64>() / c0).collect();
    let bound = 1.96 / (n as f64).sqrt();
    let outside = rho[1..].iter().filter(|r| r.abs() > bound).count();
    Ok(Autocorrelation { rho, bound, fraction_outside: outside as f64 / max_lag as f64, n })
}

/// Result of the Ljung–Box portmanteau test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LjungBox {
    /// Q = N(N+2) Σ_{k=1}^{K} ρ_k²/(N−k), dimensionless.
    pub q: f64,
    /// Degrees of freedom K − (number of fitted parameters).
    pub dof: usize,
    /// P(χ²_dof > Q): small values reject whiteness.
    pub p_value: f64,
    /// Number of lags K.
    pub lags: usize,
}

/// Ljung–Box test of residual whiteness (Ljung & Box 1978):
/// Q = N(N+2) Σ_{k=1}^{K} ρ_k²/(N−k), p = P(χ²_{K−m} > Q) with m = `fitted_params`.
///
/// Needs K − m ≥ 1 and K < N.
pub fn ljung_box(residual: &[f64], max_lag: usize, fitted_params: usize) -> Result<LjungBox, ModelCheckError> {
    if max_lag <= fitted_params {
        return Err(ModelCheckError::Invalid(format!(
            "ljung_box: the number of lags ({max_lag}) must exceed the number of fitted \
             parameters ({fitted_params}) to leave at least one degree of freedom"
        )));
    }
    let ac = autocorrelation(residual, max_lag)?;
    let n = ac.n as f64;
    let q = n * (n + 2.0) * (1..=max_lag).map(|k| ac.rho[k].powi(2) / (n - k as f64)).sum::<f64>();
    let dof = max_lag - fitted_params;
    Ok(LjungBox { q, dof, p_value: chi_square_sf(q, dof as f64)?, lags: max_lag })
}

/// Survival function of the χ² distribution, P(χ²_ν > x) = Q(ν/2, x/2), with Q the regularised
/// upper incomplete gamma function (Numerical Recipes §6.2: series for x < a+1, Lentz continued
/// fraction otherwise; ln Γ by the Lanczos approximation, g = 7, 9 terms).
///
/// Needs ν > 0; x ≤ 0 gives 1.
pub fn chi_square_sf(x: f64, dof: f64) -> Result<f64, ModelCheckError> {
    if !(dof.is_finite() && dof > 0.0) {
        return Err(ModelCheckError::Invalid(format!(
            "chi_square_sf: degrees of freedom must be positive and finite, got {dof}"
        )));
    }
    if x.is_nan() {
        return Err(ModelCheckError::Invalid("chi_square_sf: x must be a number, got NaN".into()));
    }
    if x <= 0.0 {
        return Ok(1.0);
    }
    if x.is_infinite() {
        return Ok(0.0);
    }
    Ok(gamma_q(0.5 * dof, 0.5 * x))
}

/// The x with P(χ²_ν > x) = p ([`chi_square_sf`] inverted by bisection on [0, ν + 40·√(2ν) + 100],
/// 200 halvings: exact to rounding). Needs 0 < p < 1 and ν > 0.
pub fn chi_square_isf(p: f64, dof: f64) -> Result<f64, ModelCheckError> {
    if !(p > 0.0 && p < 1.0) {
        return Err(ModelCheckError::Invalid(format!("chi_square_isf: p must be in (0, 1), got {p}")));
    }
    let (mut lo, mut hi) = (0.0, dof + 40.0 * (2.0 * dof).sqrt() + 100.0);
    chi_square_sf(hi, dof)?;
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi_square_sf(mid, dof)? > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(0.5 * (lo + hi))
}

/// ln Γ(z) for z > 0 (Lanczos, g = 7, n = 9; relative error ~1e-15).
fn ln_gamma(z: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if z < 0.5 {
        // Reflection: Γ(z)Γ(1−z) = π / sin(πz).
        let pi = std::f64::consts::PI;
        return (pi / (pi * z).sin()).ln() - ln_gamma(1.0 - z);
    }
    let z = z - 1.0;
    let mut a = C[0];
    let t = z + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (z + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (z + 0.5) * t.ln() - t + a.ln()
}

/// Regularised upper incomplete gamma Q(a, x) = Γ(a, x)/Γ(a), a > 0, x > 0.
fn gamma_q(a: f64, x: f64) -> f64 {
    let ln_pre = -x + a * x.ln() - ln_gamma(a);
    if x < a + 1.0 {
        // Series for P(a, x) = e^{−x} x^a / Γ(a) · Σ x^n / (a (a+1) … (a+n)).
        let mut term = 1.0 / a;
        let mut sum = term;
        let mut ap = a;
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        (1.0 - sum * ln_pre.exp()).clamp(0.0, 1.0)
    } else {
        // Continued fraction for Q(a, x) (modified Lentz).
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        (ln_pre.exp() * h).clamp(0.0, 1.0)
    }
}

/// Residual statistics in one bin of a categorical key (direction, speed, run...).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LabelBin<K> {
    /// The key value of this bin.
    pub key: K,
    /// Number of samples in the bin.
    pub count: usize,
    /// Mean residual (1/n) Σ r_i, in the residual's unit.
    pub mean: f64,
    /// RMS residual √((1/n) Σ r_i²), in the residual's unit.
    pub rms: f64,
}

/// Residual grouped by a categorical key (e.g. direction +1/−1 for backlash, a speed index, a
/// run name): count, mean and RMS per distinct key, in key order.
pub fn bin_by_label<K: Ord + Clone>(residual: &[f64], labels: &[K]) -> Result<Vec<LabelBin<K>>, ModelCheckError> {
    check_len("labels", residual.len(), labels.len())?;
    check_finite("residual", residual)?;
    let mut acc: BTreeMap<K, (usize, f64, f64)> = BTreeMap::new();
    for (r, k) in residual.iter().zip(labels) {
        let e = acc.entry(k.clone()).or_insert((0, 0.0, 0.0));
        e.0 += 1;
        e.1 += r;
        e.2 += r * r;
    }
    Ok(acc
        .into_iter()
        .map(|(key, (count, s, s2))| LabelBin { key, count, mean: s / count as f64, rms: (s2 / count as f64).sqrt() })
        .collect())
}

/// Residual statistics in one interval [lower, upper) of a continuous key (the last bin also
/// includes its upper edge).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RangeBin {
    /// Lower edge, in the key's unit (e.g. m for position, s for time).
    pub lower: f64,
    /// Upper edge, in the key's unit.
    pub upper: f64,
    /// Number of samples in the bin.
    pub count: usize,
    /// Mean residual, `None` for an empty bin.
    pub mean: Option<f64>,
    /// RMS residual, `None` for an empty bin.
    pub rms: Option<f64>,
}

/// Residual binned by a continuous key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BinnedResidual {
    /// One entry per interval between consecutive edges.
    pub bins: Vec<RangeBin>,
    /// Samples whose key falls outside [first edge, last edge].
    pub outside: usize,
}

/// Residual binned by a continuous key (position, time, speed): for each interval
/// [e_j, e_{j+1}) (the last one closed) the count, mean (1/n) Σ r_i and RMS √((1/n) Σ r_i²).
///
/// `edges` must be finite and strictly increasing, at least two of them.
pub fn bin_by_edges(residual: &[f64], keys: &[f64], edges: &[f64]) -> Result<BinnedResidual, ModelCheckError> {
    check_len("keys", residual.len(), keys.len())?;
    check_finite("residual", residual)?;
    check_finite("keys", keys)?;
    check_finite("edges", edges)?;
    if edges.len() < 2 {
        return Err(ModelCheckError::Invalid(format!("bin_by_edges: need at least 2 edges, got {}", edges.len())));
    }
    for w in edges.windows(2) {
        if w[1] <= w[0] {
            return Err(ModelCheckError::Invalid(format!(
                "bin_by_edges: edges must be strictly increasing, got {} after {}",
                w[1], w[0]
            )));
        }
    }
    let nb = edges.len() - 1;
    let mut acc = vec![(0usize, 0.0f64, 0.0f64); nb];
    let mut outside = 0;
    let last = edges[nb];
    for (r, k) in residual.iter().zip(keys) {
        if *k < edges[0] || *k > last {
            outside += 1;
            continue;
        }
        // Index of the last edge ≤ k, clamped so that k == last goes to the last bin.
        let j = (edges.partition_point(|e| e <= k) - 1).min(nb - 1);
        acc[j].0 += 1;
        acc[j].1 += r;
        acc[j].2 += r * r;
    }
    let bins = acc
        .into_iter()
        .enumerate()
        .map(|(j, (count, s, s2))| RangeBin {
            lower: edges[j],
            upper: edges[j + 1],
            count,
            mean: (count > 0).then(|| s / count as f64),
            rms: (count > 0).then(|| (s2 / count as f64).sqrt()),
        })
        .collect();
    Ok(BinnedResidual { bins, outside })
}

/// `n_bins + 1` equally spaced edges from `min` to `max` (for [`bin_by_edges`]).
pub fn uniform_edges(min: f64, max: f64, n_bins: usize) -> Result<Vec<f64>, ModelCheckError> {
    if !(min.is_finite() && max.is_finite() && max > min) || n_bins == 0 {
        return Err(ModelCheckError::Invalid(format!(
            "uniform_edges: need finite min < max and n_bins ≥ 1, got min = {min}, max = {max}, \
             n_bins = {n_bins}"
        )));
    }
    let h = (max - min) / n_bins as f64;
    Ok((0..=n_bins).map(|j| if j == n_bins { max } else { min + h * j as f64 }).collect())
}

/// Minimum number of samples for [`estimate_noise_sigma`]: with 20 samples (19 differences) the
/// MAD-based estimate has a relative standard error of roughly 30 %; below that it is not useful.
pub const MIN_SAMPLES_NOISE_SIGMA: usize = 20;

/// Pooled within-group scatter of repeated readings (the ISO 230-2 repeatability sum): the values
/// grouped by `key` (e.g. target and approach direction), SS = Σ_g Σ_i (y_gi − ȳ_g)², with
/// N − G degrees of freedom. Returns (SS, dof), or None when no reading is repeated. σ̂ = √(SS/dof)
/// is the unbiased pooled estimate of one reading's noise when every group shares one mean.
pub fn pooled_group_scatter<K: Ord>(readings: impl IntoIterator<Item = (K, f64)>) -> Option<(f64, usize)> {
    let mut groups: std::collections::BTreeMap<K, Vec<f64>> = std::collections::BTreeMap::new();
    let mut n: usize = 0;
    for (k, v) in readings {
        groups.entry(k).or_default().push(v);
        n += 1;
    }
    let dof = n.checked_sub(groups.len()).filter(|d| *d > 0)?;
    let ss = groups
        .values()
        .map(|g| {
            let m = g.iter().sum::<f64>() / g.len() as f64;
            g.iter().map(|v| (v - m).powi(2)).sum::<f64>()
        })
        .sum();
    Some((ss, dof))
}

/// Noise standard deviation estimated from the data, for a residual whose noise level the
/// measurement set does not give, in the residual's unit.
///
/// Uses successive differences d_i = r_{i+1} − r_i (a smooth signal cancels, a slope becomes a
/// constant offset) and their median absolute deviation (robust to the few large jumps of a
/// direction reversal or a step):
/// σ̂ = 1.4826 · median_i |d_i − median(d)| / √2,
/// where 1.4826 = 1/Φ⁻¹(3/4) makes the MAD consistent for a Gaussian and √2 because
/// Var(d_i) = 2σ² for white noise. Samples must be in acquisition order. A signal that changes
/// noticeably from one sample to the next (a resonance above a quarter of the sample rate)
/// inflates the estimate.
///
/// Errors with fewer than [`MIN_SAMPLES_NOISE_SIGMA`] samples, and when the estimate is zero
/// (more than half of the differences are identical, e.g. a quantised or constant residual).
pub fn estimate_noise_sigma(residual: &[f64]) -> Result<f64, ModelCheckError> {
    if residual.len() < MIN_SAMPLES_NOISE_SIGMA {
        return Err(ModelCheckError::TooLittleDataForSigma { need: MIN_SAMPLES_NOISE_SIGMA, got: residual.len() });
    }
    check_finite("residual", residual)?;
    let d: Vec<f64> = residual.windows(2).map(|w| w[1] - w[0]).collect();
    let med = median(&d);
    let dev: Vec<f64> = d.iter().map(|x| (x - med).abs()).collect();
    let sigma = 1.4826 * median(&dev) / std::f64::consts::SQRT_2;
    if sigma > 0.0 {
        Ok(sigma)
    } else {
        Err(ModelCheckError::Invalid(
            "estimate_noise_sigma: the estimate is zero (more than half of the successive \
             differences are equal: constant or coarsely quantised residual); give sigma explicitly"
                .into(),
        ))
    }
}

fn median(xs: &[f64]) -> f64 {
    let mut v = xs.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi_square_isf_inverts_the_survival_function() {
        // Tables (Abramowitz & Stegun 26.8): χ²_{10} upper 5 % point 18.307, lower 5 % point 3.940.
        assert!((chi_square_isf(0.05, 10.0).unwrap() - 18.307).abs() < 1e-3);
        assert!((chi_square_isf(0.95, 10.0).unwrap() - 3.940).abs() < 1e-3);
        assert!(chi_square_isf(0.0, 10.0).is_err() && chi_square_isf(0.5, 0.0).is_err());
    }

    #[test]
    fn nrmse_fit_hand_worked() {
        // y = 1,2,3,4; ŷ = 1,2,3,5: ‖y − ŷ‖ = 1, ȳ = 2.5, ‖y − ȳ‖ = √5
        // → fit = 100(1 − 1/√5) = 55.27864045 %.
        let f = fit_percent(&[1.0, 2.0, 3.0, 4.0], &[1.0, 2.0, 3.0, 5.0]).unwrap();
        // Tolerance: f64 rounding of a handful of operations.
        assert!((f - 55.278_640_450_004_2).abs() < 1e-10, "{f}");
        assert!(fit_percent(&[2.0, 2.0], &[1.0, 2.0]).is_err());
    }

    #[test]
    fn autocorrelation_hand_worked() {
        // r = 1,2,3,4,5: deviations −2,−1,0,1,2, Σd² = 10;
        // ρ1 = (2+0+0+2)/10 = 0.4, ρ2 = (0−1+0)/10 = −0.1, ρ3 = (−2−2)/10 = −0.4, ρ4 = −4/10.
        let ac = autocorrelation(&[1.0, 2.0, 3.0, 4.0, 5.0], 4).unwrap();
        let want = [1.0, 0.4, -0.1, -0.4, -0.4];
        for (g, w) in ac.rho.iter().zip(want) {
            assert!((g - w).abs() < 1e-15, "{:?}", ac.rho); // exact decimal arithmetic
        }
        // bound 1.96/√5 = 0.8765: no lag outside.
        assert!((ac.bound - 1.96 / 5f64.sqrt()).abs() < 1e-15);
        assert_eq!(ac.fraction_outside, 0.0);
        // r = 1,−1,1,−1: ρ1 = −3/4, ρ2 = 2/4, ρ3 = −1/4.
        let ac = autocorrelation(&[1.0, -1.0, 1.0, -1.0], 3).unwrap();
        assert_eq!(ac.rho, vec![1.0, -0.75, 0.5, -0.25]);
        assert!(autocorrelation(&[1.0, 2.0], 2).is_err());
        assert!(autocorrelation(&[1.0, f64::NAN, 2.0], 1).is_err());
    }

    #[test]
    fn ljung_box_hand_worked() {
        // r = 1,2,3,4,5, K = 2: Q = 5·7·(0.4²/4 + 0.1²/3) = 35·(0.04 + 0.003333) = 1.516667.
        let lb = ljung_box(&[1.0, 2.0, 3.0, 4.0, 5.0], 2, 0).unwrap();
        assert!((lb.q - 35.0 * (0.04 + 0.01 / 3.0)).abs() < 1e-12);
        // χ²_2 survival is exp(−Q/2) exactly.
        assert!((lb.p_value - (-lb.q / 2.0).exp()).abs() < 1e-14);
        assert!(ljung_box(&[1.0, 2.0, 3.0, 4.0, 5.0], 2, 2).is_err());
    }

    #[test]
    fn chi_square_sf_matches_tables() {
        // Tabulated 95 % quantiles: χ²_1 3.841458820694124, χ²_10 18.307038053275146,
        // χ²_100 124.34211340400407 (scipy.stats.chi2.ppf(0.95, ν)); 1e-10 is far below the
        // printed 16 digits' effect on p and above the series/continued-fraction accuracy.
        for (x, nu) in [(3.841458820694124, 1.0), (18.307038053275146, 10.0), (124.34211340400407, 100.0)] {
            let p = chi_square_sf(x, nu).unwrap();
            assert!((p - 0.05).abs() < 1e-10, "ν = {nu}: {p}");
        }
        // χ²_2: exp(−x/2) exactly; χ²_4: (1 + x/2) exp(−x/2).
        for x in [0.1, 1.0, 5.0, 40.0] {
            assert!((chi_square_sf(x, 2.0).unwrap() - (-x / 2.0f64).exp()).abs() < 1e-14);
            let want = (1.0 + x / 2.0) * (-x / 2.0f64).exp();
            assert!((chi_square_sf(x, 4.0).unwrap() - want).abs() < 1e-13);
        }
        assert_eq!(chi_square_sf(-1.0, 3.0).unwrap(), 1.0);
        assert!(chi_square_sf(1.0, 0.0).is_err());
    }

    #[test]
    fn binning_counts_means_and_edges() {
        let r = [1.0, 3.0, -2.0, 2.0, 5.0];
        let k = [0.0, 0.5, 1.0, 2.0, 3.5];
        let b = bin_by_edges(&r, &k, &[0.0, 1.0, 2.0]).unwrap();
        // [0,1): 1, 3 → mean 2, rms √5; [1,2] (last bin closed): −2, 2 → mean 0, rms 2.
        assert_eq!(b.outside, 1);
        assert_eq!((b.bins[0].count, b.bins[1].count), (2, 2));
        assert_eq!(b.bins[0].mean, Some(2.0));
        assert!((b.bins[0].rms.unwrap() - 5f64.sqrt()).abs() < 1e-15);
        assert_eq!((b.bins[1].mean, b.bins[1].rms), (Some(0.0), Some(2.0)));
        assert!(bin_by_edges(&r, &k, &[0.0, 2.0, 1.0]).is_err());
        let lb = bin_by_label(&r, &[1, -1, 1, -1, 1]).unwrap();
        assert_eq!(lb[0].key, -1);
        assert_eq!((lb[0].count, lb[0].mean), (2, 2.5));
        assert_eq!((lb[1].count, lb[1].mean), (3, 4.0 / 3.0));
        assert_eq!(uniform_edges(0.0, 1.0, 4).unwrap(), vec![0.0, 0.25, 0.5, 0.75, 1.0]);
    }

    #[test]
    fn noise_sigma_needs_enough_samples() {
        let e = estimate_noise_sigma(&[0.0; 5]).unwrap_err();
        assert_eq!(e.to_string(), "too little data to estimate the noise sigma: need ≥ 20 samples, got 5");
        assert!(estimate_noise_sigma(&[1.0; 30]).is_err()); // zero estimate rejected
    }

    #[test]
    fn rms_and_normalized_rms() {
        assert!((rms(&[3.0, -4.0]).unwrap() - 12.5f64.sqrt()).abs() < 1e-15);
        // r/σ = 1, −1 → 1.
        assert_eq!(normalized_rms(&[2.0, -4.0], &[2.0, 4.0]).unwrap(), 1.0);
        assert_eq!(normalized_rms(&[2.0, -2.0], &[2.0]).unwrap(), 1.0);
        assert!(normalized_rms(&[1.0, 1.0], &[1.0, 0.0]).is_err());
        assert!(normalized_rms(&[1.0, 1.0], &[1.0, 1.0, 1.0]).is_err());
        assert!(rms(&[]).is_err());
    }
}
