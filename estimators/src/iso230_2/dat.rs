//! Parser for the `*_ISO230.dat` key=value files written by the EPICS ecmc ISO 230-2 test tools
//! (github paulscherrerinstitute/ecmccfg, anderssandstrom/ecmc_target_muts_logger, ecmccomgui).
//!
//! Format (one item per line, see `shared/realdata/ecmc_iso230_2/README.txt`):
//! ```text
//! # comment                      (also: lines starting with TEST_DATA= are comments)
//! UNIT=mm                        (metadata: UNIT, CYCLES, POSITIONS, DEC, REF_PV, TEST_PV, TGT_SET_PV, ...)
//! TGT_DATA[i]=<target position of point i>
//! REF_DATA_FWD[i,j]=<reference-system position at point i, cycle j, positive approach>
//! REF_DATA_BWD[i,j]=<same, negative approach>
//! ```
//! Indices are 1-based. `REF_DATA_FWD` is the approach in the POSITIVE direction (↑, "up"); this was
//! verified from the raw log (test number 1CPP = forward) by the dataset's curator. The `.md` reports
//! printed beside the data show the two tables swapped; this parser follows the `.dat` labels.
//!
//! Sign convention: positional deviation `x_ij = REF − TGT` (reference-system reading minus target),
//! i.e. actual − target as ISO 230-2:2014 3.3 defines it, and as the ecmc reports print it
//! ("reference position − target position"). The subtraction is made in the file's unit, then the
//! result is converted to metres.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why a `.dat` text could not be parsed. Line numbers are 1-based.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DatError {
    /// A line could not be understood.
    #[error("line {line}: expected {expected}, got `{found}`")]
    Line {
        /// Line number, 1-based.
        line: usize,
        /// What the line should hold.
        expected: String,
        /// The text found there.
        found: String,
    },
    /// A key was given twice.
    #[error("line {line}: `{key}` was already given on line {first_line}")]
    Duplicate {
        /// Line number, 1-based.
        line: usize,
        /// The key given twice.
        key: String,
        /// Line where the key was first given, 1-based.
        first_line: usize,
    },
    /// The data tables are incomplete or inconsistent with the metadata.
    #[error("{0}")]
    Incomplete(String),
}

/// A parsed ISO 230-2 `.dat` file, converted to SI.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatFile {
    /// Target positions P_i, m (in file order).
    pub targets: Vec<f64>,
    /// Positional deviations `x↑_ij = REF_DATA_FWD[i,j] − TGT_DATA[i]`, m (positive approach), `[i][j]`.
    pub up: Vec<Vec<f64>>,
    /// Positional deviations `x↓_ij = REF_DATA_BWD[i,j] − TGT_DATA[i]`, m (negative approach), `[i][j]`.
    pub down: Vec<Vec<f64>>,
    /// The unit the file was written in (`UNIT`, default `mm`).
    pub unit: String,
    /// All other `KEY=value` pairs (REF_PV, TEST_PV, TGT_SET_PV, CYCLES, POSITIONS, DEC, ...).
    pub metadata: BTreeMap<String, String>,
}

/// Metres per unit for the units the ecmc tools may write.
fn unit_scale(unit: &str) -> Option<f64> {
    match unit {
        "mm" => Some(1e-3),
        "m" => Some(1.0),
        "um" | "µm" | "micron" => Some(1e-6),
        "nm" => Some(1e-9),
        _ => None,
    }
}

fn parse_number(text: &str, line: usize, what: &str) -> Result<f64, DatError> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(DatError::Line {
            line,
            expected: format!("a finite number for {what}"),
            found: text.trim().to_string(),
        }),
    }
}

fn parse_index(text: &str, line: usize, key: &str) -> Result<usize, DatError> {
    match text.trim().parse::<usize>() {
        Ok(v) if v >= 1 => Ok(v),
        _ => Err(DatError::Line {
            line,
            expected: format!("a 1-based integer index in {key}[...]"),
            found: text.trim().to_string(),
        }),
    }
}

/// Splits `NAME[a,b]` into ("NAME", Some("a,b")), or `NAME` into ("NAME", None).
fn split_key(key: &str, line: usize) -> Result<(&str, Option<&str>), DatError> {
    match key.find('[') {
        None => Ok((key, None)),
        Some(open) => {
            if !key.ends_with(']') {
                return Err(DatError::Line {
                    line,
                    expected: "a key of the form NAME[index] or NAME[index,cycle]".into(),
                    found: key.to_string(),
                });
            }
            // index: `key` ends with `]` and holds its first `[` at `open` < len − 1, so open + 1 ≤ len − 1.
            Ok((&key[..open], Some(&key[open + 1..key.len() - 1])))
        }
    }
}

type Cell = (f64, usize); // value in file units, line number

/// Parses the text of an ecmc `*_ISO230.dat` file (format in the module doc).
///
/// Returns targets in m and deviations `x_ij = REF − TGT` in m for both approach directions.
/// Errors name the line and what was expected: a line without `=`, a number that does not parse,
/// a bad index, a duplicated key, an unknown `UNIT`, a hole in the (position, cycle) table, or a
/// `POSITIONS` / `CYCLES` value that disagrees with the data.
pub fn parse_dat(text: &str) -> Result<DatFile, DatError> {
    let mut targets: BTreeMap<usize, Cell> = BTreeMap::new();
    let mut fwd: BTreeMap<(usize, usize), Cell> = BTreeMap::new();
    let mut bwd: BTreeMap<(usize, usize), Cell> = BTreeMap::new();
    let mut metadata: BTreeMap<String, String> = BTreeMap::new();
    let mut meta_lines: BTreeMap<String, usize> = BTreeMap::new();

    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let s = raw.trim();
        if s.is_empty() || s.starts_with('#') || s.starts_with("TEST_DATA=") {
            continue;
        }
        let Some(eq) = s.find('=') else {
            return Err(DatError::Line {
                line,
                expected: "KEY=value, a comment starting with '#', or an empty line".into(),
                found: s.to_string(),
            });
        };
        let key = s[..eq].trim();
        let value = s[eq + 1..].trim();
        let (name, index) = split_key(key, line)?;
        match (name, index) {
            ("TGT_DATA", Some(idx)) => {
                let i = parse_index(idx, line, name)?;
                let v = parse_number(value, line, key)?;
                if let Some(&(_, first)) = targets.get(&i) {
                    return Err(DatError::Duplicate { line, key: key.to_string(), first_line: first });
                }
                targets.insert(i, (v, line));
            }
            ("REF_DATA_FWD", Some(idx)) | ("REF_DATA_BWD", Some(idx)) => {
                let mut parts = idx.split(',');
                let (Some(a), Some(b), None) = (parts.next(), parts.next(), parts.next()) else {
                    return Err(DatError::Line {
                        line,
                        expected: format!("{name}[position,cycle]"),
                        found: key.to_string(),
                    });
                };
                let i = parse_index(a, line, name)?;
                let j = parse_index(b, line, name)?;
                let v = parse_number(value, line, key)?;
                let table = if name == "REF_DATA_FWD" { &mut fwd } else { &mut bwd };
                if let Some(&(_, first)) = table.get(&(i, j)) {
                    return Err(DatError::Duplicate { line, key: key.to_string(), first_line: first });
                }
                table.insert((i, j), (v, line));
            }
            (_, Some(_)) => {
                return Err(DatError::Line {
                    line,
                    expected: "TGT_DATA[i], REF_DATA_FWD[i,j] or REF_DATA_BWD[i,j] (or a plain KEY=value)".into(),
                    found: key.to_string(),
                })
            }
            (_, None) => {
                if key.is_empty() {
                    return Err(DatError::Line { line, expected: "a key before '='".into(), found: s.to_string() });
                }
                if let Some(&first) = meta_lines.get(key) {
                    return Err(DatError::Duplicate { line, key: key.to_string(), first_line: first });
                }
                meta_lines.insert(key.to_string(), line);
                metadata.insert(key.to_string(), value.to_string());
            }
        }
    }

    let unit = metadata.get("UNIT").cloned().unwrap_or_else(|| "mm".to_string());
    let scale = unit_scale(&unit).ok_or_else(|| DatError::Line {
        line: meta_lines.get("UNIT").copied().unwrap_or(0),
        expected: "UNIT one of mm, m, um, nm".into(),
        found: unit.clone(),
    })?;

    let m = targets.len();
    if m == 0 {
        return Err(DatError::Incomplete("no TGT_DATA[i] line found".into()));
    }
    for i in 1..=m {
        if !targets.contains_key(&i) {
            return Err(DatError::Incomplete(format!(
                "TGT_DATA indices must be 1..{m} without holes; TGT_DATA[{i}] is missing"
            )));
        }
    }
    let n = fwd.keys().chain(bwd.keys()).map(|&(_, j)| j).max().unwrap_or(0);
    if n == 0 {
        return Err(DatError::Incomplete("no REF_DATA_FWD[i,j] or REF_DATA_BWD[i,j] line found".into()));
    }
    for (key, expected) in [("POSITIONS", m), ("CYCLES", n)] {
        if let Some(v) = metadata.get(key) {
            let line = meta_lines[key];
            let given = v.parse::<usize>().map_err(|_| DatError::Line {
                line,
                expected: format!("an integer {key}"),
                found: v.clone(),
            })?;
            if given != expected {
                return Err(DatError::Line {
                    line,
                    expected: format!("{key}={expected} as the data tables hold"),
                    found: format!("{key}={given}"),
                });
            }
        }
    }

    let build = |table: &BTreeMap<(usize, usize), Cell>, name: &str| -> Result<Vec<Vec<f64>>, DatError> {
        if let Some((&(i, _), &(_, line))) = table.iter().find(|((i, _), _)| *i > m) {
            return Err(DatError::Line {
                line,
                expected: format!("a position index 1..{m} (TGT_DATA has {m} points)"),
                found: format!("{name}[{i},...]"),
            });
        }
        (1..=m)
            .map(|i| {
                let tgt = targets[&i].0;
                (1..=n)
                    .map(|j| match table.get(&(i, j)) {
                        Some(&(v, _)) => Ok((v - tgt) * scale),
                        None => Err(DatError::Incomplete(format!(
                            "{name}[{i},{j}] is missing ({m} positions x {n} cycles expected)"
                        ))),
                    })
                    .collect()
            })
            .collect()
    };
    let up = build(&fwd, "REF_DATA_FWD")?;
    let down = build(&bwd, "REF_DATA_BWD")?;
    Ok(DatFile { targets: (1..=m).map(|i| targets[&i].0 * scale).collect(), up, down, unit, metadata })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = "TEST_DATA=# header comment\n# Mandatory variable definitions:\nUNIT=mm\nCYCLES=2\nPOSITIONS=2\nREF_PV=IOC:Enc\nTGT_DATA[1]=-10\nTGT_DATA[2]=5.5\nREF_DATA_FWD[1,1]=-10.001\nREF_DATA_FWD[2,1]=5.502\nREF_DATA_FWD[1,2]=-9.999\nREF_DATA_FWD[2,2]=5.5\nREF_DATA_BWD[1,1]=-10.000\nREF_DATA_BWD[2,1]=.5e1\nREF_DATA_BWD[1,2]=-10.003\nREF_DATA_BWD[2,2]=5.497\n  \n";

    #[test]
    fn parses_a_small_file_to_metres_with_ref_minus_target() {
        let d = parse_dat(SMALL).unwrap();
        assert_eq!(d.unit, "mm");
        assert_eq!(d.metadata["REF_PV"], "IOC:Enc");
        // Tolerance 1e-15 m: mm decimals are not exact in binary; the subtraction of two ~10 mm
        // numbers leaves ~2e-15 mm = 2e-18 m of rounding, far below.
        let c = |a: f64, b: f64| (a - b).abs() < 1e-15;
        assert!(c(d.targets[0], -0.010) && c(d.targets[1], 0.0055));
        assert!(c(d.up[0][0], -1e-6) && c(d.up[0][1], 1e-6));
        assert!(c(d.up[1][0], 2e-6) && c(d.up[1][1], 0.0));
        assert!(c(d.down[0][0], 0.0) && c(d.down[0][1], -3e-6));
        assert!(c(d.down[1][0], -0.5e-3) && c(d.down[1][1], -3e-6));
    }

    #[test]
    fn malformed_text_names_the_line() {
        let bad = SMALL.replace("REF_DATA_FWD[2,1]=5.502", "REF_DATA_FWD[2,1]=5.5x2");
        let e = parse_dat(&bad).unwrap_err();
        assert!(matches!(e, DatError::Line { line: 10, .. }), "{e}");
        assert!(e.to_string().contains("line 10") && e.to_string().contains("finite number"), "{e}");

        let bad = SMALL.replace("UNIT=mm", "UNIT mm");
        let e = parse_dat(&bad).unwrap_err();
        assert!(e.to_string().starts_with("line 3: expected KEY=value"), "{e}");

        let bad = SMALL.replace("REF_DATA_BWD[1,2]=-10.003\n", "");
        let e = parse_dat(&bad).unwrap_err();
        assert!(e.to_string().contains("REF_DATA_BWD[1,2] is missing"), "{e}");

        let bad = SMALL.replace("CYCLES=2", "CYCLES=5");
        let e = parse_dat(&bad).unwrap_err();
        assert!(e.to_string().contains("line 4") && e.to_string().contains("CYCLES=2"), "{e}");

        let bad = SMALL.replace("TGT_DATA[2]=5.5", "TGT_DATA[1]=5.5");
        let e = parse_dat(&bad).unwrap_err();
        assert!(matches!(e, DatError::Duplicate { line: 8, first_line: 7, .. }), "{e}");

        let bad = SMALL.replace("UNIT=mm", "UNIT=inch");
        assert!(parse_dat(&bad).unwrap_err().to_string().contains("UNIT one of"));

        let bad = SMALL.replace("REF_DATA_FWD[1,2]", "REF_DATA_FWD[1;2]");
        assert!(parse_dat(&bad).unwrap_err().to_string().contains("line 11"));
    }
}
