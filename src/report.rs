//! The HTML report of `vmt run`: one self-contained page (inline SVG from plotters, no network) with the
//! result table, a figure for every estimate, and what was measured.

use crate::error::VmtError;
use crate::estimate::{Estimates, Quantity};
use crate::measurement::MeasurementSet;
use crate::scenario::Scenario;
use vmt_report::{render_html, Report, RowStatus, Section, Table};

fn fmt(q: Quantity, v: f64) -> String {
    match q {
        Quantity::Length => format!("{:.3} µm", v * 1e6),
        Quantity::Angle => format!("{:.3} µrad", v * 1e6),
        Quantity::Ratio => format!("{v:.3}"),
    }
}

/// Builds the report of a run: the table of checks (each row names its figure), then the figures.
pub fn run_report(sc: &Scenario, set: &MeasurementSet, est: &Estimates) -> Report {
    let rows: Vec<Vec<String>> = est
        .checks
        .iter()
        .map(|c| {
            vec![
                c.error.clone(),
                fmt(c.quantity, c.injected),
                fmt(c.quantity, c.recovered),
                fmt(c.quantity, c.difference),
                fmt(c.quantity, c.tolerance),
                if c.pass { "pass".into() } else { "FAIL".into() },
                c.figure.map_or(String::new(), |i| format!("Figure {}", i + 1)),
            ]
        })
        .collect();
    let highlight = est.checks.iter().map(|c| if c.pass { RowStatus::Pass } else { RowStatus::Fail }).collect();
    let table = Table {
        caption: "Each estimate against the injected truth, with the tolerance it must meet".into(),
        header: ["error", "injected", "recovered", "difference", "tolerance", "pass", "figure"]
            .map(String::from)
            .to_vec(),
        rows,
        highlight,
    };
    // The renderer numbers figures in order (Figure 1, 2, …), as the table's last column does.
    let figures = est.figures.clone();
    let measured = Table {
        caption: "Runs of the measurement set".into(),
        header: ["run", "procedure", "rows", "columns"].map(String::from).to_vec(),
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
    Report {
        title: format!("vmt run: {}", sc.source.display()),
        subtitle: sc.description.clone(),
        sections: vec![
            Section {
                heading: "Results".into(),
                text: vec![if failed == 0 {
                    format!("All {} estimates are within tolerance.", est.checks.len())
                } else {
                    format!("{failed} of {} estimates missed their tolerance.", est.checks.len())
                }],
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
                text: Vec::new(),
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
    }
}

/// Renders and writes the report atomically.
/// The HTML text of a run's report.
pub fn run_report_html(sc: &Scenario, set: &MeasurementSet, est: &Estimates) -> Result<String, VmtError> {
    render_html(&run_report(sc, set, est)).map_err(|e| VmtError::Internal(format!("report: {e}")))
}

