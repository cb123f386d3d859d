//! The HTML report of `vmt run` (issue 7): well-formed, self-contained, and a plot for every estimate of
//! the table.

use crate::util::{small, vmt};

/// Counts of opening and closing tags of `name` (opening tags `<name` followed by space or `>`).
fn tag_balance(html: &str, name: &str) -> (usize, usize) {
    let pat = format!("<{name}");
    let open = html
        .match_indices(&pat)
        .filter(|(i, _)| {
            let rest = &html[i + pat.len()..];
            rest.starts_with(' ') || rest.starts_with('>') || rest.starts_with('\n')
        })
        .count();
    (open, html.matches(&format!("</{name}>")).count())
}

#[test]
fn run_report_is_well_formed_and_has_a_figure_for_every_estimate() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = small();
    let out = vmt().arg("run").arg(&scenario).arg("--out").arg(tmp.path()).output().unwrap();
    assert!(out.status.code() == Some(0) || out.status.code() == Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    let html = std::fs::read_to_string(tmp.path().join("report.html")).unwrap();
    assert_eq!(html.matches("<html").count(), 1);
    for tag in ["html", "head", "body", "table", "svg", "figure", "section"] {
        let (o, c) = tag_balance(&html, tag);
        assert_eq!(o, c, "<{tag}> opened {o} times, closed {c} times");
    }
    // Self-contained: no external resources (the SVG namespace is not a fetch).
    for bad in ["src=\"http", "href=\"http", "<script src", "<link rel=\"stylesheet\" href"] {
        assert!(!html.contains(bad), "external resource `{bad}`");
    }
    // Every row of the table names a figure that exists.
    let svgs = tag_balance(&html, "svg").0;
    let text = String::from_utf8_lossy(&out.stdout);
    let rows = text.lines().filter(|l| l.ends_with("pass") || l.ends_with("FAIL")).count();
    assert!(rows >= 4, "expected the small scenario's checks in the table:\n{text}");
    let mut referenced = 0;
    for n in 1..=svgs {
        if html.contains(&format!(">Figure {n}<")) {
            referenced += 1;
        }
    }
    let figure_cells = html.matches(">Figure ").count();
    assert!(figure_cells >= rows, "{figure_cells} figure references for {rows} estimates");
    assert!(referenced >= 1 && svgs >= 2, "{svgs} svg figures, {referenced} referenced");
}

/// The figures of a `vmt run` report (from its report.json) of the lesson `name`.
fn lesson_figures(name: &str, out: &std::path::Path) -> Vec<vmt_report::Figure> {
    let scenario = crate::util::root().join(format!("scenarios/lessons/{name}/scenario.toml"));
    let dir = out.join(name);
    let o = vmt().arg("run").arg(&scenario).arg("-o").arg(&dir).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{name}: {}", String::from_utf8_lossy(&o.stderr));
    let report: vmt_report::Report =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    report.sections.into_iter().flat_map(|s| s.figures).collect()
}

fn labels(f: &vmt_report::Figure) -> Vec<&str> {
    f.series.iter().map(|s| s.label.as_str()).collect()
}

fn find<'a>(figs: &'a [vmt_report::Figure], lesson: &str, view: &str) -> &'a vmt_report::Figure {
    let titles: Vec<&str> = figs.iter().map(|f| f.title.as_str()).collect();
    figs.iter().find(|f| f.title.contains(view)).unwrap_or_else(|| panic!("{lesson}: no `{view}` figure in {titles:?}"))
}

/// Issue 16: each lesson report shows the residual where its effect lives, before and after each `add`:
/// the cold against the warm test (thermal expansion), the low against the high laser (pitch through
/// the Abbe offset), the mean force residual against the feed velocity of every sweep run (Stribeck
/// friction, where a position or spatial-period view means nothing), and one series per model of the loop
/// when it adds two effects. The normalised RMS per iteration is drawn on whole iterations.
#[test]
fn lesson_reports_show_the_residual_where_each_effect_lives() {
    let tmp = tempfile::tempdir().unwrap();
    // Thermal expansion: the warm test's residual beside the cold one, on one time axis and by position.
    let figs = lesson_figures("warm_up", tmp.path());
    for view in ["mean residual by position", "mean residual over the session time"] {
        let l = labels(find(&figs, "warm_up", view));
        for run in ["starting model: cold / laser", "starting model: warm / laser", "after add thermal_expansion: warm"]
        {
            assert!(l.iter().any(|s| s.starts_with(run)), "warm_up `{view}` lacks `{run}`: {l:?}");
        }
    }
    // Pitch: both lasers (two heights) in one figure.
    let figs = lesson_figures("abbe_pitch", tmp.path());
    let l = labels(find(&figs, "abbe_pitch", "mean residual by position"));
    for laser in ["laser_low", "laser_high"] {
        assert!(
            l.iter().any(|s| s.starts_with("starting model") && s.ends_with(laser)),
            "abbe_pitch lacks {laser}: {l:?}"
        );
    }
    // Stribeck: the velocity view, log feed axis in mm/s, every feed of the sweep per direction and model.
    let figs = lesson_figures("stribeck", tmp.path());
    let v = find(&figs, "stribeck", "against its feed velocity");
    assert!(v.log_x && v.x_unit == "mm/s" && v.y_unit == "N", "{} {} {}", v.log_x, v.x_unit, v.y_unit);
    assert_eq!(labels(v).len(), 4, "starting/final model × positive/negative direction: {:?}", labels(v));
    for s in &v.series {
        assert_eq!(s.x.len(), 7, "{}: one point per feed of the 7-feed sweep", s.label);
        assert!(s.x.windows(2).all(|w| w[0] < w[1]), "{}: feeds in increasing order", s.label);
    }
    for meaningless in ["by position", "spectrum of the residual", "approach direction"] {
        assert!(
            !figs.iter().any(|f| f.title.contains(meaningless)),
            "stribeck: a `{meaningless}` view of friction sweeps"
        );
    }
    // Two adds: the starting model and the model after each add.
    let figs = lesson_figures("drift_and_lead", tmp.path());
    let l = labels(find(&figs, "drift_and_lead", "mean residual by position"));
    for model in ["starting model", "after add cyclic_lead", "after add thermal_drift"] {
        assert!(l.iter().any(|s| s.starts_with(model)), "drift_and_lead lacks `{model}`: {l:?}");
    }
    // Cyclic lead: the residual's whole spectrum over position (period in mm, log axis) peaks at the 16 mm
    // screw lead for the starting model, on each laser; after both adds the amplitude there is below a third.
    let sp = find(&figs, "drift_and_lead", "spectrum of the residual over position");
    assert!(sp.log_x && sp.x_unit == "mm" && sp.y_unit == "µm", "{} {} {}", sp.log_x, sp.x_unit, sp.y_unit);
    for laser in ["laser_low", "laser_high"] {
        let series = |model: &str| {
            sp.series
                .iter()
                .find(|s| s.label.starts_with(model) && s.label.ends_with(laser))
                .unwrap_or_else(|| panic!("no `{model}` spectrum of {laser}: {:?}", labels(sp)))
        };
        let (start, last) = (series("starting model"), series("after add thermal_drift"));
        let (i, (period, amp)) =
            start.x.iter().zip(&start.y).enumerate().max_by(|a, b| a.1 .1.total_cmp(b.1 .1)).unwrap();
        assert!((period - 16.0).abs() < 1.6, "{laser}: peak at {period} mm");
        assert_eq!(last.x[i], *period, "{laser}: the same period grid before and after");
        assert!(last.y[i] < amp / 3.0, "{laser}: {} µm after the adds vs {amp} µm", last.y[i]);
    }
    let nrms = find(&figs, "drift_and_lead", "normalised residual RMS per iteration");
    assert_eq!(nrms.series[0].x, vec![0.0, 1.0, 2.0]);
}

/// Issue 16, first bullet: the report opens with every test condition a calibration engineer reads
/// before any number, each read from the rendered report (report.json's first section, and the same text
/// in report.html): program and version (with the git commit when built from git), date
/// (`SOURCE_DATE_EPOCH`), command line, scenario, machine, seed; per procedure feed, dwell, runs,
/// targets, overrun; per sensor noise, mounting point, Abbe offset; per laser the air, the material
/// temperature, α and the Edlén index applied. laser_x3 of tests/data/small.toml is given non-default
/// air and material so that those cells must come from the scenario.
#[test]
fn the_report_opens_with_every_test_condition() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(small()).unwrap();
    let from = "name = \"laser_x3\"\n";
    assert!(text.contains(from), "test setup: laser_x3 not in tests/data/small.toml");
    let env = "material_temperature = 22.5\nassumed_material_temperature = 22.0\nmaterial_alpha = 8e-6\n\
               air = { temperature = 23.0, pressure = 100000.0, humidity = 40.0 }\n";
    let scenario = tmp.path().join("conditions.toml");
    std::fs::write(&scenario, text.replacen(from, &format!("{from}{env}"), 1)).unwrap();
    let out_dir = tmp.path().join("out");
    let o = vmt()
        .env("SOURCE_DATE_EPOCH", "1000000000")
        .arg("run")
        .arg(&scenario)
        .arg("--out")
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(o.status.code() == Some(0) || o.status.code() == Some(1), "{}", String::from_utf8_lossy(&o.stderr));
    let report: vmt_report::Report =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("report.json")).unwrap()).unwrap();
    let html = std::fs::read_to_string(out_dir.join("report.html")).unwrap();
    let first = &report.sections[0];
    assert_eq!(first.heading, "Test conditions");
    let table = |caption: &str| -> &vmt_report::Table {
        first.tables.iter().find(|t| t.caption.starts_with(caption)).unwrap_or_else(|| panic!("no `{caption}` table"))
    };
    // A cell of `table` in the row whose first cell is `row`, under the column headed `column`; it must
    // also be on the rendered page.
    let cell = |t: &vmt_report::Table, row: &str, column: &str| -> String {
        let j =
            t.header.iter().position(|h| h == column).unwrap_or_else(|| panic!("{}: no column `{column}`", t.caption));
        let r = t.rows.iter().find(|r| r[0] == row).unwrap_or_else(|| panic!("{}: no row `{row}`", t.caption));
        let c = r[j].clone();
        let escaped = c.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;");
        assert!(html.contains(&escaped), "report.html lacks {column} of {row}: {c}");
        c
    };
    let run = table("Run");
    let program = cell(run, "program", "value");
    assert!(program.starts_with(&format!("vmt {}", env!("CARGO_PKG_VERSION"))), "{program}");
    let head = std::process::Command::new("git")
        .args(["-C", env!("CARGO_MANIFEST_DIR"), "rev-parse", "--short=12", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
    if let Some(head) = head {
        assert!(program.contains(&format!("(git {head}")), "built from git at {head}: {program}");
    }
    assert_eq!(cell(run, "date (UTC)", "value"), "2001-09-09T01:46:40Z");
    let command = cell(run, "command line", "value");
    assert!(command.contains(" run ") && command.contains(&*scenario.to_string_lossy()), "{command}");
    assert_eq!(cell(run, "scenario", "value"), scenario.display().to_string());
    assert_eq!(cell(run, "machine", "value"), "slide_column");
    assert!(cell(run, "seed", "value").starts_with("20261121 "));

    let p = table("Procedures");
    assert_eq!(cell(p, "iso", "feed"), "400 mm/s");
    assert_eq!(cell(p, "iso", "dwell"), "0.2 s (mean of last 0.1 s)");
    assert_eq!(cell(p, "iso", "runs"), "2 ↑ + 2 ↓");
    assert_eq!(cell(p, "iso", "targets"), "4 given, 100.0 mm–900.0 mm");
    assert!(cell(p, "iso", "overrun").ends_with(" mm"));
    assert_eq!(cell(p, "cv", "feed"), "200, 400 mm/s");

    let s = table("Sensors");
    assert_eq!(cell(s, "laser_x3", "noise"), "σ 0.02000 µm, step 0.001000 µm");
    assert_eq!(cell(s, "laser_x3", "mounting point"), "link mp3 at (300, 150, 1200) mm");
    // Abbe offset of a beam along x from (300, 150, 1200) mm: |(0, 150, 1200)| = 1209.3 mm.
    assert_eq!(cell(s, "laser_x3", "Abbe offset"), "1209 mm (0, 150, 1200)");
    assert_eq!(cell(s, "acc_z", "noise"), "0.300 µg/√Hz");

    let l = table("Lasers");
    assert_eq!(cell(l, "laser_x3", "air at the beam"), "23.00 °C, 100.00 kPa, 40 % RH");
    assert_eq!(cell(l, "laser_x3", "material temperature"), "22.50 °C");
    assert_eq!(cell(l, "laser_x3", "material temperature assumed"), "22.00 °C");
    assert_eq!(cell(l, "laser_x3", "α"), "8.00 µm/(m·K)");
    assert_eq!(cell(l, "laser_x1", "α"), "11.50 µm/(m·K)");
    let ppm = |c: String| -> f64 { c.strip_suffix(" ppm").unwrap_or_else(|| panic!("{c}")).parse().unwrap() };
    // Birch & Downs at 633 nm: n − 1 = 271.4 ppm in reference air; ∝ p/T, so ≈ 265 ppm at 23 °C, 100 kPa.
    let reference = ppm(cell(l, "laser_x1", "Edlén n − 1 applied"));
    let warm = ppm(cell(l, "laser_x3", "Edlén n − 1 applied"));
    assert!((271.0..271.8).contains(&reference) && (263.0..267.0).contains(&warm), "{reference} / {warm} ppm");
    // The laser assumes 22.0 °C for material at 22.5 °C: 8e-6 · 0.5 K / (1 + 8e-6 · 2 K) = 4.000 ppm.
    assert_eq!(cell(l, "laser_x3", "normalisation error"), "4.000 ppm");
}
