//! The `vmt run` pipeline in one place: a scenario's recording, simulated ([`crate::simulate`]), handed to
//! the estimate workflow ([`crate::estimate`]) as a measurement set, a truth view and a re-measurement
//! callback. `vmt run`, a study's trials and the benchmarks go through [`estimate_session`].

use crate::error::VmtError;
use crate::estimate::chain::{identify_chain_runs, ChainIdentification, LineSigma};
use crate::estimate::{estimate_recording, Estimates};
use crate::measurement::MeasurementSet;
use crate::scenario::Scenario;
use crate::simulate::{procedure_run_names, remeasure, to_measurement_set, truth_view, Physics, Retest, SessionTruth};
use vmt_sim::procedures::RunRecord;

/// Runs every estimator of `sc` on its recording `set`, read from the session `truths` simulated on `ph`
/// (the truth view compared with), the compensation check re-measuring on `ph` from the session's end
/// with the scenario's seed, its re-test simulated or derived as `retest` says (`vmt run` simulates it;
/// a study's trials derive it from the re-test without compensation simulated once per value).
pub fn estimate_session(
    sc: &Scenario,
    ph: &Physics,
    truths: &SessionTruth,
    set: &MeasurementSet,
    retest: Retest<'_>,
) -> Result<Estimates, VmtError> {
    let again = |run: &str, x: &[f64], y: &[f64]| remeasure(sc, ph, retest, sc.seed, truths.end, run, x, y);
    estimate_recording(&sc.source, &sc.estimators, &truth_view(sc, ph, truths), set, &again)
}

/// Runs every estimator of a scenario on its recording `runs` (read from the session `truths`) and
/// returns the checks with their figures: [`estimate_session`] on the measurement set written from `runs`,
/// the compensation re-test simulated.
pub fn run_estimators(
    sc: &Scenario,
    ph: &Physics,
    truths: &SessionTruth,
    runs: &[RunRecord],
) -> Result<Estimates, VmtError> {
    let set = to_measurement_set(sc, runs)?;
    estimate_session(sc, ph, truths, &set, Retest::Simulated)
}

/// The 21-error identification of the chain procedure `procedure`'s laser lines in the simulated runs
/// `runs` of a multi-axis scenario, as `vmt run`'s 3D check makes it (the axes in chain order, a line of
/// σ = 0 weighted as 1e-12 m).
pub fn identify_chain_lines(
    sc: &Scenario,
    runs: &[RunRecord],
    procedure: &str,
) -> Result<ChainIdentification, VmtError> {
    let bad = |m: String| VmtError::bad(&sc.source, format!("chain procedure `{procedure}`"), m);
    let chain = sc.chain.as_ref().ok_or_else(|| bad("needs a multi-axis scenario (axes = [...])".into()))?;
    let set = to_measurement_set(sc, runs)?;
    let names = procedure_run_names(sc, &sc.axis).remove(procedure).unwrap_or_default();
    let lines: Vec<_> = set.runs.iter().filter(|r| names.contains(&r.name)).collect();
    if lines.is_empty() {
        return Err(bad("no laser-line runs".into()));
    }
    identify_chain_runs(&set, lines, &chain.axis_names(), LineSigma::AtLeast(1e-12))
        .map(|(_, ci)| ci)
        .map_err(|e| bad(e.to_string()))
}
