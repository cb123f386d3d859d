//! Stick-slip (crawling) index from the built-in encoder, after seed 002 (CN patent 22015616,
//! 长沙理工大学, "Crawling monitoring method of machine tool based on the signal of built-in encoder").
//!
//! Seed procedure, steps 1–4:
//! 1. sample the encoder position x(n) at interval Δt (seed suggests 2000 Hz);
//! 2. velocity by first difference  `s(n) = (x(n) − x(n−1)) / Δt`;
//! 3. stick-slip index              `SSI = (s_max − s_min) / s_mean`;
//! 4. verdict: `SSI < 1` → no crawling; `SSI ≥ 1` → crawling, the larger SSI the more severe.
//!    The seed gives no further grades (its example: 2.51 at 5 mm/min "severe", 1.07 at 20 mm/min,
//!    0.15 at 80 mm/min), so only the two verdicts are implemented.
//!
//! Additions (not in the seed):
//! - the quantisation floor `2q / (Δt · v)` for an encoder of resolution q: each position sample
//!   carries a rounding error of less than one count, so a first difference can be off by up to
//!   ±q and the velocity range by up to 2q/Δt even on a perfect ramp; an SSI near this floor says
//!   nothing about friction. (A noise-free quantised ramp sits at exactly half of it, q/(Δt·v),
//!   when v·Δt/q is not an integer — see the tests.)
//! - a robust variant using percentiles p_hi, p_lo of s(n) in place of max and min, so that a
//!   single glitch does not decide the verdict.
//! - for a one-way run in the negative direction, s_mean < 0; the index uses |s_mean|.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why a stick-slip index could not be computed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SsiError {
    /// The sampling interval is not a positive finite number.
    #[error("sampling interval dt must be positive and finite, got {0} s")]
    BadInterval(f64),
    /// Too few samples for two velocity values.
    #[error("at least 3 position samples are needed (2 velocity values), got {0}")]
    TooFewSamples(usize),
    /// A position sample is NaN or infinite.
    #[error("position sample {index} must be finite, got {value}")]
    NonFinite {
        /// Index of the offending element, 0-based.
        index: usize,
        /// The offending value, in the unit the message states (m for positions, m/s for feeds).
        value: f64,
    },
    /// The axis did not move on average: SSI is undefined (division by s_mean = 0).
    #[error("mean velocity is zero (x(N) = x(0)); the stick-slip index needs a moving axis")]
    NoMotion,
    /// The encoder resolution is not a positive finite number.
    #[error("encoder resolution q must be positive and finite, got {0} m")]
    BadResolution(f64),
    /// The feed for the quantisation floor is not a positive finite number.
    #[error("feed velocity for the quantisation floor must be non-zero and finite, got {0} m/s")]
    BadFeed(f64),
    /// Percentiles out of order or outside [0, 100].
    #[error("percentiles must satisfy 0 <= lower < upper <= 100, got lower {lower}, upper {upper}")]
    BadPercentiles {
        /// Lower percentile, %.
        lower: f64,
        /// Upper percentile, %.
        upper: f64,
    },
}

/// Crawling verdict of seed 002, step 4.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CrawlVerdict {
    /// SSI < 1: no crawling.
    NoCrawling,
    /// SSI ≥ 1: crawling (the larger SSI, the more severe).
    Crawling,
}

/// Result of a stick-slip index evaluation (seed 002). Velocities in m/s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SsiResult {
    /// SSI = (s_hi − s_lo) / |s_mean| (dimensionless).
    pub ssi: f64,
    /// Upper velocity statistic: s_max, or the upper percentile for the robust variant, m/s.
    pub s_hi: f64,
    /// Lower velocity statistic: s_min, or the lower percentile for the robust variant, m/s.
    pub s_lo: f64,
    /// Mean velocity s_mean = (x(N−1) − x(0)) / ((N−1)·Δt), m/s (the mean of s(n)).
    pub s_mean: f64,
    /// Percentiles used (lower, upper) in %, or None for the seed's max/min.
    pub percentiles: Option<(f64, f64)>,
    /// Verdict of seed 002: Crawling iff SSI ≥ 1.
    pub verdict: CrawlVerdict,
    /// Quantisation floor 2q/(Δt·|s_mean|) when the encoder resolution q was given.
    pub quantisation_floor: Option<f64>,
    /// Number of velocity samples s(n) (N − 1).
    pub n_velocity: usize,
}

/// Velocity by first difference, seed 002 step 2: `s(n) = (x(n) − x(n−1)) / Δt`, n = 1..N−1.
///
/// `x` in m, `dt` in s; returns N − 1 values in m/s.
pub fn velocity_by_difference(x: &[f64], dt: f64) -> Result<Vec<f64>, SsiError> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(SsiError::BadInterval(dt));
    }
    if x.len() < 3 {
        return Err(SsiError::TooFewSamples(x.len()));
    }
    if let Some((index, &value)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(SsiError::NonFinite { index, value });
    }
    Ok(x.windows(2).map(|w| (w[1] - w[0]) / dt).collect())
}

/// Quantisation floor of the stick-slip index: `SSI_q = 2q / (Δt · |v|)`.
///
/// q: encoder resolution (m per count), Δt: sampling interval (s), v: feed (m/s). Below this
/// value an SSI cannot be told from encoder rounding (see the module doc).
pub fn quantisation_floor(q: f64, dt: f64, v: f64) -> Result<f64, SsiError> {
    if !(q.is_finite() && q > 0.0) {
        return Err(SsiError::BadResolution(q));
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(SsiError::BadInterval(dt));
    }
    if !(v.is_finite() && v != 0.0) {
        return Err(SsiError::BadFeed(v));
    }
    Ok(2.0 * q / (dt * v.abs()))
}

/// Most divisors `m` tried by [`lattice_step`] (steps d_min/m).
const LATTICE_DIVISORS: usize = 1000;
/// Fewest non-zero first differences [`lattice_step`] decides on.
const LATTICE_MIN_STEPS: usize = 20;

/// The encoder's count q (m) read from the record itself, for a record whose resolution nobody stated:
/// the largest step `d` such that every first difference `x(n) − x(n−1)` is an integer multiple of `d`,
/// searched as `d = d_min/m` for m = 1..=1000 (`d_min` the smallest non-zero |difference|). A difference
/// counts as a multiple when it lies within `10⁻³·d + 10⁻¹¹·max|x|` of one (the rounding of positions
/// written with 12 or more significant digits).
///
/// Returns None when there is no such step — the record carries noise finer than a count, or was written
/// with too few digits to tell (the tolerance exceeds 5 % of `d`) — or when fewer than 20 differences are
/// non-zero (too few to decide). Noise passes by chance with probability about (2·10⁻³)^20 or less.
/// An encoder counting in steps of 2q returns 2q: the step the record actually resolves, which is what
/// the floor 2q/(Δt·v) needs.
pub fn lattice_step(x: &[f64]) -> Option<f64> {
    let scale = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if !scale.is_finite() {
        return None;
    }
    let steps: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]).abs()).filter(|&d| d > 0.0).collect();
    if steps.len() < LATTICE_MIN_STEPS {
        return None;
    }
    let d_min = steps.iter().copied().fold(f64::INFINITY, f64::min);
    (1..=LATTICE_DIVISORS).map(|m| d_min / m as f64).find(|&d| {
        let tol = 1e-3 * d + 1e-11 * scale;
        tol <= 0.05 * d && steps.iter().all(|&s| (s - (s / d).round() * d).abs() <= tol)
    })
}

/// Percentile of sorted data with linear interpolation between order statistics:
/// rank h = (p/100)·(n − 1), value = s[⌊h⌋] + (h − ⌊h⌋)·(s[⌊h⌋+1] − s[⌊h⌋]).
fn percentile_sorted(sorted: &[f64], p: f64) -> f64 {
    // index: ≥ 2 velocities (velocity_by_difference needs ≥ 3 samples) and 0 ≤ p ≤ 100 (evaluate checks the
    // percentiles), so h is in [0, n − 1] and lo, hi < n.
    let h = p / 100.0 * (sorted.len() - 1) as f64;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

fn evaluate(x: &[f64], dt: f64, q: Option<f64>, percentiles: Option<(f64, f64)>) -> Result<SsiResult, SsiError> {
    let s = velocity_by_difference(x, dt)?;
    // Mean of s(n): the sum telescopes to (x(N−1) − x(0)) / ((N−1)·Δt); use the telescoped form,
    // which has no accumulated rounding.
    // index: velocity_by_difference above refused fewer than 3 samples.
    let s_mean = (x[x.len() - 1] - x[0]) / ((x.len() - 1) as f64 * dt);
    if s_mean == 0.0 {
        return Err(SsiError::NoMotion);
    }
    let (s_hi, s_lo) = match percentiles {
        None => (s.iter().copied().fold(f64::NEG_INFINITY, f64::max), s.iter().copied().fold(f64::INFINITY, f64::min)),
        Some((lower, upper)) => {
            if !(lower.is_finite() && upper.is_finite() && 0.0 <= lower && lower < upper && upper <= 100.0) {
                return Err(SsiError::BadPercentiles { lower, upper });
            }
            let mut sorted = s.clone();
            sorted.sort_by(f64::total_cmp);
            (percentile_sorted(&sorted, upper), percentile_sorted(&sorted, lower))
        }
    };
    let ssi = (s_hi - s_lo) / s_mean.abs();
    let quantisation_floor = match q {
        Some(q) => Some(quantisation_floor(q, dt, s_mean)?),
        None => None,
    };
    Ok(SsiResult {
        ssi,
        s_hi,
        s_lo,
        s_mean,
        percentiles,
        verdict: if ssi >= 1.0 { CrawlVerdict::Crawling } else { CrawlVerdict::NoCrawling },
        quantisation_floor,
        n_velocity: s.len(),
    })
}

/// Stick-slip index of seed 002: `SSI = (s_max − s_min) / s_mean` with `s(n) = (x(n) − x(n−1))/Δt`.
///
/// `x`: encoder positions (m) of a one-way constant-feed run, sampled every `dt` seconds.
/// `resolution`: the encoder's count q (m), if known, to report the floor 2q/(Δt·|s_mean|).
/// Verdict: crawling iff SSI ≥ 1.
///
/// # Example
///
/// ```rust
/// use vmt_estimators::ssi::{stick_slip_index, CrawlVerdict};
/// let dt = 1e-3; // s
/// // A smooth crawl at 1 mm/s: every first-difference velocity is the same, SSI = 0.
/// let smooth: Vec<f64> = (0..1001).map(|i| 1e-3 * dt * i as f64).collect();
/// let r = stick_slip_index(&smooth, dt, None).unwrap();
/// assert!(r.ssi < 1e-9 && r.verdict == CrawlVerdict::NoCrawling);
/// // Stick-slip: the slide stands for one sample, then jumps two. Velocities 0 and 2 mm/s about a
/// // mean of 1 mm/s: SSI = (2 − 0) / 1 = 2.
/// let jerky: Vec<f64> = (0..1001).map(|i| 2e-3 * dt * (i / 2) as f64).collect();
/// let r = stick_slip_index(&jerky, dt, None).unwrap();
/// assert!((r.ssi - 2.0).abs() < 1e-9 && r.verdict == CrawlVerdict::Crawling);
/// ```
pub fn stick_slip_index(x: &[f64], dt: f64, resolution: Option<f64>) -> Result<SsiResult, SsiError> {
    evaluate(x, dt, resolution, None)
}

/// Robust stick-slip index: `SSI_p = (P_upper(s) − P_lower(s)) / s_mean`, percentiles of the
/// first-difference velocity in % (e.g. 1 and 99) with linear interpolation between order
/// statistics. Same inputs and verdict rule as [`stick_slip_index`] (not in seed 002).
pub fn stick_slip_index_robust(
    x: &[f64],
    dt: f64,
    resolution: Option<f64>,
    lower_percentile: f64,
    upper_percentile: f64,
) -> Result<SsiResult, SsiError> {
    evaluate(x, dt, resolution, Some((lower_percentile, upper_percentile)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The count of a quantised record is found from the record alone (random q 1–100 nm, random zero,
    /// random speeds so that a sample moves 0.3–40 counts), to 1e-6 relative; a record with noise of a
    /// tenth of a count on top is not taken for a lattice; a record that moves fewer than 20 times is
    /// not decided.
    #[test]
    fn lattice_step_recovers_the_count_of_a_quantised_record() {
        use rand::{Rng, SeedableRng};
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(77);
        for _ in 0..200 {
            let q = 10f64.powf(rng.gen_range(-9.0..-7.0));
            let zero = rng.gen_range(0.0..q);
            let per_sample = 10f64.powf(rng.gen_range(-0.5..1.6)) * q;
            let x0 = rng.gen_range(-0.2..0.2);
            let exact: Vec<f64> =
                (0..2000).map(|i| x0 + per_sample * i as f64 * (1.0 + 0.3 * (i as f64 * 0.01).sin())).collect();
            let counts: Vec<f64> = exact.iter().map(|x| ((x + zero) / q).floor() * q).collect();
            let d = lattice_step(&counts).expect("a quantised record has a lattice");
            assert!((d / q - 1.0).abs() < 1e-6, "q {q:e}, found {d:e}");
            let noisy: Vec<f64> = counts
                .iter()
                .map(|x| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    x + 0.1 * q * z
                })
                .collect();
            assert_eq!(lattice_step(&noisy), None, "noise taken for a lattice (q {q:e})");
        }
        let still: Vec<f64> = (0..1000).map(|i| 1e-9 * (i / 100) as f64).collect();
        assert_eq!(lattice_step(&still), None, "9 moves are too few to decide");
    }

    /// Ramp with sinusoidal velocity ripple x(t) = v t + (a/ω) sin(ω t), true velocity v + a cos ωt.
    /// Sampled at t_n = t0 + nΔt with M samples per period and t0 = Δt/2, the first difference is
    /// s(n) = v + a·sinc(ωΔt/2)·cos(ω nΔt) (sum-to-product), sinc(u) = sin(u)/u, so with M even
    /// the midpoints hit cos = +1 (n = M) and −1 (n = M/2) exactly. Over an integer number of
    /// periods s_mean = v exactly. Hence SSI = 2a·sinc(π/M)/v exactly, and → 2a/v as M → ∞.
    #[test]
    fn sinusoidal_ripple_gives_the_exact_discrete_index() {
        let v = 5e-3 / 60.0; // 5 mm/min, the seed's slowest feed
        let f = 3.0; // Hz ripple
        let w = 2.0 * PI * f;
        let m = 2000usize; // samples per period → Δt = 1/6000 s
        let dt = 1.0 / (f * m as f64);
        let periods = 3usize;
        for a_over_v in [0.05, 0.6, 1.25] {
            let a = a_over_v * v;
            let x: Vec<f64> = (0..=periods * m)
                .map(|n| {
                    let t = 0.5 * dt + n as f64 * dt;
                    v * t + a / w * (w * t).sin()
                })
                .collect();
            let r = stick_slip_index(&x, dt, None).unwrap();
            let u = PI / m as f64;
            let exact = 2.0 * a * (u.sin() / u) / v;
            // 1e-9 relative: positions ~1e-4 m, differences ~1.4e-8 m → rounding of a difference is
            // ~1e-20/1.4e-8 ≈ 1e-12 relative; 1e-9 leaves margin and would catch any formula error
            // (the sinc factor alone is 4e-7).
            assert!(((r.ssi - exact) / exact).abs() < 1e-9, "SSI {} exact {exact}", r.ssi);
            // Against the continuous 2a/v the discrete value is low by 1 − sinc(π/M) ≈ (π/M)²/6 = 4.1e-7.
            let cont = 2.0 * a_over_v;
            assert!(((r.ssi - cont) / cont).abs() < 0.5e-6);
            assert!((r.s_mean - v).abs() / v < 1e-9);
            let want = if cont >= 1.0 { CrawlVerdict::Crawling } else { CrawlVerdict::NoCrawling };
            assert_eq!(r.verdict, want);
        }
    }

    /// A quantised perfect ramp: x(n) = q·floor(v t_n / q + φ). Every first difference is k or k+1
    /// counts (k = floor(vΔt/q)) when vΔt/q is not an integer, so s_max − s_min = q/Δt exactly and
    /// SSI = q/(Δt s_mean) = half the floor 2q/(Δt s_mean) that [`quantisation_floor`] states as
    /// the bound. s_mean is the true v to within one count over the record: |s_mean − v| ≤ q/(NΔt).
    #[test]
    fn quantised_perfect_ramp_sits_at_half_the_stated_floor() {
        // Seed 002's scale: 0.02 mm grating / 4096 interpolation, 2000 Hz, 5 mm/min.
        let q = 0.02e-3 / 4096.0;
        let dt = 1.0 / 2000.0;
        let v = 5e-3 / 60.0;
        let n = 2000usize;
        let x: Vec<f64> = (0..=n).map(|i| q * ((v * i as f64 * dt) / q + 0.37).floor()).collect();
        let r = stick_slip_index(&x, dt, Some(q)).unwrap();
        let floor = r.quantisation_floor.unwrap();
        // Exact relations (up to rounding ~1e-12 relative in the differences):
        assert!(((r.s_hi - r.s_lo) - q / dt).abs() < 1e-9 * q / dt);
        assert!((r.ssi - 0.5 * floor).abs() < 1e-9 * floor, "SSI {} floor {floor}", r.ssi);
        // Against the nominal floor 2q/(Δt v): s_mean differs from v by at most q/(NΔt), i.e.
        // relative q/(N Δt v) = 4.9e-9/(2000·4.2e-8) = 5.9e-5.
        let nominal = quantisation_floor(q, dt, v).unwrap();
        let rel = q / (n as f64 * dt * v);
        assert!((r.ssi - 0.5 * nominal).abs() <= 0.5 * nominal * rel * 1.01);
        assert!(r.ssi <= floor);
        // The seed's numbers: floor = 2·4.88e-9·2000/8.33e-5 = 0.234 at 5 mm/min.
        assert!((nominal - 0.234375).abs() < 1e-6);
    }

    /// One glitch of 10 counts decides the max/min index but not the 1st–99th percentile one.
    #[test]
    fn robust_variant_ignores_a_single_glitch() {
        let dt = 1e-3;
        let v = 1e-3;
        let mut x: Vec<f64> = (0..=1000).map(|i| v * i as f64 * dt).collect();
        x[500] += 1e-5; // a spike: s jumps +10 mm/s then −10 mm/s
        let plain = stick_slip_index(&x, dt, None).unwrap();
        let robust = stick_slip_index_robust(&x, dt, None, 1.0, 99.0).unwrap();
        assert_eq!(plain.verdict, CrawlVerdict::Crawling);
        // 2 outliers in 1000 samples lie beyond the 1st/99th percentile ranks (9.99 of 999 steps),
        // so the robust range is the rounding noise of the constant differences (< 1e-9 relative).
        assert!(robust.ssi < 1e-9, "robust SSI {}", robust.ssi);
        assert_eq!(robust.verdict, CrawlVerdict::NoCrawling);
    }

    #[test]
    fn negative_direction_and_errors() {
        let x: Vec<f64> = (0..100).map(|i| -1e-6 * i as f64).collect();
        let r = stick_slip_index(&x, 1e-3, Some(1e-9)).unwrap();
        assert!(r.s_mean < 0.0 && r.ssi < 1e-6);
        assert!(matches!(stick_slip_index(&x, 0.0, None), Err(SsiError::BadInterval(_))));
        assert!(matches!(stick_slip_index(&x[..2], 1e-3, None), Err(SsiError::TooFewSamples(2))));
        assert_eq!(stick_slip_index(&[1.0, 2.0, 1.0], 1e-3, None), Err(SsiError::NoMotion));
        let mut bad = x.clone();
        bad[7] = f64::NAN;
        assert!(stick_slip_index(&bad, 1e-3, None).unwrap_err().to_string().contains("sample 7"));
        assert!(matches!(stick_slip_index_robust(&x, 1e-3, None, 99.0, 1.0), Err(SsiError::BadPercentiles { .. })));
        assert!(matches!(quantisation_floor(0.0, 1e-3, 1.0), Err(SsiError::BadResolution(_))));
    }
}
