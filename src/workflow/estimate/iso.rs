//! The ISO 230-2 adapter (`vmt run`'s check, and the glue `vmt iso230-2` and `vmt compensate` share) and the
//! ISO 230-2 figure and table as laser-calibration software draws them (issue 16): every run's
//! trace per approach direction, the mean ↑ and ↓ lines, the x̄ ± 2s envelopes, the injected truth,
//! and A, B, E, M, R beside it; the table with s↑ and s↓; the uncertainty statement (ISO 230-2:2014
//! §8 asks the report to state the measurement uncertainty, ISO/TR 230-9 with coverage factor k = 2).

use super::{Check, Estimates, Iso230_2Parameter, Quantity, Statistic, TruthView};
use crate::error::VmtError;
use crate::measurement::{MeasurementSet, Run, RunData};
use std::path::Path;
use vmt_estimators::iso230_2::{evaluate_bidirectional, AxisResult};
use vmt_report::{Figure, FigureKind, Series, SeriesStyle, Table};

/// A positioning test split by approach direction: (targets (m), `up[i][j]`, `down[i][j]`), target i in
/// increasing order, j the i-th target's readings (deviations, m) in that direction in run order — the
/// arguments of `vmt_estimators::iso230_2::evaluate_bidirectional`.
pub type DirectionalDeviations = (Vec<f64>, Vec<Vec<f64>>, Vec<Vec<f64>>);

/// Deviations of one sensor column of a point-table run, split by direction ([`DirectionalDeviations`]);
/// None when the run is not a point table or has no column `sensor`. The one reader of a positioning test
/// for the ISO 230-2 check, the compensation check, `vmt iso230-2` and `vmt compensate`.
pub fn point_table_deviations(run: &Run, sensor: &str) -> Option<DirectionalDeviations> {
    let RunData::PointTable { target, direction, columns, .. } = &run.data else { return None };
    let values = &columns.iter().find(|(n, _)| n == sensor)?.1;
    Some(split_by_direction(target, direction, values))
}

/// Rows (target, direction, value) of a point table split by direction ([`DirectionalDeviations`]).
fn split_by_direction(target: &[f64], direction: &[i8], values: &[f64]) -> DirectionalDeviations {
    let mut targets: Vec<f64> = target.to_vec();
    targets.sort_by(f64::total_cmp);
    targets.dedup();
    let index = |x: f64| targets.iter().position(|&t| t == x).unwrap_or(0);
    let mut up = vec![Vec::new(); targets.len()];
    let mut down = vec![Vec::new(); targets.len()];
    for ((&x, &d), &v) in target.iter().zip(direction).zip(values) {
        let side = if d > 0 { &mut up } else { &mut down };
        side[index(x)].push(v);
    }
    (targets, up, down)
}

/// ISO 230-2 values of the truth of a positioning run: the evaluation of its noise-free point table
/// `noise_free` (m, one value per row of `run`, [`TruthView::noise_free`]) — what the machine did at the
/// sensor's point, whatever put it there (error motions, feedback chain, lead error, backlash, the
/// screw's windup, settling). With a purely geometric truth both directions see δx(P_i) = EXX + (ε × r)ₓ.
fn iso_truth(run: &Run, noise_free: &[f64]) -> Result<AxisResult, VmtError> {
    let RunData::PointTable { target, direction, .. } = &run.data else {
        return Err(VmtError::Internal(format!("run `{}` is not a point table", run.name)));
    };
    let (targets, up, down) = split_by_direction(target, direction, noise_free);
    evaluate_bidirectional(&targets, &up, &down).map_err(|e| VmtError::Internal(e.to_string()))
}

/// The ISO 230-2 check of `sensor` in the positioning run `run`: E, M and B̄ against the values of the
/// noise-free deviation at the sensor's point (within `tolerance`, m), with the standard's figure, table and
/// uncertainty statement added to `out`.
pub(super) fn iso_check(
    source: &Path,
    set: &MeasurementSet,
    truth: &TruthView<'_>,
    run: &str,
    sensor: &str,
    tolerance: f64,
    out: &mut Estimates,
) -> Result<(), VmtError> {
    let bad = |m: String| VmtError::bad(source, format!("estimators (iso230_2 {run})"), m);
    let rec = set.run(run).ok_or_else(|| bad(format!("no run `{run}`")))?;
    let (targets, up, down) = point_table_deviations(rec, sensor)
        .ok_or_else(|| bad(format!("run `{run}` is not a point table with sensor `{sensor}`")))?;
    let est = evaluate_bidirectional(&targets, &up, &down).map_err(|e| bad(e.to_string()))?;
    let (Some(_), Some(simulated)) = (set.sensor(sensor), truth.sensor(sensor)) else {
        return Err(bad(format!("sensor `{sensor}` is not declared")));
    };
    let noise_free = (truth.noise_free)(run, sensor)
        .ok_or_else(|| bad(format!("the simulation has no noise-free table of `{sensor}` in run `{run}`")))?;
    let expected = iso_truth(rec, &noise_free)?;
    let checks = [
        (Iso230_2Parameter::E, "e", expected.e, est.e),
        (Iso230_2Parameter::M, "m", expected.m, est.m),
        (Iso230_2Parameter::BMean, "b_mean", expected.b_mean, est.b_mean),
    ]
    .into_iter()
    .map(|(parameter, id, t, e)| {
        let statistic = Statistic::Iso230_2(parameter);
        Check::new(format!("{} ({sensor})", statistic.as_str()), Quantity::Length, t, e, tolerance)
            .with_id(format!("iso230_2.{sensor}.{id}"))
            .with_statistic(statistic)
    })
    .collect();
    let injected: Vec<f64> = expected.targets.iter().map(|t| t.mean_bidirectional).collect();
    let fig = iso_figure(sensor, &targets, &up, &down, &est, Some(&injected));
    out.push(checks, fig);
    out.tables.push(iso_table(&format!("ISO 230-2:2014 evaluation of run {run}, {sensor}"), &est));
    let travel = targets.last().copied().unwrap_or(0.0) - targets.first().copied().unwrap_or(0.0);
    out.notes.push(uncertainty_statement(sensor, simulated.sigma, simulated.environment_scale_error, travel));
    Ok(())
}

/// One run's deviations per target (µm) in one direction, from `per_target[i][j]` (target i, run j).
fn run_trace(per_target: &[Vec<f64>], j: usize) -> Vec<f64> {
    per_target.iter().map(|d| d.get(j).copied().unwrap_or(f64::NAN) * 1e6).collect()
}

/// The ISO 230-2 figure: x = target position (mm), y = deviation x − target (µm). `up[i][j]` and
/// `down[i][j]` are the deviations (m) at target i of run j; `truth` the injected deviation (m) at the
/// targets, when known.
pub fn iso_figure(
    name: &str,
    targets: &[f64],
    up: &[Vec<f64>],
    down: &[Vec<f64>],
    r: &AxisResult,
    truth: Option<&[f64]>,
) -> Figure {
    let x: Vec<f64> = targets.iter().map(|t| t * 1e3).collect();
    let um = |v: f64| v * 1e6;
    let mut series: Vec<Series> = Vec::new();
    let runs = |d: &[Vec<f64>]| d.iter().map(Vec::len).min().unwrap_or(0);
    for (label, per_target, stats) in [
        ("↑", up, r.targets.iter().map(|t| t.up).collect::<Vec<_>>()),
        ("↓", down, r.targets.iter().map(|t| t.down).collect::<Vec<_>>()),
    ] {
        series.push(Series {
            label: format!("mean x̄{label}"),
            x: x.clone(),
            y: stats.iter().map(|s| um(s.mean)).collect(),
            style: SeriesStyle::LinePoints,
        });
        for j in 0..runs(per_target) {
            series.push(Series {
                label: if j == 0 { format!("each run {label}") } else { String::new() },
                x: x.clone(),
                y: run_trace(per_target, j),
                style: SeriesStyle::Faint,
            });
        }
        for (k, sign) in [(0, 1.0), (1, -1.0)] {
            series.push(Series {
                label: if k == 0 { format!("x̄{label} ± 2s{label}") } else { String::new() },
                x: x.clone(),
                y: stats.iter().map(|s| um(s.mean + sign * 2.0 * s.s)).collect(),
                style: SeriesStyle::Band,
            });
        }
    }
    if let Some(t) = truth {
        series.push(Series {
            label: "injected deviation".into(),
            x: x.clone(),
            y: t.iter().map(|v| v * 1e6).collect(),
            style: SeriesStyle::Dashed,
        });
    }
    Figure {
        title: format!(
            "ISO 230-2 bidirectional positioning, {name}: A {:.2} µm, B {:.2} µm, E {:.2} µm, M {:.2} µm, R {:.2} µm",
            um(r.a),
            um(r.b),
            um(r.e),
            um(r.m),
            um(r.r)
        ),
        x_label: "target position".into(),
        x_unit: "mm".into(),
        y_label: "deviation x − target".into(),
        y_unit: "µm".into(),
        series,
        kind: FigureKind::Line,
        log_x: false,
        log_y: false,
    }
}

/// The standard's table of an ISO 230-2 evaluation: per target x̄↑, x̄↓, x̄, s↑, s↓, B_i, R↑_i, R↓_i,
/// R_i (µm), then the axis values.
pub fn iso_table(caption: &str, r: &AxisResult) -> Table {
    let um = |v: f64| format!("{:.3}", v * 1e6);
    let mut rows: Vec<Vec<String>> = r
        .targets
        .iter()
        .map(|t| {
            vec![
                format!("{:.3}", t.target * 1e3),
                um(t.up.mean),
                um(t.down.mean),
                um(t.mean_bidirectional),
                um(t.up.s),
                um(t.down.s),
                um(t.reversal),
                um(t.up.repeatability),
                um(t.down.repeatability),
                um(t.repeatability),
            ]
        })
        .collect();
    let blank = String::new;
    rows.push(vec![
        "axis".into(),
        format!("E↑ {}", um(r.e_up)),
        format!("E↓ {}", um(r.e_down)),
        format!("E {} / M {}", um(r.e), um(r.m)),
        blank(),
        blank(),
        format!("B {} / B̄ {}", um(r.b), um(r.b_mean)),
        format!("R↑ {}", um(r.r_up)),
        format!("R↓ {}", um(r.r_down)),
        format!("R {}", um(r.r)),
    ]);
    rows.push(vec![
        "accuracy".into(),
        format!("A↑ {}", um(r.a_up)),
        format!("A↓ {}", um(r.a_down)),
        format!("A {}", um(r.a)),
        blank(),
        blank(),
        blank(),
        blank(),
        blank(),
        blank(),
    ]);
    Table {
        caption: caption.to_string(),
        header: [
            "target / mm",
            "x̄↑ / µm",
            "x̄↓ / µm",
            "x̄ / µm",
            "s↑ / µm",
            "s↓ / µm",
            "B_i / µm",
            "R↑_i / µm",
            "R↓_i / µm",
            "R_i / µm",
        ]
        .map(String::from)
        .to_vec(),
        rows,
        highlight: Vec::new(),
    }
}

/// The uncertainty statement of an ISO 230-2 test with a laser of 1σ reading noise `sigma` (m) and a
/// remaining environmental scale error `env` (air + material, relative) over the travel `travel` (m):
/// U = k·u with k = 2 (≈ 95 % coverage, ISO/TR 230-9), u = √(σ² + (env·L)²/3), the environmental error
/// taken as a rectangular distribution of half-width |env|·L (GUM 4.3.7).
pub fn uncertainty_statement(sensor: &str, sigma: f64, env: f64, travel: f64) -> String {
    let u_env = env.abs() * travel / 3f64.sqrt();
    let u = (sigma * sigma + u_env * u_env).sqrt();
    format!(
        "Measurement uncertainty ({sensor}, ISO 230-2:2014 §8, ISO/TR 230-9): expanded uncertainty of one deviation \
         reading U = k·u = {:.3} µm with coverage factor k = 2 (≈ 95 %), from the laser's reading noise σ = {:.3} µm \
         and the remaining environmental scale error {:.3} ppm over the {:.0} mm travel taken as rectangular \
         (u_env = {:.3} µm). The machine's repeatability (s, R) is in the table; U is the instrument's share.",
        2.0 * u * 1e6,
        sigma * 1e6,
        env * 1e6,
        travel * 1e3,
        u_env * 1e6
    )
}
