//! The model-check loop (DESIGN.md §8) run to its end on a recording, as `vmt run`'s check: the adapter
//! from a scenario's `model_check` estimator to `crate::modelcheck`'s compare, diagnose and add.

use super::{Check, Quantity, Statistic};
use crate::error::VmtError;
use crate::measurement::MeasurementSet;
use std::path::Path;
use vmt_report::{Figure, FigureKind, Series, SeriesStyle};
use vmt_sim::effects::EffectName;

/// The model-check loop run to its end on a recording: from the model file `model` (beside the scenario
/// `source`), compare → diagnose → add the top significant effect, at most `max_steps` times; a check per
/// `expected` effect (found or not) and the normalised residual RMS at the end (at most `tolerance`, 1 =
/// noise level), with the figures of the RMS per iteration and of the residual by position.
pub(super) fn model_check_loop(
    source: &Path,
    set: &MeasurementSet,
    model: &str,
    expected: &[EffectName],
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
    // Every model's comparison with the recording: the starting model, then the model after each add.
    let mut models: Vec<(crate::modelcheck::CompareReport, String)> = vec![(first, "starting model".into())];
    let mut added: Vec<EffectName> = Vec::new();
    let mut first_ranking: Option<Vec<crate::modelcheck::RankedEffect>> = None;
    for _ in 0..max_steps {
        let d = diagnose(&m, set, source)?;
        first_ranking.get_or_insert_with(|| d.ranking.clone());
        let Some(top) = d.ranking.iter().find(|r| r.verdict == Verdict::Significant) else { break };
        m = add_effect(&m, top.effect, Some(top))
            .map_err(|e| VmtError::bad(source, "estimators (model_check)", e.to_string()))?;
        added.push(top.effect);
        let after = compare(&m, set, source)?;
        history.push(after.normalized_rms);
        models.push((after, format!("after add {}", top.effect)));
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
    // positioning, lead errors), against the feed (friction) — for the starting model and after each add.
    let iterations: Vec<f64> = (0..history.len()).map(|i| i as f64).collect();
    let nrms = Figure {
        title: format!(
            "model-check loop: normalised residual RMS per iteration (added: {})",
            if added.is_empty() { "nothing".into() } else { crate::modelcheck::effect_list(&added) }
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
    let models: Vec<(&crate::modelcheck::CompareReport, &str)> = models.iter().map(|(r, l)| (r, l.as_str())).collect();
    figures.extend(residual_figures(
        "model-check loop",
        "before and after each add",
        set,
        &models,
        MAX_FIGURE_CHANNELS,
    ));
    Ok((checks, figures))
}

/// The diagnosis ranking as a bar chart: the share of the residual each candidate explains (%), one bar
/// per candidate labelled `effect: verdict, ΔBIC` — the "which effect contributes how much" view. None
/// for an empty ranking.
pub(crate) fn ranking_figure(title: String, ranking: &[crate::modelcheck::RankedEffect]) -> Option<Figure> {
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

/// Channels of a lesson report drawn in the residual figures (the first ones of the recording).
pub(crate) const MAX_FIGURE_CHANNELS: usize = 4;

/// Where an effect lives in one channel, by the procedure of its run: a point table or a pass over
/// the travel (by direction, position, time and spatial period), or a friction sweep at one feed (by
/// velocity: the Stribeck curve). Unknown runs count as a point table.
/// The most points a spectrum series draws ([`spectrum_points`]).
pub(crate) const MAX_SPECTRUM_POINTS: usize = 1000;

/// A spectrum's (frequency, amplitude) points thinned to at most `max` (≥ 1): consecutive bins in
/// groups of g = ⌈n/max⌉, each group drawn as its bin of largest amplitude, so that a narrow peak
/// keeps its height; returns (frequencies, amplitudes).
fn spectrum_points(spectrum: &[(f64, f64)], max: usize) -> (Vec<f64>, Vec<f64>) {
    let g = spectrum.len().div_ceil(max.max(1)).max(1);
    spectrum.chunks(g).filter_map(|c| c.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1))).unzip()
}

#[derive(Clone, Copy, PartialEq)]
enum ChannelPlace {
    /// Positioning, constant-velocity, crawl or free runs.
    Travel,
    /// A friction-sweep run with its feed (mm/s) and direction (±1).
    Sweep(f64, i8),
}

fn channel_place(set: &MeasurementSet, c: &crate::modelcheck::ChannelReport) -> ChannelPlace {
    use crate::measurement::Procedure;
    let Some(run) = set.run(&c.run) else { return ChannelPlace::Travel };
    match (run.procedure, run.feed, run.direction) {
        (Procedure::FrictionSweep, Some(feed), Some(d)) => ChannelPlace::Sweep(feed * 1e3, d.signum()),
        (Procedure::FrictionSweep, _, _)
        | (Procedure::Positioning | Procedure::ConstantVelocity | Procedure::Crawl | Procedure::Free, _, _) => {
            ChannelPlace::Travel
        }
    }
}

/// The signed residual where the effects live, for the first `max_channels` channels over the travel
/// and every friction-sweep channel of the reports
/// (all compare reports of the same recording, one per model: the starting model and the model after
/// each `add`), channels of one SI unit per figure, one series per (model, channel):
/// - mean by approach direction (bars; backlash, lost motion) of point-table channels;
/// - mean by position bin (pitch, positioning, lead errors; two lasers at two heights side by side:
///   the Abbe effect of pitch) and over the session time (thermal drift; a cold and a warm test on one
///   time axis: thermal expansion) of channels over the travel;
/// - mean against the feed velocity, by direction, of friction-sweep channels (the Stribeck curve:
///   what a friction model misses at low speed);
/// - the residual's whole periodogram ([`crate::modelcheck::ChannelReport::spectrum`]): amplitude
///   against frequency in Hz for accelerometer channels (resonance), against the spatial period in mm
///   for the others (cyclic errors), each series thinned to at most [`MAX_SPECTRUM_POINTS`] points by
///   keeping the largest amplitude of consecutive bins (a peak is never dropped).
///
/// In µm for deviations, N for forces, mm/s² for accelerations. Titles read `{prefix}: … , {which}`; a
/// view without data draws no figure.
pub(crate) fn residual_figures(
    prefix: &str,
    which: &str,
    set: &MeasurementSet,
    reports: &[(&crate::modelcheck::CompareReport, &str)],
    max_channels: usize,
) -> Vec<Figure> {
    use crate::modelcheck::ChannelReport;
    let Some((first, _)) = reports.first() else { return Vec::new() };
    // The first `max_channels` channels over the travel (each adds series to every view) and every
    // friction-sweep channel (each one point of the velocity view).
    let all = 0..first.channels.len();
    let place = |i: usize| channel_place(set, &first.channels[i]);
    let travel: Vec<usize> = all.clone().filter(|&i| place(i) == ChannelPlace::Travel).take(max_channels).collect();
    let shown: Vec<usize> = all.filter(|&i| place(i) != ChannelPlace::Travel || travel.contains(&i)).collect();
    // Channels grouped by SI unit, in recording order.
    let mut units: Vec<&str> = Vec::new();
    for &i in &shown {
        if !units.contains(&first.channels[i].unit.as_str()) {
            units.push(&first.channels[i].unit);
        }
    }
    let mut figures = Vec::new();
    for si_unit in units {
        let (k, unit) = crate::modelcheck::display_unit(si_unit);
        let chans: Vec<usize> = shown.iter().copied().filter(|&i| first.channels[i].unit == si_unit).collect();
        let several = chans.len() > 1;
        // One series per (model, channel) of the channels `place` selects, from `f` (x, y in SI of y).
        type Curve = (Vec<f64>, Vec<f64>);
        let pick = |travel: bool, f: &dyn Fn(&ChannelReport) -> Curve| -> Vec<Series> {
            let mut out = Vec::new();
            for (r, model) in reports {
                for &i in &chans {
                    let Some(c) = r.channels.get(i) else { continue };
                    if (channel_place(set, c) == ChannelPlace::Travel) != travel {
                        continue;
                    }
                    let (x, y) = f(c);
                    if x.is_empty() {
                        continue;
                    }
                    out.push(Series {
                        label: if several {
                            format!("{model}: {} / {}", c.run, c.sensor)
                        } else {
                            (*model).to_string()
                        },
                        x,
                        y: y.iter().map(|v| v * k).collect(),
                        style: SeriesStyle::LinePoints,
                    });
                }
            }
            out
        };
        let names: Vec<String> =
            chans.iter().map(|&i| format!("{} / {}", first.channels[i].run, first.channels[i].sensor)).collect();
        let name = if names.len() > 3 { format!("{} channels", names.len()) } else { names.join(", ") };
        let figure = |what: &str, x_label: &str, x_unit: &str, y_label: &str, series, kind, log_x| Figure {
            title: format!("{prefix}: {what} ({name}), {which}"),
            x_label: x_label.into(),
            x_unit: x_unit.into(),
            y_label: y_label.into(),
            y_unit: unit.into(),
            series,
            kind,
            log_x,
            log_y: false,
        };
        let by_direction = pick(true, &|c| {
            (c.by_direction.iter().map(|d| d.0 as f64).collect(), c.by_direction.iter().map(|d| d.1).collect())
        });
        if by_direction.iter().any(|s| s.x.len() > 1) {
            figures.push(figure(
                "mean residual by approach direction",
                "approach direction",
                "−1 = negative, +1 = positive",
                "mean residual",
                by_direction,
                FigureKind::Bar,
                false,
            ));
        }
        let by_position = pick(true, &|c| {
            (
                c.by_position.iter().map(|b| 0.5 * (b.0 + b.1) * 1e3).collect(),
                c.by_position.iter().map(|b| b.2).collect(),
            )
        });
        if !by_position.is_empty() {
            figures.push(figure(
                "mean residual by position",
                "position",
                "mm",
                "mean residual",
                by_position,
                FigureKind::Line,
                false,
            ));
        }
        let by_time = pick(true, &|c| {
            (c.by_time.iter().map(|b| 0.5 * (b.0 + b.1)).collect(), c.by_time.iter().map(|b| b.2).collect())
        });
        if by_time.iter().any(|s| s.x.len() > 2) {
            figures.push(figure(
                "mean residual over the session time",
                "time",
                "s",
                "mean residual",
                by_time,
                FigureKind::Line,
                false,
            ));
        }
        // Friction sweeps: each run is one feed in one direction; its mean residual against the feed,
        // one series per (model, direction), in increasing feed.
        let mut by_velocity = Vec::new();
        for (r, model) in reports {
            for dir in [1i8, -1] {
                let mut pts: Vec<(f64, f64)> = chans
                    .iter()
                    .filter_map(|&i| {
                        let c = r.channels.get(i)?;
                        match (channel_place(set, c), c.by_direction.as_slice()) {
                            (ChannelPlace::Sweep(feed, d), [(_, mean, _)]) if d == dir && feed > 0.0 => {
                                Some((feed, mean * k))
                            }
                            (ChannelPlace::Sweep(..) | ChannelPlace::Travel, _) => None,
                        }
                    })
                    .collect();
                pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                if !pts.is_empty() {
                    by_velocity.push(Series {
                        label: format!("{model}, {} direction", if dir > 0 { "positive" } else { "negative" }),
                        x: pts.iter().map(|p| p.0).collect(),
                        y: pts.iter().map(|p| p.1).collect(),
                        style: SeriesStyle::LinePoints,
                    });
                }
            }
        }
        if !by_velocity.is_empty() {
            figures.push(figure(
                "mean residual of each friction-sweep run against its feed velocity",
                "feed velocity",
                "mm/s",
                "mean residual",
                by_velocity,
                FigureKind::Line,
                true,
            ));
        }
        // The residual's whole least-squares periodogram, in the channel's unit like the rest: over time
        // (Hz) for accelerometers, whose resonances live in time; over position (period in mm, log axis)
        // for the others, whose cyclic errors live in space.
        let in_time = chans.iter().all(|&i| {
            set.sensor(&first.channels[i].sensor)
                .is_some_and(|s| s.kind == crate::measurement::SensorKind::Accelerometer)
        });
        let spectrum = pick(true, &|c| {
            let (f, a) = spectrum_points(&c.spectrum, MAX_SPECTRUM_POINTS);
            if in_time {
                (f, a)
            } else {
                (f.iter().map(|f| 1e3 / f).collect(), a)
            }
        });
        if !spectrum.is_empty() {
            let thinned = chans.iter().any(|&i| {
                reports.iter().any(|(r, _)| r.channels.get(i).is_some_and(|c| c.spectrum.len() > MAX_SPECTRUM_POINTS))
            });
            let how = if thinned {
                format!(
                    "least-squares periodogram; each point the largest amplitude of consecutive bins, at most \
                     {MAX_SPECTRUM_POINTS} points"
                )
            } else {
                "least-squares periodogram".to_string()
            };
            let mut fig = if in_time {
                figure(
                    &format!("spectrum of the residual over time ({how})"),
                    "frequency",
                    "Hz",
                    "amplitude",
                    spectrum,
                    FigureKind::Line,
                    false,
                )
            } else {
                figure(
                    &format!("spectrum of the residual over position ({how})"),
                    "spatial period",
                    "mm",
                    "amplitude",
                    spectrum,
                    FigureKind::Line,
                    true,
                )
            };
            for s in &mut fig.series {
                s.style = SeriesStyle::Line;
            }
            figures.push(fig);
        }
    }
    figures
}
