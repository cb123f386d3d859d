//! vmt: a virtual machine tool. File formats (FORMAT.md), workflows, reports and the CLI.

pub mod error;
pub mod measurement;
pub mod model;
pub mod units;
