//! Scenarios (`vmt-scenario/1`, FORMAT.md §3): a machine, a truth (the injected effects, in the model
//! format), the sensors and their noise, the procedures to run, and the estimators with the tolerance
//! each estimate must meet. Every bundled scenario documents its keys in comments.

pub mod spec;

use crate::bundled;
use crate::error::VmtError;
use crate::model::{self, Model};
use serde::Deserialize;
pub use spec::EstimatorSpec;
use std::path::{Path, PathBuf};
use vmt_sim::chain::{ChainModel, ChainProcedureSpec};
use vmt_sim::effects::EffectName;
use vmt_sim::machine::{AxisConfig, AxisModel, Fidelity, MachineError};
use vmt_sim::procedures::{ProcedureSpec, COMMAND_COLUMN, MAX_SAMPLES, MAX_STEPS};
use vmt_sim::sensors::{SensorKind, SensorSpec};
use vmt_sim::urdf::{parse_urdf, MachineStructure, UrdfError};
use vmt_sim::Axis;

/// The scenario file as written (before the truth is parsed and the machine loaded).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    format: String,
    #[serde(default)]
    description: String,
    seed: u64,
    machine: String,
    #[serde(default)]
    axis: AxisConfig,
    /// Integrator of the moving bodies: "reference" (rapier3d-f64, default) or "fast".
    #[serde(default)]
    fidelity: Fidelity,
    truth: toml::Value,
    #[serde(default)]
    sensors: Vec<SensorSpec>,
    #[serde(default)]
    procedures: Vec<ProcedureSpec>,
    #[serde(default)]
    estimators: Vec<EstimatorSpec>,
    /// Multi-axis scenario (issue 3): the prismatic joints of the chain in order from the bed, e.g.
    /// `["x", "y", "z"]`, each simulated with the shared `[axis]` config (its `joint` replaced).
    #[serde(default)]
    axes: Option<Vec<String>>,
    /// Multi-axis scenario: the tool link, the measuring reference point (default `"tool"`).
    #[serde(default)]
    tool: Option<String>,
    /// Procedures on the whole chain (`kind = "laser_lines"`), multi-axis scenarios only.
    #[serde(default)]
    chain_procedures: Vec<ChainProcedureSpec>,
}

/// A loaded, validated scenario.
#[derive(Clone, Debug)]
pub struct Scenario {
    /// Where it came from (a path, or the bundled default's source path).
    pub source: PathBuf,
    /// Free text describing the scenario.
    pub description: String,
    /// Seed of every noise stream of the session.
    pub seed: u64,
    /// Machine name as written (bundled name or URDF path) and its structure.
    pub machine_name: String,
    /// The machine's links and joints (from the URDF).
    pub machine: MachineStructure,
    /// The simulated axis: masses, drive, servo and guideway settings (SI units).
    pub axis: AxisModel,
    /// Which axis that is: the last letter of its joint's name (`x` → X), the axis its effects and
    /// recordings are on.
    pub axis_name: Axis,
    /// The injected truth: the effects switched on and their parameters.
    pub truth: Model,
    /// The sensors, in the order of the scenario file.
    pub sensors: Vec<SensorSpec>,
    /// The single-axis procedures, in session order.
    pub procedures: Vec<ProcedureSpec>,
    /// The estimators to run on the recording, each with its tolerance.
    pub estimators: Vec<EstimatorSpec>,
    /// Multi-axis scenarios (`axes = [...]`): the chain of axes with the truth injected.
    pub chain: Option<ChainModel>,
    /// Procedures on the chain (`[[chain_procedures]]`).
    pub chain_procedures: Vec<ChainProcedureSpec>,
}

impl Scenario {
    /// The bundled default scenario.
    pub fn bundled_default() -> Result<Scenario, VmtError> {
        Scenario::parse(bundled::DEFAULT_SCENARIO, Path::new(bundled::DEFAULT_SCENARIO_PATH), None)
    }

    /// Reads a scenario file.
    pub fn load(path: &Path) -> Result<Scenario, VmtError> {
        let text = std::fs::read_to_string(path).map_err(|e| VmtError::io(path, "reading the scenario", e))?;
        Scenario::parse(&text, path, path.parent())
    }

    /// Parses scenario text; `base` is the directory relative paths are resolved against (None: only
    /// bundled machines and inline truths are allowed).
    pub fn parse(text: &str, source: &Path, base: Option<&Path>) -> Result<Scenario, VmtError> {
        let mut raw: RawScenario = toml::from_str(text).map_err(|e| {
            let place = e.span().map(|s| {
                let (line, col) = crate::error::line_col(text, s.start);
                format!("line {line}, column {col}")
            });
            VmtError::bad(source, place.unwrap_or_default(), e.message().to_string())
        })?;
        let bad = |place: &str, msg: String| VmtError::bad(source, place, msg);
        if raw.format != "vmt-scenario/1" {
            return Err(bad("format", format!("expected \"vmt-scenario/1\", got \"{}\"", raw.format)));
        }
        raw.axis.fidelity = raw.fidelity;
        let base_dir = base.map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
        let machine = load_machine(&raw.machine, base, source)?;
        let axis_cfg = match raw.axes.as_deref() {
            Some([first, ..]) => AxisConfig { joint: first.clone(), ..raw.axis.clone() },
            _ => raw.axis.clone(),
        };
        let axis = AxisModel::build(&machine, &axis_cfg).map_err(|e| match e {
            MachineError::Key(_, k, m) => bad(&format!("axis.{k}"), m),
            MachineError::NoJoint(..) | MachineError::Invalid(..) => bad("axis", e.to_string()),
        })?;
        let truth = match &raw.truth {
            toml::Value::String(file) => model::read_model(&base_dir.join(file))?,
            toml::Value::Table(t) => model::parse_model(t, source, &base_dir, "truth")?,
            _ => return Err(bad("truth", "expected a table (inline truth) or a file name".into())),
        };
        truth.check_error_motion_sizes("truth", "travel", |_| Some(axis.travel)).map_err(|(p, m)| bad(&p, m))?;
        validate_sensors(&raw.sensors, &axis).map_err(|(p, m)| bad(&p, m))?;
        for (i, e) in raw.estimators.iter().enumerate() {
            e.check().map_err(|(k, m)| bad(&format!("estimators[{i}].{k}"), m))?;
        }
        validate_procedures(&raw.procedures, &raw.sensors, &axis).map_err(|(p, m)| bad(&p, m))?;
        let chain = build_chain(&raw, &machine, &truth).map_err(|(p, m)| bad(&p, m))?;
        // A chain's joints are checked above (`axes[i]`); a single axis's joint here.
        let axis_name = Axis::of_joint(&axis_cfg.joint).ok_or_else(|| {
            bad(
                "axis.joint",
                format!(
                    "expected a prismatic joint named for its axis x, y or z (its name's last letter), got `{}`",
                    axis_cfg.joint
                ),
            )
        })?;
        Ok(Scenario {
            source: source.to_path_buf(),
            description: raw.description,
            seed: raw.seed,
            machine_name: raw.machine,
            machine,
            axis,
            axis_name,
            truth,
            sensors: raw.sensors,
            procedures: raw.procedures,
            estimators: raw.estimators,
            chain,
            chain_procedures: raw.chain_procedures,
        })
    }
}

/// The chain of a multi-axis scenario (None without `axes`), with its procedures checked; a
/// single-axis scenario may not carry squareness, `tool` or chain procedures. Returns the key path
/// and message of the first problem.
fn build_chain(
    raw: &RawScenario,
    machine: &MachineStructure,
    truth: &Model,
) -> Result<Option<ChainModel>, (String, String)> {
    let set = truth.effect_set();
    let Some(axes) = &raw.axes else {
        if let Some(e) = set
            .effects
            .iter()
            .find(|e| matches!(e.name, EffectName::SquarenessXy | EffectName::SquarenessXz | EffectName::SquarenessYz))
        {
            return Err((
                format!("truth.effects.{}", e.name),
                "squareness is an angle between two axes: it needs a multi-axis scenario (axes = [\"x\", \"y\", \"z\"] on a machine such as vmc_3axis)".into(),
            ));
        }
        if !raw.chain_procedures.is_empty() {
            return Err((
                "chain_procedures".into(),
                "chain procedures need a multi-axis scenario (axes = [...])".into(),
            ));
        }
        if raw.tool.is_some() {
            return Err(("tool".into(), "`tool` belongs to a multi-axis scenario (axes = [...])".into()));
        }
        return Ok(None);
    };
    if axes.is_empty() || axes.len() > 3 {
        return Err(("axes".into(), format!("expected 1 to 3 axes, e.g. [\"x\", \"y\", \"z\"], got {}", axes.len())));
    }
    for (i, a) in axes.iter().enumerate() {
        if Axis::of_joint(a).is_none() || machine.axis_by_joint(a).is_none() {
            let known: Vec<&str> = machine.axes.iter().map(|j| j.joint.as_str()).collect();
            return Err((
                format!("axes[{i}]"),
                format!(
                    "unknown axis `{a}`: expected a prismatic joint of the machine named for its axis x, y or z ({})",
                    known.join(", ")
                ),
            ));
        }
    }
    let letters: Vec<Axis> = axes.iter().filter_map(|a| Axis::of_joint(a)).collect();
    if let Some(e) = set.effects.iter().find(|e| {
        !matches!(e.name, EffectName::SquarenessXy | EffectName::SquarenessXz | EffectName::SquarenessYz)
            && !letters.contains(&e.axis)
    }) {
        return Err((
            format!("truth.effects.{}", e.name),
            format!(
                "effect on axis {}, which is not in the chain (axes = {axes:?}): expected one of {}",
                e.axis,
                letters.iter().map(|c| c.to_string()).collect::<Vec<_>>().join(", ")
            ),
        ));
    }
    let configs: Vec<AxisConfig> = axes.iter().map(|a| AxisConfig { joint: a.clone(), ..raw.axis.clone() }).collect();
    let tool = raw.tool.as_deref().unwrap_or("tool");
    let chain = ChainModel::build(machine, &configs, &set, tool).map_err(|e| ("axes".to_string(), e.to_string()))?;
    for (i, p) in raw.chain_procedures.iter().enumerate() {
        let at = |k: &str| procedure_place("chain_procedures", i, p.name(), k);
        if raw.chain_procedures[..i].iter().any(|o| o.name() == p.name())
            || raw.procedures.iter().any(|o| o.name() == p.name())
        {
            return Err((at("name"), "procedure names must be unique".into()));
        }
        match p {
            ChainProcedureSpec::LaserLines(l) => l.check(&chain).map_err(|(k, m)| (at(&k), m))?,
        }
    }
    Ok(Some(chain))
}

/// Loads a machine by bundled name or URDF path (relative to `base`).
pub fn load_machine(name: &str, base: Option<&Path>, source: &Path) -> Result<MachineStructure, VmtError> {
    let (text, file) = match bundled::machine_urdf(name) {
        Some(t) => (t.to_string(), PathBuf::from(format!("urdf/{name}.urdf"))),
        None => {
            let p = base.map(|b| b.join(name)).unwrap_or_else(|| PathBuf::from(name));
            if !p.exists() {
                return Err(VmtError::bad(
                    source,
                    "machine",
                    format!(
                        "`{name}` is neither a bundled machine ({}) nor an existing URDF file ({})",
                        bundled::MACHINES.join(", "),
                        p.display()
                    ),
                ));
            }
            (std::fs::read_to_string(&p).map_err(|e| VmtError::io(&p, "reading the URDF", e))?, p)
        }
    };
    parse_urdf(&text).map_err(|e| {
        // The line of the named link or joint, where the URDF error names one.
        let named = match &e {
            UrdfError::Link { link: n, .. } | UrdfError::Joint { joint: n, .. } => Some(n.as_str()),
            UrdfError::Parse(_) | UrdfError::Structure(_) => None,
        };
        let place = named
            .and_then(|n| text.find(&format!("name=\"{n}\"")))
            .map(|pos| format!("line {}", crate::error::line_col(&text, pos).0))
            .unwrap_or_else(|| "robot".into());
        VmtError::bad(&file, place, e.to_string())
    })
}

fn finite_nonneg(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}

/// A positioning dwell: dwell > 0, 0 < average ≤ dwell, rate > 0, overrun ≥ 0.
fn dwell_ok(dwell: f64, average: f64, rate: f64, overrun: f64) -> bool {
    dwell > 0.0 && average > 0.0 && average <= dwell && rate > 0.0 && finite_nonneg(overrun)
}

/// Checks sensor values; returns the key path and message of the first problem.
pub(crate) fn validate_sensors(sensors: &[SensorSpec], axis: &AxisModel) -> Result<(), (String, String)> {
    for (i, s) in sensors.iter().enumerate() {
        let at = |k: &str| format!("sensors[{i}] ({}).{k}", s.name);
        if s.name.is_empty()
            || s.name.contains(['[', ']', ',', '"'])
            || s.name == "t"
            || s.name == COMMAND_COLUMN && s.kind != SensorKind::Command
        {
            return Err((at("name"), "expected a column name without brackets, commas or quotes, not `t`".into()));
        }
        if sensors[..i].iter().any(|o| o.name == s.name) {
            return Err((at("name"), "sensor names must be unique".into()));
        }
        for (k, v) in [
            ("sigma", s.sigma),
            ("resolution", s.resolution),
            ("noise_density", s.noise_density),
            ("highpass", s.highpass),
        ] {
            if !finite_nonneg(v) {
                return Err((at(k), format!("expected a finite value ≥ 0, got {v}")));
            }
        }
        if !s.bias.is_finite() || !s.scale_factor.is_finite() || s.scale_factor.abs() >= 0.5 {
            return Err((
                at("scale_factor"),
                format!("expected bias finite and |scale_factor| < 0.5, got {} and {}", s.bias, s.scale_factor),
            ));
        }
        let temps = [Some(s.material_temperature), s.assumed_material_temperature];
        if !temps.iter().flatten().all(|t| t.is_finite() && (-50.0..=150.0).contains(t)) {
            return Err((
                at("material_temperature"),
                format!("expected temperatures in °C within −50…150, got {temps:?}"),
            ));
        }
        if !(s.material_alpha.is_finite() && s.material_alpha.abs() < 1e-3) {
            return Err((
                at("material_alpha"),
                format!("expected an expansion coefficient |α| < 1e-3 1/K, got {}", s.material_alpha),
            ));
        }
        if let Some(p) = s.position {
            if !p.iter().all(|v| v.is_finite() && v.abs() < 100.0) {
                return Err((at("position"), format!("expected a point within 100 m, got {p:?}")));
            }
        }
        if !s.direction.iter().all(|v| v.is_finite()) || s.unit_direction().length() < 0.5 {
            return Err((at("direction"), format!("expected a non-zero finite direction, got {:?}", s.direction)));
        }
        s.mount(axis).map_err(|e| (at("link"), e.to_string()))?;
    }
    Ok(())
}

/// Checks procedure values against the axis (travel, feed) and the declared sensors.
fn validate_procedures(
    procs: &[ProcedureSpec],
    sensors: &[SensorSpec],
    axis: &AxisModel,
) -> Result<(), (String, String)> {
    let (lo, hi) = axis.travel;
    let tol = 1e-9;
    let (mut samples, mut steps) = (0.0, 0.0);
    for (i, p) in procs.iter().enumerate() {
        let at = |k: &str| procedure_place("procedures", i, p.name(), k);
        if !p.name().is_empty() && procs[..i].iter().any(|o| o.name() == p.name()) {
            return Err((at("name"), "procedure names must be unique".into()));
        }
        let (n, s) = p.budget(axis.dt, axis.max_accel).map_err(|(k, m)| (at(&k), m))?;
        samples += n;
        steps += s;
        if samples > MAX_SAMPLES as f64 || steps > MAX_STEPS {
            return Err((
                at("name"),
                format!(
                    "the procedures up to this one record about {samples:.3e} samples over {steps:.3e} physics steps; \
                     the limits for a scenario are {MAX_SAMPLES:e} samples and {MAX_STEPS:e} steps"
                ),
            ));
        }
        for s in p.sensors() {
            if !sensors.iter().any(|d| &d.name == s) {
                return Err((at("sensors"), format!("sensor `{s}` is not declared under [[sensors]]")));
            }
        }
        let in_travel = |k: &str, x: f64| {
            if x.is_finite() && x >= lo - tol && x <= hi + tol {
                Ok(())
            } else {
                Err((at(k), format!("expected a position within the travel [{lo}, {hi}] m, got {x}")))
            }
        };
        let feed_ok = |k: &str, v: f64| {
            if v.is_finite() && v > 0.0 && v <= axis.max_feed + tol {
                Ok(())
            } else {
                Err((at(k), format!("expected a feed in (0, {}] m/s, got {v}", axis.max_feed)))
            }
        };
        match p {
            ProcedureSpec::ConstantVelocity { speeds, start, end, high_rate, settle, .. } => {
                in_travel("start", *start)?;
                in_travel("end", *end)?;
                if speeds.is_empty() {
                    return Err((at("speeds"), "expected at least one speed".into()));
                }
                for v in speeds {
                    feed_ok("speeds", *v)?;
                }
                // start and end are finite here (in_travel).
                let rate_ok = high_rate.is_finite() && *high_rate > 0.0;
                if !rate_ok || end <= start || !finite_nonneg(*settle) {
                    return Err((at("high_rate"), "expected high_rate > 0, end > start and settle ≥ 0".into()));
                }
            }
            ProcedureSpec::Positioning(q) => {
                in_travel("start", q.start)?;
                in_travel("end", q.end)?;
                feed_ok("feed", q.feed)?;
                if let Some(t) = &q.targets {
                    for x in t {
                        in_travel("targets", *x)?;
                    }
                    if t.len() < 2 || t.windows(2).any(|w| w[1] <= w[0]) {
                        return Err((at("targets"), "expected at least two strictly increasing targets".into()));
                    }
                } else if q.n_targets < 2 {
                    return Err((at("n_targets"), format!("expected at least 2 targets, got {}", q.n_targets)));
                }
                if q.accel.is_some_and(|a| !(a > 0.0 && a.is_finite())) {
                    return Err((at("accel"), format!("expected an acceleration > 0 m/s², got {:?}", q.accel)));
                }
                if q.runs < 1 || q.end <= q.start || !dwell_ok(q.dwell, q.average, q.rate, q.overrun) {
                    return Err((
                        at("dwell"),
                        "expected runs ≥ 1, end > start, dwell > 0, 0 < average ≤ dwell, rate > 0, overrun ≥ 0".into(),
                    ));
                }
            }
            ProcedureSpec::Crawl { feeds, start, duration, rate, settle, .. } => {
                in_travel("start", *start)?;
                if feeds.is_empty() {
                    return Err((at("feeds"), "expected at least one feed".into()));
                }
                for v in feeds {
                    feed_ok("feeds", *v)?;
                    in_travel("feeds", start + v * (settle + duration + 1.0))?;
                }
                if !(*duration > 0.0 && *rate > 0.0 && finite_nonneg(*settle)) {
                    return Err((at("duration"), "expected duration > 0, rate > 0 and settle ≥ 0".into()));
                }
            }
            ProcedureSpec::FrictionSweep { .. } => p.check(axis).map_err(|e| (at("speeds"), e.to_string()))?,
            ProcedureSpec::NineLine { start, end, step, feed, dwell, average, rate, overrun, .. } => {
                in_travel("start", *start)?;
                in_travel("end", *end)?;
                feed_ok("feed", *feed)?;
                if step.is_nan() || *step <= 0.0 || end <= start || !dwell_ok(*dwell, *average, *rate, *overrun) {
                    return Err((
                        at("step"),
                        "expected step > 0, end > start, dwell > 0, 0 < average ≤ dwell, rate > 0, overrun ≥ 0".into(),
                    ));
                }
            }
            ProcedureSpec::Pause { duration, .. } => {
                if !finite_nonneg(*duration) {
                    return Err((at("duration"), format!("expected a pause of ≥ 0 s, got {duration}")));
                }
            }
        }
    }
    Ok(())
}

/// The place of a procedure's key in messages: `procedures[1] (iso).dwell`; an empty key blames the
/// procedure as a whole (e.g. its machine time, which several keys set).
fn procedure_place(list: &str, i: usize, name: &str, key: &str) -> String {
    if key.is_empty() {
        format!("{list}[{i}] ({name})")
    } else {
        format!("{list}[{i}] ({name}).{key}")
    }
}
