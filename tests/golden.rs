//! Golden outputs of `vmt run` (issue 12): every bundled scenario (scenarios/*.toml) and lesson
//! (scenarios/lessons/*/scenario.toml) prints the same table, exits with the same code and writes the same
//! files as when the goldens were captured (before the redesign moved any code). The goldens are
//! tests/golden/run/NAME.txt (stdout, the output directory replaced by `<out>`) and NAME.files (one line per
//! written file: path, length in bytes, FNV-1a 64-bit hash of the bytes with the output directory replaced
//! by `<out>`, the program path by `<vmt>` and the build's `(git COMMIT)` by `(git <commit>)`).
//! `SOURCE_DATE_EPOCH=0` fixes the report date.
//!
//! Re-capture after a deliberate change of behaviour: `VMT_BLESS=1 cargo test --release --test tests golden::`;
//! `VMT_BIN=PATH` runs another build of vmt (how the goldens were captured from the build of 04efba4).

use crate::util::{bundled, root};
use std::path::{Path, PathBuf};
use std::process::Command;

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
