//! vmt-estimators: the identification algorithms of vmt and the statistics of the model-check loop.
//!
//! Pure functions on numbers: no physics engine, no file I/O. Each estimator names the seed
//! (`shared/seeds/`) or paper it follows. Units are SI unless a doc comment says otherwise.

#![deny(missing_docs)]

pub mod accel_straightness;
pub mod compensation;
pub mod dsp;
pub mod friction_id;
pub mod input;
pub mod iso230_2;
pub mod laser_ls;
pub mod line;
pub mod modelcheck;
pub mod ssi;
