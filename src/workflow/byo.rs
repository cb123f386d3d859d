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

/// Compares estimated profiles with the truth on the estimate's positions inside the truth's range
/// (truth interpolated linearly, never extrapolated): straightness about its least-squares line on
/// both sides, positioning and angles relative to their first position (the conventions of the
/// laser identifier and of ISO 230-1).
///
/// Refuses (an `Err` naming the column) a comparison that could not fail: a truth with fewer than
/// two positions, or fewer scored positions than the reference removes plus one (three for
/// straightness, whose line takes two; two for the others, whose first value is the reference) —
/// one estimate point would otherwise score as perfect.
pub fn score_profiles(truth: &ProfileTable, est: &ProfileTable) -> Result<Vec<ScoreRow>, String> {
    use vmt_sim::effects::EffectName;
    let (Some(&t_lo), Some(&t_hi)) = (truth.position.first(), truth.position.last()) else {
        return Err("the truth has no positions".into());
    };
    if truth.position.len() < 2 {
        return Err(format!("the truth has one position ({t_lo} m): it cannot be interpolated"));
    }
    // A position within 1e-9 of the span of an end counts as inside (rounding of written CSVs).
    let slack = 1e-9 * (t_hi - t_lo);
    let inside: Vec<usize> =
        (0..est.position.len()).filter(|&i| (t_lo - slack..=t_hi + slack).contains(&est.position[i])).collect();
    let xs: Vec<f64> = inside.iter().map(|&i| est.position[i].clamp(t_lo, t_hi)).collect();
    let interp = |ys: &[f64], x: f64| -> f64 {
        let p = &truth.position;
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
            return Err(format!(
                "column {}: {} of the estimate's {} positions lie inside the truth's range [{t_lo}, {t_hi}] m; \
                 scoring needs at least {need} there ({})",
                c.column_name(),
                xs.len(),
                est.position.len(),
                if straightness {
                    "straightness is compared about its least-squares line"
                } else {
                    "the first value is the reference"
                }
            ));
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

/// Fewest degrees of freedom of the repeats from which a laser line's σ is estimated when the manifest
/// gives none (σ̂ from 10 dof is within ±22 % of σ at 1σ).
pub const MIN_REPEAT_DOF_IDENTIFY: usize = 10;

/// The laser lines (linear and straightness lasers) of a point-table run of a measurement set, identified:
/// the run `run` or else the first point-table run with at least two lines. Returns the run's name, the
/// number of lines, the identification and notes for the reader. A line whose manifest gives no `sigma`
/// gets σ from its repeated readings (pooled scatter per target and direction across runs, ≥
/// [`MIN_REPEAT_DOF_IDENTIFY`] degrees of freedom; said in a note); without enough repeats the line is
/// refused, since the weights and every standard error depend on σ (a σ of 0 printed standard errors of 0).
pub fn identify_set(
    set: &MeasurementSet,
    run: Option<&str>,
) -> Result<(String, usize, vmt_estimators::laser_ls::Identification, Vec<String>), String> {
    use crate::estimate::{identify_laser_lines, LaserLine};
    use crate::measurement::{RunData, SensorKind};
    let is_line = |k: SensorKind| matches!(k, SensorKind::LaserLinear | SensorKind::LaserStraightness);
    let with_lines = |r: &&crate::measurement::Run| {
        set.sensors.iter().filter(|s| is_line(s.kind) && r.data.column(&s.name).is_some()).count() >= 2
    };
    let r = match run {
        Some(n) => set.run(n).ok_or_else(|| format!("no run named `{n}`"))?,
        None => set
            .runs
            .iter()
            .filter(|r| matches!(r.data, RunData::PointTable { .. }))
            .find(with_lines)
            .ok_or("expected a point-table run with at least two laser lines")?,
    };
    let RunData::PointTable { target, run: run_no, direction, columns, .. } = &r.data else {
        return Err(format!("run {} is not a point table", r.name));
    };
    let mut notes = Vec::new();
    let mut lines = Vec::new();
    for s in set.sensors.iter().filter(|s| is_line(s.kind)) {
        let Some(values) = r.data.column(&s.name) else { continue };
        let sigma = match s.sigma {
            Some(sigma) => sigma,
            None => {
                let keyed = target.iter().zip(direction).zip(values).map(|((x, d), v)| ((x.to_bits(), *d), *v));
                match vmt_estimators::modelcheck::pooled_group_scatter(keyed) {
                    Some((ss, dof)) if dof >= MIN_REPEAT_DOF_IDENTIFY && ss > 0.0 => {
                        let sigma = (ss / dof as f64).sqrt();
                        notes.push(format!(
                            "sigma of `{}` estimated from its repeated readings: {} m ({dof} degrees of freedom; the manifest gives none)",
                            s.name,
                            crate::error::fmt_num(sigma)
                        ));
                        sigma
                    }
                    other => {
                        let runs = run_no.iter().collect::<std::collections::BTreeSet<_>>().len();
                        return Err(format!(
                            "laser line `{}` has no sigma in the manifest and its readings ({runs} run(s)) give {} degrees of \
                             freedom of repeats, fewer than the {MIN_REPEAT_DOF_IDENTIFY} needed to estimate it: give `sigma` \
                             for the sensor (the weights and every standard error depend on it)",
                            s.name,
                            other.map_or(0, |(_, d)| d)
                        ));
                    }
                }
            }
        };
        lines.push(LaserLine { name: s.name.clone(), point: s.position, direction: s.direction, sigma });
    }
    let (id, _) = identify_laser_lines(target, columns, &lines).map_err(|m| format!("run {}: {m}", r.name))?;
    Ok((r.name.clone(), lines.len(), id, notes))
}

/// Multi-axis laser lines of a measurement set (the seed 001 line set of a chain, e.g. what `vmt simulate`
/// writes for `scenarios/squareness_3axis.toml`): every point-table run with commanded positions of at
/// least two axes (`x_cmd`, `y_cmd`, `z_cmd` columns), each laser column a reading u·δ(q, r) + the
/// line's zero, r the sensor's `position` (offset from the tool reference point) and u its `direction`.
/// Returns None when the set has no such run, else (number of lines, the 21-error identification with
/// squareness). Every laser needs its `sigma` (the weights and standard errors depend on it).
pub fn identify_axes_set(
    set: &MeasurementSet,
) -> Result<Option<(usize, crate::estimate::ChainIdentification)>, String> {
    use crate::measurement::RunData;
    use vmt_estimators::laser_ls::Reading;
    let has = |r: &crate::measurement::Run, l: char| r.data.column(&format!("{l}_cmd")).is_some();
    let letters: Vec<char> = ['x', 'y', 'z'].into_iter().filter(|&l| set.runs.iter().any(|r| has(r, l))).collect();
    let multi = |r: &crate::measurement::Run| {
        matches!(r.data, RunData::PointTable { .. }) && letters.iter().filter(|&&l| has(r, l)).count() >= 2
    };
    if letters.len() < 2 || !set.runs.iter().any(multi) {
        return Ok(None);
    }
    let mut readings = Vec::new();
    let mut n_lines = 0;
    for r in set.runs.iter().filter(|r| multi(r)) {
        let RunData::PointTable { columns, .. } = &r.data else { continue };
        let qs = crate::estimate::axis_commands(&r.name, columns, &letters)?;
        for (name, values) in columns {
            let Some(s) = set.sensor(name).filter(|s| s.kind.is_laser_line()) else {
                continue;
            };
            let sigma = s.sigma.filter(|v| *v > 0.0).ok_or_else(|| {
                format!("sensor `{name}`: the 21-error identification needs the laser's `sigma` in the manifest")
            })?;
            for (i, &v) in values.iter().enumerate() {
                readings.push(Reading {
                    q: qs.iter().map(|c| c[i]).collect(),
                    point: s.position,
                    direction: s.direction,
                    value: v,
                    sigma,
                    line: Some(n_lines),
                });
            }
            n_lines += 1;
        }
    }
    crate::estimate::identify_axis_readings(readings, &letters).map(|id| Some((n_lines, id)))
}

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
        let (_, _, id, _) =
            identify_set(set, None).map_err(|m| VmtError::bad(Path::new("<measurement set>"), "runs", m))?;
        Ok(profiles_of(&id))
    }
}
