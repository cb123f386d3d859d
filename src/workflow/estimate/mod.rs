//! Workflow `estimate`: the estimators a scenario names, applied to its recording (one measurement set,
//! FORMAT.md §1) and compared with the injected truth (a [`TruthView`]). Each check is one row of `vmt
//! run`'s table: the error (or value) estimated, the injected value, the recovered one, their difference,
//! the tolerance (with its reason) and pass/fail.
//!
//! One adapter per estimator, each taking the measurement set and plain settings; the file commands
//! (`vmt iso230-2`, `compensate`, `identify`, `ssi`, `straightness`) call the same glue:
//! [`iso`] (ISO 230-2 evaluation, figure and table), [`compensation`] (seed 004), [`laser_lines`]
//! (seeds 001/003, one axis), [`chain`] (seed 001, the 21 errors of a chain), [`ssi`] (seed 002),
//! [`straightness`] (seed 000, accelerometers), [`model_check`] (the compare → diagnose → add loop).
//! The workflow never sees the scenario or the simulator's physics (checked by a test in `workflow`): the truth
//! comes as a [`TruthView`], a re-measurement as a [`Remeasure`] callback.

use crate::error::VmtError;
use crate::measurement::{MeasurementSet, Run};
pub use crate::scenario::spec::EstimatorSpec;
pub use crate::workflow::truth::{ChainTruth, RemeasureError, SensorTruth, TruthView};
use serde::{Deserialize, Serialize};
use std::path::Path;
use vmt_report::{Figure, FigureKind, Series, SeriesStyle};

pub mod chain;
pub mod compensation;
pub mod error;
pub mod iso;
pub mod laser_lines;
pub mod model_check;
pub mod ssi;
pub mod straightness;

pub use chain::{axis_commands, identify_axis_readings, ChainIdentification};
pub use error::LineSetError;
pub use iso::{iso_table, point_table_deviations};
pub use laser_lines::{identify_laser_lines, LaserLine};

/// What a check compares (for units in the table).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// A length, m (shown in µm).
    Length,
    /// An angle, rad (shown in µrad).
    Angle,
    /// A dimensionless ratio.
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

/// An ISO 230-2:2014 positioning parameter a check compares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Iso230_2Parameter {
    /// Bidirectional systematic positioning error E (§3.3.6).
    E,
    /// Bidirectional accuracy of positioning A (§3.3.10).
    A,
    /// Range of the mean bidirectional positional deviation M (§3.3.9).
    M,
    /// Mean reversal value B̄ (§3.3.4).
    BMean,
}

impl Iso230_2Parameter {
    /// The parameter's symbol as the table shows it (`E`, `A`, `M`, `B̄`).
    pub fn symbol(self) -> &'static str {
        match self {
            Iso230_2Parameter::E => "E",
            Iso230_2Parameter::A => "A",
            Iso230_2Parameter::M => "M",
            Iso230_2Parameter::BMean => "B̄",
        }
    }
}

/// What a check's `injected` and `recovered` values are (the table's `statistic` column).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Statistic {
    /// A value against its truth, no statistic named (an empty cell).
    #[default]
    Value,
    /// Whether an expected effect was found (`found (yes/no)`).
    Found,
    /// RMS of an error-motion profile over the positions (`RMS of profile`).
    ProfileRms,
    /// An ISO 230-2 positioning parameter (`ISO 230-2 E`).
    Iso230_2(Iso230_2Parameter),
    /// An ISO 230-1 squareness angle (`ISO 230-1 squareness`).
    Iso230_1Squareness,
    /// The stick-slip index (`stick-slip index`).
    StickSlipIndex,
    /// A model check's normalised RMS residual (`normalised RMS`).
    NormalisedRms,
}

impl Statistic {
    /// Every statistic (for parsing).
    pub const ALL: [Statistic; 10] = [
        Statistic::Value,
        Statistic::Found,
        Statistic::ProfileRms,
        Statistic::Iso230_2(Iso230_2Parameter::E),
        Statistic::Iso230_2(Iso230_2Parameter::A),
        Statistic::Iso230_2(Iso230_2Parameter::M),
        Statistic::Iso230_2(Iso230_2Parameter::BMean),
        Statistic::Iso230_1Squareness,
        Statistic::StickSlipIndex,
        Statistic::NormalisedRms,
    ];

    /// The words the table and the JSON write.
    pub fn as_str(self) -> &'static str {
        match self {
            Statistic::Value => "",
            Statistic::Found => "found (yes/no)",
            Statistic::ProfileRms => "RMS of profile",
            Statistic::Iso230_2(Iso230_2Parameter::E) => "ISO 230-2 E",
            Statistic::Iso230_2(Iso230_2Parameter::A) => "ISO 230-2 A",
            Statistic::Iso230_2(Iso230_2Parameter::M) => "ISO 230-2 M",
            Statistic::Iso230_2(Iso230_2Parameter::BMean) => "ISO 230-2 B̄",
            Statistic::Iso230_1Squareness => "ISO 230-1 squareness",
            Statistic::StickSlipIndex => "stick-slip index",
            Statistic::NormalisedRms => "normalised RMS",
        }
    }
}

impl Serialize for Statistic {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl<'de> Deserialize<'de> for Statistic {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Statistic, D::Error> {
        let text = String::deserialize(d)?;
        Statistic::ALL.into_iter().find(|s| s.as_str() == text).ok_or_else(|| {
            let known: Vec<String> = Statistic::ALL.iter().map(|s| format!("{:?}", s.as_str())).collect();
            serde::de::Error::custom(format!("unknown statistic {text:?}; expected one of {}", known.join(", ")))
        })
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
    pub statistic: Statistic,
    /// A sentence printed under the table for this row (where the columns need one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// Index of the figure (in `Estimates::figures`) that shows this estimate.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub figure: Option<usize>,
    /// A lower bound of the achievable difference where one exists (Cramér–Rao), same unit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bound: Option<f64>,
    /// What `injected`, `recovered`, `difference` and `tolerance` are (their unit).
    pub quantity: Quantity,
    /// The value from the injected truth (or the reference of a one-sided limit), SI unit of `quantity`.
    pub injected: f64,
    /// The value the estimator recovered, same unit.
    pub recovered: f64,
    /// As `rule` defines it; NaN (JSON null) for [`Rule::AtMost`] and [`Rule::Found`], which form none.
    pub difference: f64,
    /// The limit `rule` compares with, same unit.
    pub tolerance: f64,
    /// How `difference`, `tolerance` and `pass` are formed.
    #[serde(default)]
    pub rule: Rule,
    /// Whether the estimate met its tolerance.
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
            statistic: Statistic::Found,
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
            statistic: Statistic::ProfileRms,
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
            statistic: Statistic::Value,
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

    /// The check with its stable identifier replaced.
    pub fn with_id(self, id: impl Into<String>) -> Check {
        Check { id: id.into(), ..self }
    }

    /// The check with what its values are (e.g. [`Statistic::ProfileRms`]).
    pub fn with_statistic(self, statistic: Statistic) -> Check {
        Check { statistic, ..self }
    }

    /// The check with a sentence to print under the table.
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
            self.statistic.as_str().to_string(),
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
        Quantity::Length => format!("{} µm", fixed3(v * 1e6)),
        Quantity::Angle => format!("{} µrad", fixed3(v * 1e6)),
        Quantity::Ratio => format!("{} (dimensionless)", fixed3(v)),
    }
}

/// `x` with three decimals, without the sign of a value that rounds to zero (−0.0002 → "0.000", not
/// "-0.000": a minus on a printed zero reads as a measured negative value).
fn fixed3(x: f64) -> String {
    let s = format!("{x:.3}");
    match s.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| b == b'0' || b == b'.') => rest.to_string(),
        _ => s,
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

/// Adds `values ± sigma` at `x` (m; values and σ in the quantity's SI unit) to a [`profile_figure`] of
/// quantity `q` as error bars in the colour of the series before it.
pub fn push_error_bars(fig: &mut Figure, q: Quantity, x: &[f64], values: &[f64], sigma: &[f64]) {
    let scale = if q == Quantity::Ratio { 1.0 } else { 1e6 };
    fig.series.push(Series {
        label: "± 1σ".into(),
        x: x.iter().flat_map(|&p| [p * 1e3, p * 1e3]).collect(),
        y: values.iter().zip(sigma).flat_map(|(v, s)| [(v - s) * scale, (v + s) * scale]).collect(),
        style: SeriesStyle::ErrorBars,
    });
}

/// The result of the estimators: the checks (rows of the table) and the figures they point to.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Estimates {
    /// One row of the table per estimate.
    pub checks: Vec<Check>,
    /// The figures the checks point to (`Check::figure`).
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
                // index: the figure was just pushed, so len ≥ 1.
                self.figures.len() - 1
            }
        };
        self.checks.extend(checks.into_iter().map(|c| Check { figure: Some(idx), ..c }));
    }
}

/// The compensation check's re-measurement: runs the positioning procedure that recorded run `run` again,
/// at other targets, on the machine with the compensation table (positions, corrections; m) in its CNC,
/// and returns the new run as its sensors read it. The estimate workflow owns no machine: the caller
/// passes one ([`crate::simulate::remeasure`] on the scenario's physics for `vmt run` and a study).
pub type Remeasure<'a> = dyn Fn(&str, &[f64], &[f64]) -> Result<Run, RemeasureError> + Sync + 'a;

/// Runs the estimators `estimators` on a recording (`set`) and returns the checks with their figures;
/// `truth` is what the estimates are compared with, `remeasure` the machine the compensation check
/// re-measures on, `source` the scenario file the estimators were read from (named in errors; model
/// files are found beside it).
pub fn estimate_recording(
    source: &Path,
    estimators: &[EstimatorSpec],
    truth: &TruthView<'_>,
    set: &MeasurementSet,
    remeasure: &Remeasure<'_>,
) -> Result<Estimates, VmtError> {
    let mut out = Estimates::default();
    for spec in estimators {
        match spec {
            EstimatorSpec::Iso230_2 { run, sensor, tolerance } => {
                iso::iso_check(source, set, truth, run, sensor, *tolerance, &mut out)?;
            }
            EstimatorSpec::LaserLines { run, sensors, tolerance_translation, tolerance_angle } => {
                let checks = laser_lines::laser_lines_checks(
                    source,
                    set,
                    truth.motions,
                    run,
                    sensors,
                    *tolerance_translation,
                    *tolerance_angle,
                )?;
                for (c, f) in checks {
                    out.push(vec![c], f);
                }
            }
            EstimatorSpec::Compensation { run, sensor, max_ratio, pearson, residual } => {
                let settings = compensation::Settings { max_ratio: *max_ratio, pearson: *pearson, residual: *residual };
                let (checks, fig) = compensation::compensation_checks(source, set, remeasure, run, sensor, &settings)?;
                out.push(checks, fig);
            }
            EstimatorSpec::Ssi { procedure, sensor, expected, tolerance } => {
                for (check, fig, zoom) in ssi::ssi_checks(source, set, truth, procedure, sensor, expected, tolerance)? {
                    out.push(vec![check], fig);
                    zoom.into_iter().for_each(|z| out.push_figure(z));
                }
            }
            EstimatorSpec::ModelCheck { model, expected, max_steps, tolerance } => {
                let (checks, figures) =
                    model_check::model_check_loop(source, set, model, expected, *max_steps, *tolerance)?;
                let mut figures = figures.into_iter();
                if let Some(first) = figures.next() {
                    out.push(checks, first);
                }
                figures.for_each(|f| out.push_figure(f));
            }
            EstimatorSpec::LaserLines3d { procedure, k_sigma, bias, bias_angle } => {
                let bias_angle = bias_angle.unwrap_or(*bias);
                for (checks, fig) in
                    chain::laser_lines_3d_checks(source, set, truth, procedure, *k_sigma, *bias, bias_angle)?
                {
                    out.push(checks, fig);
                }
            }
            EstimatorSpec::AccelStraightness { procedure, sensor, method, tolerance } => {
                let (c, f, stages) = straightness::accel_straightness_check(
                    source,
                    set,
                    truth,
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The `statistic` column and JSON key keep the words they had as strings, and read back.
    #[test]
    fn statistics_serialise_as_their_words_and_read_back() {
        for s in Statistic::ALL {
            let json = serde_json::to_string(&s).unwrap();
            assert_eq!(json, serde_json::to_string(s.as_str()).unwrap());
            assert_eq!(serde_json::from_str::<Statistic>(&json).unwrap(), s);
        }
        assert_eq!(Statistic::Iso230_2(Iso230_2Parameter::BMean).as_str(), "ISO 230-2 B̄");
        let e = serde_json::from_str::<Statistic>("\"median\"").unwrap_err().to_string();
        assert!(e.contains("unknown statistic \"median\"") && e.contains("RMS of profile"), "{e}");
    }
}
