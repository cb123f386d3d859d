//! The 21-error identification of a chain from laser line sets (seed 001, `vmt_estimators::laser_ls`
//! with squareness): the adapter of `vmt run`'s 3D check and the glue of `vmt identify` on a multi-axis set.

use super::{display, profile_figure, Check, LineSetError, Quantity, Statistic, TruthView};
use crate::error::VmtError;
use crate::measurement::{MeasurementSet, Run, RunData};
use serde::Serialize;
use std::path::Path;
use vmt_estimators::laser_ls::Reading;
use vmt_report::{Figure, FigureKind, Series, SeriesStyle};
use vmt_sim::effects::EffectName;
use vmt_sim::Axis;

/// The result of [`crate::workflow::run::identify_chain_lines`]: the identification, the model it used and the node
/// positions of each axis (m, chain order).
#[derive(Clone, Debug, Serialize)]
pub struct ChainIdentification {
    /// The identifier's result (error motions m / rad, squareness rad, standard errors).
    pub identification: vmt_estimators::laser_ls::Identification,
    /// The model it used (axes in chain order, node bases, squareness on).
    pub model: vmt_estimators::laser_ls::Model,
    /// The node positions of each axis, m, chain order.
    pub positions: Vec<Vec<f64>>,
}

/// How a laser line's 1σ is taken from the manifest: required (`vmt identify` refuses a line set without
/// it: the weights and standard errors depend on it), or floored (`vmt run`: a line of σ = 0 weighs as
/// σ = the floor, m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LineSigma {
    /// Every laser needs its `sigma` in the manifest.
    Required,
    /// σ = max(manifest `sigma` or 0, floor), m.
    AtLeast(f64),
}

/// The laser readings of the multi-axis point-table runs `runs` of a set, identified (seed 001; DESIGN.md
/// §7): every laser-line column is a reading u·δ(q, r) + the line's zero (`vmt_estimators::laser_ls`
/// model, one unknown zero per line), q from the runs' `{l}_cmd` columns of the axes `letters` (chain
/// order, bed first), r and u the manifest sensor's `position` and `direction`, σ its `sigma` as `sigma`
/// says. The one glue of `vmt run`'s 3D check and `vmt identify` on a line set. Returns the number of
/// lines and the 21-error identification with squareness.
pub fn identify_chain_runs<'a>(
    set: &MeasurementSet,
    runs: impl IntoIterator<Item = &'a Run>,
    letters: &[Axis],
    sigma: LineSigma,
) -> Result<(usize, ChainIdentification), LineSetError> {
    let mut readings = Vec::new();
    let mut n_lines = 0;
    for r in runs {
        let RunData::PointTable { columns, .. } = &r.data else {
            return Err(LineSetError::NotPointTable(r.name.clone()));
        };
        let qs = axis_commands(&r.name, columns, letters)?;
        for (name, values) in columns {
            let Some(s) = set.sensor(name).filter(|s| s.kind.is_laser_line()) else {
                continue;
            };
            let sigma = match sigma {
                LineSigma::Required => {
                    s.sigma.filter(|v| *v > 0.0).ok_or_else(|| LineSetError::NoSigma(name.clone()))?
                }
                LineSigma::AtLeast(floor) => s.sigma.unwrap_or(0.0).max(floor),
            };
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
    if readings.is_empty() {
        return Err(LineSetError::NoReadings);
    }
    identify_axis_readings(readings, letters).map(|id| (n_lines, id))
}

/// Multi-axis laser lines of a measurement set (the seed 001 line set of a chain, e.g. what `vmt simulate`
/// writes for `scenarios/squareness_3axis.toml`): every point-table run with commanded positions of at
/// least two axes (`x_cmd`, `y_cmd`, `z_cmd` columns), identified by [`identify_chain_runs`] with the axes
/// in x, y, z order. Returns None when the set has no such run, else (number of lines, the 21-error
/// identification with squareness). Every laser needs its `sigma`.
pub fn identify_axes_set(set: &MeasurementSet) -> Result<Option<(usize, ChainIdentification)>, LineSetError> {
    let has = |r: &Run, l: Axis| r.data.column(&format!("{l}_cmd")).is_some();
    let letters: Vec<Axis> = Axis::ALL.into_iter().filter(|&l| set.runs.iter().any(|r| has(r, l))).collect();
    let multi =
        |r: &&Run| matches!(r.data, RunData::PointTable { .. }) && letters.iter().filter(|&&l| has(r, l)).count() >= 2;
    if letters.len() < 2 || !set.runs.iter().any(|r| multi(&r)) {
        return Ok(None);
    }
    identify_chain_runs(set, set.runs.iter().filter(multi), &letters, LineSigma::Required).map(Some)
}

/// Column `name` of run `run`'s point table.
fn column_of<'a>(run: &str, columns: &'a [(String, Vec<f64>)], name: &str) -> Result<&'a Vec<f64>, LineSetError> {
    columns
        .iter()
        .find(|(c, _)| c == name)
        .map(|(_, v)| v)
        .ok_or_else(|| LineSetError::NoColumn { run: run.to_string(), column: name.to_string() })
}

/// The commanded joint positions of a multi-axis point table, one column `{l}_cmd` per axis letter.
pub fn axis_commands<'a>(
    run: &str,
    columns: &'a [(String, Vec<f64>)],
    letters: &[Axis],
) -> Result<Vec<&'a Vec<f64>>, LineSetError> {
    letters.iter().map(|l| column_of(run, columns, &format!("{l}_cmd"))).collect()
}

/// The 21-error identification (laser_ls with squareness) of laser readings taken at joint positions
/// `q` of the axes `letters` (chain order, bed first): each error motion is parameterised by its values
/// at the distinct positions of its axis (piecewise linear), the reference position being the lowest.
pub fn identify_axis_readings(
    mut readings: Vec<vmt_estimators::laser_ls::Reading>,
    letters: &[Axis],
) -> Result<ChainIdentification, LineSetError> {
    use vmt_estimators::laser_ls::{identify, AxisModel, IdOptions, Model};
    let mut positions = Vec::new();
    let mut axes = Vec::new();
    for (j, l) in letters.iter().enumerate() {
        let mut p: Vec<f64> = readings.iter().map(|r| r.q[j]).collect();
        p.sort_by(f64::total_cmp);
        // Stops computed as from + (to − from)·k/(n − 1) differ by float rounding: one node per 1 nm.
        p.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        if p.len() < 2 {
            return Err(LineSetError::OnePosition(*l));
        }
        axes.push(AxisModel::with_nodes(*l, &p));
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
    let identification = identify(&readings, &model, &IdOptions::default())?;
    Ok(ChainIdentification { identification, model, positions })
}

/// The 3D laser-line check of the chain procedure `procedure` (seed 001): the squareness angles the lines
/// determine against the ISO 230-1 squareness of the truth (within `k_sigma`·σ + `bias`, rad), and every
/// angular error motion with standard errors against the injected one (within `k_sigma`·σ + `bias_angle`).
pub(super) fn laser_lines_3d_checks(
    source: &Path,
    set: &MeasurementSet,
    truth: &TruthView<'_>,
    procedure: &str,
    k_sigma: f64,
    bias: f64,
    bias_angle: f64,
) -> Result<Vec<(Vec<Check>, Figure)>, VmtError> {
    let bad = |m: String| VmtError::bad(source, format!("estimators (laser_lines_3d {procedure})"), m);
    let settings_ok = k_sigma.is_finite()
        && k_sigma > 0.0
        && bias.is_finite()
        && bias >= 0.0
        && bias_angle.is_finite()
        && bias_angle >= 0.0;
    if !settings_ok {
        return Err(bad(format!(
            "expected k_sigma > 0, bias ≥ 0 and bias_angle ≥ 0 (rad), got {k_sigma}, {bias} and {bias_angle}"
        )));
    }
    let chain = truth.chain.as_ref().ok_or_else(|| bad("needs a multi-axis scenario (axes = [...])".into()))?;
    let letters = chain.axis_names();
    let lines = truth.runs_of(set, procedure);
    if lines.is_empty() {
        return Err(bad(format!("no laser-line runs of chain procedure `{procedure}`")));
    }
    // σ = 0 weighs as 1e-12 m (the scenario allows a noise-free line; the identifier needs a weight).
    let (_, ci) =
        identify_chain_runs(set, lines, &letters, LineSigma::AtLeast(1e-12)).map_err(|e| bad(e.to_string()))?;
    let injected = (chain.effective_squareness)(&ci.positions);
    let mut checks = Vec::new();
    let (mut names, mut inj, mut rec, mut raw) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut sig: Vec<f64> = Vec::new();
    for (k, (effect, iso, (a, b))) in [
        ("squareness_xy", "EC0Y", (Axis::X, Axis::Y)),
        ("squareness_xz", "EB0Z", (Axis::X, Axis::Z)),
        ("squareness_yz", "EA0Z", (Axis::Y, Axis::Z)),
    ]
    .into_iter()
    .enumerate()
    {
        if !(letters.contains(&a) && letters.contains(&b)) {
            continue;
        }
        let est = ci.identification.squareness(effect).ok_or_else(|| bad(format!("identifier returned no {iso}")))?;
        let sigma = est.std_error.ok_or_else(|| {
            bad(format!("{iso} is not observable with these lines: add a diagonal in the {a}{b} plane"))
        })?;
        let expected = injected[k];
        let check = Check {
            bound: Some(sigma),
            ..Check::new(
                // "Injected" is the ISO 230-1 squareness the lines measure: the angle between the
                // least-squares lines of the axes' paths, i.e. the injected angle plus the paths' slopes.
                format!(
                    "{iso} {effect} (laser lines 3D, ±{:.3} µrad 1σ; {:.3} µrad + path slopes)",
                    sigma * 1e6,
                    chain.squareness[k] * 1e6
                ),
                Quantity::Angle,
                expected,
                est.value,
                k_sigma * sigma + bias,
            )
            .with_id(format!("laser_lines_3d.{procedure}.{effect}"))
            .with_statistic(Statistic::Iso230_1Squareness)
            .with_note(format!(
                "ISO 230-1 squareness is the angle between the least-squares lines of the axes' paths: the injected \
                 squareness value {} plus {} from the straightness error motions' linear trends = `injected` {}",
                display(Quantity::Angle, chain.squareness[k]),
                display(Quantity::Angle, expected - chain.squareness[k]),
                display(Quantity::Angle, expected)
            ))
        };
        checks.push(check);
        names.push(iso);
        inj.push(expected);
        rec.push(est.value);
        sig.push(sigma);
        raw.push(chain.squareness[k]);
    }
    let x: Vec<f64> = (1..=names.len()).map(|i| i as f64).collect();
    let numbered: Vec<String> = names.iter().enumerate().map(|(i, n)| format!("{} = {n}", i + 1)).collect();
    let fig = Figure {
        title: format!(
            "squareness from the laser line set `{procedure}`: injected (ISO 230-1) vs recovered ± 1σ, µrad"
        ),
        x_label: format!("angle: {}", numbered.join(", ")),
        x_unit: vmt_report::DIMENSIONLESS.into(),
        y_label: "angle".into(),
        y_unit: "µrad".into(),
        series: vec![
            Series {
                label: "injected (ISO 230-1: between the least-squares lines)".into(),
                x: x.clone(),
                y: inj.iter().map(|v| v * 1e6).collect(),
                style: SeriesStyle::Points,
            },
            Series {
                label: "recovered".into(),
                x: x.clone(),
                y: rec.iter().map(|v| v * 1e6).collect(),
                style: SeriesStyle::Points,
            },
            Series {
                label: "recovered ± 1σ".into(),
                x: x.iter().flat_map(|&v| [v, v]).collect(),
                y: rec.iter().zip(&sig).flat_map(|(r, s)| [(r - s) * 1e6, (r + s) * 1e6]).collect(),
                style: SeriesStyle::ErrorBars,
            },
            Series {
                label: "squareness value of the truth (without the error motions' trends)".into(),
                x,
                y: raw.iter().map(|v| v * 1e6).collect(),
                style: SeriesStyle::Points,
            },
        ],
        kind: FigureKind::Line,
        log_x: false,
        log_y: false,
    };
    let mut out = vec![(checks, fig)];
    // The angular error motions the lines determine (every reported value has a standard error):
    // the carriage's rotation is the same at every point of it, so the truth is the injected angle
    // relative to its value at the reference position (laser_ls's reporting convention).
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    for (j, &(letter, motions)) in chain.axes.iter().enumerate() {
        for (k, effect) in [EffectName::Roll, EffectName::Pitch, EffectName::Yaw].into_iter().enumerate() {
            let Some(iso) = effect.iso230_symbol(letter) else { continue };
            let Some(p) = ci.identification.profile(&iso) else { continue };
            let Some(sig) = p.std_errors.iter().copied().collect::<Option<Vec<f64>>>() else { continue };
            let profile = motions.by_index(3 + k);
            let r0 = profile.value(ci.model.axes[j].reference_position);
            let truth: Vec<f64> = p.positions.iter().map(|&q| profile.value(q) - r0).collect();
            let s = rms(&sig);
            let name = format!("{iso} {letter}.{effect} (laser lines 3D)");
            let mut fig = profile_figure(
                format!("{name}: injected vs identified ± 1σ (RMS 1σ {:.3} µrad)", s * 1e6),
                Quantity::Angle,
                &p.positions,
                &[("injected", &truth, SeriesStyle::Line), ("identified", &p.values, SeriesStyle::Points)],
            );
            super::push_error_bars(&mut fig, Quantity::Angle, &p.positions, &p.values, &sig);
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
