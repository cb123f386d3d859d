//! The workflows, in the order data flows through them: a scenario ([`crate::scenario`]) is simulated
//! ([`simulate`]: machine → recording, the only user of the simulator's run records) into a measurement set
//! and a [`truth`] view; the estimate workflow ([`estimate`]: one adapter per estimator, the file commands
//! share them; [`byo`] for estimators of one's own) turns them into checks and figures, which [`report`]
//! lays out; [`run`] joins simulate and estimate for `vmt run`, and [`study`] repeats it over redrawn
//! sensor noise. Each layer uses only the layers before it and [`crate::format`]; `estimate` sees neither
//! the scenario nor the physics (a test in it checks this).

pub mod byo;
pub mod estimate;
pub mod report;
pub mod run;
pub mod simulate;
pub mod study;
pub mod truth;
