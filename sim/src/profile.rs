//! Error-motion profiles: a function of the axis position (m) giving an error value (m or rad).
//!
//! A profile is a sum of terms, each one of the shapes of FORMAT.md §2: a polynomial, harmonics,
//! a seeded random profile, or a table. Each term gives its value and its first and second
//! derivatives in position, so dynamics tests can compare an accelerometer with v²·E''(x).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// One harmonic term: amplitude·sin(2π·x/wavelength + phase).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Harmonic {
    /// Amplitude in the unit of the error motion (m or rad).
    pub amplitude: f64,
    /// Spatial wavelength, m (> 0).
    pub wavelength: f64,
    /// Phase, rad.
    #[serde(default)]
    pub phase: f64,
}

/// A seeded random profile: a stationary Gaussian process of the given RMS and Gaussian
/// correlation function rms²·exp(−d²/(2ℓ²)), drawn by the spectral method (a sum of cosines with
/// wavenumbers drawn from N(0, 1/ℓ²)), so it is smooth, evaluable anywhere, and reproducible.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RandomProfile {
    /// Root mean square of the profile over realisations, in the unit of the error motion (m or rad).
    pub rms: f64,
    /// Correlation length ℓ, m (> 0).
    pub correlation_length: f64,
    /// Seed of the draw: the same seed gives the same profile.
    pub seed: u64,
}

/// Number of cosines in a random profile.
const RANDOM_TERMS: usize = 64;

/// One term of a profile.
#[derive(Clone, Debug, PartialEq)]
pub enum Term {
    /// Σ c_i·x^i, x in m.
    Poly(Vec<f64>),
    /// Σ amplitude·sin(2π·x/wavelength + phase) over the harmonics.
    Harmonics(Vec<Harmonic>),
    /// Expanded random profile: (amplitude, wavenumber rad/m, phase) per cosine.
    Random {
        /// The profile as declared (RMS, correlation length, seed).
        spec: RandomProfile,
        /// The drawn cosines: value = Σ a·cos(k·x + φ).
        cosines: Vec<(f64, f64, f64)>,
    },
    /// Linear interpolation in a table of (position, value), positions strictly increasing;
    /// constant beyond the ends.
    Table {
        /// Positions, m, strictly increasing.
        x: Vec<f64>,
        /// Values at `x`, in the unit of the error motion (m or rad).
        y: Vec<f64>,
    },
}

/// An error motion as a function of axis position: the sum of its terms (zero if none).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Profile {
    /// The terms, summed.
    pub terms: Vec<Term>,
}

impl Term {
    /// Expands a random-profile specification into its cosines (deterministic in `spec.seed`).
    pub fn random(spec: RandomProfile) -> Term {
        let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
        let amp = spec.rms * (2.0 / RANDOM_TERMS as f64).sqrt();
        let cosines = (0..RANDOM_TERMS)
            .map(|_| {
                let z: f64 = rng.sample(StandardNormal);
                let k = z / spec.correlation_length;
                let phase = rng.gen::<f64>() * std::f64::consts::TAU;
                (amp, k, phase)
            })
            .collect();
        Term::Random { spec, cosines }
    }

    /// Value, first and second derivative at position x.
    pub fn eval3(&self, x: f64) -> [f64; 3] {
        match self {
            Term::Poly(c) => {
                let (mut v, mut d1, mut d2) = (0.0, 0.0, 0.0);
                for (i, ci) in c.iter().enumerate().rev() {
                    let fi = i as f64;
                    v = v * x + ci;
                    if i >= 1 {
                        d1 = d1 * x + fi * ci;
                    }
                    if i >= 2 {
                        d2 = d2 * x + fi * (fi - 1.0) * ci;
                    }
                }
                [v, d1, d2]
            }
            Term::Harmonics(h) => h.iter().fold([0.0; 3], |acc, hi| {
                let k = std::f64::consts::TAU / hi.wavelength;
                let (s, c) = (k * x + hi.phase).sin_cos();
                [acc[0] + hi.amplitude * s, acc[1] + hi.amplitude * k * c, acc[2] - hi.amplitude * k * k * s]
            }),
            Term::Random { cosines, .. } => cosines.iter().fold([0.0; 3], |acc, &(a, k, p)| {
                let (s, c) = (k * x + p).sin_cos();
                [acc[0] + a * c, acc[1] - a * k * s, acc[2] - a * k * k * c]
            }),
            Term::Table { x: xs, y: ys } => {
                let n = xs.len();
                if n == 0 {
                    return [0.0; 3];
                }
                if x <= xs[0] || n == 1 {
                    return [ys[0], 0.0, 0.0];
                }
                if x >= xs[n - 1] {
                    return [ys[n - 1], 0.0, 0.0];
                }
                let i = xs.partition_point(|&xi| xi <= x) - 1;
                let s = (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i]);
                [ys[i] + s * (x - xs[i]), s, 0.0]
            }
        }
    }
}

impl Profile {
    /// The zero profile (no terms).
    pub fn zero() -> Profile {
        Profile::default()
    }

    /// The polynomial Σ c_i·x^i (x in m) with `coeffs` = [c_0, c_1, …].
    pub fn poly(coeffs: Vec<f64>) -> Profile {
        Profile { terms: vec![Term::Poly(coeffs)] }
    }

    /// The sum of harmonics Σ a·sin(2π·x/λ + φ).
    pub fn harmonics(h: Vec<Harmonic>) -> Profile {
        Profile { terms: vec![Term::Harmonics(h)] }
    }

    /// Whether the profile has no terms (identically zero).
    pub fn is_zero(&self) -> bool {
        self.terms.is_empty()
    }

    /// Value at position x (m).
    pub fn value(&self, x: f64) -> f64 {
        self.eval3(x)[0]
    }

    /// Value, first and second derivative with respect to position at x.
    pub fn eval3(&self, x: f64) -> [f64; 3] {
        self.terms.iter().fold([0.0; 3], |acc, t| {
            let e = t.eval3(x);
            [acc[0] + e[0], acc[1] + e[1], acc[2] + e[2]]
        })
    }

    /// Mean second derivative over [a, b] (1/m times the profile's unit):
    ///
    /// ```text
    /// P̄''(a, b) = (P'(b) − P'(a)) / (b − a)            (P''(a) when b = a)
    /// ```
    ///
    /// This is what an accelerometer that averages over one sample interval sees of a profile
    /// crossed at constant velocity v: the mean acceleration v²·P̄'' between the positions of two
    /// successive samples (the simulator's reading is the difference of the point velocities
    /// v·(1 + P') at the two samples over the interval, `vmt_sim::sensors::true_readings`). Per
    /// term: polynomials and harmonics by their analytic slopes; a random profile by the analytic
    /// slope of its cosines (−a·k·sin(kx + φ)), the same sum the simulator evaluates; a table is
    /// linear between its knots, so its slope is piecewise constant and P̄'' counts the slope jump at
    /// every knot inside [a, b] (a Dirac in P'', which the point value `eval3` reports as 0).
    /// Non-finite inputs give NaN.
    pub fn mean_second_derivative(&self, a: f64, b: f64) -> f64 {
        if !(a.is_finite() && b.is_finite()) {
            return f64::NAN;
        }
        if a == b {
            return self.eval3(a)[2];
        }
        (self.eval3(b)[1] - self.eval3(a)[1]) / (b - a)
    }
}

impl Term {
    /// A bound on |d⁴/dx⁴| of the term over |x| ≤ `reach` (m), or None for a table (piecewise linear: its
    /// slope jumps, so no smooth interpolant reproduces it). Harmonics Σ|a|·k⁴ (k = 2π/λ), random
    /// cosines Σ|a|·k⁴, a polynomial Σ_{i≥4} |c_i|·i!/(i−4)!·reach^(i−4).
    fn fourth_derivative_bound(&self, reach: f64) -> Option<f64> {
        match self {
            Term::Poly(c) => Some(
                c.iter()
                    .enumerate()
                    .skip(4)
                    .map(|(i, ci)| {
                        let fi = i as f64;
                        ci.abs() * fi * (fi - 1.0) * (fi - 2.0) * (fi - 3.0) * reach.powi(i as i32 - 4)
                    })
                    .sum(),
            ),
            Term::Harmonics(h) => {
                Some(h.iter().map(|hi| hi.amplitude.abs() * (std::f64::consts::TAU / hi.wavelength).powi(4)).sum())
            }
            Term::Random { cosines, .. } => Some(cosines.iter().map(|&(a, k, _)| a.abs() * k.powi(4)).sum()),
            Term::Table { .. } => None,
        }
    }
}

/// Largest error of a tabulated value, in the profile's unit (m or rad): 1e-13, four decades below the
/// 1 nm feedback quantum of a typical scale.
pub const TABULATED_VALUE_ERROR: f64 = 1e-13;
/// Largest error of a tabulated slope, in the profile's unit per m: 1e-11 (a straightness slope error
/// of 1e-11 m/m moves a bearing's rest point by 1e-11·v·dt per step).
pub const TABULATED_SLOPE_ERROR: f64 = 1e-11;
/// Most nodes a tabulated profile may have (memory: two f64 per node); a profile needing more is
/// evaluated exactly.
const MAX_NODES: usize = 100_000;

/// Profiles tabulated for fast evaluation — N of them on one grid (N = 1: one profile): value and slope
/// at equally spaced nodes over a domain, read back by cubic Hermite interpolation (for t = (x − x_i)/h
/// in [0, 1]):
///
/// ```text
/// p(x)  = (2t³ − 3t² + 1)·v_i + (t³ − 2t² + t)·h·d_i + (3t² − 2t³)·v_{i+1} + (t³ − t²)·h·d_{i+1}
/// p'(x) = 6(t² − t)·(v_i − v_{i+1})/h + (3t² − 4t + 1)·d_i + (3t² − 2t)·d_{i+1}
/// ```
///
/// whose errors are at most M₄·h⁴/384 (value) and (√3/216)·M₄·h³ (slope) for |f⁗| ≤ M₄ (de Boor, *A
/// Practical Guide to Splines*, ch. IV); h is chosen so that they stay below [`TABULATED_VALUE_ERROR`]
/// and [`TABULATED_SLOPE_ERROR`] for every profile of the grid (the step of the most demanding one).
/// One evaluation costs a few multiplications whatever the number of harmonics or random cosines the
/// profiles have, and the N profiles of one grid share the node index and the weights of t.
#[derive(Clone, Debug, PartialEq)]
pub struct Tabulated<const N: usize = 1> {
    x0: f64,
    h: f64,
    /// 1/h, 1/m (a product where the lookup would divide).
    inv_h: f64,
    /// (value, slope) of each profile at x0 + i·h.
    nodes: Vec<[[f64; 2]; N]>,
    /// Index of the last node as a float, n: x is inside the table when (x − x0)/h < n.
    last: f64,
}

impl Tabulated {
    /// Value and slope at x, or None outside the tabulated domain.
    #[inline(always)]
    pub fn eval2(&self, x: f64) -> Option<[f64; 2]> {
        self.eval2_all(x).map(|[v]| v)
    }
}

impl<const N: usize> Tabulated<N> {
    /// The N profiles tabulated on one grid over [lo, hi] (m) within [`TABULATED_VALUE_ERROR`] and
    /// [`TABULATED_SLOPE_ERROR`]; None when one has a table term ([`Profile::tabulation_step`]), when the
    /// domain is empty or not finite, or when the accuracy would need more than 100 000 nodes.
    pub fn of(profiles: [&Profile; N], lo: f64, hi: f64) -> Option<Tabulated<N>> {
        let h = profiles.iter().map(|p| p.tabulation_step(lo, hi)).try_fold(f64::INFINITY, |m, h| Some(m.min(h?)))?;
        let span = hi - lo;
        let intervals = (span / h).ceil();
        if !(intervals >= 1.0 && intervals < MAX_NODES as f64) {
            return None;
        }
        // index: 1 ≤ intervals < MAX_NODES by the check above.
        let n = intervals as usize;
        let h = span / n as f64;
        let nodes = (0..=n)
            .map(|i| {
                profiles.map(|p| {
                    let e = p.eval3(lo + i as f64 * h);
                    [e[0], e[1]]
                })
            })
            .collect();
        // index: n ≤ MAX_NODES (checked above), exact as a float.
        Some(Tabulated { x0: lo, h, inv_h: 1.0 / h, nodes, last: n as f64 })
    }

    /// Value and slope of each profile at x, or None outside the tabulated domain.
    #[inline(always)]
    pub fn eval2_all(&self, x: f64) -> Option<[[f64; 2]; N]> {
        let u = (x - self.x0) * self.inv_h;
        // Inside the table: 0 ≤ u < n (nodes 0..=n; false for NaN), i.e. nodes i = ⌊u⌋ and i + 1 exist.
        if !(u >= 0.0 && u < self.last) {
            return None;
        }
        // index: 0 ≤ u < n < MAX_NODES here, so the cast through i64 is exact truncation (⌊u⌋) and
        // cheaper than the saturating cast to usize; `get` below still guards the table.
        let i = u as i64 as usize;
        let (a, b) = (self.nodes.get(i)?, self.nodes.get(i + 1)?);
        let t = u - i as f64;
        let (t2, t3) = (t * t, t * t * t);
        // The weights of t, shared by the N profiles.
        let (wa, wda, wb, wdb) =
            (2.0 * t3 - 3.0 * t2 + 1.0, (t3 - 2.0 * t2 + t) * self.h, 3.0 * t2 - 2.0 * t3, (t3 - t2) * self.h);
        let (sv, sda, sdb) = (6.0 * (t2 - t) * self.inv_h, 3.0 * t2 - 4.0 * t + 1.0, 3.0 * t2 - 2.0 * t);
        Some(std::array::from_fn(|k| {
            let ([va, da], [vb, db]) = (a[k], b[k]);
            [wa * va + wda * da + wb * vb + wdb * db, sv * (va - vb) + sda * da + sdb * db]
        }))
    }
}

impl Profile {
    /// The profile tabulated over [lo, hi] (m) ([`Tabulated::of`] of this one profile).
    pub fn tabulate(&self, lo: f64, hi: f64) -> Option<Tabulated> {
        Tabulated::of([self], lo, hi)
    }

    /// The node spacing (m) a table of this profile over [lo, hi] needs to stay within
    /// [`TABULATED_VALUE_ERROR`] and [`TABULATED_SLOPE_ERROR`]: min((384·ε_v/M₄)^¼, (216/√3·ε_s/M₄)^⅓, hi − lo)
    /// for |f⁗| ≤ M₄ on the domain, the whole span for at most a cubic (interpolated exactly); None for
    /// a table term (kinks, not smoothed) or an empty or non-finite domain.
    pub fn tabulation_step(&self, lo: f64, hi: f64) -> Option<f64> {
        if !(lo.is_finite() && hi.is_finite() && hi > lo) {
            return None;
        }
        let reach = lo.abs().max(hi.abs());
        let m4: f64 = self.terms.iter().map(|t| t.fourth_derivative_bound(reach)).sum::<Option<f64>>()?;
        let span = hi - lo;
        Some(if m4 > 0.0 {
            let by_value = (384.0 * TABULATED_VALUE_ERROR / m4).powf(0.25);
            let by_slope = (216.0 / 3f64.sqrt() * TABULATED_SLOPE_ERROR / m4).cbrt();
            by_value.min(by_slope).min(span)
        } else {
            span
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poly_value_and_derivatives_match_hand_worked_numbers() {
        // 1 + 2x + 3x² at x = 2: 17, 14, 6.
        let p = Profile::poly(vec![1.0, 2.0, 3.0]);
        assert_eq!(p.eval3(2.0), [17.0, 14.0, 6.0]);
    }

    #[test]
    fn harmonic_second_derivative_is_minus_k2_times_value() {
        let p = Profile::harmonics(vec![Harmonic { amplitude: 2e-6, wavelength: 0.25, phase: 0.3 }]);
        let k = std::f64::consts::TAU / 0.25;
        let [v, _, d2] = p.eval3(0.37);
        assert!((d2 + k * k * v).abs() < 1e-12 * k * k);
    }

    #[test]
    fn random_profile_is_reproducible_and_has_about_the_requested_rms() {
        let spec = RandomProfile { rms: 1e-6, correlation_length: 0.05, seed: 7 };
        let a = Profile { terms: vec![Term::random(spec.clone())] };
        let b = Profile { terms: vec![Term::random(spec)] };
        let n = 20000;
        let mut ss = 0.0;
        for i in 0..n {
            let x = i as f64 * 1e-3; // 20 m: many correlation lengths
            assert_eq!(a.value(x), b.value(x));
            ss += a.value(x).powi(2);
        }
        let rms = (ss / n as f64).sqrt();
        // 64 cosines: the sample RMS scatters by about 1/sqrt(64·2) ≈ 10 %; allow 30 %.
        assert!((rms / 1e-6 - 1.0).abs() < 0.3, "rms {rms}");
    }

    #[test]
    fn mean_second_derivative_is_exact_for_polys_and_counts_table_knots() {
        // 1 + 2x + 3x² + 4x³: P' = 2 + 6x + 12x²; over [1, 2]: (2 + 12 + 48 − 20)/1 = 42,
        // the mean of P'' = 6 + 24x over [1, 2] (6 + 24·1.5 = 42).
        let p = Profile::poly(vec![1.0, 2.0, 3.0, 4.0]);
        assert!((p.mean_second_derivative(1.0, 2.0) - 42.0).abs() < 1e-12);
        assert_eq!(p.mean_second_derivative(1.0, 1.0), 6.0 + 24.0);
        // Table with a slope jump from 0 to 2 at x = 1: over [0.5, 1.5] the mean curvature is 2/1.
        let t = Profile { terms: vec![Term::Table { x: vec![0.0, 1.0, 2.0], y: vec![0.0, 0.0, 2.0] }] };
        assert!((t.mean_second_derivative(0.5, 1.5) - 2.0).abs() < 1e-12);
        assert_eq!(t.mean_second_derivative(1.2, 1.7), 0.0);
        // A random profile: the mean over a short interval tends to the point value.
        let r = Profile { terms: vec![Term::random(RandomProfile { rms: 1e-6, correlation_length: 0.01, seed: 3 })] };
        let (m, d2) = (r.mean_second_derivative(0.3, 0.3 + 1e-7), r.eval3(0.3 + 0.5e-7)[2]);
        assert!((m - d2).abs() < 1e-6 * d2.abs().max(1e-3), "{m} {d2}");
        assert!(r.mean_second_derivative(f64::NAN, 0.0).is_nan());
    }

    #[test]
    fn table_interpolates_linearly_and_holds_its_end_values() {
        let p = Profile { terms: vec![Term::Table { x: vec![0.0, 1.0], y: vec![0.0, 2.0] }] };
        assert_eq!(p.value(0.25), 0.5);
        assert_eq!(p.value(-1.0), 0.0);
        assert_eq!(p.value(3.0), 2.0);
    }

    #[test]
    fn tabulated_profile_meets_its_stated_errors() {
        let p = Profile {
            terms: vec![
                Term::Poly(vec![1e-6, 2e-5, -3e-5, 1e-5, 4e-6, -2e-6]),
                Term::Harmonics(vec![
                    Harmonic { amplitude: 2e-6, wavelength: 0.33, phase: 0.4 },
                    Harmonic { amplitude: 0.3e-6, wavelength: 0.05, phase: 2.0 },
                ]),
                Term::random(RandomProfile { rms: 1e-6, correlation_length: 0.07, seed: 9 }),
            ],
        };
        let t = p.tabulate(-0.05, 1.05).expect("tabulable");
        let (mut ev, mut ed) = (0.0f64, 0.0f64);
        for i in 0..=20_000 {
            let x = -0.05 + 1.1 * i as f64 / 20_000.0 * 0.999_999;
            let [v, d] = t.eval2(x).unwrap();
            let e = p.eval3(x);
            ev = ev.max((v - e[0]).abs());
            ed = ed.max((d - e[1]).abs());
        }
        println!("{} nodes: value error {ev:e}, slope error {ed:e}", t.nodes.len());
        assert!(ev <= TABULATED_VALUE_ERROR && ed <= TABULATED_SLOPE_ERROR, "value {ev:e}, slope {ed:e}");
        assert!(t.eval2(-0.06).is_none() && t.eval2(1.2).is_none());
        let table = Profile { terms: vec![Term::Table { x: vec![0.0, 1.0], y: vec![0.0, 1e-6] }] };
        assert!(table.tabulate(0.0, 1.0).is_none(), "a kinked table is not smoothed");
    }
}
