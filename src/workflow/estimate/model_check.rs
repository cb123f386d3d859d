//! The model-check loop (DESIGN.md §8) run to its end on a recording, as `vmt run`'s check: the adapter
//! from a scenario's `model_check` estimator to `crate::modelcheck`'s compare, diagnose and add.

use super::{Check, Quantity, Statistic};
use crate::error::VmtError;
use crate::measurement::MeasurementSet;
use std::path::Path;
use vmt_report::{Figure, FigureKind, Series, SeriesStyle};

/// The model-check loop run to its end on a recording: from the model file `model` (beside the scenario
/// `source`), compare → diagnose → add the top significant effect, at most `max_steps` times; a check per
/// `expected` effect (found or not) and the normalised residual RMS at the end (at most `tolerance`, 1 =
/// noise level), with the figures of the RMS per iteration and of the residual by position.
pub(super) fn model_check_loop(
    source: &Path,
    set: &MeasurementSet,
    model: &str,
    expected: &[String],
    max_steps: usize,
    tolerance: f64,
) -> Result<(Vec<Check>, Vec<Figure>), VmtError> {
    use crate::modelcheck::{add_effect, compare, diagnose};
    use vmt_estimators::modelcheck::Verdict;
    let base = source.parent().unwrap_or(Path::new("."));
    let mut m = crate::model::read_model(&base.join(model))?;
    m.check_error_motion_sizes("", "the recording's positions", |axis| set.position_range(axis))
        .map_err(|(place, msg)| VmtError::bad(&base.join(model), place, msg))?;
    let first = compare(&m, set, source)?;
    let mut history = vec![first.normalized_rms];
    let mut last_report = first.clone();
    let mut added: Vec<String> = Vec::new();
    let mut first_ranking: Option<Vec<vmt_estimators::modelcheck::RankingEntry>> = None;
    for _ in 0..max_steps {
        let d = diagnose(&m, set, source)?;
        first_ranking.get_or_insert_with(|| d.ranking.clone());
        let Some(top) = d.ranking.iter().find(|r| r.verdict == Verdict::Significant) else { break };
        let name: vmt_sim::effects::EffectName =
            top.effect.parse().map_err(|e: vmt_sim::effects::UnknownEffect| VmtError::Internal(e.to_string()))?;
        m = add_effect(&m, name, Some(top)).map_err(|e| VmtError::bad(source, "estimators (model_check)", e))?;
        added.push(top.effect.clone());
        last_report = compare(&m, set, source)?;
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
        .with_statistic(Statistic::NormalisedRms)
        .with_note(format!(
            "residual RMS / noise σ (1 = noise level); `injected` shows it for the starting model ({:.3})",
            history[0]
        )),
    );
    // The loop's evidence (issue 16): the error per iteration against the noise level, the first
    // diagnosis's ranking (which effect explains how much), and the signed residual where the effects
    // live — by approach direction (backlash, lost motion), over time (thermal drift), by position (pitch,
    // positioning, lead errors) — for the starting and the final model.
    let iterations: Vec<f64> = (0..history.len()).map(|i| i as f64).collect();
    let nrms = Figure {
        title: format!(
            "model-check loop: normalised residual RMS per iteration (added: {})",
            if added.is_empty() { "nothing".into() } else { added.join(", ") }
        ),
        x_label: "iteration".into(),
        x_unit: vmt_report::DIMENSIONLESS.into(),
        y_label: "normalised RMS".into(),
        y_unit: "1 = noise".into(),
        series: vec![
            Series {
                label: "residual RMS / σ".into(),
                x: iterations.clone(),
                y: history.clone(),
                style: SeriesStyle::LinePoints,
            },
            Series {
                label: "noise level (1.0)".into(),
                x: vec![0.0, iterations.last().copied().unwrap_or(0.0).max(1.0)],
                y: vec![1.0, 1.0],
                style: SeriesStyle::Dashed,
            },
        ],
        kind: FigureKind::Line,
        log_x: false,
        log_y: history.iter().all(|v| *v > 0.0),
    };
    let mut figures = vec![nrms];
    figures.extend(first_ranking.and_then(|r| {
        ranking_figure(
            "model-check loop: first diagnosis, share of the residual each candidate explains (verdict, ΔBIC)".into(),
            &r,
        )
    }));
    figures.extend(residual_figures(
        "model-check loop",
        "starting and final model",
        0,
        &[(&first, "starting model"), (&last_report, "final model")],
    ));
    Ok((checks, figures))
}

/// The diagnosis ranking as a bar chart: the share of the residual each candidate explains (%), one bar
/// per candidate labelled `effect: verdict, ΔBIC` — the "which effect contributes how much" view. None
/// for an empty ranking.
pub(crate) fn ranking_figure(title: String, ranking: &[vmt_estimators::modelcheck::RankingEntry]) -> Option<Figure> {
    (!ranking.is_empty()).then(|| Figure {
        title,
        x_label: "rank".into(),
        x_unit: vmt_report::DIMENSIONLESS.into(),
        y_label: "explained residual".into(),
        y_unit: "%".into(),
        series: ranking
            .iter()
            .enumerate()
            .map(|(i, e)| Series {
                label: format!("{}: {}, ΔBIC {:.1}", e.effect, format!("{:?}", e.verdict).to_lowercase(), e.delta_bic),
                x: vec![(i + 1) as f64],
                y: vec![100.0 * e.explained],
                style: SeriesStyle::Points,
            })
            .collect(),
        kind: FigureKind::Bar,
        log_x: false,
        log_y: false,
    })
}

/// The signed residual of channel `channel` where the effects live, one series per (report, label):
/// mean by approach direction (bars; backlash, lost motion), mean by position bin (pitch, positioning,
/// lead errors), mean over the session time (thermal drift), and the strongest spatial periods of the
/// residual (bars; cyclic errors). In µm for deviations, N for forces, m/s² for accelerations. Titles
/// read `{prefix}: … ({run} / {sensor}), {which}`; a view without data draws no figure.
pub(crate) fn residual_figures(
    prefix: &str,
    which: &str,
    channel: usize,
    reports: &[(&crate::modelcheck::CompareReport, &str)],
) -> Vec<Figure> {
    let Some(c) = reports.first().and_then(|(r, _)| r.channels.get(channel)) else { return Vec::new() };
    let (k, unit) = crate::modelcheck::display_unit(&c.unit);
    let name = format!("{} / {}", c.run, c.sensor);
    // One curve of a channel report: (x, y) in the report's units.
    type Curve = (Vec<f64>, Vec<f64>);
    let pick = |label: &str, f: &dyn Fn(&crate::modelcheck::ChannelReport) -> Curve| {
        reports
            .iter()
            .filter_map(|(r, model)| {
                let (x, y) = f(r.channels.get(channel)?);
                (!x.is_empty()).then(|| Series {
                    label: format!("{model} ({label})"),
                    x,
                    y: y.iter().map(|v| v * k).collect(),
                    style: SeriesStyle::LinePoints,
                })
            })
            .collect::<Vec<Series>>()
    };
    let figure = |what: &str, x_label: &str, x_unit: &str, y_label: &str, y_unit: &str, series, kind| Figure {
        title: format!("{prefix}: {what} ({name}), {which}"),
        x_label: x_label.into(),
        x_unit: x_unit.into(),
        y_label: y_label.into(),
        y_unit: y_unit.into(),
        series,
        kind,
        log_x: false,
        log_y: false,
    };
    let mut figures = Vec::new();
    let by_direction = pick("mean per direction", &|c| {
        (c.by_direction.iter().map(|d| d.0 as f64).collect(), c.by_direction.iter().map(|d| d.1).collect())
    });
    if by_direction.iter().any(|s| s.x.len() > 1) {
        figures.push(figure(
            "mean residual by approach direction",
            "approach direction",
            "−1 = negative, +1 = positive",
            "mean residual",
            unit,
            by_direction,
            FigureKind::Bar,
        ));
    }
    let by_position = pick("mean per position bin", &|c| {
        (c.by_position.iter().map(|b| 0.5 * (b.0 + b.1) * 1e3).collect(), c.by_position.iter().map(|b| b.2).collect())
    });
    figures.push(figure(
        "mean residual by position",
        "position",
        "mm",
        "mean residual",
        unit,
        by_position,
        FigureKind::Line,
    ));
    let by_time = pick("mean per time bin", &|c| {
        (c.by_time.iter().map(|b| 0.5 * (b.0 + b.1)).collect(), c.by_time.iter().map(|b| b.2).collect())
    });
    if by_time.iter().any(|s| s.x.len() > 2) {
        figures.push(figure(
            "mean residual over the session time",
            "time",
            "s",
            "mean residual",
            unit,
            by_time,
            FigureKind::Line,
        ));
    }
    // Amplitudes of a least-squares periodogram over position: drawn in the channel's unit like the rest.
    let spectrum = pick("strongest periods", &|c| {
        (c.spectrum_peaks.iter().map(|p| p.0 * 1e3).collect(), c.spectrum_peaks.iter().map(|p| p.1).collect())
    });
    if !spectrum.is_empty() {
        figures.push(figure(
            "strongest spatial periods of the residual (least-squares periodogram over position)",
            "wavelength",
            "mm",
            "amplitude",
            unit,
            spectrum,
            FigureKind::Bar,
        ));
    }
    figures
}
