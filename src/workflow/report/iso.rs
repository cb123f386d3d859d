//! The ISO 230-2 figure and table as laser-calibration software draws them (issue 16): every run's
//! trace per approach direction, the mean ↑ and ↓ lines, the x̄ ± 2s envelopes, the injected truth,
//! and A, B, E, M, R beside it; the table with s↑ and s↓; the uncertainty statement (ISO 230-2:2014
//! §8 asks the report to state the measurement uncertainty, ISO/TR 230-9 with coverage factor k = 2).

use vmt_estimators::iso230_2::AxisResult;
use vmt_report::{Figure, FigureKind, Series, SeriesStyle, Table};

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
