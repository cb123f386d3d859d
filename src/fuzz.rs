//! The bodies of vmt's fuzz targets (issue 14): each feeds arbitrary bytes to one reader and ignores
//! its result; a panic, an abort or a hang is the failure. Used by the cargo-fuzz targets in `fuzz/`
//! and replayed over a seed corpus with a deterministic mutator by `tests/fuzz_replay.rs` (stable).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// A fresh scratch directory under the system's temporary directory.
fn scratch() -> PathBuf {
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let d = std::env::temp_dir().join(format!("vmt-fuzz-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    let _ = std::fs::create_dir_all(&d);
    d
}

/// The two parts of an input, split at the first line `---`: (first, rest).
fn split(data: &[u8]) -> (&[u8], &[u8]) {
    match data.windows(5).position(|w| w == b"\n---\n") {
        Some(i) => (&data[..i + 1], &data[i + 5..]),
        None => (data, &[]),
    }
}

/// A scenario (TOML) through `Scenario::parse` with no base directory (bundled machines only).
pub fn scenario_toml(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = crate::scenario::Scenario::parse(text, Path::new("fuzz.toml"), None);
    }
}

/// A measurement set: the input's first part is `manifest.toml`, the rest the run file `run.csv`.
pub fn measurement_set(data: &[u8]) {
    let (manifest, csv) = split(data);
    let d = scratch();
    if std::fs::write(d.join("manifest.toml"), manifest).is_ok() && std::fs::write(d.join("run.csv"), csv).is_ok() {
        let _ = crate::measurement::read(&d);
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// An ISO 230-2 `.dat` file through `read_data` (parser, target checks, conversion to a set).
pub fn iso230_2_dat(data: &[u8]) {
    let d = scratch();
    let p = d.join("test.dat");
    if std::fs::write(&p, data).is_ok() {
        let _ = crate::measurement::read_data(&p);
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// A URDF through `parse_urdf`, and the axis model of its first prismatic joint with default keys.
pub fn urdf(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(m) = vmt_sim::urdf::parse_urdf(text) {
            if let Some(a) = m.axes.first() {
                let cfg = vmt_sim::machine::AxisConfig { joint: a.joint.clone(), ..Default::default() };
                let _ = vmt_sim::machine::AxisModel::build(&m, &cfg);
            }
        }
    }
}

/// An error-motion profile CSV (FORMAT.md §5) through `read_profiles`.
pub fn profile_csv(data: &[u8]) {
    let d = scratch();
    let p = d.join("profiles.csv");
    if std::fs::write(&p, data).is_ok() {
        let _ = crate::measurement::read_profiles(&p);
    }
    let _ = std::fs::remove_dir_all(&d);
}
