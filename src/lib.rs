//! vmt: a virtual machine tool. File formats (FORMAT.md), scenarios, workflows (simulate, estimate),
//! reports and the CLI.

pub mod bundled;
pub mod byo;
pub mod cli;
pub mod error;
pub mod estimate;
pub mod fuzz;
pub mod measurement;
pub mod model;
pub mod modelcheck;
pub mod output;
pub mod report;
pub mod scenario;
pub mod simulate;
pub mod straightness;
pub mod study;
pub mod units;
