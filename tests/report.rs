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
