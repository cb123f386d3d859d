//! Compensation tables as controllers load them (docs/formats.md §7): a plain CSV, a SINUMERIK-style
//! leadscrew-error table (`$AA_ENC_COMP`) and a FANUC-style pitch-error table (parameters 3620–3624 with
//! incremental values). Writers and readers of plain data only; the table itself comes from
//! `vmt_estimators::compensation`.
//!
//! **Sign conventions.** vmt's table holds, at each node, the *deviation* it removes,
//! `c(x) = measured − target` (ISO 230-2's sign), which the simulated CNC adds to its position feedback
//! (`vmt_sim::machine::AxisModel::compensation`). Each format states its own sign in the file:
//! - CSV: `correction[um]` = c, the deviation (vmt's convention);
//! - SINUMERIK LEC: the value is c in mm — the control adds it to the actual position, so a positive
//!   value moves the axis in the negative direction (SINUMERIK function manual, leadscrew error
//!   compensation);
//! - FANUC pitch error: the value is the *correction* −c, added to the command, written incrementally
//!   (the change from the previous point, seen from the negative end) in integer units of
//!   0.1 µm × the magnification (parameter 3623), relative to the reference point (whose absolute
//!   deviation is a zero offset the table does not hold).

use crate::error::VmtError;
use crate::measurement::round_significant;
use std::path::Path;
use vmt_estimators::compensation::CompensationTable;

/// A compensation-table file format a controller loads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControllerFormat {
    /// `position[mm],correction[um]` with comment lines: any node spacing (seed 004's variable step).
    Csv,
    /// SINUMERIK-style leadscrew error compensation: `$AA_ENC_COMP[0,N,AXIS]` values (mm) at equidistant
    /// points `$AA_ENC_COMP_MIN + N·$AA_ENC_COMP_STEP`.
    Siemens,
    /// FANUC-style pitch error compensation: equidistant points (parameter 3624), incremental integer
    /// values in 0.1 µm × magnification (parameter 3623).
    Fanuc,
}

/// One FANUC-style value's largest magnitude, in units of 0.1 µm × magnification: a signed byte. Older
/// series accept only ±7 per point; check the controller's parameter manual.
pub const FANUC_MAX_INCREMENT: i64 = 127;
/// The largest FANUC-style magnification (parameter 3623) vmt writes.
pub const FANUC_MAX_MAGNIFICATION: i64 = 100;
/// FANUC-style value unit before magnification, m (0.1 µm: the detection unit of IS-C).
pub const FANUC_UNIT: f64 = 1e-7;
/// Node spacing quantum of the equidistant formats, m (0.1 µm, so the spacing is an exact decimal in mm).
pub const SPACING_QUANTUM: f64 = 1e-7;

impl ControllerFormat {
    /// Parses a `--format` value: `csv`, `siemens` or `fanuc` (another is a usage error).
    pub fn parse(s: &str) -> Result<Self, VmtError> {
        match s {
            "csv" => Ok(Self::Csv),
            "siemens" => Ok(Self::Siemens),
            "fanuc" => Ok(Self::Fanuc),
            other => Err(VmtError::Usage(format!("--format: expected `csv`, `siemens` or `fanuc`, got `{other}`"))),
        }
    }

    /// The format's name as `--format` spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Csv => "csv",
            Self::Siemens => "siemens",
            Self::Fanuc => "fanuc",
        }
    }

    /// Most points a table of this format may hold: 100 000 for the CSV (vmt's size budget), 5 000 for
    /// SINUMERIK (the largest `MM_ENC_COMP_MAX_POINTS`; small controls hold 200 — choose `--points`),
    /// 128 for FANUC (points between the two extremes of one axis).
    pub fn max_points(self) -> usize {
        match self {
            Self::Csv => 100_000,
            Self::Siemens => 5_000,
            Self::Fanuc => 128,
        }
    }

    /// Whether the format needs equidistant points.
    pub fn equidistant(self) -> bool {
        match self {
            Self::Csv => false,
            Self::Siemens | Self::Fanuc => true,
        }
    }

    /// One sentence on the sign of the values, as written into the file and printed.
    pub fn sign_convention(self) -> &'static str {
        match self {
            Self::Csv => {
                "correction = the deviation removed (measured - target), added to the position feedback \
                 (vmt's simulated CNC, SINUMERIK LEC); a controller adding it to the command needs -correction"
            }
            Self::Siemens => {
                "value = deviation (measured - target) in mm, added to the actual position: a positive value \
                 moves the axis in the negative direction (SINUMERIK leadscrew error compensation)"
            }
            Self::Fanuc => {
                "value = correction = -(measured - target), added to the command, incremental from the previous \
                 point (seen from the negative end), in units of 0.1 um x magnification (parameter 3623), \
                 relative to the reference point"
            }
        }
    }
}

/// Equidistant nodes from `lo` covering `[lo, hi]` with `n` points: the spacing (hi − lo)/(n − 1) rounded
/// up to [`SPACING_QUANTUM`], so every node is an exact decimal in mm and the last node reaches `hi`.
pub fn equidistant_nodes(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let quanta = (hi - lo) / (n.max(2) - 1) as f64 / SPACING_QUANTUM;
    // A whole number of quanta up to rounding noise (0.96 / 10 / 1e-7 = 960000.0000000001) stays as it is.
    let quanta = if (quanta - quanta.round()).abs() < 1e-6 { quanta.round() } else { quanta.ceil() };
    let step = quanta * SPACING_QUANTUM;
    (0..n).map(|k| round_significant(lo + k as f64 * step, 12)).collect()
}

/// Why a compensation table does not fit a controller format (the caller names the table's source).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TableFitError {
    /// More points than the format holds.
    #[error(
        "the table has {points} points; a {} table holds at most {} (choose fewer with --points)",
        .format.name(),
        .format.max_points()
    )]
    TooManyPoints {
        /// The format.
        format: ControllerFormat,
        /// Points in the table.
        points: usize,
    },
    /// An equidistant format and unequal spacing.
    #[error(
        "a {} table needs equidistant points; interval {interval} is {interval_mm} mm, the first {first_mm} mm",
        .format.name()
    )]
    NotEquidistant {
        /// The format.
        format: ControllerFormat,
        /// The interval (1-based) that differs from the first.
        interval: usize,
        /// Its length, mm (12 significant digits).
        interval_mm: f64,
        /// The first interval's length, mm (12 significant digits).
        first_mm: f64,
    },
    /// A FANUC increment beyond [`FANUC_MAX_INCREMENT`] even at the largest magnification.
    #[error(
        "a change of the correction between two points exceeds {} × 0.1 µm × {} (the largest \
         magnification): use more --points or another format",
        FANUC_MAX_INCREMENT,
        FANUC_MAX_MAGNIFICATION
    )]
    IncrementTooLarge,
}

/// A table's text in `format` (with comment lines naming its provenance `about` and its sign) and notes
/// for the user (a FANUC magnification above 1 coarsens the table's resolution), or why it does not fit
/// the format: too many points, unequal spacing, a FANUC increment beyond [`FANUC_MAX_INCREMENT`] even at
/// the largest magnification.
pub fn table_text(
    format: ControllerFormat,
    table: &CompensationTable,
    axis: &str,
    about: &str,
) -> Result<(String, Vec<String>), TableFitError> {
    let n = table.positions.len();
    if n > format.max_points() {
        return Err(TableFitError::TooManyPoints { format, points: n });
    }
    let r = |x: f64| round_significant(x, 12);
    let step = if n > 1 { table.positions[1] - table.positions[0] } else { 0.0 };
    if format.equidistant() {
        for k in 1..n {
            let d = table.positions[k] - table.positions[k - 1];
            if (d - step).abs() > 1e-9 * step.abs().max(1e-9) {
                return Err(TableFitError::NotEquidistant {
                    format,
                    interval: k,
                    interval_mm: r(d * 1e3),
                    first_mm: r(step * 1e3),
                });
            }
        }
    }
    let head = format!(
        "vmt compensation table ({} format, docs/formats.md §7), axis {axis}, {about}\nsign: {}\n",
        format.name(),
        format.sign_convention()
    );
    let comment = |prefix: &str| head.lines().map(|l| format!("{prefix} {l}\n")).collect::<String>();
    let mut s = String::new();
    let mut notes = Vec::new();
    match format {
        ControllerFormat::Csv => {
            s += &comment("#");
            s += "position[mm],correction[um]\n";
            for (p, c) in table.positions.iter().zip(&table.corrections) {
                s += &format!("{},{}\n", r(p * 1e3), r(c * 1e6));
            }
        }
        ControllerFormat::Siemens => {
            s += &comment(";");
            s += "CHANDATA(1)\n";
            for (k, c) in table.corrections.iter().enumerate() {
                s += &format!("$AA_ENC_COMP[0,{k},{axis}]={}\n", r(c * 1e3));
            }
            s += &format!("$AA_ENC_COMP_STEP[0,{axis}]={}\n", r(step * 1e3));
            s += &format!("$AA_ENC_COMP_MIN[0,{axis}]={}\n", r(table.positions[0] * 1e3));
            s += &format!("$AA_ENC_COMP_MAX[0,{axis}]={}\n", r(table.positions[n - 1] * 1e3));
            s += &format!("$AA_ENC_COMP_IS_MODULO[0,{axis}]=0\nM17\n");
        }
        ControllerFormat::Fanuc => {
            let (magnification, increments) = fanuc_increments(&table.corrections)?;
            if magnification > 1 {
                notes.push(format!(
                    "magnification {magnification} (parameter 3623): the FANUC table's resolution is {} µm, not 0.1 µm \
                     (a change between two points exceeds {FANUC_MAX_INCREMENT} units); more --points make it finer",
                    magnification as f64 * 0.1
                ));
            }
            s += &comment(";");
            s +=
                &format!("; axis {axis}: reference point 0 at the first point; the deviation there is a zero offset\n");
            s += "P3620=0 ; number of the reference point\n";
            s += "P3621=0 ; most negative point\n";
            s += &format!("P3622={} ; most positive point\n", n - 1);
            s += &format!("P3623={magnification} ; magnification\n");
            s += &format!("P3624={} ; interval, mm\n", r(step * 1e3));
            s += &format!(
                "REF={} ; machine position of the reference point, mm (vmt's key, not a parameter)\n",
                r(table.positions[0] * 1e3)
            );
            for (k, v) in increments.iter().enumerate() {
                s += &format!("N{k}={v}\n");
            }
        }
    }
    Ok((s, notes))
}

/// FANUC-style incremental values of deviations `c` (m): the correction −(c_k − c_0) rounded cumulatively
/// (no drift) to units of [`FANUC_UNIT`] × M, differenced; M the smallest magnification (1..=100) with
/// every |increment| ≤ [`FANUC_MAX_INCREMENT`]. Returns (M, increments).
fn fanuc_increments(c: &[f64]) -> Result<(i64, Vec<i64>), TableFitError> {
    for m in 1..=FANUC_MAX_MAGNIFICATION {
        let q = FANUC_UNIT * m as f64;
        let total: Vec<i64> = c.iter().map(|&ck| (-(ck - c[0]) / q).round() as i64).collect();
        let inc: Vec<i64> = (0..c.len()).map(|k| if k == 0 { 0 } else { total[k] - total[k - 1] }).collect();
        if inc.iter().all(|v| v.abs() <= FANUC_MAX_INCREMENT) {
            return Ok((m, inc));
        }
    }
    Err(TableFitError::IncrementTooLarge)
}

/// Reads a compensation table in any of the three formats (recognised by its content: `$AA_ENC_COMP`
/// lines; `P36…=` or `N<k>=` lines; else the CSV) as vmt's table: positions (m, increasing) and the
/// deviations they remove (m).
pub fn read_table(path: &Path) -> Result<CompensationTable, VmtError> {
    const MAX_BYTES: u64 = 64 << 20;
    let text = VmtError::read_bounded(path, MAX_BYTES, "a compensation table")?;
    let (x, c) = if text.contains("$AA_ENC_COMP") {
        read_siemens(path, &text)?
    } else if assignments(&text).any(|(_, k, _)| {
        k.starts_with("P36")
            || k.strip_prefix('N').is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
    }) {
        read_fanuc(path, &text)?
    } else {
        crate::measurement::read_value_table(path, "correction", crate::units::Dimension::Length)?
    };
    CompensationTable::new(x, c).map_err(|e| VmtError::bad(path, "", e.to_string()))
}

/// The `KEY=VALUE` lines of a controller file with their line numbers (comments after `;` removed, blank
/// lines and lines without `=` skipped).
fn assignments(text: &str) -> impl Iterator<Item = (usize, &str, &str)> {
    text.lines().enumerate().filter_map(|(i, l)| {
        let l = l.split(';').next().unwrap_or("").trim();
        l.split_once('=').map(|(k, v)| (i + 1, k.trim(), v.trim()))
    })
}

fn number(path: &Path, line: usize, key: &str, v: &str) -> Result<f64, VmtError> {
    v.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
        VmtError::bad(path, format!("line {line}, {key}"), format!("expected a finite number, got `{v}`"))
    })
}

/// Values `N0..N(n−1)` given once each, as many as the format allows.
fn dense(path: &Path, format: ControllerFormat, mut v: Vec<(usize, f64)>) -> Result<Vec<f64>, VmtError> {
    v.sort_by_key(|&(k, _)| k);
    for (i, &(k, _)) in v.iter().enumerate() {
        if k != i {
            return Err(VmtError::bad(
                path,
                "",
                format!(
                    "expected the points 0..{} once each, point {i} is {}",
                    v.len(),
                    if k > i { "missing" } else { "repeated" }
                ),
            ));
        }
    }
    if v.len() < 2 || v.len() > format.max_points() {
        return Err(VmtError::bad(
            path,
            "",
            format!("expected 2..={} points in a {} table, got {}", format.max_points(), format.name(), v.len()),
        ));
    }
    Ok(v.into_iter().map(|(_, x)| x).collect())
}

fn index(path: &Path, line: usize, key: &str, s: &str) -> Result<usize, VmtError> {
    s.trim().parse::<usize>().ok().filter(|&k| k < 1_000_000).ok_or_else(|| {
        VmtError::bad(path, format!("line {line}, {key}"), format!("expected a point number, got `{s}`"))
    })
}

fn need(path: &Path, what: &str, v: Option<f64>) -> Result<f64, VmtError> {
    v.ok_or_else(|| VmtError::bad(path, "", format!("expected `{what}`, found none")))
}

fn read_siemens(path: &Path, text: &str) -> Result<(Vec<f64>, Vec<f64>), VmtError> {
    let (mut vals, mut step, mut min, mut max) = (Vec::new(), None, None, None);
    for (line, key, v) in assignments(text) {
        let Some(inner) = key.strip_prefix("$AA_ENC_COMP").and_then(|k| k.split_once('[')) else { continue };
        let args: Vec<&str> = inner.1.trim_end_matches(']').split(',').collect();
        let x = number(path, line, key, v)? * 1e-3;
        match (inner.0, args.len()) {
            ("", 3) => {
                if vals.len() >= ControllerFormat::Siemens.max_points() {
                    return Err(VmtError::bad(
                        path,
                        format!("line {line}"),
                        "more points than a SINUMERIK table holds",
                    ));
                }
                vals.push((index(path, line, key, args[1])?, x));
            }
            ("_STEP", 2) => step = Some(x),
            ("_MIN", 2) => min = Some(x),
            ("_MAX", 2) => max = Some(x),
            ("_IS_MODULO", 2) if x == 0.0 => {}
            ("_IS_MODULO", 2) => {
                return Err(VmtError::bad(
                    path,
                    format!("line {line}, {key}"),
                    "a modulo (rotary) table is not supported",
                ))
            }
            _ => return Err(VmtError::bad(path, format!("line {line}"), format!("unexpected `{key}`"))),
        }
    }
    let c = dense(path, ControllerFormat::Siemens, vals)?;
    let (step, min) = (need(path, "$AA_ENC_COMP_STEP", step)?, need(path, "$AA_ENC_COMP_MIN", min)?);
    if step <= 0.0 {
        return Err(VmtError::bad(path, "$AA_ENC_COMP_STEP", format!("expected a spacing > 0, got {} mm", step * 1e3)));
    }
    let x: Vec<f64> = (0..c.len()).map(|k| min + k as f64 * step).collect();
    if let Some(max) = max {
        if (x[x.len() - 1] - max).abs() > 1e-6 * step {
            return Err(VmtError::bad(
                path,
                "$AA_ENC_COMP_MAX",
                format!("expected MIN + (points − 1)·STEP = {} mm, got {} mm", x[x.len() - 1] * 1e3, max * 1e3),
            ));
        }
    }
    Ok((x, c))
}

fn read_fanuc(path: &Path, text: &str) -> Result<(Vec<f64>, Vec<f64>), VmtError> {
    let (mut vals, mut interval, mut magnification, mut reference) = (Vec::new(), None, None, None);
    for (line, key, v) in assignments(text) {
        let x = number(path, line, key, v)?;
        match key {
            "P3620" | "P3621" if x == 0.0 => {}
            "P3620" | "P3621" => {
                return Err(VmtError::bad(
                    path,
                    format!("line {line}, {key}"),
                    "vmt reads tables whose reference point is point 0",
                ))
            }
            "P3622" => {}
            "P3623" if x.fract() == 0.0 && (1.0..=FANUC_MAX_MAGNIFICATION as f64).contains(&x) => {
                magnification = Some(x)
            }
            "P3623" => {
                return Err(VmtError::bad(
                    path,
                    format!("line {line}, {key}"),
                    format!("expected an integer magnification 1..={FANUC_MAX_MAGNIFICATION}, got {v}"),
                ))
            }
            "P3624" => interval = Some(x * 1e-3),
            "REF" => reference = Some(x * 1e-3),
            _ => {
                let Some(k) = key.strip_prefix('N') else {
                    return Err(VmtError::bad(path, format!("line {line}"), format!("unexpected `{key}`")));
                };
                if x.fract() != 0.0 || x.abs() > FANUC_MAX_INCREMENT as f64 {
                    return Err(VmtError::bad(
                        path,
                        format!("line {line}, {key}"),
                        format!("expected an integer within ±{FANUC_MAX_INCREMENT}, got {v}"),
                    ));
                }
                if vals.len() >= ControllerFormat::Fanuc.max_points() {
                    return Err(VmtError::bad(
                        path,
                        format!("line {line}"),
                        "more points than a FANUC table holds (128)",
                    ));
                }
                vals.push((index(path, line, key, k)?, x));
            }
        }
    }
    let inc = dense(path, ControllerFormat::Fanuc, vals)?;
    let interval = need(path, "P3624", interval)?;
    if interval <= 0.0 {
        return Err(VmtError::bad(path, "P3624", format!("expected an interval > 0, got {} mm", interval * 1e3)));
    }
    let q = FANUC_UNIT * need(path, "P3623", magnification)?;
    let reference = need(path, "REF", reference)?;
    let x: Vec<f64> = (0..inc.len()).map(|k| reference + k as f64 * interval).collect();
    // The value is the correction (−deviation), incremental: the deviation is minus the running sum.
    let c: Vec<f64> = inc
        .iter()
        .scan(0.0, |s, v| {
            *s += v;
            Some(-*s * q)
        })
        .collect();
    Ok((x, c))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> CompensationTable {
        let x = equidistant_nodes(0.02, 0.98, 17);
        let c = x.iter().map(|p| 2.2e-5 * p - 6e-6 * (p - 0.5) * (p - 0.5) + 1.3e-6 * (p / 0.32).sin()).collect();
        CompensationTable::new(x, c).unwrap()
    }

    /// Each format reads back what it wrote: positions exactly, values within the format's quantum
    /// (FANUC: 0.1 µm × M, cumulative rounding, relative to the first point; the others: 12 digits).
    #[test]
    fn every_format_reads_back_what_it_wrote() {
        let t = table();
        let dir = tempfile::tempdir().unwrap();
        for f in [ControllerFormat::Csv, ControllerFormat::Siemens, ControllerFormat::Fanuc] {
            let path = dir.path().join(f.name());
            std::fs::write(&path, table_text(f, &t, "AX1", "test").unwrap().0).unwrap();
            let back = read_table(&path).unwrap();
            assert_eq!(back.positions.len(), t.positions.len(), "{f:?}");
            for k in 0..t.positions.len() {
                assert!((back.positions[k] - t.positions[k]).abs() < 1e-12, "{f:?} {k}");
                let (want, tol) = match f {
                    ControllerFormat::Fanuc => (t.corrections[k] - t.corrections[0], 0.5e-7 + 1e-15),
                    ControllerFormat::Csv | ControllerFormat::Siemens => (t.corrections[k], 1e-15),
                };
                assert!((back.corrections[k] - want).abs() <= tol, "{f:?} {k}: {} vs {want}", back.corrections[k]);
            }
        }
    }

    /// A table that does not fit a format is refused, never truncated: 129 FANUC points, unequal spacing,
    /// a change of 2 mm between two points (beyond 127 × 0.1 µm × 100 = 1.27 mm).
    #[test]
    fn tables_beyond_a_formats_limits_are_refused() {
        let x = equidistant_nodes(0.0, 1.0, 129);
        let t = CompensationTable::new(x.clone(), vec![0.0; 129]).unwrap();
        assert!(table_text(ControllerFormat::Fanuc, &t, "X", "").unwrap_err().to_string().contains("at most 128"));
        assert!(table_text(ControllerFormat::Siemens, &t, "X", "").is_ok());
        let uneven = CompensationTable::new(vec![0.0, 0.1, 0.3], vec![0.0; 3]).unwrap();
        assert!(table_text(ControllerFormat::Siemens, &uneven, "X", "")
            .unwrap_err()
            .to_string()
            .contains("equidistant"));
        assert!(table_text(ControllerFormat::Csv, &uneven, "X", "").is_ok());
        let jump = CompensationTable::new(vec![0.0, 0.1, 0.2], vec![0.0, 2e-3, 0.0]).unwrap();
        assert!(table_text(ControllerFormat::Fanuc, &jump, "X", "").unwrap_err().to_string().contains("magnification"));
        // The smallest magnification that fits is chosen: a 20 µm step needs M = 2 (200 units > 127).
        let step = CompensationTable::new(vec![0.0, 0.1], vec![0.0, 2e-5]).unwrap();
        let (text, notes) = table_text(ControllerFormat::Fanuc, &step, "X", "").unwrap();
        assert!(text.contains("P3623=2 ") && notes[0].contains("0.2 µm"), "{text} {notes:?}");
    }
}
