//! ISO 230-2:2014 evaluation of a positioning test of a numerically controlled linear axis.
//!
//! Notation of the standard (clause 3): target positions `P_i` (i = 1..m), runs `j = 1..n`,
//! positional deviation `x_ij = P_ij − P_i` (actual position reached minus target), approach
//! direction ↑ (positive, "up") and ↓ (negative, "down"). All quantities here are in metres.
//!
//! Per target (ISO 230-2:2014, 3.3–3.4 and 3.9–3.12):
//! - mean unidirectional positional deviation  `x̄↑_i = (1/n) Σ_j x↑_ij`, likewise `x̄↓_i`;
//! - mean bidirectional positional deviation   `x̄_i = (x̄↑_i + x̄↓_i) / 2`;
//! - reversal value                            `B_i = x̄↑_i − x̄↓_i`;
//! - estimator of unidirectional repeatability `s↑_i = sqrt( Σ_j (x↑_ij − x̄↑_i)² / (n − 1) )`;
//! - unidirectional repeatability              `R↑_i = 4 s↑_i`, `R↓_i = 4 s↓_i`;
//! - bidirectional repeatability               `R_i = max(2 s↑_i + 2 s↓_i + |B_i|, R↑_i, R↓_i)`.
//!
//! For the axis (ISO 230-2:2014, 3.13–3.21):
//! - reversal value of the axis           `B = max_i |B_i|`;
//! - mean reversal value of the axis      `B̄ = (1/m) Σ_i B_i`;
//! - unidirectional repeatability         `R↑ = max_i R↑_i`, `R↓ = max_i R↓_i`; bidirectional `R = max_i R_i`;
//! - unidirectional systematic positioning error `E↑ = max_i x̄↑_i − min_i x̄↑_i` (likewise E↓);
//! - bidirectional systematic positioning error  `E = max_i(x̄↑_i, x̄↓_i) − min_i(x̄↑_i, x̄↓_i)`;
//! - range of mean bidirectional positional deviation `M = max_i x̄_i − min_i x̄_i`;
//! - unidirectional accuracy  `A↑ = max_i(x̄↑_i + 2 s↑_i) − min_i(x̄↑_i − 2 s↑_i)` (likewise A↓);
//! - bidirectional accuracy   `A = max_i(x̄↑_i + 2 s↑_i, x̄↓_i + 2 s↓_i) − min_i(x̄↑_i − 2 s↑_i, x̄↓_i − 2 s↓_i)`.
//!
//! The standard defines `B` as the maximum of the *absolute* reversal values, i.e. a non-negative
//! number; [`AxisResult::b_signed`] additionally keeps the signed `B_i` of largest magnitude, because
//! its sign tells the direction of the lost motion.
//!
//! The `.dat` input format of the EPICS ecmc test tools is parsed by [`dat::parse_dat`].

pub mod dat;

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why an ISO 230-2 evaluation could not be made.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum Iso230Error {
    /// No target position was given.
    /// No target position was given.
    #[error("at least one target position is needed, got none")]
    NoTargets,
    /// A target position is NaN or infinite.
    #[error("target position {index} must be finite, got {value}")]
    NonFiniteTarget {
        /// Index of the target, 0-based.
        index: usize,
        /// The target position, m.
        value: f64,
    },
    /// Targets are not strictly increasing.
    #[error("targets must be strictly increasing, got {value} m (target {index}) after {previous} m")]
    TargetsNotIncreasing {
        /// Index of the target, 0-based.
        index: usize,
        /// The target before it, m.
        previous: f64,
        /// The target position, m.
        value: f64,
    },
    /// The deviation table does not have one row per target.
    #[error("{direction} deviations: expected one row per target ({expected} rows), got {got}")]
    RowCount {
        /// Approach direction of the table (`up` or `down`).
        direction: &'static str,
        /// Rows expected: one per target (count).
        expected: usize,
        /// How many were given (count).
        got: usize,
    },
    /// Fewer than two runs at a target: the standard deviation s_i (n − 1 in the denominator) is undefined.
    #[error("{direction} deviations at target {index}: at least 2 runs are needed for s_i, got {got}")]
    TooFewRuns {
        /// Approach direction of the table (`up` or `down`).
        direction: &'static str,
        /// Index of the target, 0-based.
        index: usize,
        /// How many were given (count).
        got: usize,
    },
    /// A deviation is NaN or infinite.
    #[error("{direction} deviation at target {index}, run {run} must be finite, got {value}")]
    NonFiniteDeviation {
        /// Approach direction of the table (`up` or `down`).
        direction: &'static str,
        /// Index of the target, 0-based.
        index: usize,
        /// Index of the run, 0-based.
        run: usize,
        /// The deviation, m.
        value: f64,
    },
}

/// Direction of approach to a target (ISO 230-2:2014, 3.7): `Up` = ↑ = approach in the positive
/// direction of the axis, `Down` = ↓ = approach in the negative direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Approach {
    /// ↑: the target is approached moving in the + direction.
    Up,
    /// ↓: the target is approached moving in the − direction.
    Down,
}

impl Approach {
    fn label(self) -> &'static str {
        match self {
            Approach::Up => "up",
            Approach::Down => "down",
        }
    }
}

/// Statistics of one approach direction at one target (ISO 230-2:2014, 3.3, 3.9, 3.11). Metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DirectionStats {
    /// Mean unidirectional positional deviation x̄_i = (1/n) Σ_j x_ij, m.
    pub mean: f64,
    /// Estimator of unidirectional repeatability s_i = sqrt(Σ_j (x_ij − x̄_i)² / (n − 1)), m.
    pub s: f64,
    /// Unidirectional repeatability R_i = 4 s_i, m.
    pub repeatability: f64,
    /// Number of runs n used at this target.
    pub runs: usize,
}

/// Per-target values of a bidirectional ISO 230-2 evaluation. Metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TargetResult {
    /// Target position P_i, m.
    pub target: f64,
    /// ↑ statistics: x̄↑_i, s↑_i, R↑_i = 4 s↑_i.
    pub up: DirectionStats,
    /// ↓ statistics: x̄↓_i, s↓_i, R↓_i = 4 s↓_i.
    pub down: DirectionStats,
    /// Mean bidirectional positional deviation x̄_i = (x̄↑_i + x̄↓_i)/2, m.
    pub mean_bidirectional: f64,
    /// Reversal value B_i = x̄↑_i − x̄↓_i, m.
    pub reversal: f64,
    /// Bidirectional repeatability R_i = max(2s↑_i + 2s↓_i + |B_i|, R↑_i, R↓_i), m.
    pub repeatability: f64,
}

/// Axis values of a bidirectional ISO 230-2:2014 evaluation (clause 3.13–3.21). Metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisResult {
    /// Per-target values, in the order of the targets.
    pub targets: Vec<TargetResult>,
    /// Reversal value of the axis B = max_i |B_i| (non-negative, as the standard defines it), m.
    pub b: f64,
    /// The signed B_i of largest magnitude (same magnitude as `b`), m.
    pub b_signed: f64,
    /// Mean reversal value B̄ = (1/m) Σ_i B_i (signed), m.
    pub b_mean: f64,
    /// Unidirectional repeatability R↑ = max_i R↑_i, m.
    pub r_up: f64,
    /// Unidirectional repeatability R↓ = max_i R↓_i, m.
    pub r_down: f64,
    /// Bidirectional repeatability R = max_i R_i, m.
    pub r: f64,
    /// Unidirectional systematic positioning error E↑ = max x̄↑_i − min x̄↑_i, m.
    pub e_up: f64,
    /// Unidirectional systematic positioning error E↓ = max x̄↓_i − min x̄↓_i, m.
    pub e_down: f64,
    /// Bidirectional systematic positioning error E = max(x̄↑_i, x̄↓_i) − min(x̄↑_i, x̄↓_i), m.
    pub e: f64,
    /// Range of the mean bidirectional positional deviation M = max x̄_i − min x̄_i, m.
    pub m: f64,
    /// Unidirectional accuracy A↑ = max(x̄↑_i + 2s↑_i) − min(x̄↑_i − 2s↑_i), m.
    pub a_up: f64,
    /// Unidirectional accuracy A↓ = max(x̄↓_i + 2s↓_i) − min(x̄↓_i − 2s↓_i), m.
    pub a_down: f64,
    /// Bidirectional accuracy A = max over both directions of (x̄ + 2s) − min over both of (x̄ − 2s), m.
    pub a: f64,
}

/// Axis values of a unidirectional ISO 230-2:2014 evaluation (only one approach direction measured).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnidirectionalResult {
    /// Which direction the data belong to.
    pub approach: Approach,
    /// Target positions P_i, m.
    pub targets: Vec<f64>,
    /// Per-target statistics x̄_i, s_i, R_i = 4 s_i, in the order of the targets.
    pub stats: Vec<DirectionStats>,
    /// Unidirectional repeatability R = max_i 4 s_i, m.
    pub r: f64,
    /// Unidirectional systematic positioning error E = max x̄_i − min x̄_i, m.
    pub e: f64,
    /// Unidirectional accuracy A = max(x̄_i + 2s_i) − min(x̄_i − 2s_i), m.
    pub a: f64,
}

fn check_targets(targets: &[f64]) -> Result<(), Iso230Error> {
    if targets.is_empty() {
        return Err(Iso230Error::NoTargets);
    }
    for (i, &p) in targets.iter().enumerate() {
        if !p.is_finite() {
            return Err(Iso230Error::NonFiniteTarget { index: i + 1, value: p });
        }
        if i > 0 && p <= targets[i - 1] {
            return Err(Iso230Error::TargetsNotIncreasing { index: i + 1, previous: targets[i - 1], value: p });
        }
    }
    Ok(())
}

/// Mean and sample standard deviation (n − 1) of the deviations at one target.
fn direction_stats(row: &[f64], approach: Approach, index: usize) -> Result<DirectionStats, Iso230Error> {
    let direction = approach.label();
    if row.len() < 2 {
        return Err(Iso230Error::TooFewRuns { direction, index: index + 1, got: row.len() });
    }
    for (j, &x) in row.iter().enumerate() {
        if !x.is_finite() {
            return Err(Iso230Error::NonFiniteDeviation { direction, index: index + 1, run: j + 1, value: x });
        }
    }
    let n = row.len() as f64;
    let mean = row.iter().sum::<f64>() / n;
    let ss: f64 = row.iter().map(|x| (x - mean) * (x - mean)).sum();
    let s = (ss / (n - 1.0)).sqrt();
    Ok(DirectionStats { mean, s, repeatability: 4.0 * s, runs: row.len() })
}

fn all_stats(targets: &[f64], rows: &[Vec<f64>], approach: Approach) -> Result<Vec<DirectionStats>, Iso230Error> {
    if rows.len() != targets.len() {
        return Err(Iso230Error::RowCount { direction: approach.label(), expected: targets.len(), got: rows.len() });
    }
    rows.iter().enumerate().map(|(i, row)| direction_stats(row, approach, i)).collect()
}

fn max_of(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(f64::NEG_INFINITY, f64::max)
}

fn min_of(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(f64::INFINITY, f64::min)
}

/// Evaluates a bidirectional positioning test per ISO 230-2:2014 (formulas in the module doc).
///
/// `targets`: P_i in m, strictly increasing. `up[i][j]` / `down[i][j]`: positional deviation
/// x_ij = actual − target (m) at target i, run j, approached in the + / − direction. Runs may
/// differ in number between targets and directions, but at least 2 are needed per target and
/// direction (the standard asks for 5).
///
/// # Example
///
/// Three targets, two runs each way, deviations in m (whole micrometres, so the results are exact):
///
/// ```rust
/// use vmt_estimators::iso230_2::evaluate_bidirectional;
/// let um = 1e-6;
/// let targets = [0.0, 0.1, 0.2]; // m
/// let up = vec![vec![1.0 * um, 1.0 * um], vec![2.0 * um, 2.0 * um], vec![1.0 * um, 1.0 * um]];
/// let down = vec![vec![0.0, 0.0], vec![0.5 * um, 0.5 * um], vec![0.0, 0.0]];
/// let r = evaluate_bidirectional(&targets, &up, &down).unwrap();
/// // Reversal value B = max_i |x̄↑_i − x̄↓_i| = 1.5 µm (at 0.1 m);
/// // bidirectional systematic positioning error E = max(x̄↑, x̄↓) − min(x̄↑, x̄↓) = 2 µm − 0 µm.
/// assert!((r.b - 1.5 * um).abs() < 1e-15);
/// assert!((r.e - 2.0 * um).abs() < 1e-15);
/// ```
pub fn evaluate_bidirectional(targets: &[f64], up: &[Vec<f64>], down: &[Vec<f64>]) -> Result<AxisResult, Iso230Error> {
    check_targets(targets)?;
    let su = all_stats(targets, up, Approach::Up)?;
    let sd = all_stats(targets, down, Approach::Down)?;

    let per_target: Vec<TargetResult> = targets
        .iter()
        .zip(su.iter().zip(&sd))
        .map(|(&p, (u, d))| {
            let b_i = u.mean - d.mean;
            let r_i = (2.0 * u.s + 2.0 * d.s + b_i.abs()).max(u.repeatability).max(d.repeatability);
            TargetResult {
                target: p,
                up: *u,
                down: *d,
                mean_bidirectional: 0.5 * (u.mean + d.mean),
                reversal: b_i,
                repeatability: r_i,
            }
        })
        .collect();

    let t = &per_target;
    let mut b_signed: f64 = 0.0;
    for tr in t {
        if tr.reversal.abs() > b_signed.abs() {
            b_signed = tr.reversal;
        }
    }
    let m_count = t.len() as f64;
    let both_hi = || t.iter().flat_map(|r| [r.up.mean, r.down.mean]);
    let e = max_of(both_hi()) - min_of(both_hi());
    let a_hi = max_of(t.iter().flat_map(|r| [r.up.mean + 2.0 * r.up.s, r.down.mean + 2.0 * r.down.s]));
    let a_lo = min_of(t.iter().flat_map(|r| [r.up.mean - 2.0 * r.up.s, r.down.mean - 2.0 * r.down.s]));
    Ok(AxisResult {
        b: b_signed.abs(),
        b_signed,
        b_mean: t.iter().map(|r| r.reversal).sum::<f64>() / m_count,
        r_up: max_of(t.iter().map(|r| r.up.repeatability)),
        r_down: max_of(t.iter().map(|r| r.down.repeatability)),
        r: max_of(t.iter().map(|r| r.repeatability)),
        e_up: max_of(t.iter().map(|r| r.up.mean)) - min_of(t.iter().map(|r| r.up.mean)),
        e_down: max_of(t.iter().map(|r| r.down.mean)) - min_of(t.iter().map(|r| r.down.mean)),
        e,
        m: max_of(t.iter().map(|r| r.mean_bidirectional)) - min_of(t.iter().map(|r| r.mean_bidirectional)),
        a_up: max_of(t.iter().map(|r| r.up.mean + 2.0 * r.up.s)) - min_of(t.iter().map(|r| r.up.mean - 2.0 * r.up.s)),
        a_down: max_of(t.iter().map(|r| r.down.mean + 2.0 * r.down.s))
            - min_of(t.iter().map(|r| r.down.mean - 2.0 * r.down.s)),
        a: a_hi - a_lo,
        targets: per_target,
    })
}

/// Standard uncertainties (type A, GUM 4.2, from the repeats of the test itself) of the axis values that
/// are functions of the mean deviations, m. ISO 230-2 gives no uncertainty for them; ISO 230-2:2014 §8
/// asks the report to state one.
///
/// With u(x̄↑ᵢ) = s↑ᵢ/√n↑ᵢ and u(x̄↓ᵢ) = s↓ᵢ/√n↓ᵢ (runs independent), to first order at the extreme
/// targets the values are taken at:
/// - E = max − min over both directions of x̄: u(E) = √(u(x̄_max)² + u(x̄_min)²); E↑, E↓ likewise;
/// - M = max x̄ᵢ − min x̄ᵢ, x̄ᵢ = (x̄↑ᵢ + x̄↓ᵢ)/2: u(x̄ᵢ) = ½·√(u(x̄↑ᵢ)² + u(x̄↓ᵢ)²), combined as for E;
/// - B = |Bᵢ| at the target of largest |Bᵢ|, Bᵢ = x̄↑ᵢ − x̄↓ᵢ: u(Bᵢ) = √(u(x̄↑ᵢ)² + u(x̄↓ᵢ)²);
/// - B̄ = (1/m)·Σ Bᵢ: u(B̄) = √(Σ u(Bᵢ)²)/m.
///
/// First order means: the extremes stay at the same targets under the noise. Where two targets compete
/// for an extreme within a few u, the spread of E (M, B) over repeated tests is smaller than u and its
/// mean is pushed outward (a maximum of noisy values); u then overstates the spread. The repeatability
/// R and the accuracy A are maxima of the scatter estimates s themselves and get no value here. The
/// instrument's systematic share (laser calibration, environment: ISO/TR 230-9) is not in the repeats.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AxisUncertainty {
    /// u(E), m.
    pub e: f64,
    /// u(E↑), m.
    pub e_up: f64,
    /// u(E↓), m.
    pub e_down: f64,
    /// u(M), m.
    pub m: f64,
    /// u(B), m.
    pub b: f64,
    /// u(B̄), m.
    pub b_mean: f64,
}

/// The standard uncertainty of a range max − min of `values` (value, u(value)): √(u_max² + u_min²) at the
/// first largest and the first smallest value.
fn range_uncertainty(values: impl Iterator<Item = (f64, f64)> + Clone) -> f64 {
    let pick = |better: fn(f64, f64) -> bool| {
        values.clone().fold(None, |best: Option<(f64, f64)>, (v, u)| match best {
            Some((bv, _)) if !better(v, bv) => best,
            _ => Some((v, u)),
        })
    };
    let hi = pick(|a, b| a > b).map_or(0.0, |p| p.1);
    let lo = pick(|a, b| a < b).map_or(0.0, |p| p.1);
    (hi * hi + lo * lo).sqrt()
}

/// The type-A standard uncertainties of E, E↑, E↓, M, B and B̄ of an evaluation ([`AxisUncertainty`]).
pub fn axis_uncertainties(r: &AxisResult) -> AxisUncertainty {
    let u_mean = |d: &DirectionStats| d.s / (d.runs as f64).sqrt();
    let t = &r.targets;
    let u_b = |tr: &TargetResult| u_mean(&tr.up).hypot(u_mean(&tr.down));
    let widest = t.iter().fold(None, |best: Option<&TargetResult>, tr| match best {
        Some(b) if tr.reversal.abs() <= b.reversal.abs() => best,
        _ => Some(tr),
    });
    AxisUncertainty {
        e: range_uncertainty(t.iter().flat_map(|tr| [(tr.up.mean, u_mean(&tr.up)), (tr.down.mean, u_mean(&tr.down))])),
        e_up: range_uncertainty(t.iter().map(|tr| (tr.up.mean, u_mean(&tr.up)))),
        e_down: range_uncertainty(t.iter().map(|tr| (tr.down.mean, u_mean(&tr.down)))),
        m: range_uncertainty(t.iter().map(|tr| (tr.mean_bidirectional, 0.5 * u_b(tr)))),
        b: widest.map_or(0.0, u_b),
        b_mean: t.iter().map(|tr| u_b(tr).powi(2)).sum::<f64>().sqrt() / t.len().max(1) as f64,
    }
}

/// Evaluates a unidirectional positioning test per ISO 230-2:2014 (only one approach direction).
///
/// `deviations[i][j]` = x_ij = actual − target (m) at target i, run j. Returns x̄_i, s_i,
/// R_i = 4 s_i per target and the axis values R = max R_i, E = max x̄_i − min x̄_i,
/// A = max(x̄_i + 2 s_i) − min(x̄_i − 2 s_i).
pub fn evaluate_unidirectional(
    targets: &[f64],
    deviations: &[Vec<f64>],
    approach: Approach,
) -> Result<UnidirectionalResult, Iso230Error> {
    check_targets(targets)?;
    let st = all_stats(targets, deviations, approach)?;
    Ok(UnidirectionalResult {
        approach,
        targets: targets.to_vec(),
        r: max_of(st.iter().map(|s| s.repeatability)),
        e: max_of(st.iter().map(|s| s.mean)) - min_of(st.iter().map(|s| s.mean)),
        a: max_of(st.iter().map(|s| s.mean + 2.0 * s.s)) - min_of(st.iter().map(|s| s.mean - 2.0 * s.s)),
        stats: st,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const UM: f64 = 1e-6;

    /// Hand-worked example, 3 targets × 3 runs, deviations in µm (multiplied by 1e-6 below).
    ///
    /// ```text
    /// i  P_i    up runs      x̄↑   s↑    down runs    x̄↓   s↓
    /// 1  0.0    1, 2, 3      2    1     -1, 0, 1     0    1
    /// 2  0.1    4, 4, 4      4    0      0, 2, 4     2    2
    /// 3  0.25   0, 3, 6      3    3      1, 1, 4     2    √3
    /// ```
    /// s: i=1 up: ((−1)²+0+1²)/2 = 1 → 1; i=2 down: (4+0+4)/2 = 4 → 2; i=3 up: (9+0+9)/2 = 9 → 3;
    /// i=3 down: mean 2, (1+1+4)/2 = 3 → √3.
    /// B_i = 2, 2, 1 → B = 2, B̄ = 5/3. x̄_i = 1, 3, 2.5 → M = 2.
    /// R↑_i = 4, 0, 12; R↓_i = 4, 8, 4√3 = 6.928; 2s↑+2s↓+|B_i| = 2+2+2 = 6, 0+4+2 = 6, 6+2√3+1 = 10.464
    /// → R_i = 6, 8, 12 → R↑ = 12, R↓ = 8, R = 12.
    /// E↑ = 4 − 2 = 2, E↓ = 2 − 0 = 2, E = max(2,4,3,0,2,2) − min(…) = 4 − 0 = 4.
    /// A↑: x̄+2s = 4, 4, 9; x̄−2s = 0, 4, −3 → 9 − (−3) = 12.
    /// A↓: x̄+2s = 2, 6, 2+2√3 = 5.464; x̄−2s = −2, −2, 2−2√3 = −1.464 → 6 − (−2) = 8.
    /// A = max(9, 6) − min(−3, −2) = 12.
    #[test]
    fn hand_worked_three_targets_three_runs() {
        let targets = [0.0, 0.1, 0.25];
        let up =
            vec![vec![1.0 * UM, 2.0 * UM, 3.0 * UM], vec![4.0 * UM, 4.0 * UM, 4.0 * UM], vec![0.0, 3.0 * UM, 6.0 * UM]];
        let down = vec![vec![-UM, 0.0, 1.0 * UM], vec![0.0, 2.0 * UM, 4.0 * UM], vec![1.0 * UM, 1.0 * UM, 4.0 * UM]];
        let r = evaluate_bidirectional(&targets, &up, &down).unwrap();
        // Tolerance 1e-18 m: the µm-scaled inputs carry relative rounding ~1e-16, i.e. ~1e-21 m.
        let close = |a: f64, b: f64| (a - b).abs() < 1e-18;
        let s3 = 3f64.sqrt();
        assert!(close(r.targets[0].up.s, 1.0 * UM));
        assert!(close(r.targets[1].down.s, 2.0 * UM));
        assert!(close(r.targets[2].up.s, 3.0 * UM));
        assert!(close(r.targets[2].down.s, s3 * UM));
        let want_r_i = [6.0, 8.0, 12.0];
        for (t, w) in r.targets.iter().zip(want_r_i) {
            assert!(close(t.repeatability, w * UM), "R_i {}", t.repeatability);
        }
        assert!(close(r.b, 2.0 * UM) && close(r.b_signed, 2.0 * UM));
        assert!(close(r.b_mean, 5.0 / 3.0 * UM));
        assert!(close(r.m, 2.0 * UM));
        assert!(close(r.r_up, 12.0 * UM) && close(r.r_down, 8.0 * UM) && close(r.r, 12.0 * UM));
        assert!(close(r.e_up, 2.0 * UM) && close(r.e_down, 2.0 * UM) && close(r.e, 4.0 * UM));
        assert!(close(r.a_up, 12.0 * UM) && close(r.a_down, 8.0 * UM) && close(r.a, 12.0 * UM));

        // The unidirectional evaluation of the ↓ data alone reproduces R↓, E↓, A↓.
        let u = evaluate_unidirectional(&targets, &down, Approach::Down).unwrap();
        assert!(close(u.r, r.r_down) && close(u.e, r.e_down) && close(u.a, r.a_down));
    }

    /// R_i is decided by 2s↑+2s↓+|B_i| when the reversal dominates: s↑ = s↓ = 1 µm, B_i = 10 µm
    /// → R_i = 14 µm while R↑_i = R↓_i = 4 µm. B̄ keeps the sign, B is the magnitude.
    #[test]
    fn reversal_dominated_repeatability_and_signed_b() {
        let targets = [0.0, 1.0];
        let up = vec![vec![-UM, 0.0, 1.0 * UM], vec![-UM, 0.0, 1.0 * UM]];
        let down = vec![vec![9.0 * UM, 10.0 * UM, 11.0 * UM], vec![1.0 * UM, 2.0 * UM, 3.0 * UM]];
        let r = evaluate_bidirectional(&targets, &up, &down).unwrap();
        // 1e-18 m: rounding of µm-scaled inputs (see above).
        assert!((r.targets[0].repeatability - 14.0 * UM).abs() < 1e-18);
        assert!((r.r - 14.0 * UM).abs() < 1e-18);
        assert!((r.r_up.max(r.r_down) - 4.0 * UM).abs() < 1e-18);
        assert!((r.b - 10.0 * UM).abs() < 1e-18 && (r.b_signed + 10.0 * UM).abs() < 1e-18);
        assert!((r.b_mean + 6.0 * UM).abs() < 1e-18);
    }

    #[test]
    fn bad_inputs_are_rejected_with_a_message() {
        let row = vec![0.0, 1e-6];
        let e =
            evaluate_bidirectional(&[0.0, 0.0], &[row.clone(), row.clone()], &[row.clone(), row.clone()]).unwrap_err();
        assert!(e.to_string().contains("strictly increasing"), "{e}");
        let e = evaluate_bidirectional(&[0.0], &[vec![1e-6]], std::slice::from_ref(&row)).unwrap_err();
        assert!(e.to_string().contains("at least 2 runs"), "{e}");
        let e = evaluate_bidirectional(&[0.0], &[vec![f64::NAN, 0.0]], std::slice::from_ref(&row)).unwrap_err();
        assert!(e.to_string().contains("finite"), "{e}");
        let e =
            evaluate_bidirectional(&[0.0, 1.0], std::slice::from_ref(&row), &[row.clone(), row.clone()]).unwrap_err();
        assert!(e.to_string().contains("one row per target"), "{e}");
        assert_eq!(evaluate_bidirectional(&[], &[], &[]).unwrap_err(), Iso230Error::NoTargets);
    }
}
