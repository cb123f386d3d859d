//! Workflow `study`: a Monte Carlo tolerance study over one parameter (DESIGN.md §6, §9): a sensor
//! parameter (the physics is simulated once and shared) or any number of the scenario file (a truth
//! effect's parameter, a servo gain, a feed: the physics is simulated once per value). Every trial
//! redraws the sensor noise with its own seed (derived from the scenario seed, the value index and the
//! trial number), so the results are the same on any number of threads and shards can be computed on
//! different machines and merged. A compensation check's re-test is simulated once per value without
//! compensation and each trial's table applied to it (`crate::simulate::Retest::Derived`: within about
//! one feedback count per reading of the simulated re-test `vmt run` makes, docs/methods.md), so a
//! trial simulates no physics.

use crate::byo::{score_profiles, Estimator};
use crate::error::VmtError;
use crate::estimate::Quantity;
use crate::scenario::Scenario;
use crate::simulate::{
    physics, read_all, simulate_truth, to_measurement_set, uncompensated_retests, Physics, Retest, UncompensatedRetests,
};
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
    /// `scale_factor`: scale-factor error of the reading (dimensionless, reading = (1 + s)·true; 0 = exact).
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

/// What a study varies.
#[derive(Clone, Debug, PartialEq)]
pub enum VaryKey {
    /// `sensors.NAME.KEY` with KEY one of [`SensorParam`]'s keys: the physics is simulated once and
    /// shared by every value; each trial redraws the sensor noise.
    Sensor {
        /// The sensor's name.
        sensor: String,
        /// Which of its parameters.
        key: SensorParam,
    },
    /// Any number the scenario file gives, by its TOML key path (`truth.effects.backlash.value`,
    /// `axis.servo.kp`, `truth.effects.pitch.poly[1]`, `procedures[1].feed`): each value is a new
    /// scenario, parsed and validated as the file would be (its range checks included), with its own
    /// physics; the trials of a value share it and redraw the sensor noise.
    Scenario {
        /// The path, as written.
        path: String,
        /// Its parts: a key and an optional array index each.
        parts: Vec<(String, Option<usize>)>,
    },
}

/// The varied parameter and its values.
#[derive(Clone, Debug, PartialEq)]
pub struct Vary {
    /// What is varied.
    pub key: VaryKey,
    /// The values, in the parameter's SI unit.
    pub values: Vec<f64>,
}

/// Most values of a parameter that changes the physics (each is simulated and held in memory).
pub const MAX_PHYSICS_VALUES: usize = 256;

impl Vary {
    /// Parses `sensors.acc_z.noise_density=1e-7,2e-7` or `truth.effects.backlash.value=2e-6,4e-6`.
    pub fn parse(s: &str) -> Result<Vary, VmtError> {
        let usage = |m: &str| {
            VmtError::Usage(format!(
                "--vary {s}: {m} (expected sensors.NAME.KEY=V1,V2,… or a scenario key path such as \
                 truth.effects.backlash.value=V1,V2,…)"
            ))
        };
        let (path, vals) = s.split_once('=').ok_or_else(|| usage("no `=`"))?;
        let parts: Vec<&str> = path.split('.').collect();
        let values = vals
            .split(',')
            .map(|v| v.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(|| usage("values must be finite numbers"))?;
        if values.is_empty() {
            return Err(usage("no values"));
        }
        let key = if parts.first() == Some(&"sensors") {
            let [_, sensor, key] = parts.as_slice() else { return Err(usage("expected sensors.NAME.KEY")) };
            let key = SensorParam::ALL
                .into_iter()
                .find(|p| p.key() == *key)
                .ok_or_else(|| usage(&format!("unknown sensor key `{key}`")))?;
            // A bias and a scale-factor error have either sign; the other keys are sizes (≥ 0). Each
            // value is checked against the scenario's own sensor checks in `run_study`.
            let signed = matches!(key, SensorParam::Bias | SensorParam::ScaleFactor);
            if !signed && values.iter().any(|v| *v < 0.0) {
                return Err(usage("sensor parameter values must be ≥ 0"));
            }
            VaryKey::Sensor { sensor: sensor.to_string(), key }
        } else {
            if values.len() > MAX_PHYSICS_VALUES {
                return Err(usage(&format!(
                    "{} values of a parameter that changes the physics; the limit is {MAX_PHYSICS_VALUES}",
                    values.len()
                )));
            }
            VaryKey::Scenario {
                path: path.to_string(),
                parts: parse_key_path(path).map_err(|e| usage(&e.to_string()))?,
            }
        };
        Ok(Vary { key, values })
    }

    /// The varied parameter as written (`sensors.acc_z.noise_density`, `axis.servo.kp`).
    pub fn label(&self) -> String {
        match &self.key {
            VaryKey::Sensor { sensor, key } => format!("sensors.{sensor}.{}", key.key()),
            VaryKey::Scenario { path, .. } => path.clone(),
        }
    }
}

/// Why a scenario key path is refused, or the number at it cannot be set ([`set_scenario_number`]).
#[derive(Debug, thiserror::Error)]
pub enum KeyPathError {
    /// A part of the path that is neither `KEY` nor `KEY[INDEX]`.
    #[error("`{0}`: expected KEY or KEY[INDEX]")]
    Part(String),
    /// The scenario text is not TOML.
    #[error("{}", .0.message())]
    Toml(toml::de::Error),
    /// The first key of the path is not in the scenario.
    #[error("no key `{0}` in the scenario")]
    NoKey(String),
    /// A later key of the path is not in the scenario (the path walked so far).
    #[error("no key `{0}` in the scenario (--vary changes a number the file gives; add it there first)")]
    NoInnerKey(String),
    /// An array index past the end (the path walked so far).
    #[error("no item `{0}` in the scenario")]
    NoItem(String),
    /// A fractional or too large value for an integer key.
    #[error("`{path}` is an integer; got {value}")]
    NotInteger {
        /// The key path.
        path: String,
        /// The value asked for, in the key's unit.
        value: f64,
    },
    /// The key holds no number (what it holds, e.g. `a string "abc"`).
    #[error("`{path}` is {what}, not a number")]
    NotNumber {
        /// The key path.
        path: String,
        /// What the key holds.
        what: String,
    },
    /// The edited scenario could not be written as TOML.
    #[error(transparent)]
    Write(#[from] toml::ser::Error),
}

/// A scenario key path `a.b[2].c` as (key, optional array index) parts.
fn parse_key_path(path: &str) -> Result<Vec<(String, Option<usize>)>, KeyPathError> {
    path.split('.')
        .map(|p| match p.split_once('[') {
            None if !p.is_empty() => Ok((p.to_string(), None)),
            Some((k, i)) if !k.is_empty() => i
                .strip_suffix(']')
                .and_then(|i| i.parse::<usize>().ok())
                .map(|i| (k.to_string(), Some(i)))
                .ok_or_else(|| KeyPathError::Part(p.to_string())),
            _ => Err(KeyPathError::Part(p.to_string())),
        })
        .collect()
}

/// A distribution a physical parameter is drawn from once per trial (`--sample KEY=DIST`), SI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Distribution {
    /// `uniform(lo,hi)`: every value in [lo, hi) equally likely.
    Uniform {
        /// Lower end.
        lo: f64,
        /// Upper end.
        hi: f64,
    },
    /// `normal(mean,sd)`: Gaussian.
    Normal {
        /// Mean.
        mean: f64,
        /// Standard deviation.
        sd: f64,
    },
    /// `loguniform(lo,hi)`: ln x uniform on [ln lo, ln hi) (0 < lo < hi), for a parameter known
    /// to an order of magnitude.
    LogUniform {
        /// Lower end (> 0).
        lo: f64,
        /// Upper end.
        hi: f64,
    },
}

/// Why a `--sample` distribution is refused ([`Distribution::parse`]); its two arguments as written.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum DistributionError {
    /// Not one of the three forms, or an argument that is not a finite number.
    #[error("expected uniform(LO,HI), normal(MEAN,SD) or loguniform(LO,HI) with finite numbers")]
    Form,
    /// `uniform(LO,HI)` with LO ≥ HI.
    #[error("uniform({0},{1}): expected LO < HI")]
    Uniform(f64, f64),
    /// `normal(MEAN,SD)` with SD ≤ 0.
    #[error("normal({0},{1}): expected SD > 0")]
    Normal(f64, f64),
    /// `loguniform(LO,HI)` without 0 < LO < HI.
    #[error("loguniform({0},{1}): expected 0 < LO < HI")]
    LogUniform(f64, f64),
}

impl Distribution {
    /// Parses `uniform(2e-6,8e-6)`, `normal(5e-6,1e-6)` or `loguniform(1e-7,1e-5)`.
    pub fn parse(s: &str) -> Result<Distribution, DistributionError> {
        let form = DistributionError::Form;
        let (name, rest) = s.split_once('(').ok_or(form)?;
        let args: Vec<f64> = rest
            .strip_suffix(')')
            .ok_or(form)?
            .split(',')
            .map(|a| a.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .ok_or(form)?;
        let [a, b] = args[..] else { return Err(form) };
        match name.trim() {
            "uniform" if a < b => Ok(Distribution::Uniform { lo: a, hi: b }),
            "normal" if b > 0.0 => Ok(Distribution::Normal { mean: a, sd: b }),
            "loguniform" if 0.0 < a && a < b => Ok(Distribution::LogUniform { lo: a, hi: b }),
            "uniform" => Err(DistributionError::Uniform(a, b)),
            "normal" => Err(DistributionError::Normal(a, b)),
            "loguniform" => Err(DistributionError::LogUniform(a, b)),
            _ => Err(form),
        }
    }

    /// One draw.
    pub fn draw(self, rng: &mut impl rand::Rng) -> f64 {
        match self {
            Distribution::Uniform { lo, hi } => rng.gen_range(lo..hi),
            Distribution::Normal { mean, sd } => {
                mean + sd * rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, rng)
            }
            Distribution::LogUniform { lo, hi } => rng.gen_range(lo.ln()..hi.ln()).exp(),
        }
    }
}

/// A parameter of the scenario file drawn per trial: `--sample KEY.PATH=DIST`.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// The key path, as written.
    pub path: String,
    /// Its parts ([`set_scenario_number`]).
    pub parts: Vec<(String, Option<usize>)>,
    /// Its distribution.
    pub dist: Distribution,
}

impl Sample {
    /// Parses `truth.effects.backlash.value=uniform(2e-6,8e-6)`.
    pub fn parse(s: &str) -> Result<Sample, VmtError> {
        let usage = |m: &str| {
            VmtError::Usage(format!(
                "--sample {s}: {m} (expected KEY.PATH=uniform(LO,HI), normal(MEAN,SD) or loguniform(LO,HI))"
            ))
        };
        let (path, dist) = s.split_once('=').ok_or_else(|| usage("no `=`"))?;
        if path.starts_with("sensors.") {
            return Err(usage("sensor parameters are studied with --vary (their physics is shared)"));
        }
        Ok(Sample {
            path: path.to_string(),
            parts: parse_key_path(path).map_err(|e| usage(&e.to_string()))?,
            dist: Distribution::parse(dist).map_err(|e| usage(&e.to_string()))?,
        })
    }
}

/// Runs a sampled study: trials `k` with k % shard.1 == shard.0; each trial draws every sampled
/// parameter (its own counter-based random stream `sample/k` from the scenario seed, so a trial's
/// values do not depend on the shard count or threads), simulates that scenario's physics and runs
/// the estimators as [`run_study`] does. Rows carry `value` 0 (one group: all trials) and the drawn
/// values in `sampled`.
pub fn run_sampled_study(
    sc: &Scenario,
    samples: &[Sample],
    trials: usize,
    shard: (usize, usize),
    estimator: Option<&dyn Estimator>,
    tolerance: Option<f64>,
) -> Result<Vec<TrialRow>, VmtError> {
    if trials == 0 || samples.is_empty() {
        return Err(VmtError::Usage("--sample: expected at least one parameter and 1 trial".into()));
    }
    if trials / shard.1 > MAX_TRIALS {
        return Err(VmtError::Usage(format!(
            "{trials} trials in this shard; the limit is {MAX_TRIALS} (split with --shard i/n)"
        )));
    }
    let text = std::fs::read_to_string(&sc.source)
        .map_err(|e| VmtError::io(&sc.source, "reading the scenario to sample it", e))?;
    let jobs: Vec<usize> = (0..trials).filter(|k| k % shard.1 == shard.0).collect();
    let rows: Result<Vec<Vec<TrialRow>>, VmtError> = jobs
        .par_iter()
        .map(|&k| {
            let mut rng = vmt_sim::rng::source_rng(sc.seed, &format!("sample/{k}"));
            let values: Vec<f64> = samples.iter().map(|s| s.dist.draw(&mut rng)).collect();
            let drawn = || {
                samples.iter().zip(&values).map(|(s, v)| format!("{} = {v}", s.path)).collect::<Vec<_>>().join(", ")
            };
            let at = |m: String| {
                VmtError::Usage(format!(
                    "--sample: trial {k} drew {}, which the scenario refuses: {m} (narrow the distribution to values the parameter can take)",
                    drawn()
                ))
            };
            let mut t = text.clone();
            for (s, v) in samples.iter().zip(&values) {
                t = set_scenario_number(&t, &s.parts, *v).map_err(|e| at(e.to_string()))?;
            }
            let scenario = Scenario::parse(&t, &sc.source, sc.source.parent()).map_err(|e| at(e.to_string()))?;
            let ph = physics(&scenario).map_err(|e| at(e.to_string()))?;
            let truth_table = crate::simulate::truth_profiles(&scenario, &ph).map_err(|e| at(e.to_string()))?;
            let truths = simulate_truth(&scenario, &ph);
            // Each trial has its own physics: its compensation re-test is simulated (deriving it would
            // simulate the re-test without compensation instead, at the same cost).
            let session = Session {
                sc: &scenario,
                ph: &ph,
                truths: &truths,
                truth_table: &truth_table,
                clean: None,
                retest: Retest::Simulated,
            };
            let seed = vmt_sim::rng::derive_seed(sc.seed, &format!("study/0/{k}"));
            let mut rows = trial_rows(&session, seed, (0.0, k), estimator, tolerance)?;
            rows.iter_mut().for_each(|r| r.sampled = values.clone());
            Ok(rows)
        })
        .collect();
    Ok(rows?.into_iter().flatten().collect())
}

/// First-order sensitivity of one estimate to one sampled parameter.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SensitivityRow {
    /// The estimate (run-table row).
    pub estimate: String,
    /// The sampled parameter's key path.
    pub parameter: String,
    /// First-order Sobol index S1 = Var(E[d | x]) / Var(d) of the estimate's difference d.
    pub s1: f64,
    /// Half-width of its 95 % bootstrap interval (SALib's `S1_conf`).
    pub s1_conf: f64,
    /// Trials it is computed from.
    pub trials: usize,
}

/// First-order Sobol index from given data (no extra model runs): the trials sorted by x and cut
/// into M = ⌊√n⌋ bins of equal count, S1 = (Var_b(ȳ_b) − mean_b(s_b²/n_b)) / Var(y), the variance of
/// the bin means corrected for the scatter each mean carries (Plischke, Borgonovo & Smith 2013, Eur.
/// J. Oper. Res. 226:536, the "given data" estimator). 0 when y does not vary.
pub fn first_order_index(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len());
    let mut idx: Vec<usize> = (0..n).collect();
    idx.sort_by(|a, b| x[*a].total_cmp(&x[*b]).then(a.cmp(b)));
    let mean = y[..n].iter().sum::<f64>() / n as f64;
    let var = y[..n].iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
    // index: n is a count, so √n is finite and ≥ 0, and m is in 1..=√n.
    let m = ((n as f64).sqrt().floor() as usize).max(1);
    if n < 4 || var <= 0.0 {
        return 0.0;
    }
    let (mut between, mut noise) = (0.0, 0.0);
    for b in 0..m {
        let bin: Vec<f64> = idx[b * n / m..(b + 1) * n / m].iter().map(|&i| y[i]).collect();
        let nb = bin.len() as f64;
        let mb = bin.iter().sum::<f64>() / nb;
        let sb = if nb > 1.0 { bin.iter().map(|v| (v - mb).powi(2)).sum::<f64>() / (nb - 1.0) } else { 0.0 };
        between += nb / n as f64 * (mb - mean).powi(2);
        noise += nb / n as f64 * sb / nb;
    }
    ((between - noise) / var).clamp(0.0, 1.0)
}

/// First-order indices of every estimate's difference to every sampled parameter, with 95 %
/// bootstrap half-widths (200 resamples of the trials, a fixed stream: deterministic).
pub fn sensitivity(rows: &[TrialRow], names: &[String]) -> Vec<SensitivityRow> {
    use rand::Rng;
    let mut estimates: Vec<&str> = rows.iter().map(|r| r.estimate.as_str()).collect();
    estimates.sort_unstable();
    estimates.dedup();
    let mut out = Vec::new();
    for e in estimates {
        let mut of: Vec<&TrialRow> = rows.iter().filter(|r| r.estimate == e && r.difference.is_finite()).collect();
        of.sort_by_key(|r| r.trial);
        let y: Vec<f64> = of.iter().map(|r| r.difference).collect();
        for (j, name) in names.iter().enumerate() {
            let x: Vec<f64> = of.iter().map(|r| r.sampled.get(j).copied().unwrap_or(f64::NAN)).collect();
            let s1 = first_order_index(&x, &y);
            let mut rng = vmt_sim::rng::source_rng(0, &format!("sensitivity/{e}/{name}"));
            let mut boot: Vec<f64> = (0..200)
                .map(|_| {
                    let pick: Vec<usize> = (0..y.len()).map(|_| rng.gen_range(0..y.len().max(1))).collect();
                    let xb: Vec<f64> = pick.iter().map(|&i| x[i]).collect();
                    let yb: Vec<f64> = pick.iter().map(|&i| y[i]).collect();
                    first_order_index(&xb, &yb)
                })
                .collect();
            boot.sort_by(f64::total_cmp);
            let s1_conf = if y.len() >= 4 { 0.5 * (boot[194] - boot[4]) } else { f64::NAN };
            out.push(SensitivityRow { estimate: e.to_string(), parameter: name.clone(), s1, s1_conf, trials: y.len() });
        }
    }
    out
}

/// The scenario text with the number at `parts` replaced by `v`. The key must be in the file (a new
/// key would be ignored where the format accepts unknown keys, so a typo would pass silently); an
/// integer key takes only integral values.
pub fn set_scenario_number(text: &str, parts: &[(String, Option<usize>)], v: f64) -> Result<String, KeyPathError> {
    let mut root: toml::Table = toml::from_str(text).map_err(KeyPathError::Toml)?;
    let mut node: &mut toml::Value =
        root.get_mut(&parts[0].0).ok_or_else(|| KeyPathError::NoKey(parts[0].0.clone()))?;
    let mut walked = parts[0].0.clone();
    for (i, (key, index)) in parts.iter().enumerate() {
        if i > 0 {
            walked += &format!(".{key}");
            node = node
                .as_table_mut()
                .and_then(|t| t.get_mut(key))
                .ok_or_else(|| KeyPathError::NoInnerKey(walked.clone()))?;
        }
        if let Some(j) = index {
            walked += &format!("[{j}]");
            node =
                node.as_array_mut().and_then(|a| a.get_mut(*j)).ok_or_else(|| KeyPathError::NoItem(walked.clone()))?;
        }
    }
    *node = match node {
        toml::Value::Float(_) => toml::Value::Float(v),
        toml::Value::Integer(_) if v.fract() == 0.0 && v.abs() < 9.0e15 => toml::Value::Integer(v as i64),
        toml::Value::Integer(_) => return Err(KeyPathError::NotInteger { path: walked, value: v }),
        other => return Err(KeyPathError::NotNumber { path: walked, what: crate::error::describe_value(other) }),
    };
    Ok(toml::to_string(&root)?)
}

/// One trial's result for one estimate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrialRow {
    /// The varied parameter's value of this trial, in its key's unit (0 in a sampled study, whose draws
    /// are columns of their own).
    pub value: f64,
    /// Trial number, from 0.
    pub trial: usize,
    /// The estimate's label (`Check::error`; `EFFECT RMS` for an external estimator).
    pub estimate: String,
    /// Recovered − injected, SI unit of `quantity`.
    pub difference: f64,
    /// Whether the difference met the tolerance; `None` where no tolerance was given (an external
    /// estimator run without `--tolerance`).
    pub pass: Option<bool>,
    /// Cramér–Rao bound of the difference, where one exists (NaN otherwise).
    pub bound: f64,
    /// What the difference measures (its SI unit: m, rad or none); the `quantity` column of trials.csv.
    pub quantity: Quantity,
    /// A sampled study's parameter values of this trial, in the order of its `--sample` keys (SI);
    /// empty otherwise. The columns of trials.csv after `quantity`, named by their key paths.
    pub sampled: Vec<f64>,
    /// The largest |difference| that passes (SI unit of `quantity`), where the pass rule compares the
    /// difference with a tolerance; `None` for a one-sided limit, a found/not-found check or an external
    /// estimator run without `--tolerance`. The last column of trials.csv.
    pub tolerance: Option<f64>,
}

/// The tolerance a check's difference is held to ([`TrialRow::tolerance`]).
fn difference_tolerance(c: &crate::estimate::Check) -> Option<f64> {
    use crate::estimate::Rule;
    match c.rule {
        Rule::Difference | Rule::RmsDifference => c.tolerance.is_finite().then_some(c.tolerance),
        Rule::AtMost | Rule::Found => None,
    }
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
    // The scenario and physics of each value: one shared for a sensor parameter, one per value for
    // a scenario key (simulated in parallel; each value's trials then share it).
    let scenarios: Vec<Scenario> = match &vary.key {
        VaryKey::Sensor { sensor, key } => {
            if !sc.sensors.iter().any(|s| &s.name == sensor) {
                return Err(VmtError::Usage(format!("--vary: no sensor `{sensor}` in the scenario")));
            }
            // Each value is checked as the scenario file's sensor would be (issue 14: `--vary
            // sensors.laser.scale_factor=0.9` bypassed the file's |scale_factor| < 0.5).
            for &v in &vary.values {
                let mut edited = sc.sensors.clone();
                for s in edited.iter_mut().filter(|s| &s.name == sensor) {
                    *s = s.resolved();
                    key.set(s, v);
                    s.preset = None;
                }
                crate::scenario::validate_sensors(&edited, &sc.axis).map_err(|(place, m)| {
                    VmtError::Usage(format!(
                        "--vary sensors.{sensor}.{}={v}: {}: {place}: {m}",
                        key.key(),
                        sc.source.display()
                    ))
                })?;
            }
            vec![sc.clone()]
        }
        VaryKey::Scenario { path, parts } => {
            let text = std::fs::read_to_string(&sc.source)
                .map_err(|e| VmtError::io(&sc.source, "reading the scenario to vary it", e))?;
            vary.values
                .iter()
                .map(|&v| {
                    let at = |m: String| VmtError::Usage(format!("--vary {path}={v}: {m}"));
                    let t = set_scenario_number(&text, parts, v).map_err(|e| at(e.to_string()))?;
                    Scenario::parse(&t, &sc.source, sc.source.parent()).map_err(|e| at(e.to_string()))
                })
                .collect::<Result<_, _>>()?
        }
    };
    // Each value's compensation re-tests are simulated once without compensation; every trial derives
    // its own table's re-test from them (`Retest::Derived`, issue 12) instead of simulating it.
    type ValueSession =
        (Physics, crate::simulate::SessionTruth, crate::measurement::ProfileTable, UncompensatedRetests);
    let sessions: Vec<ValueSession> = scenarios
        .par_iter()
        .enumerate()
        .map(|(i, s)| {
            let session = || -> Result<_, VmtError> {
                let ph = physics(s)?;
                let table = crate::simulate::truth_profiles(s, &ph)?;
                let truths = simulate_truth(s, &ph);
                let retests = match estimator {
                    Some(_) => UncompensatedRetests::new(),
                    None => uncompensated_retests(s, &ph, truths.end)?,
                };
                Ok((ph, truths, table, retests))
            };
            session().map_err(|e| match &vary.key {
                VaryKey::Sensor { .. } => e,
                VaryKey::Scenario { path, .. } => VmtError::Usage(format!(
                    "--vary {path}={}: the scenario with this value cannot be simulated: {e}",
                    vary.values[i]
                )),
            })
        })
        .collect::<Result<_, VmtError>>()?;
    let of_value = |i: usize| i.min(scenarios.len() - 1);
    // Each value's physics with its sensors, and their noise-free readings: computed once per value,
    // read by every trial with its own seed (the trials differ only in the noise).
    let values: Vec<(Physics, Vec<Vec<Vec<f64>>>)> = (0..vary.values.len())
        .into_par_iter()
        .map(|i| {
            let (sc, (ph, truths, _, _)) = (&scenarios[of_value(i)], &sessions[of_value(i)]);
            let mut p = ph.clone();
            if let VaryKey::Sensor { sensor, key } = &vary.key {
                for s in p.sensors.iter_mut().filter(|s| &s.name == sensor) {
                    *s = s.resolved();
                    key.set(s, vary.values[i]);
                    s.preset = None;
                }
            }
            let clean = crate::simulate::clean_all(sc, &p, truths)?;
            Ok((p, clean))
        })
        .collect::<Result<_, VmtError>>()?;
    let jobs: Vec<(usize, usize)> = (0..vary.values.len())
        .flat_map(|i| (0..trials).filter(|k| k % shard.1 == shard.0).map(move |k| (i, k)))
        .collect();
    let rows: Result<Vec<Vec<TrialRow>>, VmtError> = jobs
        .par_iter()
        .map(|&(i, k)| {
            let (sc, (_, truths, truth_table, retests)) = (&scenarios[of_value(i)], &sessions[of_value(i)]);
            let (p, clean) = &values[i];
            let seed = vmt_sim::rng::derive_seed(sc.seed, &format!("study/{i}/{k}"));
            let session =
                Session { sc, ph: p, truths, truth_table, clean: Some(clean), retest: Retest::Derived(retests) };
            trial_rows(&session, seed, (vary.values[i], k), estimator, tolerance)
        })
        .collect();
    Ok(rows?.into_iter().flatten().collect())
}

/// One value's session: the scenario, its physics with the trial's sensors, the simulated truth of
/// every run and the truth profiles.
struct Session<'a> {
    sc: &'a Scenario,
    ph: &'a Physics,
    truths: &'a crate::simulate::SessionTruth,
    truth_table: &'a crate::measurement::ProfileTable,
    /// The runs' noise-free readings ([`crate::simulate::clean_all`]) when the trials share them;
    /// `None`: computed in the trial.
    clean: Option<&'a [Vec<Vec<f64>>]>,
    /// How the compensation check's re-test is obtained.
    retest: Retest<'a>,
}

/// The rows of one trial: the session read by its sensors with the trial's `seed`, then the
/// scenario's estimators (or `estimator`, scored against the truth). `(v, k)`: the row's value and
/// trial number.
fn trial_rows(
    session: &Session,
    seed: u64,
    (v, k): (f64, usize),
    estimator: Option<&dyn Estimator>,
    tolerance: Option<f64>,
) -> Result<Vec<TrialRow>, VmtError> {
    let Session { sc, ph: p, truths, truth_table, clean, retest } = *session;
    let runs = match clean {
        Some(c) => crate::simulate::read_all_clean(sc, p, truths, seed, c)?,
        None => read_all(sc, p, truths, seed)?,
    };
    let set = to_measurement_set(sc, &runs)?;
    if let Some(e) = estimator {
        let work = std::env::temp_dir().join(format!("vmt-study-{}-{seed:x}", std::process::id()));
        let table = e.estimate(&set, &work);
        let _ = std::fs::remove_dir_all(&work);
        let rows = score_profiles(truth_table, &table?).map_err(|e| {
            VmtError::Usage(format!("--estimator-cmd: its profile CSV cannot be scored against the truth: {e}"))
        })?;
        return Ok(rows
            .into_iter()
            .map(|r| TrialRow {
                value: v,
                trial: k,
                estimate: format!("{} RMS", r.effect),
                difference: r.rms,
                pass: tolerance.map(|t| r.rms <= t),
                bound: f64::NAN,
                quantity: motion_quantity(&r.effect),
                sampled: Vec::new(),
                tolerance,
            })
            .collect());
    }
    // The compensation check re-measures on this trial's sensors, after the session simulated once.
    let est = crate::workflow::run::estimate_session(sc, p, truths, &set, retest)?;
    Ok(est
        .checks
        .into_iter()
        .map(|c| TrialRow {
            tolerance: difference_tolerance(&c),
            value: v,
            trial: k,
            estimate: c.error,
            difference: c.difference,
            pass: Some(c.pass),
            bound: c.bound.unwrap_or(f64::NAN),
            quantity: c.quantity,
            sampled: Vec::new(),
        })
        .collect())
}

/// How a study CSV writes a difference-like number of quantity `q` (SI m, rad or ratio): with
/// `UnitChoice::Si` as is; with `UnitChoice::Metrology` ("human") lengths in µm and angles in µrad,
/// returned with the unit the file's `unit` column names (`um`, `urad`, `1`).
pub fn study_unit(q: Quantity, units: crate::measurement::UnitChoice) -> (f64, &'static str) {
    use crate::measurement::UnitChoice;
    match (units, q) {
        (UnitChoice::Si, Quantity::Length) => (1.0, "m"),
        (UnitChoice::Si, Quantity::Angle) => (1.0, "rad"),
        (UnitChoice::Metrology, Quantity::Length) => (1e6, "um"),
        (UnitChoice::Metrology, Quantity::Angle) => (1e6, "urad"),
        (UnitChoice::Si | UnitChoice::Metrology, Quantity::Ratio) => (1.0, "1"),
    }
}

/// One statistic `si` (SI) of a study row of quantity `q` as a CSV cell in `units`: SI as Rust prints
/// it; in human units (µm, µrad) with the fewest digits that read back to within one ulp of the SI
/// value ([`crate::measurement::fmt_in_unit`]): a 0.1 µm tolerance is written 0.1, not the product
/// 1e-7 × 1e6 = 0.09999999999999999.
pub fn study_cell(q: Quantity, units: crate::measurement::UnitChoice, si: f64) -> String {
    use crate::measurement::UnitChoice;
    match units {
        UnitChoice::Si => si.to_string(),
        UnitChoice::Metrology => {
            let (_, symbol) = study_unit(q, units);
            crate::units::unit(symbol).map_or_else(|| si.to_string(), |u| crate::measurement::fmt_in_unit(&u, si))
        }
    }
}

/// CSV of trial rows (value, trial, estimate, difference, pass, bound, quantity, then one column per
/// sampled parameter named by its key path, then `tolerance`), sorted so shards merge to the same file.
/// With `UnitChoice::Metrology` the difference, bound and tolerance of each row are in µm or µrad as its
/// quantity says, and a last column `unit` names it (`value` and the sampled parameters stay in their
/// keys' SI units); `study merge` reads only the SI file.
pub fn rows_csv(rows: &[TrialRow], sampled: &[String], units: crate::measurement::UnitChoice) -> String {
    let human = units == crate::measurement::UnitChoice::Metrology;
    let mut rows = rows.to_vec();
    rows.sort_by(|a, b| a.value.total_cmp(&b.value).then(a.trial.cmp(&b.trial)).then(a.estimate.cmp(&b.estimate)));
    let mut s = String::from("value,trial,estimate,difference,pass,bound,quantity");
    for name in sampled {
        s += &format!(",\"{}\"", name.replace('"', "'"));
    }
    s += if human { ",tolerance,unit\n" } else { ",tolerance\n" };
    for r in rows {
        let (_, unit) = study_unit(r.quantity, units);
        let cell = |x: f64| study_cell(r.quantity, units, x);
        s += &format!(
            "{},{},\"{}\",{},{},{},{}",
            r.value,
            r.trial,
            r.estimate.replace('"', "'"),
            cell(r.difference),
            r.pass.map_or(String::new(), |p| p.to_string()),
            cell(r.bound),
            quantity_id(r.quantity)
        );
        for v in &r.sampled {
            s += &format!(",{v}");
        }
        s += &format!(",{}", r.tolerance.map_or(String::new(), cell));
        s += &if human { format!(",{unit}\n") } else { "\n".to_string() };
    }
    s
}

/// Reads a CSV written by `rows_csv`: its rows and the names of its sampled-parameter columns.
pub fn read_rows(path: &Path) -> Result<(Vec<TrialRow>, Vec<String>), VmtError> {
    let text = std::fs::read_to_string(path).map_err(|e| VmtError::io(path, "reading", e))?;
    let mut rdr = csv::ReaderBuilder::new().from_reader(text.as_bytes());
    let mut sampled: Vec<String> = rdr
        .headers()
        .map_err(|e| VmtError::bad(path, "line 1 (header)", e.to_string()))?
        .iter()
        .skip(7)
        .map(str::to_string)
        .collect();
    if sampled.last().is_some_and(|n| n == "unit") {
        return Err(VmtError::bad(
            path,
            "line 1 (header)",
            "a trials.csv written with --units human (µm/µrad per row); merge the SI files (--units si)",
        ));
    }
    // The last column `tolerance` (absent from files written before it existed).
    let with_tolerance = sampled.last().is_some_and(|n| n == "tolerance");
    if with_tolerance {
        sampled.pop();
    }
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
        // The trial number as `study` writes it: a non-negative integer (issue 14: `-1`, `1.5` or `nan`
        // were cast to a trial number without a word).
        let trial = f(1).parse::<usize>().map_err(|_| {
            VmtError::bad(
                path,
                format!("line {}, column trial", i + 2),
                format!("expected a trial number (an integer ≥ 0), got `{}`", f(1)),
            )
        })?;
        out.push(TrialRow {
            value,
            trial,
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
            sampled: (7..7 + sampled.len()).map(&num).collect::<Result<_, _>>()?,
            tolerance: match (with_tolerance, f(7 + sampled.len())) {
                (false, _) | (true, "") => None,
                (true, _) => Some(num(7 + sampled.len())?),
            },
        });
    }
    Ok((out, sampled))
}

/// Which part of which study an output directory holds: `shard.toml` beside `trials.csv`
/// (docs/formats.md §6), written by `vmt study` (and by `vmt study merge`, as shard 0 of 1) so that
/// `vmt study merge` can name a missing or repeated shard and refuse shards of different studies.
///
/// Two shards belong to one study when every field but `shard` is equal: the same vmt version, the same
/// scenario file content (FNV-1a 64 of its bytes; the file may sit at another path on another machine),
/// the same design (`--vary`/`--sample` arguments as given), trial count, external estimator and its
/// tolerance. Shard i of n holds the trials k < `trials` with k mod n = i.
#[derive(Clone, Debug, PartialEq)]
pub struct ShardInfo {
    /// The vmt version that computed the shard.
    pub vmt_version: String,
    /// FNV-1a 64 of the scenario file's bytes, 16 hex digits.
    pub scenario_fnv1a64: String,
    /// The design as given on the command line: `--vary KEY=V1,V2,…` or the `--sample KEY=DIST`
    /// arguments joined by spaces.
    pub design: String,
    /// Trials per value of the whole study (`--trials`).
    pub trials: usize,
    /// `--estimator-cmd`, if any.
    pub estimator_cmd: Option<String>,
    /// `--tolerance` (SI: m or rad), if any.
    pub tolerance: Option<f64>,
    /// This shard's index i, 0 ≤ i < `shards`.
    pub shard: usize,
    /// The number of shards n the study was split into (1: the whole study).
    pub shards: usize,
}

/// The format line of `shard.toml`.
pub const SHARD_FORMAT: &str = "vmt-study-shard/1";

impl ShardInfo {
    /// The file's text (TOML).
    pub fn to_toml(&self) -> String {
        let q = |s: &str| toml::Value::String(s.to_string()).to_string();
        let mut t = format!(
            "# which part of which vmt study this directory holds (docs/formats.md §6)\nformat = {}\nvmt_version = {}\n\
             scenario_fnv1a64 = {}\ndesign = {}\ntrials = {}\n",
            q(SHARD_FORMAT),
            q(&self.vmt_version),
            q(&self.scenario_fnv1a64),
            q(&self.design),
            self.trials
        );
        if let Some(c) = &self.estimator_cmd {
            t += &format!("estimator_cmd = {}\n", q(c));
        }
        if let Some(x) = self.tolerance {
            t += &format!("tolerance = {}\n", crate::measurement::fmt_toml_f64(x));
        }
        t += &format!("shard = {}\nshards = {}\n", self.shard, self.shards);
        t
    }

    /// Reads `shard.toml` (every key checked; unknown keys refused).
    pub fn read(path: &Path) -> Result<ShardInfo, VmtError> {
        let text = std::fs::read_to_string(path).map_err(|e| VmtError::io(path, "reading the shard's identity", e))?;
        let table = crate::error::parse_toml(path, &text)?;
        let r = crate::error::TomlReader::new(path, "", &table);
        let format = r.req_str("format", "the format line")?;
        if format != SHARD_FORMAT {
            return Err(r.bad("format", format!("expected \"{SHARD_FORMAT}\", got \"{format}\"")));
        }
        let count = |key: &str| -> Result<usize, VmtError> {
            let v = r.opt_u64(key, "a count")?.ok_or_else(|| r.bad(key, "missing key: expected a count"))?;
            usize::try_from(v).map_err(|_| r.bad(key, format!("{v} is too large")))
        };
        let info = ShardInfo {
            vmt_version: r.req_str("vmt_version", "the vmt version")?.to_string(),
            scenario_fnv1a64: r.req_str("scenario_fnv1a64", "a hash")?.to_string(),
            design: r.req_str("design", "the study design")?.to_string(),
            trials: count("trials")?,
            estimator_cmd: r.opt_str("estimator_cmd", "a command")?.map(str::to_string),
            tolerance: r.opt_f64("tolerance", "a tolerance")?,
            shard: count("shard")?,
            shards: count("shards")?,
        };
        r.deny_unknown()?;
        if info.shards == 0 || info.shard >= info.shards {
            return Err(r.bad("shard", format!("shard {} of {}: expected 0 ≤ shard < shards", info.shard, info.shards)));
        }
        Ok(info)
    }

    /// The fields two shards of one study share, by name, as text (everything but `shard`).
    fn identity(&self) -> [(&'static str, String); 7] {
        [
            ("vmt_version", self.vmt_version.clone()),
            ("scenario_fnv1a64", self.scenario_fnv1a64.clone()),
            ("design", self.design.clone()),
            ("trials", self.trials.to_string()),
            ("estimator_cmd", format!("{:?}", self.estimator_cmd)),
            ("tolerance", format!("{:?}", self.tolerance)),
            ("shards", self.shards.to_string()),
        ]
    }
}

/// FNV-1a 64 of a file's bytes as `ShardInfo::scenario_fnv1a64` writes it.
pub fn content_fnv1a64(bytes: &[u8]) -> String {
    let h = bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ *b as u64).wrapping_mul(0x0000_0100_0000_01b3));
    format!("{h:016x}")
}

/// Checks that `shards` (directory, its `shard.toml`, its trial rows) are the n shards of one study, each
/// once and complete: the same identity ([`ShardInfo`]), every index 0..n present once, and each shard's
/// rows holding exactly its trials (k < trials, k mod n = i, every such k present). Errors name the
/// directories, the missing or repeated shard indices, or the field that differs.
pub fn check_shards(shards: &[(std::path::PathBuf, ShardInfo, Vec<TrialRow>)]) -> Result<(), VmtError> {
    let Some((first_dir, first, _)) = shards.first() else {
        return Err(VmtError::Usage("study merge: expected at least one shard directory".into()));
    };
    let file = |d: &Path| d.join("shard.toml");
    for (dir, info, _) in &shards[1..] {
        for ((key, a), (_, b)) in first.identity().iter().zip(info.identity().iter()) {
            if a != b {
                return Err(VmtError::bad(
                    &file(dir),
                    format!("key {key}"),
                    format!("{key} = {b}, but {} has {key} = {a}: not shards of one study", file(first_dir).display()),
                ));
            }
        }
    }
    let n = first.shards;
    let mut by_index: Vec<Vec<&Path>> = vec![Vec::new(); n];
    for (dir, info, _) in shards {
        by_index[info.shard].push(dir);
    }
    let repeated: Vec<String> = by_index
        .iter()
        .enumerate()
        .filter(|(_, d)| d.len() > 1)
        .map(|(i, d)| {
            format!("{i}/{n} in {}", d.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(" and "))
        })
        .collect();
    if !repeated.is_empty() {
        return Err(VmtError::Usage(format!("study merge: shard given more than once: {}", repeated.join("; "))));
    }
    let missing: Vec<String> =
        by_index.iter().enumerate().filter(|(_, d)| d.is_empty()).map(|(i, _)| format!("{i}/{n}")).collect();
    if !missing.is_empty() {
        return Err(VmtError::Usage(format!(
            "study merge: shard{} {} missing (a study split in {n} needs every shard 0/{n} … {}/{n})",
            if missing.len() > 1 { "s" } else { "" },
            missing.join(", "),
            n - 1
        )));
    }
    for (dir, info, rows) in shards {
        let csv = dir.join("trials.csv");
        let mut seen = std::collections::BTreeSet::new();
        for r in rows {
            if r.trial >= info.trials || r.trial % n != info.shard {
                return Err(VmtError::bad(
                    &csv,
                    format!("trial {}", r.trial),
                    format!("not a trial of shard {}/{n} of a study of {} trials", info.shard, info.trials),
                ));
            }
            seen.insert(r.trial);
        }
        if let Some(k) = (info.shard..info.trials).step_by(n).find(|k| !seen.contains(k)) {
            return Err(VmtError::bad(
                &csv,
                format!("trial {k}"),
                format!(
                    "missing: shard {}/{n} holds trials k < {} with k mod {n} = {}",
                    info.shard, info.trials, info.shard
                ),
            ));
        }
    }
    Ok(())
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
    /// What the differences are (their unit).
    pub quantity: Quantity,
    /// The tolerance every trial of the group held its difference to (SI), `None` when the trials had
    /// none or differing ones.
    pub tolerance: Option<f64>,
}

/// The `quantity` column of trials.csv and summary.csv.
pub fn quantity_id(q: Quantity) -> &'static str {
    match q {
        Quantity::Length => "length",
        Quantity::Angle => "angle",
        Quantity::Ratio => "ratio",
    }
}

/// One summary row per (value, estimate) of the trials, sorted by value then estimate: mean, RMS and
/// 95th percentile of |difference|, pass rate and mean bound ([`SummaryRow`]).
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
            let tolerances: Vec<Option<f64>> = rows.iter().filter(|r| same(r, v, &e)).map(|r| r.tolerance).collect();
            let tolerance = tolerances.first().copied().flatten().filter(|t| tolerances.iter().all(|x| *x == Some(*t)));
            SummaryRow {
                value: v,
                estimate: e,
                trials: n,
                mean_abs: stat(&|d| d.iter().sum::<f64>() / n as f64),
                rms: stat(&|d| (d.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt()),
                // clamp: `stat` runs only when `defined`, i.e. n ≥ 1.
                // index: the clamp keeps ⌈0.95·n⌉ in 1..=n, so the index is in 0..n (n ≥ 1 when `stat` runs).
                p95_abs: stat(&|d| d[((0.95 * n as f64).ceil() as usize).clamp(1, n) - 1]),
                pass_rate,
                bound,
                quantity,
                tolerance,
            }
        })
        .collect()
}

/// The (value, statistic × `scale`) points of `rows` where the statistic `stat` is defined, for a plot
/// (an estimate without a difference, e.g. the compensation check's one-sided limit, has none).
pub fn defined_points(rows: &[&SummaryRow], stat: fn(&SummaryRow) -> Option<f64>, scale: f64) -> (Vec<f64>, Vec<f64>) {
    rows.iter().filter_map(|s| stat(s).map(|y| (s.value, y * scale))).filter(|(_, y)| y.is_finite()).unzip()
}

/// The tolerance of an estimate's summary rows as a figure series (µm or µrad against the varied value,
/// drawn across the values it holds at), or None where the rows have no common tolerance.
pub fn tolerance_line(rows: &[&SummaryRow]) -> Option<vmt_report::Series> {
    let (x, y): (Vec<f64>, Vec<f64>) = rows.iter().filter_map(|s| s.tolerance.map(|t| (s.value, t * 1e6))).unzip();
    (!x.is_empty()).then(|| vmt_report::Series {
        label: "tolerance".into(),
        x,
        y,
        style: vmt_report::SeriesStyle::Dashed,
    })
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
        if let Some(t) = tolerance_line(&pts) {
            series.push(Series { label: format!("{n}: tolerance"), ..t });
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
