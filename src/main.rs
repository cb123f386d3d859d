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
    Compare {
        #[arg(long)]
        model: PathBuf,
        #[arg(long)]
        data: PathBuf,
        #[arg(long)]
        json: bool,
    },
    /// Rank the effects a model lacks by how much of the residual they explain (ΔBIC, verdicts).
    Diagnose {
        #[arg(long)]
        model: PathBuf,
        #[arg(long)]
        data: PathBuf,
        #[arg(long)]
        json: bool,
    },
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
        Command::Iso230_2 { path, run, sensor, json } => {
            vmt::cli::iso230_2(&path, run.as_deref(), sensor.as_deref(), json)
        }
        Command::Compare { model, data, json } => vmt::cli::compare(&model, &data, json),
        Command::Diagnose { model, data, json } => vmt::cli::diagnose(&model, &data, json),
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
