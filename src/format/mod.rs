//! The file formats of FORMAT.md and docs/formats.md: readers and writers of plain data only (no physics,
//! no estimation). Layer 1 of the root crate: everything else may use it, it uses nothing above it.
//!
//! - [`error`]: the error type (bad input names file and place) and a key-path-tracking TOML reader;
//! - [`units`]: the units of CSV header cells;
//! - [`measurement`]: measurement sets (FORMAT.md §1) and error-motion profile CSVs (§5);
//! - [`model`]: models and truths (`vmt-model/1`, §2);
//! - [`compensation`]: compensation tables as controllers load them (CSV, SINUMERIK-, FANUC-style);
//! - [`output`]: one output transaction per command (a directory filled beside its destination, swapped in).

pub mod compensation;
pub mod error;
pub mod measurement;
pub mod model;
pub mod output;
pub mod units;
