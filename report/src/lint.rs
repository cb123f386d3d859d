//! Checks that a report is readable as a metrologist expects (issue 16): every figure names both axes
//! with their units, every table column whose cells are bare numbers names its unit in the header, and no
//! section, table or figure is empty. [`lint`] lists every problem; an empty list means the report passes.

use crate::{Figure, Report, Table, DIMENSIONLESS};

/// Every readability problem of `report`, each naming the section and the figure or table. Rules:
/// - a section holds at least one non-blank paragraph, figure or table;
/// - a figure has an x and a y label and an x and a y unit (write [`DIMENSIONLESS`] for a ratio or
///   index), and at least one series with data;
/// - a table has at least one row; a column in which any cell is a bare number (no unit after it) has
///   a header naming the unit: `quantity / unit`, `quantity (unit)` or `quantity [unit]`.
pub fn lint(report: &Report) -> Vec<String> {
    let mut problems: Vec<String> = Vec::new();
    for (i, section) in report.sections.iter().enumerate() {
        let place: String = format!("section {} \"{}\"", i + 1, section.heading);
        let has_text: bool = section.text.iter().any(|t| !t.trim().is_empty());
        if !has_text && section.figures.is_empty() && section.tables.is_empty() {
            problems.push(format!("{place} is empty (no text, figure or table)"));
        }
        for figure in &section.figures {
            lint_figure(&place, figure, &mut problems);
        }
        for table in &section.tables {
            lint_table(&place, table, &mut problems);
        }
    }
    problems
}

fn lint_figure(place: &str, figure: &Figure, problems: &mut Vec<String>) {
    let name: String = format!("{place}, figure \"{}\"", figure.title);
    for (axis, label, unit) in [("x", &figure.x_label, &figure.x_unit), ("y", &figure.y_label, &figure.y_unit)] {
        if label.trim().is_empty() {
            problems.push(format!("{name}: the {axis} axis has no label"));
        }
        if unit.trim().is_empty() {
            problems.push(format!(
                "{name}: the {axis} axis \"{label}\" names no unit (use \"{DIMENSIONLESS}\" for a ratio)"
            ));
        }
    }
    if figure.series.iter().all(|s| s.x.is_empty()) {
        problems.push(format!("{name} has no data"));
    }
}

fn lint_table(place: &str, table: &Table, problems: &mut Vec<String>) {
    let name: String = format!("{place}, table \"{}\"", table.caption);
    if table.rows.is_empty() {
        problems.push(format!("{name} has no rows"));
    }
    for (c, heading) in table.header.iter().enumerate() {
        let bare: bool = table.rows.iter().any(|row| row.get(c).is_some_and(|cell| cell.trim().parse::<f64>().is_ok()));
        if bare && !names_unit(heading) {
            problems.push(format!(
                "{name}: column \"{heading}\" holds bare numbers but its header names no unit (write \"{heading} / unit\")"
            ));
        }
    }
}

/// True when a column header names a unit: `quantity / unit`, `quantity (unit)` or `quantity [unit]`.
fn names_unit(heading: &str) -> bool {
    heading.contains(" / ")
        || (heading.contains('(') && heading.ends_with(')'))
        || (heading.contains('[') && heading.ends_with(']'))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{FigureKind, Section, Series, SeriesStyle};

    fn report(figure: Figure, table: Table) -> Report {
        Report {
            title: "t".into(),
            subtitle: String::new(),
            sections: vec![
                Section { heading: "a".into(), text: vec![], figures: vec![figure], tables: vec![table] },
                Section { heading: "b".into(), text: vec![" ".into()], figures: vec![], tables: vec![] },
            ],
        }
    }

    #[test]
    fn finds_each_kind_of_problem_and_passes_a_good_report() {
        let series = Series { label: "s".into(), x: vec![1.0], y: vec![2.0], style: SeriesStyle::Line };
        let good_fig = Figure {
            title: "f".into(),
            x_label: "position".into(),
            x_unit: "mm".into(),
            y_label: "SSI".into(),
            y_unit: DIMENSIONLESS.into(),
            series: vec![series],
            kind: FigureKind::Line,
            log_x: false,
            log_y: false,
        };
        let good_table = Table {
            caption: "c".into(),
            header: vec!["error".into(), "E / µm".into(), "value".into(), "runs (count)".into()],
            rows: vec![vec!["EXX".into(), "1.5".into(), "2.0 µm".into(), "5".into()]],
            highlight: vec![],
        };
        let mut ok = report(good_fig.clone(), good_table.clone());
        ok.sections[1].text = vec!["text".into()];
        assert_eq!(lint(&ok), Vec::<String>::new());

        let mut bad_fig = good_fig;
        bad_fig.y_unit = String::new();
        let mut bad_table = good_table;
        bad_table.header[1] = "E".into();
        let problems = lint(&report(bad_fig, bad_table));
        assert_eq!(problems.len(), 3, "{problems:#?}");
        assert!(problems[0].contains("y axis \"SSI\" names no unit"));
        assert!(problems[1].contains("column \"E\""));
        assert!(problems[2].contains("section 2 \"b\" is empty"));
    }
}
