//! Bring your own estimator: an estimator maps a measurement set to error-motion profiles (FORMAT.md §5),
//! in process (the `Estimator` trait) or as any program (`CommandEstimator`: `CMD {data} {out}` reads the
//! set at {data} and writes its profile CSV to {out}); `score_profiles` compares the result with the truth.

use crate::error::VmtError;
use crate::measurement::{self, MeasurementSet, ProfileTable, UnitChoice};
use serde::Serialize;
use std::path::Path;

/// An estimator of error-motion profiles from a measurement set.
pub trait Estimator: Sync {
    /// A short name for tables.
    fn name(&self) -> &str;
    /// Estimates profiles; `work` is a scratch directory the estimator may use.
    fn estimate(&self, set: &MeasurementSet, work: &Path) -> Result<ProfileTable, VmtError>;
}

/// A program run as `sh -c CMD` with `{data}` and `{out}` replaced by the paths of the measurement set
/// and of the profile CSV it must write.
pub struct CommandEstimator {
    /// The shell command line, with the `{data}` and `{out}` placeholders.
    pub command: String,
}

impl Estimator for CommandEstimator {
    fn name(&self) -> &str {
        &self.command
    }

    fn estimate(&self, set: &MeasurementSet, work: &Path) -> Result<ProfileTable, VmtError> {
        let data = work.join("data");
        let out = work.join("estimate.csv");
        measurement::write(set, &data, UnitChoice::Si)?;
        let cmd =
            self.command.replace("{data}", &data.display().to_string()).replace("{out}", &out.display().to_string());
        let status = std::process::Command::new("sh")
            .arg("-c")
            .arg(&cmd)
            .status()
            .map_err(|e| VmtError::Usage(format!("--estimator-cmd: cannot run `{cmd}`: {e}")))?;
        if !status.success() {
            return Err(VmtError::Usage(format!("--estimator-cmd: `{cmd}` exited with {status}")));
        }
        measurement::read_profiles(&out)
    }
}

/// One error motion's comparison: RMS and max of estimate − truth on the estimate's positions
/// inside the truth's range.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ScoreRow {
    /// The error-motion column (`positioning`, `y.pitch`, …).
    pub effect: String,
    /// RMS of d = estimate − truth over the scored positions, the column's SI unit (m or rad).
    pub rms: f64,
    /// max |d| over the scored positions, same unit.
    pub max: f64,
    /// Number of scored positions (the estimate's positions inside the truth's range).
    pub points: usize,
    /// The estimate's positions outside the truth's range, not scored (the truth is never
    /// extrapolated); optional JSON key `outside_truth`.
    #[serde(rename = "outside_truth")]
    pub outside: usize,
}

/// Why two profile tables cannot be scored against each other ([`score_profiles`]); positions in m.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ScoreError {
    /// The truth has no positions.
    #[error("the truth has no positions")]
    NoTruth,
    /// The truth has one position (m), which cannot be interpolated.
    #[error("the truth has one position ({0} m): it cannot be interpolated")]
    OneTruthPosition(f64),
    /// Too few of the estimate's positions lie inside the truth's range for a column.
    #[error(
        "column {column}: {inside} of the estimate's {total} positions lie inside the truth's range [{lo}, {hi}] m; \
         scoring needs at least {need} there ({})",
        if *.straightness { "straightness is compared about its least-squares line" } else { "the first value is the reference" }
    )]
    TooFewInside {
        /// The column's name.
        column: String,
        /// The estimate's positions inside the truth's range.
        inside: usize,
        /// The estimate's positions.
        total: usize,
        /// First position of the truth, m.
        lo: f64,
        /// Last position of the truth, m.
        hi: f64,
        /// Positions needed inside (3 for straightness, 2 for the others).
        need: usize,
        /// Whether the column is a straightness (compared about its least-squares line).
        straightness: bool,
    },
}

/// Compares estimated profiles with the truth on the estimate's positions inside the truth's range
/// (truth interpolated linearly, never extrapolated): straightness about its least-squares line on
/// both sides, positioning and angles relative to their first position (the conventions of the
/// laser identifier and of ISO 230-1).
///
/// Refuses (an `Err` naming the column) a comparison that could not fail: a truth with fewer than
/// two positions, or fewer scored positions than the reference removes plus one (three for
/// straightness, whose line takes two; two for the others, whose first value is the reference) —
/// one estimate point would otherwise score as perfect.
pub fn score_profiles(truth: &ProfileTable, est: &ProfileTable) -> Result<Vec<ScoreRow>, ScoreError> {
    use vmt_sim::effects::EffectName;
    let (Some(&t_lo), Some(&t_hi)) = (truth.position.first(), truth.position.last()) else {
        return Err(ScoreError::NoTruth);
    };
    if truth.position.len() < 2 {
        return Err(ScoreError::OneTruthPosition(t_lo));
    }
    // A position within 1e-9 of the span of an end counts as inside (rounding of written CSVs).
    let slack = 1e-9 * (t_hi - t_lo);
    let inside: Vec<usize> =
        (0..est.position.len()).filter(|&i| (t_lo - slack..=t_hi + slack).contains(&est.position[i])).collect();
    // clamp: t_lo ≤ t_hi, the first and last of the truth's positions (read as strictly increasing, ≥ 2).
    let xs: Vec<f64> = inside.iter().map(|&i| est.position[i].clamp(t_lo, t_hi)).collect();
    let interp = |ys: &[f64], x: f64| -> f64 {
        let p = &truth.position;
        // clamp: 1 ≤ p.len() − 1, the truth has ≥ 2 positions (checked above).
        let i = p.partition_point(|&v| v <= x).clamp(1, p.len() - 1);
        let w = (x - p[i - 1]) / (p[i] - p[i - 1]);
        ys[i - 1] + w * (ys[i] - ys[i - 1])
    };
    let mut rows = Vec::new();
    for c in &est.columns {
        let Some(tc) = truth.columns.iter().find(|tc| tc.effect == c.effect && tc.axis == c.axis) else { continue };
        if c.values.is_empty() {
            continue;
        }
        let straightness = matches!(c.effect, EffectName::StraightnessY | EffectName::StraightnessZ);
        let need = if straightness { 3 } else { 2 };
        if xs.len() < need {
            return Err(ScoreError::TooFewInside {
                column: c.column_name(),
                inside: xs.len(),
                total: est.position.len(),
                lo: t_lo,
                hi: t_hi,
                need,
                straightness,
            });
        }
        let ev: Vec<f64> = inside.iter().map(|&i| c.values[i]).collect();
        let tv: Vec<f64> = xs.iter().map(|&x| interp(&tc.values, x)).collect();
        let norm = |v: &[f64]| -> Vec<f64> {
            if straightness {
                vmt_estimators::line::remove_line(&xs, v)
            } else {
                v.iter().map(|x| x - v[0]).collect()
            }
        };
        let d: Vec<f64> = norm(&ev).iter().zip(norm(&tv)).map(|(a, b)| a - b).collect();
        rows.push(ScoreRow {
            effect: c.column_name(),
            rms: (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt(),
            max: d.iter().fold(0.0f64, |m, x| m.max(x.abs())),
            points: d.len(),
            outside: est.position.len() - xs.len(),
        });
    }
    Ok(rows)
}

pub use crate::estimate::chain::identify_axes_set;
pub use crate::estimate::laser_lines::identify_set;

/// The six identified error motions as a FORMAT.md §5 table, with their standard errors as `NAME_sigma`
/// when every one is known.
pub fn profiles_of(id: &vmt_estimators::laser_ls::Identification) -> ProfileTable {
    use crate::measurement::ProfileColumn;
    let syms = ["EXX", "EYX", "EZX", "EAX", "EBX", "ECX"];
    let position = id.profile("EXX").map(|p| p.positions.clone()).unwrap_or_default();
    let columns = vmt_sim::effects::EffectName::ERROR_MOTIONS
        .iter()
        .zip(syms)
        .filter_map(|(&effect, sym)| {
            id.profile(sym).map(|p| {
                let sigma: Option<Vec<f64>> = p.std_errors.iter().copied().collect();
                ProfileColumn { axis: None, effect, values: p.values.clone(), sigma }
            })
        })
        .collect();
    ProfileTable { position, columns }
}

/// The laser-lines identifier (seeds 001/003) as an in-process `Estimator`: the six error motions of the
/// first point-table run that has at least two laser lines. Also the worked example of the trait.
pub struct LaserLines;

impl Estimator for LaserLines {
    fn name(&self) -> &str {
        "laser lines"
    }

    fn estimate(&self, set: &MeasurementSet, _work: &Path) -> Result<ProfileTable, VmtError> {
        let (_, _, id, _) = identify_set(set, None)
            .map_err(|e| VmtError::bad(Path::new("<measurement set>"), "runs", e.to_string()))?;
        Ok(profiles_of(&id))
    }
}
