//! The HTML report of `vmt run`: one self-contained page (inline SVG from plotters, no network) with the
//! result table, a figure for every estimate, and what was measured.

use crate::error::VmtError;
use crate::estimate::{Estimates, CHECK_HEADER, CHECK_LEGEND};
use crate::measurement::MeasurementSet;
use crate::scenario::Scenario;

mod conditions;
pub use conditions::{command_line, conditions, conditions_for_data, report_date, version};
use vmt_report::{render_html, Report, RowStatus, Section, Table};

/// Builds the report of a run: the table of checks (each row names its figure), then the figures.
pub fn run_report(sc: &Scenario, set: &MeasurementSet, est: &Estimates) -> Report {
    let rows: Vec<Vec<String>> = est
        .checks
        .iter()
        .map(|c| {
            let mut row = c.cells().to_vec();
            row.push(c.figure.map_or(String::new(), |i| format!("Figure {}", i + 1)));
            row
        })
        .collect();
    let highlight = est.checks.iter().map(|c| if c.pass { RowStatus::Pass } else { RowStatus::Fail }).collect();
    let table = Table {
        caption: "Each estimate against the injected truth, with the tolerance it must meet".into(),
        header: CHECK_HEADER.iter().chain(&["figure"]).map(|h| h.to_string()).collect(),
        rows,
        highlight,
    };
    // The renderer numbers figures in order (Figure 1, 2, …), as the table's last column does.
    let figures = est.figures.clone();
    let measured = Table {
        caption: "Runs of the measurement set".into(),
        header: ["run", "procedure", "rows (count)", "columns"].map(String::from).to_vec(),
        rows: set
            .runs
            .iter()
            .map(|r| {
                vec![
                    r.name.clone(),
                    r.procedure.as_str().into(),
                    r.data.len().to_string(),
                    r.data.columns().iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>().join(", "),
                ]
            })
            .collect(),
        highlight: Vec::new(),
    };
    let failed = est.checks.iter().filter(|c| !c.pass).count();
    let mut report = Report {
        title: format!("vmt run: {}", sc.source.display()),
        subtitle: sc.description.clone(),
        sections: vec![
            conditions(sc),
            Section {
                heading: "Results".into(),
                text: std::iter::once(if failed == 0 {
                    format!("All {} estimates are within tolerance.", est.checks.len())
                } else {
                    format!("{failed} of {} estimates missed their tolerance.", est.checks.len())
                })
                .chain(std::iter::once(CHECK_LEGEND.to_string()))
                .chain(est.checks.iter().filter_map(|c| c.note.as_ref().map(|n| format!("{}: {n}", c.error))))
                .chain(std::iter::once(
                    "Methods and their sources: docs/methods.md; file formats: docs/formats.md (in the vmt repository).".into(),
                ))
                .collect(),
                figures: Vec::new(),
                tables: vec![table],
            },
            Section {
                heading: "Figures".into(),
                text: vec!["Injected (truth) against recovered profiles and values, one figure per estimator.".into()],
                figures,
                tables: Vec::new(),
            },
            Section {
                heading: "Tables of the estimators".into(),
                text: est.notes.clone(),
                figures: Vec::new(),
                tables: est.tables.clone(),
            },
            Section {
                heading: "What was measured".into(),
                text: vec![format!("Machine {}, seed {}.", sc.machine_name, sc.seed)],
                figures: Vec::new(),
                tables: vec![measured],
            },
        ],
    };
    // A scenario without estimator tables or notes (the crawl) has nothing for that section: no empty section.
    report.sections.retain(|s| !(s.text.is_empty() && s.figures.is_empty() && s.tables.is_empty()));
    report
}

/// The report's HTML page and its data as JSON (`report.json` beside `report.html`: the [`Report`]
/// data, for other programs and for the readability check), to be written in one output transaction.
pub fn report_files(report: &Report) -> Result<(String, String), VmtError> {
    let html = render_html(report).map_err(|e| VmtError::Internal(format!("report: {e}")))?;
    let json = serde_json::to_string_pretty(report).map_err(|e| VmtError::Internal(format!("report JSON: {e}")))?;
    Ok((html, json))
}
/// The HTML report of a tolerance study (`vmt study`, `study merge`): the test conditions, one figure
/// per estimate of the error against the varied value (mean and 95th percentile of |estimate − truth|
/// over the trials, markers at the studied values, with the Cramér–Rao bound where one exists), and the
/// summary table.
pub fn study_report(sc: Option<&Scenario>, summary: &[crate::study::SummaryRow], label: &str) -> Report {
    use vmt_report::{Figure, FigureKind, Series, SeriesStyle};
    // One figure per estimate, in first-appearance order (the summary is sorted by value, then estimate:
    // a plain `dedup` kept every repetition and drew values × estimates figures of all points each).
    let mut names: Vec<&str> = Vec::new();
    for s in summary {
        if !names.contains(&s.estimate.as_str()) {
            names.push(&s.estimate);
        }
    }
    let positive = crate::study::all_positive(summary);
    // An estimate without a difference (a one-sided limit or a found/not-found check) has only a pass
    // rate, which the table shows: no figure for it.
    let undefined: Vec<&str> =
        names.iter().copied().filter(|n| summary.iter().all(|s| s.estimate != *n || s.mean_abs.is_none())).collect();
    let figures: Vec<Figure> = names
        .iter()
        .filter(|n| !undefined.contains(n))
        .map(|n| {
            let pts: Vec<&crate::study::SummaryRow> = summary.iter().filter(|s| s.estimate == *n).collect();
            let line = |label: &str, stat: fn(&crate::study::SummaryRow) -> Option<f64>| {
                let (x, y) = crate::study::defined_points(&pts, stat, 1e6);
                Series { label: label.into(), x, y, style: SeriesStyle::LinePoints }
            };
            let mut series = vec![line("mean |error|", |s| s.mean_abs), line("95th percentile |error|", |s| s.p95_abs)];
            let bound: Vec<(f64, f64)> =
                pts.iter().filter(|s| s.bound.is_finite() && s.bound > 0.0).map(|s| (s.value, s.bound * 1e6)).collect();
            if !bound.is_empty() {
                series.push(Series {
                    label: "Cramér–Rao bound (RMS)".into(),
                    x: bound.iter().map(|b| b.0).collect(),
                    y: bound.iter().map(|b| b.1).collect(),
                    style: SeriesStyle::Dashed,
                });
            }
            if let Some(t) = crate::study::tolerance_line(&pts) {
                series.push(t);
            }
            Figure {
                title: format!(
                    "{n}: error of the estimate against {label}, {} trials per value",
                    pts.first().map_or(0, |p| p.trials)
                ),
                x_label: label.to_string(),
                x_unit: "SI unit of the key".into(),
                y_label: "|estimate − truth|".into(),
                y_unit: "µm (µrad for angles)".into(),
                series,
                kind: FigureKind::Line,
                log_x: positive,
                log_y: positive,
            }
        })
        .collect();
    let table = Table {
        caption: "Summary per studied value and estimate".into(),
        header: [
            "value (SI)",
            "estimate",
            "trials (count)",
            "mean |error| / µm",
            "p95 |error| / µm",
            "pass rate / %",
            "Cramér–Rao bound / µm",
        ]
        .map(String::from)
        .to_vec(),
        rows: summary
            .iter()
            .map(|r| {
                vec![
                    format!("{:.3e}", r.value),
                    r.estimate.clone(),
                    r.trials.to_string(),
                    r.mean_abs.map_or("—".into(), |m| format!("{:.4}", m * 1e6)),
                    r.p95_abs.map_or("—".into(), |p| format!("{:.4}", p * 1e6)),
                    r.pass_rate.map_or("—".into(), |p| format!("{:.0}", 100.0 * p)),
                    if r.bound.is_finite() { format!("{:.4}", r.bound * 1e6) } else { "—".into() },
                ]
            })
            .collect(),
        highlight: Vec::new(),
    };
    let head = match sc {
        Some(sc) => conditions(sc),
        None => conditions_for_data(vec![vec!["varied parameter".into(), label.to_string()]]),
    };
    Report {
        title: format!("vmt study: {label}"),
        subtitle: sc.map_or(String::new(), |s| s.description.clone()),
        sections: vec![
            head,
            Section {
                heading: "Error against the varied parameter".into(),
                text: std::iter::once(
                    "Each marker is one studied value; lengths in µm, angles in µrad (the trial rows carry SI values)."
                        .to_string(),
                )
                .chain(undefined.iter().map(|n| {
                    format!(
                        "{n}: a limit or found/not-found check forms no difference from the truth, so its \
                         |error| is undefined (—) and it has no figure; its pass rate is in the table."
                    )
                }))
                .collect(),
                figures,
                tables: vec![table],
            },
        ],
    }
}

/// Channels over the travel a `--report` of compare/diagnose draws in its residual figures (each adds a
/// series to every view; friction sweeps are all drawn, one point each in the velocity view).
pub const MAX_REPORT_CHANNELS: usize = 8;

/// The HTML report of `vmt compare` / `vmt diagnose --report FILE` on a user's data: the test
/// conditions (program, date, command, model, data), each channel's residual against its noise, the
/// fitted shapes and parameters, for a diagnosis its ranking (table and bar chart of the share each
/// candidate explains) with the advice, and per channel the signed residual where the effects live (by
/// approach direction, position, time, and its spectrum: over position for deviations, over time in Hz for
/// accelerometers).
pub fn model_check_report(
    model: &std::path::Path,
    data: &std::path::Path,
    set: &crate::measurement::MeasurementSet,
    cmp: &crate::modelcheck::CompareReport,
    diag: Option<&crate::modelcheck::DiagnoseReport>,
) -> Report {
    use crate::modelcheck::{effect_list, param_text, shapes_text, sigma_text};
    use vmt_estimators::modelcheck::Verdict;
    let kind = if diag.is_some() { "diagnose" } else { "compare" };
    let unit_of = crate::modelcheck::display_unit;
    let channels = Table {
        caption: "The model against each channel: residual RMS, the noise σ of one reading, their ratio (1 = the \
                  residual is noise), NRMSE fit and the Ljung–Box p-value of the residual in acquisition order"
            .into(),
        header: [
            "run",
            "sensor",
            "residual RMS",
            "σ",
            "normalised RMS (1 = noise)",
            "fit (%)",
            "Ljung–Box p (probability)",
        ]
        .map(String::from)
        .to_vec(),
        rows: cmp
            .channels
            .iter()
            .map(|c| {
                let (k, u) = unit_of(&c.unit);
                vec![
                    c.run.clone(),
                    c.sensor.clone(),
                    format!("{:.4} {u}", c.rms * k),
                    format!("{:.4} {u}{}", c.sigma * k, if c.sigma_estimated { " (estimated)" } else { "" }),
                    format!("{:.3}", c.normalized_rms),
                    format!("{:.1}", c.fit_percent),
                    c.ljung_box_p.map_or("—".into(), |p| format!("{p:.3}")),
                ]
            })
            .collect(),
        highlight: Vec::new(),
    };
    let fitted = Table {
        caption: "Fitted parameters of the model (units of the effect catalogue; other keys SI)".into(),
        header: ["effect", "parameter", "value"].map(String::from).to_vec(),
        rows: cmp
            .fitted
            .iter()
            .flat_map(|(e, p)| p.iter().map(move |(k, v)| vec![e.to_string(), k.clone(), param_text(e, k, *v)]))
            .collect(),
        highlight: Vec::new(),
    };
    let mut text = vec![format!(
        "Normalised RMS over all {} samples: {:.3} (1.0 = noise level), {} fitted parameters.",
        cmp.n, cmp.normalized_rms, cmp.n_params
    )];
    text.extend(shapes_text(&cmp.shapes).lines().map(|l| format!("Shape of {l}.")));
    text.extend(sigma_text(cmp.sigma.as_ref()).lines().map(String::from));
    text.extend(cmp.notes.iter().map(|n| format!("Note: {n}")));
    let mut sections = vec![
        conditions_for_data(vec![
            vec!["model".into(), model.display().to_string()],
            vec!["data".into(), data.display().to_string()],
        ]),
        Section {
            heading: "The model against the data".into(),
            text,
            figures: Vec::new(),
            tables: [channels, fitted].into_iter().filter(|t| !t.rows.is_empty()).collect(),
        },
    ];
    if let Some(d) = diag {
        let verdict = |v: Verdict| match v {
            Verdict::Significant => "significant",
            Verdict::Noise => "noise",
            Verdict::Inseparable => "inseparable",
        };
        let ranking = Table {
            caption: "Candidate effects the model lacks, best first: ΔBIC of adding each alone (negative favours \
                      it), the bound on the probability that noise alone explains this much (searches counted), \
                      the share of the residual it explains, the verdict and its fitted parameters"
                .into(),
            header: ["rank (order)", "effect", "ΔBIC (1)", "p (noise alone)", "explained (%)", "verdict", "parameters"]
                .map(String::from)
                .to_vec(),
            rows: d
                .ranking
                .iter()
                .enumerate()
                .map(|(i, e)| {
                    let mut v = verdict(e.verdict).to_string();
                    if !e.confused_with.is_empty() {
                        v += &format!(" (confused with {})", effect_list(&e.confused_with));
                    }
                    vec![
                        (i + 1).to_string(),
                        e.effect.to_string(),
                        format!("{:.1}", e.delta_bic),
                        e.p_value.map_or("—".into(), |p| format!("{p:.1e}")),
                        format!("{:.1}", 100.0 * e.explained),
                        v,
                        e.params
                            .iter()
                            .map(|(k, x)| format!("{k} = {}", param_text(e.effect, k, *x)))
                            .collect::<Vec<_>>()
                            .join(", "),
                    ]
                })
                .collect(),
            highlight: Vec::new(),
        };
        let mut text = vec![format!("Advice: {}", d.advice)];
        // A candidate's note is often also one of the diagnosis's notes: each sentence once.
        let notes = d.ranking.iter().filter_map(|e| e.note.as_ref().map(|n| format!("{}: {n}", e.effect)));
        for n in notes.chain(d.notes.iter().map(|n| format!("Note: {n}"))) {
            if !text.iter().any(|t| t.ends_with(n.split_once(": ").map_or(n.as_str(), |x| x.1))) {
                text.push(n);
            }
        }
        sections.push(Section {
            heading: "Diagnosis: which effect is missing".into(),
            text,
            figures: crate::estimate::model_check::ranking_figure(
                "vmt diagnose: share of the residual each candidate explains (verdict, ΔBIC)".into(),
                &d.ranking,
            )
            .into_iter()
            .collect(),
            tables: if ranking.rows.is_empty() { Vec::new() } else { vec![ranking] },
        });
    }
    let figures: Vec<vmt_report::Figure> = crate::estimate::model_check::residual_figures(
        &format!("vmt {kind}"),
        "model",
        set,
        &[(cmp, "model")],
        MAX_REPORT_CHANNELS,
    );
    let mut text = vec!["The signed residual (measured − model) where each effect lives: by approach direction \
                         (backlash, lost motion), by position (pitch, positioning and lead errors; lasers at \
                         two heights side by side for pitch), over the session time (thermal drift; a cold and \
                         a warm test on one time axis), against the feed velocity for friction sweeps \
                         (Stribeck friction) and its spectrum: over position for cyclic errors, over time in Hz for the \
                         resonances accelerometers see."
        .to_string()];
    if cmp.channels.len() > MAX_REPORT_CHANNELS {
        text.push(format!(
            "Figures for the first {MAX_REPORT_CHANNELS} channels over the travel and every friction sweep, of {} \
             channels; the table above lists all.",
            cmp.channels.len()
        ));
    }
    sections.push(Section { heading: "Where the residual lives".into(), text, figures, tables: Vec::new() });
    sections.retain(|s| !(s.text.is_empty() && s.figures.is_empty() && s.tables.is_empty()));
    Report {
        title: format!("vmt {kind}: {} against {}", model.display(), data.display()),
        subtitle: String::new(),
        sections,
    }
}
