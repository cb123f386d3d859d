//! Workflow tests of the HTML report: a small well-formedness checker written here, escaping of user
//! text, one inline <svg> per figure, no external resources, and graceful handling of degenerate data.

use std::collections::HashMap;
use vmt_report::{
    figure_svg, render_html, write_atomic, Figure, FigureKind, Report, ReportError, RowStatus, Section, Series,
    SeriesStyle, Table, PALETTE_HEX,
};

// ---------------------------------------------------------------------------------------------------
// A minimal checker for the markup this crate emits (HTML5 + inline SVG written as XML).
// ---------------------------------------------------------------------------------------------------

/// Element counts of a checked document.
#[derive(Debug, Default)]
struct Checked {
    /// Number of start tags per element name (lower case).
    elements: HashMap<String, usize>,
    /// Start tags with their attributes as written, e.g. `tr class="pass"`.
    start_tags: Vec<String>,
    /// Text content outside tags (entity-encoded, as written).
    texts: Vec<String>,
}

impl Checked {
    fn count(&self, name: &str) -> usize {
        self.elements.get(name).copied().unwrap_or(0)
    }
}

const VOID: [&str; 6] = ["meta", "link", "br", "hr", "img", "input"];
const ENTITIES: [&str; 6] = ["&amp;", "&lt;", "&gt;", "&quot;", "&#39;", "&apos;"];

/// Every `&` must start one of the entities we emit.
fn check_entities(text: &str, at: usize) -> Result<(), String> {
    for (i, _) in text.match_indices('&') {
        if !ENTITIES.iter().any(|e| text[i..].starts_with(e)) {
            return Err(format!("bare '&' at byte {} in {:?}", at + i, &text[i..(i + 12).min(text.len())]));
        }
    }
    Ok(())
}

/// Checks that every start tag is closed in order (void HTML elements and `<x/>` excepted), that tags
/// and attribute values are well quoted, that text contains no raw `<` and only known entities, and
/// that the doctype comes first. Returns the element counts.
fn check_markup(doc: &str) -> Result<Checked, String> {
    let mut out: Checked = Checked::default();
    let mut stack: Vec<(String, usize)> = Vec::new();
    let bytes: &[u8] = doc.as_bytes();
    let mut i: usize = 0;
    let mut seen_doctype: bool = false;
    while i < bytes.len() {
        if bytes[i] != b'<' {
            let end: usize = doc[i..].find('<').map_or(doc.len(), |k| i + k);
            let text: &str = &doc[i..end];
            if text.contains('>') {
                return Err(format!("raw '>' in text at byte {i}: {:?}", &text[..text.len().min(40)]));
            }
            check_entities(text, i)?;
            if !text.trim().is_empty() {
                if stack.is_empty() {
                    return Err(format!("text outside the root element at byte {i}"));
                }
                out.texts.push(text.trim().to_string());
            }
            i = end;
            continue;
        }
        if doc[i..].starts_with("<!--") {
            i = doc[i..].find("-->").map(|k| i + k + 3).ok_or("unterminated comment")?;
            continue;
        }
        if doc[i..].starts_with("<!DOCTYPE html>") {
            if i != 0 || seen_doctype {
                return Err(format!("doctype must come first and once (byte {i})"));
            }
            seen_doctype = true;
            i += "<!DOCTYPE html>".len();
            continue;
        }
        // Find the end of the tag, honouring quoted attribute values.
        let mut j: usize = i + 1;
        let mut quote: Option<u8> = None;
        while j < bytes.len() {
            match (quote, bytes[j]) {
                (None, b'"') | (None, b'\'') => quote = Some(bytes[j]),
                (Some(q), c) if c == q => quote = None,
                (Some(_), b'<') => return Err(format!("raw '<' inside an attribute value at byte {j}")),
                (None, b'<') => return Err(format!("'<' inside a tag at byte {j}")),
                (None, b'>') => break,
                _ => {}
            }
            j += 1;
        }
        if j >= bytes.len() {
            return Err(format!("unterminated tag at byte {i}"));
        }
        let inner: &str = &doc[i + 1..j];
        check_entities(inner, i)?;
        if let Some(name) = inner.strip_prefix('/') {
            let name: String = name.trim().to_ascii_lowercase();
            match stack.pop() {
                Some((open, _)) if open == name => {}
                Some((open, at)) => {
                    return Err(format!("</{name}> at byte {i} closes <{open}> opened at byte {at}"));
                }
                None => return Err(format!("</{name}> at byte {i} without a start tag")),
            }
        } else {
            let self_closing: bool = inner.ends_with('/');
            let body: &str = inner.trim_end_matches('/');
            let name: String = body.split_whitespace().next().unwrap_or("").to_ascii_lowercase();
            if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-') {
                return Err(format!("bad tag name {name:?} at byte {i}"));
            }
            *out.elements.entry(name.clone()).or_insert(0) += 1;
            out.start_tags.push(body.trim().to_string());
            if !self_closing && !VOID.contains(&name.as_str()) {
                if name == "style" || name == "script" {
                    // Raw text element: skip to its end tag.
                    let close: String = format!("</{name}>");
                    let end: usize = doc[j..].find(&close).ok_or(format!("<{name}> never closed"))? + j;
                    i = end + close.len();
                    continue;
                }
                stack.push((name, i));
            }
        }
        i = j + 1;
    }
    if let Some((open, at)) = stack.pop() {
        return Err(format!("<{open}> opened at byte {at} is never closed"));
    }
    if !seen_doctype {
        return Err("no <!DOCTYPE html>".to_string());
    }
    Ok(out)
}

/// No external resource: the only URL allowed is the SVG namespace in `xmlns`; no script, no `src`,
/// no `url(...)`, no `@import`, no `<link>`.
fn check_self_contained(doc: &str) -> Result<(), String> {
    let allowed: &str = "xmlns=\"http://www.w3.org/2000/svg\"";
    for scheme in ["http://", "https://"] {
        for (i, _) in doc.match_indices(scheme) {
            let start: usize = i.saturating_sub("xmlns=\"".len());
            if !doc[start..].starts_with(allowed) {
                return Err(format!("external reference at byte {i}: {:?}", &doc[start..(i + 40).min(doc.len())]));
            }
        }
    }
    let lower: String = doc.to_ascii_lowercase();
    for forbidden in ["<script", " src=", "url(", "@import", "<link", "<iframe", "<img"] {
        if lower.contains(forbidden) {
            return Err(format!("found {forbidden:?}"));
        }
    }
    Ok(())
}

#[test]
fn checker_rejects_broken_markup() {
    // The checker must be able to fail, or the tests built on it prove nothing.
    let ok: &str = "<!DOCTYPE html>\n<html><body><p>a &amp; b</p><svg><g><line/></g></svg></body></html>";
    assert!(check_markup(ok).is_ok(), "{:?}", check_markup(ok).err());
    let broken: [&str; 8] = [
        "<!DOCTYPE html><html><body><svg><g></svg></body></html>", // unclosed <g>
        "<!DOCTYPE html><html><body><p>a</body></html>",           // unclosed <p>
        "<!DOCTYPE html><html><body><p>a & b</p></body></html>",   // bare &
        "<!DOCTYPE html><html><body><p>a > b</p></body></html>",   // raw >
        "<!DOCTYPE html><html><body><p title=\"<\">a</p></body></html>", // < in attribute
        "<html><body></body></html>",                              // no doctype
        "<!DOCTYPE html><html><body></body></html></p>",           // stray end tag
        "<!DOCTYPE html><html><body><svg></body></html>",          // unclosed svg
    ];
    for doc in broken {
        assert!(check_markup(doc).is_err(), "checker accepted {doc:?}");
    }
    assert!(check_self_contained("<svg xmlns=\"http://www.w3.org/2000/svg\"></svg>").is_ok());
    assert!(check_self_contained("<a href=\"https://example.org\">x</a>").is_err());
    assert!(check_self_contained("<p style=\"background: url(x.png)\">").is_err());
}

// ---------------------------------------------------------------------------------------------------
// Sample data
// ---------------------------------------------------------------------------------------------------

fn series(label: &str, x: Vec<f64>, y: Vec<f64>, style: SeriesStyle) -> Series {
    Series { label: label.to_string(), x, y, style }
}

fn figure(title: &str, kind: FigureKind, series: Vec<Series>) -> Figure {
    Figure {
        title: title.to_string(),
        x_label: "position".to_string(),
        x_unit: "mm".to_string(),
        y_label: "EXX".to_string(),
        y_unit: "µm".to_string(),
        series,
        kind,
        log_x: false,
        log_y: false,
    }
}

fn strings(cells: &[&str]) -> Vec<String> {
    cells.iter().map(|s| s.to_string()).collect()
}

/// Two sections, three figures (line+dashed, log-log scatter, bar), two tables.
fn sample_report() -> Report {
    let x: Vec<f64> = (0..=40).map(|i| i as f64 * 10.0).collect();
    let truth: Vec<f64> = x.iter().map(|&p| 0.01 * p + (p / 50.0).sin()).collect();
    let estimate: Vec<f64> = truth.iter().map(|&e| e + 0.05).collect();
    let f: Vec<f64> = (0..30).map(|i| 10f64.powf(-1.0 + 0.1 * i as f64)).collect();
    let psd: Vec<f64> = f.iter().map(|&v| 1e-3 / (1.0 + v * v)).collect();
    let mut log_fig: Figure =
        figure("Spectrum", FigureKind::Scatter, vec![series("measured", f, psd, SeriesStyle::Line)]);
    log_fig.log_x = true;
    log_fig.log_y = true;
    Report {
        title: "vmt run".to_string(),
        subtitle: "default scenario".to_string(),
        sections: vec![
            Section {
                heading: "Summary".to_string(),
                text: strings(&["First paragraph.", "Second paragraph."]),
                figures: vec![],
                tables: vec![
                    Table {
                        caption: "Errors".to_string(),
                        header: strings(&["error", "injected", "recovered", "pass"]),
                        rows: vec![
                            strings(&["EXX", "1.0", "1.02", "yes"]),
                            strings(&["EYX", "0.5", "0.9", "no"]),
                            strings(&["EZX", "0.2", "0.21", "yes"]),
                        ],
                        highlight: vec![RowStatus::Pass, RowStatus::Fail, RowStatus::Pass],
                    },
                    Table {
                        caption: "Settings".to_string(),
                        header: strings(&["key", "value"]),
                        rows: vec![strings(&["seed", "7"])],
                        highlight: vec![],
                    },
                ],
            },
            Section {
                heading: "Profiles".to_string(),
                text: strings(&["Dashed is the truth."]),
                figures: vec![
                    figure(
                        "EXX",
                        FigureKind::Line,
                        vec![
                            series("injected", x.clone(), truth, SeriesStyle::Dashed),
                            series("recovered", x, estimate, SeriesStyle::Line),
                        ],
                    ),
                    log_fig,
                    figure(
                        "RMS",
                        FigureKind::Bar,
                        vec![
                            series("injected", vec![1.0, 2.0, 3.0], vec![1.0, 0.5, 0.2], SeriesStyle::Line),
                            series("recovered", vec![1.0, 2.0, 3.0], vec![1.02, 0.9, 0.21], SeriesStyle::Line),
                        ],
                    ),
                ],
                tables: vec![],
            },
        ],
    }
}

// ---------------------------------------------------------------------------------------------------
// Report-level tests
// ---------------------------------------------------------------------------------------------------

#[test]
fn sample_report_is_well_formed_and_self_contained() {
    let report: Report = sample_report();
    let html: String = render_html(&report).expect("valid report renders");
    let checked: Checked = check_markup(&html).unwrap_or_else(|e| panic!("malformed HTML: {e}"));
    check_self_contained(&html).unwrap_or_else(|e| panic!("not self-contained: {e}"));
    for once in ["html", "head", "body", "title", "style", "main", "nav"] {
        assert_eq!(checked.count(once), 1, "<{once}> count");
    }
    let n_figures: usize = report.sections.iter().map(|s| s.figures.len()).sum();
    let n_tables: usize = report.sections.iter().map(|s| s.tables.len()).sum();
    assert_eq!(n_figures, 3);
    assert_eq!(checked.count("svg"), n_figures, "one inline <svg> per Figure");
    assert_eq!(checked.count("figure"), n_figures);
    assert_eq!(checked.count("figcaption"), n_figures);
    assert_eq!(checked.count("table"), n_tables);
    assert_eq!(checked.count("section"), report.sections.len());
    // Pass/fail rows: 2 pass, 1 fail in the first table, neutral rows have no class.
    let pass: usize = checked.start_tags.iter().filter(|t| t.as_str() == "tr class=\"pass\"").count();
    let fail: usize = checked.start_tags.iter().filter(|t| t.as_str() == "tr class=\"fail\"").count();
    assert_eq!((pass, fail), (2, 1));
    // Table of contents: one link per section, each to an existing id.
    for k in 1..=report.sections.len() {
        assert!(html.contains(&format!("<a href=\"#sec-{k}\">")), "toc link {k}");
        assert!(html.contains(&format!("<section id=\"sec-{k}\">")), "section id {k}");
    }
    // Figures and tables are numbered through the report.
    for k in 1..=n_figures {
        assert!(html.contains(&format!("<figcaption>Figure {k}. ")), "figure {k}");
    }
    for k in 1..=n_tables {
        assert!(html.contains(&format!("<caption>Table {k}. ")), "table {k}");
    }
    // Paragraphs present in order.
    let p1: usize = html.find("<p>First paragraph.</p>").expect("paragraph 1");
    let p2: usize = html.find("<p>Second paragraph.</p>").expect("paragraph 2");
    assert!(p1 < p2);
}

#[test]
fn user_text_is_escaped_everywhere() {
    let nasty: &str = "<script>alert('x')</script> & <b>bold</b> \"q\"";
    let mut report: Report = sample_report();
    report.title = nasty.to_string();
    report.subtitle = nasty.to_string();
    report.sections[0].heading = nasty.to_string();
    report.sections[0].text.push(nasty.to_string());
    report.sections[0].tables[0].caption = nasty.to_string();
    report.sections[0].tables[0].header[0] = nasty.to_string();
    report.sections[0].tables[0].rows[0][0] = nasty.to_string();
    let fig: &mut Figure = &mut report.sections[1].figures[0];
    fig.title = nasty.to_string();
    fig.x_label = nasty.to_string();
    fig.series[0].label = nasty.to_string();
    let html: String = render_html(&report).expect("renders");
    check_markup(&html).unwrap_or_else(|e| panic!("malformed HTML: {e}"));
    check_self_contained(&html).unwrap_or_else(|e| panic!("not self-contained: {e}"));
    assert!(!html.contains("<script"), "raw <script> leaked");
    assert!(!html.contains("<b>"), "raw <b> leaked");
    // Title (twice: <title> and <h1>), subtitle, toc + heading, paragraph, caption, header, cell,
    // figure caption and aria-label: the HTML escape form appears at least 10 times.
    let escaped: &str = "&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; &amp; &lt;b&gt;bold&lt;/b&gt; &quot;q&quot;";
    assert!(html.matches(escaped).count() >= 10, "escaped count {}", html.matches(escaped).count());
    // Inside the SVG, plotters escapes the axis title and legend label (with &apos;).
    assert!(html.contains("&lt;script&gt;alert(&apos;x&apos;)"), "SVG text escaped");
}

#[test]
fn report_round_trips_through_json() {
    let report: Report = sample_report();
    let json: String = serde_json::to_string(&report).expect("serialise");
    let back: Report = serde_json::from_str(&json).expect("deserialise");
    assert_eq!(back, report);
    assert!(json.contains("\"kind\":\"scatter\"") && json.contains("\"highlight\":[\"pass\",\"fail\",\"pass\"]"));
}

#[test]
fn invalid_tables_and_figures_are_errors_naming_them() {
    let mut ragged: Report = sample_report();
    ragged.sections[0].tables[1].rows.push(strings(&["only one cell"]));
    match render_html(&ragged) {
        Err(ReportError::RaggedTable { caption, row, got, expected }) => {
            assert_eq!((caption.as_str(), row, got, expected), ("Settings", 1, 1, 2));
        }
        other => panic!("expected RaggedTable, got {other:?}"),
    }
    let mut highlight: Report = sample_report();
    highlight.sections[0].tables[0].highlight.pop();
    assert!(matches!(render_html(&highlight), Err(ReportError::HighlightMismatch { got: 2, rows: 3, .. })));
    let mut nan: Report = sample_report();
    nan.sections[1].figures[0].series[1].y[4] = f64::NAN;
    let err: ReportError = render_html(&nan).expect_err("NaN rejected");
    let message: String = err.to_string();
    assert!(message.contains("figure \"EXX\"") && message.contains("y[4] = NaN"), "{message}");
}

#[test]
fn empty_report_is_still_a_page() {
    let report: Report = Report { title: String::new(), subtitle: String::new(), sections: vec![] };
    let html: String = render_html(&report).expect("renders");
    let checked: Checked = check_markup(&html).unwrap_or_else(|e| panic!("malformed HTML: {e}"));
    assert_eq!(checked.count("html"), 1);
    assert_eq!(checked.count("svg"), 0);
    assert_eq!(checked.count("nav"), 0, "no table of contents without sections");
}

#[test]
fn write_atomic_replaces_file_and_leaves_no_temporary() {
    let dir: std::path::PathBuf = std::env::temp_dir().join(format!("vmt-report-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path: std::path::PathBuf = dir.join("report.html");
    write_atomic(&path, "first").expect("write 1");
    assert_eq!(std::fs::read_to_string(&path).expect("read"), "first");
    write_atomic(&path, "second, longer").expect("write 2");
    assert_eq!(std::fs::read_to_string(&path).expect("read"), "second, longer");
    let names: Vec<String> = std::fs::read_dir(&dir)
        .expect("list")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into())
        .collect();
    assert_eq!(names, vec!["report.html".to_string()], "temporary file left behind");
    // A missing directory is an error naming the path, not a panic.
    let missing: std::path::PathBuf = dir.join("no/such/dir/report.html");
    match write_atomic(&missing, "x") {
        Err(ReportError::Io { path, .. }) => assert!(path.ends_with("report.html")),
        other => panic!("expected Io error, got {other:?}"),
    }
    std::fs::remove_dir_all(&dir).expect("clean up");
}

// ---------------------------------------------------------------------------------------------------
// Figure-level tests
// ---------------------------------------------------------------------------------------------------

/// `points="x,y x,y ..."` of every polyline with the given stroke colour.
fn polylines(svg: &str, colour: &str) -> Vec<Vec<(i32, i32)>> {
    let mut out: Vec<Vec<(i32, i32)>> = Vec::new();
    for tag in svg.split("<polyline").skip(1) {
        let tag: &str = &tag[..tag.find('>').unwrap_or(tag.len())];
        if !tag.to_ascii_lowercase().contains(&format!("stroke=\"{}\"", colour.to_ascii_lowercase())) {
            continue;
        }
        let points: &str = tag.split("points=\"").nth(1).and_then(|p| p.split('"').next()).unwrap_or("");
        let parsed: Vec<(i32, i32)> = points
            .split_whitespace()
            .map(|pair| {
                let (a, b) = pair.split_once(',').expect("x,y");
                (a.parse().expect("x"), b.parse().expect("y"))
            })
            .collect();
        out.push(parsed);
    }
    out
}

fn texts(svg: &str) -> Vec<String> {
    check_markup(&format!("<!DOCTYPE html>{svg}")).expect("well-formed SVG").texts
}

#[test]
fn line_figure_draws_every_point_in_order_with_labels() {
    let n: usize = 50;
    let x: Vec<f64> = (0..n).map(|i| i as f64).collect();
    let fig: Figure =
        figure("ramp", FigureKind::Line, vec![series("ramp series", x.clone(), x.clone(), SeriesStyle::Line)]);
    let svg: String = figure_svg(&fig, 640, 400).expect("renders");
    let lines: Vec<Vec<(i32, i32)>> = polylines(&svg, PALETTE_HEX[0]);
    // One polyline for the data (50 points) and one 2-point legend sample.
    let data: &Vec<(i32, i32)> = lines.iter().find(|l| l.len() == n).expect("a 50-point polyline");
    // y = x rises: pixel x increases and pixel y decreases (SVG y points down) along the line.
    assert!(data.windows(2).all(|w| w[1].0 > w[0].0 && w[1].1 < w[0].1), "{data:?}");
    // Everything within the 640 x 400 canvas.
    assert!(data.iter().all(|&(px, py)| (0..640).contains(&px) && (0..400).contains(&py)));
    let t: Vec<String> = texts(&svg);
    for expected in ["ramp", "position / mm", "EXX / µm", "ramp series", "0", "40"] {
        assert!(t.iter().any(|s| s == expected), "missing text {expected:?} in {t:?}");
    }
}

#[test]
fn scatter_draws_one_marker_per_point_and_dashed_draws_segments() {
    let x: Vec<f64> = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
    let y: Vec<f64> = vec![3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0];
    let fig: Figure =
        figure("scatter", FigureKind::Scatter, vec![series("pts", x.clone(), y.clone(), SeriesStyle::Line)]);
    let svg: String = figure_svg(&fig, 640, 400).expect("renders");
    // 7 data markers + 1 legend marker.
    assert_eq!(svg.matches("<circle").count(), x.len() + 1);
    let dashed: Figure = figure("dashed", FigureKind::Line, vec![series("d", x, y, SeriesStyle::Dashed)]);
    let svg: String = figure_svg(&dashed, 640, 400).expect("renders");
    let segments: usize = polylines(&svg, PALETTE_HEX[0]).len();
    // A dashed polyline over 6 segments spanning ~550 px with 8+5 px dashes gives dozens of dashes.
    assert!(segments > 20, "only {segments} dash segments");
}

#[test]
fn eight_series_get_eight_distinct_colours() {
    let all: Vec<Series> = (0..8)
        .map(|k| series(&format!("s{k}"), vec![0.0, 1.0], vec![k as f64, k as f64 + 1.0], SeriesStyle::Line))
        .collect();
    let svg: String = figure_svg(&figure("eight", FigureKind::Line, all), 800, 500).expect("renders");
    let mut distinct: Vec<&str> = PALETTE_HEX.to_vec();
    distinct.sort();
    distinct.dedup();
    assert_eq!(distinct.len(), 8);
    for hex in PALETTE_HEX {
        // Data line + legend sample per colour.
        assert_eq!(polylines(&svg, hex).len(), 2, "colour {hex}");
    }
}

#[test]
fn constant_single_and_empty_series_do_not_panic() {
    // Constant y = 5: axis padded to 4.5 … 5.5 and the value is labelled.
    let constant: Figure = figure(
        "constant",
        FigureKind::Line,
        vec![series("c", vec![0.0, 1.0, 2.0], vec![5.0, 5.0, 5.0], SeriesStyle::Line)],
    );
    let svg: String = figure_svg(&constant, 640, 400).expect("constant renders");
    assert!(texts(&svg).iter().any(|s| s == "5"), "tick at 5 expected");
    // A single point (constant x and y) is drawn as a marker.
    let single: Figure = figure("one", FigureKind::Line, vec![series("p", vec![3.0], vec![-2.0], SeriesStyle::Line)]);
    let svg: String = figure_svg(&single, 640, 400).expect("single point renders");
    assert_eq!(svg.matches("<circle").count(), 2, "one marker + legend marker");
    // All-zero constant.
    let zeros: Figure =
        figure("zeros", FigureKind::Bar, vec![series("z", vec![0.0, 0.0], vec![0.0, 0.0], SeriesStyle::Line)]);
    figure_svg(&zeros, 640, 400).expect("zeros render");
    // Empty series and no series: an empty frame that says so.
    for fig in [
        figure("empty", FigureKind::Line, vec![series("e", vec![], vec![], SeriesStyle::Line)]),
        figure("none", FigureKind::Scatter, vec![]),
        figure("empty bars", FigureKind::Bar, vec![series("e", vec![], vec![], SeriesStyle::Line)]),
    ] {
        let svg: String = figure_svg(&fig, 640, 400).expect("empty renders");
        assert!(texts(&svg).iter().any(|s| s == "no data"), "{}: no 'no data' message", fig.title);
    }
    let mut empty_log: Figure = figure("empty log", FigureKind::Line, vec![]);
    empty_log.log_x = true;
    empty_log.log_y = true;
    assert!(texts(&figure_svg(&empty_log, 640, 400).expect("renders")).iter().any(|s| s == "no data"));
    // One empty series beside a real one: no message.
    let mixed: Figure = figure(
        "mixed",
        FigureKind::Line,
        vec![
            series("e", vec![], vec![], SeriesStyle::Line),
            series("r", vec![0.0, 1.0], vec![0.0, 1.0], SeriesStyle::Line),
        ],
    );
    assert!(!figure_svg(&mixed, 640, 400).expect("renders").contains("no data"));
}

#[test]
fn log_axes_label_decades_and_reject_non_positive_values() {
    let mut fig: Figure = figure(
        "log",
        FigureKind::Line,
        vec![series("psd", vec![0.05, 1.0, 300.0], vec![2e-6, 3e-4, 0.5], SeriesStyle::Line)],
    );
    fig.log_x = true;
    fig.log_y = true;
    let svg: String = figure_svg(&fig, 800, 500).expect("log-log renders");
    let t: Vec<String> = texts(&svg);
    // x spans the decades 0.01 … 1000, y 1e-6 … 1: every decade is a labelled tick.
    for label in ["0.01", "0.1", "1", "10", "100", "1000", "1e-6", "1e-5", "1e-4", "0.001"] {
        assert!(t.iter().any(|s| s == label), "missing log tick {label:?} in {t:?}");
    }
    // Zero on a log y axis: a clear error, index and value given.
    let mut zero: Figure = fig.clone();
    zero.series[0].y[2] = 0.0;
    let err: ReportError = figure_svg(&zero, 800, 500).expect_err("0 on log axis");
    assert!(matches!(err, ReportError::NonPositiveOnLogAxis { axis: "y", index: 2, .. }));
    let message: String = err.to_string();
    assert!(message.contains("logarithmic") && message.contains("y[2] = 0"), "{message}");
    // Negative on a log x axis.
    let mut negative: Figure = fig.clone();
    negative.series[0].x[0] = -1.0;
    assert!(matches!(
        figure_svg(&negative, 800, 500),
        Err(ReportError::NonPositiveOnLogAxis { axis: "x", index: 0, value, .. }) if value == -1.0
    ));
    // The same negative value on a linear axis is fine.
    negative.log_x = false;
    figure_svg(&negative, 800, 500).expect("negative x on a linear axis");
}

#[test]
fn bad_data_and_sizes_are_errors_not_panics() {
    let mut fig: Figure =
        figure("bad", FigureKind::Line, vec![series("s", vec![0.0, 1.0, 2.0], vec![0.0, 1.0], SeriesStyle::Line)]);
    assert!(matches!(figure_svg(&fig, 640, 400), Err(ReportError::LengthMismatch { x_len: 3, y_len: 2, .. })));
    fig.series[0].y.push(f64::INFINITY);
    assert!(matches!(
        figure_svg(&fig, 640, 400),
        Err(ReportError::NonFinite { axis: "y", index: 2, value, .. }) if value == f64::INFINITY
    ));
    fig.series[0].y[2] = 2.0;
    fig.series[0].x[0] = f64::NAN;
    assert!(matches!(figure_svg(&fig, 640, 400), Err(ReportError::NonFinite { axis: "x", index: 0, .. })));
    fig.series[0].x[0] = 0.0;
    figure_svg(&fig, 640, 400).expect("repaired figure renders");
    assert!(matches!(figure_svg(&fig, 10, 400), Err(ReportError::BadSize { width: 10, height: 400 })));
    assert!(matches!(figure_svg(&fig, 640, 0), Err(ReportError::BadSize { .. })));
}

#[test]
fn bars_start_at_zero_and_are_grouped() {
    let fig: Figure = figure(
        "bars",
        FigureKind::Bar,
        vec![
            series("a", vec![1.0, 2.0, 3.0], vec![1.0, 2.0, 3.0], SeriesStyle::Line),
            series("b", vec![1.0, 2.0, 3.0], vec![-1.0, 0.5, 1.5], SeriesStyle::Line),
        ],
    );
    let svg: String = figure_svg(&fig, 640, 400).expect("renders");
    // 6 bars + 2 legend swatches, in the two series colours.
    let rects: Vec<&str> = svg.split("<rect").skip(1).collect();
    let coloured =
        |hex: &str| rects.iter().filter(|r| r.to_ascii_lowercase().contains(&format!("fill=\"{hex}\""))).count();
    assert_eq!(coloured(PALETTE_HEX[0]), 4);
    assert_eq!(coloured(PALETTE_HEX[1]), 4);
    // The negative bar makes the axis include −1, and 0 is a labelled tick (the baseline).
    let t: Vec<String> = texts(&svg);
    assert!(t.iter().any(|s| s == "0") && t.iter().any(|s| s == "-1"), "{t:?}");
}
