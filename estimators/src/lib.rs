//! vmt-estimators: the identification algorithms of vmt and the statistics of the model-check loop.
//!
//! Pure functions on numbers: no physics engine, no file I/O. Each estimator names the seed
//! (`shared/seeds/`) or paper it follows. Units are SI unless a doc comment says otherwise.

#![deny(missing_docs)]

pub mod accel_straightness;
pub mod compensation;
pub mod cpu;
pub mod dsp;
pub mod friction_id;
pub mod input;
pub mod iso230_2;
pub mod laser_ls;
pub mod line;
// Clippy lints left inside modelcheck/ (owner: the model-check issues): `!(x > y)` written on purpose so
// that NaN takes the refusing branch (refine.rs, spectrum.rs), and index loops over several arrays at once
// (ortho.rs, refine.rs); rustdoc reads `rss[m]` in ortho.rs as a link. Lift once rewritten.
#[allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop, rustdoc::broken_intra_doc_links)]
pub mod modelcheck;
pub mod ssi;
