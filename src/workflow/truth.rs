//! The truth as the estimate workflow sees it: plain data and functions of position, built by
//! [`crate::simulate::truth_view`] from the scenario's physics and read by [`crate::estimate`] to compare
//! its estimates with. Neither side imports the other: the simulator's types (machine, procedures,
//! sensor specs, chain model) stay behind this view.

use crate::measurement::{MeasurementSet, Run};
use std::collections::BTreeMap;
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::Axis;

/// Why a re-measurement ([`crate::estimate::Remeasure`]) failed: the simulator side's answer to the
/// estimate workflow, which sees only this type.
#[derive(Debug, thiserror::Error)]
pub enum RemeasureError {
    /// No procedure recorded the run named.
    #[error("no procedure `{0}`")]
    NoProcedure(String),
    /// The run's procedure is not a positioning procedure (a point table).
    #[error("expected a positioning procedure")]
    NotPositioning,
    /// The machine could not measure (its own error, e.g. a sensor that cannot be read).
    #[error("{0}")]
    Machine(Box<dyn std::error::Error + Send + Sync>),
}

/// What the estimate workflow may know of the truth of a recording.
pub struct TruthView<'a> {
    /// The six injected error motions of the scenario's (single) axis, functions of the axis position.
    pub motions: &'a ErrorMotions,
    /// The sensors as simulated (the truth's sensor effects applied), by name.
    pub sensors: Vec<SensorTruth>,
    /// The chain of a multi-axis scenario, None for one axis.
    pub chain: Option<ChainTruth<'a>>,
    /// The runs each procedure of the scenario recorded: procedure name → run names, from the session
    /// plan (`crate::simulate::procedure_run_names`).
    pub procedure_runs: BTreeMap<String, Vec<String>>,
    /// The noise-free point table of (run, sensor) as the simulation left the table at rest (deviations,
    /// m, one per row in the recorded row order; `vmt_sim::procedures::noise_free_point_table`), None for
    /// a time series or an unrecorded sensor.
    pub noise_free: NoiseFreeOf<'a>,
}

impl TruthView<'_> {
    /// The simulated sensor `name`.
    pub fn sensor(&self, name: &str) -> Option<&SensorTruth> {
        self.sensors.iter().find(|s| s.name == name)
    }

    /// The runs of `set` that the scenario procedure `procedure` recorded, in the set's order (none for
    /// an unknown procedure). Selected by the plan's run names, never by a name prefix: a prefix
    /// `crawl_` would also take the runs of a procedure `crawl_fast`.
    pub fn runs_of<'s>(&self, set: &'s MeasurementSet, procedure: &str) -> Vec<&'s Run> {
        let names = self.procedure_runs.get(procedure).map_or(&[][..], |v| v.as_slice());
        set.runs.iter().filter(|r| names.contains(&r.name)).collect()
    }
}

/// A sensor as simulated: the noise and instrument values a measurement-set manifest does not carry
/// (for the Cramér–Rao bounds, the SSI quantisation floor and the ISO 230-2 uncertainty statement).
#[derive(Clone, Debug, PartialEq)]
pub struct SensorTruth {
    /// The sensor's name (its column in the runs).
    pub name: String,
    /// White noise of one reading, 1σ, in the unit of the reading (m for lasers and encoders).
    pub sigma: f64,
    /// Quantisation step of a reading, same unit (0 = none).
    pub resolution: f64,
    /// One-sided white-noise density with presets filled in, reading unit per √Hz (0 = given by `sigma`).
    pub noise_density: f64,
    /// Remaining relative scale error of a laser reading from the environment: the air's refractive-index
    /// error (Edlén) plus the material's thermal expansion left uncorrected (dimensionless).
    pub environment_scale_error: f64,
}

/// (run, sensor) → the noise-free point table of [`TruthView::noise_free`].
pub type NoiseFreeOf<'a> = Box<dyn Fn(&str, &str) -> Option<Vec<f64>> + Sync + 'a>;

/// The squareness [EC0Y, EB0Z, EA0Z] (rad) that laser line sets see over given node positions (m, one
/// list per axis in chain order).
pub type SquarenessOf<'a> = Box<dyn Fn(&[Vec<f64>]) -> [f64; 3] + Sync + 'a>;

/// The injected truth of a serial chain (DESIGN.md §3, `vmc_3axis`), as the 3D laser-line check compares.
pub struct ChainTruth<'a> {
    /// The axes in chain order (bed first) and their injected error motions.
    pub axes: Vec<(Axis, &'a ErrorMotions)>,
    /// The injected squareness values [EC0Y (xy), EB0Z (xz), EA0Z (yz)], rad.
    pub squareness: [f64; 3],
    /// The squareness as laser line sets see it over the node positions of each axis (m, chain order):
    /// the injected angles plus the error motions' linear trends, [EC0Y, EB0Z, EA0Z], rad
    /// (`vmt_sim::chain::ChainModel::effective_squareness`).
    pub effective_squareness: SquarenessOf<'a>,
}

impl ChainTruth<'_> {
    /// The axes in chain order.
    pub fn axis_names(&self) -> Vec<Axis> {
        self.axes.iter().map(|a| a.0).collect()
    }
}
