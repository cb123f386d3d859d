//! The `vmt` command line. Exit codes: 0 success, 1 an estimate missed its tolerance, 2 bad input.

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "vmt",
    version,
    about = "A virtual machine tool: simulate machine-tool linear axes, identify their errors, check models against measurements"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// A model checked against a measurement set (`vmt compare`, `vmt diagnose`).
#[derive(clap::Args)]
struct ModelAndData {
    /// The model (`vmt-model/1`, FORMAT.md §2).
    #[arg(long)]
    model: PathBuf,
    /// The measurement set directory (FORMAT.md §1) or an ISO 230-2 `.dat` file.
    #[arg(long)]
    data: PathBuf,
    /// Print JSON (FORMAT.md §4) instead of the text report.
    #[arg(long)]
    json: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a scenario and run its estimators (no argument: the bundled default scenario).
    Run {
        scenario: Option<PathBuf>,
        /// Directory for the measurement set and report (default: vmt-out/<scenario name>).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Print machine-readable JSON instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Simulate a scenario and write its measurement set (FORMAT.md §1) with the truth beside it.
    Simulate {
        scenario: Option<PathBuf>,
        /// Output directory (written atomically).
        #[arg(short, long)]
        out: PathBuf,
        /// Write CSV columns in these units instead of SI ("si" or "human": um, urad, mm/s, ...).
        #[arg(long, default_value = "si")]
        units: String,
    },
    /// Monte Carlo tolerance study over a sensor parameter (physics simulated once), or `study merge`.
    Study {
        /// Scenario file, or `merge` to join shard outputs.
        scenario: PathBuf,
        /// With `merge`: the shard output directories.
        shards: Vec<PathBuf>,
        /// The varied parameter, e.g. sensors.acc_z.noise_density=1e-7,3e-7,1e-6
        #[arg(long)]
        vary: Option<String>,
        #[arg(long, default_value_t = 100)]
        trials: usize,
        /// Compute only trials k with k mod n = i (for a cluster job array), e.g. 0/4.
        #[arg(long)]
        shard: Option<String>,
        /// Run this program in every trial instead of the scenario's estimators: `CMD {data} {out}` reads
        /// the measurement set at {data} and writes a FORMAT.md §5 profile CSV to {out}.
        #[arg(long)]
        estimator_cmd: Option<String>,
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Straightness (and roll from a horizontal accelerometer) from the constant-velocity passes of a
    /// measurement set: recoverable band, Cramér–Rao bounds, profile CSV with standard errors.
    Straightness {
        data: PathBuf,
        /// Write the estimate as a FORMAT.md §5 profile CSV with `_sigma` columns.
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// `fusion` (SNR-weighted, DESIGN.md §7) or `seed` (seed 000, spatial-frequency continuity).
        #[arg(long, default_value = "fusion")]
        method: String,
        /// Accelerometers to use (default: every accelerometer with a column in a constant_velocity run).
        #[arg(long, num_args = 1..)]
        sensor: Vec<String>,
        #[arg(long)]
        json: bool,
    },
    /// Stick-slip index (seed 002) of the time-series runs of a measurement set.
    Ssi {
        data: PathBuf,
        #[arg(long)]
        sensor: Option<String>,
        #[arg(long)]
        json: bool,
    },
    /// Stribeck friction parameters from the friction-sweep runs of a measurement set.
    Friction {
        data: PathBuf,
        #[arg(long)]
        sensor: Option<String>,
        #[arg(long)]
        json: bool,
    },
    /// Compensation table (seed 004) from the positioning run of a measurement set.
    Compensate {
        data: PathBuf,
        #[arg(long)]
        sensor: Option<String>,
        #[arg(short, long)]
        out: PathBuf,
        /// Write an equidistant controller-style table of N points (0.1 µm units) instead.
        #[arg(long)]
        equidistant: Option<usize>,
    },
    /// The six error motions from the laser lines of a point-table run (seeds 001/003 identifier).
    Identify {
        data: PathBuf,
        #[arg(long)]
        run: Option<String>,
        /// Write the profiles with standard errors (FORMAT.md §5).
        #[arg(short, long)]
        out: Option<PathBuf>,
        #[arg(long)]
        json: bool,
    },
    /// Compare an estimate's profile CSV with the truth's (FORMAT.md §5): RMS and max per error motion.
    Score {
        #[arg(long)]
        truth: PathBuf,
        #[arg(long)]
        estimate: PathBuf,
        #[arg(long)]
        json: bool,
    },
    /// ISO 230-2 evaluation of a positioning test: a measurement set directory or an ecmc .dat file.
    #[command(name = "iso230-2")]
    Iso230_2 {
        path: PathBuf,
        /// Run of the measurement set (default: the first positioning run).
        #[arg(long)]
        run: Option<String>,
        /// Deviation column (default: the first linear laser of the run).
        #[arg(long)]
        sensor: Option<String>,
        #[arg(long)]
        json: bool,
    },
    /// Fit a model's free parameters to a measurement set and report the residual (DESIGN.md §8).
    Compare(ModelAndData),
    /// Rank the effects a model lacks by how much of the residual they explain (ΔBIC, verdicts).
    Diagnose(ModelAndData),
    /// Write the model with an effect added (fit = true); keeps history.json beside the output.
    Add {
        #[arg(long)]
        model: PathBuf,
        #[arg(long)]
        effect: String,
        /// Start from the parameters the diagnosis found (needs --data).
        #[arg(long)]
        from_diagnosis: bool,
        #[arg(long)]
        data: Option<PathBuf>,
        #[arg(short, long)]
        out: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run { scenario, out, json } => vmt::cli::run(scenario.as_deref(), out.as_deref(), json),
        Command::Simulate { scenario, out, units } => vmt::cli::simulate(scenario.as_deref(), &out, &units).map(|_| 0),
        Command::Study { scenario, shards, vary, trials, shard, estimator_cmd, out } => {
            if scenario.as_os_str() == "merge" {
                vmt::cli::study_merge(&out, &shards)
            } else {
                match vary {
                    Some(v) => vmt::cli::study(&scenario, &v, trials, shard.as_deref(), estimator_cmd.as_deref(), &out),
                    None => Err(vmt::error::VmtError::Usage("study needs --vary sensors.NAME.KEY=V1,V2,…".into())),
                }
            }
        }
        Command::Straightness { data, out, method, sensor, json } => {
            vmt::straightness::command(&data, out.as_deref(), &method, &sensor, json)
        }
        Command::Ssi { data, sensor, json } => vmt::cli::ssi(&data, sensor.as_deref(), json),
        Command::Friction { data, sensor, json } => vmt::cli::friction(&data, sensor.as_deref(), json),
        Command::Compensate { data, sensor, out, equidistant } => {
            vmt::cli::compensate(&data, sensor.as_deref(), &out, equidistant)
        }
        Command::Identify { data, run, out, json } => vmt::cli::identify(&data, run.as_deref(), out.as_deref(), json),
        Command::Score { truth, estimate, json } => vmt::cli::score(&truth, &estimate, json),
        Command::Iso230_2 { path, run, sensor, json } => {
            vmt::cli::iso230_2(&path, run.as_deref(), sensor.as_deref(), json)
        }
        Command::Compare(a) => vmt::cli::compare(&a.model, &a.data, a.json),
        Command::Diagnose(a) => vmt::cli::diagnose(&a.model, &a.data, a.json),
        Command::Add { model, effect, from_diagnosis, data, out } => {
            vmt::cli::add(&model, &effect, from_diagnosis, data.as_deref(), &out)
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
