//! Workflow `simulate`: scenario → machine → recording. The procedures are planned into runs placed
//! one after another on the session clock, and the physics of each run is simulated once (in
//! parallel: each run is deterministic given its plan and start time, so the result does not depend
//! on the number of threads); the sensors then read the truth with noise seeded per run and
//! sensor (so a tolerance study can redraw the noise without redoing the physics).

use crate::error::VmtError;
use crate::measurement::{self, MeasurementSet, ProfileColumn, ProfileTable, Run, Sensor, SensorKind, UnitChoice};
use crate::model::model_to_toml;
use crate::scenario::Scenario;
use crate::workflow::truth::{ChainTruth, RemeasureError, SensorTruth, TruthView};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;
use vmt_sim::axis_sim::AxisTruth;
use vmt_sim::chain::{
    dominant_axis, plan_laser_lines, read_line, simulate_line, ChainProcedureSpec, LaserLineSpec, LaserLinesSpec,
    LinePlan, LineTruth,
};
use vmt_sim::effects::EffectName;
use vmt_sim::machine::AxisModel;
use vmt_sim::procedures::{
    noise_free_point_table, plan_procedure, plan_session, read_run, simulate_run, ProcedureSpec, RunPlan, RunRecord,
    RunTruth,
};
use vmt_sim::profile::{Profile, Term};

use vmt_sim::sensors::SensorSpec;
use vmt_sim::truth::axis_physics;

/// The machine, truth and sensors as the physics sees them: the scenario's axis model with the truth's
/// servo changes, the injected effects, and the sensors with the truth's sensor effects.
#[derive(Clone, Debug)]
pub struct Physics {
    /// The axis model with the truth's servo changes applied.
    pub model: AxisModel,
    /// The injected effects as the physics applies them (error motions, friction, drive, …).
    pub truth: AxisTruth,
    /// The sensors with the truth's sensor effects applied.
    pub sensors: Vec<SensorSpec>,
}

/// Builds the physics of a scenario from its truth.
pub fn physics(sc: &Scenario) -> Result<Physics, VmtError> {
    let mut model = sc.axis.clone();
    let (truth, adj) = axis_physics(&sc.truth.effect_set(), sc.axis_name, &model)
        .map_err(|m| VmtError::bad(&sc.source, "truth", m.to_string()))?;
    adj.apply(&mut model);
    let sensors = sc
        .sensors
        .iter()
        .map(|s| match (s.kind, adj.accel_bias_drift) {
            (SensorKind::Accelerometer, Some(rate)) => SensorSpec { bias_drift: rate, ..s.clone() },
            _ => s.clone(),
        })
        .collect();
    Ok(Physics { model, truth, sensors })
}

/// What the estimate workflow may know of the truth of `sc` simulated on `ph` (to compare its estimates
/// with): the axis's injected error motions, the sensors as simulated (their noise and instrument values,
/// for the Cramér–Rao bounds, the quantisation floor and the uncertainty statement) and, for a multi-axis
/// scenario, the chain's error motions and squareness; and the noise-free point tables of the session
/// `truths` (what an ISO 230-2 evaluation is compared with).
pub fn truth_view<'a>(sc: &'a Scenario, ph: &'a Physics, truths: &'a SessionTruth) -> TruthView<'a> {
    let sensors = ph
        .sensors
        .iter()
        .map(|s| SensorTruth {
            name: s.name.clone(),
            sigma: s.sigma,
            resolution: s.resolution,
            noise_density: s.resolved().noise_density,
            environment_scale_error: s.air_scale_error() + s.material_scale_error(),
        })
        .collect();
    let chain = sc.chain.as_ref().map(|c| ChainTruth {
        axes: c.axes.iter().map(|a| (a.axis, &a.motions)).collect(),
        squareness: c.squareness.to_array(),
        effective_squareness: Box::new(move |positions: &[Vec<f64>]| c.effective_squareness(positions).to_array()),
    });
    let noise_free = Box::new(move |run: &str, sensor: &str| {
        let rt = truths.runs.iter().find(|r| r.name == run)?;
        noise_free_point_table(&ph.model, &ph.truth, rt, &ph.sensors, sensor).ok().flatten()
    });
    TruthView {
        motions: &ph.truth.motions,
        sensors,
        chain,
        procedure_runs: procedure_run_names(sc, &ph.model),
        noise_free,
    }
}

/// The run names each procedure of the scenario records, procedure name → names in session order: the
/// session plan's names for a single-axis procedure (planned on `model`), `{procedure}_{line}` for each
/// line of a chain procedure. The estimate workflow picks a procedure's runs by them
/// ([`TruthView::runs_of`]).
pub fn procedure_run_names(sc: &Scenario, model: &AxisModel) -> BTreeMap<String, Vec<String>> {
    let mut out = BTreeMap::new();
    for p in &sc.procedures {
        if let ProcedureSpec::Pause { .. } = p {
            continue;
        }
        out.insert(p.name().to_string(), plan_procedure(model, p, sc.seed).into_iter().map(|r| r.name).collect());
    }
    for c in &sc.chain_procedures {
        let ChainProcedureSpec::LaserLines(l) = c;
        out.insert(l.name.clone(), l.lines.iter().map(|line| l.run_name(line)).collect());
    }
    out
}

/// How the compensation check's re-test is obtained ([`remeasure`]).
#[derive(Clone, Copy, Debug)]
pub enum Retest<'a> {
    /// Simulated with the table in the CNC: the exact re-test (`vmt run`, a sampled study's trials,
    /// each with its own physics).
    Simulated,
    /// Derived from the same re-test simulated once without compensation ([`uncompensated_retests`]),
    /// each sample moved to where the table's action puts the body at rest
    /// (`vmt_sim::retest::at_rest_with_compensation`: exact in the table, the positioning chain and the
    /// error motions' values; it neglects where inside one feedback count the loop settles, up to one
    /// count (1 nm on the bundled scenarios) per reading, the change of a not yet settled loop error δ
    /// with the loop gain the table alters, about |c'|·|δ|, and the settling state's change over the
    /// correction, below 1e-14 m). A study's trials of one value share the physics, so the re-test of
    /// each trial's table costs no physics (issue 12); `tests/retest.rs` holds it to [`Retest::Simulated`].
    Derived(&'a UncompensatedRetests),
}

/// The compensation check's re-tests without compensation, positioning run name → the re-test's
/// noise-free truth ([`uncompensated_retests`]).
pub type UncompensatedRetests = BTreeMap<String, RunTruth>;

/// The re-test of the positioning procedure that recorded run `run`: the procedure again at other
/// irregular targets (they derive from the procedure name, `{run}_after_compensation`; as many as
/// before), planned on `model` with `seed`.
fn retest_plan(sc: &Scenario, model: &AxisModel, seed: u64, run: &str) -> Result<RunPlan, RemeasureError> {
    let spec =
        sc.procedures.iter().find(|p| p.name() == run).ok_or_else(|| RemeasureError::NoProcedure(run.to_string()))?;
    let mut verify = spec.clone();
    let ProcedureSpec::Positioning(q) = &mut verify else {
        return Err(RemeasureError::NotPositioning);
    };
    q.n_targets = q.targets.as_ref().map_or(q.n_targets, Vec::len);
    q.targets = None;
    q.name = format!("{run}_after_compensation");
    plan_procedure(model, &verify, seed).into_iter().next().ok_or(RemeasureError::NotPositioning)
}

/// The machine of `ph` without a compensation table in its CNC.
fn uncompensated(ph: &Physics) -> AxisModel {
    AxisModel { compensation: Profile::zero(), ..ph.model.clone() }
}

/// The re-test of every positioning run a compensation check of `sc` names, simulated on the machine of
/// `ph` without compensation from session time `session_end` (s) with the scenario's seed: what
/// [`Retest::Derived`] moves to each table's compensated positions. Simulated in parallel (each run is
/// deterministic given its plan and start).
pub fn uncompensated_retests(sc: &Scenario, ph: &Physics, session_end: f64) -> Result<UncompensatedRetests, VmtError> {
    let model = uncompensated(ph);
    let mut runs: Vec<&str> = sc
        .estimators
        .iter()
        .filter_map(|e| {
            if let crate::scenario::EstimatorSpec::Compensation { run, .. } = e {
                Some(run.as_str())
            } else {
                None
            }
        })
        .collect();
    runs.sort_unstable();
    runs.dedup();
    runs.par_iter()
        .map(|run| {
            let plan = retest_plan(sc, &model, sc.seed, run)
                .map_err(|e| VmtError::bad(&sc.source, format!("estimators (compensation {run})"), e.to_string()))?;
            Ok((run.to_string(), simulate_run(&model, &ph.truth, &plan, session_end)))
        })
        .collect()
}

/// The compensation check's re-measurement (seed 004): the positioning procedure that recorded run `run`
/// run again at other irregular targets (`{run}_after_compensation`, as many as before) on the machine of
/// `ph` with the compensation table (`positions`, `corrections`, m) in its CNC, starting at session time
/// `session_end` (s; time-dependent effects have moved on during the session), read by the sensors with
/// noise seed `seed`; simulated or derived as `retest` says. The one place the estimate workflow's
/// [`crate::estimate::Remeasure`] callback reaches the physics.
#[allow(clippy::too_many_arguments)]
pub fn remeasure(
    sc: &Scenario,
    ph: &Physics,
    retest: Retest<'_>,
    seed: u64,
    session_end: f64,
    run: &str,
    positions: &[f64],
    corrections: &[f64],
) -> Result<Run, RemeasureError> {
    let table = Profile { terms: vec![Term::Table { x: positions.to_vec(), y: corrections.to_vec() }] };
    let (model, truth) = match retest {
        Retest::Simulated => {
            let model = AxisModel { compensation: table, ..ph.model.clone() };
            let plan = retest_plan(sc, &model, seed, run)?;
            let truth = simulate_run(&model, &ph.truth, &plan, session_end);
            (model, truth)
        }
        Retest::Derived(retests) => {
            let model = uncompensated(ph);
            let plain = retests.get(run).ok_or_else(|| RemeasureError::NoProcedure(run.to_string()))?;
            let truth = vmt_sim::retest::at_rest_with_compensation(&model, &ph.truth, plain, &table)
                .ok_or(RemeasureError::NotPositioning)?;
            (model, truth)
        }
    };
    let rec = read_run(&model, &ph.truth, &truth, &ph.sensors, seed).map_err(|e| RemeasureError::Machine(e.into()))?;
    Ok(run_of(sc, &rec))
}

/// The runs of every procedure of a scenario, in scenario order, with their session start times: the
/// runs follow one another from t = 0, `pause` procedures advancing the clock
/// (`vmt_sim::procedures::plan_session`).
pub fn session_plan(sc: &Scenario, ph: &Physics) -> Vec<(RunPlan, f64)> {
    plan_session(&ph.model, &sc.procedures, sc.seed)
}

/// Session time at which the last run of a session plan ends, s (0 for an empty plan).
pub fn session_end(plan: &[(RunPlan, f64)]) -> f64 {
    plan.last().map_or(0.0, |(r, t0)| t0 + r.duration())
}

/// The noise-free truth of a scenario's session: the runs of the single-axis procedures and, for a
/// multi-axis scenario, the lines of its chain procedures. Computed once; read with noise as often
/// as a study needs ([`read_all`]).
#[derive(Clone, Debug)]
pub struct SessionTruth {
    /// The noise-free runs of the single-axis procedures, in session order.
    pub runs: Vec<RunTruth>,
    /// Session time at which the last single-axis run ends, s ([`session_end`] of the plan).
    pub end: f64,
    /// (index of the chain procedure, line truth).
    pub lines: Vec<(usize, LineTruth)>,
}

/// Noise-free truth of every run of a scenario, in scenario order, and of every chain line. Runs are
/// simulated in parallel: each is deterministic given its plan and session start, so the result does
/// not depend on the number of threads.
pub fn simulate_truth(sc: &Scenario, ph: &Physics) -> SessionTruth {
    let plan = session_plan(sc, ph);
    let end = session_end(&plan);
    let runs = plan.par_iter().map(|(r, t0)| simulate_run(&ph.model, &ph.truth, r, *t0)).collect();
    SessionTruth { runs, end, lines: chain_truths(sc, end) }
}

/// Sensor readings of every run, noise seeded by `seed`: the single-axis runs, then the chain lines.
pub fn read_all(sc: &Scenario, ph: &Physics, truths: &SessionTruth, seed: u64) -> Result<Vec<RunRecord>, VmtError> {
    read_all_clean(sc, ph, truths, seed, &clean_all(sc, ph, truths)?)
}

/// The noise-free readings of every sensor of every single-axis run (`vmt_sim::procedures::clean_run`,
/// one entry per run of `truths.runs`), to be read by [`read_all_clean`] with any number of seeds.
pub fn clean_all(sc: &Scenario, ph: &Physics, truths: &SessionTruth) -> Result<Vec<Vec<Vec<f64>>>, VmtError> {
    truths
        .runs
        .iter()
        .map(|t| {
            vmt_sim::procedures::clean_run(&ph.model, &ph.truth, t, &ph.sensors)
                .map_err(|e| VmtError::bad(&sc.source, "sensors", e.to_string()))
        })
        .collect()
}

/// [`read_all`] from the runs' noise-free readings `clean` ([`clean_all`] of the same physics and truths).
pub fn read_all_clean(
    sc: &Scenario,
    ph: &Physics,
    truths: &SessionTruth,
    seed: u64,
    clean: &[Vec<Vec<f64>>],
) -> Result<Vec<RunRecord>, VmtError> {
    let mut runs = truths
        .runs
        .iter()
        .zip(clean)
        .map(|(t, c)| {
            vmt_sim::procedures::read_run_clean(&ph.model, t, &ph.sensors, seed, c)
                .map_err(|e| VmtError::bad(&sc.source, "sensors", e.to_string()))
        })
        .collect::<Result<Vec<RunRecord>, VmtError>>()?;
    runs.extend(read_chain(sc, &truths.lines, seed));
    Ok(runs)
}

/// Noise-free truth of every line of every chain procedure of a multi-axis scenario, with the index of
/// its procedure; empty for one axis. The lines follow one another on the session clock from
/// `session_start` (s: after the single-axis runs) and are simulated in parallel (each is deterministic
/// given its plan and start time).
pub fn chain_truths(sc: &Scenario, session_start: f64) -> Vec<(usize, LineTruth)> {
    let Some(chain) = &sc.chain else { return Vec::new() };
    let mut clock = session_start;
    let mut jobs: Vec<(usize, LinePlan, f64)> = Vec::new();
    for (i, p) in sc.chain_procedures.iter().enumerate() {
        let ChainProcedureSpec::LaserLines(l) = p;
        for line in plan_laser_lines(chain, l) {
            // On the recorder's clock, as the single-axis runs' starts (`recorder_time`).
            let start = vmt_sim::procedures::recorder_time(clock);
            clock += line.duration();
            jobs.push((i, line, start));
        }
    }
    jobs.par_iter().map(|(i, line, start)| (*i, simulate_line(chain, line, *start))).collect()
}

/// The laser readings of the chain lines (point tables, FORMAT.md §1), noise seeded by `seed`.
pub fn read_chain(sc: &Scenario, truths: &[(usize, LineTruth)], seed: u64) -> Vec<RunRecord> {
    let Some(chain) = &sc.chain else { return Vec::new() };
    truths
        .iter()
        .map(|(i, t)| {
            let sigma = match &sc.chain_procedures[*i] {
                ChainProcedureSpec::LaserLines(l) => l.sigma,
            };
            read_line(chain, t, sigma, seed)
        })
        .collect()
}

/// The chain line of a run name `{procedure}_{line}`: (procedure spec, line).
pub fn chain_line<'a>(sc: &'a Scenario, run: &str) -> Option<(&'a LaserLinesSpec, &'a LaserLineSpec)> {
    sc.chain_procedures.iter().find_map(|p| match p {
        ChainProcedureSpec::LaserLines(l) => l.lines.iter().find(|line| l.run_name(line) == run).map(|line| (l, line)),
    })
}

/// 1σ of one reading of a sensor as written in the manifest: white noise and quantisation combined,
/// √(σ² + q²/12); None where the noise is given as a density (it depends on the run's sample rate).
fn reading_sigma(s: &SensorSpec) -> Option<f64> {
    let s = s.resolved();
    (s.noise_density == 0.0).then(|| (s.sigma * s.sigma + s.resolution * s.resolution / 12.0).sqrt())
}

/// An accelerometer's resolved spec (preset values filled in), for the manifest's `noise_density` (the
/// white part, m/s²/√Hz) and `highpass` (AC-coupling corner, Hz); None for other sensors.
fn accel_spec(s: &SensorSpec) -> Option<SensorSpec> {
    (s.kind == SensorKind::Accelerometer).then(|| s.resolved())
}

/// The measurement set (FORMAT.md §1) of a recording.
pub fn to_measurement_set(sc: &Scenario, runs: &[RunRecord]) -> Result<MeasurementSet, VmtError> {
    let axis = sc.axis_name;
    let used = |name: &str| runs.iter().any(|r| r.data.column(name).is_some());
    let mut sensors = Vec::new();
    for s in sc.sensors.iter().filter(|s| s.kind != SensorKind::Command && used(&s.name)) {
        sensors.push(Sensor {
            name: s.name.clone(),
            kind: s.kind,
            axis,
            position: s.axis_position(&sc.axis).map_err(|e| VmtError::bad(&sc.source, "sensors", e.to_string()))?,
            direction: s.unit_direction().to_array(),
            sigma: reading_sigma(s),
            closes_loop: false,
            noise_density: accel_spec(s).map(|r| r.noise_density).filter(|&rho| rho > 0.0),
            highpass: accel_spec(s).map(|r| r.highpass),
        });
    }
    if let Some(chain) = &sc.chain {
        // Each chain line's laser: reflector on the last body at the line's point, beam along it.
        let last = chain.axes.last().map_or(sc.axis_name, |a| a.axis);
        for r in runs {
            if let Some((spec, line)) = chain_line(sc, &r.name) {
                sensors.push(Sensor {
                    name: line.name.clone(),
                    kind: SensorKind::LaserLinear,
                    axis: last,
                    position: line.point,
                    direction: line.beam().to_array(),
                    sigma: (spec.sigma > 0.0).then_some(spec.sigma),
                    closes_loop: false,
                    noise_density: None,
                    highpass: None,
                });
            }
        }
    }
    let runs = runs.iter().map(|r| run_of(sc, r)).collect();
    Ok(MeasurementSet {
        description: Some(sc.description.clone()),
        machine: Some(sc.machine_name.clone()),
        seed: Some(sc.seed),
        sensors,
        runs,
    })
}

/// A simulated run as its measurement-set run (FORMAT.md §1): the data as read, its file `NAME.csv`, the
/// axis it moves (a chain line's dominant axis; the scenario's axis otherwise).
fn run_of(sc: &Scenario, r: &RunRecord) -> Run {
    Run {
        name: r.name.clone(),
        file: format!("{}.csv", r.name),
        procedure: r.procedure,
        axis: match (&sc.chain, chain_line(sc, &r.name)) {
            (Some(chain), Some((_, line))) => dominant_axis(chain, line).unwrap_or(sc.axis_name),
            _ => sc.axis_name,
        },
        start_time: Some(r.start_time),
        feed: r.feed,
        direction: r.direction,
        data: r.data.clone(),
    }
}

/// The truth written beside a measurement set (FORMAT.md §5): `truth.toml` (the truth in the model
/// format, with any table sidecars) and `truth_profiles.csv` (the six error motions every millimetre
/// over the travel, in `units` like the set's runs).
pub fn truth_extras(sc: &Scenario, ph: &Physics, units: UnitChoice) -> Result<Vec<(String, Vec<u8>)>, VmtError> {
    let (toml_text, sidecars) = model_to_toml(&sc.truth, "truth")?;
    let mut out = vec![("truth.toml".to_string(), toml_text.into_bytes())];
    out.extend(sidecars.into_iter().map(|(n, t)| (n, t.into_bytes())));
    let table = truth_profiles(sc, ph)?;
    let csv = measurement::profiles_csv(&table, Path::new("truth_profiles.csv"), units)?;
    out.push(("truth_profiles.csv".to_string(), csv.into_bytes()));
    Ok(out)
}

/// Most points of a truth profile (size budget, DESIGN.md §2): 1 mm steps up to a 10 m travel.
pub const MAX_PROFILE_POINTS: usize = 10_001;

/// Positions of a truth profile over [lo, hi] (m): every millimetre, but at most
/// [`MAX_PROFILE_POINTS`] points evenly spread (a 1000 m URDF travel gets 10 cm steps, not 10⁶ points),
/// each on the 1 pm grid of written positions.
fn profile_positions(lo: f64, hi: f64) -> Vec<f64> {
    // clamp: constant bounds, 1 ≤ MAX_PROFILE_POINTS − 1.
    let n = ((hi - lo) / 1e-3).round().clamp(1.0, (MAX_PROFILE_POINTS - 1) as f64);
    // index: n is clamped to [1, MAX_PROFILE_POINTS − 1] above, and NaN becomes 1 here: a bounded point count.
    let n = if n.is_finite() { n as usize } else { 1 };
    // On the 1 pm grid: the truth is evaluated at the position written (0.003, not 0.0030000000000000005).
    (0..=n).map(|i| vmt_sim::motion::on_position_grid(lo + (hi - lo) * i as f64 / n as f64)).collect()
}

/// The six injected error motions every millimetre over the travel (FORMAT.md §5 table), from the
/// physics `ph` built once by the caller; for a multi-axis scenario the six of every axis of the chain,
/// prefixed by the axis (`y.pitch`), every millimetre from the lowest lower to the highest upper travel
/// end of the axes.
pub fn truth_profiles(sc: &Scenario, ph: &Physics) -> Result<ProfileTable, VmtError> {
    if let Some(chain) = &sc.chain {
        let lo = chain.travels().iter().map(|t| t.0).fold(f64::INFINITY, f64::min);
        let hi = chain.travels().iter().map(|t| t.1).fold(f64::NEG_INFINITY, f64::max);
        let position = profile_positions(lo, hi);
        let mut columns = Vec::new();
        for a in &chain.axes {
            for (i, &effect) in EffectName::ERROR_MOTIONS.iter().enumerate() {
                columns.push(ProfileColumn {
                    axis: Some(a.axis),
                    effect,
                    values: position.iter().map(|&x| a.motions.by_index(i).value(x)).collect(),
                    sigma: None,
                });
            }
        }
        return Ok(ProfileTable { position, columns });
    }
    let errors = &ph.truth.motions;
    let (lo, hi) = sc.axis.travel;
    let position = profile_positions(lo, hi);
    let columns = EffectName::ERROR_MOTIONS
        .iter()
        .enumerate()
        .map(|(i, &effect)| ProfileColumn {
            axis: None,
            effect,
            values: position.iter().map(|&x| errors.by_index(i).value(x)).collect(),
            sigma: None,
        })
        .collect();
    Ok(ProfileTable { position, columns })
}
