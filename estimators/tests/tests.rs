//! vmt-estimators' integration tests, built as one test binary (the layout ripgrep uses): every file in
//! this folder is one module. One file's tests: `cargo test --release --workspace --test tests laser_ls::`.
//! A new file must be declared below (`autotests = false`; the root test `every_test_file_is_a_module`
//! checks it).

/// The real third-party data (shared with the other crates' tests).
#[path = "../../tests/util/realdata.rs"]
mod realdata;

mod accel_straightness;
mod friction_realdata;
mod independent;
mod iso230_2_realdata;
mod laser_ls;
// TODO(issue 19, owner of this file): the file wraps its tests in an inner `mod modelcheck` (for the
// name filter of its old one-file binary), now redundant: unwrap it and drop this allow.
#[allow(clippy::module_inception)]
mod modelcheck;
