//! vmt-core: the plain types and laws that both the simulator (`vmt-sim`) and the estimators
//! (`vmt-estimators`) need, so that each is written once while the two crates stay independent of each
//! other (the estimators have no physics engine; the simulator runs no estimator). No I/O, no physics
//! engine: equations and small value types only.
//!
//! - [`friction`]: the Stribeck friction law F(v) and its derivatives (the simulator integrates it, the
//!   estimators fit it);
//! - [`axis`]: the machine axes X, Y, Z as an enum (the simulator's chain, the laser-line identifier).
#![deny(missing_docs)]

pub mod axis;
pub mod friction;
