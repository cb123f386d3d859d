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
