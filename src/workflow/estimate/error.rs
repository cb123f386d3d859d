//! The typed error of the laser-line glue (one axis, [`super::laser_lines`]; a chain, [`super::chain`]):
//! why a measurement set's lines cannot be identified. It names the run, column, sensor or axis at
//! fault; the caller, which knows the file, turns it into a [`crate::error::VmtError::BadInput`].

use vmt_estimators::laser_ls::LaserLsError;
use vmt_sim::Axis;

/// Why the laser lines of a measurement set cannot be identified.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LineSetError {
    /// A run named on the command line is not in the set.
    #[error("no run named `{0}`")]
    NoRun(String),
    /// The run is a time series, the identifier needs a point table.
    #[error("run `{0}` is not a point table")]
    NotPointTable(String),
    /// No run of the set is a point table with two laser lines or more.
    #[error("expected a point-table run with at least two laser lines")]
    NoLineSetRun,
    /// A run lacks a column the identification needs (a laser line or an axis command `x_cmd`).
    #[error("run `{run}` has no column `{column}`")]
    NoColumn {
        /// The run.
        run: String,
        /// The missing column.
        column: String,
    },
    /// A point table lacks the column of one of its laser lines.
    #[error("no column `{0}`")]
    NoLineColumn(String),
    /// A laser line names a sensor the manifest does not declare.
    #[error("sensor `{0}` is not declared")]
    UndeclaredSensor(String),
    /// The 21-error identification weighs each line by its manifest `sigma`, which is missing.
    #[error("sensor `{0}`: the 21-error identification needs the laser's `sigma` in the manifest")]
    NoSigma(String),
    /// A line without a manifest `sigma` has too few repeated readings to estimate it.
    #[error(
        "laser line `{line}` has no sigma in the manifest and its readings ({runs} run(s)) give {dof} degrees of \
         freedom of repeats, fewer than the {needed} needed to estimate it: give `sigma` for the sensor (the \
         weights and every standard error depend on it)"
    )]
    TooFewRepeats {
        /// The line (sensor) name.
        line: String,
        /// Runs in the table.
        runs: usize,
        /// Degrees of freedom of the repeats.
        dof: usize,
        /// Degrees of freedom needed.
        needed: usize,
    },
    /// The runs hold no laser-line reading at all.
    #[error("no laser-line readings in the runs")]
    NoReadings,
    /// Every line stops at the same position of an axis: its error motions have one node.
    #[error("the lines stop at only one position of axis {0}: at least two are needed")]
    OnePosition(Axis),
    /// The identifier refused the readings (rank, SVD).
    #[error("{0}")]
    Identifier(#[from] LaserLsError),
    /// The error of one run, prefixed with its name.
    #[error("run {run}: {source}")]
    InRun {
        /// The run.
        run: String,
        /// What went wrong in it.
        #[source]
        source: Box<LineSetError>,
    },
}
