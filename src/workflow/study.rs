//! Workflow `study`: a Monte Carlo tolerance study over one sensor parameter (DESIGN.md §6, §9). The
//! physics is simulated once; every trial redraws the sensor noise with its own seed (derived from the
//! scenario seed, the value index and the trial number), so the results are the same on any number of
//! threads and shards can be computed on different machines and merged.

use crate::byo::{score_profiles, Estimator};
use crate::error::VmtError;
use crate::estimate::Quantity;
use crate::scenario::Scenario;
use crate::simulate::{physics, read_all, simulate_truth, to_measurement_set};
use rayon::prelude::*;
use serde::Serialize;
use std::path::Path;

/// A sensor parameter a study can vary without new physics (`--vary sensors.NAME.KEY=…`), each in
/// the unit of its [`SensorSpec`](vmt_sim::sensors::SensorSpec) field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SensorParam {
    /// `sigma`: white noise of one reading, 1σ (unit of the sensor's reading).
    Sigma,
    /// `noise_density`: white noise density (reading unit per √Hz).
    NoiseDensity,
    /// `bias`: constant offset (reading unit).
    Bias,
    /// `resolution`: quantisation step (reading unit).
    Resolution,
    /// `scale_factor`: gain of the reading (dimensionless, 1 = exact).
    ScaleFactor,
    /// `bias_drift`: bias random-walk rate (reading unit per √s).
    BiasDrift,
}

impl SensorParam {
    /// Every parameter, in the order `--vary`'s message lists them.
    pub const ALL: [SensorParam; 6] = [
        SensorParam::Sigma,
        SensorParam::NoiseDensity,
        SensorParam::Bias,
        SensorParam::Resolution,
        SensorParam::ScaleFactor,
        SensorParam::BiasDrift,
    ];

    /// The key as written after `sensors.NAME.`.
    pub fn key(self) -> &'static str {
        match self {
            SensorParam::Sigma => "sigma",
            SensorParam::NoiseDensity => "noise_density",
            SensorParam::Bias => "bias",
            SensorParam::Resolution => "resolution",
            SensorParam::ScaleFactor => "scale_factor",
            SensorParam::BiasDrift => "bias_drift",
        }
    }

    /// Sets this parameter of a sensor to `v`.
    pub fn set(self, s: &mut vmt_sim::sensors::SensorSpec, v: f64) {
        match self {
            SensorParam::Sigma => s.sigma = v,
            SensorParam::NoiseDensity => s.noise_density = v,
            SensorParam::Bias => s.bias = v,
            SensorParam::Resolution => s.resolution = v,
            SensorParam::ScaleFactor => s.scale_factor = v,
            SensorParam::BiasDrift => s.bias_drift = v,
        }
    }
}

/// The varied parameter: `sensors.NAME.KEY` with KEY one of [`SensorParam`]'s keys, and its values.
#[derive(Clone, Debug, PartialEq)]
pub struct Vary {
    /// The sensor's name.
    pub sensor: String,
    /// Which of its parameters.
    pub key: SensorParam,
    /// The values, in the parameter's unit.
    pub values: Vec<f64>,
}

impl Vary {
    /// Parses `sensors.acc_z.noise_density=1e-7,2e-7`.
    pub fn parse(s: &str) -> Result<Vary, VmtError> {
        let usage = |m: &str| VmtError::Usage(format!("--vary {s}: {m} (expected sensors.NAME.KEY=V1,V2,…)"));
        let (path, vals) = s.split_once('=').ok_or_else(|| usage("no `=`"))?;
        let parts: Vec<&str> = path.split('.').collect();
        let [root, sensor, key] = parts.as_slice() else { return Err(usage("expected three dot-separated parts")) };
        if *root != "sensors" {
            return Err(usage("only sensor parameters can be varied without new physics"));
        }
        let key = SensorParam::ALL
            .into_iter()
            .find(|p| p.key() == *key)
            .ok_or_else(|| usage(&format!("unknown sensor key `{key}`")))?;
        let values = vals
            .split(',')
            .map(|v| v.trim().parse::<f64>().ok().filter(|x| x.is_finite() && *x >= 0.0))
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(|| usage("values must be finite numbers ≥ 0"))?;
        if values.is_empty() {
            return Err(usage("no values"));
        }
        Ok(Vary { sensor: sensor.to_string(), key, values })
    }
}

/// One trial's result for one estimate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrialRow {
    pub value: f64,
    pub trial: usize,
    pub estimate: String,
    pub difference: f64,
    /// Whether the difference met the tolerance; `None` where no tolerance was given (an external
    /// estimator run without `--tolerance`).
    pub pass: Option<bool>,
    /// Cramér–Rao bound of the difference, where one exists (NaN otherwise).
    pub bound: f64,
    /// What the difference measures (its SI unit: m, rad or none); the `quantity` column of trials.csv.
    pub quantity: Quantity,
}

/// The quantity of an error motion named as in a profile CSV (`pitch`, `y.straightness_z`): lengths for
/// the translational ones, angles otherwise.
pub fn motion_quantity(name: &str) -> Quantity {
    match name.rsplit('.').next().and_then(|n| n.parse::<vmt_sim::effects::EffectName>().ok()) {
        Some(e) if e.is_translational() => Quantity::Length,
        Some(_) => Quantity::Angle,
        None => Quantity::Ratio,
    }
}

/// Most trials (values × trials) one study or shard computes (size budget, DESIGN.md §2): the job
/// list is built before any work.
pub const MAX_TRIALS: usize = 1_000_000;

/// Runs trials `k` with k % shard.1 == shard.0 of every value. Each trial runs the scenario's estimators,
/// or, with `estimator`, that estimator (e.g. a user's program) scored against the truth per error motion:
/// the RMS of (estimate − truth) of each error motion passes when it is at most `tolerance` (SI: m or rad);
/// without a tolerance the rows carry no pass/fail.
pub fn run_study(
    sc: &Scenario,
    vary: &Vary,
    trials: usize,
    shard: (usize, usize),
    estimator: Option<&dyn Estimator>,
    tolerance: Option<f64>,
) -> Result<Vec<TrialRow>, VmtError> {
    if trials == 0 {
        return Err(VmtError::Usage("--trials: expected at least 1 trial".into()));
    }
    let jobs_total = vary.values.len() as f64 * trials as f64 / shard.1 as f64;
    if jobs_total > MAX_TRIALS as f64 {
        return Err(VmtError::Usage(format!(
            "{} values × {trials} trials = {jobs_total:e} trials in this shard; the limit is {MAX_TRIALS} (split with --shard i/n)",
            vary.values.len()
        )));
    }
    let ph = physics(sc)?;
    let truth_table = crate::simulate::truth_profiles(sc, &ph)?;
    if !ph.sensors.iter().any(|s| s.name == vary.sensor) {
        return Err(VmtError::Usage(format!("--vary: no sensor `{}` in the scenario", vary.sensor)));
    }
    let truths = simulate_truth(sc, &ph);
    let jobs: Vec<(usize, usize)> = (0..vary.values.len())
        .flat_map(|i| (0..trials).filter(|k| k % shard.1 == shard.0).map(move |k| (i, k)))
        .collect();
    let rows: Result<Vec<Vec<TrialRow>>, VmtError> = jobs
        .par_iter()
        .map(|&(i, k)| {
            let mut p = ph.clone();
            let v = vary.values[i];
            for s in p.sensors.iter_mut().filter(|s| s.name == vary.sensor) {
                *s = s.resolved();
                vary.key.set(s, v);
                s.preset = None;
            }
            let seed = vmt_sim::rng::derive_seed(sc.seed, &format!("study/{i}/{k}"));
            let runs = read_all(sc, &p, &truths, seed)?;
            let set = to_measurement_set(sc, &runs)?;
            if let Some(e) = estimator {
                let work = std::env::temp_dir().join(format!("vmt-study-{}-{i}-{k}", std::process::id()));
                let table = e.estimate(&set, &work);
                let _ = std::fs::remove_dir_all(&work);
                return Ok(score_profiles(&truth_table, &table?)
                    .into_iter()
                    .map(|r| TrialRow {
                        value: v,
                        trial: k,
                        estimate: format!("{} RMS", r.effect),
                        difference: r.rms,
                        pass: tolerance.map(|t| r.rms <= t),
                        bound: f64::NAN,
                        quantity: motion_quantity(&r.effect),
                    })
                    .collect());
            }
            // The compensation check re-measures on this trial's sensors, after the session simulated once.
            let est = crate::workflow::run::estimate_session(sc, &p, truths.end, &set)?;
            Ok(est
                .checks
                .into_iter()
                .map(|c| TrialRow {
                    value: v,
                    trial: k,
                    estimate: c.error,
                    difference: c.difference,
                    pass: Some(c.pass),
                    bound: c.bound.unwrap_or(f64::NAN),
                    quantity: c.quantity,
                })
                .collect())
        })
        .collect();
    Ok(rows?.into_iter().flatten().collect())
}

/// CSV of trial rows (value, trial, estimate, difference, pass), sorted so shards merge to the same file.
pub fn rows_csv(rows: &[TrialRow]) -> String {
    let mut rows = rows.to_vec();
    rows.sort_by(|a, b| a.value.total_cmp(&b.value).then(a.trial.cmp(&b.trial)).then(a.estimate.cmp(&b.estimate)));
    let mut s = String::from("value,trial,estimate,difference,pass,bound,quantity\n");
    for r in rows {
        s += &format!(
            "{},{},\"{}\",{},{},{},{}\n",
            r.value,
            r.trial,
            r.estimate.replace('"', "'"),
            r.difference,
            r.pass.map_or(String::new(), |p| p.to_string()),
            r.bound,
            quantity_id(r.quantity)
        );
    }
    s
}

/// Reads a CSV written by `rows_csv`.
pub fn read_rows(path: &Path) -> Result<Vec<TrialRow>, VmtError> {
    let text = std::fs::read_to_string(path).map_err(|e| VmtError::io(path, "reading", e))?;
    let mut rdr = csv::ReaderBuilder::new().from_reader(text.as_bytes());
    let mut out = Vec::new();
    for (i, rec) in rdr.records().enumerate() {
        let rec = rec.map_err(|e| VmtError::bad(path, format!("line {}", i + 2), e.to_string()))?;
        let f = |j: usize| rec.get(j).unwrap_or("");
        let num = |j: usize| {
            f(j).parse::<f64>().map_err(|_| {
                VmtError::bad(path, format!("line {}", i + 2), format!("expected a number, got `{}`", f(j)))
            })
        };
        let value = num(0)?;
        if !value.is_finite() {
            return Err(VmtError::bad(
                path,
                format!("line {}, column value", i + 2),
                format!("expected a finite varied value, got `{}`", f(0)),
            ));
        }
        out.push(TrialRow {
            value,
            trial: num(1)? as usize,
            estimate: f(2).to_string(),
            difference: num(3)?,
            pass: match f(4) {
                "true" => Some(true),
                "false" => Some(false),
                "" => None,
                other => {
                    return Err(VmtError::bad(
                        path,
                        format!("line {}", i + 2),
                        format!("pass: expected true, false or empty, got `{other}`"),
                    ))
                }
            },
            bound: f(5).parse().unwrap_or(f64::NAN),
            quantity: match f(6) {
                "length" => Quantity::Length,
                "angle" => Quantity::Angle,
                // A file written before the column existed: unit unknown, shown bare.
                "ratio" | "" => Quantity::Ratio,
                other => {
                    return Err(VmtError::bad(
                        path,
                        format!("line {}", i + 2),
                        format!("quantity: expected length, angle or ratio, got `{other}`"),
                    ))
                }
            },
        });
    }
    Ok(out)
}

/// Summary per (value, estimate): trials, mean |difference|, 95th percentile of |difference|, pass rate.
///
/// The difference statistics are `None` (undefined, written empty and shown as "—") for an estimate whose
/// trials form no difference: a one-sided limit ([`crate::estimate::Rule::AtMost`], e.g. the compensation
/// check's "E after compensation ≤ 30 % of E before") or a found/not-found check has only a pass rate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SummaryRow {
    /// The varied parameter's value (SI unit of the `--vary` key).
    pub value: f64,
    /// The estimate's name (the run-table row).
    pub estimate: String,
    /// Number of trials of this value and estimate.
    pub trials: usize,
    /// Mean |d| over the trials (SI: m, rad or ratio as `quantity`); `None` if any trial's d is undefined.
    pub mean_abs: Option<f64>,
    /// Root mean square of the difference over the trials, √(mean d²): the statistic a Cramér–Rao bound
    /// (a bound on the expected squared error) is compared with; `None` as `mean_abs`.
    pub rms: Option<f64>,
    /// 95th percentile of |d| over the trials (the ⌈0.95 n⌉-th smallest); `None` as `mean_abs`.
    pub p95_abs: Option<f64>,
    /// Fraction of the trials that met the tolerance; `None` when the trials had no tolerance.
    pub pass_rate: Option<f64>,
    /// Mean Cramér–Rao bound over the trials (NaN where none exists).
    pub bound: f64,
    pub quantity: Quantity,
}

/// The `quantity` column of trials.csv and summary.csv.
pub fn quantity_id(q: Quantity) -> &'static str {
    match q {
        Quantity::Length => "length",
        Quantity::Angle => "angle",
        Quantity::Ratio => "ratio",
    }
}

pub fn summarize(rows: &[TrialRow]) -> Vec<SummaryRow> {
    let mut keys: Vec<(f64, String)> = rows.iter().map(|r| (r.value, r.estimate.clone())).collect();
    keys.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    keys.dedup();
    // One group per (value, estimate) key; `total_cmp` so that a NaN value (refused by the readers,
    // but never a panic here) forms its own group rather than an empty one.
    let same = |r: &TrialRow, v: f64, e: &str| r.value.total_cmp(&v).is_eq() && r.estimate == e;
    keys.into_iter()
        .map(|(v, e)| {
            let mut d: Vec<f64> = rows.iter().filter(|r| same(r, v, &e)).map(|r| r.difference.abs()).collect();
            d.sort_by(f64::total_cmp);
            let n = d.len();
            // A statistic of d exists only where every trial formed a difference (NaN: the check has none).
            let defined = n > 0 && d.iter().all(|x| x.is_finite());
            let stat = |f: &dyn Fn(&[f64]) -> f64| defined.then(|| f(&d));
            let judged: Vec<bool> = rows.iter().filter(|r| same(r, v, &e)).filter_map(|r| r.pass).collect();
            let pass_rate = (judged.len() == n).then(|| judged.iter().filter(|&&p| p).count() as f64 / n.max(1) as f64);
            let bounds: Vec<f64> = rows.iter().filter(|r| same(r, v, &e)).map(|r| r.bound).collect();
            let bound = bounds.iter().sum::<f64>() / bounds.len().max(1) as f64;
            let quantity = rows.iter().find(|r| same(r, v, &e)).map_or(Quantity::Ratio, |r| r.quantity);
            SummaryRow {
                value: v,
                estimate: e,
                trials: n,
                mean_abs: stat(&|d| d.iter().sum::<f64>() / n as f64),
                rms: stat(&|d| (d.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt()),
                p95_abs: stat(&|d| d[((0.95 * n as f64).ceil() as usize).clamp(1, n) - 1]),
                pass_rate,
                bound,
                quantity,
            }
        })
        .collect()
}

/// The (value, statistic × `scale`) points of `rows` where the statistic `stat` is defined, for a plot
/// (an estimate without a difference, e.g. the compensation check's one-sided limit, has none).
pub fn defined_points(rows: &[&SummaryRow], stat: fn(&SummaryRow) -> Option<f64>, scale: f64) -> (Vec<f64>, Vec<f64>) {
    rows.iter().filter_map(|s| stat(s).map(|y| (s.value, y * scale))).filter(|(_, y)| y.is_finite()).unzip()
}

/// Whether every defined statistic of `summary` and every varied value is > 0 (a log-log plot is possible).
pub fn all_positive(summary: &[SummaryRow]) -> bool {
    summary.iter().all(|s| s.value > 0.0 && [s.mean_abs, s.p95_abs].iter().flatten().all(|&y| y > 0.0))
}

/// An SVG plot of mean and p95 |difference| against the varied value, one pair of series per estimate
/// (none for an estimate whose difference is undefined).
pub fn summary_svg(summary: &[SummaryRow], x_label: &str) -> Result<String, VmtError> {
    use vmt_report::{figure_svg, Figure, FigureKind, Series, SeriesStyle};
    // One pair of series per estimate: the summary is sorted by value first, so sort before dedup
    // (else every estimate repeats once per value and the SVG grows with the square of the values).
    let mut names: Vec<&str> = summary.iter().map(|s| s.estimate.as_str()).collect();
    names.sort_unstable();
    names.dedup();
    let mut series = Vec::new();
    for n in names {
        let pts: Vec<&SummaryRow> = summary.iter().filter(|s| s.estimate == n).collect();
        for (label, stat, style) in [
            ("mean", (|s: &SummaryRow| s.mean_abs) as fn(&SummaryRow) -> Option<f64>, SeriesStyle::Line),
            ("p95", |s: &SummaryRow| s.p95_abs, SeriesStyle::Dashed),
        ] {
            let (x, y) = defined_points(&pts, stat, 1e6);
            if !x.is_empty() {
                series.push(Series { label: format!("{n}: {label}"), x, y, style });
            }
        }
    }
    let positive = all_positive(summary);
    let fig = Figure {
        title: "tolerance study: estimate error against the varied parameter".into(),
        x_label: x_label.into(),
        x_unit: "SI".into(),
        y_label: "|difference|".into(),
        y_unit: "µm or µrad".into(),
        series,
        kind: FigureKind::Line,
        log_x: positive,
        log_y: positive,
    };
    figure_svg(&fig, 900, 560).map_err(|e| VmtError::Internal(format!("study plot: {e}")))
}
