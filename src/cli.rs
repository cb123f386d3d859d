//! The commands of the `vmt` binary as library functions (so tests can call them): each parses its
//! inputs, runs a workflow and prints. They return the process exit code or a `VmtError` (exit 2 for
//! bad input).

use crate::error::VmtError;
use crate::estimate::straightness::{
    parse_method, profile_table, sensor_straightness, PassSelection, SensorStraightness,
};
use crate::estimate::{display, Check, Quantity, CHECK_HEADER, CHECK_LEGEND};
use crate::measurement::{self, MeasurementSet, Procedure, SensorKind, UnitChoice};
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
    simulate_set_on(sc, &physics(sc)?)
}

/// Simulates a scenario on its physics `ph` (built once by the caller) and returns its measurement set.
fn simulate_set_on(sc: &Scenario, ph: &crate::simulate::Physics) -> Result<MeasurementSet, VmtError> {
    let truths = simulate_truth(sc, ph);
    let runs = read_all(sc, ph, &truths, sc.seed)?;
    to_measurement_set(sc, &runs)
}

/// `vmt simulate [SCENARIO] -o DIR [--compensation TABLE]`: writes the measurement set with the truth
/// beside it; with a compensation table (any `vmt compensate` format) loaded in the simulated CNC.
pub fn simulate(path: Option<&Path>, out: &Path, units: &str, compensation: Option<&Path>) -> Result<(), VmtError> {
    let units = parse_units(units)?;
    let sc = load_scenario(path)?;
    let inputs: Vec<&Path> = path.into_iter().chain(compensation).collect();
    crate::output::refuse_input_overwrite(out, &inputs)?;
    crate::output::check_destination(out)?;
    let table = compensation.map(crate::format::compensation::read_table).transpose()?;
    let mut ph = physics(&sc)?;
    if let Some(table) = table {
        ph.model.compensation = vmt_sim::profile::Profile {
            terms: vec![vmt_sim::profile::Term::Table { x: table.positions, y: table.corrections }],
        };
    }
    let mut set = simulate_set_on(&sc, &ph)?;
    if let Some(c) = compensation {
        let with = format!("compensation table {} loaded in the simulated CNC", c.display());
        set.description = Some(set.description.map_or(with.clone(), |d| format!("{d}; {with}")));
    }
    measurement::write_with_extras(&set, out, units, &truth_extras(&sc, &ph, units)?)?;
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

/// Default output directory of `vmt run`: `vmt-out/` followed by the scenario's path without its
/// extension, a leading `scenarios/` and any root or `..` (so `scenarios/default.toml` → `vmt-out/default`,
/// `scenarios/lessons/backlash/scenario.toml` → `vmt-out/lessons/backlash/scenario`): two scenarios with
/// the same file name never write over each other's outputs.
pub fn default_out(source: &Path) -> PathBuf {
    use std::path::Component;
    let rel = source.with_extension("");
    let parts: Vec<&std::ffi::OsStr> = rel
        .components()
        .filter_map(|c| match c {
            Component::Normal(p) => Some(p),
            Component::Prefix(_) | Component::RootDir | Component::CurDir | Component::ParentDir => None,
        })
        .collect();
    let skip = usize::from(parts.len() > 1 && parts[0] == "scenarios");
    let mut out = PathBuf::from("vmt-out");
    if parts.len() == skip {
        out.push("scenario");
    } else {
        out.extend(&parts[skip..]);
    }
    out
}

/// `vmt run [SCENARIO] [--units si|human]`: simulate, estimate, print the table (the measurement set
/// written in `units`); exit 1 if any estimate misses its tolerance.
pub fn run(path: Option<&Path>, out: Option<&Path>, json: bool, units: &str) -> Result<i32, VmtError> {
    let units = parse_units(units)?;
    let sc = load_scenario(path)?;
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| default_out(&sc.source));
    if let Some(p) = path {
        crate::output::refuse_input_overwrite(&out, &[p])?;
    }
    crate::output::check_destination(&out)?;
    let bar = spinner(&format!(
        "simulating {} procedures and running {} estimators",
        sc.procedures.len(),
        sc.estimators.len()
    ));
    let ph = physics(&sc)?;
    let truths = simulate_truth(&sc, &ph);
    let runs = read_all(&sc, &ph, &truths, sc.seed)?;
    let set = to_measurement_set(&sc, &runs)?;
    let files = measurement::set_files(&set, &out.join("data"), units, &truth_extras(&sc, &ph, units)?)?;
    // The compensation re-test simulated with the table in the CNC (exact; a study derives it instead).
    let est = crate::workflow::run::estimate_session(&sc, &ph, &truths, &set, crate::simulate::Retest::Simulated)?;
    let checks = &est.checks;
    let html = out.join("report.html");
    let (report, report_json) = crate::report::report_files(&crate::report::run_report(&sc, &set, &est))?;
    // One transaction: the measurement set and the report swapped in together, after all the work.
    crate::output::replace_dir(&out, |tmp| {
        measurement::put_files(&tmp.join("data"), &files)?;
        measurement::put_files(
            tmp,
            &[("report.html".into(), report.into_bytes()), ("report.json".into(), report_json.into_bytes())],
        )
    })?;
    let failed: Vec<&Check> = checks.iter().filter(|c| !c.pass).collect();
    bar.finish_and_clear();
    if json {
        let v = serde_json::json!({
            "scenario": sc.source,
            "data": out.join("data"),
            "report": html,
            "checks": checks_by_id(checks),
            "pass": failed.is_empty()
        });
        print_json("vmt-run/1", &v)?;
    } else {
        println!("vmt run: {} — {}", sc.source.display(), sc.description);
        println!("{}", summary_table(&set));
        println!("{}", check_table(checks));
        println!("measurement set: {}", out.join("data").display());
        println!("report: {}", html.display());
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

/// The checks keyed by their stable ids (a repeated id gets `#2`, `#3`, … in table order).
fn checks_by_id(checks: &[Check]) -> std::collections::BTreeMap<String, &Check> {
    let mut map = std::collections::BTreeMap::new();
    for c in checks {
        let mut id = c.id.clone();
        let mut k = 1;
        while map.contains_key(&id) {
            k += 1;
            id = format!("{}#{k}", c.id);
        }
        map.insert(id, c);
    }
    map
}

/// A spinner on stderr when it is a terminal; hidden otherwise (CI logs, pipes).
fn spinner(message: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new_spinner();
    if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        bar.set_message(message.to_string());
        bar.enable_steady_tick(std::time::Duration::from_millis(200));
    } else {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar
}

/// Keeps freed memory in the process for reuse (glibc's malloc; elsewhere nothing). By default glibc
/// serves a block above 128 kB from the kernel, gives it back when freed and lets a later one fault
/// its pages in anew; a model-check search allocates and frees columns of n values thousands of
/// times (800 kB each at 100 000 samples), and the kernel's page clearing took a sixth of a
/// 100 000-sample `vmt diagnose`. Here blocks up to 32 MB (glibc's largest threshold) come from the
/// heap, and the heap keeps up to 512 MB free before it shrinks. Call once, before threads start.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets malloc's tuning parameters (an out-of-range value is refused with
    // 0, leaving the default); it is called at start, before any other thread allocates.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 512 << 20);
        libc::mallopt(libc::M_TOP_PAD, 64 << 20);
    }
}

/// A spinner on stderr that appears only when the work lasts more than a second and stderr is a
/// terminal (the model-check commands: most runs answer at once), with the time since the start;
/// `set_message` changes what it says (a stage), `finish_and_clear` removes it.
fn slow_spinner(message: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::with_draw_target(None, indicatif::ProgressDrawTarget::hidden());
    bar.set_message(message.to_string());
    if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        let b = bar.clone();
        std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_secs(1));
            if !b.is_finished() {
                b.set_draw_target(indicatif::ProgressDrawTarget::stderr());
                let style = indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner());
                b.set_style(style);
                b.enable_steady_tick(std::time::Duration::from_millis(200));
            }
        });
    }
    bar
}

/// The table of checks ([`Check::cells`] under [`CHECK_HEADER`]), its legend and each row's note.
/// Columns are at least as wide as before and widen to their longest cell, so a long value such as
/// "42.253 (dimensionless)" stays in its column; combining marks (the bar of B̄) take no width.
pub fn check_table(checks: &[Check]) -> String {
    const MIN_WIDTH: [usize; 8] = [36, 20, 14, 14, 14, 14, 27, 0];
    let rows: Vec<[String; 8]> =
        std::iter::once(CHECK_HEADER.map(String::from)).chain(checks.iter().map(Check::cells)).collect();
    let width = |t: &str| t.chars().filter(|c| !('\u{300}'..='\u{36f}').contains(c)).count();
    let w: Vec<usize> =
        (0..8).map(|j| rows.iter().map(|r| width(&r[j])).max().unwrap_or(0).max(MIN_WIDTH[j])).collect();
    let mut s = String::new();
    for r in &rows {
        let pad = |j: usize| " ".repeat(w[j] - width(&r[j]));
        // error, statistic and pass rule to the left; the four numbers to the right; pass last.
        s += &format!(
            "{}{} {}{} {}{} {}{} {}{} {}{}  {}{} {}\n",
            r[0],
            pad(0),
            r[1],
            pad(1),
            pad(2),
            r[2],
            pad(3),
            r[3],
            pad(4),
            r[4],
            pad(5),
            r[5],
            r[6],
            pad(6),
            r[7]
        );
    }
    s += &format!("{CHECK_LEGEND}\n");
    for c in checks {
        if let Some(n) = &c.note {
            s += &format!("  {}: {n}\n", c.error);
        }
    }
    s
}

/// What was measured: per run, its procedure, samples and the RMS about the mean of each channel
/// (√(Σ(xᵢ − x̄)²/n), the spread of its readings), in the channel's display unit ([`channel_unit`]).
pub fn summary_table(set: &MeasurementSet) -> String {
    let mut s = format!("{:<16} {:<18} {:>8}  channels (RMS about the mean)\n", "run", "procedure", "samples");
    for r in &set.runs {
        let chans: Vec<String> = r
            .data
            .columns()
            .iter()
            .filter(|(n, _)| n != vmt_sim::procedures::COMMAND_COLUMN)
            .map(|(n, v)| {
                let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
                let rms = (v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / v.len().max(1) as f64).sqrt();
                let (k, unit) = set.sensor(n).map_or((1.0, "(SI)"), |s| channel_unit(s.kind));
                format!("{n} {} {unit}", measurement::round_significant(rms * k, 4))
            })
            .collect();
        s += &format!("{:<16} {:<18} {:>8}  {}\n", r.name, r.procedure.as_str(), r.data.len(), chans.join(", "));
    }
    s
}

/// The unit a person reads a sensor kind's values in, with the factor from SI: positions (commands,
/// encoders) in mm, deviations in µm, angles in µrad, accelerations in mm/s², velocities in mm/s,
/// forces in N, temperatures in K, pressures in Pa, humidity in %.
pub fn channel_unit(kind: SensorKind) -> (f64, &'static str) {
    use crate::units::Dimension;
    match (kind, measurement::kind_dimension(kind)) {
        (SensorKind::Command | SensorKind::EncoderLinear | SensorKind::EncoderRotary, _) => (1e3, "mm"),
        (_, Dimension::Length) => (1e6, "µm"),
        (_, Dimension::Angle) => (1e6, "µrad"),
        (_, Dimension::Acceleration) => (1e3, "mm/s²"),
        (_, Dimension::Velocity) => (1e3, "mm/s"),
        (_, Dimension::Force) => (1.0, "N"),
        (_, Dimension::Time) => (1.0, "s"),
        (_, Dimension::Temperature) => (1.0, "K"),
        (_, Dimension::Pressure) => (1.0, "Pa"),
        (_, Dimension::Ratio) => (100.0, "%"),
    }
}

/// `vmt iso230-2 PATH`: ISO 230-2 evaluation of a positioning test, from a measurement set directory
/// (a point-table run and one of its deviation columns) or from an ecmc `.dat` file (key=value format).
pub fn iso230_2(path: &Path, run: Option<&str>, sensor: Option<&str>, json: bool) -> Result<i32, VmtError> {
    use vmt_estimators::iso230_2::evaluate_bidirectional;
    // `place`: where the deviations come from, for a message on them (the estimator names target and run).
    let (label, place, targets, up, down) = if path.is_dir() {
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
        let (t, u, d) = crate::estimate::point_table_deviations(r, &col).ok_or_else(|| {
            VmtError::bad(path, format!("run {}", r.name), format!("expected a point table with column `{col}`"))
        })?;
        (format!("{} / {} / {}", path.display(), r.name, col), format!("run {}, column `{col}`", r.name), t, u, d)
    } else {
        let dat = measurement::read_dat(path)?;
        (path.display().to_string(), "deviations".to_string(), dat.targets, dat.up, dat.down)
    };
    let res = evaluate_bidirectional(&targets, &up, &down).map_err(|e| VmtError::bad(path, place, e.to_string()))?;
    let u = vmt_estimators::iso230_2::axis_uncertainties(&res);
    if json {
        /// `vmt iso230-2 --json`: the evaluation and the type-A standard uncertainties of its axis values.
        #[derive(serde::Serialize)]
        struct Out<'a> {
            #[serde(flatten)]
            result: &'a vmt_estimators::iso230_2::AxisResult,
            uncertainty: vmt_estimators::iso230_2::AxisUncertainty,
        }
        print_json("vmt-iso230-2/1", &Out { result: &res, uncertainty: u })?;
        return Ok(0);
    }
    let table = crate::estimate::iso_table(&format!("ISO 230-2:2014 evaluation of {label} (µm)"), &res);
    println!("{}", table.caption);
    let line = |cells: &[String]| cells.iter().map(|c| format!("{c:>12}")).collect::<Vec<_>>().join(" ");
    println!("{}", line(&table.header));
    for row in &table.rows {
        println!("{}", line(row));
    }
    let um = |v: f64| format!("{:.3}", v * 1e6);
    println!(
        "standard uncertainty (1σ, type A from the repeats, first order at the extreme targets), µm: u(E) {}  u(E↑) {}  \
         u(E↓) {}  u(M) {}  u(B) {}  u(B̄) {}",
        um(u.e),
        um(u.e_up),
        um(u.e_down),
        um(u.m),
        um(u.b),
        um(u.b_mean)
    );
    println!(
        "per target: the scatter s↑, s↓ above (u of a mean x̄ = s/√n); R and A are maxima of the scatter and get \
         no uncertainty here; the instrument's systematic share (ISO/TR 230-9) is not in the repeats"
    );
    Ok(0)
}

/// A job-array index variable of a cluster scheduler: (variable, first index the scheduler counts from
/// — subtracted —, variable holding the first index if the scheduler sets one).
const ARRAY_INDEX: [(&str, usize, Option<&str>); 5] = [
    ("SLURM_ARRAY_TASK_ID", 0, Some("SLURM_ARRAY_TASK_MIN")),
    ("HQ_TASK_ID", 0, None),
    ("PBS_ARRAY_INDEX", 0, None),
    ("PBS_ARRAYID", 0, None),
    ("LSB_JOBINDEX", 1, None),
];

/// Job-array size variables: Slurm's task count; LSF's last index (arrays `[1-N]`).
const ARRAY_COUNT: [&str; 2] = ["SLURM_ARRAY_TASK_COUNT", "LSB_JOBINDEX_END"];

/// `--shard i/n`, or `--shard auto` (index and count from a Slurm, HyperQueue, PBS or LSF job array),
/// or `--shard auto/n` (index from the scheduler, n given: HyperQueue and PBS do not export the array
/// size). `env` reads an environment variable. Returns (i, n) with 0 ≤ i < n.
pub fn parse_shard(s: &str, env: &dyn Fn(&str) -> Option<String>) -> Result<(usize, usize), VmtError> {
    let usage = |m: String| VmtError::Usage(format!("--shard {s}: {m}"));
    let num = |v: &str, what: &str| {
        v.trim().parse::<usize>().map_err(|_| usage(format!("{what} must be a whole number, got `{v}`")))
    };
    let (i, n) = s.split_once('/').map_or((s, None), |(i, n)| (i, Some(n)));
    let (i, n) = if i == "auto" {
        let (var, first, min_var) = *ARRAY_INDEX.iter().find(|e| env(e.0).is_some()).ok_or_else(|| {
            usage(format!(
                "no job-array index in the environment (looked for {})",
                ARRAY_INDEX.iter().map(|v| v.0).collect::<Vec<_>>().join(", ")
            ))
        })?;
        let first = match min_var.and_then(|m| env(m).map(|v| (m, v))) {
            Some((m, v)) => num(&v, m)?,
            None => first,
        };
        let raw = num(&env(var).unwrap_or_default(), var)?;
        let i =
            raw.checked_sub(first).ok_or_else(|| usage(format!("{var} = {raw} is below the first index {first}")))?;
        let n = match n {
            Some(n) => num(n, "n")?,
            None => {
                let (cvar, c) = ARRAY_COUNT.iter().find_map(|&c| env(c).map(|v| (c, v))).ok_or_else(|| {
                    usage(format!("{var} is set but the scheduler exports no array size: use --shard auto/N"))
                })?;
                num(&c, cvar)?
            }
        };
        (i, n)
    } else {
        (num(i, "i")?, num(n.ok_or_else(|| usage("expected i/n, auto or auto/n".into()))?, "n")?)
    };
    if n == 0 || i >= n {
        return Err(usage(format!("expected 0 ≤ i < n, got i = {i}, n = {n}")));
    }
    Ok((i, n))
}

/// `vmt study SCENARIO (--vary KEY=V1,V2… | --sample KEY=DIST…) --trials N [--shard i/n|auto] -o DIR`:
/// writes trials.csv, summary.csv, study.svg and the report (and sensitivity.csv for a sampled study).
#[allow(clippy::too_many_arguments)]
pub fn study(
    path: &Path,
    vary: Option<&str>,
    sample: &[String],
    trials: usize,
    shard: Option<&str>,
    estimator_cmd: Option<&str>,
    tolerance: Option<f64>,
    units: &str,
    out: &Path,
) -> Result<i32, VmtError> {
    let units = parse_units(units)?;
    if tolerance.is_some() && estimator_cmd.is_none() {
        return Err(VmtError::Usage(
            "--tolerance applies to --estimator-cmd; the scenario's estimators carry their own tolerances".into(),
        ));
    }
    if let Some(t) = tolerance.filter(|t| !(t.is_finite() && *t >= 0.0)) {
        return Err(VmtError::Usage(format!("--tolerance: expected a finite number ≥ 0 (SI: m or rad), got {t}")));
    }
    use crate::study::{run_sampled_study, run_study, Sample, Vary};
    let shard = match shard {
        None => (0, 1),
        Some(s) => parse_shard(s, &|k| std::env::var(k).ok())?,
    };
    let sc = Scenario::load(path)?;
    crate::output::check_destination(out)?;
    let cmd = estimator_cmd.map(|c| crate::byo::CommandEstimator { command: c.to_string() });
    let cmd = cmd.as_ref().map(|c| c as &dyn crate::byo::Estimator);
    // What `study merge` checks the shards by (the scenario file's content, not its path).
    let bytes = std::fs::read(path).map_err(|e| VmtError::io(path, "reading the scenario", e))?;
    let info = |design: String| crate::study::ShardInfo {
        vmt_version: env!("CARGO_PKG_VERSION").to_string(),
        scenario_fnv1a64: crate::study::content_fnv1a64(&bytes),
        design,
        trials,
        estimator_cmd: estimator_cmd.map(str::to_string),
        tolerance,
        shard: shard.0,
        shards: shard.1,
    };
    match (vary, sample) {
        (Some(v), []) => {
            let vary = Vary::parse(v)?;
            let bar = spinner(&format!("{} values × {trials} trials", vary.values.len()));
            let rows = run_study(&sc, &vary, trials, shard, cmd, tolerance)?;
            bar.finish_and_clear();
            write_study(&rows, &vary.label(), &[], out, Some(&sc), &info(format!("--vary {v}")), units)
        }
        (None, samples) if !samples.is_empty() => {
            let design = samples.iter().map(|s| format!("--sample {s}")).collect::<Vec<_>>().join(" ");
            let samples: Vec<Sample> = samples.iter().map(|s| Sample::parse(s)).collect::<Result<_, _>>()?;
            let names: Vec<String> = samples.iter().map(|s| s.path.clone()).collect();
            let bar = spinner(&format!("{trials} trials, each with its own physics"));
            let rows = run_sampled_study(&sc, &samples, trials, shard, cmd, tolerance)?;
            bar.finish_and_clear();
            let label = "0 = all trials (parameters sampled per trial)";
            write_study(&rows, label, &names, out, Some(&sc), &info(design), units)
        }
        _ => Err(VmtError::Usage(
            "study needs either --vary KEY=V1,V2,… (sensors.NAME.KEY or a scenario key path) or one or more \
             --sample KEY.PATH=DIST, not both"
                .into(),
        )),
    }
}

/// `vmt study merge OUT SHARD_DIRS…`: joins the trials of shards and writes the same outputs as one run.
/// The shards must be every shard of one study once ([`crate::study::check_shards`]: each directory's
/// `shard.toml` names its study and index); a missing or repeated shard, or shards of different
/// studies, are refused (exit 2) naming them.
pub fn study_merge(out: &Path, shards: &[PathBuf], units: &str) -> Result<i32, VmtError> {
    let units = parse_units(units)?;
    crate::output::check_destination(out)?;
    let mut parts = Vec::new();
    let mut names: Option<Vec<String>> = None;
    for d in shards {
        let file = d.join("trials.csv");
        let (r, n) = crate::study::read_rows(&file)?;
        let info = crate::study::ShardInfo::read(&d.join("shard.toml"))?;
        match &names {
            Some(first) if first != &n => {
                return Err(VmtError::bad(
                    &file,
                    "line 1 (header)",
                    format!("sampled columns {n:?} differ from the first shard's {first:?}: not shards of one study"),
                ))
            }
            _ => names = Some(n),
        }
        parts.push((d.clone(), info, r));
    }
    crate::study::check_shards(&parts)?;
    // The merged directory is the whole study: shard 0 of 1.
    let info = crate::study::ShardInfo { shard: 0, shards: 1, ..parts[0].1.clone() };
    let rows: Vec<_> = parts.into_iter().flat_map(|(_, _, r)| r).collect();
    write_study(&rows, "varied parameter", &names.unwrap_or_default(), out, None, &info, units)
}

fn write_study(
    rows: &[crate::study::TrialRow],
    label: &str,
    sampled: &[String],
    out: &Path,
    sc: Option<&Scenario>,
    shard: &crate::study::ShardInfo,
    units: UnitChoice,
) -> Result<i32, VmtError> {
    use crate::study::{rows_csv, study_cell, study_unit, summarize, summary_svg};
    let summary = summarize(rows);
    let human = units == UnitChoice::Metrology;
    let mut s =
        String::from("value,estimate,trials,mean_abs,p95_abs,pass_rate,cramer_rao_bound,rms,quantity,tolerance");
    s += if human { ",unit\n" } else { "\n" };
    for r in &summary {
        // An undefined statistic (no tolerance; no difference) is an empty cell, as docs/formats.md §6 says.
        let (_, unit) = study_unit(r.quantity, units);
        let cell = |x: f64| study_cell(r.quantity, units, x);
        let opt = |x: Option<f64>| x.map_or(String::new(), cell);
        s += &format!(
            "{},\"{}\",{},{},{},{},{},{},{},{}",
            r.value,
            r.estimate,
            r.trials,
            opt(r.mean_abs),
            opt(r.p95_abs),
            r.pass_rate.map_or(String::new(), |x| x.to_string()),
            cell(r.bound),
            opt(r.rms),
            crate::study::quantity_id(r.quantity),
            opt(r.tolerance)
        );
        s += &if human { format!(",{unit}\n") } else { "\n".to_string() };
    }
    let (html, json) = crate::report::report_files(&crate::report::study_report(sc, &summary, label))?;
    let mut files = vec![
        ("trials.csv".to_string(), rows_csv(rows, sampled, units).into_bytes()),
        ("summary.csv".to_string(), s.into_bytes()),
        ("study.svg".to_string(), summary_svg(&summary, label)?.into_bytes()),
        ("report.html".to_string(), html.into_bytes()),
        ("report.json".to_string(), json.into_bytes()),
        ("shard.toml".to_string(), shard.to_toml().into_bytes()),
    ];
    // A sampled study: first-order Sobol indices of each estimate's difference per parameter
    // (SALib's S1 / S1_conf, one row per estimate and parameter).
    let sens = crate::study::sensitivity(rows, sampled);
    if !sampled.is_empty() {
        let mut t = String::from("estimate,parameter,S1,S1_conf,trials\n");
        for r in &sens {
            t += &format!(
                "\"{}\",\"{}\",{},{},{}\n",
                r.estimate.replace('"', "'"),
                r.parameter,
                r.s1,
                r.s1_conf,
                r.trials
            );
        }
        files.push(("sensitivity.csv".to_string(), t.into_bytes()));
    }
    // One transaction: the study files and the report swapped in together.
    crate::output::replace_dir(out, |tmp| measurement::put_files(tmp, &files))?;
    let judged = summary.iter().all(|r| r.pass_rate.is_some());
    println!("value: {label} (SI); over the trials of each value: mean |d|, RMS of d and 95th percentile of |d|,");
    println!(
        "d = the estimate's difference from the truth (see the run table); CR bound = Cramér–Rao lower bound of RMS d"
    );
    println!(
        "{:>10}  {:<40} {:>6} {:>14} {:>14} {:>14} {:>14}{}",
        "value",
        "estimate",
        "trials",
        "mean |d|",
        "RMS d",
        "p95 |d|",
        "CR bound",
        if judged { "  pass (d ≤ tolerance)" } else { "" }
    );
    for r in &summary {
        let shown = |x: Option<f64>| x.map_or("-".to_string(), |x| display(r.quantity, x));
        let bound = if r.bound.is_finite() { display(r.quantity, r.bound) } else { "-".to_string() };
        println!(
            "{:>10.3e}  {:<40} {:>6} {:>14} {:>14} {:>14} {:>14}{}",
            r.value,
            r.estimate,
            r.trials,
            shown(r.mean_abs),
            shown(r.rms),
            shown(r.p95_abs),
            bound,
            r.pass_rate.map_or(String::new(), |p| format!("  {:>5.1} %", 100.0 * p))
        );
    }
    if !sampled.is_empty() {
        println!("first-order Sobol index S1 of each estimate's d per sampled parameter (share of Var d explained by");
        println!(
            "the parameter alone; ± the 95 % bootstrap half-width), from {} trials:",
            sens.first().map_or(0, |r| r.trials)
        );
        for r in &sens {
            println!("  {:<40} {:<44} S1 = {:.2} ± {:.2}", r.estimate, r.parameter, r.s1, r.s1_conf);
        }
    }
    println!("wrote {}", out.display());
    let missed = rows.iter().filter(|r| r.pass == Some(false)).count();
    if missed > 0 {
        println!("{missed} of {} trial estimates missed their tolerance", rows.len());
        return Ok(1);
    }
    Ok(0)
}

/// `vmt ssi DATA [--sensor NAME]`: seed 002's stick-slip index of every time-series run (crawl first).
pub fn ssi(path: &Path, sensor: Option<&str>, json: bool) -> Result<i32, VmtError> {
    let set = measurement::read(path)?;
    let mut results = Vec::new();
    for r in &set.runs {
        let measurement::RunData::TimeSeries { t, .. } = &r.data else { continue };
        // The encoder method reads a position: an encoder's or a linear laser's, never an acceleration.
        let is_position = |k: SensorKind| {
            matches!(k, SensorKind::EncoderLinear | SensorKind::EncoderRotary | SensorKind::LaserLinear)
        };
        let s = match sensor {
            Some(s) => {
                let s = set.sensor(s).ok_or_else(|| VmtError::bad(path, "sensors", format!("no sensor `{s}`")))?;
                if !is_position(s.kind) {
                    return Err(VmtError::bad(
                        path,
                        format!("sensors.{}", s.name),
                        format!(
                            "the stick-slip index reads a position: expected an encoder_linear, encoder_rotary or laser_linear \
                             sensor, got kind `{}`",
                            s.kind.as_str()
                        ),
                    ));
                }
                s
            }
            None => match set.sensors.iter().find(|s| {
                matches!(s.kind, SensorKind::EncoderLinear | SensorKind::EncoderRotary)
                    && r.data.column(&s.name).is_some()
            }) {
                Some(s) => s,
                None => continue,
            },
        };
        let Some(x) = r.data.column(&s.name) else { continue };
        if t.len() < 3 {
            continue;
        }
        // The count q for the floor 2q/(Δt·v): nobody states it in a measurement set, so it is read from
        // the record (every first difference a multiple of q), or the floor is not known.
        let q = vmt_estimators::ssi::lattice_step(x);
        let (_, res) = crate::estimate::ssi::run_ssi(t, x, q)
            .map_err(|m| VmtError::bad(&path.join(&r.file), format!("run {}", r.name), m.to_string()))?;
        let resolution_source = if q.is_some() {
            "found in the record: every first difference is a multiple of it"
        } else {
            "not found: the record is not on a lattice of counts (noise finer than a count, or too few moves)"
        };
        results.push(serde_json::json!({
            "run": r.name, "sensor": s.name, "feed": r.feed, "ssi": res.ssi,
            "quantisation_floor": res.quantisation_floor, "resolution": q,
            "resolution_source": resolution_source, "result": res
        }));
    }
    if results.is_empty() {
        return Err(VmtError::bad(path, "runs", "expected a time-series run with an encoder column"));
    }
    if json {
        print_json("vmt-ssi/1", &serde_json::json!({ "runs": results }))?;
    } else {
        println!(
            "{:<16} {:<12} {:>12} {:>8} {:>10} {:>10}  verdict (SSI ≥ 1: crawling)",
            "run", "sensor", "feed mm/min", "SSI", "floor", "count nm"
        );
        for r in &results {
            let ssi = r["ssi"].as_f64().unwrap_or(f64::NAN);
            let feed = r["feed"].as_f64().map_or("-".to_string(), |f| format!("{:.1}", f * 60_000.0));
            let floor = r["quantisation_floor"].as_f64();
            let verdict = match floor {
                Some(f) if (ssi - 1.0).abs() <= f => "undecided (|SSI − 1| ≤ floor)",
                _ if ssi >= 1.0 => "crawling",
                _ => "smooth",
            };
            println!(
                "{:<16} {:<12} {:>12} {:>8.3} {:>10} {:>10}  {verdict}",
                r["run"].as_str().unwrap_or(""),
                r["sensor"].as_str().unwrap_or(""),
                feed,
                ssi,
                floor.map_or("-".to_string(), |f| format!("{f:.3}")),
                r["resolution"].as_f64().map_or("-".to_string(), |q| format!("{:.4}", q * 1e9)),
            );
        }
        println!(
            "floor: the quantisation floor 2q/(Δt·v̄) of the index (dimensionless): |SSI − SSI of the exact motion| ≤ floor;"
        );
        println!("count q: the encoder count read from the record (\"-\": the record is not on a lattice of counts, the floor is not known)");
    }
    Ok(0)
}

/// `vmt friction DATA [--sensor NAME]`: Stribeck parameters from the friction-sweep runs (mean motor force
/// per constant-velocity run against its signed feed), nonlinear least squares with standard errors.
pub fn friction(path: &Path, sensor: Option<&str>, json: bool) -> Result<i32, VmtError> {
    use vmt_estimators::friction_id::{fit_stribeck, StribeckFitOptions};
    let set = measurement::read(path)?;
    let name = match sensor {
        Some(s) => s.to_string(),
        None => set
            .sensors
            .iter()
            .find(|s| s.kind == SensorKind::MotorForce)
            .map(|s| s.name.clone())
            .ok_or_else(|| VmtError::bad(path, "sensors", "expected a motor_force sensor"))?,
    };
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for (i, r) in set.runs.iter().enumerate().filter(|(_, r)| r.procedure == measurement::Procedure::FrictionSweep) {
        let Some(col) = r.data.column(&name) else { continue };
        let bad = |m: String| VmtError::bad(path, format!("runs[{i}] ({})", r.name), m);
        // A sweep point is the run's signed steady speed and its mean force: a run without `feed`, or
        // whose direction is neither stated nor read from `x_cmd`, is refused (never taken as +1).
        let feed = r.feed.ok_or_else(|| bad("missing `feed` (m/s): the speed of this sweep point".to_string()))?;
        if !(feed.is_finite() && feed > 0.0) {
            return Err(bad(format!("expected `feed` > 0 (m/s), got {feed}")));
        }
        let moved = r.data.command().filter(|x| x.len() >= 2).map(|x| x[x.len() - 1] - x[0]).filter(|m| *m != 0.0);
        let dir = match (r.direction, moved) {
            (Some(d), Some(m)) if f64::from(d) * m < 0.0 => {
                return Err(bad(format!("`direction` = {d} but x_cmd moves by {m:.6e} m")));
            }
            (Some(d), _) => f64::from(d),
            (None, Some(m)) => m.signum(),
            (None, None) => {
                return Err(bad("missing `direction` (+1 / −1) and no moving `x_cmd` column to read it from".into()))
            }
        };
        if col.is_empty() {
            return Err(bad(format!("no samples in column `{name}`")));
        }
        v.push(feed * dir);
        f.push(col.iter().sum::<f64>() / col.len() as f64);
    }
    if v.len() < 6 {
        return Err(VmtError::bad(
            path,
            "runs",
            format!("expected at least 6 friction_sweep runs with `{name}`, got {}", v.len()),
        ));
    }
    let fit =
        fit_stribeck(&v, &f, &StribeckFitOptions::default()).map_err(|e| VmtError::bad(path, "runs", e.to_string()))?;
    if json {
        print_json("vmt-friction/1", &fit)?;
    } else {
        let c = &fit.coefficients;
        println!("Stribeck fit of {} sweep points (residual RMS {:.3} N):", v.len(), fit.residual_rms);
        let e = &fit.std_errors;
        // Each value with its standard error, or why it has none (never a bare number).
        let pm = |name: &str, v: Option<f64>, sci: bool| match v {
            Some(v) if sci => format!("± {v:.4e}"),
            Some(v) => format!("± {v:.3}"),
            None if fit.at_bound.iter().any(|b| b == name) => {
                "(at a bound of the fit: a limit, no standard error)".into()
            }
            None => "(no standard error: not determined by these points)".into(),
        };
        println!("  value ± standard error (1σ, from the Jacobian at the solution and the residual RMS):");
        println!("  Fc {:>12.3} {} N", c.fc, pm("fc", e.fc, false));
        println!("  Fs {:>12.3} {} N", c.fs, pm("fs", e.fs, false));
        println!("  vs {:>12.4e} {} m/s", c.vs, pm("vs", e.vs, true));
        println!("  δ  {:>12.3} {} (shape exponent, dimensionless)", c.delta, pm("delta", e.delta, false));
        println!("  Fv {:>12.3} {} N·s/m", c.fv, pm("fv", e.fv, false));
    }
    Ok(0)
}

/// Most points of an equidistant compensation table (size budget, DESIGN.md §2).
pub const MAX_TABLE_NODES: usize = 100_000;

/// What `vmt compensate` writes (its options).
#[derive(Clone, Debug, Default)]
pub struct CompensateOptions {
    /// Deviation column (default: the first linear laser of the run).
    pub sensor: Option<String>,
    /// `--equidistant N`: the legacy controller-style table of N points in 0.1 µm units.
    pub equidistant: Option<usize>,
    /// `--format csv|siemens|fanuc` (default csv).
    pub format: Option<String>,
    /// `--points N`: equidistant points (siemens/fanuc default: one per target; csv: variable step).
    pub points: Option<usize>,
    /// `--axis NAME`: the controller's axis name (default: the run's axis letter and 1, e.g. X1).
    pub axis: Option<String>,
    /// `--json`: print `vmt-compensate/1` (the nodes with their uncertainties, the targets) instead of text.
    pub json: bool,
}

/// `vmt compensate DATA -o TABLE [--format csv|siemens|fanuc] [--points N] [--axis NAME]`: a compensation
/// table from the mean bidirectional deviations of a positioning run — seed 004's variable-step table
/// (CSV), or an equidistant least-squares table of N points (SINUMERIK-, FANUC-style, or CSV with
/// `--points`), each format's limits checked and its sign convention written into the file
/// (docs/formats.md §7); `--equidistant N` for the legacy controller-style table.
pub fn compensate(path: &Path, out: &Path, opts: &CompensateOptions) -> Result<i32, VmtError> {
    use crate::format::compensation::{equidistant_nodes, table_text, ControllerFormat};
    use vmt_estimators::compensation::{
        equidistant_table, export_controller_table, fit_table_on_nodes, variable_step_table, VariableStepParams,
    };
    use vmt_estimators::iso230_2::evaluate_bidirectional;
    let format = opts.format.as_deref().map(ControllerFormat::parse).transpose()?;
    if opts.equidistant.is_some() && (format.is_some() || opts.points.is_some()) {
        return Err(VmtError::Usage("--equidistant: give either it or --format/--points, not both".into()));
    }
    let format = format.unwrap_or(ControllerFormat::Csv);
    if let Some(n) = opts.points {
        if n < 2 || n > format.max_points() {
            return Err(VmtError::Usage(format!(
                "--points {n}: a {} table holds 2..={} points",
                format.name(),
                format.max_points()
            )));
        }
    }
    if let Some(a) = &opts.axis {
        let ok = a.len() <= 16
            && a.starts_with(|c: char| c.is_ascii_alphabetic())
            && a.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !ok {
            return Err(VmtError::Usage(format!(
                "--axis `{a}`: expected a controller axis name (a letter, then letters, digits or _; ≤ 16)"
            )));
        }
    }
    crate::output::refuse_input_overwrite(out, &[path])?;
    let set = measurement::read(path)?;
    let run = set
        .runs
        .iter()
        .find(|r| r.procedure == measurement::Procedure::Positioning)
        .ok_or_else(|| VmtError::bad(path, "runs", "expected a positioning run"))?;
    let col = opts.sensor.clone().or_else(|| {
        set.sensors
            .iter()
            .find(|s| s.kind == SensorKind::LaserLinear && run.data.column(&s.name).is_some())
            .map(|s| s.name.clone())
    });
    let col = col.ok_or_else(|| VmtError::bad(path, format!("run {}", run.name), "expected a laser_linear column"))?;
    let (t, u, d) = crate::estimate::point_table_deviations(run, &col)
        .ok_or_else(|| VmtError::bad(path, format!("run {}", run.name), format!("no column `{col}`")))?;
    let iso = evaluate_bidirectional(&t, &u, &d)
        .map_err(|e| VmtError::bad(path, format!("run {}, column `{col}`", run.name), e.to_string()))?;
    let targets: Vec<f64> = iso.targets.iter().map(|x| x.target).collect();
    let dev: Vec<f64> = iso.targets.iter().map(|x| x.mean_bidirectional).collect();
    let bad = |e: String| VmtError::bad(path, format!("run {}", run.name), e);
    let axis = opts.axis.clone().unwrap_or_else(|| format!("{}1", run.axis.iso_letter()));
    let (table, text) = if let Some(n) = opts.equidistant {
        if n > MAX_TABLE_NODES {
            return Err(VmtError::Usage(format!(
                "--equidistant {n}: the limit is {MAX_TABLE_NODES} table points (controllers hold a few thousand)"
            )));
        }
        let table = equidistant_table(&t, &dev, n).map_err(|e| bad(e.to_string()))?;
        let ctl = export_controller_table(&table).map_err(|e| bad(e.to_string()))?;
        let r = |x: f64| measurement::round_significant(x, 12);
        let mut s = format!(
            "# controller table: start {} mm, spacing {} mm, corrections in 0.1 µm\n",
            r(ctl.start * 1e3),
            r(ctl.spacing * 1e3)
        );
        s += "index,correction_0p1um\n";
        for (i, c) in ctl.corrections_0p1um.iter().enumerate() {
            s += &format!("{i},{c}\n");
        }
        (table, s)
    } else {
        let table = match (format.equidistant(), opts.points) {
            (false, None) => {
                variable_step_table(&targets, &dev, &VariableStepParams::default())
                    .map_err(|e| bad(e.to_string()))?
                    .table
            }
            (true, None) | (_, Some(_)) => {
                let n = opts.points.unwrap_or(targets.len()).min(format.max_points());
                let (lo, hi) = (targets[0], targets[targets.len() - 1]);
                fit_table_on_nodes(&equidistant_nodes(lo, hi, n), &targets, &dev).map_err(|e| {
                    bad(format!(
                        "{e} (an equidistant table of {n} points over {} targets: choose fewer --points)",
                        targets.len()
                    ))
                })?
            }
        };
        let about = format!("from run {} sensor {col} of {}", run.name, path.display());
        let (text, notes) = table_text(format, &table, &axis, &about).map_err(|e| bad(e.to_string()))?;
        for n in notes {
            eprintln!("note: {n}");
        }
        (table, text)
    };
    let summary = compensation_summary(&iso, &table);
    measurement::write_file_atomic(out, text.as_bytes())?;
    let format_name = if opts.equidistant.is_some() { "legacy equidistant" } else { format.name() };
    if opts.json {
        #[derive(serde::Serialize)]
        struct Out<'a> {
            data: String,
            run: &'a str,
            sensor: &'a str,
            file: String,
            table_format: &'a str,
            sign: &'a str,
            e_before: f64,
            a_before: f64,
            #[serde(flatten)]
            summary: &'a CompensationSummary,
        }
        let sign = if opts.equidistant.is_some() {
            "correction_0p1um = deviation (vmt's convention)"
        } else {
            format.sign_convention()
        };
        return print_json(
            "vmt-compensate/1",
            &Out {
                data: path.display().to_string(),
                run: &run.name,
                sensor: &col,
                file: out.display().to_string(),
                table_format: format_name,
                sign,
                e_before: iso.e,
                a_before: iso.a,
                summary: &summary,
            },
        )
        .map(|_| 0);
    }
    println!(
        "wrote {} ({format_name} format, {} points; from run {}, sensor {col}; E before {:.3} µm)",
        out.display(),
        table.positions.len(),
        run.name,
        iso.e * 1e6
    );
    let worst_u =
        summary.nodes.iter().filter_map(|n| n.u).fold(None, |m: Option<f64>, u| Some(m.map_or(u, |m| m.max(u))));
    println!(
        "largest |mean deviation − table| at the targets: {:.3} µm; largest standard uncertainty of a table value (from the repeats): {}",
        summary.max_table_residual * 1e6,
        worst_u.map_or("not available (fewer than 2 runs per direction)".into(), |u| format!("{:.3} µm", u * 1e6))
    );
    if opts.equidistant.is_none() {
        println!("sign: {}", format.sign_convention());
    }
    Ok(0)
}

/// One table node of `vmt compensate --json`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CompensationNode {
    /// Node position, m.
    pub position: f64,
    /// The deviation the table removes there (vmt's sign: measured − target), m.
    pub correction: f64,
    /// Its standard uncertainty from the repeats (nodes held fixed), m; null with fewer than 2 runs per
    /// direction at some target.
    pub u: Option<f64>,
}

/// One ISO 230-2 target of `vmt compensate --json`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CompensationTarget {
    /// Target position, m.
    pub position: f64,
    /// Mean bidirectional deviation x̄, m.
    pub mean_deviation: f64,
    /// Its standard uncertainty ½·√(s↑²/n↑ + s↓²/n↓), m; null with fewer than 2 runs in a direction.
    pub u: Option<f64>,
    /// x̄ − c(P): what the table leaves at the target, m.
    pub table_residual: f64,
}

/// What `vmt compensate` reports beside the table file: nodes with uncertainties, targets with what the
/// table leaves there.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CompensationSummary {
    /// The table's nodes.
    pub nodes: Vec<CompensationNode>,
    /// The ISO 230-2 targets the table was fitted to.
    pub targets: Vec<CompensationTarget>,
    /// max |x̄ − c(P)| over the targets, m.
    pub max_table_residual: f64,
}

/// The nodes with their standard uncertainties (the fit propagated, [`node_uncertainties`]) and the
/// targets with the mean deviation's uncertainty and what the table leaves there.
///
/// [`node_uncertainties`]: vmt_estimators::compensation::node_uncertainties
fn compensation_summary(
    iso: &vmt_estimators::iso230_2::AxisResult,
    table: &vmt_estimators::compensation::CompensationTable,
) -> CompensationSummary {
    let u_of = |t: &vmt_estimators::iso230_2::TargetResult| {
        (t.up.runs >= 2 && t.down.runs >= 2)
            .then(|| 0.5 * (t.up.s * t.up.s / t.up.runs as f64 + t.down.s * t.down.s / t.down.runs as f64).sqrt())
    };
    let targets: Vec<CompensationTarget> = iso
        .targets
        .iter()
        .map(|t| CompensationTarget {
            position: t.target,
            mean_deviation: t.mean_bidirectional,
            u: u_of(t),
            table_residual: t.mean_bidirectional - table.correction_at(t.target),
        })
        .collect();
    let u: Option<Vec<f64>> = targets.iter().map(|t| t.u).collect();
    let p: Vec<f64> = targets.iter().map(|t| t.position).collect();
    let node_u = u.and_then(|u| vmt_estimators::compensation::node_uncertainties(&table.positions, &p, &u).ok());
    let nodes = table
        .positions
        .iter()
        .zip(&table.corrections)
        .enumerate()
        .map(|(k, (&position, &correction))| CompensationNode {
            position,
            correction,
            u: node_u.as_ref().map(|v| v[k]),
        })
        .collect();
    let max_table_residual = targets.iter().map(|t| t.table_residual.abs()).fold(0.0, f64::max);
    CompensationSummary { nodes, targets, max_table_residual }
}
/// `vmt straightness DIR [-o EST.csv] [--units si|human] [--method seed|fusion] [--sensor NAME…] [--json]`: the straightness
/// (and tilt) of each accelerometer from the constant-velocity passes of a measurement set, printed or as
/// JSON, optionally written as a FORMAT.md §5 profile table.
pub fn straightness(
    path: &Path,
    out: Option<&Path>,
    method: &str,
    sensors: &[String],
    json: bool,
    units: &str,
) -> Result<i32, VmtError> {
    let method = parse_method(method).map_err(|e| VmtError::Usage(e.to_string()))?;
    let units = parse_units(units)?;
    let set = measurement::read(path)?;
    let names: Vec<String> = if sensors.is_empty() {
        set.sensors
            .iter()
            .filter(|s| {
                s.kind == SensorKind::Accelerometer
                    && set
                        .runs
                        .iter()
                        .any(|r| r.procedure == Procedure::ConstantVelocity && r.data.column(&s.name).is_some())
            })
            .map(|s| s.name.clone())
            .collect()
    } else {
        sensors.to_vec()
    };
    if names.is_empty() {
        return Err(VmtError::bad(
            path,
            "sensors",
            "expected an accelerometer with a column in a constant_velocity run, found none",
        ));
    }
    let results = names
        .iter()
        .map(|n| sensor_straightness(&set, path, n, PassSelection::ConstantVelocity, method))
        .collect::<Result<Vec<_>, _>>()?;
    let table = match out {
        Some(o) => Some((o, profile_table(&results, o)?)),
        None => None,
    };
    if json {
        let v = serde_json::json!({
            "data": path,
            "method": method,
            "sensors": results,
        });
        print_json("vmt-straightness/1", &v)?;
    } else {
        print_straightness(path, &results);
    }
    if let Some((o, t)) = table {
        measurement::write_profiles(&t, o, units)?;
        eprintln!("wrote {}", o.display());
    }
    Ok(0)
}

/// Root mean square of `v` (same unit), 0 for none.
fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn print_straightness(path: &Path, results: &[SensorStraightness]) {
    println!("vmt straightness: {}", path.display());
    for r in results {
        let e = &r.estimate;
        println!(
            "\n{} → {} ({:?}), {} passes, travel {:.1} mm",
            r.sensor,
            r.effect.as_str(),
            e.method,
            r.passes.len(),
            e.travel * 1e3
        );
        for p in &r.passes {
            println!(
                "  {:<16} {:>8.1} mm/s {:>8.1} Hz {:>7} samples  noise density {:.3} µg/√Hz ({})",
                p.run,
                p.speed * 1e3,
                p.sample_rate,
                p.samples,
                p.noise_density / vmt_estimators::accel_straightness::STANDARD_GRAVITY * 1e6,
                p.noise_density_source
            );
        }
        println!("  band: {}", e.band.note);
        println!(
            "  straightness: RMS {:.4} µm, peak-to-valley {:.4} µm; Cramér–Rao bound of the in-band RMS error {:.4} µm",
            rms(&e.straightness) * 1e6,
            (e.straightness.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
                - e.straightness.iter().cloned().fold(f64::INFINITY, f64::min))
                * 1e6,
            r.bounds.straightness_rms * 1e6
        );
        if let (Some(t), Some(tb)) = (&e.tilt, r.bounds.tilt_rms) {
            let what = r.tilt_effect.map_or("gravity tilt of the sensitive axis", |(eff, _)| eff.as_str());
            println!(
                "  {what} (mean removed): RMS {:.4} µrad; Cramér–Rao bound of the in-band RMS error {:.4} µrad",
                rms(t) * 1e6,
                tb * 1e6
            );
        }
        println!("  Cramér–Rao bound per harmonic (1σ per quadrature component), a selection:");
        println!("  {:>12} {:>16} {:>16}", "λ mm", "straightness µm", "tilt µrad");
        let n = r.bounds.bins.len();
        let step = (n / 8).max(1);
        for b in r.bounds.bins.iter().step_by(step) {
            let s = b.straightness.map_or("-".to_string(), |v| format!("{:.5}", v * 1e6));
            let t = b.tilt.map_or("-".to_string(), |v| format!("{:.5}", v * 1e6));
            println!("  {:>12.1} {:>16} {:>16}", b.wavelength * 1e3, s, t);
        }
    }
}

/// Reads a model and a measurement set for the model-check commands.
fn model_and_data(model: &Path, data: &Path) -> Result<(crate::model::Model, MeasurementSet), VmtError> {
    let m = crate::model::read_model(model)?;
    let set = measurement::read_data(data)?;
    check_model_on_data(&m, &set, model)?;
    Ok((m, set))
}

/// The model's stated error motions within [`crate::model::MAX_ERROR_MOTION`] over the positions the
/// data measured (issue 14: polynomial coefficients of 1e300 were used as given, and surfaced as a
/// message about the data's noise).
fn check_model_on_data(m: &crate::model::Model, set: &MeasurementSet, model: &Path) -> Result<(), VmtError> {
    m.check_error_motion_sizes("", "the data's positions", |axis| set.position_range(axis))
        .map_err(|(place, msg)| VmtError::bad(model, place, msg))
}

/// Prints a result as JSON (`--json`) or as the text `text` makes of it; exit code 0.
fn print_result<T: serde::Serialize>(
    format: &str,
    r: &T,
    json: bool,
    text: impl Fn(&T) -> String,
) -> Result<i32, VmtError> {
    if json {
        print_json(format, r)?;
    } else {
        print!("{}", text(r));
    }
    Ok(0)
}

/// Prints `v` (which must serialize to a JSON object) as one JSON object whose first key is
/// `"format": format` (`vmt-NAME/VERSION`, docs/formats.md), the rest in `v`'s own key order.
pub(crate) fn print_json<T: serde::Serialize>(format: &str, v: &T) -> Result<(), VmtError> {
    let internal = |m: String| VmtError::Internal(format!("{format} JSON: {m}"));
    let text = serde_json::to_string_pretty(v).map_err(|e| internal(e.to_string()))?;
    let body = text.strip_prefix('{').ok_or_else(|| internal("the output is not a JSON object".into()))?;
    let id = serde_json::to_string(format).map_err(|e| internal(e.to_string()))?;
    if body.trim() == "}" {
        println!("{{\n  \"format\": {id}\n}}");
    } else {
        println!("{{\n  \"format\": {id},{body}");
    }
    Ok(())
}

/// `vmt compare --model M --data D [--json] [--report FILE.html]`: fit the model's free parameters, predict, report the
/// residual (FORMAT.md §4).
pub fn compare(model: &Path, data: &Path, json: bool, report: Option<&Path>) -> Result<i32, VmtError> {
    if let Some(out) = report {
        crate::output::refuse_input_overwrite(out, &[model, data])?;
    }
    let (m, set) = model_and_data(model, data)?;
    let bar = slow_spinner("compare: fitting the model");
    let r = crate::modelcheck::compare(&m, &set, data);
    bar.finish_and_clear();
    let r = r?;
    if let Some(out) = report {
        write_report_html(out, &crate::report::model_check_report(model, data, &set, &r, None))?;
    }
    print_result("vmt-compare/1", &r, json, crate::modelcheck::compare_text)
}

/// `vmt diagnose --model M --data D [--json] [--report FILE.html]`: rank the effects the model lacks
/// (FORMAT.md §4).
pub fn diagnose(model: &Path, data: &Path, json: bool, report: Option<&Path>) -> Result<i32, VmtError> {
    if let Some(out) = report {
        crate::output::refuse_input_overwrite(out, &[model, data])?;
    }
    let (m, set) = model_and_data(model, data)?;
    let bar = slow_spinner("diagnose: starting");
    let stage = |st: crate::modelcheck::Stage| bar.set_message(format!("diagnose: {st}"));
    let r = crate::modelcheck::diagnose_with(&m, &set, data, &stage);
    let cmp = match (&r, report) {
        (Ok(_), Some(_)) => Some(crate::modelcheck::compare(&m, &set, data)),
        _ => None,
    };
    bar.finish_and_clear();
    let r = r?;
    if let (Some(out), Some(cmp)) = (report, cmp) {
        write_report_html(out, &crate::report::model_check_report(model, data, &set, &cmp?, Some(&r)))?;
    }
    print_result("vmt-diagnose/1", &r, json, crate::modelcheck::diagnose_text)
}

/// Writes a report's self-contained HTML page to `out` (atomically) and says so on stderr.
fn write_report_html(out: &Path, report: &vmt_report::Report) -> Result<(), VmtError> {
    let (html, _) = crate::report::report_files(report)?;
    measurement::write_file_atomic(out, html.as_bytes())?;
    eprintln!("wrote {}", out.display());
    Ok(())
}

/// Where `vmt add` takes the added effect's starting parameters from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FromDiagnosis {
    /// The catalogue's defaults.
    No,
    /// A diagnosis of the model on `--data`, computed (`--from-diagnosis`).
    Computed,
    /// A diagnosis `vmt diagnose --json` wrote (`--diagnosis FILE`), checked to belong to the model
    /// and `--data` by its normalised RMS ([`DIAGNOSIS_RMS_MATCH`]).
    File(std::path::PathBuf),
}

/// A diagnosis file ([`FromDiagnosis::File`]) belongs to the model and data when its
/// `normalized_rms` and the model's on the data (`compare`) agree within this fraction. The two
/// are the same fit's by different sums (`diagnose` and `compare` differ in the last digits:
/// 4e-16 and 2e-15 relative on the benchmark's sets `res15000` and `enc_backlash`), and any change
/// of the model's fitted terms or of the data moves it by far more.
pub const DIAGNOSIS_RMS_MATCH: f64 = 1e-9;

/// Largest diagnosis file `vmt add --diagnosis` reads, bytes (a diagnosis is a few kB).
const DIAGNOSIS_MAX_BYTES: u64 = 16 << 20;

/// The diagnosis file `file` (`vmt-diagnose/1`, read whole: at most [`DIAGNOSIS_MAX_BYTES`]).
fn read_diagnosis(file: &Path) -> Result<crate::modelcheck::DiagnoseReport, VmtError> {
    let text = VmtError::read_bounded(file, DIAGNOSIS_MAX_BYTES, "a diagnosis (vmt diagnose --json)")?;
    let value: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
        VmtError::bad(file, format!("line {}", e.line()), format!("expected JSON (vmt diagnose --json): {e}"))
    })?;
    let format = value.get("format").and_then(|f| f.as_str());
    if format != Some("vmt-diagnose/1") {
        return Err(VmtError::bad(
            file,
            "format",
            format!(
                "expected \"vmt-diagnose/1\" (the output of vmt diagnose --json), found {}",
                format.unwrap_or("none")
            ),
        ));
    }
    serde_json::from_value(value).map_err(|e| VmtError::bad(file, "", format!("not a vmt-diagnose/1 report: {e}")))
}

/// Checks that the diagnosis `diag` read from `file` was made for the model and data: its
/// normalised RMS is the model's on the data (`rms`, from `compare`; [`DIAGNOSIS_RMS_MATCH`]).
fn check_diagnosis_rms(file: &Path, diag: &crate::modelcheck::DiagnoseReport, rms: f64) -> Result<(), VmtError> {
    if diag.normalized_rms == rms || (diag.normalized_rms / rms - 1.0).abs() <= DIAGNOSIS_RMS_MATCH {
        return Ok(());
    }
    Err(VmtError::bad(
        file,
        "normalized_rms",
        format!(
            "the diagnosis was not made for this model on these data: its normalised RMS is {}, the model's on \
             --data is {rms} (run vmt diagnose --json again, or use --from-diagnosis)",
            diag.normalized_rms
        ),
    ))
}

/// `vmt add --model M --effect NAME [--from-diagnosis | --diagnosis FILE] [--data D] -o M2`: writes the
/// model with the effect added (`fit = true`; with `--from-diagnosis` starting from the diagnosed
/// parameters, computed again, or with `--diagnosis FILE` from those of a diagnosis `vmt diagnose
/// --json` wrote for this model and data; both need `--data`). With `--data`, appends (model,
/// normalised RMS) of the input model (if the history is empty) and of the new model to
/// `history.json` beside M2.
pub fn add(model: &Path, effect: &str, from: &FromDiagnosis, data: Option<&Path>, out: &Path) -> Result<i32, VmtError> {
    use vmt_sim::effects::EffectName;
    let m = crate::model::read_model(model)?;
    let name: EffectName =
        effect.parse().map_err(|e: vmt_sim::effects::UnknownEffect| VmtError::Usage(format!("--effect: {e}")))?;
    let set = match data {
        Some(d) => {
            let set = measurement::read_data(d)?;
            check_model_on_data(&m, &set, model)?;
            Some(set)
        }
        None if *from == FromDiagnosis::Computed => {
            return Err(VmtError::Usage("--from-diagnosis needs --data (the diagnosis is computed again)".into()))
        }
        None if *from != FromDiagnosis::No => {
            return Err(VmtError::Usage("--diagnosis needs --data (the diagnosis is checked against them)".into()))
        }
        None => None,
    };
    // The diagnosis the added effect starts from, with where it came from (for errors), and the
    // input model on the data (the history's first entry) when it checks a diagnosis file (read
    // before anything is computed).
    let (diag, r0) = match (from, &set, data) {
        (FromDiagnosis::No, ..) | (_, None, _) | (_, _, None) => (None, None),
        (FromDiagnosis::Computed, Some(s), Some(d)) => (Some((d, "", crate::modelcheck::diagnose(&m, s, d)?)), None),
        (FromDiagnosis::File(file), Some(s), Some(d)) => {
            let diag = read_diagnosis(file)?;
            let r0 = crate::modelcheck::compare(&m, s, d)?;
            check_diagnosis_rms(file, &diag, r0.normalized_rms)?;
            (Some((file.as_path(), "ranking", diag)), Some(r0))
        }
    };
    let entry = diag
        .map(|(place, key, diag)| {
            diag.ranking.into_iter().find(|r| r.effect == name).ok_or_else(|| {
                VmtError::bad(place, key, format!("the diagnosis has no candidate `{name}` on these data"))
            })
        })
        .transpose()?;
    let hpath = crate::modelcheck::history_path(out);
    if data.is_some() && hpath.exists() && crate::modelcheck::read_history(&hpath).is_none() {
        return Err(VmtError::bad(
            &hpath,
            "",
            "expected a history.json written by vmt add (a JSON array of iterations); it is unreadable or corrupt, \
             and vmt will not replace it: move it away or choose another --out directory",
        ));
    }
    crate::output::refuse_input_overwrite(out, &[model])?;
    if let Some(d) = data {
        crate::output::refuse_input_overwrite(out, &[d])?;
    }
    if let FromDiagnosis::File(file) = from {
        crate::output::refuse_input_overwrite(out, &[file])?;
    }
    let mut m2 =
        crate::modelcheck::add_effect(&m, name, entry.as_ref()).map_err(|e| VmtError::bad(model, "", e.to_string()))?;
    m2.source = out.to_path_buf();
    crate::model::write_model(&m2, out)?;
    eprintln!("wrote {} ({} added, fit = true)", out.display(), name);
    if let (Some(s), Some(d)) = (&set, data) {
        let mut entries = Vec::new();
        if crate::modelcheck::read_history(&hpath).unwrap_or_default().is_empty() {
            let r0 = match r0 {
                Some(r) => r,
                None => crate::modelcheck::compare(&m, s, d)?,
            };
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

/// `vmt identify DATA [--run R] [-o PROFILES.csv]`: the six error motions of the axis from the laser
/// lines (linear and straightness lasers) of a point-table run, with standard errors (FORMAT.md §5 CSV).
pub fn identify(path: &Path, run: Option<&str>, out: Option<&Path>, units: &str, json: bool) -> Result<i32, VmtError> {
    let units = parse_units(units)?;
    if let Some(o) = out {
        crate::output::refuse_input_overwrite(o, &[path])?;
    }
    let set = measurement::read(path)?;
    if run.is_none() {
        if let Some((n_lines, ci)) =
            crate::byo::identify_axes_set(&set).map_err(|e| VmtError::bad(path, "runs", e.to_string()))?
        {
            return identify_axes(path, n_lines, &ci, out, json);
        }
    }
    let (run, n_lines, id, notes) =
        crate::byo::identify_set(&set, run).map_err(|e| VmtError::bad(path, "runs", e.to_string()))?;
    for n in &notes {
        eprintln!("note: {n}");
    }
    if json {
        print_identify_json(
            "vmt-identify/1",
            &IdentifyJson { unobservable_profiles: unobservable_profiles(&id.profiles), result: &id },
        )?;
    } else {
        println!(
            "identified from {n_lines} laser lines of run {run}: rank {}, condition {:.3e}",
            id.rank, id.condition
        );
        for u in &id.unobservable {
            println!("  not observable: {u}");
        }
        print_profiles(&id.profiles);
    }
    if let Some(out) = out {
        // Only the error motions the lines determine at every position are written, with their σ (a
        // column has a σ exactly then, `byo::profiles_of`): a column of the minimum-norm solution's
        // 1e-21 m would read as "no error".
        let mut table = crate::byo::profiles_of(&id);
        let left_out = unobservable_profiles(&id.profiles);
        table.columns.retain(|c| c.sigma.is_some());
        if !left_out.is_empty() {
            eprintln!(
                "note: not written to {} (not observable from these lines): {}",
                out.display(),
                left_out.join(", ")
            );
        }
        measurement::write_profiles(&table, out, units)?;
        eprintln!("wrote {}", out.display());
    }
    Ok(0)
}

/// `vmt identify` on a multi-axis line set: the 21-error identification with squareness.
fn identify_axes(
    path: &Path,
    n_lines: usize,
    ci: &crate::estimate::ChainIdentification,
    out: Option<&Path>,
    json: bool,
) -> Result<i32, VmtError> {
    if let Some(out) = out {
        return Err(VmtError::bad(
            out,
            "",
            "-o writes a single-axis profile table; for a multi-axis line set use --json (profiles per axis, squareness)",
        ));
    }
    let id = &ci.identification;
    if json {
        let unobservable_profiles = unobservable_profiles(&id.profiles);
        print_identify_json("vmt-identify-chain/1", &IdentifyJson { unobservable_profiles, result: ci })?;
        return Ok(0);
    }
    println!(
        "identified from {n_lines} laser lines of {} ({} axes): rank {}, condition {:.3e}",
        path.display(),
        ci.positions.len(),
        id.rank,
        id.condition
    );
    for u in &id.unobservable {
        println!("  not observable: {u}");
    }
    for s in &id.squareness {
        match s.std_error {
            Some(e) => {
                println!("  {} {:<14} {:>10.3} µrad ± {:.3} µrad (1σ)", s.name, s.effect, s.value * 1e6, e * 1e6)
            }
            None => println!("  {} {:<14} unobservable from these lines", s.name, s.effect),
        }
    }
    print_profiles(&id.profiles);
    Ok(0)
}

/// `vmt identify --json`: the identification, whose standard errors are `null` where a value is not
/// observable, and the names of the profiles with such values.
#[derive(serde::Serialize)]
struct IdentifyJson<'a, T: serde::Serialize> {
    #[serde(flatten)]
    result: &'a T,
    /// Profiles (ISO 230-1 names) with at least one position whose value the lines do not determine.
    unobservable_profiles: Vec<&'a str>,
}

fn unobservable_profiles(profiles: &[vmt_estimators::laser_ls::ProfileEstimate]) -> Vec<&str> {
    profiles.iter().filter(|p| p.std_errors.iter().any(Option::is_none)).map(|p| p.name.as_str()).collect()
}

/// Prints an identification as JSON with `null` for every value the lines do not determine: a
/// profile's `values[i]` and a parameter's `params[i]` where the matching `std_errors[i]` is `null`, a
/// squareness `value` whose `std_error` is `null` (the solver's minimum-norm numbers there, e.g.
/// 7e-22 m, are not estimates), and the whole of a profile determined only at its reference position.
/// `unobservable_profiles` is the flag naming the profiles concerned.
fn print_identify_json<T: serde::Serialize>(format: &str, v: &T) -> Result<(), VmtError> {
    fn null_unobservable(v: &mut serde_json::Value) {
        use serde_json::Value;
        match v {
            Value::Object(m) => {
                if let Some(Value::Array(mut se)) = m.get("std_errors").cloned() {
                    // A profile determined only at its reference position (zero there by the reporting
                    // convention, σ = 0) is not observable at all: nothing of it is a number.
                    if se.iter().any(Value::is_null) && se.iter().all(|s| s.is_null() || s.as_f64() == Some(0.0)) {
                        se.iter_mut().for_each(|s| *s = Value::Null);
                        m.insert("std_errors".into(), Value::Array(se.clone()));
                    }
                    for key in ["values", "params"] {
                        if let Some(Value::Array(xs)) = m.get_mut(key) {
                            if xs.len() == se.len() {
                                xs.iter_mut().zip(&se).filter(|(_, s)| s.is_null()).for_each(|(x, _)| *x = Value::Null);
                            }
                        }
                    }
                }
                if m.get("std_error").is_some_and(Value::is_null) {
                    if let Some(x) = m.get_mut("value") {
                        *x = Value::Null;
                    }
                }
                m.values_mut().for_each(null_unobservable);
            }
            Value::Array(a) => a.iter_mut().for_each(null_unobservable),
            Value::Null | Value::Bool(_) | Value::Number(_) | Value::String(_) => {}
        }
    }
    let mut value = serde_json::to_value(v).map_err(|e| VmtError::Internal(format!("{format} JSON: {e}")))?;
    null_unobservable(&mut value);
    print_json(format, &value)
}

/// The identified profiles, one line each: peak |value| and largest standard error in µm or µrad, or
/// "unobservable" where the readings do not determine the value (never a number for those).
fn print_profiles(profiles: &[vmt_estimators::laser_ls::ProfileEstimate]) {
    for p in profiles {
        let q = if p.component < 3 { Quantity::Length } else { Quantity::Angle };
        let peak =
            p.values.iter().zip(&p.std_errors).filter(|(_, e)| e.is_some()).fold(0.0f64, |m, (v, _)| m.max(v.abs()));
        let missing = p.std_errors.iter().filter(|e| e.is_none()).count();
        let worst = p.std_errors.iter().flatten().cloned().fold(0.0, f64::max);
        // A profile whose only determined value is its zero at the reference position (σ = 0 by the
        // reporting convention) is not observable at all.
        let datum_only = missing > 0 && worst == 0.0;
        let se = match missing {
            0 => format!("largest standard error (1σ) {}", display(q, worst)),
            m if m == p.std_errors.len() || datum_only => "unobservable from these lines".to_string(),
            m => format!(
                "unobservable at {m} of {} positions; elsewhere largest standard error (1σ) {}",
                p.std_errors.len(),
                display(q, worst)
            ),
        };
        if missing == p.std_errors.len() || datum_only {
            println!("  {:<4} {se}", p.name);
        } else {
            println!("  {:<4} peak |value| {:>12}  {se}", p.name, display(q, peak));
        }
    }
}

/// `vmt score --truth T --estimate E`: compares two FORMAT.md §5 profile CSVs (crate::byo::score_profiles):
/// RMS and max difference per error motion.
pub fn score(truth: &Path, estimate: &Path, json: bool) -> Result<i32, VmtError> {
    let rows = crate::byo::score_profiles(&measurement::read_profiles(truth)?, &measurement::read_profiles(estimate)?)
        .map_err(|e| VmtError::bad(estimate, "positions", e.to_string()))?;
    if rows.is_empty() {
        return Err(VmtError::bad(estimate, "line 1 (header)", "no error-motion column in common with the truth"));
    }
    if json {
        print_json("vmt-score/1", &serde_json::json!({ "rows": rows }))?;
    } else {
        println!("difference d = estimate − truth on the estimate's positions inside the truth's range (straightness");
        println!("about its least-squares line, the other motions relative to their first position); positions");
        println!("outside the truth's range are not scored (the truth is not extrapolated)");
        println!("{:<20} {:>14} {:>14} {:>8} {:>8}", "error motion", "RMS of d", "max |d|", "points", "outside");
        for r in &rows {
            let q = crate::study::motion_quantity(&r.effect);
            println!(
                "{:<20} {:>14} {:>14} {:>8} {:>8}",
                r.effect,
                display(q, r.rms),
                display(q, r.max),
                r.points,
                r.outside
            );
        }
    }
    Ok(0)
}

#[cfg(test)]
mod shard_tests {
    use super::parse_shard;

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| vars.iter().find(|(n, _)| *n == k).map(|(_, v)| v.to_string())
    }

    #[test]
    fn shard_auto_reads_each_scheduler_and_explicit_forms() {
        assert_eq!(parse_shard("2/4", &env(&[])).unwrap(), (2, 4));
        // Slurm `--array=1-4`: ids 1..4, min 1, count 4.
        let slurm = [("SLURM_ARRAY_TASK_ID", "3"), ("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_COUNT", "4")];
        assert_eq!(parse_shard("auto", &env(&slurm)).unwrap(), (2, 4));
        // LSF `-J "s[1-8]"`: index 1-based, end 8.
        assert_eq!(parse_shard("auto", &env(&[("LSB_JOBINDEX", "8"), ("LSB_JOBINDEX_END", "8")])).unwrap(), (7, 8));
        // HyperQueue and PBS give the index only.
        assert_eq!(parse_shard("auto/5", &env(&[("HQ_TASK_ID", "4")])).unwrap(), (4, 5));
        assert_eq!(parse_shard("auto/2", &env(&[("PBS_ARRAY_INDEX", "1")])).unwrap(), (1, 2));
        for (s, vars, msg) in [
            ("auto", &[][..], "no job-array index"),
            ("auto", &[("PBS_ARRAYID", "1")][..], "use --shard auto/N"),
            ("auto/2", &[("HQ_TASK_ID", "2")][..], "0 ≤ i < n"),
            (
                "auto",
                &[("SLURM_ARRAY_TASK_ID", "x"), ("SLURM_ARRAY_TASK_COUNT", "2")][..],
                "SLURM_ARRAY_TASK_ID must be",
            ),
            ("1", &[][..], "expected i/n"),
        ] {
            let e = parse_shard(s, &env(vars)).unwrap_err().to_string();
            assert!(e.contains(msg), "{s}: {e}");
        }
    }
}
