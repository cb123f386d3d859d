//! [`Report`] → one self-contained HTML5 page.

use crate::figure::render_svg;
use crate::{Figure, Report, ReportError, RowStatus, Table};
use std::fmt::Write as _;

/// Width and height in pixels of the SVG figures in the HTML page (CSS scales them down on narrow
/// screens and in print, keeping the aspect ratio through the SVG viewBox).
const FIGURE_SIZE: (u32, u32) = (860, 480);

/// Inline style sheet: readable on screen, printable (no page break inside figures and tables, row
/// colours kept in print), no external fonts.
const CSS: &str = r#"
:root { --fg: #1d2330; --muted: #5b6474; --rule: #d8dce3; --pass: #e2f3e5; --pass-edge: #2e7d32;
  --fail: #fbe3e3; --fail-edge: #c62828; }
* { box-sizing: border-box; }
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif;
  color: var(--fg); background: #fff; line-height: 1.5; max-width: 60rem; margin: 0 auto;
  padding: 1.5rem 1.25rem 3rem; }
header { border-bottom: 2px solid var(--fg); margin-bottom: 1rem; }
h1 { font-size: 1.8rem; margin: 0 0 .2rem; }
.subtitle { color: var(--muted); margin: 0 0 .75rem; }
nav.toc { background: #f5f7fa; border: 1px solid var(--rule); border-radius: 6px; padding: .5rem 1rem;
  margin: 1rem 0 2rem; }
nav.toc h2 { font-size: 1rem; margin: .25rem 0; border: 0; }
nav.toc ol { margin: .25rem 0; padding-left: 1.5rem; }
a { color: #0b5cad; }
section { margin-bottom: 2.5rem; }
h2 { font-size: 1.35rem; border-bottom: 1px solid var(--rule); padding-bottom: .2rem; margin-top: 2rem; }
figure { margin: 1.25rem 0; text-align: center; }
svg.plot { max-width: 100%; height: auto; border: 1px solid var(--rule); }
figcaption { font-size: .92rem; color: var(--muted); margin-top: .35rem; }
table { border-collapse: collapse; margin: 1.25rem 0; font-size: .9rem; width: 100%; }
caption { caption-side: top; text-align: left; font-weight: 600; padding-bottom: .35rem; }
th, td { border: 1px solid var(--rule); padding: .3rem .55rem; text-align: left; vertical-align: top; }
th { background: #eef1f5; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
tr.pass td { background: var(--pass); }
tr.pass td:first-child { box-shadow: inset 4px 0 0 var(--pass-edge); }
tr.fail td { background: var(--fail); }
tr.fail td:first-child { box-shadow: inset 4px 0 0 var(--fail-edge); }
.status-note { font-size: .8rem; color: var(--muted); margin-top: -.9rem; }
footer { color: var(--muted); font-size: .8rem; border-top: 1px solid var(--rule); padding-top: .5rem; margin-top: 3rem; }
@media print {
  body { max-width: none; padding: 0; }
  nav.toc { break-after: avoid; }
  figure, table, tr { break-inside: avoid; }
  * { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
  a { color: inherit; text-decoration: none; }
}
"#;

/// Escapes text for HTML element content and quoted attribute values (HTML5 §13.1): `&` → `&amp;`,
/// `<` → `&lt;`, `>` → `&gt;`, `"` → `&quot;`, `'` → `&#39;`. Everything else is kept as is.
pub fn escape_html(text: &str) -> String {
    let mut out: String = String::with_capacity(text.len() + text.len() / 8);
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            other => out.push(other),
        }
    }
    out
}

/// Renders `report` as one self-contained HTML5 page (UTF-8): inline CSS, a table of contents linking
/// to each numbered section, each section's paragraphs, tables (pass rows green, fail rows red) and
/// figures (inline `<svg>` from [`crate::figure_svg`], 860 × 480 px scaled to the page width). All user
/// text is escaped with [`escape_html`]; the page has no scripts and references no external resource.
/// Figures and tables are numbered through the whole report.
///
/// Errors: the first invalid figure ([`crate::figure_svg`]'s errors) or table (row length differs from
/// the header, `highlight` neither empty nor one per row), naming it.
pub fn render_html(report: &Report) -> Result<String, ReportError> {
    let mut out: String = String::with_capacity(64 * 1024);
    out.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    out.push_str("<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n");
    out.push_str("<meta name=\"generator\" content=\"vmt-report\">\n");
    let _ = writeln!(out, "<title>{}</title>", escape_html(&report.title));
    let _ = writeln!(out, "<style>{CSS}</style>\n</head>\n<body>");

    out.push_str("<header>\n");
    let _ = writeln!(out, "<h1>{}</h1>", escape_html(&report.title));
    if !report.subtitle.trim().is_empty() {
        let _ = writeln!(out, "<p class=\"subtitle\">{}</p>", escape_html(&report.subtitle));
    }
    out.push_str("</header>\n");

    if !report.sections.is_empty() {
        out.push_str("<nav class=\"toc\" aria-label=\"Contents\">\n<h2>Contents</h2>\n<ol>\n");
        for (i, section) in report.sections.iter().enumerate() {
            let _ = writeln!(out, "<li><a href=\"#sec-{}\">{}</a></li>", i + 1, escape_html(&section.heading));
        }
        out.push_str("</ol>\n</nav>\n");
    }

    out.push_str("<main>\n");
    let mut figure_no: usize = 0;
    let mut table_no: usize = 0;
    for (i, section) in report.sections.iter().enumerate() {
        let _ = writeln!(out, "<section id=\"sec-{}\">", i + 1);
        let _ = writeln!(out, "<h2>{}. {}</h2>", i + 1, escape_html(&section.heading));
        for paragraph in &section.text {
            let _ = writeln!(out, "<p>{}</p>", escape_html(paragraph));
        }
        for table in &section.tables {
            table_no += 1;
            write_table(&mut out, table, table_no)?;
        }
        for figure in &section.figures {
            figure_no += 1;
            write_figure(&mut out, figure, figure_no)?;
        }
        out.push_str("</section>\n");
    }
    out.push_str("</main>\n");
    out.push_str("<footer>Generated by vmt. Self-contained page: figures are inline SVG, no scripts, no external resources.</footer>\n");
    out.push_str("</body>\n</html>\n");
    Ok(out)
}

fn write_figure(out: &mut String, figure: &Figure, number: usize) -> Result<(), ReportError> {
    let svg: String = render_svg(figure, FIGURE_SIZE.0, FIGURE_SIZE.1, false)?;
    let svg: String = match svg.strip_prefix("<svg ") {
        Some(rest) => {
            format!("<svg class=\"plot\" role=\"img\" aria-label=\"{}\" {}", escape_html(&figure.title), rest)
        }
        None => svg,
    };
    let _ = writeln!(out, "<figure id=\"fig-{number}\">");
    out.push_str(svg.trim_end());
    out.push('\n');
    let _ = writeln!(out, "<figcaption>Figure {number}. {}</figcaption>", escape_html(&figure.title));
    out.push_str("</figure>\n");
    Ok(())
}

fn write_table(out: &mut String, table: &Table, number: usize) -> Result<(), ReportError> {
    let columns: usize = table.header.len();
    for (row, cells) in table.rows.iter().enumerate() {
        if columns > 0 && cells.len() != columns {
            return Err(ReportError::RaggedTable {
                caption: table.caption.clone(),
                row,
                got: cells.len(),
                expected: columns,
            });
        }
    }
    if !table.highlight.is_empty() && table.highlight.len() != table.rows.len() {
        return Err(ReportError::HighlightMismatch {
            caption: table.caption.clone(),
            got: table.highlight.len(),
            rows: table.rows.len(),
        });
    }
    let _ = writeln!(out, "<table id=\"tab-{number}\">");
    let _ = writeln!(out, "<caption>Table {number}. {}</caption>", escape_html(&table.caption));
    if columns > 0 {
        out.push_str("<thead><tr>");
        for heading in &table.header {
            let _ = write!(out, "<th scope=\"col\">{}</th>", escape_html(heading));
        }
        out.push_str("</tr></thead>\n");
    }
    out.push_str("<tbody>\n");
    for (row, cells) in table.rows.iter().enumerate() {
        let status: RowStatus = table.highlight.get(row).copied().unwrap_or_default();
        match status {
            RowStatus::Pass => out.push_str("<tr class=\"pass\">"),
            RowStatus::Fail => out.push_str("<tr class=\"fail\">"),
            RowStatus::Neutral => out.push_str("<tr>"),
        }
        for cell in cells {
            let numeric: bool = looks_numeric(cell);
            let _ = write!(out, "<td{}>{}</td>", if numeric { " class=\"num\"" } else { "" }, escape_html(cell));
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</tbody>\n</table>\n");
    if table.highlight.iter().any(|s| *s != RowStatus::Neutral) {
        out.push_str("<p class=\"status-note\">Green rows passed their check; red rows failed it.</p>\n");
    }
    Ok(())
}

/// True for cells such as "-1.5", "2e-6", "+3", "12.0 %" or "0.4 µm" (a number, optionally followed by
/// a short unit), which are right-aligned.
fn looks_numeric(cell: &str) -> bool {
    let trimmed: &str = cell.trim();
    let first: &str = trimmed.split_whitespace().next().unwrap_or("");
    let words: usize = trimmed.split_whitespace().count();
    !first.is_empty() && first.parse::<f64>().is_ok() && words <= 2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_hand_worked() {
        assert_eq!(escape_html(r#"a<b & "c" 'd'>"#), "a&lt;b &amp; &quot;c&quot; &#39;d&#39;&gt;");
        assert_eq!(escape_html("µm ±0.5"), "µm ±0.5");
    }

    #[test]
    fn numeric_cells() {
        assert!(looks_numeric("-1.5"));
        assert!(looks_numeric("2e-6"));
        assert!(looks_numeric("0.4 µm"));
        assert!(!looks_numeric("EXX"));
        assert!(!looks_numeric(""));
        assert!(!looks_numeric("3 of 4 passed"));
    }
}
