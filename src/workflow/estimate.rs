//! Workflow `estimate`: the estimators a scenario names, applied to its recording and compared with the
//! injected truth. Each check is one row of `vmt run`'s table: the error (or value) estimated, the
//! injected value, the recovered one, their difference, the tolerance (with its reason) and pass/fail.

use crate::error::VmtError;
use crate::measurement::MeasurementSet;
pub use crate::scenario::spec::EstimatorSpec;
use crate::scenario::Scenario;
use crate::simulate::{Physics, TruthView};
use serde::{Deserialize, Serialize};
use std::path::Path;
use vmt_estimators::iso230_2::{evaluate_bidirectional, AxisResult};
use vmt_report::{Figure, FigureKind, Series, SeriesStyle};
use vmt_sim::effects::EffectName;
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::procedures::{ProcedureSpec, RunData, RunRecord};

/// What a check compares (for units in the table).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    Length,
    Angle,
    Ratio,
}

/// How a row of the result table passes; the table prints the rule in words beside each row.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Rule {
    /// |recovered − injected| ≤ tolerance; difference = recovered − injected.
    #[default]
    Difference,
    /// Profiles: injected and recovered are the RMS of each profile over the positions, difference the
    /// RMS of their point-by-point difference (recovered − injected); passes when difference ≤ tolerance.
    RmsDifference,
    /// One-sided: recovered ≤ tolerance. `injected` is the reference the limit derives from (e.g. E before
    /// compensation), not a truth the estimate should equal; no difference is formed.
    AtMost,
    /// The expected effect was found (recovered 1 = yes, 0 = no; injected 1 = expected).
    Found,
}

impl Rule {
    /// The rule in words, as the table's `pass rule` column shows it.
    pub fn describe(self) -> &'static str {
        match self {
            Rule::Difference => "|difference| ≤ tolerance",
            Rule::RmsDifference => "RMS difference ≤ tolerance",
            Rule::AtMost => "recovered ≤ tolerance",
            Rule::Found => "found",
        }
    }
}

/// One row of the result table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Check {
    /// Stable identifier of the row (for programs: `--json` keys checks by it), e.g.
    /// `iso230_2.laser_x3.e`; the display label `error` may change, this does not.
    #[serde(default)]
    pub id: String,
    /// Display label of the row.
    pub error: String,
    /// What `injected` and `recovered` are (e.g. `ISO 230-2 E`, `RMS of profile`, `SSI`).
    #[serde(default)]
    pub statistic: String,
    /// A sentence printed under the table for this row (where the columns need one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// Index of the figure (in `Estimates::figures`) that shows this estimate.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub figure: Option<usize>,
    /// A lower bound of the achievable difference where one exists (Cramér–Rao), same unit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bound: Option<f64>,
    pub quantity: Quantity,
    pub injected: f64,
    pub recovered: f64,
    /// As `rule` defines it; NaN (JSON null) for [`Rule::AtMost`] and [`Rule::Found`], which form none.
    pub difference: f64,
    pub tolerance: f64,
    #[serde(default)]
    pub rule: Rule,
    pub pass: bool,
}

/// Lower-case identifier from a label: letters and digits kept, everything else one `_`.
pub fn slug(label: &str) -> String {
    let mut s = String::new();
    for c in label.chars() {
        if c.is_ascii_alphanumeric() {
            s.push(c.to_ascii_lowercase());
        } else if !s.ends_with('_') && !s.is_empty() {
            s.push('_');
        }
    }
    s.trim_end_matches('_').to_string()
}

impl Check {
    /// A one-sided limit: `recovered` (e.g. E re-measured after compensation) passes when ≤ `limit`;
    /// `reference` (e.g. E before compensation) is shown in the `injected` column.
    pub fn at_most(
        id: impl Into<String>,
        error: impl Into<String>,
        quantity: Quantity,
        reference: f64,
        recovered: f64,
        limit: f64,
    ) -> Check {
        Check {
            rule: Rule::AtMost,
            difference: f64::NAN,
            pass: recovered <= limit,
            ..Check::new(error, quantity, reference, recovered, limit).with_id(id)
        }
    }

    /// The expected effect `found` or not.
    pub fn found(id: impl Into<String>, error: impl Into<String>, found: bool) -> Check {
        Check {
            rule: Rule::Found,
            statistic: "found (yes/no)".into(),
            difference: f64::NAN,
            tolerance: f64::NAN,
            pass: found,
            ..Check::new(error, Quantity::Ratio, 1.0, if found { 1.0 } else { 0.0 }, 0.0).with_id(id)
        }
    }

    /// A profile comparison: RMS of the injected and recovered profiles, and the RMS of their difference
    /// as the difference (the check passes when it is within the tolerance).
    pub fn profile(
        error: impl Into<String>,
        quantity: Quantity,
        truth: &[f64],
        estimate: &[f64],
        tolerance: f64,
    ) -> Check {
        let rms = |v: &mut dyn Iterator<Item = f64>| {
            let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
            (s / n.max(1) as f64).sqrt()
        };
        let difference = rms(&mut truth.iter().zip(estimate).map(|(a, b)| b - a));
        Check {
            statistic: "RMS of profile".into(),
            rule: Rule::RmsDifference,
            injected: rms(&mut truth.iter().copied()),
            recovered: rms(&mut estimate.iter().copied()),
            difference,
            pass: difference <= tolerance,
            ..Check::new(error, quantity, 0.0, 0.0, tolerance)
        }
    }

    /// A value against its injected truth: passes when |recovered − injected| ≤ tolerance. The id is the
    /// label's [`slug`] until [`Check::with_id`] sets one.
    pub fn new(error: impl Into<String>, quantity: Quantity, injected: f64, recovered: f64, tolerance: f64) -> Check {
        let error = error.into();
        let difference = recovered - injected;
        Check {
            id: slug(&error),
            error,
            statistic: String::new(),
            note: None,
            figure: None,
            bound: None,
            quantity,
            injected,
            recovered,
            difference,
            tolerance,
            rule: Rule::Difference,
            pass: difference.abs() <= tolerance,
        }
    }

    pub fn with_id(self, id: impl Into<String>) -> Check {
        Check { id: id.into(), ..self }
    }

    pub fn with_statistic(self, statistic: impl Into<String>) -> Check {
        Check { statistic: statistic.into(), ..self }
    }

    pub fn with_note(self, note: impl Into<String>) -> Check {
        Check { note: Some(note.into()), ..self }
    }

    /// The row's cells as the table prints them: error, statistic, injected, recovered, difference,
    /// tolerance, pass rule, pass. Cells a rule does not use are `—`.
    pub fn cells(&self) -> [String; 8] {
        let q = self.quantity;
        let dash = || "—".to_string();
        let (injected, recovered) = match self.rule {
            Rule::Found => ("yes".to_string(), if self.recovered == 1.0 { "yes" } else { "no" }.to_string()),
            Rule::Difference | Rule::RmsDifference | Rule::AtMost => {
                (display(q, self.injected), display(q, self.recovered))
            }
        };
        let difference = match self.rule {
            Rule::Difference | Rule::RmsDifference => display(q, self.difference),
            Rule::AtMost | Rule::Found => dash(),
        };
        let tolerance = match self.rule {
            Rule::Found => dash(),
            Rule::Difference | Rule::RmsDifference | Rule::AtMost => display(q, self.tolerance),
        };
        [
            self.error.clone(),
            self.statistic.clone(),
            injected,
            recovered,
            difference,
            tolerance,
            self.rule.describe().to_string(),
            if self.pass { "pass" } else { "FAIL" }.to_string(),
        ]
    }
}

/// The header of [`Check::cells`].
pub const CHECK_HEADER: [&str; 8] =
    ["error", "statistic", "injected", "recovered", "difference", "tolerance", "pass rule", "pass"];

/// What the columns of the result table mean, printed under it.
pub const CHECK_LEGEND: &str =
    "difference = recovered − injected; for `RMS of profile` rows, injected and recovered are the \
RMS of each profile over the positions and difference is the RMS of their point-by-point difference (not the \
difference of the two RMS values). Each row passes by the rule in its `pass rule` column.";

/// A value in display units with sensible digits: µm for lengths, µrad for angles, 3 decimals otherwise.
pub fn display(q: Quantity, v: f64) -> String {
    if !v.is_finite() {
        return "—".to_string();
    }
    match q {
        Quantity::Length => format!("{:.3} µm", v * 1e6),
        Quantity::Angle => format!("{:.3} µrad", v * 1e6),
        Quantity::Ratio => format!("{v:.3} (dimensionless)"),
    }
}

/// A line figure of profiles against position: x in mm, y in µm (lengths) or µrad (angles).
pub fn profile_figure(title: String, q: Quantity, x: &[f64], series: &[(&str, &[f64], SeriesStyle)]) -> Figure {
    let (y_label, y_unit) = match q {
        Quantity::Length => ("deviation", "µm"),
        Quantity::Angle => ("angle", "µrad"),
        Quantity::Ratio => ("value", ""),
    };
    let scale = if q == Quantity::Ratio { 1.0 } else { 1e6 };
    Figure {
        title,
        x_label: "position".into(),
        x_unit: "mm".into(),
        y_label: y_label.into(),
        y_unit: y_unit.into(),
        series: series
            .iter()
            .map(|(label, y, style)| Series {
                label: label.to_string(),
                x: x.iter().map(|v| v * 1e3).collect(),
                y: y.iter().map(|v| v * scale).collect(),
                style: *style,
            })
            .collect(),
        kind: FigureKind::Line,
        log_x: false,
        log_y: false,
    }
}

/// The result of the estimators: the checks (rows of the table) and the figures they point to.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Estimates {
    pub checks: Vec<Check>,
    #[serde(skip)]
    pub figures: Vec<Figure>,
    /// Tables an estimator reports in full (e.g. the ISO 230-2 table).
    #[serde(skip)]
    pub tables: Vec<vmt_report::Table>,
    /// Statements the report prints beside the tables (e.g. the ISO 230-2 uncertainty statement).
    #[serde(skip)]
    pub notes: Vec<String>,
}

impl Estimates {
    /// Adds a figure that illustrates an estimator without being the figure of a check.
    fn push_figure(&mut self, figure: Figure) {
        self.figures.push(figure);
    }

    /// Adds checks shown by a figure (a figure with the same title as an earlier one is shared).
    fn push(&mut self, checks: Vec<Check>, figure: Figure) {
        let idx = match self.figures.iter().position(|f| f.title == figure.title) {
            Some(i) => i,
            None => {
                self.figures.push(figure);
                self.figures.len() - 1
            }
        };
        self.checks.extend(checks.into_iter().map(|c| Check { figure: Some(idx), ..c }));
    }
}

pub use crate::report::iso::iso_table;

/// Deviations of one sensor column of a point table, split by direction: (targets, up[i][j], down[i][j]).
pub fn point_table_deviations(run: &RunRecord, sensor: &str) -> Option<(Vec<f64>, Vec<Vec<f64>>, Vec<Vec<f64>>)> {
    let RunData::PointTable { target, direction, columns, .. } = &run.data else { return None };
    let values = &columns.iter().find(|(n, _)| n == sensor)?.1;
    let mut targets: Vec<f64> = target.clone();
    targets.sort_by(f64::total_cmp);
    targets.dedup();
    let index = |x: f64| targets.iter().position(|&t| t == x).unwrap_or(0);
    let mut up = vec![Vec::new(); targets.len()];
    let mut down = vec![Vec::new(); targets.len()];
    for ((&x, &d), &v) in target.iter().zip(direction).zip(values) {
        let side = if d > 0 { &mut up } else { &mut down };
        side[index(x)].push(v);
    }
    Some((targets, up, down))
}

/// ISO 230-2 values of the noise-free injected deviation along x at body point r (axis frame) at the
/// targets: with no noise and a purely geometric truth, both directions see δx(P_i) = EXX + (ε × r)_x.
pub fn iso_truth(errors: &ErrorMotions, r: [f64; 3], targets: &[f64]) -> Result<AxisResult, VmtError> {
    let r = rapier3d_f64::glamx::DVec3::from_array(r);
    let dev: Vec<Vec<f64>> = targets.iter().map(|&x| vec![errors.deviation(x, r).x; 2]).collect();
    evaluate_bidirectional(targets, &dev, &dev).map_err(|e| VmtError::Internal(e.to_string()))
}

/// The compensation check's re-measurement: runs `procedure` (a positioning procedure) on the machine
/// with the compensation table (positions, corrections; m) in its CNC and returns the run as its sensors
/// read it. The estimate workflow owns no machine: the caller passes one
/// ([`crate::simulate::remeasure`] on the scenario's physics for `vmt run` and a study).
pub type Remeasure<'a> = dyn Fn(&ProcedureSpec, &[f64], &[f64]) -> Result<RunRecord, String> + Sync + 'a;

/// Runs every estimator of a scenario on its simulated recording and returns the checks with their
/// figures: [`estimate_recording`] with the measurement set written from `runs` and the compensation
/// check re-measuring on `ph` after the session.
pub fn run_estimators(sc: &Scenario, ph: &Physics, runs: &[RunRecord]) -> Result<Estimates, VmtError> {
    let set = crate::simulate::to_measurement_set(sc, runs)?;
    let end = crate::simulate::session_end(&crate::simulate::session_plan(sc, ph));
    let remeasure = |p: &ProcedureSpec, x: &[f64], y: &[f64]| crate::simulate::remeasure(ph, sc.seed, end, p, x, y);
    estimate_recording(sc, ph.view(), runs, &set, &remeasure)
}

/// Runs every estimator of a scenario on its recording (`runs`, and `set`, the measurement set they are
/// written as) and returns the checks with their figures; `truth` is what the estimates are compared
/// with, `remeasure` the machine the compensation check re-measures on.
pub fn estimate_recording(
    sc: &Scenario,
    truth: TruthView<'_>,
    runs: &[RunRecord],
    set: &MeasurementSet,
    remeasure: &Remeasure<'_>,
) -> Result<Estimates, VmtError> {
    let errors = truth.motions;
    let mut out = Estimates::default();
    for spec in &sc.estimators {
        match spec {
            EstimatorSpec::Iso230_2 { run, sensor, tolerance } => {
                let bad = |m: String| VmtError::bad(&sc.source, format!("estimators (iso230_2 {run})"), m);
                let rec = runs.iter().find(|r| &r.name == run).ok_or_else(|| bad(format!("no run `{run}`")))?;
                let (targets, up, down) = point_table_deviations(rec, sensor)
                    .ok_or_else(|| bad(format!("run `{run}` is not a point table with sensor `{sensor}`")))?;
                let est = evaluate_bidirectional(&targets, &up, &down).map_err(|e| bad(e.to_string()))?;
                let spec = sc
                    .sensors
                    .iter()
                    .find(|s| &s.name == sensor)
                    .ok_or_else(|| bad(format!("sensor `{sensor}` is not declared")))?;
                let r = spec.axis_position(&sc.axis).map_err(bad)?;
                let truth = iso_truth(errors, r, &targets)?;
                let checks =
                    [("E", "e", truth.e, est.e), ("M", "m", truth.m, est.m), ("B̄", "b_mean", truth.b_mean, est.b_mean)]
                        .into_iter()
                        .map(|(label, id, t, e)| {
                            Check::new(format!("ISO 230-2 {label} ({sensor})"), Quantity::Length, t, e, *tolerance)
                                .with_id(format!("iso230_2.{sensor}.{id}"))
                                .with_statistic(format!("ISO 230-2 {label}"))
                        })
                        .collect();
                let injected: Vec<f64> = truth.targets.iter().map(|t| t.mean_bidirectional).collect();
                let fig = crate::report::iso::iso_figure(sensor, &targets, &up, &down, &est, Some(&injected));
                out.push(checks, fig);
                out.tables.push(iso_table(&format!("ISO 230-2:2014 evaluation of run {run}, {sensor}"), &est));
                let travel = targets.last().copied().unwrap_or(0.0) - targets.first().copied().unwrap_or(0.0);
                let env = spec.air_scale_error() + spec.material_scale_error();
                out.notes.push(crate::report::iso::uncertainty_statement(sensor, spec.sigma, env, travel));
            }
            EstimatorSpec::LaserLines { run, sensors, tolerance_translation, tolerance_angle } => {
                for (c, f) in
                    laser_lines_checks(sc, runs, errors, run, sensors, *tolerance_translation, *tolerance_angle)?
                {
                    out.push(vec![c], f);
                }
            }
            EstimatorSpec::Compensation { run, sensor, max_ratio, pearson, residual } => {
                let (checks, fig) =
                    compensation_checks(sc, remeasure, runs, run, sensor, *max_ratio, *pearson, *residual)?;
                out.push(checks, fig);
            }
            EstimatorSpec::Ssi { procedure, sensor, expected, tolerance } => {
                let bad = |m: String| VmtError::bad(&sc.source, format!("estimators (ssi {procedure})"), m);
                let crawl: Vec<&RunRecord> =
                    runs.iter().filter(|r| r.name.starts_with(&format!("{procedure}_"))).collect();
                if crawl.len() != expected.len() || expected.len() != tolerance.len() {
                    return Err(bad(format!(
                        "{} runs but {} expected values and {} tolerances",
                        crawl.len(),
                        expected.len(),
                        tolerance.len()
                    )));
                }
                let q = sc.sensors.iter().find(|s| &s.name == sensor).map(|s| s.resolution).filter(|&q| q > 0.0);
                for ((r, e), tol) in crawl.iter().zip(expected).zip(tolerance) {
                    let RunData::TimeSeries { t, .. } = &r.data else { return Err(bad("expected time series".into())) };
                    let x = r.data.column(sensor).ok_or_else(|| bad(format!("run `{}` has no `{sensor}`", r.name)))?;
                    let dt =
                        crate::measurement::uniform_interval(t).map_err(|m| bad(format!("run `{}`: {m}", r.name)))?;
                    let res = vmt_estimators::ssi::stick_slip_index(x, dt, q).map_err(|e| bad(e.to_string()))?;
                    let feed = r.feed.unwrap_or(0.0) * 60_000.0;
                    let v: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]) / dt * 60_000.0).collect();
                    let fig = Figure {
                        title: format!(
                            "crawl at {feed:.0} mm/min: velocity from the differentiated {sensor} (SSI {:.2})",
                            res.ssi
                        ),
                        x_label: "time".into(),
                        x_unit: "s".into(),
                        y_label: "velocity".into(),
                        y_unit: "mm/min".into(),
                        series: vec![Series {
                            label: sensor.clone(),
                            x: t[1..].to_vec(),
                            y: v,
                            style: SeriesStyle::Line,
                        }],
                        kind: FigureKind::Line,
                        log_x: false,
                        log_y: false,
                    };
                    // The patent's example value is a reference, not an injected truth (the SSI follows from
                    // the simulated physics). An interval that reaches 0 is a one-sided limit: say so.
                    let id = format!("ssi.{sensor}.{feed:.0}_mm_per_min");
                    let label = format!("SSI at {feed:.0} mm/min");
                    let check = if e - tol <= 0.0 {
                        Check::at_most(id, label, Quantity::Ratio, *e, res.ssi, e + tol)
                    } else {
                        Check::new(label, Quantity::Ratio, *e, res.ssi, *tol).with_id(id)
                    };
                    let check = check.with_statistic("stick-slip index").with_note(format!(
                        "`injected` is the patent's example SSI at this feed ({e:.2}); SSI ≥ 1 means crawling (SSI {:.3}: {})",
                        res.ssi,
                        if res.ssi >= 1.0 { "crawling" } else { "smooth" }
                    ));
                    out.push(vec![check], fig);
                }
            }
            EstimatorSpec::ModelCheck { model, expected, max_steps, tolerance } => {
                let (checks, fig, residuals) = model_check_loop(sc, set, model, expected, *max_steps, *tolerance)?;
                out.push(checks, fig);
                out.push_figure(residuals);
            }
            EstimatorSpec::LaserLines3d { procedure, k_sigma, bias, bias_angle } => {
                let bias_angle = bias_angle.unwrap_or(*bias);
                for (checks, fig) in laser_lines_3d_checks(sc, runs, procedure, *k_sigma, *bias, bias_angle)? {
                    out.push(checks, fig);
                }
            }
            EstimatorSpec::AccelStraightness { procedure, sensor, method, tolerance } => {
                let simulated = truth.sensors.iter().find(|s| &s.name == sensor).map(|s| s.resolved());
                let (c, f, stages) = accel_straightness_check(
                    sc,
                    set,
                    errors,
                    simulated.as_ref(),
                    procedure,
                    sensor,
                    method.as_deref(),
                    *tolerance,
                )?;
                out.push(vec![c], f);
                stages.into_iter().for_each(|g| out.push_figure(g));
            }
        }
    }
    Ok(out)
}

/// The accelerometer straightness check of one sensor (seed 000 / SNR-weighted fusion).
#[allow(clippy::too_many_arguments)]
fn accel_straightness_check(
    sc: &Scenario,
    set: &MeasurementSet,
    errors: &ErrorMotions,
    simulated: Option<&vmt_sim::sensors::SensorSpec>,
    procedure: &str,
    sensor: &str,
    method: Option<&str>,
    tolerance: f64,
) -> Result<(Check, Figure, Vec<Figure>), VmtError> {
    use crate::straightness::{parse_method, sensor_straightness, PassSelection};
    use vmt_estimators::accel_straightness::{integrate_curvature_cosine, zero_phase_highpass, SpectralBasis};
    let bad = |m: String| VmtError::bad(&sc.source, format!("estimators ({procedure}/{sensor})"), m);
    let spec = sc.sensors.iter().find(|s| s.name == sensor).ok_or_else(|| bad("sensor not declared".into()))?;
    // The same adapter as `vmt straightness` on the measurement set this recording is written as.
    let method = parse_method(method.unwrap_or("snr_weighted")).map_err(bad)?;
    let result = sensor_straightness(set, &sc.source, sensor, PassSelection::Procedure(procedure), method)?;
    let (acc_runs, est) = (result.runs, result.estimate);
    let r = rapier3d_f64::glamx::DVec3::from_array(spec.axis_position(&sc.axis).map_err(bad)?);
    let u = spec.unit_direction();
    let n = est.positions.len();
    let dx = (est.positions[n - 1] - est.positions[0]).abs() / (n - 1) as f64;
    // What the check does to a profile over the whole range before comparing (the same for truth, estimate
    // and, below, each basis function of the bound): the DFT pipeline applies the estimator's zero-phase
    // high-pass at the band's longest wavelength (the accelerometer cannot see longer ones) and keeps the
    // interior 80 % (edge transients of the filter); both then remove the least-squares line (ISO 230-1).
    let (i0, i1) = match est.basis {
        SpectralBasis::Cosine => (0, n),
        SpectralBasis::Periodic => (n / 10, n - n / 10),
    };
    let xs = &est.positions[i0..i1];
    let post = |p: &[f64]| -> Result<Vec<f64>, VmtError> {
        let p = match est.basis {
            SpectralBasis::Cosine => p.to_vec(),
            SpectralBasis::Periodic => {
                zero_phase_highpass(p, 1.0 / est.band.max_wavelength, 1.0 / dx).map_err(|e| bad(e.to_string()))?
            }
        };
        Ok(vmt_estimators::line::remove_line(xs, &p[i0..i1]))
    };
    let truth: Vec<f64> = match est.basis {
        // The truth band-limited by the estimator's own operator: the mount point's noise-free curvature
        // u·(E'' + ε''×r) integrated in the cosine basis over the recoverable band, over the whole range.
        SpectralBasis::Cosine => {
            let curvature: Vec<f64> = est.positions.iter().map(|&x| u.dot(errors.curvature(x, r))).collect();
            let (lo, hi) = (est.band.min_wavelength, est.band.max_wavelength);
            integrate_curvature_cosine(&est.positions, &curvature, lo, hi).map_err(|e| bad(e.to_string()))?
        }
        SpectralBasis::Periodic => est.positions.iter().map(|&x| u.dot(errors.deviation(x, r))).collect(),
    };
    let (truth, estimate) = (post(&truth)?, post(&est.straightness)?);
    // Cramér–Rao bound of the RMS difference as this check measures it. The estimate's error is a sum of
    // the band's basis functions φ_k (λ_k = P/k; P = L for the DFT with a cosine and a sine per k, P = 2L
    // for the cosine basis, φ_k = cos(π·k·(x − x₀ + Δx/2)/L)), each coefficient of an unbiased estimate
    // with variance ≥ σ_k², the bound per quadrature component (`cramer_rao_harmonic`: AC-coupling loss,
    // joint when the tilt is separated). The check compares P(estimate) with P(truth) for the linear
    // post-processing P above, so E[RMS²] ≥ Σ_k σ_k²·mean((P φ_k)²). P matters: the longest wavelengths
    // carry the largest σ_k (σ ∝ λ²) and are nearly a straight line over the range, which the reference
    // line removes.
    //
    // A bound follows from the true noise model, not from the data: σ_k uses the simulated sensor's white
    // noise density ρ (or σ/√(fs/2) for a sensor given by its per-sample σ), the same for any estimator.
    // The estimator's own ρ, estimated from the record's upper half-band (`estimate_noise_density`), also
    // holds the machine's high-frequency vibration; with it the "bound" stayed near 0.06 µm over a 100×
    // range of ρ and lay above the achieved error (issue 13).
    let rhos: Vec<f64> = est
        .runs
        .iter()
        .map(|r| match simulated {
            Some(s) if s.noise_density > 0.0 => s.noise_density,
            Some(s) => s.sigma / (r.sample_rate / 2.0).sqrt(),
            None => r.noise_density,
        })
        .collect();
    let speeds: Vec<f64> = est.runs.iter().map(|r| r.speed).collect();
    let sigma_k = |lam: f64| {
        vmt_estimators::accel_straightness::cramer_rao_harmonic(
            &rhos,
            &speeds,
            est.travel,
            lam,
            est.ac_coupling_hz,
            est.gravity_tilt_separated,
        )
        .map(|b| b.straightness)
    };
    let (period, phases): (f64, &[f64]) = match est.basis {
        SpectralBasis::Periodic => (est.travel, &[0.0, std::f64::consts::FRAC_PI_2]),
        SpectralBasis::Cosine => (2.0 * est.travel, &[0.0]),
    };
    let x0 = est.positions[0]
        - match est.basis {
            SpectralBasis::Periodic => 0.0,
            SpectralBasis::Cosine => dx / 2.0,
        };
    let mut var = 0.0;
    for k in 1.. {
        let lam = period / k as f64;
        if lam < est.band.min_wavelength {
            break;
        }
        if lam > est.band.max_wavelength {
            continue;
        }
        let Ok(s) = sigma_k(lam) else { continue };
        for &phase in phases {
            let phi: Vec<f64> =
                est.positions.iter().map(|&x| (2.0 * std::f64::consts::PI * (x - x0) / lam - phase).cos()).collect();
            let p = post(&phi)?;
            var += s * s * p.iter().map(|v| v * v).sum::<f64>() / p.len() as f64;
        }
    }
    let bound = var.sqrt();
    let name = format!("straightness {sensor} (accelerometer)");
    let fig = profile_figure(
        format!(
            "{name}: injected vs recovered in the recoverable band {:.0}–{:.0} mm (Cramér–Rao bound of the RMS error {:.3} µm)",
            est.band.min_wavelength * 1e3,
            est.band.max_wavelength * 1e3,
            bound * 1e6
        ),
        Quantity::Length,
        xs,
        &[("injected (same band)", &truth, SeriesStyle::Line), ("recovered", &estimate, SeriesStyle::Dashed)],
    );
    let check = Check {
        bound: Some(bound),
        ..Check::profile(name, Quantity::Length, &truth, &estimate, tolerance)
            .with_id(format!("accel_straightness.{sensor}"))
            .with_note(format!(
                "both profiles band-limited to the recoverable wavelengths {}–{} mm; Cramér–Rao bound of the RMS difference {}",
                four_significant(est.band.min_wavelength * 1e3),
                four_significant(est.band.max_wavelength * 1e3),
                display(Quantity::Length, bound)
            ))
    };
    // The pipeline stage by stage (seed 000): raw acceleration per speed, then each speed's displacement
    // after Kalman filter, double integration and zero-phase high-pass; the fused result is `fig`.
    let mut raw = Figure {
        title: format!("{sensor}, stage 1: acceleration of each constant-velocity pass (mean removed)"),
        x_label: "position".into(),
        x_unit: "mm".into(),
        y_label: "acceleration".into(),
        y_unit: "mm/s²".into(),
        series: Vec::new(),
        kind: FigureKind::Line,
        log_x: false,
        log_y: false,
    };
    let mut disp = Figure {
        title: format!(
            "{sensor}, stage 2: displacement of each pass (Kalman, double integration, zero-phase high-pass)"
        ),
        y_label: "displacement".into(),
        y_unit: "µm".into(),
        ..raw.clone()
    };
    for (r, d) in acc_runs.iter().zip(&est.runs) {
        let x = vmt_estimators::accel_straightness::run_positions(r).map_err(|e| bad(e.to_string()))?;
        let mean = r.acceleration.iter().sum::<f64>() / r.acceleration.len() as f64;
        let label = format!("{:.0} mm/s", r.speed * 1e3);
        raw.series.push(Series {
            label: label.clone(),
            x: x.iter().map(|v| v * 1e3).collect(),
            y: r.acceleration.iter().map(|a| (a - mean) * 1e3).collect(),
            style: SeriesStyle::Line,
        });
        let cutoff = d.cutoff_wavelength.unwrap_or(est.band.max_wavelength);
        if let Ok((u, _)) = vmt_estimators::accel_straightness::seed_run_displacement(r, cutoff, true) {
            disp.series.push(Series {
                label,
                x: x.iter().map(|v| v * 1e3).collect(),
                y: u.iter().map(|v| v * 1e6).collect(),
                style: SeriesStyle::Line,
            });
        }
    }
    Ok((check, fig, vec![raw, disp]))
}

/// One laser line of a point table: its column, measuring point (axis frame, m), beam direction and the
/// 1σ noise of a reading (m).
#[derive(Clone, Debug, PartialEq)]
pub struct LaserLine {
    pub name: String,
    pub point: [f64; 3],
    pub direction: [f64; 3],
    pub sigma: f64,
}

/// Identifies the six error motions of one axis from the laser lines of a point table with the general
/// least-squares identifier (seeds 001/003), one zero offset per line, values at the measured targets.
pub fn identify_laser_lines(
    target: &[f64],
    columns: &[(String, Vec<f64>)],
    lines: &[LaserLine],
) -> Result<(vmt_estimators::laser_ls::Identification, vmt_estimators::laser_ls::Model), String> {
    use vmt_estimators::laser_ls::{identify, AxisModel, AxisName, IdOptions, Model, Reading};
    let mut readings = Vec::new();
    for (line, l) in lines.iter().enumerate() {
        let values = &columns.iter().find(|(n, _)| *n == l.name).ok_or_else(|| format!("no column `{}`", l.name))?.1;
        for (&x, &v) in target.iter().zip(values) {
            readings.push(Reading {
                q: vec![x],
                point: l.point,
                direction: l.direction,
                value: v,
                sigma: l.sigma.max(1e-12),
                line: Some(line),
            });
        }
    }
    let mut nodes = target.to_vec();
    nodes.sort_by(f64::total_cmp);
    nodes.dedup();
    let model = Model { axes: vec![AxisModel::with_nodes(AxisName::X, &nodes)], squareness: false };
    let id = identify(&readings, &model, &IdOptions::default()).map_err(|e| e.to_string())?;
    Ok((id, model))
}

/// The six error motions identified from the laser lines of a point-table run, compared with the truth.
fn laser_lines_checks(
    sc: &Scenario,
    runs: &[RunRecord],
    errors: &ErrorMotions,
    run: &str,
    sensors: &[String],
    tol_t: f64,
    tol_a: f64,
) -> Result<Vec<(Check, Figure)>, VmtError> {
    let bad = |m: String| VmtError::bad(&sc.source, format!("estimators (laser_lines {run})"), m);
    let rec = runs.iter().find(|r| r.name == run).ok_or_else(|| bad(format!("no run `{run}`")))?;
    let RunData::PointTable { target, columns, .. } = &rec.data else {
        return Err(bad("expected a point table".into()));
    };
    let mut lines = Vec::new();
    for name in sensors {
        let spec = sc
            .sensors
            .iter()
            .find(|s| &s.name == name)
            .ok_or_else(|| bad(format!("sensor `{name}` is not declared")))?;
        lines.push(LaserLine {
            name: name.clone(),
            point: spec.axis_position(&sc.axis).map_err(bad)?,
            direction: spec.unit_direction().to_array(),
            sigma: (spec.sigma.powi(2) + spec.resolution.powi(2) / 12.0).sqrt(),
        });
    }
    let (id, model) = identify_laser_lines(target, columns, &lines).map_err(bad)?;
    let mut checks = Vec::new();
    for (i, sym) in ["EXX", "EYX", "EZX", "EAX", "EBX", "ECX"].iter().enumerate() {
        let p = id.profile(sym).ok_or_else(|| bad(format!("identifier returned no {sym}")))?;
        let mut truth: Vec<f64> = p.positions.iter().map(|&x| errors.by_index(i).value(x)).collect();
        if i == 1 || i == 2 {
            truth = vmt_estimators::line::remove_line(&p.positions, &truth);
        } else {
            let t0 = errors.by_index(i).value(model.axes[0].reference_position);
            truth.iter_mut().for_each(|v| *v -= t0);
        }
        let (q, tol) = if i < 3 { (Quantity::Length, tol_t) } else { (Quantity::Angle, tol_a) };
        let name = format!("{sym} {} (laser lines)", vmt_sim::geometry::ERROR_MOTION_NAMES[i]);
        let fig = profile_figure(
            format!("{name}: injected vs identified"),
            q,
            &p.positions,
            &[("injected", &truth, SeriesStyle::Line), ("identified", &p.values, SeriesStyle::Points)],
        );
        let check = Check::profile(name, q, &truth, &p.values, tol).with_id(format!("laser_lines.{run}.{sym}"));
        checks.push((check, fig));
    }
    if !id.unobservable.is_empty() {
        return Err(bad(format!("the laser lines leave unobservable: {}", id.unobservable.join("; "))));
    }
    Ok(checks)
}

/// Seed 004's compensation loop: table from the ISO test, applied in the CNC, test repeated.
/// The result of [`identify_chain_lines`]: the identification, the model it used and the node
/// positions of each axis (m, chain order).
#[derive(Clone, Debug, Serialize)]
pub struct ChainIdentification {
    pub identification: vmt_estimators::laser_ls::Identification,
    pub model: vmt_estimators::laser_ls::Model,
    pub positions: Vec<Vec<f64>>,
}

/// Identifies the 3 × 6 error motions and the squareness of a chain from the laser-line runs of the
/// chain procedure `procedure` (seed 001; DESIGN.md §7): every reading is u·δ(q, r) + offset of its
/// line (`vmt_estimators::laser_ls` model, one unknown zero per line), q from the runs' `x_cmd`, `y_cmd`,
/// `z_cmd` columns, r and u from the line, σ the procedure's `sigma` (1e-12 m if zero). Each error
/// motion is parameterised by its values at the distinct joint positions of its axis (piecewise
/// linear), the reference position being the lowest.
pub fn identify_chain_lines(sc: &Scenario, runs: &[RunRecord], procedure: &str) -> Result<ChainIdentification, String> {
    use vmt_estimators::laser_ls::Reading;
    let chain = sc.chain.as_ref().ok_or("laser_lines_3d needs a multi-axis scenario (axes = [...])")?;
    let letters = chain.letters();
    let mut readings = Vec::new();
    let mut n_lines = 0;
    for rec in runs {
        let Some((spec, line)) = crate::simulate::chain_line(sc, &rec.name) else { continue };
        if spec.name != procedure {
            continue;
        }
        let RunData::PointTable { columns, .. } = &rec.data else {
            return Err(format!("run `{}` is not a point table", rec.name));
        };
        let qs = axis_commands(&rec.name, columns, &letters)?;
        let values = column_of(&rec.name, columns, &line.name)?;
        for (i, &v) in values.iter().enumerate() {
            readings.push(Reading {
                q: qs.iter().map(|c| c[i]).collect(),
                point: line.point,
                direction: line.beam().to_array(),
                value: v,
                sigma: spec.sigma.max(1e-12),
                line: Some(n_lines),
            });
        }
        n_lines += 1;
    }
    if readings.is_empty() {
        return Err(format!("no laser-line runs of chain procedure `{procedure}`"));
    }
    identify_axis_readings(readings, &letters)
}

/// Column `name` of run `run`'s point table.
fn column_of<'a>(run: &str, columns: &'a [(String, Vec<f64>)], name: &str) -> Result<&'a Vec<f64>, String> {
    columns.iter().find(|(c, _)| c == name).map(|(_, v)| v).ok_or_else(|| format!("run `{run}` has no column `{name}`"))
}

/// The commanded joint positions of a multi-axis point table, one column `{l}_cmd` per axis letter.
pub fn axis_commands<'a>(
    run: &str,
    columns: &'a [(String, Vec<f64>)],
    letters: &[char],
) -> Result<Vec<&'a Vec<f64>>, String> {
    letters.iter().map(|l| column_of(run, columns, &format!("{l}_cmd"))).collect()
}

/// The 21-error identification (laser_ls with squareness) of laser readings taken at joint positions
/// `q` of the axes `letters` (chain order, bed first): each error motion is parameterised by its values
/// at the distinct positions of its axis (piecewise linear), the reference position being the lowest.
pub fn identify_axis_readings(
    mut readings: Vec<vmt_estimators::laser_ls::Reading>,
    letters: &[char],
) -> Result<ChainIdentification, String> {
    use vmt_estimators::laser_ls::{identify, AxisModel, AxisName, IdOptions, Model};
    let mut positions = Vec::new();
    let mut axes = Vec::new();
    for (j, l) in letters.iter().enumerate() {
        let mut p: Vec<f64> = readings.iter().map(|r| r.q[j]).collect();
        p.sort_by(f64::total_cmp);
        // Stops computed as from + (to − from)·k/(n − 1) differ by float rounding: one node per 1 nm.
        p.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        if p.len() < 2 {
            return Err(format!("the lines stop at only one position of axis {l}: at least two are needed"));
        }
        let name = match l {
            'x' => AxisName::X,
            'y' => AxisName::Y,
            _ => AxisName::Z,
        };
        axes.push(AxisModel::with_nodes(name, &p));
        positions.push(p);
    }
    // Snap each reading's q onto its node (float rounding of the stops) so the basis is exact there.
    for r in &mut readings {
        for (j, q) in r.q.iter_mut().enumerate() {
            if let Some(n) = positions[j].iter().find(|n| (**n - *q).abs() < 1e-9) {
                *q = *n;
            }
        }
    }
    let model = Model { axes, squareness: true };
    let identification = identify(&readings, &model, &IdOptions::default()).map_err(|e| e.to_string())?;
    Ok(ChainIdentification { identification, model, positions })
}

fn laser_lines_3d_checks(
    sc: &Scenario,
    runs: &[RunRecord],
    procedure: &str,
    k_sigma: f64,
    bias: f64,
    bias_angle: f64,
) -> Result<Vec<(Vec<Check>, Figure)>, VmtError> {
    let bad = |m: String| VmtError::bad(&sc.source, format!("estimators (laser_lines_3d {procedure})"), m);
    if !(k_sigma.is_finite() && k_sigma > 0.0 && bias.is_finite() && bias >= 0.0)
        || !(bias_angle.is_finite() && bias_angle >= 0.0)
    {
        return Err(bad(format!(
            "expected k_sigma > 0, bias ≥ 0 and bias_angle ≥ 0 (rad), got {k_sigma}, {bias} and {bias_angle}"
        )));
    }
    let chain = sc.chain.as_ref().ok_or_else(|| bad("needs a multi-axis scenario (axes = [...])".into()))?;
    let ci = identify_chain_lines(sc, runs, procedure).map_err(bad)?;
    let injected = chain.effective_squareness(&ci.positions);
    let letters = chain.letters();
    let mut checks = Vec::new();
    let (mut names, mut inj, mut rec, mut raw) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (effect, iso, (a, b)) in [
        ("squareness_xy", "EC0Y", ('x', 'y')),
        ("squareness_xz", "EB0Z", ('x', 'z')),
        ("squareness_yz", "EA0Z", ('y', 'z')),
    ] {
        if !(letters.contains(&a) && letters.contains(&b)) {
            continue;
        }
        let est = ci.identification.squareness(effect).ok_or_else(|| bad(format!("identifier returned no {iso}")))?;
        let sigma = est.std_error.ok_or_else(|| {
            bad(format!("{iso} is not observable with these lines: add a diagonal in the {a}{b} plane"))
        })?;
        let truth = injected.pair(a, b).map_or(0.0, |(t, _)| t);
        let check = Check {
            bound: Some(sigma),
            ..Check::new(
                // "Injected" is the ISO 230-1 squareness the lines measure: the angle between the
                // least-squares lines of the axes' paths, i.e. the injected angle plus the paths' slopes.
                format!(
                    "{iso} {effect} (laser lines 3D, ±{:.3} µrad 1σ; {:.3} µrad + path slopes)",
                    sigma * 1e6,
                    chain.squareness.pair(a, b).map_or(0.0, |(t, _)| t) * 1e6
                ),
                Quantity::Angle,
                truth,
                est.value,
                k_sigma * sigma + bias,
            )
            .with_id(format!("laser_lines_3d.{procedure}.{effect}"))
            .with_statistic("ISO 230-1 squareness")
            .with_note(format!(
                "ISO 230-1 squareness is the angle between the least-squares lines of the axes' paths: the injected \
                 squareness value {} plus {} from the straightness error motions' linear trends = `injected` {}",
                display(Quantity::Angle, chain.squareness.pair(a, b).map_or(0.0, |(t, _)| t)),
                display(Quantity::Angle, truth - chain.squareness.pair(a, b).map_or(0.0, |(t, _)| t)),
                display(Quantity::Angle, truth)
            ))
        };
        checks.push(check);
        names.push(iso);
        inj.push(truth);
        rec.push(est.value);
        raw.push(chain.squareness.pair(a, b).map_or(0.0, |(t, _)| t));
    }
    let x: Vec<f64> = (1..=names.len()).map(|i| i as f64).collect();
    let fig = Figure {
        title: format!(
            "squareness from the laser line set `{procedure}` ({}): injected vs recovered, µrad",
            names.join(", ")
        ),
        x_label: "angle (1 = first listed)".into(),
        x_unit: vmt_report::DIMENSIONLESS.into(),
        y_label: "angle".into(),
        y_unit: "µrad".into(),
        series: vec![
            Series {
                label: "injected".into(),
                x: x.clone(),
                y: inj.iter().map(|v| v * 1e6).collect(),
                style: SeriesStyle::Line,
            },
            Series {
                label: "recovered".into(),
                x: x.clone(),
                y: rec.iter().map(|v| v * 1e6).collect(),
                style: SeriesStyle::Line,
            },
            Series {
                label: "squareness value of the truth (without the error motions' trends)".into(),
                x,
                y: raw.iter().map(|v| v * 1e6).collect(),
                style: SeriesStyle::Line,
            },
        ],
        kind: FigureKind::Bar,
        log_x: false,
        log_y: false,
    };
    let mut out = vec![(checks, fig)];
    // The angular error motions the lines determine (every reported value has a standard error):
    // the carriage's rotation is the same at every point of it, so the truth is the injected angle
    // relative to its value at the reference position (laser_ls's reporting convention).
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    for (j, a) in chain.axes.iter().enumerate() {
        for (k, effect) in [EffectName::Roll, EffectName::Pitch, EffectName::Yaw].into_iter().enumerate() {
            let Some(iso) = effect.iso230_symbol(a.letter) else { continue };
            let Some(p) = ci.identification.profile(&iso) else { continue };
            let Some(sig) = p.std_errors.iter().copied().collect::<Option<Vec<f64>>>() else { continue };
            let profile = a.motions.by_index(3 + k);
            let r0 = profile.value(ci.model.axes[j].reference_position);
            let truth: Vec<f64> = p.positions.iter().map(|&q| profile.value(q) - r0).collect();
            let s = rms(&sig);
            let name = format!("{iso} {}.{effect} (laser lines 3D)", a.letter);
            let fig = profile_figure(
                format!("{name}: injected vs identified (±{:.3} µrad RMS 1σ)", s * 1e6),
                Quantity::Angle,
                &p.positions,
                &[("injected", &truth, SeriesStyle::Line), ("identified", &p.values, SeriesStyle::Points)],
            );
            let check = Check {
                bound: Some(s),
                ..Check::profile(name, Quantity::Angle, &truth, &p.values, k_sigma * s + bias_angle)
                    .with_id(format!("laser_lines_3d.{procedure}.{iso}"))
            };
            out.push((vec![check], fig));
        }
    }
    Ok(out)
}

#[allow(clippy::too_many_arguments)]
fn compensation_checks(
    sc: &Scenario,
    remeasure: &Remeasure<'_>,
    runs: &[RunRecord],
    run: &str,
    sensor: &str,
    max_ratio: f64,
    pearson: f64,
    residual: f64,
) -> Result<(Vec<Check>, Figure), VmtError> {
    use vmt_estimators::compensation::{variable_step_table, VariableStepParams};
    let bad = |m: String| VmtError::bad(&sc.source, format!("estimators (compensation {run})"), m);
    let iso = |rec: &RunRecord| -> Result<AxisResult, VmtError> {
        let (t, u, d) = point_table_deviations(rec, sensor)
            .ok_or_else(|| bad(format!("run `{}` has no point-table column `{sensor}`", rec.name)))?;
        evaluate_bidirectional(&t, &u, &d).map_err(|e| bad(e.to_string()))
    };
    let rec = runs.iter().find(|r| r.name == run).ok_or_else(|| bad(format!("no run `{run}`")))?;
    let before = iso(rec)?;
    let positions: Vec<f64> = before.targets.iter().map(|t| t.target).collect();
    let deviations: Vec<f64> = before.targets.iter().map(|t| t.mean_bidirectional).collect();
    let params = VariableStepParams { min_abs_pearson: pearson, max_abs_residual: residual, ..Default::default() };
    let table = variable_step_table(&positions, &deviations, &params).map_err(|e| bad(e.to_string()))?.table;
    let spec = sc.procedures.iter().find(|p| p.name() == run).ok_or_else(|| bad(format!("no procedure `{run}`")))?;
    let ProcedureSpec::Positioning { .. } = spec else { return Err(bad("expected a positioning procedure".into())) };
    let mut verify = spec.clone();
    if let ProcedureSpec::Positioning { name, targets, n_targets, .. } = &mut verify {
        // Re-test at other irregular targets (targets derive from the procedure name), as many as before.
        *n_targets = targets.as_ref().map_or(*n_targets, Vec::len);
        *targets = None;
        *name = format!("{run}_after_compensation");
    }
    // The re-test follows the scenario's session (time-dependent effects have moved on meanwhile).
    let after_rec = remeasure(&verify, &table.positions, &table.corrections).map_err(bad)?;
    let after = iso(&after_rec)?;
    let label = format!("{} nodes", table.positions.len());
    let after_t: Vec<f64> = after.targets.iter().map(|t| t.target).collect();
    let after_dev: Vec<f64> = after.targets.iter().map(|t| t.mean_bidirectional).collect();
    let mut fig = profile_figure(
        format!("compensation (variable-step table, docs/methods.md, of {label}): mean deviation before and after"),
        Quantity::Length,
        &positions,
        &[("before", &deviations, SeriesStyle::Line), ("table", &table.corrections, SeriesStyle::Points)],
    );
    fig.series.push(Series {
        label: "after (other targets)".into(),
        x: after_t.iter().map(|v| v * 1e3).collect(),
        y: after_dev.iter().map(|v| v * 1e6).collect(),
        style: SeriesStyle::Line,
    });
    fig.series[1].x = table.positions.iter().map(|v| v * 1e3).collect();
    Ok((
        vec![
            Check::at_most(
                format!("compensation.{sensor}.e_after"),
                format!("E after compensation ({label})"),
                Quantity::Length,
                before.e,
                after.e,
                max_ratio * before.e,
            )
            .with_statistic("ISO 230-2 E")
            .with_note(format!(
                "re-measured at other targets after compensation; `injected` shows E before compensation \
                 ({}), the tolerance is {max_ratio} × that",
                display(Quantity::Length, before.e)
            )),
            Check::at_most(
                format!("compensation.{sensor}.a_after"),
                format!("A after compensation ({label})"),
                Quantity::Length,
                before.a,
                after.a,
                max_ratio * before.a,
            )
            .with_statistic("ISO 230-2 A")
            .with_note(format!(
                "`injected` shows A before compensation ({}), the tolerance is {max_ratio} × that",
                display(Quantity::Length, before.a)
            )),
        ],
        fig,
    ))
}

/// The model-check loop run to its end on a recording: normalised RMS per iteration and the effects added.
fn model_check_loop(
    sc: &Scenario,
    set: &MeasurementSet,
    model: &str,
    expected: &[String],
    max_steps: usize,
    tolerance: f64,
) -> Result<(Vec<Check>, Figure, Figure), VmtError> {
    use crate::modelcheck::{add_effect, compare, diagnose};
    use vmt_estimators::modelcheck::Verdict;
    let base = sc.source.parent().unwrap_or(Path::new("."));
    let mut m = crate::model::read_model(&base.join(model))?;
    let first = compare(&m, set, &sc.source)?;
    let mut history = vec![first.normalized_rms];
    let mut last_report = first.clone();
    let mut added: Vec<String> = Vec::new();
    for _ in 0..max_steps {
        let d = diagnose(&m, set, &sc.source)?;
        let Some(top) = d.ranking.iter().find(|r| r.verdict == Verdict::Significant) else { break };
        let name: vmt_sim::effects::EffectName =
            top.effect.parse().map_err(|e: vmt_sim::effects::UnknownEffect| VmtError::Internal(e.to_string()))?;
        m = add_effect(&m, name, Some(top)).map_err(|e| VmtError::bad(&sc.source, "estimators (model_check)", e))?;
        added.push(top.effect.clone());
        last_report = compare(&m, set, &sc.source)?;
        history.push(last_report.normalized_rms);
    }
    let mut checks: Vec<Check> = expected
        .iter()
        .map(|e| {
            Check::found(format!("model_check.finds.{e}"), format!("model-check loop finds {e}"), added.contains(e))
        })
        .collect();
    let last = *history.last().unwrap_or(&f64::NAN);
    checks.push(
        Check::at_most(
            "model_check.normalized_rms",
            format!("normalised RMS after {} step(s)", added.len()),
            Quantity::Ratio,
            history[0],
            last,
            tolerance,
        )
        .with_statistic("normalised RMS")
        .with_note(format!(
            "residual RMS / noise σ (1 = noise level); `injected` shows it for the starting model ({:.3})",
            history[0]
        )),
    );
    let fig = Figure {
        title: format!(
            "model-check loop: normalised residual RMS per iteration (added: {})",
            if added.is_empty() { "nothing".into() } else { added.join(", ") }
        ),
        x_label: "iteration".into(),
        x_unit: vmt_report::DIMENSIONLESS.into(),
        y_label: "normalised RMS".into(),
        y_unit: "1 = noise".into(),
        series: vec![Series {
            label: "residual / σ".into(),
            x: (0..history.len()).map(|i| i as f64).collect(),
            y: history.clone(),
            style: SeriesStyle::Points,
        }],
        kind: FigureKind::Line,
        log_x: false,
        log_y: history.iter().all(|v| *v > 0.0),
    };
    // Residual RMS by position of the first channel, before and after the loop.
    let by_pos = |r: &crate::modelcheck::CompareReport, label: &str| -> Option<Series> {
        let c = r.channels.first()?;
        Some(Series {
            label: format!("{label} ({} / {})", c.run, c.sensor),
            x: c.by_position.iter().map(|b| 0.5 * (b.0 + b.1) * 1e3).collect(),
            y: c.by_position.iter().map(|b| b.3 * 1e6).collect(),
            style: SeriesStyle::Line,
        })
    };
    let residuals = Figure {
        title: "model-check loop: residual RMS by position, starting model and final model".into(),
        x_label: "position".into(),
        x_unit: "mm".into(),
        y_label: "residual RMS".into(),
        y_unit: "µm (or N for force channels)".into(),
        series: [by_pos(&first, "starting model"), by_pos(&last_report, "final model")].into_iter().flatten().collect(),
        kind: FigureKind::Line,
        log_x: false,
        log_y: false,
    };
    Ok((checks, fig, residuals))
}

/// `x` with four significant digits and no trailing zeros (1.5, 399.9, 0.04): a band edge read literally
/// (whole millimetres showed 1.5 mm as "2").
fn four_significant(x: f64) -> String {
    if !(x.is_finite() && x != 0.0) {
        return format!("{x}");
    }
    let decimals = (3 - x.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}
