//! Workflow `estimate`: the estimators a scenario names, applied to its recording and compared with the
//! injected truth. Each check is one row of `vmt run`'s table: the error (or value) estimated, the
//! injected value, the recovered one, their difference, the tolerance (with its reason) and pass/fail.

use crate::error::VmtError;
use crate::scenario::Scenario;
use serde::{Deserialize, Serialize};
use vmt_estimators::iso230_2::{evaluate_bidirectional, AxisResult};
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::procedures::{RunData, RunRecord};

/// Estimators a scenario can ask for (`[[estimators]]`), each with the tolerance its estimate must meet.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum EstimatorSpec {
    /// ISO 230-2 evaluation of a positioning run read by a linear laser: E, M and B̄ compared with the
    /// values of the injected deviations at the laser's measuring point.
    Iso230_2 { run: String, sensor: String, tolerance: f64 },
}

/// What a check compares (for units in the table).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    Length,
    Angle,
    Ratio,
}

/// One row of the result table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Check {
    pub error: String,
    pub quantity: Quantity,
    pub injected: f64,
    pub recovered: f64,
    pub difference: f64,
    pub tolerance: f64,
    pub pass: bool,
}

impl Check {
    pub fn new(error: impl Into<String>, quantity: Quantity, injected: f64, recovered: f64, tolerance: f64) -> Check {
        let difference = recovered - injected;
        Check {
            error: error.into(),
            quantity,
            injected,
            recovered,
            difference,
            tolerance,
            pass: difference.abs() <= tolerance,
        }
    }
}

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

/// Runs every estimator of a scenario on its recording and returns the checks.
pub fn run_estimators(sc: &Scenario, runs: &[RunRecord], errors: &ErrorMotions) -> Result<Vec<Check>, VmtError> {
    let mut checks = Vec::new();
    for spec in &sc.estimators {
        match spec {
            EstimatorSpec::Iso230_2 { run, sensor, tolerance } => {
                let rec = runs
                    .iter()
                    .find(|r| &r.name == run)
                    .ok_or_else(|| VmtError::bad(&sc.source, "estimators", format!("no run `{run}`")))?;
                let (targets, up, down) = point_table_deviations(rec, sensor).ok_or_else(|| {
                    VmtError::bad(
                        &sc.source,
                        "estimators",
                        format!("run `{run}` is not a point table with sensor `{sensor}`"),
                    )
                })?;
                let est = evaluate_bidirectional(&targets, &up, &down)
                    .map_err(|e| VmtError::bad(&sc.source, "estimators", format!("ISO 230-2 of run `{run}`: {e}")))?;
                let spec = sc.sensors.iter().find(|s| &s.name == sensor).expect("validated sensor");
                let r = spec.axis_position(&sc.axis).map_err(|m| VmtError::bad(&sc.source, "sensors", m))?;
                let truth = iso_truth(errors, r, &targets)?;
                checks.push(Check::new(
                    format!("ISO 230-2 E ({sensor})"),
                    Quantity::Length,
                    truth.e,
                    est.e,
                    *tolerance,
                ));
                checks.push(Check::new(
                    format!("ISO 230-2 M ({sensor})"),
                    Quantity::Length,
                    truth.m,
                    est.m,
                    *tolerance,
                ));
                checks.push(Check::new(
                    format!("ISO 230-2 B̄ ({sensor})"),
                    Quantity::Length,
                    truth.b_mean,
                    est.b_mean,
                    *tolerance,
                ));
            }
        }
    }
    Ok(checks)
}
