//! The model-check loop (DESIGN.md §8) run to its end on a recording, as `vmt run`'s check: the adapter
//! from a scenario's `model_check` estimator to `crate::modelcheck`'s compare, diagnose and add.

use super::{Check, Quantity};
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
) -> Result<(Vec<Check>, Figure, Figure), VmtError> {
    use crate::modelcheck::{add_effect, compare, diagnose};
    use vmt_estimators::modelcheck::Verdict;
    let base = source.parent().unwrap_or(Path::new("."));
    let mut m = crate::model::read_model(&base.join(model))?;
    let first = compare(&m, set, source)?;
    let mut history = vec![first.normalized_rms];
    let mut last_report = first.clone();
    let mut added: Vec<String> = Vec::new();
    for _ in 0..max_steps {
        let d = diagnose(&m, set, source)?;
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
