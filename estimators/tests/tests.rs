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
mod modelcheck;
