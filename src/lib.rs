//! vmt: a virtual machine tool. The root crate in layers, data flowing forward:
//!
//! ```text
//! format/    FORMAT readers and writers (error, units, measurement, model)       plain data
//! scenario/  Scenario, load, chain building; spec.rs: EstimatorSpec             uses format
//! modelcheck/ compare / diagnose / add                                           uses format
//! workflow/  simulate → truth view + measurement set → estimate (one adapter      uses scenario, modelcheck, format
//!            per estimator; byo) → report; run, study join them; estimate sees no scenario or physics
//! cli, main  the commands                                                        uses all
//! ```
//!
//! The old flat paths (`vmt::measurement`, `vmt::simulate`, …) stay available as re-exports.

pub mod bundled;
pub mod cli;
pub mod format;
pub mod fuzz;
pub mod modelcheck;
pub mod output;
pub mod scenario;
pub mod workflow;

pub use format::{error, measurement, model, units};
pub use workflow::estimate::straightness;
pub use workflow::{byo, estimate, report, simulate, study};
