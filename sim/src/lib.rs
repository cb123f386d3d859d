//! vmt-sim: the physics of vmt. A machine from URDF, rapier3d-f64 rigid-body dynamics, guideways whose
//! rest pose follows injected error motions, a servo-driven feed axis, sensors with seeded noise, and
//! the measurement procedures a metrologist runs. Plain data flows forward: scenario → machine →
//! recording. No file I/O: URDF text is passed in.
#![deny(missing_docs)]

/// Default-value functions for serde's `default = "..."` (it needs a function per value):
/// `defaults! { d_rate: f64 = 500.0; }` defines `fn d_rate() -> f64 { 500.0 }`.
macro_rules! defaults {
    ($($name:ident: $t:ty = $v:expr;)*) => { $(fn $name() -> $t { $v })* };
}

pub mod air;
pub mod axis_sim;
pub mod chain;
pub mod drive;
pub mod effects;
pub mod feedback;
pub mod friction;
pub mod geometry;
pub mod machine;
pub mod motion;
pub mod presets;
pub mod procedures;
pub mod profile;
pub mod retest;
pub mod rng;
pub mod sensors;
pub mod servo;
pub mod truth;
pub mod urdf;

/// A machine axis X, Y or Z (crate `vmt-core`, shared with the estimators).
pub use vmt_core::axis::Axis;
