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
