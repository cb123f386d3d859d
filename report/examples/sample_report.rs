//! Writes a sample report (two sections, a table with pass/fail rows, three figures) to the path given
//! as the first argument (default `example.html`): `cargo run --release -p vmt-report --example
//! sample_report -- /tmp/example.html`. The data are made up here for illustration: a linear-axis
//! positioning error EXX "injected" as 2 µm/100 mm slope plus a 1.5 µm sine of 40 mm wavelength, and a
//! "recovered" copy with a small made-up deviation.

use vmt_report::{write_atomic, Figure, FigureKind, Report, RowStatus, Section, Series, SeriesStyle, Table};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path: String = std::env::args().nth(1).unwrap_or_else(|| "example.html".to_string());
    let x_mm: Vec<f64> = (0..=60).map(|i| i as f64 * 5.0).collect();
    let injected_um: Vec<f64> =
        x_mm.iter().map(|&x| 0.02 * x + 1.5 * (2.0 * std::f64::consts::PI * x / 40.0).sin()).collect();
    let recovered_um: Vec<f64> =
        x_mm.iter().zip(&injected_um).map(|(&x, &e)| e + 0.15 * (x / 37.0).cos() - 0.05).collect();
    let freq_hz: Vec<f64> = (0..40).map(|i| 10f64.powf(-1.0 + i as f64 * 0.08)).collect();
    let psd: Vec<f64> = freq_hz.iter().map(|&f| 1e-3 / (1.0 + (f / 5.0).powi(2))).collect();
    let psd_fit: Vec<f64> = freq_hz.iter().map(|&f| 1.1e-3 / (1.0 + (f / 4.6).powi(2))).collect();

    let report = Report {
        title: "vmt run — default scenario (X axis)".to_string(),
        subtitle: "Injected versus recovered geometric errors; illustrative data".to_string(),
        sections: vec![
            Section {
                heading: "Summary".to_string(),
                text: vec![
                    "Each row compares the error injected into the simulated axis with the value the estimator recovered. \
                     A row passes when |recovered − injected| ≤ tolerance."
                        .to_string(),
                ],
                figures: vec![],
                tables: vec![Table {
                    caption: "Estimated errors (RMS over the travel)".to_string(),
                    header: ["error", "injected / µm", "recovered / µm", "difference / µm", "tolerance / µm", "pass"]
                        .map(String::from)
                        .to_vec(),
                    rows: vec![
                        ["EXX", "1.68", "1.66", "-0.02", "0.20", "yes"].map(String::from).to_vec(),
                        ["EYX", "0.80", "0.77", "-0.03", "0.20", "yes"].map(String::from).to_vec(),
                        ["EZX", "0.50", "0.81", "0.31", "0.20", "no"].map(String::from).to_vec(),
                        ["backlash", "3.00", "2.95", "-0.05", "0.50", "yes"].map(String::from).to_vec(),
                    ],
                    highlight: vec![RowStatus::Pass, RowStatus::Pass, RowStatus::Fail, RowStatus::Pass],
                }],
            },
            Section {
                heading: "Profiles".to_string(),
                text: vec!["Dashed: injected truth; solid: recovered by the estimator.".to_string()],
                figures: vec![
                    Figure {
                        title: "EXX positioning error along X".to_string(),
                        x_label: "position X".to_string(),
                        x_unit: "mm".to_string(),
                        y_label: "EXX".to_string(),
                        y_unit: "µm".to_string(),
                        series: vec![
                            Series {
                                label: "injected".to_string(),
                                x: x_mm.clone(),
                                y: injected_um,
                                style: SeriesStyle::Dashed,
                            },
                            Series { label: "recovered".to_string(), x: x_mm, y: recovered_um, style: SeriesStyle::Line },
                        ],
                        kind: FigureKind::Line,
                        log_x: false,
                        log_y: false,
                    },
                    Figure {
                        title: "Vibration power spectral density".to_string(),
                        x_label: "frequency".to_string(),
                        x_unit: "Hz".to_string(),
                        y_label: "PSD".to_string(),
                        y_unit: "µm²/Hz".to_string(),
                        series: vec![
                            Series { label: "measured".to_string(), x: freq_hz.clone(), y: psd, style: SeriesStyle::Points },
                            Series { label: "model".to_string(), x: freq_hz, y: psd_fit, style: SeriesStyle::Line },
                        ],
                        kind: FigureKind::Line,
                        log_x: true,
                        log_y: true,
                    },
                    Figure {
                        title: "RMS error by component".to_string(),
                        x_label: "component index".to_string(),
                        x_unit: String::new(),
                        y_label: "RMS".to_string(),
                        y_unit: "µm".to_string(),
                        series: vec![
                            Series {
                                label: "injected".to_string(),
                                x: vec![1.0, 2.0, 3.0, 4.0],
                                y: vec![1.68, 0.80, 0.50, 3.0],
                                style: SeriesStyle::Line,
                            },
                            Series {
                                label: "recovered".to_string(),
                                x: vec![1.0, 2.0, 3.0, 4.0],
                                y: vec![1.66, 0.77, 0.81, 2.95],
                                style: SeriesStyle::Line,
                            },
                        ],
                        kind: FigureKind::Bar,
                        log_x: false,
                        log_y: false,
                    },
                ],
                tables: vec![],
            },
        ],
    };
    let html: String = vmt_report::render_html(&report)?;
    write_atomic(&path, html)?;
    println!("wrote {path}");
    Ok(())
}
