//! What the integration tests share: the repository root, the `vmt` binary they were built with, the
//! small test scenario, the list of bundled scenarios and the real third-party data ([`realdata`]).

pub mod realdata;

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root (the vmt package's manifest directory).
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file under `dir` (recursively), appended to `out` in directory order (callers sort).
pub fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// A command that runs the `vmt` binary built with these tests, or the one `VMT_BIN` names (as in golden.rs) (a rate
/// study run from a copied test binary keeps a copied `vmt` while the tree is rebuilt).
pub fn vmt() -> Command {
    Command::new(std::env::var_os("VMT_BIN").unwrap_or_else(|| env!("CARGO_BIN_EXE_vmt").into()))
}

/// tests/data/small.toml: the small test scenario most command-line tests start from.
pub fn small() -> PathBuf {
    root().join("tests/data/small.toml")
}

/// Every bundled scenario (scenarios/*.toml) and lesson (scenarios/lessons/*/scenario.toml), as paths
/// relative to the repository root (what `vmt run` prints), sorted.
pub fn bundled() -> Vec<String> {
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

/// Root mean square of `v` about zero, in the unit of `v`: √(Σ vᵢ² / n).
pub fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64).sqrt()
}
