//! Where the tests find the real third-party data, and the one thing they do when it is absent.
//!
//! The data (`realdata/`, see its README.md) is not part of the repository: most of it carries no
//! licence that allows redistribution. It is looked up in `$VMT_REALDATA` if that variable is set, else in
//! `../shared/realdata` beside the checkout (the directory above the workspace root). A test that needs it
//! calls [`realdata`]; when the folder is missing the test is skipped: it returns early after writing
//! `SKIPPED (real data not found at …): <test>` straight to the process's stderr. libtest captures only
//! the `print!`/`eprint!` macros, so this line shows in the output of a plain `cargo test` (no
//! `--nocapture` needed) and a person reading the test output sees every skipped real-data test.
//! CI (`.ci/run`) requires the data to be present, so nothing is skipped there.
//!
//! One source file shared by the test binaries of the workspace: the root's `util::realdata`; vmt-sim's
//! and vmt-estimators' `tests/tests.rs` include it with `#[path = …]`.
#![allow(dead_code)]

use std::io::Write;
use std::path::{Path, PathBuf};

/// The real-data root: `$VMT_REALDATA`, else `<workspace root>/../shared/realdata`.
pub fn realdata_root() -> PathBuf {
    if let Some(dir) = std::env::var_os("VMT_REALDATA") {
        return PathBuf::from(dir);
    }
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let workspace = manifest
        .ancestors()
        .find(|d| std::fs::read_to_string(d.join("Cargo.toml")).is_ok_and(|t| t.contains("[workspace]")))
        .unwrap_or(manifest);
    workspace.join("../shared/realdata")
}

/// The folder `sub` of the real data (e.g. `"ecmc_iso230_2"`), or `None` after writing the visible
/// skip line naming `test` when it is not there.
pub fn realdata(sub: &str, test: &str) -> Option<PathBuf> {
    let dir = realdata_root().join(sub);
    if dir.is_dir() {
        return Some(dir);
    }
    // Straight to the stderr handle (not `eprintln!`, which the test harness captures); one write call.
    let line = format!("SKIPPED (real data not found at {}; set VMT_REALDATA): {test}\n", dir.display());
    let _ = std::io::stderr().lock().write_all(line.as_bytes());
    None
}

/// Numeric rows of a CSV after `skip` header lines (the first line may carry a UTF-8 BOM).
fn read_rows(dir: &Path, name: &str, skip: usize) -> Vec<Vec<f64>> {
    let path = dir.join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .skip(skip)
        .filter(|l| !l.trim().is_empty())
        .enumerate()
        .map(|(i, l)| {
            l.split(',')
                .map(|c| {
                    c.trim()
                        .parse::<f64>()
                        .unwrap_or_else(|_| panic!("{name}: line {}: not a number: {c:?}", i + skip + 1))
                })
                .collect()
        })
        .collect()
}

/// Linear interpolation of (tx, x) at t (tx increasing); None outside the range.
fn interp(tx: &[f64], x: &[f64], t: f64) -> Option<f64> {
    if t < tx[0] || t > tx[tx.len() - 1] {
        return None;
    }
    let j = tx.partition_point(|&s| s <= t).clamp(1, tx.len() - 1);
    let f = (t - tx[j - 1]) / (tx[j] - tx[j - 1]);
    Some(x[j - 1] + f * (x[j] - x[j - 1]))
}

/// The rack-and-pinion move of `friction_rack_pinion/` on the servo timebase: time (s), servo
/// velocity (m/s), offset-corrected load-cell force (N), sample interval (s).
pub struct RackPinion {
    pub t: Vec<f64>,
    pub v_raw: Vec<f64>,
    pub force_raw: Vec<f64>,
    pub dt: f64,
}

/// The rack-and-pinion axis of K. Mnich (`friction_rack_pinion/`, see its README.txt): reads both
/// files and puts force and velocity on the servo timebase (README processing: F = −(V − V₀)·200 N/V,
/// NI time +4 ms, v = −rpm·20 mm/60 000, force interpolated linearly); `None` (the test `test` is
/// skipped, visibly) when the real data is absent.
pub fn rack_pinion(test: &str) -> Option<RackPinion> {
    let dir = realdata("friction_rack_pinion", test)?;
    let ni = read_rows(&dir, "a3NI.csv", 4);
    let mr = read_rows(&dir, "a3MR.csv", 5);
    assert!(ni.len() > 1000 && mr.len() == 1024, "{} NI rows, {} MR rows", ni.len(), mr.len());
    let v0: f64 = ni[..10].iter().map(|r| r[1]).sum::<f64>() / 10.0;
    let t_ni: Vec<f64> = ni.iter().map(|r| r[0] + 0.004).collect();
    let f_ni: Vec<f64> = ni.iter().map(|r| -(r[1] - v0) * 200.0).collect();
    let mut t = Vec::new();
    let mut v_raw = Vec::new();
    let mut force_raw = Vec::new();
    for r in &mr {
        let ts = r[0] * 1e-3;
        // Before the shifted NI record starts (first 4 ms) the axis is at rest and unloaded: the
        // force is the offset-corrected zero.
        let f = if ts < t_ni[0] { Some(0.0) } else { interp(&t_ni, &f_ni, ts) };
        if let Some(f) = f {
            t.push(ts);
            v_raw.push(-r[1] * 20.0 / 1000.0 / 60.0);
            force_raw.push(f);
        }
    }
    let dt = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
    Some(RackPinion { t, v_raw, force_raw, dt })
}
