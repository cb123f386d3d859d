//! Golden outputs of `vmt run` (issue 12): every bundled scenario (scenarios/*.toml) and lesson
//! (scenarios/lessons/*/scenario.toml) prints the same table, exits with the same code and writes the same
//! files as when the goldens were captured (before the redesign moved any code). The goldens are
//! tests/golden/run/NAME.txt (stdout, the output directory replaced by `<out>`) and NAME.files (one line per
//! written file: path, length in bytes, FNV-1a 64-bit hash of the bytes with the output directory replaced
//! by `<out>`, the program path by `<vmt>` and the build's `(git COMMIT)` by `(git <commit>)`).
//! `SOURCE_DATE_EPOCH=0` fixes the report date.
//!
//! Re-capture after a deliberate change of behaviour: `VMT_BLESS=1 cargo test --release --test golden`;
//! `VMT_BIN=PATH` runs another build of vmt (how the goldens were captured from the build of 04efba4).

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every bundled scenario and lesson, as paths relative to the repository root (the table prints the path).
fn bundled() -> Vec<String> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(root().join("scenarios")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            v.push(format!("scenarios/{}", p.file_name().unwrap().to_string_lossy()));
        }
    }
    for e in std::fs::read_dir(root().join("scenarios/lessons")).unwrap() {
        let p = e.unwrap().path();
        if p.join("scenario.toml").is_file() {
            v.push(format!("scenarios/lessons/{}/scenario.toml", p.file_name().unwrap().to_string_lossy()));
        }
    }
    v.sort();
    v
}

/// FNV-1a, 64 bit (a stable content hash needing no dependency).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

/// The program under test: `VMT_BIN`, else the vmt this test was built with.
fn vmt_bin() -> PathBuf {
    std::env::var_os("VMT_BIN").map(PathBuf::from).unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_vmt")))
}

/// Text with what legitimately differs between builds and runs replaced: the output directory, the
/// program path (the report records the command line) and the commit in `(git COMMIT)`.
fn normalise(text: &str, out: &str) -> String {
    let text = text.replace(out, "<out>").replace(&*vmt_bin().to_string_lossy(), "<vmt>");
    let mut s = String::new();
    let mut rest = text.as_str();
    while let Some(i) = rest.find("(git ") {
        s.push_str(&rest[..i]);
        s.push_str("(git <commit>)");
        rest = &rest[i..];
        rest = rest.find(')').map_or("", |j| &rest[j + 1..]);
    }
    s.push_str(rest);
    s
}

/// Every file below `dir` (paths relative to `dir`, sorted), as `path length hash` lines.
fn listing(dir: &Path, out: &str) -> String {
    fn walk(d: &Path, acc: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, acc);
            } else {
                acc.push(p);
            }
        }
    }
    let mut files = Vec::new();
    walk(dir, &mut files);
    files.sort();
    let mut s = String::new();
    for f in files {
        let rel = f.strip_prefix(dir).unwrap().to_string_lossy().replace('\\', "/");
        if rel == ".vmt-output" {
            continue; // the output marker names the process and the directory
        }
        let bytes = std::fs::read(&f).unwrap();
        let text = String::from_utf8(bytes.clone()).map(|t| normalise(&t, out).into_bytes());
        let bytes = text.unwrap_or(bytes);
        s.push_str(&format!("{rel} {} {:016x}\n", bytes.len(), fnv1a(&bytes)));
    }
    s
}

/// Name of a scenario's golden files: its path with `/` → `_` and without `.toml`.
fn golden_name(scenario: &str) -> String {
    scenario.trim_end_matches(".toml").replace('/', "_")
}

#[test]
fn vmt_run_on_every_bundled_scenario_and_lesson_matches_its_golden_output() {
    let tmp = tempfile::tempdir().unwrap();
    let scenarios = bundled();
    assert!(scenarios.len() >= 10, "expected the 5 scenarios and 5 lessons, found {scenarios:?}");
    let bless = std::env::var_os("VMT_BLESS").is_some();
    let golden_dir = root().join("tests/golden/run");
    // All runs at once: the longest (default.toml) takes ~5 s, the whole set ~12 s of CPU.
    let results: Vec<(String, Result<(), String>)> = std::thread::scope(|s| {
        let handles: Vec<_> = scenarios
            .iter()
            .map(|sc| {
                let out = tmp.path().join(golden_name(sc));
                let golden_dir = &golden_dir;
                s.spawn(move || {
                    let o = Command::new(vmt_bin())
                        .current_dir(root())
                        .args(["run", sc, "-o"])
                        .arg(&out)
                        .env("SOURCE_DATE_EPOCH", "0")
                        .env("RAYON_NUM_THREADS", "1")
                        .output()
                        .unwrap();
                    let outs = out.to_string_lossy().into_owned();
                    let stdout = normalise(&String::from_utf8(o.stdout).unwrap(), &outs);
                    let text = format!("exit code {:?}\n{stdout}", o.status.code());
                    let files = listing(&out, &outs);
                    let name = golden_name(sc);
                    let (gt, gf) = (golden_dir.join(format!("{name}.txt")), golden_dir.join(format!("{name}.files")));
                    if bless {
                        std::fs::create_dir_all(golden_dir).unwrap();
                        std::fs::write(&gt, &text).unwrap();
                        std::fs::write(&gf, &files).unwrap();
                        return Ok(());
                    }
                    let want_t = std::fs::read_to_string(&gt).map_err(|e| format!("{}: {e}", gt.display()))?;
                    let want_f = std::fs::read_to_string(&gf).map_err(|e| format!("{}: {e}", gf.display()))?;
                    let mut diffs = String::new();
                    if text != want_t {
                        diffs.push_str(&format!(
                            "printed table differs from {}:\n--- golden\n{want_t}\n--- now\n{text}\nstderr: {}\n",
                            gt.display(),
                            String::from_utf8_lossy(&o.stderr)
                        ));
                    }
                    if files != want_f {
                        diffs.push_str(&format!(
                            "written files differ from {}:\n--- golden\n{want_f}--- now\n{files}",
                            gf.display()
                        ));
                    }
                    if diffs.is_empty() {
                        Ok(())
                    } else {
                        Err(diffs)
                    }
                })
            })
            .collect();
        scenarios.iter().cloned().zip(handles.into_iter().map(|h| h.join().unwrap())).collect()
    });
    let failed: Vec<String> =
        results.into_iter().filter_map(|(sc, r)| r.err().map(|e| format!("== {sc}\n{e}"))).collect();
    assert!(
        failed.is_empty(),
        "{} of {} differ from their goldens:\n{}",
        failed.len(),
        scenarios.len(),
        failed.join("\n")
    );
}

/// One value of a result-table cell: a number (in the row's printed unit), yes/no, or none (—).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Cell {
    Number(f64),
    Yes(bool),
    None,
}

/// The four value cells (injected, recovered, difference, tolerance), the pass rule and the verdict of a
/// result-table line, or None for a line that is not a result row. Cells are read from the right: a
/// value is `—`, `yes`/`no`, or a number optionally followed by one unit token.
fn table_row(line: &str) -> Option<([Cell; 4], &'static str, bool)> {
    let (rest, pass) =
        if let Some(r) = line.strip_suffix("pass") { (r, true) } else { (line.strip_suffix("FAIL")?, false) };
    let rules = ["|difference| ≤ tolerance", "RMS difference ≤ tolerance", "recovered ≤ tolerance", "found"];
    let rest = rest.trim_end();
    let rule = rules.into_iter().find(|r| rest.ends_with(r))?;
    let mut tokens: Vec<&str> = rest[..rest.len() - rule.len()].split_whitespace().collect();
    let mut cells = Vec::new();
    while cells.len() < 4 {
        let t = tokens.pop()?;
        let cell = match t {
            "—" => Cell::None,
            "yes" => Cell::Yes(true),
            "no" => Cell::Yes(false),
            _ => match t.parse::<f64>() {
                Ok(v) => Cell::Number(v),
                // A unit: the number is the token before it.
                Err(_) => Cell::Number(tokens.pop()?.parse().ok()?),
            },
        };
        cells.push(cell);
    }
    cells.reverse();
    Some(([cells[0], cells[1], cells[2], cells[3]], rule, pass))
}

/// Issue 13: every row of `vmt run`'s table can be read literally. On every bundled scenario's golden
/// output (the test above holds them equal to the program's), the printed numbers obey the printed
/// rule: `difference` = recovered − injected and |difference| ≤ tolerance ⇔ pass for `|difference| ≤
/// tolerance`; difference ≥ 0 and difference ≤ tolerance ⇔ pass for RMS rows; no difference and
/// recovered ≤ tolerance ⇔ pass for one-sided limits; found = expected ⇔ pass. Printed values carry 3
/// decimals, so comparisons allow the rounding of the cells involved (± 0.0005 each); a row whose
/// verdict sits within that rounding of its limit is not judged (counted, and must be rare).
#[test]
fn every_result_row_reads_literally() {
    let dir = root().join("tests/golden/run");
    let (mut rows, mut undecided, mut problems) = (0, 0, Vec::new());
    let r = 0.0005;
    for e in std::fs::read_dir(&dir).unwrap().flatten() {
        let p = e.path();
        if p.extension().is_none_or(|x| x != "txt") {
            continue;
        }
        for line in std::fs::read_to_string(&p).unwrap().lines() {
            let Some(([inj, rec, diff, tol], rule, pass)) = table_row(line) else { continue };
            rows += 1;
            let mut bad =
                |why: &str| problems.push(format!("{}: {why}: {line}", p.file_name().unwrap().to_string_lossy()));
            let judge = |value: f64, limit: f64, slack: f64, bad: &mut dyn FnMut(&str), undecided: &mut usize| {
                if (value - limit).abs() <= slack {
                    *undecided += 1;
                } else if (value <= limit) != pass {
                    bad("the verdict contradicts the printed numbers");
                }
            };
            match (rule, inj, rec, diff, tol) {
                ("|difference| ≤ tolerance", Cell::Number(i), Cell::Number(x), Cell::Number(d), Cell::Number(t)) => {
                    if (d - (x - i)).abs() > 3.0 * r {
                        bad("difference ≠ recovered − injected");
                    }
                    judge(d.abs(), t, 2.0 * r, &mut bad, &mut undecided);
                }
                ("RMS difference ≤ tolerance", Cell::Number(_), Cell::Number(_), Cell::Number(d), Cell::Number(t)) => {
                    if d < 0.0 {
                        bad("an RMS difference is negative");
                    }
                    judge(d, t, 2.0 * r, &mut bad, &mut undecided);
                }
                ("recovered ≤ tolerance", _, Cell::Number(x), Cell::None, Cell::Number(t)) => {
                    judge(x, t, 2.0 * r, &mut bad, &mut undecided);
                }
                ("found", Cell::Yes(i), Cell::Yes(x), Cell::None, Cell::None) => {
                    if (i == x) != pass {
                        bad("found/expected contradicts the verdict");
                    }
                }
                _ => bad("cells do not fit the rule"),
            }
        }
    }
    assert!(rows >= 30, "read only {rows} result rows from {} (38 when written)", dir.display());
    assert!(undecided * 20 <= rows, "{undecided} of {rows} rows sit within rounding of their limit");
    assert!(problems.is_empty(), "{} rows do not read literally:\n{}", problems.len(), problems.join("\n"));
}
