//! vmt-sim's integration tests, built as one test binary (the layout ripgrep uses): every file in this
//! folder is one module, what they share is in [`util`]. One file's tests:
//! `cargo test --release -p vmt-sim --test tests resonance::` (or `--workspace --test tests resonance::`).
//! A new file must be declared below (`autotests = false`; the root test
//! `every_test_file_is_a_module` checks it).

mod util;

mod chain;
mod crawl_seed002;
mod drive_effects;
mod dynamics;
mod effect_signatures;
mod friction_sweep;
mod lugre_canudas1995;
mod quasi_static;
mod resonance;
mod urdf_realdata;
