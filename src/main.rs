//! The `vmt` command line. Exit codes: 0 success, 1 an estimate missed its tolerance, 2 bad input,
//! 3 an I/O failure of the machine (disk full, permission denied), 70 a bug in vmt.

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "vmt",
    version,
    about = "A virtual machine tool: simulate machine-tool linear axes, identify their errors, check models against measurements",
    after_help = "Exit codes: 0 success; 1 an estimate missed its tolerance; 2 bad input (a file, a key or an \
                  option: the message names the file and the place); 3 an I/O failure of the machine (disk \
                  full, permission denied); 70 a bug in vmt."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// A model checked against a measurement set (`vmt compare`, `vmt diagnose`).
#[derive(clap::Args)]
struct ModelAndData {
    /// The model (`vmt-model/1`, docs/formats.md).
    #[arg(long)]
    model: PathBuf,
    /// The measurement set directory (docs/formats.md) or an ISO 230-2 `.dat` file.
    #[arg(long)]
    data: PathBuf,
    /// Print JSON (`vmt-compare/1` / `vmt-diagnose/1`, docs/formats.md) instead of the text report.
    #[arg(long)]
    json: bool,
    /// Also write an HTML report (self-contained page: the channels, the fitted model, the ranking and
    /// the residual's figures).
    #[arg(long)]
    report: Option<PathBuf>,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a scenario and run its estimators (no argument: the bundled default scenario).
    Run {
        /// Scenario file (`vmt-scenario/1`, docs/formats.md); default: the bundled scenarios/default.toml.
        scenario: Option<PathBuf>,
        /// Directory for the measurement set and report (default: vmt-out/<scenario name>).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Print JSON (`vmt-run/1`, docs/formats.md) instead of the table: the checks, the data and report paths.
        #[arg(long)]
        json: bool,
        /// Write the measurement set's CSV columns in these units instead of SI ("si" or "human": mm
        /// positions, um, urad, mm/s; time in s, accelerations in m/s^2 and forces in N, each header
        /// naming its unit).
        #[arg(long, default_value = "si")]
        units: String,
    },
    /// Simulate a scenario and write its measurement set (docs/formats.md) with the truth beside it.
    Simulate {
        /// Scenario file (`vmt-scenario/1`); default: the bundled scenarios/default.toml.
        scenario: Option<PathBuf>,
        /// Output directory (written atomically).
        #[arg(short, long)]
        out: PathBuf,
        /// Write CSV columns in these units instead of SI ("si" or "human": um, urad, mm/s, ...).
        #[arg(long, default_value = "si")]
        units: String,
        /// A compensation table loaded in the simulated CNC (`vmt compensate` output in any of its formats,
        /// docs/formats.md §7): every run is measured with it applied.
        #[arg(long)]
        compensation: Option<PathBuf>,
    },
    /// Monte Carlo tolerance study over a sensor or scenario parameter, or `study merge`.
    Study {
        /// Scenario file, or `merge` to join shard outputs.
        scenario: PathBuf,
        /// With `merge`: the shard output directories (every shard of one study once, each with its
        /// `shard.toml`; a missing, repeated or foreign shard is refused).
        shards: Vec<PathBuf>,
        /// The varied parameter and its values (SI): a sensor parameter, e.g.
        /// sensors.acc_z.noise_density=1e-7,3e-7,1e-6 (physics simulated once), or any number the scenario
        /// file gives, by its key path, e.g. truth.effects.backlash.value=2e-6,4e-6 or axis.servo.kp=30,50
        /// (each value a new scenario, validated as the file would be, simulated once)
        #[arg(long)]
        vary: Option<String>,
        /// A scenario number drawn per trial (repeatable; instead of --vary): KEY.PATH=uniform(LO,HI),
        /// normal(MEAN,SD) or loguniform(LO,HI), SI, e.g. truth.effects.backlash.value=uniform(2e-6,8e-6);
        /// every trial simulates its own physics, and sensitivity.csv gives first-order Sobol indices
        #[arg(long)]
        sample: Vec<String>,
        /// Monte Carlo trials per value (each redraws the sensor noise; at least 1).
        // index: a u64 ≥ 1 (the parser's range) to usize, lossless on 64-bit; run_study bounds values × trials by
        // MAX_TRIALS before any allocation.
        #[arg(long, default_value_t = 100, value_parser = clap::builder::TypedValueParser::map(clap::value_parser!(u64).range(1..), |n| n as usize))]
        trials: usize,
        /// Compute only trials k with k mod n = i (for a cluster job array), e.g. 0/4; `auto` reads i and n
        /// from a Slurm, HyperQueue, PBS or LSF job array (`auto/n` where the scheduler gives no size).
        #[arg(long)]
        shard: Option<String>,
        /// Run this program in every trial instead of the scenario's estimators: `CMD {data} {out}` reads
        /// the measurement set at {data} and writes a profile CSV (docs/formats.md) to {out}.
        #[arg(long)]
        estimator_cmd: Option<String>,
        /// With --estimator-cmd: the largest RMS difference (SI: m for straightness/positioning, rad for
        /// angles) an error motion may show and pass; without it no pass column is printed.
        #[arg(long)]
        tolerance: Option<f64>,
        /// Output directory for trials.csv, summary.csv and study.svg.
        #[arg(short, long)]
        out: PathBuf,
        /// Write trials.csv and summary.csv in these units ("si", or "human": each row's differences in
        /// um or urad, with a `unit` column; `study merge` reads only SI files).
        #[arg(long, default_value = "si")]
        units: String,
    },
    /// Straightness (and roll from a horizontal accelerometer) from the constant-velocity passes of a
    /// measurement set: recoverable band, Cramér–Rao bounds, profile CSV with standard errors.
    Straightness {
        /// The measurement set directory (manifest.toml + CSV runs with accelerometer columns).
        data: PathBuf,
        /// Write the estimate as a profile CSV (docs/formats.md §5) with `_sigma` columns.
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// `fusion` (vmt's SNR-weighted spectral fusion) or `seed` (the Dalian University of Technology
        /// patent's spatial-frequency continuity); both in docs/methods.md.
        #[arg(long, default_value = "fusion")]
        method: String,
        /// Accelerometers to use (default: every accelerometer with a column in a constant_velocity run).
        #[arg(long, num_args = 1..)]
        sensor: Vec<String>,
        /// Print the result as one JSON object (format `vmt-straightness/1`) instead of the text table.
        #[arg(long)]
        json: bool,
        /// Write the profile CSV in these units instead of SI ("si" or "human": mm, um, urad).
        #[arg(long, default_value = "si")]
        units: String,
    },
    /// Stick-slip (crawl) index of the time-series runs (encoder method, docs/methods.md).
    Ssi {
        /// Measurement set directory (docs/formats.md).
        data: PathBuf,
        /// Position column to use (default: the first encoder of each run).
        #[arg(long)]
        sensor: Option<String>,
        /// Print JSON (`vmt-ssi/1`) instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Stribeck friction parameters from the friction-sweep runs of a measurement set.
    Friction {
        /// Measurement set directory (docs/formats.md).
        data: PathBuf,
        /// Motor-force column (default: the first motor_force sensor).
        #[arg(long)]
        sensor: Option<String>,
        /// Print JSON (`vmt-friction/1`) instead of the text.
        #[arg(long)]
        json: bool,
    },
    /// Compensation table (docs/methods.md, docs/formats.md §7) from the positioning run of a measurement set.
    Compensate {
        /// Measurement set directory (docs/formats.md).
        data: PathBuf,
        /// Deviation column (default: the first linear laser of the run).
        #[arg(long)]
        sensor: Option<String>,
        /// Output file of the table (written atomically).
        #[arg(short, long)]
        out: PathBuf,
        /// Write an equidistant controller-style table of N points (0.1 µm units) instead (legacy).
        #[arg(long)]
        equidistant: Option<usize>,
        /// Table format: csv (default; variable-step nodes), siemens ($AA_ENC_COMP, ≤ 5000 points) or
        /// fanuc (parameters 3620–3624, incremental 0.1 µm values, ≤ 128 points); docs/formats.md §7.
        #[arg(long)]
        format: Option<String>,
        /// Equidistant table points (siemens/fanuc default: one per target; csv default: variable step).
        #[arg(long)]
        points: Option<usize>,
        /// The controller's axis name (default: the run's axis letter and 1, e.g. X1).
        #[arg(long)]
        axis: Option<String>,
        /// Print JSON (`vmt-compensate/1`, docs/formats.md §4): the nodes with their standard
        /// uncertainties and what the table leaves at each target.
        #[arg(long)]
        json: bool,
    },
    /// Error motions (and squareness) from laser lines: least-squares line-set identification (docs/methods.md).
    Identify {
        /// Measurement set directory (docs/formats.md) holding laser-line point tables.
        data: PathBuf,
        /// Run to use (default: the set's line runs).
        #[arg(long)]
        run: Option<String>,
        /// Write the profiles with standard errors (profile CSV, docs/formats.md).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Units of the -o CSV: "si" (m, rad) or "human" (mm positions, µm, µrad).
        #[arg(long, default_value = "si")]
        units: String,
        /// Print JSON (`vmt-identify/1`) instead of the text.
        #[arg(long)]
        json: bool,
    },
    /// Compare an estimate's profile CSV with the truth's (docs/formats.md): RMS and max per error motion.
    Score {
        /// The truth profile CSV (e.g. truth_profiles.csv beside a simulated set).
        #[arg(long)]
        truth: PathBuf,
        /// The estimate profile CSV (same columns: position, then one per error motion).
        #[arg(long)]
        estimate: PathBuf,
        /// Print JSON (`vmt-score/1`) instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// ISO 230-2 evaluation of a positioning test: a measurement set directory or an ecmc .dat file.
    #[command(name = "iso230-2")]
    Iso230_2 {
        /// Measurement set directory or ecmc ISO 230-2 .dat file.
        path: PathBuf,
        /// Run of the measurement set (default: the first positioning run).
        #[arg(long)]
        run: Option<String>,
        /// Deviation column (default: the first linear laser of the run).
        #[arg(long)]
        sensor: Option<String>,
        /// Print JSON (`vmt-iso230-2/1`) instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Fit a model's free parameters to a measurement set and report the residual (model-check loop, docs/methods.md).
    Compare(ModelAndData),
    /// Rank the effects a model lacks by how much of the residual they explain (ΔBIC, verdicts).
    Diagnose(ModelAndData),
    /// Write the model with an effect added (fit = true); keeps history.json beside the output.
    Add {
        /// The model to extend (`vmt-model/1`).
        #[arg(long)]
        model: PathBuf,
        /// The effect to add (its name in the model format).
        #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(vmt_sim::effects::EffectName::ALL.map(|n| n.as_str())))]
        effect: String,
        /// Start from the parameters the diagnosis found (needs --data).
        #[arg(long)]
        from_diagnosis: bool,
        /// Start from the parameters of this diagnosis (the vmt-diagnose/1 JSON object `vmt diagnose`
        /// printed for this model and --data) instead of computing it again; implies
        /// --from-diagnosis, needs --data.
        #[arg(long, value_name = "FILE")]
        diagnosis: Option<PathBuf>,
        /// Measurement set the diagnosis and the history's normalised RMS are computed on.
        #[arg(long)]
        data: Option<PathBuf>,
        /// Output model file (history.json is kept beside it).
        #[arg(short, long)]
        out: PathBuf,
    },
}

fn main() -> ExitCode {
    vmt::cli::keep_freed_memory();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run { scenario, out, json, units } => vmt::cli::run(scenario.as_deref(), out.as_deref(), json, &units),
        Command::Simulate { scenario, out, units, compensation } => {
            vmt::cli::simulate(scenario.as_deref(), &out, &units, compensation.as_deref()).map(|_| 0)
        }
        Command::Study { scenario, shards, vary, sample, trials, shard, estimator_cmd, tolerance, out, units } => {
            if scenario.as_os_str() == "merge" {
                vmt::cli::study_merge(&out, &shards, &units)
            } else {
                vmt::cli::study(
                    &scenario,
                    vary.as_deref(),
                    &sample,
                    trials,
                    shard.as_deref(),
                    estimator_cmd.as_deref(),
                    tolerance,
                    &units,
                    &out,
                )
            }
        }
        Command::Straightness { data, out, method, sensor, json, units } => {
            vmt::cli::straightness(&data, out.as_deref(), &method, &sensor, json, &units)
        }
        Command::Ssi { data, sensor, json } => vmt::cli::ssi(&data, sensor.as_deref(), json),
        Command::Friction { data, sensor, json } => vmt::cli::friction(&data, sensor.as_deref(), json),
        Command::Compensate { data, sensor, out, equidistant, format, points, axis, json } => vmt::cli::compensate(
            &data,
            &out,
            &vmt::cli::CompensateOptions { sensor, equidistant, format, points, axis, json },
        ),
        Command::Identify { data, run, out, units, json } => {
            vmt::cli::identify(&data, run.as_deref(), out.as_deref(), &units, json)
        }
        Command::Score { truth, estimate, json } => vmt::cli::score(&truth, &estimate, json),
        Command::Iso230_2 { path, run, sensor, json } => {
            vmt::cli::iso230_2(&path, run.as_deref(), sensor.as_deref(), json)
        }
        Command::Compare(a) => vmt::cli::compare(&a.model, &a.data, a.json, a.report.as_deref()),
        Command::Diagnose(a) => vmt::cli::diagnose(&a.model, &a.data, a.json, a.report.as_deref()),
        Command::Add { model, effect, from_diagnosis, diagnosis, data, out } => {
            let from = match diagnosis {
                Some(file) => vmt::cli::FromDiagnosis::File(file),
                None if from_diagnosis => vmt::cli::FromDiagnosis::Computed,
                None => vmt::cli::FromDiagnosis::No,
            };
            vmt::cli::add(&model, &effect, &from, data.as_deref(), &out)
        }
    };
    match result {
        Ok(code) => ExitCode::from(code as u8),
        Err(e) => {
            eprintln!("vmt: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    /// Every subcommand and every argument (positional or option) has a help line, at every depth.
    #[test]
    fn every_command_and_argument_has_help() {
        fn walk(cmd: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for a in cmd.get_arguments() {
                let builtin = matches!(a.get_id().as_str(), "help" | "version");
                if !builtin && a.get_help().is_none() && a.get_long_help().is_none() {
                    missing.push(format!("{path} {}", a.get_id()));
                }
            }
            for sub in cmd.get_subcommands() {
                if sub.get_about().is_none() && sub.get_name() != "help" {
                    missing.push(format!("{path} {} (the command)", sub.get_name()));
                }
                walk(sub, &format!("{path} {}", sub.get_name()), missing);
            }
        }
        let cmd = Cli::command();
        cmd.clone().debug_assert();
        let mut missing = Vec::new();
        walk(&cmd, "vmt", &mut missing);
        assert!(missing.is_empty(), "arguments without a help line: {missing:#?}");
    }
}
