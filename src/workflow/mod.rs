//! The workflows, in the order data flows through them: a scenario ([`crate::scenario`]) is simulated
//! ([`simulate`]: machine → recording, the only user of the simulator's run records), its recording is
//! estimated ([`estimate`], [`straightness`], [`byo`]) and reported ([`report`]); [`study`] repeats the
//! estimate over redrawn sensor noise. Each layer uses only the layers before it and [`crate::format`].

pub mod byo;
pub mod estimate;
pub mod report;
pub mod simulate;
pub mod straightness;
pub mod study;
