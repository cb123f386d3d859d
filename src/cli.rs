//! The commands of the `vmt` binary as library functions (so tests can call them): each parses its
//! inputs, runs a workflow and prints. They return the process exit code or a `VmtError` (exit 2 for
//! bad input).

use crate::error::VmtError;
use crate::estimate::{run_estimators, Check, Quantity};
use crate::measurement::{self, MeasurementSet, UnitChoice};
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
