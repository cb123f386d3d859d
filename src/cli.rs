//! The commands of the `vmt` binary as library functions (so tests can call them): each parses its
//! inputs, runs a workflow and prints. They return the process exit code or a `VmtError` (exit 2 for
//! bad input).

use crate::error::VmtError;
use crate::estimate::{run_estimators, Check, Quantity};
use crate::measurement::{self, MeasurementSet, SensorKind, UnitChoice};
use crate::scenario::Scenario;
use crate::simulate::{physics, read_all, simulate_truth, to_measurement_set, truth_extras};
use std::path::{Path, PathBuf};

/// Loads the scenario at `path`, or the bundled default.
pub fn load_scenario(path: Option<&Path>) -> Result<Scenario, VmtError> {
    match path {
        Some(p) => Scenario::load(p),
        None => Scenario::bundled_default(),
    }
}

/// Simulates a scenario and returns its measurement set.
pub fn simulate_set(sc: &Scenario) -> Result<MeasurementSet, VmtError> {
    let ph = physics(sc)?;
    let truths = simulate_truth(sc, &ph);
    let runs = read_all(sc, &ph, &truths, sc.seed)?;
    to_measurement_set(sc, &runs)
}

/// `vmt simulate [SCENARIO] -o DIR`: writes the measurement set with the truth beside it.
pub fn simulate(path: Option<&Path>, out: &Path, units: &str) -> Result<(), VmtError> {
    let units = parse_units(units)?;
    let sc = load_scenario(path)?;
    let set = simulate_set(&sc)?;
    measurement::write_with_extras(&set, out, units, &truth_extras(&sc)?)?;
    eprintln!("wrote {} runs to {}", set.runs.len(), out.display());
    Ok(())
}

fn parse_units(units: &str) -> Result<UnitChoice, VmtError> {
    match units {
        "si" => Ok(UnitChoice::Si),
        "human" | "metrology" => Ok(UnitChoice::Metrology),
        other => Err(VmtError::Usage(format!("--units: expected `si` or `human`, got `{other}`"))),
    }
}

/// Default output directory of `vmt run`: vmt-out/<scenario file stem>.
fn default_out(sc: &Scenario) -> PathBuf {
    let stem = sc.source.file_stem().and_then(|s| s.to_str()).unwrap_or("scenario");
    PathBuf::from("vmt-out").join(stem)
}

/// `vmt run [SCENARIO]`: simulate, estimate, print the table; exit 1 if any estimate misses its tolerance.
pub fn run(path: Option<&Path>, out: Option<&Path>, json: bool) -> Result<i32, VmtError> {
    let sc = load_scenario(path)?;
    let ph = physics(&sc)?;
    let truths = simulate_truth(&sc, &ph);
    let runs = read_all(&sc, &ph, &truths, sc.seed)?;
    let set = to_measurement_set(&sc, &runs)?;
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| default_out(&sc));
    measurement::write_with_extras(&set, &out.join("data"), UnitChoice::Si, &truth_extras(&sc)?)?;
    let checks = run_estimators(&sc, &runs, &ph.truth.motions)?;
    let failed: Vec<&Check> = checks.iter().filter(|c| !c.pass).collect();
    if json {
        let v = serde_json::json!({"scenario": sc.source, "checks": checks, "pass": failed.is_empty()});
        println!("{}", serde_json::to_string_pretty(&v).map_err(|e| VmtError::Internal(e.to_string()))?);
    } else {
        println!("vmt run: {} — {}", sc.source.display(), sc.description);
        println!("{}", summary_table(&set));
        println!("{}", check_table(&checks));
        println!("measurement set: {}", out.join("data").display());
        if failed.is_empty() {
            println!("all {} estimates within tolerance", checks.len());
        } else {
            println!(
                "{} of {} estimates missed their tolerance: {}",
                failed.len(),
                checks.len(),
                failed.iter().map(|c| c.error.as_str()).collect::<Vec<_>>().join(", ")
            );
        }
    }
    Ok(if failed.is_empty() { 0 } else { 1 })
}

/// Value in display units: µm for lengths, µrad for angles.
fn display(q: Quantity, v: f64) -> String {
    match q {
        Quantity::Length => format!("{:.3} µm", v * 1e6),
        Quantity::Angle => format!("{:.3} µrad", v * 1e6),
        Quantity::Ratio => format!("{v:.3}"),
    }
}

/// The table of checks: error, injected, recovered, difference, tolerance, pass.
pub fn check_table(checks: &[Check]) -> String {
    let mut s = format!(
        "{:<34} {:>14} {:>14} {:>14} {:>14}  {}\n",
        "error", "injected", "recovered", "difference", "tolerance", "pass"
    );
    for c in checks {
        s += &format!(
            "{:<34} {:>14} {:>14} {:>14} {:>14}  {}\n",
            c.error,
            display(c.quantity, c.injected),
            display(c.quantity, c.recovered),
            display(c.quantity, c.difference),
            display(c.quantity, c.tolerance),
            if c.pass { "pass" } else { "FAIL" }
        );
    }
    s
}

/// What was measured: per run, its procedure, samples and the RMS of each channel.
pub fn summary_table(set: &MeasurementSet) -> String {
    let mut s = format!("{:<16} {:<18} {:>8}  channels (RMS)\n", "run", "procedure", "samples");
    for r in &set.runs {
        let chans: Vec<String> = r
            .data
            .columns()
            .iter()
            .filter(|(n, _)| n != "x_cmd")
            .map(|(n, v)| {
                let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
                let rms = (v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / v.len().max(1) as f64).sqrt();
                format!("{n} {rms:.3e}")
            })
            .collect();
        s += &format!("{:<16} {:<18} {:>8}  {}\n", r.name, r.procedure.as_str(), r.data.len(), chans.join(", "));
    }
    s
}

/// `vmt iso230-2 PATH`: ISO 230-2 evaluation of a positioning test, from a measurement set directory
/// (a point-table run and one of its deviation columns) or from an ecmc `.dat` file (key=value format).
pub fn iso230_2(path: &Path, run: Option<&str>, sensor: Option<&str>, json: bool) -> Result<i32, VmtError> {
    use vmt_estimators::iso230_2::{dat::parse_dat, evaluate_bidirectional};
    let (label, targets, up, down) = if path.is_dir() {
        let set = measurement::read(path)?;
        let r = match run {
            Some(n) => set.run(n).ok_or_else(|| VmtError::bad(path, "runs", format!("no run named `{n}`")))?,
            None => set
                .runs
                .iter()
                .find(|r| r.procedure == measurement::Procedure::Positioning)
                .ok_or_else(|| VmtError::bad(path, "runs", "expected a positioning run (point table)"))?,
        };
        let col = match sensor {
            Some(s) => s.to_string(),
            None => set
                .sensors
                .iter()
                .find(|s| r.data.column(&s.name).is_some() && s.kind == SensorKind::LaserLinear)
                .or_else(|| set.sensors.iter().find(|s| r.data.column(&s.name).is_some()))
                .map(|s| s.name.clone())
                .ok_or_else(|| VmtError::bad(path, format!("run {}", r.name), "expected a sensor column"))?,
        };
        let rec = vmt_sim::procedures::RunRecord {
            name: r.name.clone(),
            procedure: r.procedure,
            feed: r.feed,
            direction: r.direction,
            start_time: r.start_time.unwrap_or(0.0),
            data: r.data.clone(),
        };
        let (t, u, d) = crate::estimate::point_table_deviations(&rec, &col).ok_or_else(|| {
            VmtError::bad(path, format!("run {}", r.name), format!("expected a point table with column `{col}`"))
        })?;
        (format!("{} / {} / {}", path.display(), r.name, col), t, u, d)
    } else {
        let text = std::fs::read_to_string(path).map_err(|e| VmtError::io(path, "reading", e))?;
        let dat = parse_dat(&text).map_err(|e| VmtError::bad(path, "", e.to_string()))?;
        (path.display().to_string(), dat.targets, dat.up, dat.down)
    };
    let res = evaluate_bidirectional(&targets, &up, &down).map_err(|e| VmtError::bad(path, "", e.to_string()))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&res).map_err(|e| VmtError::Internal(e.to_string()))?);
        return Ok(0);
    }
    let um = |v: f64| format!("{:10.3}", v * 1e6);
    println!("ISO 230-2:2014 evaluation of {label} (µm)");
    println!(
        "{:>12} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "target mm", "x̄↑", "x̄↓", "x̄", "B_i", "R↑_i", "R↓_i", "R_i"
    );
    for t in &res.targets {
        println!(
            "{:>12.3} {} {} {} {} {} {} {}",
            t.target * 1e3,
            um(t.up.mean),
            um(t.down.mean),
            um(t.mean_bidirectional),
            um(t.reversal),
            um(t.up.repeatability),
            um(t.down.repeatability),
            um(t.repeatability)
        );
    }
    println!("A {}  A↑ {}  A↓ {}", um(res.a), um(res.a_up), um(res.a_down));
    println!("E {}  E↑ {}  E↓ {}  M {}", um(res.e), um(res.e_up), um(res.e_down), um(res.m));
    println!("R {}  R↑ {}  R↓ {}  B {}  B̄ {}", um(res.r), um(res.r_up), um(res.r_down), um(res.b), um(res.b_mean));
    Ok(0)
}

/// Reads a model and a measurement set for the model-check commands.
fn model_and_data(model: &Path, data: &Path) -> Result<(crate::model::Model, MeasurementSet), VmtError> {
    let m = crate::model::read_model(model)?;
    let set = measurement::read(data)?;
    Ok((m, set))
}

fn print_json<T: serde::Serialize>(v: &T) -> Result<(), VmtError> {
    println!("{}", serde_json::to_string_pretty(v).map_err(|e| VmtError::Internal(e.to_string()))?);
    Ok(())
}

/// `vmt compare --model M --data D [--json]`: fit the model's free parameters, predict, report the
/// residual (FORMAT.md §4).
pub fn compare(model: &Path, data: &Path, json: bool) -> Result<i32, VmtError> {
    let (m, set) = model_and_data(model, data)?;
    let r = crate::modelcheck::compare(&m, &set, data)?;
    if json {
        print_json(&r)?;
    } else {
        print!("{}", crate::modelcheck::compare_text(&r));
    }
    Ok(0)
}

/// `vmt diagnose --model M --data D [--json]`: rank the effects the model lacks (FORMAT.md §4).
pub fn diagnose(model: &Path, data: &Path, json: bool) -> Result<i32, VmtError> {
    let (m, set) = model_and_data(model, data)?;
    let r = crate::modelcheck::diagnose(&m, &set, data)?;
    if json {
        print_json(&r)?;
    } else {
        print!("{}", crate::modelcheck::diagnose_text(&r));
    }
    Ok(0)
}

/// `vmt add --model M --effect NAME [--from-diagnosis] [--data D] -o M2`: writes the model with the
/// effect added (`fit = true`; with `--from-diagnosis` starting from the diagnosed parameters, which
/// needs `--data`). With `--data`, appends (model, normalised RMS) of the input model (if the history
/// is empty) and of the new model to `history.json` beside M2.
pub fn add(model: &Path, effect: &str, from_diagnosis: bool, data: Option<&Path>, out: &Path) -> Result<i32, VmtError> {
    use vmt_sim::effects::EffectName;
    let m = crate::model::read_model(model)?;
    let name: EffectName =
        effect.parse().map_err(|e: vmt_sim::effects::UnknownEffect| VmtError::Usage(format!("--effect: {e}")))?;
    let set = match data {
        Some(d) => Some(measurement::read(d)?),
        None if from_diagnosis => {
            return Err(VmtError::Usage("--from-diagnosis needs --data (the diagnosis is computed again)".into()))
        }
        None => None,
    };
    let entry = match (&set, from_diagnosis, data) {
        (Some(s), true, Some(d)) => {
            let diag = crate::modelcheck::diagnose(&m, s, d)?;
            Some(diag.ranking.into_iter().find(|r| r.effect == name.as_str()).ok_or_else(|| {
                VmtError::bad(d, "", format!("the diagnosis has no candidate `{name}` on these data"))
            })?)
        }
        _ => None,
    };
    let mut m2 = crate::modelcheck::add_effect(&m, name, entry.as_ref()).map_err(|e| VmtError::bad(model, "", e))?;
    m2.source = out.to_path_buf();
    crate::model::write_model(&m2, out)?;
    eprintln!("wrote {} ({} added, fit = true)", out.display(), name);
    if let (Some(s), Some(d)) = (&set, data) {
        let hpath = crate::modelcheck::history_path(out);
        let mut entries = Vec::new();
        if crate::modelcheck::read_history(&hpath).unwrap_or_default().is_empty() {
            let r0 = crate::modelcheck::compare(&m, s, d)?;
            entries.push(crate::modelcheck::HistoryEntry {
                model: model.display().to_string(),
                data: d.display().to_string(),
                added: String::new(),
                normalized_rms: r0.normalized_rms,
            });
        }
        let r1 = crate::modelcheck::compare(&m2, s, d)?;
        entries.push(crate::modelcheck::HistoryEntry {
            model: out.display().to_string(),
            data: d.display().to_string(),
            added: name.as_str().to_string(),
            normalized_rms: r1.normalized_rms,
        });
        crate::modelcheck::append_history(&hpath, &entries)?;
        eprintln!("normalised RMS now {:.3} (history in {})", r1.normalized_rms, hpath.display());
    }
    Ok(0)
}
