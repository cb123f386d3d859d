//! The laser line-set identifier of one axis (seeds 001/003, `vmt_estimators::laser_ls`): the adapter of
//! `vmt run`'s laser-lines check and the glue of `vmt identify` on a single-axis set.

use super::{profile_figure, Check, LineSetError, Quantity};
use crate::error::VmtError;
use crate::measurement::{MeasurementSet, Run, RunData, SensorKind};
use std::path::Path;
use vmt_report::{Figure, SeriesStyle};
use vmt_sim::geometry::ErrorMotions;

/// One laser line of a point table: its column, measuring point (axis frame, m), beam direction and the
/// 1σ noise of a reading (m).
#[derive(Clone, Debug, PartialEq)]
pub struct LaserLine {
    /// The sensor's column name.
    pub name: String,
    /// Measuring point in the axis frame, m.
    pub point: [f64; 3],
    /// Unit beam direction in the axis frame.
    pub direction: [f64; 3],
    /// 1σ noise of one reading, m.
    pub sigma: f64,
}

/// Identifies the six error motions of one axis from the laser lines of a point table with the general
/// least-squares identifier (seeds 001/003), one zero offset per line, values at the measured targets.
pub fn identify_laser_lines(
    target: &[f64],
    columns: &[(String, Vec<f64>)],
    lines: &[LaserLine],
) -> Result<(vmt_estimators::laser_ls::Identification, vmt_estimators::laser_ls::Model), LineSetError> {
    use vmt_estimators::laser_ls::{identify, Axis, AxisModel, IdOptions, Model, Reading};
    let mut readings = Vec::new();
    for (line, l) in lines.iter().enumerate() {
        let values =
            &columns.iter().find(|(n, _)| *n == l.name).ok_or_else(|| LineSetError::NoLineColumn(l.name.clone()))?.1;
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
    let model = Model { axes: vec![AxisModel::with_nodes(Axis::X, &nodes)], squareness: false };
    let id = identify(&readings, &model, &IdOptions::default())?;
    Ok((id, model))
}

/// The laser lines `names` of a measurement set as the identifier takes them: each sensor's column, point
/// (m, axis frame), unit beam direction and 1σ reading noise from the manifest (0 where not given). The
/// one place both `vmt run` and `vmt identify` turn manifest sensors into lines; a name the manifest does
/// not declare is an error.
pub fn manifest_lines<'a>(
    set: &MeasurementSet,
    names: impl IntoIterator<Item = &'a str>,
) -> Result<Vec<LaserLine>, LineSetError> {
    names
        .into_iter()
        .map(|name| {
            let s = set.sensor(name).ok_or_else(|| LineSetError::UndeclaredSensor(name.to_string()))?;
            Ok(LaserLine {
                name: s.name.clone(),
                point: s.position,
                direction: s.direction,
                sigma: s.sigma.unwrap_or(0.0),
            })
        })
        .collect()
}

/// Fewest degrees of freedom of the repeats from which a laser line's σ is estimated when the manifest
/// gives none (σ̂ from 10 dof is within ±22 % of σ at 1σ).
pub const MIN_REPEAT_DOF_IDENTIFY: usize = 10;

/// The laser lines (linear and straightness lasers) of a point-table run of a measurement set, identified:
/// the run `run` or else the first point-table run with at least two lines (`vmt identify`, the in-process
/// `LaserLines` estimator). Returns the run's name, the number of lines, the identification and notes for
/// the reader. A line whose manifest gives no `sigma` gets σ from its repeated readings (pooled scatter per
/// target and direction across runs, ≥ [`MIN_REPEAT_DOF_IDENTIFY`] degrees of freedom; said in a note);
/// without enough repeats it is refused, since the weights and every standard error depend on σ (a σ of 0
/// printed standard errors of 0).
pub fn identify_set(
    set: &MeasurementSet,
    run: Option<&str>,
) -> Result<(String, usize, vmt_estimators::laser_ls::Identification, Vec<String>), LineSetError> {
    let line_names = |r: &Run| -> Vec<&str> {
        set.sensors
            .iter()
            // Linear and straightness lasers (not `laser_vector`, unlike the chain path: kept as it was).
            .filter(|s| matches!(s.kind, SensorKind::LaserLinear | SensorKind::LaserStraightness))
            .filter(|s| r.data.column(&s.name).is_some())
            .map(|s| s.name.as_str())
            .collect()
    };
    let r = match run {
        Some(n) => set.run(n).ok_or_else(|| LineSetError::NoRun(n.to_string()))?,
        None => set
            .runs
            .iter()
            .find(|r| matches!(r.data, RunData::PointTable { .. }) && line_names(r).len() >= 2)
            .ok_or(LineSetError::NoLineSetRun)?,
    };
    let RunData::PointTable { target, run: run_no, direction, columns, .. } = &r.data else {
        return Err(LineSetError::NotPointTable(r.name.clone()));
    };
    let mut lines = manifest_lines(set, line_names(r))?;
    let mut notes = Vec::new();
    for line in &mut lines {
        if set.sensor(&line.name).and_then(|s| s.sigma).is_some() {
            continue;
        }
        let values = r.data.column(&line.name).ok_or_else(|| LineSetError::NoLineColumn(line.name.clone()))?;
        let keyed = target.iter().zip(direction).zip(values).map(|((x, d), v)| ((x.to_bits(), *d), *v));
        match vmt_estimators::modelcheck::pooled_group_scatter(keyed) {
            Some((ss, dof)) if dof >= MIN_REPEAT_DOF_IDENTIFY && ss > 0.0 => {
                line.sigma = (ss / dof as f64).sqrt();
                notes.push(format!(
                    "sigma of `{}` estimated from its repeated readings: {} m ({dof} degrees of freedom; the manifest gives none)",
                    line.name,
                    crate::error::fmt_num(line.sigma)
                ));
            }
            other => {
                let runs = run_no.iter().collect::<std::collections::BTreeSet<_>>().len();
                return Err(LineSetError::TooFewRepeats {
                    line: line.name.clone(),
                    runs,
                    dof: other.map_or(0, |(_, d)| d),
                    needed: MIN_REPEAT_DOF_IDENTIFY,
                });
            }
        }
    }
    let (id, _) = identify_laser_lines(target, columns, &lines)
        .map_err(|e| LineSetError::InRun { run: r.name.clone(), source: Box::new(e) })?;
    Ok((r.name.clone(), lines.len(), id, notes))
}

/// The six error motions identified from the laser lines `sensors` of the point-table run `run`,
/// compared with the injected `errors` (translations within `tol_t`, m; angles within `tol_a`, rad).
pub(super) fn laser_lines_checks(
    source: &Path,
    set: &MeasurementSet,
    errors: &ErrorMotions,
    run: &str,
    sensors: &[String],
    tol_t: f64,
    tol_a: f64,
) -> Result<Vec<(Check, Figure)>, VmtError> {
    let bad = |m: String| VmtError::bad(source, format!("estimators (laser_lines {run})"), m);
    let rec = set.run(run).ok_or_else(|| bad(format!("no run `{run}`")))?;
    let RunData::PointTable { target, columns, .. } = &rec.data else {
        return Err(bad("expected a point table".into()));
    };
    let lines = manifest_lines(set, sensors.iter().map(String::as_str)).map_err(|e| bad(e.to_string()))?;
    let (id, model) = identify_laser_lines(target, columns, &lines).map_err(|e| bad(e.to_string()))?;
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
        let mut fig = profile_figure(
            format!("{name}: injected vs identified ± 1σ"),
            q,
            &p.positions,
            &[("injected", &truth, SeriesStyle::Line), ("identified", &p.values, SeriesStyle::Points)],
        );
        if let Some(sig) = p.std_errors.iter().copied().collect::<Option<Vec<f64>>>() {
            super::push_error_bars(&mut fig, q, &p.positions, &p.values, &sig);
        }
        let check = Check::profile(name, q, &truth, &p.values, tol).with_id(format!("laser_lines.{run}.{sym}"));
        checks.push((check, fig));
    }
    if !id.unobservable.is_empty() {
        return Err(bad(format!("the laser lines leave unobservable: {}", id.unobservable.join("; "))));
    }
    Ok(checks)
}
