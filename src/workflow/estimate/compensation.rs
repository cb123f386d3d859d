//! Seed 004's compensation loop (DESIGN.md §7): a variable-step table from the ISO 230-2 test, applied in
//! the CNC, the test repeated. The adapter of `vmt run`'s compensation check; the machine it re-measures
//! on is the caller's ([`super::Remeasure`]).

use super::iso::point_table_deviations;
use super::{display, profile_figure, Check, Iso230_2Parameter, Quantity, Remeasure, Statistic};
use crate::error::VmtError;
use crate::measurement::{MeasurementSet, Run};
use std::path::Path;
use vmt_estimators::iso230_2::{evaluate_bidirectional, AxisResult};
use vmt_report::{Figure, Series, SeriesStyle};

/// The compensation check's settings (scenario `[[estimators]] kind = "compensation"`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// E and A after compensation must be at most `max_ratio` × their values before (dimensionless).
    pub max_ratio: f64,
    /// The variable-step table's least |Pearson r| per segment (dimensionless, seed 004).
    pub pearson: f64,
    /// The variable-step table's largest |residual| of a segment's line, m.
    pub residual: f64,
}

/// Seed 004's compensation loop on the positioning run `run`: a variable-step table from the ISO 230-2
/// mean deviations of `sensor`, applied in the CNC through `remeasure` (the re-test at other targets),
/// and E and A after compensation checked against `settings.max_ratio` × their values before.
pub(super) fn compensation_checks(
    source: &Path,
    set: &MeasurementSet,
    remeasure: &Remeasure<'_>,
    run: &str,
    sensor: &str,
    settings: &Settings,
) -> Result<(Vec<Check>, Figure), VmtError> {
    use vmt_estimators::compensation::{variable_step_table, VariableStepParams};
    let Settings { max_ratio, pearson, residual } = *settings;
    let bad = |m: String| VmtError::bad(source, format!("estimators (compensation {run})"), m);
    let iso = |rec: &Run| -> Result<AxisResult, VmtError> {
        let (t, u, d) = point_table_deviations(rec, sensor)
            .ok_or_else(|| bad(format!("run `{}` has no point-table column `{sensor}`", rec.name)))?;
        evaluate_bidirectional(&t, &u, &d).map_err(|e| bad(e.to_string()))
    };
    let rec = set.run(run).ok_or_else(|| bad(format!("no run `{run}`")))?;
    let before = iso(rec)?;
    let positions: Vec<f64> = before.targets.iter().map(|t| t.target).collect();
    let deviations: Vec<f64> = before.targets.iter().map(|t| t.mean_bidirectional).collect();
    let params = VariableStepParams { min_abs_pearson: pearson, max_abs_residual: residual, ..Default::default() };
    let table = variable_step_table(&positions, &deviations, &params).map_err(|e| bad(e.to_string()))?.table;
    // The re-test follows the scenario's session (time-dependent effects have moved on meanwhile), at
    // other irregular targets, as many as before.
    let after_rec = remeasure(run, &table.positions, &table.corrections).map_err(|e| bad(e.to_string()))?;
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
            .with_statistic(Statistic::Iso230_2(Iso230_2Parameter::E))
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
            .with_statistic(Statistic::Iso230_2(Iso230_2Parameter::A))
            .with_note(format!(
                "`injected` shows A before compensation ({}), the tolerance is {max_ratio} × that",
                display(Quantity::Length, before.a)
            )),
        ],
        fig,
    ))
}
